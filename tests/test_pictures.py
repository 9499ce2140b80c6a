"""The picture files of an atlas folder (segparam.pictures) and carrying data onto atlases."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
from PIL import Image

from segparam.bake import BakeError, carry_to_atlas, interpolate_at_closest, load_vertex_colors
from segparam.io import load_mesh
from segparam.pictures import PictureOptions, check_bakes, flat_default, make_pictures
from segparam.pipeline import PipelineConfig, build_atlas
from segparam.synthetic import brain_like_surface


@pytest.fixture(scope="module")
def small_atlas():
    V, F = brain_like_surface(1000)
    cfg = PipelineConfig().replace(pack={"resolution": 128}, remesh={"mode": "off"})
    return V, F, build_atlas(V, F, cfg, seed=0)


def test_make_pictures_every_file(small_atlas, tmp_path):
    import nibabel as nib

    V, F, atlas = small_atlas
    data = tmp_path / "lh.thickness"
    thickness = 2 + (V[:, 0] - V[:, 0].min()) / np.ptp(V[:, 0])  # 2 to 3 mm along x
    nib.freesurfer.write_morph_data(str(data), thickness.astype(np.float32))
    opts = PictureOptions(bakes=("curvature", "normals", str(data)), flat=True)
    files, info = make_pictures(atlas, "b", opts, checker_png=b"\x89PNG-c", uv_png=b"\x89PNG-u")
    assert sorted(files) == sorted(opts.file_names("b").values())
    assert sorted(files) == sorted(
        [
            "b_preview.png",
            "b.html",
            "b_curvature.png",
            "b_normals.png",
            "b_lh.thickness.png",
            "b_flat.gii",
            "b_flat.func.gii",
            "b_flatmap.png",
        ]
    )
    for name in ("b_curvature.png", "b_normals.png", "b_lh.thickness.png", "b_flatmap.png"):
        assert Image.open(io.BytesIO(files[name])).size == (128, 128)
    assert Image.open(io.BytesIO(files["b_preview.png"])).size == (512, 512)
    bakes = {b["file"]: b for b in info["bakes"]}
    lo, hi = bakes["b_curvature.png"]["range"]
    assert lo < hi and bakes["b_curvature.png"]["colormap"] in ("diverging", "viridis")
    lo, hi = bakes["b_lh.thickness.png"]["range"]
    assert 2.0 <= lo < hi <= 3.0 and bakes["b_lh.thickness.png"]["colormap"] == "viridis"
    assert "colormap" not in bakes["b_normals.png"]  # colours, not a scalar
    assert info["flatmap"]["data"] == "lh.thickness"
    img = nib.gifti.GiftiImage.from_bytes(files["b_flat.gii"])
    coords, faces = img.agg_data(("pointset", "triangle"))
    assert len(coords) == len(atlas.uv) and (faces == atlas.uv_F).all()
    named = {d.meta.get("Name"): d.data for d in img.darrays[2:]}
    assert list(named) == ["curvature", "lh.thickness", "vertex_index"]
    # --no-remesh: data map one to one, so the flat file holds the input's values per uv row
    np.testing.assert_allclose(named["lh.thickness"], thickness[atlas.uv_vertex], rtol=1e-6)
    data_only = nib.gifti.GiftiImage.from_bytes(files["b_flat.func.gii"])
    assert [d.meta.get("Name") for d in data_only.darrays] == ["curvature", "lh.thickness"]
    np.testing.assert_array_equal(data_only.darrays[1].data, named["lh.thickness"])
    page = files["b.html"].decode()
    assert page.count("data:image/png;base64,") == 5  # checker, 3 bakes, uv layout
    assert "preview" in info["seconds"] and "viewer" in info["seconds"]  # -> report timings


def test_no_pictures(small_atlas):
    _, _, atlas = small_atlas
    opts = PictureOptions(preview=False, viewer=False)
    files, info = make_pictures(atlas, "b", opts, checker_png=b"", uv_png=b"")
    assert files == {} and info["bakes"] == []


def test_check_bakes_refuses_before_work(tmp_path):
    V, F = brain_like_surface(500)
    np.save(tmp_path / "short.npy", np.zeros(len(V) - 1))
    with pytest.raises(BakeError, match=f"{len(V) - 1} values, but the input mesh has {len(V)}"):
        check_bakes([str(tmp_path / "short.npy")], None, V)
    with pytest.raises(BakeError, match="both write _curvature.png"):
        check_bakes(["curvature", "mean-curvature"], None, V)
    obj = tmp_path / "plain.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(BakeError, match="no vertex colours"):
        check_bakes(["vertex-colors"], obj, load_mesh(obj)[0])
    check_bakes(["curvature", "normals"], None, V)  # built-ins need nothing


def test_vertex_colors_of_a_ply(tmp_path):
    import trimesh

    V, F = brain_like_surface(500)
    colours = np.zeros((len(V), 4), dtype=np.uint8)
    colours[:, 0] = np.arange(len(V)) % 256
    colours[:, 3] = 255
    path = tmp_path / "c.ply"
    trimesh.Trimesh(V, F, vertex_colors=colours, process=False).export(path)
    V0, _ = load_mesh(path)
    got = load_vertex_colors(path, V0)
    np.testing.assert_allclose(got[:, 0] * 255, colours[:, 0], atol=1e-9)


def test_closest_point_interpolation_reproduces_linear_data():
    # barycentric interpolation of a function linear in position is exact on the surface
    V, F = brain_like_surface(2000)
    f = V @ [0.3, -0.2, 0.1] + 4
    rng = np.random.default_rng(0)
    faces = rng.integers(0, len(F), 200)
    w = rng.dirichlet(np.ones(3), 200)
    Q = np.einsum("qk,qkd->qd", w, V[F[faces]])
    np.testing.assert_allclose(interpolate_at_closest(V, F, f, Q), Q @ [0.3, -0.2, 0.1] + 4)


def test_carry_to_a_remeshed_atlas():
    V, F = brain_like_surface(1500)
    cfg = PipelineConfig().replace(pack={"resolution": 128}, remesh={"mode": "on"})
    atlas = build_atlas(V, F, cfg, seed=0)
    assert atlas.remeshing.remeshed  # new vertices (as many as before, here), not the input's
    assert len(atlas.V) != len(V) or np.abs(atlas.V - V).max() > 1e-3 * np.ptp(V, axis=0).max()
    f = V @ [1.0, 2.0, -1.0]
    carried = carry_to_atlas(atlas, f)
    # the remeshed vertices lie close to the input surface: the carried values follow the
    # linear function to within its gradient times that distance
    size = np.ptp(V, axis=0).max()
    assert np.abs(carried - atlas.V @ [1.0, 2.0, -1.0]).max() < np.sqrt(6) * 0.02 * size


def test_flat_default():
    assert flat_default("lh.pial.gii") and flat_default("x.GII.gz")
    assert not flat_default("x.obj") and not flat_default(None)


# ---------------------------------------------------------------------------------------------
# segparam atlas: --bake, --no-preview, --no-viewer, --flat


def grid_file(path):
    from meshes import tri_grid

    from segparam.export import write_obj

    V, F = tri_grid(12, 10)
    V[:, 2] = 0.2 * np.sin(3 * V[:, 0])
    write_obj(path, V, F)
    return path, V


def test_cli_bake_of_the_wrong_length_refused_before_the_work(tmp_path, capsys, monkeypatch):
    import segparam.pipeline
    from segparam.cli import main

    source, V = grid_file(tmp_path / "g.obj")
    np.save(tmp_path / "d.npy", np.zeros(len(V) + 1))

    def work(*args, **kwargs):
        raise AssertionError("the pipeline ran although --bake was bad")

    monkeypatch.setattr(segparam.pipeline, "build_atlas", work)
    out = tmp_path / "out"
    code = main(["atlas", str(source), "-o", str(out), "--bake", str(tmp_path / "d.npy")])
    lines = capsys.readouterr().err.splitlines()
    assert code == 2 and len(lines) == 1, lines
    assert f"{len(V) + 1} values, but the input mesh has {len(V)} vertices" in lines[0]
    assert not out.exists()


def test_cli_pictures_on_and_off(tmp_path, capsys):
    from segparam.cli import main

    source, V = grid_file(tmp_path / "g.obj")
    np.savetxt(tmp_path / "d.csv", V[:, 0])
    fast = ["--resolution", "128", "--no-remesh", "--quiet"]
    out = tmp_path / "a"
    assert (
        main(["atlas", str(source), "-o", str(out), *fast, "--bake", str(tmp_path / "d.csv")]) == 0
    )
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(
        ["g.obj", "g.mtl", "g.glb", "g_checker.png", "g_uv.png", "report.json"]
        + ["g_preview.png", "g.html", "g_d.png"]
    )
    report = json.loads((out / "report.json").read_text())
    assert report["pictures"]["bakes"][0]["file"] == "g_d.png"
    out = tmp_path / "b"
    assert main(["atlas", str(source), "-o", str(out), *fast, "--no-preview", "--no-viewer"]) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["g.obj", "g.mtl", "g.glb", "g_checker.png", "g_uv.png", "report.json"]
    )


def test_cli_gifti_input_gets_flat_maps(tmp_path, capsys):
    import nibabel as nib

    from segparam.cli import main

    V, F = brain_like_surface(1000)
    arrays = [
        nib.gifti.GiftiDataArray(V.astype(np.float32), intent="NIFTI_INTENT_POINTSET"),
        nib.gifti.GiftiDataArray(F.astype(np.int32), intent="NIFTI_INTENT_TRIANGLE"),
    ]
    source = tmp_path / "lh.pial.gii"
    nib.save(nib.gifti.GiftiImage(darrays=arrays), str(source))
    thickness = tmp_path / "lh.thickness"
    nib.freesurfer.write_morph_data(str(thickness), np.linspace(1, 4, len(V)).astype(np.float32))
    out = tmp_path / "out"
    argv = ["atlas", str(source), "-o", str(out), "--resolution", "128", "--no-remesh"]
    assert main([*argv, "--quiet", "--bake", str(thickness)]) == 0
    img = nib.load(str(out / "lh.pial_flat.gii"))
    coords = img.agg_data("pointset")
    uv_rows = len(coords)
    assert uv_rows >= len(V) and np.all(coords[:, 2] == 0)
    named = {d.meta.get("Name"): d.data for d in img.darrays[2:]}
    index = named["vertex_index"]
    np.testing.assert_allclose(named["lh.thickness"], np.linspace(1, 4, len(V))[index], rtol=1e-6)
    assert (out / "lh.pial_flatmap.png").exists() and (out / "lh.pial_lh.thickness.png").exists()
    assert (out / "lh.pial_flat.func.gii").exists()


def test_top_level_names():
    import segparam
    from segparam.bake import bake
    from segparam.render import render_preview

    assert segparam.render_preview is render_preview
    assert segparam.bake.bake is bake  # the module segparam.bake
    with pytest.raises(AttributeError):
        segparam.no_such_name  # noqa: B018
