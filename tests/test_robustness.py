"""Robustness of the whole tool: bad files, awkward meshes, nothing lost, determinism, limits.

The requirement: segparam never crashes with a traceback, never writes half a result, never drops a
face silently, and gives the same result twice. Bad input is one line on stderr and exit code 2
(``segparam.cli.main``), or a :class:`~segparam.errors.SegparamError` from the Python API.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from meshes import plate_with_holes, rigid, tri_grid

import segparam.export
import segparam.io
import segparam.pipeline
from segparam.clean import clean
from segparam.cli import main
from segparam.errors import InvalidMeshError, MeshFileError, SegparamError
from segparam.export import write_obj
from segparam.io import load_mesh
from segparam.pipeline import PipelineConfig, build_atlas
from segparam.quality import signed_areas
from segparam.segment import segment
from segparam.split import parameterize_charts

CFG = PipelineConfig().replace(pack={"resolution": 256})
FAST = ["--resolution", "256", "--quiet"]
PROPERTY = settings(
    max_examples=8,
    deadline=None,
    derandomize=True,  # CI sees the same examples every run
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


# ---------------------------------------------------------------------------------------------
# Helpers
# ---------------------------------------------------------------------------------------------


def wavy_grid(nx: int = 6, ny: int = 5) -> tuple[np.ndarray, np.ndarray]:
    V, F = tri_grid(nx, ny)
    V[:, 2] = 0.2 * np.sin(3 * V[:, 0])
    return V, F


def torus(major: int = 12, minor: int = 8) -> tuple[np.ndarray, np.ndarray]:
    t = trimesh.creation.torus(1.0, 0.4, major_sections=major, minor_sections=minor)
    return np.asarray(t.vertices, dtype=np.float64), np.asarray(t.faces, dtype=np.int64)


def icosphere(subdivisions: int = 1) -> tuple[np.ndarray, np.ndarray]:
    s = trimesh.creation.icosphere(subdivisions)
    return np.asarray(s.vertices, dtype=np.float64), np.asarray(s.faces, dtype=np.int64)


def export(path: Path, V: np.ndarray, F: np.ndarray, **kwargs) -> Path:
    """Write a mesh with trimesh (binary PLY and STL by default)."""
    mesh = trimesh.Trimesh(V, F, process=False)
    data = mesh.export(file_type=path.suffix[1:], **kwargs)
    path.write_bytes(data.encode() if isinstance(data, str) else data)
    return path


def messy_mesh() -> tuple[np.ndarray, np.ndarray, dict[str, set[int]]]:
    """A grid with a fin, a bowtie, flipped, duplicated and degenerate faces, a second part.

    Returns V, F and the input faces that must be removed, by reason.
    """
    V, F = wavy_grid(6, 5)
    n = len(V)
    a, b = F[7, 0], F[7, 1]  # an interior edge of the grid gets a third face: a fin
    corner = int(np.argmin(V[:, 0] + V[:, 1]))  # a triangle touching only this vertex: a bowtie
    Vs, Fs = icosphere(0)
    V = np.vstack([V, [[V[a, 0], V[a, 1], 1.0], [-1.0, -1.0, 0.0], [-1.0, -0.5, 0.0]], Vs + 3])
    F = F.copy()
    F[::3] = F[::3, ::-1]  # inconsistent winding
    good = np.vstack([F, [[a, b, n], [corner, n + 1, n + 2]], Fs + n + 3])
    m = len(good)
    bad = np.array([good[4], good[9, ::-1], [0, 0, 1]])  # duplicate, reversed duplicate, repeat
    k = len(V)
    V = np.vstack([V, [[-2.0, -2, 0], [-1.5, -2, 0], [-1, -2, 0]]])  # on a line (exact in text)
    F = np.vstack([good, bad, [[k, k + 2, k + 1]]]).astype(np.int64)
    expected = {
        "duplicate face": {m, m + 1},
        "repeated vertex": {m + 2},
        "zero area": {m + 3},
    }
    return V, F, expected


def assert_valid_atlas(atlas) -> None:
    """Every face has uvs in [0, 1]^2, none is flipped, uv rows point at the right vertices."""
    assert len(atlas.F) > 0
    assert atlas.uv_F.shape == atlas.F.shape
    assert np.isfinite(atlas.uv).all()
    assert atlas.uv.min() >= 0.0 and atlas.uv.max() <= 1.0
    assert (signed_areas(atlas.uv, atlas.uv_F) > 0).all()
    assert np.array_equal(atlas.uv_vertex[atlas.uv_F], atlas.F)


def assert_nothing_lost(atlas, m: int) -> None:
    """Every input face is kept or removed with a reason, exactly once."""
    c = atlas.cleaning
    assert c.input_faces == m
    every = np.concatenate([c.face_index, c.removed_faces])
    assert np.array_equal(np.sort(every), np.arange(m))
    assert len(c.removed_reasons) == len(c.removed_faces)
    assert all(c.removed_reasons)  # each has a reason


def files_in(folder: Path) -> list[str]:
    """Everything in a folder, hidden entries too ([] if it does not exist)."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*")) if folder.exists() else []


