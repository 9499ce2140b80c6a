"""The package face (issue 17, parts 1-3): lazy top-level names, xatlas's parametrize contract
checked on the same arrays as xatlas itself, and trimesh in and out."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import types

import numpy as np
import pytest
import trimesh
from meshes import tri_grid

import segparam
from segparam.errors import ConfigError, InvalidMeshError
from segparam.pipeline import PipelineConfig, build_atlas
from segparam.quality import signed_areas

HEAVY = ("numpy", "numba", "scipy", "pymeshlab", "trimesh")
FAST = PipelineConfig().replace(pack={"resolution": 256})


def _fresh_python(code: str) -> str:
    env = dict(os.environ, PYTHONPATH=os.getcwd())
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
    )
    return out.stdout


# ---------------------------------------------------------------------------------------------
# 1. the package face


def test_every_name_in_all_resolves():
    assert segparam.__all__ == sorted(
        [*segparam._EXPORTS, *segparam._SAME_NAME_MODULES, "__version__"]
    )
    for name in segparam.__all__:
        assert getattr(segparam, name) is not None, name
    assert set(segparam.__all__) <= set(dir(segparam))
    assert segparam.build_atlas is build_atlas
    assert segparam.ConfigError is ConfigError
    with pytest.raises(AttributeError, match="no attribute 'nothing_here'"):
        segparam.nothing_here  # noqa: B018


def test_same_name_modules_are_modules_whatever_the_import_order():
    import segparam.pipeline  # noqa: F401  (imports segparam.clean, .remesh, .segment)

    for name in segparam._SAME_NAME_MODULES:
        module = getattr(segparam, name)
        assert isinstance(module, types.ModuleType)
        assert callable(getattr(module, name))
    code = "import segparam; print(type(segparam.clean).__name__, callable(segparam.clean.clean))"
    assert _fresh_python(code).split() == ["module", "True"]


def test_import_segparam_loads_no_heavy_module():
    probe = "import json, sys; print(json.dumps([m for m in {} if m in sys.modules]))"
    code = "import segparam, segparam.errors; segparam.ConfigError; " + probe.format(HEAVY)
    assert json.loads(_fresh_python(code)) == []
    # the probe can fail: using the pipeline loads them
    code = "import segparam; segparam.build_atlas; " + probe.format(HEAVY)
    assert set(json.loads(_fresh_python(code))) >= {"numpy", "scipy", "numba"}


def test_py_typed_is_shipped():
    # CI runs the tests against the installed package: the marker is in what pip installed
    # (pyproject's package-data), not only in the source tree.
    assert os.path.isfile(os.path.join(os.path.dirname(segparam.__file__), "py.typed"))


# ---------------------------------------------------------------------------------------------
# 2. xatlas's contract


def _sphere():
    m = trimesh.creation.icosphere(subdivisions=2)
    return np.array(m.vertices), np.array(m.faces)


def _defective():
    """The sphere plus faces no atlas can chart and one unreferenced vertex."""
    V, F = _sphere()
    n = len(V)
    V = np.vstack([V, 0.5 * (V[0] + V[1]), [5.0, 5.0, 5.0]])
    extra = [[0, 0, 1], [0, 1, n], F[0]]  # repeated index, zero area, duplicate face
    return V, np.vstack([F, extra]), np.arange(len(F), len(F) + 3), n + 1


def _check_contract(V, F, vmapping, indices, uvs):
    """What code written for xatlas.parametrize relies on."""
    k = len(vmapping)
    assert vmapping.dtype == np.uint32 and vmapping.shape == (k,)
    assert indices.dtype == np.uint32 and indices.shape == np.shape(F)
    assert uvs.dtype == np.float32 and uvs.shape == (k, 2)
    assert all(a.flags.c_contiguous for a in (vmapping, indices, uvs))
    assert indices.max() < k and vmapping.max() < len(V)
    V, F = np.asarray(V), np.asarray(F)
    np.testing.assert_array_equal(V[vmapping][indices], V[F])
    assert uvs.min() >= 0 and uvs.max() <= 1


@pytest.mark.parametrize("dtypes", [(np.float64, np.int64), (np.float32, np.int32)])
def test_parametrize_keeps_xatlas_contract(dtypes):
    import xatlas  # in the test extra: the comparison runs in CI

    V, F = _sphere()
    V, F = V.astype(dtypes[0]), F.astype(dtypes[1])
    _check_contract(V, F, *xatlas.parametrize(V, F))
    vmapping, indices, uvs = segparam.parametrize(V, F, config=FAST)
    _check_contract(V, F, vmapping, indices, uvs)
    # segparam's own promise: bijective charts, wound as the input
    assert (signed_areas(uvs.astype(float), indices.astype(np.int64)) > 0).all()
    # every vertex is used, some split along seams
    assert np.array_equal(np.unique(vmapping), np.arange(len(V)))
    assert len(vmapping) > len(V)


def test_parametrize_handles_dropped_faces_as_xatlas_does():
    import xatlas  # in the test extra: the comparison runs in CI

    V, F, bad, unused = _defective()
    for vmapping, indices, uvs in (
        xatlas.parametrize(V, F),
        segparam.parametrize(V, F, config=FAST),
    ):
        _check_contract(V, F, vmapping, indices, uvs)
        assert unused not in vmapping
        # repeated-index and zero-area faces: corners of their own at uv (0, 0)
        for face in bad[:2]:
            assert (uvs[indices[face]] == 0).all()
            assert not np.isin(indices[face], np.delete(indices, bad, axis=0)).any()


def test_parametrize_takes_lists_and_trimesh_and_a_wound_face():
    V, F = _sphere()
    F = F.copy()
    F[5] = F[5, ::-1]  # inconsistent winding: cleaning turns it, the corners stay the input's
    out_lists = segparam.parametrize(V.tolist(), F.tolist(), config=FAST)
    _check_contract(V, F, *out_lists)
    out_mesh = segparam.parametrize(trimesh.Trimesh(V, F, process=False), config=FAST)
    for a, b in zip(out_lists, out_mesh, strict=True):
        np.testing.assert_array_equal(a, b)


def test_parametrize_welds_a_triangle_soup_into_charts():
    V, F = _sphere()
    soup_V, soup_F = V[F].reshape(-1, 3), np.arange(3 * len(F)).reshape(-1, 3)
    vmapping, indices, uvs = segparam.parametrize(soup_V, soup_F, config=FAST)
    _check_contract(soup_V, soup_F, vmapping, indices, uvs)
    # charted as a surface (cleaning merges the copies), not one island per triangle
    assert len(np.unique(uvs, axis=0)) < len(V) * 1.5 < len(soup_V)


def test_parametrize_refuses_remeshing_and_bad_input():
    V, F = _sphere()
    with pytest.raises(ConfigError, match="keeps the input vertices"):
        segparam.parametrize(V, F, config=FAST.replace(remesh={"mode": "on"}))
    with pytest.raises(InvalidMeshError, match="face indices span"):
        segparam.parametrize(V, F + len(V))
    with pytest.raises(InvalidMeshError, match="no faces"):
        segparam.parametrize(V)


# ---------------------------------------------------------------------------------------------
# 3. trimesh


def test_stage_functions_take_a_trimesh():
    from segparam.clean import clean
    from segparam.segment import segment

    V, F = _sphere()
    mesh = trimesh.Trimesh(V, F, process=False)
    a, b = build_atlas(mesh, config=FAST), build_atlas(V, F, FAST)
    np.testing.assert_array_equal(a.uv, b.uv)
    np.testing.assert_array_equal(clean(mesh).F, clean(V, F).F)
    np.testing.assert_array_equal(segment(mesh).labels, segment(V, F).labels)
    from segparam.parameterize import parameterize_chart
    from segparam.remesh import RemeshConfig, remesh
    from segparam.split import parameterize_charts

    off = RemeshConfig(mode="off")
    np.testing.assert_array_equal(remesh(mesh, config=off).F, F)
    labels = segment(V, F).labels
    pieces = parameterize_charts(mesh, labels=labels).charts
    assert [c.faces.tolist() for c in pieces] == [
        c.faces.tolist() for c in parameterize_charts(V, F, labels).charts
    ]
    Vd, Fd = tri_grid(6, 5)
    disk = trimesh.Trimesh(Vd, Fd, process=False)
    np.testing.assert_array_equal(parameterize_chart(disk).uv, parameterize_chart(Vd, Fd).uv)
    with pytest.raises(InvalidMeshError, match="pass the mesh alone"):
        clean(mesh, F)
    with pytest.raises(InvalidMeshError, match="Scene"):
        clean(trimesh.Scene([mesh]))


@pytest.mark.parametrize("file_type", ["obj", "glb"])
def test_to_trimesh_round_trip_keeps_the_uvs(tmp_path, file_type):
    V, F = _sphere()
    atlas = build_atlas(V, F, FAST)
    mesh = atlas.to_trimesh()
    assert isinstance(mesh.visual, trimesh.visual.TextureVisuals)
    assert mesh.visual.material.image is not None
    np.testing.assert_array_equal(mesh.visual.uv, atlas.uv)
    np.testing.assert_array_equal(mesh.faces, atlas.uv_F)
    path = tmp_path / f"atlas.{file_type}"
    mesh.export(path)
    back = trimesh.load(path, force="mesh", process=False)
    material = back.visual.material  # glTF gives a PBRMaterial, OBJ a SimpleMaterial
    assert getattr(material, "image", None) or getattr(material, "baseColorTexture", None)
    assert len(back.faces) == len(F)
    # corner by corner (the loaders may renumber vertices, never the faces)
    np.testing.assert_allclose(back.vertices[back.faces], mesh.vertices[mesh.faces], atol=1e-6)
    np.testing.assert_allclose(back.visual.uv[back.faces], atlas.uv[atlas.uv_F], atol=1e-6)


def test_unwrap_mirrors_trimesh_unwrap():
    V, F = _sphere()
    mesh = trimesh.Trimesh(V, F, process=False)
    before = mesh.vertices.copy()
    out = segparam.unwrap(mesh, config=FAST)
    vmapping, indices, uvs = segparam.parametrize(V, F, config=FAST)
    np.testing.assert_array_equal(out.vertices, V[vmapping])
    np.testing.assert_array_equal(out.faces, indices)
    np.testing.assert_array_equal(out.visual.uv, uvs)
    default = trimesh.visual.TextureVisuals(uv=uvs, image=None).material.image  # trimesh's
    assert out.visual.material.image.size == default.size
    np.testing.assert_array_equal(mesh.vertices, before)
    from segparam.export import checker_image

    image = checker_image(64)
    assert segparam.unwrap(mesh, image, config=FAST).visual.material.image is image
    with pytest.raises(InvalidMeshError, match="takes a trimesh.Trimesh"):
        segparam.unwrap(V)
