"""Where the outputs go, and the options: checked before any work, one line, exit code 2.

Users found that a read-only output folder, an output path under a file, an input name too long
for the derived names, ``segparam atlas dir/scan.obj -o dir`` (which replaced ``scan.obj``), and
out-of-range options (``--seed -1``) all failed only after the whole pipeline had run, with a
traceback, or not at all. Each case is built here; the checks must stop it before any stage runs
(the stages are replaced by functions that fail the test), and the input must stay untouched.
"""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from meshes import tri_grid

import segparam.artifacts
import segparam.batch
import segparam.export
import segparam.io
import segparam.pipeline
from segparam import cli
from segparam.artifacts import stage_paths
from segparam.batch import assign_folders, expand_inputs, process_one
from segparam.cli import main
from segparam.errors import ConfigError, MeshFileError, SegparamError, SolverError
from segparam.export import write_obj
from segparam.io import (
    ATLAS_SUFFIXES,
    SUPPORTED_SUFFIXES,
    fit_name,
    load_mesh,
    mesh_stem,
    split_suffix,
)
from segparam.pipeline import MAX_RESOLUTION, MAX_SEED, PipelineConfig, build_atlas, chart_room

FAST = ["--resolution", "128", "--no-remesh", "--quiet"]
CFG = PipelineConfig().replace(pack={"resolution": 128}, remesh={"mode": "off"})


# ---------------------------------------------------------------------------------------------
# Helpers
# ---------------------------------------------------------------------------------------------


def wavy_grid(nx: int = 6, ny: int = 5) -> tuple[np.ndarray, np.ndarray]:
    V, F = tri_grid(nx, ny)
    V[:, 2] = 0.2 * np.sin(3 * V[:, 0])
    return V, F