def run_atlas(path: Path, out: Path, capsys, *extra: str) -> tuple[int, list[str]]:
    code = main(["atlas", str(path), "-o", str(out), *FAST, *extra])
    captured = capsys.readouterr()
    assert captured.out == ""
    return code, captured.err.splitlines()


def assert_one_line_error(code: int, lines: list[str], path: Path, out: Path) -> None:
    assert code == 2, lines
    assert len(lines) == 1, lines
    assert lines[0].startswith("segparam: error: "), lines
    assert path.name in lines[0], lines
    assert files_in(out) == []


# ---------------------------------------------------------------------------------------------
# Bad files: exit code 2, one line naming the file and the problem, no output
# ---------------------------------------------------------------------------------------------

PLY_HEADER = (
    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
    "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
)


def _truncated(path: Path, keep: float) -> Path:
    data = export(path, *wavy_grid()).read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    return path


def _point_cloud_ply(path: Path) -> Path:
    path.write_bytes(trimesh.PointCloud(wavy_grid()[0]).export(file_type="ply"))
    return path


def _obj(d: Path, name: str, text: str) -> Path:
    return _write(d / name, text)


def _ply(d: Path, name: str, body: str) -> Path:
    return _write(d / name, PLY_HEADER + body)


TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
TRI_PLY = "0 0 0\n1 0 0\n0 1 0\n"

BAD_FILES = {
    # name: (make(tmp_path) -> path, what the message must say)
    "empty": (lambda d: _write(d / "empty.obj", b""), "empty"),
    "garbage obj": (lambda d: _write(d / "garbage.obj", _noise(600)), "not a readable OBJ"),
    "latin-1 obj": (lambda d: _write(d / "latin.obj", "# caf\xe9\n".encode("latin-1")), "no faces"),
    "garbage ply": (lambda d: _write(d / "garbage.ply", _noise(600)), "PLY"),
    "garbage stl": (lambda d: _write(d / "garbage.stl", _noise(600)), "STL"),
    "garbage off": (lambda d: _write(d / "garbage.off", _noise(600)), "not a readable OFF"),
    "truncated stl": (lambda d: _truncated(d / "cut.stl", 0.5), "truncated"),
    "truncated stl header": (lambda d: _truncated(d / "cut.stl", 0.02), "truncated"),
    "truncated ply": (lambda d: _truncated(d / "cut.ply", 0.6), "PLY"),
    "truncated ply header": (lambda d: _truncated(d / "cut.ply", 0.05), "PLY"),
    "text obj": (lambda d: _write(d / "notes.obj", b"hello\nnot a mesh\n"), "no faces"),
    "text stl": (lambda d: _write(d / "notes.stl", b"hello\nnot a mesh\n"), "no faces"),
    "text ply": (lambda d: _write(d / "notes.ply", b"hello\nnot a mesh\n"), "PLY"),
    "unsupported": (lambda d: _write(d / "mesh.xyz", b"0 0 0\n"), "unsupported format .xyz"),
    "no extension": (lambda d: _write(d / "mesh", b"v 0 0 0\n"), "unsupported format"),
    "missing": (lambda d: d / "missing.obj", "no such file"),
    "directory": (lambda d: _mkdir(d / "folder.obj"), "directory"),
    "nan": (lambda d: _obj(d, "nan.obj", "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n"), "NaN"),
    "inf": (lambda d: _obj(d, "inf.obj", "v 0 0 0\nv 1 0 0\nv 0 -inf 0\nf 1 2 3\n"), "inf"),
    "nan ply": (lambda d: _ply(d, "nan.ply", "0 0 0\n1 0 nan\n0 1 0\n3 0 1 2\n"), "NaN"),
    "index obj": (lambda d: _obj(d, "index.obj", TRI + "f 1 2 7\n"), "out of"),
    "zero index obj": (
        lambda d: _obj(d, "zero.obj", TRI + "f 0 1 2\n"),
        "line 4 uses vertex index 0",
    ),
    "index ply": (lambda d: _ply(d, "index.ply", TRI_PLY + "3 0 1 9\n"), "indices"),
    "negative index ply": (lambda d: _ply(d, "neg.ply", TRI_PLY + "3 0 1 -4\n"), "indices"),
    "index off": (
        lambda d: _write(d / "index.off", "OFF\n3 1 0\n" + TRI_PLY + "3 0 1 5\n"),
        "range",
    ),
    "points obj": (lambda d: _obj(d, "points.obj", TRI), "no faces"),
    "point cloud ply": (lambda d: _point_cloud_ply(d / "cloud.ply"), "no faces"),
}


