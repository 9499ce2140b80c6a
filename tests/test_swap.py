"""A rerun into an existing output folder replaces its files all or nothing.

The files are written into a staging folder inside OUTDIR and then moved into place one by one.
An interrupted rerun used to delete the previous files it had already replaced and keep the
others: the folder ended half old, half gone. Now every previous file is set aside before its
replacement moves in, and on any failure or Ctrl-C between two moves the new files go out and the
previous ones come back: the folder is byte for byte what it was, and files of other names are
never touched.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest
from meshes import tri_grid

import segparam.io
from segparam.cli import main
from segparam.errors import MeshFileError
from segparam.export import write_obj
from segparam.io import atlas_file_names, staged_outputs

NAMES = sorted(atlas_file_names("scan").values())  # what an atlas folder holds
USER_FILES = {"notes.txt": b"mine, not segparam's", "scan.blend": b"\x00blender\xff"}


def snapshot(folder: Path) -> dict[str, bytes | None]:
    """Every entry under ``folder``: relative path -> bytes (None for a folder)."""
    return {
        str(p.relative_to(folder)): (None if p.is_dir() else p.read_bytes())
        for p in sorted(folder.rglob("*"))
    }


def old_folder(folder: Path, names: list[str]) -> dict[str, bytes | None]:
    """``folder`` holding an earlier run's ``names`` and the user's own files."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        (folder / name).write_bytes(f"old {name}\n".encode())
    for name, data in USER_FILES.items():
        (folder / name).write_bytes(data)
    return snapshot(folder)


def write_new(stage: Path) -> None:
    for name in NAMES:
        (stage / name).write_bytes(f"new {name}, longer than the old one\n".encode())


class FailingReplace:
    """``os.replace`` whose ``k``-th call (1-based) raises ``exc``: before the move (``after``
    False), or after it (a Ctrl-C that lands between the rename and the next statement)."""

    def __init__(self, k: int, exc: BaseException, *, after: bool = False, only=None):
        self.k, self.exc, self.after, self.only = k, exc, after, only
        self.calls = 0
        self.real = os.replace

    def __call__(self, src, dst, **kwargs):
        if self.only is not None and not self.only(Path(src), Path(dst)):
            return self.real(src, dst, **kwargs)
        self.calls += 1
        if self.calls == self.k:
            if self.after:
                self.real(src, dst, **kwargs)
            raise self.exc
        return self.real(src, dst, **kwargs)


def count_moves(tmp_path: Path, names: list[str]) -> int:
    """How many renames a successful swap over a folder holding ``names`` makes."""
    folder = tmp_path / "count"
    old_folder(folder, names)
    counter = FailingReplace(0, AssertionError())
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(os, "replace", counter)
        with staged_outputs(folder) as stage:
            write_new(stage)
    return counter.calls


# Previous runs: every name there, some of them, none (only the user's files).
PREVIOUS = {"all": NAMES, "some": NAMES[::2], "none": []}
EXCEPTIONS = {
    "ctrl-c": KeyboardInterrupt,
    "oserror": lambda: OSError(28, "No space left on device"),
}


@pytest.mark.parametrize("previous", list(PREVIOUS))
@pytest.mark.parametrize("exc", list(EXCEPTIONS))
@pytest.mark.parametrize("after", [False, True], ids=["before-move", "after-move"])
def test_a_failure_after_any_number_of_moves_leaves_the_folder_exactly(
    previous, exc, after, tmp_path, monkeypatch
):
    names = PREVIOUS[previous]
    n_moves = count_moves(tmp_path, names)
    assert n_moves == len(NAMES) + len(names)  # each previous file set aside, each new moved in
    for k in range(1, n_moves + 1):
        folder = tmp_path / f"out-{k}"
        before = old_folder(folder, names)
        fake = FailingReplace(k, EXCEPTIONS[exc](), after=after)
        monkeypatch.setattr(os, "replace", fake)
        with pytest.raises(KeyboardInterrupt if exc == "ctrl-c" else OSError):
            with staged_outputs(folder) as stage:
                write_new(stage)
        monkeypatch.undo()
        assert fake.calls >= k, "the failure was never injected"
        assert snapshot(folder) == before, f"failure at move {k} of {n_moves}"


