import csv
import json
import sys

import numpy as np
import pytest
import trimesh
from meshes import tri_grid

import segparam.batch as batch
from segparam.batch import (
    DONE_MARKER,
    SUMMARY_FIELDS,
    assign_folders,
    expand_inputs,
    process_one,
    run_batch,
)
from segparam.cli import main
from segparam.errors import MeshFileError, SegparamError
from segparam.export import write_obj
from segparam.pipeline import PipelineConfig

FAST = ["--resolution", "256", "--quiet"]
ATLAS_FILES = ["{s}.glb", "{s}.mtl", "{s}.obj", "{s}_checker.png", "{s}_uv.png", "report.json"]
ATLAS_FILES += ["{s}_preview.png", "{s}.html"]


def run_cli(argv):
    """``segparam batch ARGV`` in this process (the CLI's ``main``: a SegparamError is exit 2)."""
    return main(["batch", *map(str, argv)])


def write_grid(path, nx=8, ny=7):
    V, F = tri_grid(nx, ny)
    V[:, 2] = 0.1 * np.sin(3 * V[:, 0])
    path.parent.mkdir(parents=True, exist_ok=True)
    write_obj(path, V, F)
    return path


def read_summary(outdir):
    with open(outdir / "summary.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    return {r["output"]: r for r in rows}, json.loads((outdir / "summary.json").read_text())


@pytest.fixture(scope="module")
def scheduler():
    """One local Dask cluster (2 worker processes) for the whole module."""
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        yield cluster.scheduler_address


@pytest.fixture(scope="module")
def collection(tmp_path_factory):
    """Three small meshes and one broken file."""
    root = tmp_path_factory.mktemp("meshes")
    sphere = trimesh.creation.icosphere(2)
    write_obj(root / "sphere.obj", sphere.vertices, sphere.faces)
    trimesh.creation.torus(1.0, 0.3, major_sections=24, minor_sections=12).export(
        root / "torus.ply"
    )
    write_grid(root / "grid.obj")
    (root / "broken.obj").write_text("v 0 0 0\nf 1 2 7\nnot an obj\n")
    (root / "notes.txt").write_text("not a mesh")
    return root


@pytest.fixture(scope="module")
def first_run(collection, scheduler, tmp_path_factory):
    outdir = tmp_path_factory.mktemp("batch") / "out"
    code = run_cli([collection, "-o", outdir, "--scheduler", scheduler, *FAST])
    return outdir, code


def test_batch_makes_every_atlas_and_records_the_failure(first_run, collection):
    outdir, code = first_run
    assert code == 1
    rows, doc = read_summary(outdir)
    assert sorted(rows) == ["broken", "grid", "sphere", "torus"]
    assert {k: r["status"] for k, r in rows.items()} == {
        "broken": "failed",
        "grid": "done",
        "sphere": "done",
        "torus": "done",
    }
    broken = rows["broken"]
    assert "broken.obj" in broken["reason"] and "\n" not in broken["reason"]
    assert broken["charts"] == ""
    assert doc["counts"] == {"done": 3, "skipped": 0, "failed": 1, "pending": 0}
    assert doc["seed"] == 0 and doc["settings"]["pack"]["resolution"] == 256
    assert [m["input"] for m in doc["meshes"]] == sorted(m["input"] for m in doc["meshes"])
    assert set(doc["meshes"][0]) == set(SUMMARY_FIELDS)
    for stem in ("grid", "sphere", "torus"):
        row = rows[stem]
        assert row["input"] == str(next(collection.glob(f"{stem}.*")).resolve())
        assert int(row["charts"]) >= 1 and 0 < float(row["utilization"]) <= 1
        assert float(row["angle_distortion"]) >= 1 and float(row["l2_stretch"]) >= 1
        assert float(row["seconds"]) > 0 and row["reason"] == ""
        files = sorted(p.name for p in (outdir / stem).iterdir())
        assert files == sorted([DONE_MARKER, *(f.format(s=stem) for f in ATLAS_FILES)])
        report = json.loads((outdir / stem / "report.json").read_text())
        assert report["settings"]["pack"]["resolution"] == 256
        assert report["atlas"]["charts"] == int(row["charts"])
        size = (report["atlas"]["width"], report["atlas"]["height"])
        assert (int(row["width"]), int(row["height"])) == size and max(size) == 256
    assert not (outdir / "broken").exists()


def test_failures_are_counted_on_stderr(collection, scheduler, tmp_path, capsys):
    outdir = tmp_path / "out"
    argv = [collection / "broken.obj", collection / "grid.obj", "-o", outdir]
    assert run_cli([*argv, "--scheduler", scheduler, "--resolution", "256"]) == 1
    captured = capsys.readouterr()
    assert f"1 of 2 failed; see {outdir / 'summary.csv'}" in captured.err
    assert "failed: " in captured.err and "broken.obj" in captured.err
    assert "2 meshes: 1 done, 0 skipped, 1 failed" in captured.out


def test_rerun_skips_what_is_done(first_run, collection, scheduler):
    outdir, _ = first_run
    mtimes = {p: p.stat().st_mtime_ns for p in outdir.glob("*/*")}
    code = run_cli([collection, "-o", outdir, "--scheduler", scheduler, *FAST])
    assert code == 1  # the broken file is tried again, and fails again
    rows, doc = read_summary(outdir)
    assert doc["counts"] == {"done": 0, "skipped": 3, "failed": 1, "pending": 0}
    assert {p: p.stat().st_mtime_ns for p in outdir.glob("*/*")} == mtimes  # nothing rewritten
    assert int(rows["grid"]["charts"]) >= 1  # the figures of the earlier run are kept


def test_changed_seed_or_settings_reprocess(collection, scheduler, tmp_path):
    outdir = tmp_path / "out"
    grid = collection / "grid.obj"
    marker = outdir / "grid" / DONE_MARKER

    def status(*options, where=("--scheduler", scheduler)):
        assert run_cli([grid, "-o", outdir, *FAST, *where, *options]) == 0
        return read_summary(outdir)[0]["grid"]["status"]

    assert status(where=("--workers", "1")) == "done"  # the local-cluster path
    first = json.loads(marker.read_text())
    assert status("--seed", "0") == "skipped"
    assert status("--seed", "1") == "done"
    second = json.loads(marker.read_text())
    assert second["seed"] == 1 and second["fingerprint"] != first["fingerprint"]
    assert second["input_sha256"] == first["input_sha256"]
    assert status("--seed", "1") == "skipped"
    assert status("--seed", "1", "--resolution", "512") == "done"


def test_stem_collisions_get_numbered_folders(scheduler, tmp_path):
    a = write_grid(tmp_path / "a" / "mesh.obj")
    b = write_grid(tmp_path / "b" / "mesh.obj", nx=9)
    c = write_grid(tmp_path / "c" / "mesh-2.obj")
    outdir = tmp_path / "out"
    glob = tmp_path / "*" / "mesh*.obj"
    assert run_cli([glob, "-o", outdir, "--scheduler", scheduler, *FAST]) == 0
    rows, _ = read_summary(outdir)
    assert {k: r["input"] for k, r in rows.items()} == {
        "mesh": str(a),
        "mesh-2": str(b),
        "mesh-2-2": str(c),
    }
    assert (outdir / "mesh-2" / "mesh.obj").exists()  # files keep the input's stem
    assert (outdir / "mesh-2-2" / "mesh-2.obj").exists()


def test_interrupt_leaves_a_summary_and_closes(collection, scheduler, tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    outdir = tmp_path / "out"

    def stop(row):
        raise KeyboardInterrupt

    files = [collection / "grid.obj", collection / "sphere.obj", collection / "torus.ply"]
    config = PipelineConfig().replace(pack={"resolution": 256})
    with distributed.Client(scheduler) as client:
        with pytest.raises(KeyboardInterrupt):
            run_batch(files, outdir, config, client=client, progress=stop)
    rows, doc = read_summary(outdir)
    assert doc["counts"]["done"] == 1 and doc["counts"]["pending"] == 2
    done = next(k for k, r in rows.items() if r["status"] == "done")
    assert (outdir / done / DONE_MARKER).exists()


def test_ctrl_c_exits_130_with_one_line(collection, tmp_path, monkeypatch, capsys):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(batch, "run_batch", interrupted)
    monkeypatch.setattr(batch, "require_dask", lambda: None)
    assert run_cli([collection / "grid.obj", "-o", tmp_path / "out", "--quiet"]) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("segparam: interrupted")


def test_missing_dask_says_how_to_install(collection, tmp_path, monkeypatch, capsys):
    for name in ("dask", "dask.distributed", "distributed"):
        monkeypatch.setitem(sys.modules, name, None)  # makes `import name` raise ImportError
    with pytest.raises(SegparamError, match=r"pip install 'segparam\[batch\]'"):
        run_batch([collection / "grid.obj"], tmp_path / "out")
    assert run_cli([collection / "grid.obj", "-o", tmp_path / "out"]) == 2
    err = capsys.readouterr().err
    assert err == "segparam: error: segparam batch needs Dask: pip install 'segparam[batch]'\n"
    assert not (tmp_path / "out").exists()


def test_usage_errors_exit_2(collection, tmp_path, capsys):
    pytest.importorskip("dask.distributed")
    out = tmp_path / "out"
    assert run_cli([tmp_path / "nothing-*.obj", "-o", out]) == 2
    assert "no mesh files matched" in capsys.readouterr().err
    assert run_cli([tmp_path / "missing.obj", "-o", out]) == 2
    assert "no such file or folder" in capsys.readouterr().err
    assert run_cli([collection, "-o", out, "--config", tmp_path / "bad.toml"]) == 2
    assert "no such config file" in capsys.readouterr().err
    assert run_cli([collection, "-o", out, "--workers", "0"]) == 2
    # argparse: one or the other
    assert run_cli([collection, "-o", out, "--workers", "2", "--scheduler", "tcp://x:8786"]) == 2
    assert "not allowed with argument" in capsys.readouterr().err


def test_expand_inputs_folders_globs_dedup_and_order(tmp_path):
    for name in ("b.obj", "a.PLY", "c.gii.gz", ".hidden.obj", "readme.txt", "sub/d.stl"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("x")
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "old.obj").write_text("x")
    top = [tmp_path / n for n in ("a.PLY", "b.obj", "c.gii.gz")]
    assert expand_inputs([tmp_path], exclude=tmp_path / "out") == top
    got = expand_inputs([tmp_path], recursive=True, exclude=tmp_path / "out")
    assert got == [*top, tmp_path / "sub" / "d.stl"]
    # the same file named three ways counts once; a folder matched by a pattern is expanded
    again = [tmp_path / "b.obj", tmp_path / "*.obj", tmp_path, tmp_path / "su*"]
    assert expand_inputs(again, exclude=tmp_path / "out") == [*top, tmp_path / "sub" / "d.stl"]
    assert expand_inputs([tmp_path / "**" / "*.stl"], recursive=True) == [tmp_path / "sub/d.stl"]
    assert expand_inputs([tmp_path / "readme.txt"]) == [tmp_path / "readme.txt"]  # named: kept
    with pytest.raises(MeshFileError, match="no such file or folder"):
        expand_inputs([tmp_path / "nope.obj"])
    with pytest.raises(MeshFileError, match="no mesh files matched"):
        expand_inputs([tmp_path / "*.off"])


def test_assign_folders_is_deterministic_and_case_insensitive(tmp_path):
    paths = [
        tmp_path / "a" / "brain.obj",
        tmp_path / "b" / "Brain.ply",
        tmp_path / "c" / "brain-2.obj",
        tmp_path / "lh.pial.gii.gz",
    ]
    assert assign_folders(paths) == ["brain", "Brain-2", "brain-2-2", "lh.pial"]


def test_process_one_reports_unexpected_errors_as_type_and_message(tmp_path, monkeypatch):
    grid = write_grid(tmp_path / "grid.obj")

    def boom(*args, **kwargs):
        raise RuntimeError("solver exploded\n  on two lines")

    monkeypatch.setattr("segparam.pipeline.build_atlas", boom)
    row = process_one(grid, tmp_path / "out" / "grid", PipelineConfig().as_dict(), 0)
    assert row["status"] == "failed"
    assert row["reason"] == "RuntimeError: solver exploded on two lines"
    assert not (tmp_path / "out" / "grid" / DONE_MARKER).exists()