def _write(path: Path, data: bytes | str) -> Path:
    path.write_bytes(data.encode() if isinstance(data, str) else data)
    return path


def _mkdir(path: Path) -> Path:
    path.mkdir()
    return path


def _noise(n: int) -> bytes:
    return np.random.default_rng(n).bytes(n)


@pytest.mark.parametrize("case", list(BAD_FILES))
def test_bad_file_is_one_line_exit_2_and_no_output(case, tmp_path, capsys):
    make, what = BAD_FILES[case]
    path = make(tmp_path)
    out = tmp_path / "out"
    code, lines = run_atlas(path, out, capsys)
    assert_one_line_error(code, lines, path, out)
    assert what.lower() in lines[0].lower(), lines
    with pytest.raises(MeshFileError, match=path.name):
        load_mesh(path)


def test_unreadable_file(tmp_path, capsys):
    path = export(tmp_path / "locked.stl", *wavy_grid())
    path.chmod(0)
    try:
        if os.access(path, os.R_OK):
            pytest.skip("running as root: the file stays readable")
        out = tmp_path / "out"
        code, lines = run_atlas(path, out, capsys)
        assert_one_line_error(code, lines, path, out)
        assert "cannot read" in lines[0]
    finally:
        path.chmod(0o644)


def test_only_degenerate_faces_is_one_line_exit_2(tmp_path, capsys):
    path = _write(tmp_path / "flat.obj", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n")
    out = tmp_path / "out"
    code, lines = run_atlas(path, out, capsys)
    assert code == 2 and len(lines) == 1 and files_in(out) == []
    assert "1 repeated vertex, 1 zero area" in lines[0]
    with pytest.raises(InvalidMeshError, match="no faces left"):
        build_atlas(*load_mesh(path), CFG)


def test_only_degenerate_faces_message_names_the_file(tmp_path, capsys):
    path = _write(tmp_path / "flat.obj", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n")
    code, lines = run_atlas(path, tmp_path / "out", capsys)
    assert code == 2 and path.name in lines[0]


def test_output_path_is_a_file(tmp_path, capsys):
    path = export(tmp_path / "grid.ply", *wavy_grid())
    out = _write(tmp_path / "taken", b"keep me")
    code, lines = run_atlas(path, out, capsys)
    assert code == 2 and len(lines) == 1 and "taken" in lines[0]
    assert out.read_bytes() == b"keep me"


def test_bad_file_in_a_fresh_process_has_no_traceback(tmp_path):
    path = _truncated(tmp_path / "cut mesh.stl", 0.5)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "segparam.cli", "atlas", str(path), "-o", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert len(proc.stderr.splitlines()) == 1 and path.name in proc.stderr
    assert proc.stdout == "" and files_in(out) == []


# ---------------------------------------------------------------------------------------------
# Python API: SegparamError subclasses, never a bare IndexError, AssertionError...
# ---------------------------------------------------------------------------------------------

_V3 = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
BAD_ARRAYS = {
    "nan": (np.where(np.eye(3, dtype=bool), np.nan, _V3), [[0, 1, 2]]),
    "inf": (np.where(np.eye(3, dtype=bool), -np.inf, _V3), [[0, 1, 2]]),
    "index too large": (_V3, [[0, 1, 3]]),
    "negative index": (_V3, [[0, 1, -1]]),
    "huge index": (_V3, [[0, 1, 2**62]]),
    "no faces": (_V3, np.zeros((0, 3), dtype=np.int64)),
    "no vertices": (np.zeros((0, 3)), [[0, 1, 2]]),
    "2-d vertices": (_V3[:, :2], [[0, 1, 2]]),
    "quad faces": (_V3, [[0, 1, 2, 0]]),
    "flat face list": (_V3, [0, 1, 2]),
    "fractional indices": (_V3, [[0, 1, 1.5]]),
    "boolean faces": (_V3, [[True, False, True]]),
    "text vertices": ([["a", "b", "c"]] * 3, [[0, 1, 2]]),
    "None": (None, None),
    "only degenerate": (_V3 * [1, 0, 0], [[0, 1, 2], [0, 0, 1]]),
}


@pytest.mark.parametrize("case", list(BAD_ARRAYS))
def test_build_atlas_raises_invalid_mesh_error(case):
    V, F = BAD_ARRAYS[case]
    with pytest.raises(InvalidMeshError):
        build_atlas(V, F, CFG)


def test_ragged_faces_raise_invalid_mesh_error():
    with pytest.raises(InvalidMeshError):
        build_atlas(_V3, [[0, 1, 2], [0, 1]], CFG)


@pytest.mark.parametrize(
    "stage",
    [
        pytest.param(
            lambda V, F: segment(V, F),
            id="segment",
        ),
        pytest.param(
            lambda V, F: parameterize_charts(V, F, np.zeros(len(F), dtype=np.int64)),
            id="parameterize_charts",
        ),
        pytest.param(lambda V, F: clean(V, F), id="clean"),
    ],
)
def test_public_stages_reject_out_of_range_indices(stage):
    with pytest.raises(InvalidMeshError):
        stage(_V3, np.array([[0, 1, 3]]))


# ---------------------------------------------------------------------------------------------
# Awkward but valid meshes: a valid atlas
# ---------------------------------------------------------------------------------------------


def _fin() -> tuple[np.ndarray, np.ndarray]:
    V, F = wavy_grid()
    a, b = F[7, 0], F[7, 1]
    return np.vstack([V, [V[a, 0], V[a, 1], 1.0]]), np.vstack([F, [[a, b, len(V)]]])


def _bowtie() -> tuple[np.ndarray, np.ndarray]:
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0.3], [0, -1, 0]])
    return V, np.array([[0, 1, 2], [0, 3, 4]])


