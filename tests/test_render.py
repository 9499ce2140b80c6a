"""The software-rasterized 3-D preview (segparam.render) against scenes computed by ray casting."""

from __future__ import annotations

import numpy as np
import pytest

from segparam.render import (
    AMBIENT,
    BACKGROUND,
    SEAM_COLOR,
    camera_for,
    render_preview,
    render_view,
    seam_edges,
)

# A square [-1, 1]^2 in the plane z = 0, uv = its position mapped to [0, 1]^2.
SQUARE_V = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=np.float64)
SQUARE_F = np.array([[0, 1, 2], [0, 2, 3]])
SQUARE_UV = (SQUARE_V[:, :2] + 1) / 2


def checker(n_squares: int = 8, px: int = 8) -> np.ndarray:
    """A black-and-white checker texture of n x n squares of px texels, picture order."""
    i = np.arange(n_squares * px) // px
    white = (i[:, None] + i[None, :]) % 2 == 0
    tex = np.zeros((n_squares * px, n_squares * px, 3), dtype=np.uint8)
    tex[white] = (255, 255, 255)
    return tex


def ray_cast_square(camera, texture):
    """The expected picture, computed independently of the rasterizer: the ray through each
    pixel centre is intersected with the plane z = 0 and the texture looked up at the hit."""
    n = camera.size
    c = (np.arange(n) + 0.5 - n / 2) / camera.focal
    X, Y = c[None, :], -c[:, None]  # right and up per unit depth; row 0 at the top
    D = camera.forward + X[..., None] * camera.right + Y[..., None] * camera.up
    t = -camera.eye[2] / D[..., 2]
    P = camera.eye + t[..., None] * D
    inside = (np.abs(P[..., 0]) < 1) & (np.abs(P[..., 1]) < 1) & (t > 0)
    u, v = (P[..., 0] + 1) / 2, (P[..., 1] + 1) / 2
    h, w = texture.shape[:2]
    row = np.clip(((1 - v) * h).astype(int), 0, h - 1)
    col = np.clip((u * w).astype(int), 0, w - 1)
    out = np.empty((n, n, 3), dtype=np.uint8)
    out[:] = BACKGROUND
    out[inside] = texture[row[inside], col[inside]]
    return out, inside


@pytest.mark.parametrize("view", [(0, 0), (25, 35), (-40, 25)])
def test_textured_square_matches_ray_casting(view):
    tex = checker()
    # the plane's normal is +z; views from the front half-space
    cam = camera_for(SQUARE_V, view[0], view[1], 160)
    got = render_view(SQUARE_V, SQUARE_F, SQUARE_UV, SQUARE_F, tex, cam, shade=False)
    want, inside = ray_cast_square(cam, tex)
    assert inside.sum() > 0.15 * 160 * 160
    differ = np.any(got != want, axis=2)
    # only pixels whose centre is within rounding of a checker or square edge may differ
    assert differ.mean() < 0.01, differ.mean()


def test_affine_texture_lookup_would_fail_the_same_check():
    # the check above detects a missing perspective correction: an affine (screen-space) uv
    # interpolation across the same steep view puts many pixels on the wrong square
    tex = checker()
    cam = camera_for(SQUARE_V, 25, 35, 160)
    want, inside = ray_cast_square(cam, tex)
    S = cam.project(SQUARE_V)
    n = cam.size
    yy, xx = np.mgrid[0:n, 0:n] + 0.5
    A = np.c_[S[:, :2], np.ones(4)]
    affine = np.empty((n, n, 3), dtype=np.uint8)
    affine[:] = BACKGROUND
    for tri in SQUARE_F:  # two triangles
        M = np.linalg.solve(A[tri].T, np.stack([xx.ravel(), yy.ravel(), np.ones(n * n)]))
        m = (M >= 0).all(axis=0).reshape(n, n)
        uv = (SQUARE_UV[tri].T @ M).T.reshape(n, n, 2)
        r = np.clip(((1 - uv[..., 1]) * 64).astype(int), 0, 63)
        c = np.clip((uv[..., 0] * 64).astype(int), 0, 63)
        affine[m] = tex[r[m], c[m]]
    assert np.any(affine != want, axis=2).mean() > 0.03


