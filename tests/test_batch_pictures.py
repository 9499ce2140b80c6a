"""``segparam batch`` pictures: --no-preview, --no-viewer and the built-in --bake names; data
files refused (they are per input). Runs process_one and the CLI wiring without Dask."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from meshes import tri_grid

import segparam.batch as batch
from segparam.bake import BakeError
from segparam.batch import DONE_MARKER, _done_row, picture_settings, process_one
from segparam.cli import main
from segparam.export import write_obj
from segparam.pipeline import PipelineConfig

CONFIG = PipelineConfig().replace(pack={"resolution": 64}, remesh={"mode": "off"}).as_dict()


def _grid(path):
    V, F = tri_grid(8, 7)
    V[:, 2] = 0.1 * np.sin(3 * V[:, 0])
    write_obj(path, V, F)
    return path


def test_picture_settings_take_built_in_names_only(tmp_path):
    assert picture_settings() == {"preview": True, "viewer": True, "bakes": []}
    settings = picture_settings(preview=False, bakes=("curvature", "normals"))
    assert settings == {"preview": False, "viewer": True, "bakes": ["curvature", "normals"]}
    with pytest.raises(BakeError, match=r"a data file belongs to one input"):
        picture_settings(bakes=[str(tmp_path / "lh.thickness")])
    with pytest.raises(BakeError, match=r"would both write _curvature.png"):
        picture_settings(bakes=["curvature", "mean-curvature"])


def test_process_one_makes_the_pictures_asked_for(tmp_path):
    grid = _grid(tmp_path / "grid.obj")
    folder = tmp_path / "out" / "grid"
    pictures = {"preview": False, "viewer": False, "bakes": ["curvature"]}
    row = process_one(grid, folder, CONFIG, 0, pictures)
    assert row["status"] == "done", row["reason"]
    names = {p.name for p in folder.iterdir()}
    assert "grid_curvature.png" in names and DONE_MARKER in names
    assert "grid_preview.png" not in names and "grid.html" not in names
    # the same pictures are done; other pictures are not
    assert _done_row(grid, folder, CONFIG, 0, pictures) is not None
    assert _done_row(grid, folder, CONFIG, 0, None) is None
    row = process_one(grid, folder, CONFIG, 0)  # the default: preview and viewer
    assert row["status"] == "done"
    names = {p.name for p in folder.iterdir()}
    assert {"grid_preview.png", "grid.html"} <= names


def test_process_one_vertex_colors_fail_for_an_input_without_them(tmp_path):
    grid = _grid(tmp_path / "grid.obj")
    row = process_one(grid, tmp_path / "out" / "grid", CONFIG, 0, {"bakes": ["vertex-colors"]})
    assert row["status"] == "failed" and "colo" in row["reason"]
    assert not (tmp_path / "out" / "grid" / "grid.obj").exists()  # refused before work


def test_cli_batch_passes_the_picture_options(tmp_path, monkeypatch):
    (tmp_path / "in").mkdir()
    grid = _grid(tmp_path / "in" / "grid.obj")
    seen = {}

    def fake_run_batch(paths, outdir, config, **kwargs):
        seen.update(kwargs)
        return batch.BatchResult(rows=[], outdir=outdir, seconds=0.0)

    monkeypatch.setattr(batch, "run_batch", fake_run_batch)
    monkeypatch.setattr(batch, "require_dask", lambda: None)
    args = ["batch", str(grid), "-o", str(tmp_path / "out"), "--quiet"]
    assert main([*args, "--no-preview", "--bake", "normals", "--bake", "curvature"]) == 0
    assert seen["pictures"] == {"preview": False, "viewer": True, "bakes": ["normals", "curvature"]}
    assert main([*args, "--no-viewer"]) == 0
    assert seen["pictures"] == {"preview": True, "viewer": False, "bakes": []}


def test_cli_batch_refuses_a_data_file_before_any_work(tmp_path, monkeypatch, capsys):
    grid = _grid(tmp_path / "grid.obj")
    np.save(tmp_path / "data.npy", np.zeros(56))
    for name in ("dask", "dask.distributed", "distributed"):
        monkeypatch.setitem(sys.modules, name, None)  # refused before Dask is even looked for
    out = tmp_path / "out"
    args = ["batch", str(grid), "-o", str(out), "--bake", str(tmp_path / "data.npy")]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a data file belongs to one input" in err
    assert not out.exists()
    assert main(["batch", str(grid), "-o", str(out), "--flat"]) == 2  # no --flat in batch
    assert "unrecognized arguments: --flat" in capsys.readouterr().err


def test_batch_gifti_inputs_get_their_flat_map_as_in_atlas(tmp_path):
    nib = pytest.importorskip("nibabel")
    V, F = tri_grid(8, 7)
    V[:, 2] = 0.1 * np.sin(3 * V[:, 0])
    img = nib.gifti.GiftiImage()
    img.add_gifti_data_array(
        nib.gifti.GiftiDataArray(V.astype(np.float32), intent="NIFTI_INTENT_POINTSET")
    )
    img.add_gifti_data_array(
        nib.gifti.GiftiDataArray(F.astype(np.int32), intent="NIFTI_INTENT_TRIANGLE")
    )
    nib.save(img, tmp_path / "lh.pial.gii")
    folder = tmp_path / "out" / "lh.pial"
    row = process_one(tmp_path / "lh.pial.gii", folder, CONFIG, 0, {"viewer": False})
    assert row["status"] == "done", row["reason"]
    assert (folder / "lh.pial_flat.gii").exists() and (folder / "lh.pial_flatmap.png").exists()
