"""Repacking from files (issue 17 part 4): the loaders keep OBJ ``vt`` and glTF ``TEXCOORD_0``,
``segparam atlas INPUT --uvs keep|repair`` packs the input's own islands."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from test_repack import _broken_layout, _known_layout, _similarity

from segparam.cli import main
from segparam.export import write_obj
from segparam.io import MeshUV, load_mesh
from segparam.quality import signed_areas
from segparam.repack import uv_islands


def test_obj_loader_keeps_vt_through_polygons_and_relative_indices(tmp_path):
    path = tmp_path / "quad.obj"
    path.write_text(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\n"
        "vt 0 0\nvt 0.5 0\nvt 0.5 0.5\nvt 0 0.5\nvt 0.9 0.9 0\n"
        "f 1/1/1 2/2/1 3/3/1 4/4/1\nf 2/5 5/5 -3/-1\n"
    )
    V, F = load_mesh(path)  # unchanged for every existing caller
    mesh = load_mesh(path, uvs=True)
    assert isinstance(mesh, MeshUV)
    np.testing.assert_array_equal(mesh.F, F)
    np.testing.assert_array_equal(mesh.uv_F, [[0, 1, 2], [0, 2, 3], [4, 4, 4]])
    np.testing.assert_array_equal(mesh.uv[3], [0, 0.5])
    # the quad's uv corners follow its vertices through the triangulation
    np.testing.assert_array_equal(mesh.uv[mesh.uv_F[:2]], 0.5 * mesh.V[mesh.F[:2], :2])


@pytest.mark.parametrize(
    "faces", ["f 1 2 3\n", "f 1//1 2//1 3//1\n", "f 1/1 2/2 3\n", "f 1/1 2/2 3/3\nf 1 3 2\n"]
)
def test_obj_without_vt_on_every_corner_has_no_uv(tmp_path, faces):
    path = tmp_path / "t.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n" + faces)
    mesh = load_mesh(path, uvs=True)
    assert mesh.uv is None and mesh.uv_F is None and len(mesh.F) >= 1


def test_obj_vt_index_out_of_range_is_one_line(tmp_path):
    path = tmp_path / "t.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/7\n")
    with pytest.raises(Exception, match=r"t\.obj: face on line 5 uses texture index 7"):
        load_mesh(path, uvs=True)


def test_glb_loader_keeps_texcoord_0(tmp_path):
    V, F, uv = _known_layout()
    path = tmp_path / "m.glb"
    mesh = trimesh.Trimesh(V, F, visual=trimesh.visual.TextureVisuals(uv=uv), process=False)
    mesh.export(path)
    got = load_mesh(path, uvs=True)
    np.testing.assert_array_equal(got.uv_F, got.F)
    np.testing.assert_allclose(got.uv[got.uv_F], uv[F], atol=1e-6)  # float32 in the file
    trimesh.Trimesh(V, F, process=False).export(tmp_path / "plain.glb")
    assert load_mesh(tmp_path / "plain.glb", uvs=True).uv is None


def test_uvs_keep_from_an_obj_keeps_every_island_shape(tmp_path, capsys):
    V, F, uv = _known_layout()
    source = tmp_path / "islands.obj"
    write_obj(source, V, F, uv=uv, uv_faces=F)
    out = tmp_path / "out"
    assert main(["atlas", str(source), "--uvs", "keep", "-o", str(out), "--resolution", "256"]) == 0
    assert "3 uv islands, 3 kept, 0 re-charted" in capsys.readouterr().out
    got = load_mesh(out / "islands.obj", uvs=True)
    np.testing.assert_allclose(got.V[got.F], V[F])  # the input's vertices and faces, in order
    assert got.uv.min() >= 0 and got.uv.max() <= 1
    scales = []
    islands = uv_islands(F)
    for i in range(3):
        faces = np.flatnonzero(islands == i)
        before, after = uv[F[faces]].reshape(-1, 2), got.uv[got.uv_F[faces]].reshape(-1, 2)
        a, residual = _similarity(before, after)  # a rotation times a scale, no mirror
        assert residual < 1e-9
        scales.append(abs(a))
        assert np.array_equal(
            np.sign(signed_areas(got.uv, got.uv_F[faces])), np.sign(signed_areas(uv, F[faces]))
        )
    np.testing.assert_allclose(scales, scales[0], rtol=1e-9)  # one texel density
    report = json.loads((out / "report.json").read_text())
    assert report["mode"] == "keep" and report["kept_islands"] == 3


def test_uvs_repair_says_why_islands_were_recharted(tmp_path, capsys):
    V, F, uv = _broken_layout()
    source = tmp_path / "broken.obj"
    write_obj(source, V, F, uv=uv, uv_faces=F)
    out = tmp_path / "out"
    args = ["atlas", str(source), "--uvs", "repair", "-o", str(out), "--resolution", "256"]
    assert main(args) == 0
    text = capsys.readouterr().out
    lines = {line.split(":")[0].strip(): line for line in text.splitlines()}
    assert "flipped faces" in lines["island 3 re-charted"]
    assert lines["island 4 re-charted"].endswith(": outside the unit square")
    assert "island 0 re-charted" not in lines
    report = json.loads((out / "report.json").read_text())
    kept = [i["kept"] for i in report["islands"]]
    assert kept == [True, False, False, False, False, False]


@pytest.mark.parametrize("mode", ["keep", "repair"])
def test_uvs_on_a_mesh_without_uvs_exits_2_and_writes_nothing(tmp_path, capsys, mode):
    V, F, _ = _known_layout()
    source = tmp_path / "plain.obj"
    write_obj(source, V, F)
    out = tmp_path / "out"
    assert main(["atlas", str(source), "--uvs", mode, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--uvs {mode} needs them" in err and "plain.obj" in err
    assert not out.exists()
