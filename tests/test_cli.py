import json
import subprocess
import sys

import numpy as np
import pytest
from meshes import tri_grid

from segparam.cli import main
from segparam.export import write_obj
from segparam.io import load_mesh


@pytest.fixture
def grid_obj(tmp_path):
    V, F = tri_grid(12, 10)
    V[:, 2] = 0.2 * np.sin(3 * V[:, 0])
    path = tmp_path / "grid mesh é.obj"  # a space and a non-ASCII letter
    write_obj(path, V, F)
    return path


def test_chart_command(grid_obj, tmp_path, capsys):
    out = tmp_path / "chart.obj"
    assert main(["chart", str(grid_obj), "-o", str(out)]) == 0
    assert "bijective True" in capsys.readouterr().out
    V, F = load_mesh(out)
    assert len(F) == 2 * 11 * 9
    assert (tmp_path / "chart_uv.png").exists()


def test_atlas_command_writes_every_output(grid_obj, tmp_path, capsys):
    out = tmp_path / "atlas"
    code = main(["atlas", str(grid_obj), "-o", str(out), "--resolution", "256", "--no-remesh"])
    assert code == 0
    names = sorted(p.name for p in out.iterdir())
    stem = grid_obj.stem
    expected = [
        f"{stem}.glb",
        f"{stem}.mtl",
        f"{stem}.obj",
        f"{stem}_checker.png",
        f"{stem}_uv.png",
        f"{stem}_preview.png",
        f"{stem}.html",
    ]
    assert names == sorted(expected + ["report.json"])
    report = json.loads((out / "report.json").read_text())
    assert report["atlas"]["flipped_triangles"] == 0
    assert report["settings"]["pack"]["resolution"] == 256
    assert report["settings"]["remesh"]["mode"] == "off"
    text = (out / f"{stem}.obj").read_text()
    assert f"mtllib {stem}.mtl" in text and "\nvt " in text and "/" in text.split("\nf ")[1]
    summary = capsys.readouterr().out
    assert "charts" in summary and "utilization" in summary


def test_atlas_output_is_byte_identical_for_a_seed(grid_obj, tmp_path):
    for name in ("a", "b"):
        args = ["atlas", str(grid_obj), "-o", str(tmp_path / name), "--resolution", "256"]
        assert main([*args, "--quiet", "--seed", "3"]) == 0
    for path in (tmp_path / "a").iterdir():
        other = tmp_path / "b" / path.name
        if path.name == "report.json":  # timings differ; everything else must not
            a, b = json.loads(path.read_text()), json.loads(other.read_text())
            a.pop("timings"), b.pop("timings")
            assert a == b
        else:
            assert path.read_bytes() == other.read_bytes(), path.name


@pytest.mark.parametrize(
    "content, message",
    [
        (b"", "empty"),
        (b"\x00\x01\x02garbage\xff" * 10, "not a readable"),
        (b"hello world\nthis is not a mesh\n", "no faces"),
    ],
)
def test_bad_files_exit_2_with_one_line_and_no_output(tmp_path, capsys, content, message):
    bad = tmp_path / "bad.obj"
    bad.write_bytes(content)
    out = tmp_path / "out"
    assert main(["atlas", str(bad), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err and "bad.obj" in err
    assert not out.exists() or not any(out.iterdir())


def test_missing_file_and_unknown_config(tmp_path, capsys, grid_obj):
    assert main(["atlas", str(tmp_path / "nope.obj")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["atlas", str(grid_obj), "--config", "nonexistent"]) == 2
    assert "no pipeline named" in capsys.readouterr().err
    assert main(["atlas", str(grid_obj), "--resolution", "0", "-o", str(tmp_path / "x")]) == 2
    assert capsys.readouterr().err.startswith("segparam: error:")


def test_console_script_runs_without_traceback(tmp_path):
    bad = tmp_path / "bad.stl"
    bad.write_bytes(b"solid x\nfacet normal 0 0 1\n")
    result = subprocess.run(
        [sys.executable, "-m", "segparam.cli", "atlas", str(bad), "-o", str(tmp_path / "o")],
        capture_output=True,
        text=True,
        cwd=tmp_path,  # not the repository: the child imports the package the tests import
    )
    assert result.returncode == 2
    assert "Traceback" not in result.stderr and result.stderr.count("\n") == 1


def test_stage_commands_chain_and_match_the_atlas_command(grid_obj, tmp_path):
    d = tmp_path
    assert main(["remesh", str(grid_obj), "-o", str(d / "r.npz"), "--quiet"]) == 0
    assert main(["segment", str(d / "r.npz"), "-o", str(d / "s.npz"), "--quiet"]) == 0
    assert main(["parameterize", str(d / "s.npz"), "-o", str(d / "p.npz"), "--quiet"]) == 0
    args = ["pack", str(d / "p.npz"), "-o", str(d / "staged"), "--resolution", "256", "--quiet"]
    assert main(args) == 0
    args = ["atlas", str(grid_obj), "-o", str(d / "direct"), "--resolution", "256", "--quiet"]
    assert main(args) == 0
    for name in ("r", "s", "p"):
        assert json.loads((d / f"{name}.json").read_text())["stage"]
    staged = json.loads((d / "staged" / "report.json").read_text())["atlas"]
    direct = json.loads((d / "direct" / "report.json").read_text())["atlas"]
    # The same stages on the same input: the same atlas.
    assert staged == direct
    assert (d / "staged" / "p_uv.png").read_bytes() == (
        d / "direct" / f"{grid_obj.stem}_uv.png"
    ).read_bytes()
    # --square on the stage command too: the whole square, whatever the layout uses
    args = ["pack", str(d / "p.npz"), "-o", str(d / "square"), "--resolution", "256", "--square"]
    assert main([*args, "--quiet"]) == 0
    square = json.loads((d / "square" / "report.json").read_text())["atlas"]
    assert (square["width"], square["height"]) == (256, 256)
    assert square["texels_per_unit"] == pytest.approx(staged["texels_per_unit"], rel=1e-12)


def test_stage_command_rejects_wrong_artifact(grid_obj, tmp_path, capsys):
    assert main(["remesh", str(grid_obj), "-o", str(tmp_path / "r.npz"), "--quiet"]) == 0
    assert main(["parameterize", str(tmp_path / "r.npz"), "-o", str(tmp_path / "p.npz")]) == 2
    assert "lacks labels" in capsys.readouterr().err