def test_shading_and_background():
    tex = np.full((4, 4, 3), 200, dtype=np.uint8)
    cam = camera_for(SQUARE_V, 0, 60, 64)  # the plane seen at 60 degrees from its normal (+z)
    got = render_view(SQUARE_V, SQUARE_F, SQUARE_UV, SQUARE_F, tex, cam, shade=True)
    _, inside = ray_cast_square(cam, tex)
    expected = round(200 * (AMBIENT + (1 - AMBIENT) * abs(cam.forward[2])))
    assert abs(abs(cam.forward[2]) - np.cos(np.radians(60))) < 1e-12
    np.testing.assert_array_equal(
        got[inside & np.roll(inside, 1, 0) & np.roll(inside, -1, 0)][:, 0], expected
    )
    assert (got[~inside] == BACKGROUND).all(axis=1).mean() > 0.99


def test_nearer_face_hides_farther_one():
    # two squares, the red one in front (z = 0.5) of the blue one: z-buffer keeps the red
    V = np.vstack([SQUARE_V + [0, 0, 0.5], SQUARE_V * [2, 2, 1]])
    F = np.vstack([SQUARE_F, SQUARE_F + 4])
    uv = np.vstack([SQUARE_UV * [0.5, 1], SQUARE_UV * [0.5, 1] + [0.5, 0]])
    tex = np.zeros((2, 2, 3), dtype=np.uint8)
    tex[:, 0] = (255, 0, 0)  # u < 0.5: red
    tex[:, 1] = (0, 0, 255)
    for order in (F, F[::-1]):
        cam = camera_for(V, 0, 0, 64)
        img = render_view(V, order, uv, order, tex, cam, shade=False)
        x, y, _ = cam.project(np.array([[0.0, 0.0, 0.5], [1.5, 0.0, 0.0]])).astype(int).T
        assert tuple(img[y[0], x[0]]) == (255, 0, 0)
        assert tuple(img[y[1], x[1]]) == (0, 0, 255)


def test_seams_drawn_where_visible():
    # the square's border is its uv boundary: drawn in the seam colour around the square
    assert len(seam_edges(SQUARE_F, SQUARE_F)) == 4
    img = render_preview(
        SQUARE_V, SQUARE_F, SQUARE_UV, SQUARE_F, checker(), views=[(0, 0)], size=64
    )
    red = (img == SEAM_COLOR).all(axis=2)
    assert red.sum() > 4 * 30  # four sides of ~40 px
    assert not red[20:44, 20:44].any()  # none inside


def test_preview_layout():
    img = render_preview(SQUARE_V, SQUARE_F, SQUARE_UV, SQUARE_F, size=32)
    assert img.shape == (64, 64, 3) and img.dtype == np.uint8
    assert render_preview(
        SQUARE_V, SQUARE_F, SQUARE_UV, SQUARE_F, views=[(0, 0)] * 3, size=32
    ).shape == (32, 96, 3)


def test_one_compiled_renderer_for_writable_and_read_only_faces():
    """The kernel sees the faces read-only whatever the caller passes (an atlas's are), so a
    writable array does not compile a second copy of it; the picture is the same."""
    from segparam import render

    cam = camera_for(SQUARE_V, 20.0, 10.0, 32)
    tex = checker()
    frozen = SQUARE_F.copy()
    frozen.flags.writeable = False
    a = render_view(SQUARE_V, SQUARE_F.copy(), SQUARE_UV, SQUARE_F, tex, cam)
    b = render_view(SQUARE_V, frozen, SQUARE_UV, SQUARE_F, tex, cam)
    assert np.array_equal(a, b)
    assert len(render._render_kernel.signatures) == 1