def _components() -> tuple[np.ndarray, np.ndarray]:
    Vs, Fs = icosphere(0)
    Vg, Fg = wavy_grid()
    return np.vstack([Vg, Vs + 3]), np.vstack([Fg, Fs + len(Vg)])


def _duplicated() -> tuple[np.ndarray, np.ndarray]:
    V, F = wavy_grid()
    return V, np.vstack([F, F[:5], F[5:8, ::-1]])


AWKWARD = {
    "single triangle": lambda: (_V3, np.array([[0, 1, 2]])),
    "closed sphere": lambda: icosphere(1),
    "torus": lambda: torus(),
    "genus 2": lambda: plate_with_holes(12, 6, holes=((2, 4, 2, 4), (7, 9, 2, 4))),
    "components": _components,
    "fin": _fin,
    "bowtie": _bowtie,
    "duplicated faces": _duplicated,
    "large coordinates": lambda: (wavy_grid()[0] * 1e12, wavy_grid()[1]),
    "large offset": lambda: (wavy_grid()[0] * 1e3 + 1e12, wavy_grid()[1]),
    "small coordinates": lambda: (wavy_grid()[0] * 1e-9, wavy_grid()[1]),
    "small offset": lambda: (wavy_grid()[0] * 1e-9 + 1e-3, wavy_grid()[1]),
}


