"""Several meshes in one atlas (issue 17 part 5): one pack_charts call for the charts of every
mesh, so one texture and one texel density; ``segparam atlas a.obj b.ply -o OUT``."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from meshes import cylinder_patch, tri_grid

from segparam.cli import main
from segparam.errors import InvalidMeshError
from segparam.export import write_obj
from segparam.io import load_mesh
from segparam.mesh import face_areas
from segparam.pipeline import PipelineConfig, build_atlas, build_atlases
from segparam.quality import signed_areas
from segparam.raster import footprint_conflicts

CONFIG = PipelineConfig().replace(pack={"resolution": 256}, remesh={"mode": "off"})


def _meshes():
    plate = tri_grid(12, 10, width=1.0)
    tube = cylinder_patch(20, 12, radius=0.5, angle=np.pi, length=1.5)
    return [plate, tube]


def _chart_pieces(atlases):
    """Every chart of every atlas as (uv, faces) for footprint_conflicts."""
    uvs, faces = [], []
    for a in atlases:
        for c in range(a.n_charts):
            uvs.append(a.uv)
            faces.append(a.uv_F[a.chart_of_face == c])
    return uvs, faces


def _densities(uvs, faces, V_list, F_list):
    """Per chart: sqrt(area in ``uvs``' units / 3-D area)."""
    out = []
    for uv, f, V, F in zip(uvs, faces, V_list, F_list, strict=True):
        out.append(np.sqrt(np.abs(signed_areas(uv, f)).sum() / face_areas(V, F).sum()))
    return np.array(out)


def test_two_meshes_share_one_texture_without_overlap_at_one_density():
    multi = build_atlases(_meshes(), CONFIG, names=["plate", "tube"])
    assert multi.names == ("plate", "tube")
    assert len(multi.atlases) == 2 and multi.packing.resolution == 256
    uvs, faces = _chart_pieces(multi.atlases)
    assert len(uvs) == len(multi.packing.uvs)
    assert footprint_conflicts(uvs, faces, resolution=multi.packing.size, padding=2) == 0
    Vs, Fs = [], []
    for a in multi.atlases:
        np.testing.assert_array_equal(a.uv_vertex[a.uv_F], a.F)
        assert a.uv.min() >= 0 and a.uv.max() <= 1
        for c in range(a.n_charts):
            Vs.append(a.V)
            Fs.append(a.F[a.chart_of_face == c])
    texels = np.array(multi.packing.size, dtype=float)
    density = _densities([u * texels for u in uvs], faces, Vs, Fs)  # texels per unit
    np.testing.assert_allclose(density, multi.packing.scale * texels[0], rtol=1e-9)
    # the parts add up to the whole
    total = sum(a.packing.utilization for a in multi.atlases)
    assert total == pytest.approx(multi.packing.utilization, rel=1e-12)
    report = multi.report()
    assert [m["name"] for m in report["meshes"]] == ["plate", "tube"]
    assert report["texture"]["charts"] == len(uvs)
    assert report["meshes"][1]["atlas"]["faces"] == len(multi.atlases[1].F)


def test_one_mesh_through_build_atlases_is_build_atlas():
    V, F = _meshes()[0]
    one = build_atlases([(V, F)], CONFIG).atlases[0]
    np.testing.assert_array_equal(one.uv, build_atlas(V, F, CONFIG).uv)


def test_build_atlases_names_and_bad_input():
    meshes = _meshes()
    tm = trimesh.Trimesh(*meshes[1], process=False)
    multi = build_atlases([meshes[0], tm], CONFIG, names=["a", "A"])
    assert multi.names == ("a", "A_2")  # file names differ on case-insensitive systems too
    with pytest.raises(InvalidMeshError, match="at least one mesh"):
        build_atlases([], CONFIG)
    with pytest.raises(InvalidMeshError, match=r"^mesh1: "):
        build_atlases([meshes[0], (np.zeros((3, 3)), np.array([[0, 1, 5]]))], CONFIG)


def test_cli_several_inputs_make_one_atlas(tmp_path, capsys):
    (V1, F1), (V2, F2) = _meshes()
    a, b = tmp_path / "plate.obj", tmp_path / "tube.ply"
    write_obj(a, V1, F1)
    trimesh.Trimesh(V2, F2, process=False).export(b)
    out = tmp_path / "out"
    args = ["atlas", str(a), str(b), "-o", str(out), "--resolution", "256", "--no-remesh"]
    assert main(args) == 0
    assert "2 meshes" in capsys.readouterr().out
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(
        [
            "atlas.mtl",
            "atlas_checker.png",
            "atlas_uv.png",
            "atlas_preview.png",
            "atlas.html",
            "report.json",
            "plate.obj",
            "plate.glb",
            "tube.obj",
            "tube.glb",
        ]
    )
    report = json.loads((out / "report.json").read_text())
    assert [m["name"] for m in report["meshes"]] == ["plate", "tube"]
    uvs, faces, Vs, Fs = [], [], [], []
    for name in ("plate", "tube"):
        mesh = load_mesh(out / f"{name}.obj", uvs=True)
        assert "mtllib atlas.mtl" in (out / f"{name}.obj").read_text()
        uvs.append(mesh.uv)
        faces.append(mesh.uv_F)
        Vs.append(mesh.V)
        Fs.append(mesh.F)
    # the meshes' layouts never overlap, and both have the texture's density
    size = (report["texture"]["width"], report["texture"]["height"])
    assert footprint_conflicts(uvs, faces, resolution=size, padding=2) == 0
    density = _densities([u * np.array(size, dtype=float) for u in uvs], faces, Vs, Fs)
    np.testing.assert_allclose(density, report["texture"]["texels_per_unit"], rtol=1e-6)


def test_cli_several_inputs_with_texel_density(tmp_path):
    (V1, F1), (V2, F2) = _meshes()
    a, b = tmp_path / "a.obj", tmp_path / "b.obj"
    write_obj(a, V1, F1)
    write_obj(b, V2, F2)
    out = tmp_path / "out"
    args = ["atlas", str(a), str(b), "-o", str(out), "--texels-per-unit", "64", "--quiet"]
    assert main([*args, "--no-remesh"]) == 0
    texture = json.loads((out / "report.json").read_text())["texture"]
    assert texture["texels_per_unit"] == pytest.approx(64)
    area = face_areas(V1, F1).sum() + face_areas(V2, F2).sum()
    assert np.sqrt(area) * 64 < texture["resolution"]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--uvs", "keep", "-o", "OUT"], "--uvs repacks one input mesh, got 2"),
        ([], "name its folder with -o"),
        (["-o", "OUT", "--bad"], "unrecognized arguments"),
    ],
)
def test_cli_several_inputs_refused_before_any_work(tmp_path, capsys, extra, message):
    V, F = _meshes()[0]
    a = tmp_path / "a.obj"
    write_obj(a, V, F)
    extra = [str(tmp_path / "out") if e == "OUT" else e for e in extra]
    assert main(["atlas", str(a), str(a), *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err
    assert not (tmp_path / "out").exists()


def test_cli_several_inputs_one_unreadable_writes_nothing(tmp_path, capsys):
    V, F = _meshes()[0]
    a, b = tmp_path / "a.obj", tmp_path / "b.obj"
    write_obj(a, V, F)
    b.write_text("v 0 0 0\nf 1 2 3\n")
    out = tmp_path / "out"
    assert main(["atlas", str(a), str(b), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "b.obj" in err
    assert not out.exists()