def mesh_file(path: Path) -> Path:
    """A small wavy grid written to ``path`` (OBJ by us, other formats by trimesh)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    V, F = wavy_grid()
    if path.suffix == ".obj":
        write_obj(path, V, F)
    else:
        path.write_bytes(trimesh.Trimesh(V, F, process=False).export(file_type=path.suffix[1:]))
    return path


def files_in(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*")) if folder.exists() else []


def run(argv: list[str], capsys) -> tuple[int, list[str]]:
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.err.splitlines()


def assert_refused(code: int, lines: list[str], *words: str) -> None:
    """Exit code 2, one line ``segparam: error: ...`` holding every word."""
    assert code == 2, lines
    assert len(lines) == 1, lines
    assert lines[0].startswith("segparam: error: "), lines
    for word in words:
        assert word in lines[0], (word, lines)


@pytest.fixture
def no_work(monkeypatch):
    """Any stage (or the mesh reader) that runs fails the test: the checks come first."""

    def work(*args, **kwargs):
        raise AssertionError("work started although the output location or an option is bad")

    for module, name in [
        (segparam.io, "load_mesh"),
        (segparam.pipeline, "build_atlas"),
        (segparam.pipeline, "pack_atlas"),
        (segparam.pipeline, "clean"),
        (segparam.batch, "require_dask"),
    ]:
        monkeypatch.setattr(module, name, work)


@pytest.fixture
def read_only_folder(tmp_path, monkeypatch):
    """A folder nobody may write into. Root writes through mode bits, so for root (as in many
    containers) creating anything inside also fails the way the kernel would say it."""
    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o555)
    probe = folder / "probe"
    try:
        probe.mkdir()
    except OSError:
        pass
    else:  # root: refuse creation inside the folder as a read-only one would
        probe.rmdir()
        real_mkdir, real_open = os.mkdir, os.open

        def inside(path) -> bool:
            return Path(os.path.abspath(path)).parent == folder

        def mkdir(path, mode=0o777, *, dir_fd=None):
            if inside(path):
                raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
            return real_mkdir(path, mode, dir_fd=dir_fd)

        def open_(path, flags, mode=0o777, *, dir_fd=None):
            if flags & os.O_CREAT and inside(path):
                raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
            return real_open(path, flags, mode, dir_fd=dir_fd)

        monkeypatch.setattr(os, "mkdir", mkdir)
        monkeypatch.setattr(os, "open", open_)
    yield folder
    folder.chmod(0o755)


# ---------------------------------------------------------------------------------------------
# The input is never overwritten
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".obj", ".glb"])
def test_atlas_into_the_inputs_folder_never_overwrites_it(suffix, tmp_path, capsys, no_work):
    folder = tmp_path / "dir"
    source = mesh_file(folder / f"scan{suffix}")
    before = source.read_bytes()
    code, lines = run(["atlas", source, "-o", folder, *FAST], capsys)
    assert_refused(code, lines, source.name, "overwrite")
    assert source.read_bytes() == before
    assert files_in(folder) == [source.name]


def test_atlas_into_the_inputs_folder_under_another_stem_is_fine(tmp_path, capsys):
    folder = tmp_path / "dir"
    source = mesh_file(folder / "scan.ply")  # scan.obj, scan.glb ... are not the input
    before = source.read_bytes()
    code, lines = run(["atlas", source, "-o", folder, *FAST], capsys)
    assert code == 0 and lines == []
    assert source.read_bytes() == before
    assert (folder / "scan.obj").exists() and (folder / "report.json").exists()


def test_stage_commands_never_overwrite_their_input(tmp_path, capsys, monkeypatch):
    source = mesh_file(tmp_path / "scan.obj")
    assert main(["remesh", str(source), "-o", str(tmp_path / "r.npz"), "--quiet"]) == 0
    capsys.readouterr()
    artifact = tmp_path / "r.npz"
    for name in ("segment", "parameterize_charts", "load_mesh"):
        for module in (segparam.pipeline, segparam.io):
            if hasattr(module, name):
                monkeypatch.setattr(module, name, _no_stage)
    monkeypatch.setattr(segparam.artifacts, "load_stage", _no_stage)
    before = artifact.read_bytes()
    for argv in (
        ["segment", artifact, "-o", artifact],
        ["segment", artifact, "-o", tmp_path / "r"],  # .npz is added: the same file
        ["parameterize", artifact, "-o", artifact],
    ):
        code, lines = run([*argv, "--quiet"], capsys)
        assert_refused(code, lines, "r.npz", "overwrite")
    assert artifact.read_bytes() == before
    code, lines = run(["chart", source, "-o", source, "--quiet"], capsys)
    assert_refused(code, lines, "scan.obj", "overwrite")


def test_an_output_name_taken_by_a_folder_is_refused_before_any_work(tmp_path, capsys, no_work):
    source = mesh_file(tmp_path / "scan.obj")
    out = tmp_path / "out"
    (out / "scan_uv.png").mkdir(parents=True)
    code, lines = run(["atlas", source, "-o", out, *FAST], capsys)
    assert_refused(code, lines, "scan_uv.png", "is a folder")
    for target in (tmp_path, f"{tmp_path}/there/", "."):
        code, lines = run(["remesh", source, "-o", target, "--quiet"], capsys)
        assert_refused(code, lines, "is a folder")
    with pytest.raises(MeshFileError, match="is a folder"):
        stage_paths(tmp_path)


# ---------------------------------------------------------------------------------------------
# Read-only folders, a file in the way: before any work
# ---------------------------------------------------------------------------------------------


def _stage_input(tmp_path: Path) -> Path:
    """A parameterize artifact of the small grid (input of ``segparam pack``)."""
    source = mesh_file(tmp_path / "inputs" / "grid.obj")
    d = tmp_path / "inputs"
    assert main(["remesh", str(source), "-o", str(d / "r"), "--remesh", "off", "--quiet"]) == 0
    assert main(["segment", str(d / "r.npz"), "-o", str(d / "s"), "--quiet"]) == 0
    assert main(["parameterize", str(d / "s.npz"), "-o", str(d / "p"), "--quiet"]) == 0
    return d / "p.npz"


def _commands(source: Path, artifact: Path, out: Path) -> dict[str, list]:
    return {
        "atlas": ["atlas", source, "-o", out, *FAST],
        "atlas folder to create": ["atlas", source, "-o", out / "new" / "folder", *FAST],
        "remesh": ["remesh", source, "-o", out / "r.npz", "--quiet"],
        "segment": ["segment", artifact, "-o", out / "s.npz", "--quiet"],
        "pack": ["pack", artifact, "-o", out / "atlas", "--quiet"],
        "chart": ["chart", source, "-o", out / "chart.obj", "--quiet"],
    }


COMMANDS = ["atlas", "atlas folder to create", "remesh", "segment", "pack", "chart"]


@pytest.mark.parametrize("command", COMMANDS)
def test_read_only_output_folder_is_refused_before_any_work(
    command, tmp_path, capsys, monkeypatch, read_only_folder
):
    artifact = _stage_input(tmp_path)
    source = tmp_path / "inputs" / "grid.obj"
    monkeypatch.setattr(segparam.pipeline, "build_atlas", _no_stage)
    monkeypatch.setattr(segparam.pipeline, "pack_atlas", _no_stage)
    monkeypatch.setattr(segparam.io, "load_mesh", _no_stage)
    monkeypatch.setattr(segparam.artifacts, "load_stage", _no_stage)
    code, lines = run(_commands(source, artifact, read_only_folder)[command], capsys)
    assert_refused(code, lines, str(read_only_folder), "cannot write")
    assert files_in(read_only_folder) == []


@pytest.mark.parametrize("command", COMMANDS)
def test_output_under_a_file_is_refused_before_any_work(command, tmp_path, capsys, monkeypatch):
    artifact = _stage_input(tmp_path)
    source = tmp_path / "inputs" / "grid.obj"
    blocker = tmp_path / "notes.txt"
    blocker.write_text("keep me")
    monkeypatch.setattr(segparam.pipeline, "build_atlas", _no_stage)
    monkeypatch.setattr(segparam.pipeline, "pack_atlas", _no_stage)
    monkeypatch.setattr(segparam.io, "load_mesh", _no_stage)
    monkeypatch.setattr(segparam.artifacts, "load_stage", _no_stage)
    code, lines = run(_commands(source, artifact, blocker)[command], capsys)
    assert_refused(code, lines, "notes.txt", "is a file")
    assert blocker.read_text() == "keep me"


def _no_stage(*args, **kwargs):
    raise AssertionError("a stage ran although the output location is bad")


def test_batch_checks_its_output_folder_before_dask_and_any_mesh(
    tmp_path, capsys, no_work, read_only_folder
):
    source = mesh_file(tmp_path / "inputs" / "grid.obj")
    blocker = tmp_path / "notes.txt"
    blocker.write_text("keep me")
    code, lines = run(["batch", source, "-o", blocker / "out", "--quiet"], capsys)
    assert_refused(code, lines, "notes.txt", "is a file")
    code, lines = run(["batch", source, "-o", read_only_folder, "--quiet"], capsys)
    assert_refused(code, lines, "read-only", "cannot write")
    with pytest.raises(MeshFileError, match="is a file"):
        segparam.batch.run_batch([source], blocker / "out")


def test_batch_task_with_a_file_in_place_of_its_folder_fails_alone(tmp_path, monkeypatch):
    source = mesh_file(tmp_path / "grid.obj")
    folder = tmp_path / "out" / "grid"
    folder.parent.mkdir()
    folder.write_text("not a folder")
    monkeypatch.setattr(segparam.pipeline, "build_atlas", _no_stage)
    row = process_one(source, folder, CFG.as_dict(), 0)
    assert row["status"] == "failed" and "is a file, not a folder" in row["reason"]


# ---------------------------------------------------------------------------------------------
# Names too long for the file system: shortened, unique and readable
# ---------------------------------------------------------------------------------------------


def test_fit_name_keeps_short_names_and_shortens_long_ones_uniquely():
    assert fit_name("scan", ".obj") == "scan.obj"
    a, b = "x" * 300 + "left", "x" * 300 + "right"
    na, nb = fit_name(a, "_checker.png"), fit_name(b, "_checker.png")
    assert na != nb
    for name in (na, nb):
        assert len(name.encode()) == 255 and name.startswith("x" * 200)
        assert name.endswith("_checker.png") and "~" in name
    assert fit_name(a, "_checker.png") == na  # deterministic
    # Multi-byte characters are never cut in half.
    wide = fit_name("é" * 200, ".obj")
    assert len(wide.encode()) <= 255 and wide.encode().decode() == wide
    assert fit_name("a" * 300, limit=40) == fit_name("a" * 300, limit=40)
    assert len(fit_name("a" * 300, "-2", limit=40).encode()) == 40


@pytest.mark.parametrize("stem", ["x" * 246, "é" * 123], ids=["250 characters", "250 bytes"])
def test_a_250_character_input_name_gets_shortened_output_names(stem, tmp_path, capsys):
    source = mesh_file(tmp_path / f"{stem}.obj")  # <stem>_checker.png would be 258 bytes
    out = tmp_path / "out"
    code, lines = run(["atlas", source, "-o", out, *FAST], capsys)
    assert code == 0 and lines == []
    names = files_in(out)
    assert len(names) == 8 and "report.json" in names
    (obj,) = [name for name in names if name.endswith(".obj")]
    short = obj[: -len(".obj")]
    assert short[-9] == "~" and int(short[-8:], 16) >= 0
    assert stem.startswith(short[:-9]) and len(short[:-9]) >= 100
    assert sorted(short + suffix for suffix in ATLAS_SUFFIXES) == sorted(
        set(names) - {"report.json"}
    )
    assert all(len(name.encode()) <= 255 for name in names)
    V, F = load_mesh(out / f"{short}.obj")
    assert len(F) == len(wavy_grid()[1])
    text = (out / f"{short}.obj").read_text(encoding="utf-8")
    assert f"mtllib {short}.mtl" in text  # the OBJ points at its real MTL


def test_a_long_input_name_with_the_default_output_folders(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    source = mesh_file(tmp_path / "in" / f"{'y' * 250}.obj")
    code, lines = run(["atlas", source, *FAST], capsys)  # default folder: <stem>_atlas
    assert code == 0 and lines == []
    (folder,) = [p for p in tmp_path.iterdir() if p.name.endswith("_atlas")]
    assert len(folder.name.encode()) <= 255 and folder.name.startswith("y" * 200)
    assert len(files_in(folder)) == 8
    code, lines = run(["chart", source, "--quiet"], capsys)  # default <stem>_uv.obj
    assert code == 0 and lines == []
    made = sorted(p.name for p in tmp_path.iterdir() if p.is_file())
    assert len(made) == 2 and all(len(n.encode()) <= 255 for n in made)


def test_an_explicit_output_file_name_too_long_is_refused(tmp_path, capsys, no_work):
    source = mesh_file(tmp_path / "grid.obj")
    code, lines = run(["remesh", source, "-o", tmp_path / ("r" * 300 + ".npz")], capsys)
    assert_refused(code, lines, "bytes long")
    code, lines = run(["atlas", source, "-o", tmp_path / ("o" * 300), *FAST], capsys)
    assert_refused(code, lines, "bytes long")
    assert files_in(tmp_path) == ["grid.obj"]


def test_batch_folders_of_long_stems_fit_and_stay_distinct(tmp_path):
    paths = [
        tmp_path / "a" / f"{'z' * 260}one.obj",
        tmp_path / "b" / f"{'z' * 260}two.obj",
        tmp_path / "c" / f"{'z' * 260}one.obj",
    ]
    names = assign_folders(paths, limit=255)
    assert len(set(names)) == 3 and all(len(n.encode()) <= 255 for n in names)
    assert names[2].endswith("-2") and names[0].startswith("z" * 200)
    assert assign_folders(paths[:1]) == names[:1]


# ---------------------------------------------------------------------------------------------
# Atlas.save: the package's own error, one line, no file
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_atlas():
    return build_atlas(*wavy_grid(), CFG)


def test_atlas_save_raises_segparam_errors(small_atlas, tmp_path, monkeypatch):
    blocker = tmp_path / "notes.txt"
    blocker.write_text("keep me")
    with pytest.raises(MeshFileError, match="is a file") as info:
        small_atlas.save(blocker / "out", stem="grid")
    assert "\n" not in str(info.value) and isinstance(info.value, SegparamError)
    with pytest.raises(MeshFileError, match="is a file, not a folder"):
        small_atlas.save(blocker, stem="grid")
    with pytest.raises(MeshFileError, match="not a file name"):
        small_atlas.save(tmp_path / "out", stem="a/b")
    assert blocker.read_text() == "keep me"

    def disk_full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(segparam.export, "render_uv_layout", disk_full)
    out = tmp_path / "out"
    with pytest.raises(MeshFileError, match="No space left on device"):
        small_atlas.save(out, stem="grid")
    assert files_in(out) == []


def test_atlas_save_into_a_read_only_folder(small_atlas, read_only_folder):
    with pytest.raises(MeshFileError, match="cannot write there"):
        small_atlas.save(read_only_folder, stem="grid")
    assert files_in(read_only_folder) == []


def test_atlas_save_shortens_a_long_stem(small_atlas, tmp_path):
    written = small_atlas.save(tmp_path, stem="s" * 300)
    assert len(written) == 8 and all(p.exists() for p in written)
    assert all(len(p.name.encode()) <= 255 for p in written)


# ---------------------------------------------------------------------------------------------
# Options: range-checked at the edge, one line, exit code 2
# ---------------------------------------------------------------------------------------------

BAD_OPTIONS = [
    (["--seed", "-1"], "--seed"),
    (["--seed", "4294967296"], "--seed"),
    (["--seed", "1.5"], "--seed"),
    (["--resolution", "0"], "--resolution"),
    (["--resolution", "100000"], "--resolution"),
    (["--resolution", "big"], "--resolution"),
    (["--padding", "-1"], "--padding"),
    (["--max-charts", "0"], "--max-charts"),
    (["--max-charts", "-5"], "--max-charts"),
    (["--max-distortion", "0.5"], "--max-distortion"),
    (["--max-distortion", "nan"], "--max-distortion"),
    (["--max-distortion", "inf"], "--max-distortion"),
    (["--remesh", "sometimes"], "--remesh"),
]


@pytest.mark.parametrize("command", ["atlas", "batch"])
@pytest.mark.parametrize(
    "option, flag", BAD_OPTIONS, ids=lambda v: " ".join(v) if isinstance(v, list) else None
)
def test_bad_option_is_one_line_exit_2(command, option, flag, tmp_path, capsys, no_work):
    source = mesh_file(tmp_path / "grid.obj")
    code, lines = run([command, source, "-o", tmp_path / "out", *option], capsys)
    assert_refused(code, lines, f"argument {flag}")
    assert "Traceback" not in "\n".join(lines)
    assert files_in(tmp_path) == ["grid.obj"]


@pytest.mark.parametrize(
    "argv, words",
    [
        (["chart", "{mesh}", "--seed", "-1"], "argument --seed"),
        (["remesh", "{mesh}", "-o", "{out}", "--seed", "4294967296"], "argument --seed"),
        (["segment", "{mesh}", "-o", "{out}", "--seed", "-1"], "argument --seed"),
        (["parameterize", "{mesh}", "-o", "{out}", "--max-distortion", "0"], "--max-distortion"),
        (["pack", "{mesh}", "-o", "{out}", "--resolution", "-3"], "argument --resolution"),
        (["pack", "{mesh}", "-o", "{out}", "--padding", "-3"], "argument --padding"),
        (["batch", "{mesh}", "-o", "{out}", "--workers", "0"], "argument --workers"),
        (["atlas", "{mesh}", "--bogus"], "unrecognized arguments: --bogus"),
        (["segment", "{mesh}"], "required: -o/--output"),
    ],
    ids=lambda v: " ".join(a for a in v if "{" not in a) if isinstance(v, list) else "",
)
def test_bad_option_of_every_command_is_one_line_exit_2(argv, words, tmp_path, capsys, no_work):
    mesh = mesh_file(tmp_path / "grid.obj")
    code, lines = run([a.format(mesh=mesh, out=tmp_path / "out") for a in argv], capsys)
    assert_refused(code, lines, words)
    assert files_in(tmp_path) == ["grid.obj"]


def test_seed_out_of_range_in_a_fresh_process_has_no_traceback(tmp_path):
    source = mesh_file(tmp_path / "grid.obj")
    cmd = [sys.executable, "-m", "segparam.cli", "atlas", str(source), "--seed", "-1"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.splitlines() == [
        "segparam: error: argument --seed: must be from 0 to 4294967295, got -1"
    ]


def test_the_cli_limits_are_the_librarys():
    assert (cli._MAX_SEED, cli._MAX_RESOLUTION) == (MAX_SEED, MAX_RESOLUTION)
    for good in ("0", "4294967295"):
        assert cli.SEED(good) == int(good)


@pytest.mark.parametrize("seed", [-1, 2**32, 1.5, "3", True, None])
def test_build_atlas_rejects_a_bad_seed_before_any_work(seed, monkeypatch):
    monkeypatch.setattr(segparam.pipeline, "clean", _no_stage)
    with pytest.raises(ConfigError, match="seed must be an integer"):
        build_atlas(*wavy_grid(), CFG, seed=seed)


def test_resolution_above_the_limit_is_a_config_error():
    with pytest.raises(ConfigError, match="limit"):
        PipelineConfig().replace(pack={"resolution": MAX_RESOLUTION + 1})


# ---------------------------------------------------------------------------------------------
# Too many charts for the texture: refused as soon as it is known, naming the file
# ---------------------------------------------------------------------------------------------


def test_chart_room_is_the_block_bound():
    assert chart_room(32, 2) == 100  # ceil(28 / 3) ** 2
    assert chart_room(1024, 2) == 340**2
    assert chart_room(7, 0) == 49
    assert chart_room(5, 2) == 1 and chart_room(4, 2) == 0


def _pieces(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` separate tetrahedra in a row: at least ``n`` charts."""
    Vt = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    Ft = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    V = np.vstack([Vt + [3.0 * k, 0, 0] for k in range(n)])
    F = np.vstack([Ft + 4 * k for k in range(n)])
    return V, F.astype(np.int64)