@pytest.mark.parametrize("case", list(AWKWARD))
def test_awkward_mesh_gives_a_valid_atlas(case):
    V, F = AWKWARD[case]()
    atlas = build_atlas(V, F, CFG)
    assert_valid_atlas(atlas)
    assert_nothing_lost(atlas, len(F))
    if atlas.remeshing is not None and not atlas.remeshing.remeshed:
        # nothing is dropped apart from exact duplicates
        kept = set(atlas.cleaning.removed_reasons) <= {"duplicate face"}
        assert kept and len(atlas.F) == len(F) - len(atlas.cleaning.removed_faces)


def test_coordinates_beyond_float64_geometry_are_an_error():
    V, F = wavy_grid()
    for call in (clean, lambda V, F: build_atlas(V, F, CFG)):
        with pytest.raises(InvalidMeshError, match="overflow"):
            call(V * 1e200, F)


def test_coordinates_of_1e100_give_an_atlas():
    V, F = wavy_grid()
    assert_valid_atlas(build_atlas(V * 1e100, F, CFG))  # every stage works in the unit frame


def test_parser_warnings_stay_off_stderr(tmp_path, capsys):
    """trimesh logs a traceback for an unreadable STL normal; the mesh itself is fine."""
    V, F = wavy_grid()
    text = trimesh.Trimesh(V, F, process=False).export(file_type="stl_ascii")
    path = _write(tmp_path / "odd normal.stl", text.replace("facet normal", "facet normal x", 1))
    code, lines = run_atlas(path, tmp_path / "out", capsys)
    assert code == 0 and lines == []


def test_non_manifold_cases_are_split():
    assert build_atlas(*_fin(), CFG).cleaning.split_edges == 1
    assert build_atlas(*_bowtie(), CFG).cleaning.split_vertices == 1


def test_quads_and_pentagons_in_an_oddly_named_file(tmp_path, capsys):
    path = _write(
        tmp_path / "quad and pentagon é ü 日本.obj",
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0.2\nv 2.5 0.5 0.3\nv 2 1 0.2\n"
        "f 1 2 3 4\nf 2 5 6 7 3\n",
    )
    V, F = load_mesh(path)
    assert len(F) == 2 + 3
    out = tmp_path / "out put ø"
    code, lines = run_atlas(path, out, capsys)
    assert code == 0 and lines == []
    stem = path.stem
    assert f"{stem}.obj" in files_in(out) and not any(n.startswith(".") for n in files_in(out))
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    assert report["input"]["faces"] == 5 and report["atlas"]["flipped_triangles"] == 0
    V2, F2 = load_mesh(out / f"{stem}.obj")
    assert len(F2) == report["atlas"]["faces"]


@pytest.mark.parametrize("suffix", [".stl", ".ply", ".off", ".glb"])
def test_every_format_round_trips_through_the_cli(suffix, tmp_path, capsys):
    path = export(tmp_path / f"grid{suffix}", *wavy_grid())
    code, lines = run_atlas(path, tmp_path / "out", capsys)
    assert code == 0 and lines == []
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["input"]["faces"] == len(wavy_grid()[1])


# ---------------------------------------------------------------------------------------------
# Nothing lost: every input face is kept or removed with its reason
# ---------------------------------------------------------------------------------------------


def test_messy_mesh_accounts_for_every_face(tmp_path, capsys):
    V, F, expected = messy_mesh()
    atlas = build_atlas(V, F, CFG)
    assert_valid_atlas(atlas)
    assert_nothing_lost(atlas, len(F))
    c = atlas.cleaning
    got = {r: set(f.tolist()) for r, f in c.removed_by_reason().items()}
    assert got == expected
    assert c.split_edges == 1 and c.split_vertices >= 3 and c.flipped_faces > 0

    # The same through a file and the CLI: report.json names every removed face and why.
    path = tmp_path / "messy.obj"
    write_obj(path, V, F)
    np.testing.assert_array_equal(load_mesh(path)[1], F)
    out = tmp_path / "out"
    code, lines = run_atlas(path, out, capsys)
    assert code == 0 and lines == []
    section = json.loads((out / "report.json").read_text())["cleaning"]
    assert {r: set(f) for r, f in section["removed_faces"].items()} == expected
    removed = sum(len(f) for f in section["removed_faces"].values())
    assert section["input_faces"] == len(F) == section["output_faces"] + removed


