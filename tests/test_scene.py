"""A GLB/glTF scene of several meshes through the several-meshes path, and the pictures of a
several-meshes atlas (issue 17 part 5, issue 18 for ``segparam atlas a b -o OUT``)."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
import trimesh
from meshes import cylinder_patch, tri_grid
from PIL import Image

from segparam.cli import main
from segparam.export import write_obj
from segparam.io import load_mesh, load_scene
from segparam.mesh import face_areas
from segparam.pictures import PictureOptions, merge_atlases
from segparam.pipeline import PipelineConfig, build_atlases
from segparam.quality import signed_areas
from segparam.raster import footprint_conflicts
from segparam.render import render_preview

FAST = ["--resolution", "256", "--no-remesh", "--quiet"]
SHIFT = np.array([3.0, 0.5, -1.0])
# a mirror (x -> -x) and a shift: the node's triangles must be turned around
MIRROR = np.diag([-1.0, 1.0, 1.0, 1.0])
MIRROR[:3, 3] = [0.0, 4.0, 0.0]


def _meshes():
    plate = tri_grid(12, 10, width=1.0)
    tube = cylinder_patch(20, 12, radius=0.5, angle=np.pi, length=1.5)
    return plate, tube


def _scene_file(path):
    """A GLB of two named nodes, the plate shifted and the tube mirrored; their world meshes."""
    (V1, F1), (V2, F2) = _meshes()
    scene = trimesh.Scene()
    shift = trimesh.transformations.translation_matrix(SHIFT)
    scene.add_geometry(
        trimesh.Trimesh(V1, F1, process=False), node_name="plate", geom_name="g0", transform=shift
    )
    scene.add_geometry(
        trimesh.Trimesh(V2, F2, process=False), node_name="tube", geom_name="g1", transform=MIRROR
    )
    scene.export(path)
    tube = V2 @ MIRROR[:3, :3].T + MIRROR[:3, 3]
    return {"plate": (V1 + SHIFT, F1), "tube": (tube, F2[:, ::-1])}


def _glb_json(path):
    data = path.read_bytes()
    (n,) = struct.unpack("<I", data[12:16])
    return json.loads(data[20 : 20 + n])


def test_load_scene_applies_node_transforms_and_keeps_names(tmp_path):
    world = _scene_file(tmp_path / "scene.glb")
    meshes = load_scene(tmp_path / "scene.glb")
    assert [m.name for m in meshes] == ["plate", "tube"]
    for m in meshes:
        V, F = world[m.name]
        np.testing.assert_allclose(m.V, V, atol=1e-6)  # the GLB stores float32
        np.testing.assert_array_equal(m.F, F)
    # the mirrored tube faces as before the mirror: its normals are the mirrored normals
    (V2, F2) = _meshes()[1]
    n_before = np.cross(V2[F2[:, 1]] - V2[F2[:, 0]], V2[F2[:, 2]] - V2[F2[:, 0]])
    tube = meshes[1]
    n_after = np.cross(
        tube.V[tube.F[:, 1]] - tube.V[tube.F[:, 0]], tube.V[tube.F[:, 2]] - tube.V[tube.F[:, 0]]
    )
    np.testing.assert_allclose(n_after, n_before * [-1, 1, 1], atol=1e-5)


def test_single_mesh_glb_and_other_formats_read_as_load_mesh(tmp_path):
    V, F = _meshes()[0]
    trimesh.Trimesh(V, F, process=False).export(tmp_path / "one.glb")
    write_obj(tmp_path / "two.obj", V, F)
    for name in ("one.glb", "two.obj"):
        (m,) = load_scene(tmp_path / name)
        V0, F0 = load_mesh(tmp_path / name)
        assert m.name == name.split(".")[0]
        np.testing.assert_array_equal(m.V, V0)
        np.testing.assert_array_equal(m.F, F0)


def test_cli_scene_makes_one_texture_and_the_scene_back_with_its_nodes(tmp_path):
    world = _scene_file(tmp_path / "scene.glb")
    out = tmp_path / "out"
    assert main(["atlas", str(tmp_path / "scene.glb"), "-o", str(out), *FAST]) == 0
    names = sorted(p.name for p in out.iterdir())
    expected = ["scene.glb", "scene.mtl", "scene_checker.png", "scene_uv.png", "report.json"]
    expected += ["scene_preview.png", "scene.html", "plate.obj", "tube.obj"]
    assert names == sorted(expected)
    gltf = _glb_json(out / "scene.glb")
    assert [n["name"] for n in gltf["nodes"]] == ["plate", "tube"]
    assert len(gltf["images"]) == 1 and len(gltf["materials"]) == 1  # one shared texture
    assert gltf["scenes"] == [{"nodes": [0, 1]}]
    back = trimesh.load(out / "scene.glb", force="scene", process=False)
    uvs, faces = [], []
    for node in ("plate", "tube"):
        transform, geometry = back.graph[node]
        mesh = back.geometry[geometry]
        V = np.asarray(mesh.vertices) @ transform[:3, :3].T + transform[:3, 3]
        lo, hi = world[node][0].min(axis=0), world[node][0].max(axis=0)
        # the node's mesh is where the input scene placed it (the remesher is off)
        np.testing.assert_allclose(V.min(axis=0), lo, atol=1e-5)
        np.testing.assert_allclose(V.max(axis=0), hi, atol=1e-5)
        uvs.append(np.asarray(mesh.visual.uv))
        faces.append(np.asarray(mesh.faces))
    report = json.loads((out / "report.json").read_text())
    size = np.array([report["texture"]["width"], report["texture"]["height"]])
    assert footprint_conflicts(uvs, faces, resolution=tuple(size), padding=2) == 0  # no overlap
    assert [m["name"] for m in report["meshes"]] == ["plate", "tube"]
    density = []
    for name in ("plate", "tube"):  # one texel density, read back from the OBJs
        m = load_mesh(out / f"{name}.obj", uvs=True)
        texel_area = np.abs(signed_areas(m.uv * size, m.uv_F)).sum()
        density.append(np.sqrt(texel_area / face_areas(m.V, m.F).sum()))
    np.testing.assert_allclose(density, report["texture"]["texels_per_unit"], rtol=1e-6)


def test_cli_single_mesh_glb_behaves_as_before(tmp_path):
    V, F = _meshes()[0]
    trimesh.Trimesh(V, F, process=False).export(tmp_path / "one.glb")
    out = tmp_path / "out"
    assert main(["atlas", str(tmp_path / "one.glb"), "-o", str(out), *FAST]) == 0
    names = sorted(p.name for p in out.iterdir())
    expected = ["one.glb", "one.mtl", "one.obj", "one_checker.png", "one_uv.png"]
    assert names == sorted([*expected, "one_preview.png", "one.html", "report.json"])
    assert "atlas" in json.loads((out / "report.json").read_text())  # a one-mesh report
    assert "name" not in _glb_json(out / "one.glb")["nodes"][0]


def test_cli_scene_among_other_inputs(tmp_path):
    _scene_file(tmp_path / "scene.glb")
    V, F = _meshes()[0]
    write_obj(tmp_path / "scene.obj", V, F)  # its own GLB must not take the scene's name
    out = tmp_path / "out"
    args = ["atlas", str(tmp_path / "scene.glb"), str(tmp_path / "scene.obj"), "-o", str(out)]
    assert main([*args, *FAST, "--no-preview", "--no-viewer"]) == 0
    names = sorted(p.name for p in out.iterdir())
    expected = ["atlas.mtl", "atlas_checker.png", "atlas_uv.png", "report.json"]
    expected += ["plate.obj", "tube.obj", "scene.obj", "scene.glb", "scene_2.glb"]
    assert names == sorted(expected)
    assert [n["name"] for n in _glb_json(out / "scene_2.glb")["nodes"]] == ["plate", "tube"]
    assert len(_glb_json(out / "scene.glb")["nodes"]) == 1


def test_several_meshes_get_the_pictures_of_the_whole_set(tmp_path):
    config = PipelineConfig().replace(pack={"resolution": 128}, remesh={"mode": "off"})
    multi = build_atlases(list(_meshes()), config, names=["plate", "tube"])
    merged = merge_atlases(multi.atlases, multi.packing)
    np.testing.assert_array_equal(merged.uv_vertex[merged.uv_F], merged.F)
    corners = np.concatenate([a.V[a.F] for a in multi.atlases])
    np.testing.assert_array_equal(merged.V[merged.F], corners)
    assert merged.chart_of_face.max() + 1 == sum(a.n_charts for a in multi.atlases)
    out = tmp_path / "out"
    options = PictureOptions(bakes=("curvature", "normals"))
    written = multi.save(out, pictures=options)
    assert {p.name for p in written} >= {
        "atlas_preview.png",
        "atlas.html",
        "atlas_curvature.png",
        "atlas_normals.png",
    }
    from segparam.export import _checker_pixels, checker_size

    checker = _checker_pixels(checker_size(multi.packing.size), 16)  # square on the texture
    expected = render_preview(merged.V, merged.F, merged.uv, merged.uv_F, checker)
    preview = np.asarray(Image.open(out / "atlas_preview.png").convert("RGB"))
    np.testing.assert_array_equal(preview, expected)  # both meshes, one picture
    with Image.open(out / "atlas_normals.png") as img:
        assert img.size == multi.packing.size  # one baked texture: the shared texture's size
    assert max(multi.packing.size) == 128
    html = (out / "atlas.html").read_text()
    assert "curvature" in html and "normals" in html
    report = json.loads((out / "report.json").read_text())
    assert [b["file"] for b in report["pictures"]["bakes"]] == [
        "atlas_curvature.png",
        "atlas_normals.png",
    ]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--flat"], "--flat makes the flat map of one mesh, got 2 meshes"),
        (["--bake", "DATA"], "per-input data, but 2 meshes share the texture"),
        (["--bake", "vertex-colors"], "--bake vertex-colors: per-input data"),
    ],
)
def test_cli_several_meshes_refuse_per_input_pictures_before_reading(
    tmp_path, capsys, extra, message
):
    V, F = _meshes()[0]
    write_obj(tmp_path / "a.obj", V, F)
    np.save(tmp_path / "data.npy", np.zeros(len(V)))
    extra = [str(tmp_path / "data.npy") if e == "DATA" else e for e in extra]
    out = tmp_path / "out"
    # the second input does not exist: the refusal comes before any file is read
    args = ["atlas", str(tmp_path / "a.obj"), str(tmp_path / "missing.obj"), "-o", str(out)]
    assert main([*args, *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err
    assert not out.exists()


def test_cli_scene_refuses_flat_before_any_work(tmp_path, capsys):
    _scene_file(tmp_path / "scene.glb")
    out = tmp_path / "out"
    assert main(["atlas", str(tmp_path / "scene.glb"), "-o", str(out), "--flat"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "got 2 meshes" in err
    assert not out.exists()


def test_node_names_that_are_no_file_names(tmp_path):
    (V1, F1), (V2, F2) = _meshes()
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.Trimesh(V1, F1, process=False), node_name="left/arm", geom_name="a")
    scene.add_geometry(trimesh.Trimesh(V2, F2, process=False), node_name="..", geom_name="b")
    scene.export(tmp_path / "body.glb")
    out = tmp_path / "out"
    args = ["atlas", str(tmp_path / "body.glb"), "-o", str(out), "--no-preview", "--no-viewer"]
    assert main([*args, *FAST]) == 0
    assert {"left_arm.obj", "mesh.obj", "body.glb"} <= {p.name for p in out.iterdir()}
    assert [n["name"] for n in _glb_json(out / "body.glb")["nodes"]] == ["left/arm", ".."]


def test_several_inputs_output_checked_before_any_file_is_read(tmp_path, capsys, monkeypatch):
    import segparam.io

    V, F = _meshes()[0]
    write_obj(tmp_path / "a.obj", V, F)
    _scene_file(tmp_path / "scene.glb")

    def read(*args, **kwargs):
        raise AssertionError("a file was read before the output folder was checked")

    monkeypatch.setattr(segparam.io, "load_mesh", read)
    monkeypatch.setattr(segparam.io, "load_scene", read)
    sources = [str(tmp_path / "a.obj"), str(tmp_path / "scene.glb")]
    # into the inputs' folder: a.obj and scene.glb would be overwritten
    assert main(["atlas", *sources, "-o", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "would overwrite this input" in err