def test_too_many_pieces_for_the_resolution_are_refused_before_segmenting(
    tmp_path, capsys, monkeypatch
):
    source = tmp_path / "parts.obj"
    write_obj(source, *_pieces(200))
    monkeypatch.setattr(segparam.pipeline, "segment", _no_stage)
    out = tmp_path / "out"
    code, lines = run(["atlas", source, "-o", out, "--resolution", "32", "--quiet"], capsys)
    assert_refused(code, lines, str(source), "200 connected pieces", "room for at most 100")
    assert files_in(out) == []


def test_too_many_charts_from_the_segmentation_are_refused_before_parameterizing(monkeypatch):
    monkeypatch.setattr(segparam.pipeline, "parameterize_charts", _no_stage)
    cfg = CFG.replace(segment={"n_charts": 12}, pack={"resolution": 16, "padding": 3})
    with pytest.raises(ConfigError, match="segmentation made 12 charts.*at most 9"):
        build_atlas(*wavy_grid(12, 10), cfg)


def test_a_packing_failure_names_the_input_file(tmp_path, capsys, monkeypatch):
    def cannot_fit(*args, **kwargs):
        raise SolverError("40 charts do not fit a 64x64 texture with padding 2 at any scale")

    monkeypatch.setattr(segparam.pipeline, "pack_charts", cannot_fit)
    source = mesh_file(tmp_path / "scan.obj")
    code, lines = run(["atlas", source, "-o", tmp_path / "out", *FAST], capsys)
    assert_refused(code, lines, f"{source}: 40 charts do not fit")
    artifact = _stage_input(tmp_path)
    code, lines = run(["pack", artifact, "-o", tmp_path / "packed", "--quiet"], capsys)
    assert_refused(code, lines, f"{artifact}: 40 charts do not fit")