@pytest.mark.parametrize("previous", list(PREVIOUS))
def test_a_rerun_replaces_every_file_and_keeps_the_users(previous, tmp_path):
    folder = tmp_path / "out"
    old_folder(folder, PREVIOUS[previous])
    with staged_outputs(folder) as stage:
        write_new(stage)
    expected = {name: f"new {name}, longer than the old one\n".encode() for name in NAMES}
    assert snapshot(folder) == dict(sorted({**expected, **USER_FILES}.items()))


def test_a_failure_while_writing_leaves_the_folder_exactly(tmp_path):
    folder = tmp_path / "out"
    before = old_folder(folder, NAMES)
    with pytest.raises(KeyboardInterrupt):
        with staged_outputs(folder) as stage:
            write_new(stage)
            raise KeyboardInterrupt
    assert snapshot(folder) == before


def test_previous_files_that_cannot_be_put_back_are_kept_and_named(tmp_path, monkeypatch):
    """The file system fails from the 4th move on (gone read-only): nothing previous is lost."""
    folder = tmp_path / "out"
    old_folder(folder, NAMES)
    real = os.replace
    calls = []

    def replace(src, dst, **kwargs):
        calls.append((src, dst))
        if len(calls) >= 4:
            raise OSError(30, "Read-only file system")
        return real(src, dst, **kwargs)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(MeshFileError, match="previous files are kept in") as exc:
        with staged_outputs(folder) as stage:
            write_new(stage)
    monkeypatch.undo()
    kept = Path(str(exc.value).rsplit(" kept in ", 1)[1])
    assert kept.is_dir() and kept.parent.parent == folder
    for name in NAMES:  # every previous file is in the folder or in the one named
        old = f"old {name}\n".encode()
        assert [p for p in (folder / name, kept / name) if p.exists() and p.read_bytes() == old]
    for name, data in USER_FILES.items():
        assert (folder / name).read_bytes() == data


def test_ctrl_c_while_putting_files_back_waits_until_they_are_back(tmp_path, monkeypatch):
    """A second Ctrl-C during the roll-back does not cut it short: it is raised afterwards."""
    folder = tmp_path / "out"
    before = old_folder(folder, NAMES)
    real = os.replace
    calls = []

    def replace(src, dst, **kwargs):
        calls.append((src, dst))
        if len(calls) == 5:
            raise OSError(28, "No space left on device")
        if len(calls) == 6:  # the first move of the roll-back
            signal.raise_signal(signal.SIGINT)
        return real(src, dst, **kwargs)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        with staged_outputs(folder) as stage:
            write_new(stage)
    monkeypatch.undo()
    assert len(calls) > 6
    assert snapshot(folder) == before
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


# ---------------------------------------------------------------------------------------------
# Through the command line: a rerun of `segparam atlas` into the folder of an earlier atlas
# ---------------------------------------------------------------------------------------------


def test_an_interrupted_atlas_rerun_leaves_the_earlier_atlas(tmp_path, capsys, monkeypatch):
    source = tmp_path / "scan.obj"
    write_obj(source, *tri_grid(6, 5))
    out = tmp_path / "out"
    argv = ["atlas", str(source), "-o", str(out), "--resolution", "128", "--no-remesh", "--quiet"]
    assert main(argv) == 0
    (out / "notes.txt").write_bytes(USER_FILES["notes.txt"])
    for name in NAMES:  # an earlier atlas whose files differ from what this run writes
        with open(out / name, "ab") as fh:
            fh.write(b"\n# earlier run\n")
    before = snapshot(out)
    assert sorted(before) == sorted([*NAMES, "notes.txt"])

    def in_out(src: Path, dst: Path) -> bool:  # the swap's moves, not the writes in the stage
        return (src.parent == out) != (dst.parent == out)

    n_moves = 2 * len(NAMES)
    for k in (1, 2, len(NAMES), n_moves - 1, n_moves):
        fake = FailingReplace(k, KeyboardInterrupt(), only=in_out)
        monkeypatch.setattr(segparam.io.os, "replace", fake)
        code = main(argv)
        monkeypatch.undo()
        assert code == 130
        assert capsys.readouterr().err.splitlines() == ["segparam: interrupted"]
        assert fake.calls >= k
        assert snapshot(out) == before, f"Ctrl-C at move {k} of {n_moves}"
    assert main(argv) == 0  # and a rerun that goes through replaces them all
    after = snapshot(out)
    assert sorted(after) == sorted(before)
    assert after["notes.txt"] == before["notes.txt"]
    assert all(after[name] != before[name] for name in NAMES)
