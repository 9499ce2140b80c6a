"""Baking per-vertex data into atlas textures (segparam.bake)."""

from __future__ import annotations

import numpy as np
import pytest
from meshes import spherical_cap, tri_grid

from segparam.bake import (
    BakeError,
    bake,
    colorize,
    gaussian_curvature,
    load_vertex_data,
    mean_curvature,
    pull_push,
)


def cube_atlas(gap: float = 0.1):
    """A unit cube whose six sides are separate charts (24 vertices), each side a square in its
    own cell of a 3 x 2 uv grid with ``gap`` between the cells and at the border."""
    corners = np.array(
        [[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64
    )  # a side's square, counter-clockwise
    V, F, uv = [], [], []
    cell = (1 - 4 * gap) / 3  # three cells across u, with gaps
    cellv = (1 - 3 * gap) / 2
    for side in range(6):
        axis, sign = divmod(side, 2)
        a, b = (axis + 1) % 3, (axis + 2) % 3
        P = np.zeros((4, 3))
        P[:, axis] = sign
        P[:, a] = corners[:, 0]
        P[:, b] = corners[:, 1]
        base = 4 * side
        tris = np.array([[0, 1, 2], [0, 2, 3]]) + base
        V.append(P)
        F.append(tris)
        col, row = side % 3, side // 3
        origin = np.array([gap + col * (cell + gap), gap + row * (cellv + gap)])
        uv.append(origin + corners * [cell, cellv])
    return np.vstack(V), np.vstack(F), np.vstack(uv)


def texel_uv(R: int) -> tuple[np.ndarray, np.ndarray]:
    """The uv of every texel centre in picture order (row 0 at v = 1)."""
    c = (np.arange(R) + 0.5) / R
    return c[None, :].repeat(R, 0), (1 - c)[:, None].repeat(R, 1)


def test_cube_one_colour_per_side_reads_back_texel_by_texel():
    V, F, uv = cube_atlas()
    side_colours = np.array(
        [[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 0], [0, 255, 255], [128, 64, 32]]
    )
    colours = np.repeat(side_colours / 255, 4, axis=0)  # the side's colour at its 4 vertices
    R = 64
    image, covered = bake(V, F, uv, F, colours, R)
    u, v = texel_uv(R)
    seen = 0
    for s in range(6):  # the six charts
        lo, hi = uv[4 * s : 4 * s + 4].min(0), uv[4 * s : 4 * s + 4].max(0)
        inside = (u > lo[0]) & (u < hi[0]) & (v > lo[1]) & (v < hi[1])
        assert covered[inside].all()
        expected = np.broadcast_to(colours[4 * s], image[inside].shape)
        np.testing.assert_array_equal(image[inside], expected)
        rgb = np.round(image[inside] * 255).astype(np.uint8)  # as the 8-bit texture stores it
        np.testing.assert_array_equal(rgb, np.broadcast_to(side_colours[s], rgb.shape))
        seen += inside.sum()
    assert seen == covered.sum()  # nothing else is covered
    assert seen > 0.4 * R * R  # six cells of ~0.27 x 0.35


def test_linear_function_exact_at_texel_centres():
    V, F = tri_grid(9, 9)
    uv = (V[:, :2] - V[:, :2].min(0)) / np.ptp(V[:, :2], axis=0).max() * 0.8 + 0.1
    f = 3.0 * uv[:, 0] - 2.0 * uv[:, 1] + 0.5  # linear in uv: interpolation reproduces it
    R = 50
    image, covered = bake(V, F, uv, F, f, R)
    u, v = texel_uv(R)
    assert covered.sum() > 0.4 * R * R
    np.testing.assert_allclose(image[covered], (3 * u - 2 * v + 0.5)[covered], atol=1e-12)


def test_curved_function_within_interpolation_error():
    # a quadratic is reproduced to within the linear interpolation error h^2/8 * max|f''|
    V, F = tri_grid(21, 21)
    uv = (V[:, :2] - V[:, :2].min(0)) / np.ptp(V[:, :2], axis=0).max() * 0.8 + 0.1
    f = uv[:, 0] ** 2
    image, covered = bake(V, F, uv, F, f, 64)
    u, _ = texel_uv(64)
    h = 0.8 / 20
    err = np.abs(image[covered] - u[covered] ** 2).max()
    assert 0 < err <= h**2 / 8 * 2 + 1e-12


@pytest.mark.parametrize("padding", [2, 4, 8])
def test_dilation_fills_padding_with_chart_values_only(padding):
    # one chart of constant value 7 on a background of 0: every texel within the padding (and
    # beyond) must hold 7, not a mix with the background
    V, F = tri_grid(6, 6)
    uv = (V[:, :2] - V[:, :2].min(0)) / np.ptp(V[:, :2], axis=0).max() * 0.5 + 0.2
    R = 40
    image, covered = bake(V, F, uv, F, np.full(len(V), 7.0), R, padding)
    from scipy.ndimage import binary_dilation

    near = binary_dilation(covered, iterations=padding) & ~covered
    assert near.sum() > 0
    np.testing.assert_allclose(image[near], 7.0, rtol=0, atol=1e-12)


def test_pull_push_two_charts_fill_from_the_nearest():
    img = np.zeros((16, 16, 1))
    cov = np.zeros((16, 16), bool)
    img[:, :4, 0], cov[:, :4] = 1.0, True
    img[:, 12:, 0], cov[:, 12:] = 5.0, True
    out = pull_push(img, cov)
    assert (out[:, 4, 0] == 1.0).all() and (out[:, 11, 0] == 5.0).all()
    assert out.min() >= 1.0 and out.max() <= 5.0  # no background anywhere


def test_sphere_curvature():
    V, F = spherical_cap(30, 30, extent=1.2)
    # spherical_cap lies on the unit sphere: H = 1, K = 1 away from the boundary
    from segparam.mesh import boundary_edges

    interior = np.setdiff1d(np.arange(len(V)), boundary_edges(F).ravel())
    H, K = mean_curvature(V, F), gaussian_curvature(V, F)
    np.testing.assert_allclose(np.abs(H[interior]), 1.0, rtol=0.05)
    np.testing.assert_allclose(K[interior], 1.0, rtol=0.05)


def test_colorize_reports_scale():
    rgb, scale = colorize(np.array([-2.0, 0.0, 1.0]))
    assert scale["colormap"] == "diverging" and scale["range"][0] == -scale["range"][1]
    assert rgb.shape == (3, 3) and rgb.dtype == np.uint8
    assert tuple(rgb[1]) == (247, 247, 247)  # 0 is the middle, white
    _, scale = colorize(np.linspace(1, 2, 101))
    assert scale["colormap"] == "viridis"
    np.testing.assert_allclose(scale["range"], [1.02, 1.98])


def test_load_vertex_data_formats(tmp_path):
    import nibabel as nib

    x = np.linspace(0, 1, 10)
    np.save(tmp_path / "a.npy", x)
    (tmp_path / "a.csv").write_text("thickness\n" + "\n".join(map(str, x)) + "\n")
    (tmp_path / "a.txt").write_text("\n".join(map(str, x)))
    nib.freesurfer.write_morph_data(str(tmp_path / "lh.thickness"), x.astype(np.float32))
    img = nib.gifti.GiftiImage(darrays=[nib.gifti.GiftiDataArray(x.astype(np.float32))])
    nib.save(img, str(tmp_path / "a.func.gii"))
    for name in ("a.npy", "a.csv", "a.txt", "lh.thickness", "a.func.gii"):
        np.testing.assert_allclose(load_vertex_data(tmp_path / name, 10), x, atol=1e-6)


def test_load_vertex_data_errors(tmp_path):
    np.save(tmp_path / "a.npy", np.zeros(9))
    with pytest.raises(BakeError, match="9 values, but the input mesh has 10 vertices"):
        load_vertex_data(tmp_path / "a.npy", 10)
    (tmp_path / "b.csv").write_text("1,2\n3,4\n")
    with pytest.raises(BakeError, match="2 columns"):
        load_vertex_data(tmp_path / "b.csv", 2)
    (tmp_path / "c.dat").write_text("1\n")
    with pytest.raises(BakeError, match="unknown per-vertex data file"):
        load_vertex_data(tmp_path / "c.dat", 1)
    (tmp_path / "d.txt").write_text("1\nx\n")
    with pytest.raises(BakeError, match="not one number per line"):
        load_vertex_data(tmp_path / "d.txt", 2)