def test_a_batch_row_names_the_reason_of_a_refusal(tmp_path):
    source = tmp_path / "parts.obj"
    write_obj(source, *_pieces(30))
    cfg = CFG.replace(pack={"resolution": 12, "padding": 1})  # room for 25
    row = process_one(source, tmp_path / "out" / "parts", cfg.as_dict(), 0)
    assert row["status"] == "failed" and "30 connected pieces" in row["reason"]
    report = tmp_path / "out" / "parts" / "report.json"
    assert not report.exists()
    assert json.dumps(row)  # a plain row


@pytest.mark.parametrize(
    "name, stem, suffix",
    [
        ("lh.pial.gii.gz", "lh.pial", ".gii.gz"),
        ("lh.pial.GII.GZ", "lh.pial", ".gii.gz"),
        ("lh.pial.Gii", "lh.pial", ".gii"),
        ("scan.OBJ", "scan", ".obj"),
        ("archive.tar.gz", "archive.tar", ".gz"),
        ("noext", "noext", ""),
    ],
)
def test_split_suffix_knows_gii_gz_in_any_case(name, stem, suffix, tmp_path):
    assert split_suffix(tmp_path / name) == (stem, suffix)
    assert mesh_stem(name) == stem
    if suffix in SUPPORTED_SUFFIXES:  # the batch takes it from a folder, whatever its case
        write_obj(tmp_path / "m.obj", *tri_grid(2, 2))
        (tmp_path / "m.obj").rename(tmp_path / name)
        assert expand_inputs([tmp_path]) == [tmp_path / name]