# ---------------------------------------------------------------------------------------------
# Determinism
# ---------------------------------------------------------------------------------------------


def _compare_outputs(a: Path, b: Path) -> None:
    names = files_in(a)
    assert names == files_in(b) and "report.json" in names
    for name in names:
        if name == "report.json":
            ra, rb = (json.loads((d / name).read_text()) for d in (a, b))
            ra.pop("timings"), rb.pop("timings")
            assert ra == rb
        else:
            assert (a / name).read_bytes() == (b / name).read_bytes(), name


def test_same_input_and_seed_give_the_same_files(tmp_path, capsys):
    V, F = torus()
    V = V + np.random.default_rng(0).normal(0, 0.01, V.shape)  # no symmetric ties
    path = tmp_path / "torus.obj"
    write_obj(path, V, F)
    for name in ("a", "b"):
        code, _ = run_atlas(path, tmp_path / name, capsys, "--seed", "7")
        assert code == 0
    _compare_outputs(tmp_path / "a", tmp_path / "b")


def test_a_fresh_process_gives_the_same_files(tmp_path, capsys):
    """No state of this process (hash seed, caches, imports) shapes the atlas: a new process with
    another hash seed writes the same files. Small mesh: the cost is the process start (~2 s)."""
    V, F, _ = messy_mesh()
    path = tmp_path / "messy.obj"
    write_obj(path, V, F)
    assert run_atlas(path, tmp_path / "a", capsys, "--seed", "3")[0] == 0
    cmd = [sys.executable, "-m", "segparam.cli", "atlas", str(path), "-o", str(tmp_path / "b")]
    env = {**os.environ, "PYTHONHASHSEED": "12345"}
    argv = [*cmd, *FAST, "--seed", "3"]  # cwd: not the repository, which python -m would import
    proc = subprocess.run(argv, capture_output=True, env=env, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    _compare_outputs(tmp_path / "a", tmp_path / "b")


# ---------------------------------------------------------------------------------------------
# Limits: the memory guard and Ctrl-C
# ---------------------------------------------------------------------------------------------


def test_memory_guard_stops_before_any_work(tmp_path, capsys, monkeypatch):
    V, F = wavy_grid()
    path = export(tmp_path / "grid.ply", V, F)
    monkeypatch.setattr(segparam.pipeline, "MAX_FACES", 10)

    def no_work(*args, **kwargs):
        raise AssertionError("a stage ran although the mesh is over the limit")

    monkeypatch.setattr(segparam.pipeline, "clean", no_work)
    out = tmp_path / "out"
    code, lines = run_atlas(path, out, capsys)
    assert code == 2 and len(lines) == 1 and files_in(out) == []
    assert f"{len(F)} faces" in lines[0] and "10" in lines[0]
    with pytest.raises(InvalidMeshError, match=f"{len(F)} faces"):
        build_atlas(V, F, CFG)


def _interrupt(*args, **kwargs):
    raise KeyboardInterrupt


def _interrupt_between_moves(monkeypatch, out: Path) -> None:
    """Ctrl-C after two of the finished files were moved into the output folder."""
    real = os.replace
    moved = []

    def replace(src, dst):
        if Path(dst).parent == out:
            if len(moved) == 2:
                raise KeyboardInterrupt
            moved.append(dst)
        real(src, dst)

    monkeypatch.setattr(segparam.io.os, "replace", replace)


@pytest.mark.parametrize("where", ["pack", "render", "moving files"])
def test_ctrl_c_exits_130_and_leaves_no_file(where, tmp_path, capsys, monkeypatch):
    path = export(tmp_path / "grid.stl", *wavy_grid())
    out = tmp_path / "out"
    if where == "pack":
        monkeypatch.setattr(segparam.pipeline, "pack_charts", _interrupt)
    elif where == "render":
        monkeypatch.setattr(segparam.export, "render_uv_layout", _interrupt)
    else:
        _interrupt_between_moves(monkeypatch, out)
    code, lines = run_atlas(path, out, capsys)
    assert code == 130
    assert lines == ["segparam: interrupted"]
    assert files_in(out) == []  # not even the staging folder .segparam-*


# ---------------------------------------------------------------------------------------------
# Properties
# ---------------------------------------------------------------------------------------------


@settings(PROPERTY, max_examples=5)
@given(
    seed=st.integers(0, 2**32 - 1),
    keep=st.floats(0.3, 1.0),
    amplitude=st.floats(0.0, 0.5),
    flip=st.floats(0.0, 0.5),
)
def test_property_random_grid_pieces_give_a_valid_atlas(seed, keep, amplitude, flip):
    rng = np.random.default_rng(seed)
    V, F = tri_grid(5, 5)
    V[:, 2] = amplitude * rng.standard_normal(len(V))
    F = F[rng.random(len(F)) < keep]
    if len(F) == 0:
        return
    F = np.where((rng.random(len(F)) < flip)[:, None], F[:, ::-1], F)
    atlas = build_atlas(V, F, CFG, seed=seed % 7)
    assert_valid_atlas(atlas)
    assert_nothing_lost(atlas, len(F))
    assert len(atlas.cleaning.removed_faces) == 0  # nothing here deserves removal


def _valid_files(tmp: Path) -> dict[str, bytes]:
    V, F = wavy_grid(5, 4)
    files = {}
    for suffix, kwargs in [(".obj", {}), (".ply", {}), (".stl", {}), (".off", {})]:
        files[suffix] = export(tmp / f"ok{suffix}", V, F, **kwargs).read_bytes()
    files[".ply ascii"] = export(tmp / "ascii.ply", V, F, encoding="ascii").read_bytes()
    files[".stl ascii"] = (
        trimesh.Trimesh(V, F, process=False).export(file_type="stl_ascii").encode()
    )
    return files


@PROPERTY
@given(data=st.data())
def test_property_corrupted_files_give_an_atlas_or_a_clean_error(data, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("corrupt")
    files = _valid_files(tmp)
    kind = data.draw(st.sampled_from(sorted(files)))
    raw = bytearray(files[kind])
    if data.draw(st.booleans()):
        raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
    flips = data.draw(
        st.lists(st.tuples(st.integers(0, len(raw) - 1), st.integers(1, 255)), max_size=6)
    )
    for i, x in flips:
        if i < len(raw):
            raw[i] ^= x
    path = tmp / f"corrupt{kind.split()[0]}"
    path.write_bytes(bytes(raw))
    try:
        V, F = load_mesh(path)
        atlas = build_atlas(V, F, CFG)
    except SegparamError as exc:
        assert str(exc)
        return
    assert_valid_atlas(atlas)
    assert_nothing_lost(atlas, len(F))


@pytest.mark.parametrize("kind", [".ply", ".stl", ".ply ascii", ".stl ascii", ".obj", ".off"])
def test_every_truncation_point_of_a_file(kind, tmp_path):
    """Cut a file at 60 places: a mesh or a MeshFileError, nothing else."""
    raw = _valid_files(tmp_path)[kind]
    path = tmp_path / f"cut{kind.split()[0]}"
    for n in np.unique(np.linspace(0, len(raw) - 1, 60).astype(int)):
        path.write_bytes(raw[:n])
        try:
            V, F = load_mesh(path)
        except MeshFileError as exc:
            assert path.name in str(exc)
            continue
        try:
            clean(V, F)
        except InvalidMeshError:
            pass


@PROPERTY
@given(
    noise=st.integers(0, 2**16),
    motion=st.integers(0, 2**16),
    log_scale=st.floats(-6.0, 6.0),
)
def test_property_charts_are_invariant_under_rigid_motion_and_scale(noise, motion, log_scale):
    V, F = torus()
    V = V + np.random.default_rng(noise).normal(0, 0.02, V.shape)  # generic: no symmetric ties
    a = segment(V, F, seed=0)
    b = segment(rigid(V, seed=motion, scale=10.0**log_scale), F, seed=0)
    assert a.n_charts > 1
    np.testing.assert_array_equal(a.labels, b.labels)


def test_latin1_names_in_a_text_file_are_fine(tmp_path):
    path = _write(tmp_path / "café.obj", "# café\no pièce\n".encode("latin-1") + TRI.encode())
    path.write_bytes(path.read_bytes() + b"f 1 2 3\n")
    V, F = load_mesh(path)
    assert F.tolist() == [[0, 1, 2]]
