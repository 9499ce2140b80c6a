"""Flat GIfTI surfaces and flatmap pictures (segparam.flatmap)."""

from __future__ import annotations

import numpy as np
import pytest
from meshes import spherical_cap, tri_grid

from segparam.flatmap import (
    GYRUS_GREY,
    SULCUS_GREY,
    data_gifti,
    render_flatmap,
    write_flat_gifti,
)


def atlas_of_grid(n=8):
    V, F = tri_grid(n, n)
    uv = (V[:, :2] - V[:, :2].min(0)) / np.ptp(V[:, :2], axis=0).max() * 0.8 + 0.1
    return V, F, uv


def test_flat_gifti_read_back_with_nibabel(tmp_path):
    import nibabel as nib

    V, F, uv = atlas_of_grid()
    thickness = np.linspace(1.5, 3.5, len(uv))
    curv = np.sin(np.arange(len(uv)))
    path = tmp_path / "brain_flat.gii"
    write_flat_gifti(
        path, uv, F, {"thickness": thickness, "curvature": curv}, vertex_of_uv=np.arange(len(uv))
    )
    img = nib.load(str(path))
    coords, faces = img.agg_data(("pointset", "triangle"))
    assert coords.shape == (len(uv), 3)
    np.testing.assert_allclose(coords[:, :2], uv, atol=1e-7)
    np.testing.assert_array_equal(coords[:, 2], 0)
    np.testing.assert_array_equal(faces, F)
    named = {d.meta.get("Name"): d.data for d in img.darrays[2:]}
    assert list(named) == ["thickness", "curvature", "vertex_index"]
    np.testing.assert_allclose(named["thickness"], thickness, rtol=1e-6)
    np.testing.assert_allclose(named["curvature"], curv, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(named["vertex_index"], np.arange(len(uv)))


def test_flat_gifti_read_by_nilearn(tmp_path):
    from nilearn import surface  # in the test extra: this check runs in CI

    V, F, uv = atlas_of_grid()
    path = tmp_path / "x_flat.gii"
    write_flat_gifti(path, uv, F, {"data": uv[:, 0]})
    mesh = surface.load_surf_mesh(path)
    assert mesh.coordinates.shape == (len(uv), 3) and mesh.faces.shape == F.shape


def test_flat_data_read_by_nilearn(tmp_path):
    # nilearn takes data from data-only files: the <stem>_flat.func.gii companion
    import nibabel as nib
    from nilearn import surface  # in the test extra: this check runs in CI

    V, F, uv = atlas_of_grid()
    a, b = uv[:, 0], uv[:, 1] * 2
    path = tmp_path / "x_flat.func.gii"
    nib.save(data_gifti({"a": a, "b": b}), str(path))
    got = surface.load_surf_data(path)
    np.testing.assert_allclose(got, np.stack([a, b], axis=1), rtol=1e-6)


def test_flat_gifti_refuses_data_of_the_wrong_length(tmp_path):
    V, F, uv = atlas_of_grid()
    with pytest.raises(ValueError, match="shape"):
        write_flat_gifti(tmp_path / "x.gii", uv, F, {"data": np.zeros(3)})
    assert not (tmp_path / "x.gii").exists()


def test_flatmap_curvature_shading_and_data():
    # a spherical cap is convex everywhere: the curvature layer alone is light grey (gyri)
    V, F = spherical_cap(15, 15)
    uv = (V[:, :2] - V[:, :2].min(0)) / np.ptp(V[:, :2], axis=0).max() * 0.8 + 0.1
    rgb, scale = render_flatmap(V, F, uv, F, resolution=64)
    assert scale is None
    inside = (rgb != 255).any(axis=2)
    assert inside.mean() > 0.3
    grey = rgb[inside]
    assert (grey[:, 0] == grey[:, 1]).all() and (grey[:, 0] > (SULCUS_GREY + GYRUS_GREY) / 2).all()
    # the same with concave shading: flip the normals by reversing the winding
    rgb2, _ = render_flatmap(V, F[:, ::-1], uv, F[:, ::-1], resolution=64)
    assert (rgb2[inside][:, 0] < (SULCUS_GREY + GYRUS_GREY) / 2).all()
    # with data: colours vary along the data's gradient, the scale is reported
    rgb3, scale = render_flatmap(V, F, uv, F, uv[:, 0], resolution=64)
    assert scale["colormap"] == "viridis"
    left, right = rgb3[32, 10].astype(int), rgb3[32, 53].astype(int)
    assert np.abs(left - right).sum() > 100
    assert (rgb3[~inside] == 255).all()
