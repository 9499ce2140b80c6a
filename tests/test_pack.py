"""Tests of the packing stage (segparam.pack).

The no-overlap checks do not trust the packer's own rasterizer: `touched_texels` below decides
triangle/texel contact with the separating-axis theorem on every texel of each triangle's
bounding box, which is a different computation from the library's slab scan.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from segparam import pack, raster
from segparam.errors import ConfigError, InvalidMeshError
from segparam.pack import (
    PackConfig,
    PackResult,
    footprint_conflicts,
    min_area_rotation,
    pack_charts,
    rasterize_footprint,
)

# ----------------------------------------------------------------------------------------------
# charts built in code


def disc(n_theta: int = 24, n_r: int = 3, aspect: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    theta = np.linspace(0, 2 * np.pi, n_theta, endpoint=False)
    t = np.arange(1, n_r + 1) / n_r
    ring = t[:, None, None] * np.stack([np.cos(theta), aspect * np.sin(theta)], -1)[None]
    uv = np.vstack([np.zeros((1, 2)), ring.reshape(-1, 2)])
    j = np.arange(n_theta)
    jn = (j + 1) % n_theta
    F = [np.stack([np.zeros(n_theta, int), 1 + j, 1 + jn], 1)]
    for r in range(n_r - 1):
        a, b = 1 + r * n_theta, 1 + (r + 1) * n_theta
        F += [np.stack([a + j, b + j, b + jn], 1), np.stack([a + j, b + jn, a + jn], 1)]
    return uv, np.vstack(F).astype(np.int64)


def grid(nx: int, ny: int, keep=None) -> tuple[np.ndarray, np.ndarray]:
    i, j = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij"))
    if keep is not None:
        sel = keep(i, j)
        i, j = i[sel], j[sel]
    v = (ny + 1) * i + j
    F = np.vstack([np.stack([v, v + ny + 1, v + ny + 2], 1), np.stack([v, v + ny + 2, v + 1], 1)])
    X, Y = np.meshgrid(np.arange(nx + 1.0), np.arange(ny + 1.0), indexing="ij")
    uv = np.stack([X.ravel(), Y.ravel()], 1)
    used, inv = np.unique(F, return_inverse=True)
    return uv[used], inv.reshape(-1, 3).astype(np.int64)


def area_uv(uv: np.ndarray, F: np.ndarray) -> float:
    a, b, c = uv[F[:, 0]], uv[F[:, 1]], uv[F[:, 2]]
    d1, d2 = b - a, c - a
    return float(np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]).sum() / 2)


def rotate(uv: np.ndarray, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return uv @ np.array([[c, -s], [s, c]]).T


def mixed_charts(n: int, seed: int) -> tuple[list, list, np.ndarray]:
    """Discs, ellipses, L-shapes and strips at random poses, with log-uniform 3-D areas."""
    rng = np.random.default_rng(seed)
    uvs, faces, areas = [], [], []
    for i in range(n):
        kind = i % 4
        if kind == 0:
            uv, F = disc()
        elif kind == 1:
            uv, F = disc(aspect=rng.uniform(0.3, 0.7))
        elif kind == 2:
            uv, F = grid(6, 6, lambda a, b: (a < 3) | (b < 3))
        else:
            uv, F = grid(int(rng.integers(8, 16)), 1)
        uv = rotate(uv, rng.uniform(0, 2 * np.pi)) * rng.uniform(0.2, 5) + rng.normal(0, 3, 2)
        uvs.append(uv)
        faces.append(F)
        areas.append(float(np.exp(rng.uniform(np.log(0.05), 0))))
    return uvs, faces, np.array(areas)


# ----------------------------------------------------------------------------------------------
# independent conservative rasterization (separating-axis theorem, texel by texel)


def touched_texels(uv: np.ndarray, F: np.ndarray, res) -> np.ndarray:
    """(H, W) bool: texels [j, j+1] / W x [i, i+1] / H that a closed triangle meets (``res``: a
    side, or the texture's (W, H))."""
    W, H = raster.texture_size(res)
    P = uv * np.array([W, H], dtype=float)
    T = P[F]  # (m, 3, 2)
    out = np.zeros((H, W), dtype=bool)
    top = np.array([W - 1, H - 1])
    lo = np.clip(np.floor(T.min(axis=1)).astype(int) - 1, 0, top)  # closed: x = i touches i - 1
    hi = np.clip(np.floor(T.max(axis=1)).astype(int), 0, top)
    for t in range(len(F)):  # test helper: clarity over speed
        xs = np.arange(lo[t, 0], hi[t, 0] + 1)
        ys = np.arange(lo[t, 1], hi[t, 1] + 1)
        X, Y = np.meshgrid(xs, ys)
        corners = np.stack(
            [np.stack([X + dx, Y + dy], -1) for dx in (0, 1) for dy in (0, 1)], -2
        )  # (ny, nx, 4, 2)
        tmin, tmax = T[t].min(axis=0), T[t].max(axis=0)
        # separating axes: the two texel axes, then the three edge normals
        hit = (X <= tmax[0]) & (X + 1 >= tmin[0]) & (Y <= tmax[1]) & (Y + 1 >= tmin[1])
        for e in range(3):
            a, b, c = T[t, e], T[t, (e + 1) % 3], T[t, (e + 2) % 3]
            normal = np.array([b[1] - a[1], a[0] - b[0]])
            if not normal.any():
                continue
            side_c = normal @ (c - a)
            if side_c == 0:
                continue
            proj = (corners - a) @ normal * np.sign(side_c)
            # the box is separated when all its corners lie strictly outside this edge
            hit &= proj.max(axis=-1) >= -1e-9 * np.abs(normal).sum()
        out[Y[hit], X[hit]] = True
    return out


def chebyshev_dilate(mask: np.ndarray, r: int) -> np.ndarray:
    out = mask.copy()
    for _ in range(r):
        grown = out.copy()
        grown[1:] |= out[:-1]
        grown[:-1] |= out[1:]
        grown[:, 1:] |= grown[:, :-1].copy()
        grown[:, :-1] |= grown[:, 1:].copy()
        out = grown
    return out


def assert_valid_layout(res: PackResult, faces: list) -> None:
    (W, H), p = res.size, res.padding
    # each side is the square's, or trimmed to whole blocks (both can be, at a fixed density)
    for side in (W, H):
        assert side == res.resolution or (side < res.resolution and side % pack.TRIM_MULTIPLE == 0)
    feet = [touched_texels(uv, F, (W, H)) for uv, F in zip(res.uvs, faces, strict=True)]
    border = np.ones((H, W), dtype=bool)
    border[p : H - p, p : W - p] = False
    for i, a in enumerate(feet):
        assert a.any()
        assert not (a & border).any(), f"chart {i} within {p} texels of the border"
        grown = chebyshev_dilate(a, p)
        for j in range(i + 1, len(feet)):
            assert not (grown & feet[j]).any(), f"charts {i} and {j} closer than {p} texels"
    for uv in res.uvs:
        low, high = p / np.array([W, H]), 1 - p / np.array([W, H])
        assert np.all(uv.min(axis=0) >= low - 1e-12) and np.all(uv.max(axis=0) <= high + 1e-12)


def in_texels(res: PackResult) -> list:
    """Per chart, its packed uv in texels of the (possibly trimmed) texture."""
    return [uv * np.array(res.size, dtype=float) for uv in res.uvs]


def texel_transforms(res: PackResult) -> np.ndarray:
    """The packed charts' affine maps into texels (u times the width, v times the height)."""
    return res.transforms * np.array(res.size, dtype=float)[None, :, None]


def assert_uniform_density(res: PackResult, faces: list, areas) -> None:
    """Every chart's area in texels is its 3-D area times the one density squared."""
    pairs = zip(in_texels(res), faces, areas, strict=True)
    ratio = [area_uv(u, F) / a for u, F, a in pairs]
    np.testing.assert_allclose(ratio, (res.scale * res.width) ** 2, rtol=1e-9)


# ----------------------------------------------------------------------------------------------
# min-area rotation


@pytest.mark.parametrize("angle", [0.0, 0.3, -1.1, np.pi / 2, 2.5])
def test_min_area_rotation_rectangle_comes_back_axis_aligned(angle: float) -> None:
    rect = np.array([[0, 0], [3, 0], [3, 1], [0, 1], [1.5, 0.5]], dtype=float)
    uv = rotate(rect, angle) + [10.0, -4.0]
    out, theta = min_area_rotation(uv)
    w, h = np.ptp(out, axis=0)
    assert w == pytest.approx(3.0, abs=1e-12) and h == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(out, rotate(uv, theta), atol=1e-12)
    # the returned angle undoes the input one up to a half turn
    assert np.sin(2 * (theta + angle)) == pytest.approx(0.0, abs=1e-12)


def test_min_area_rotation_square_and_triangle() -> None:
    square = rotate(np.array([[0, 0], [2, 0], [2, 2], [0, 2]], float), np.pi / 4)
    out, _ = min_area_rotation(square)
    assert np.prod(np.ptp(out, axis=0)) == pytest.approx(4.0)
    # right isosceles triangle: the best box has the legs on its sides (area 1, not 1.0 x 0.5*2)
    tri = rotate(np.array([[0, 0], [1, 0], [0, 1]], float), 0.7)
    out, _ = min_area_rotation(tri)
    assert np.prod(np.ptp(out, axis=0)) == pytest.approx(1.0)


def test_min_area_rotation_rejects_collinear_points() -> None:
    with pytest.raises(InvalidMeshError, match="collinear"):
        min_area_rotation(np.array([[0, 0], [1, 1], [2, 2.0]]))


# ----------------------------------------------------------------------------------------------
# rasterization helper against the independent one


def test_rasterize_footprint_matches_independent_raster() -> None:
    rng = np.random.default_rng(5)
    for trial in range(20):
        n = 12
        uv = rng.uniform(0.05, 0.95, (n, 2))
        if trial % 2:  # vertices on texel corners and edges, the delicate cases
            uv = np.round(uv * 64) / 64
        F = rng.integers(0, n, (15, 3))
        F = F[[area_uv(uv, f[None]) > 1e-6 for f in F]]  # the helpers differ on degenerate ones
        got = rasterize_footprint(uv, F, resolution=64)
        want = touched_texels(uv, F, 64)
        assert np.array_equal(got, want)


def test_rasterize_footprint_analytic_triangle() -> None:
    # a right triangle whose legs run along texel lines covers exactly the texels on/below its
    # hypotenuse (closed sets: texels touching it at a corner count)
    uv = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]]) / 8
    got = rasterize_footprint(uv, np.array([[0, 1, 2]]), resolution=8)
    i, j = np.mgrid[:8, :8]
    assert np.array_equal(got, i + j <= 4)


def ccw(uv: np.ndarray, F: np.ndarray) -> np.ndarray:
    a, b, c = uv[F[:, 0]], uv[F[:, 1]], uv[F[:, 2]]
    signed = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    return np.where((signed < 0)[:, None], F[:, [0, 2, 1]], F)


@pytest.mark.parametrize("seed", range(6))
def test_outline_fill_rasterizer_matches_triangle_rasterizer(seed: int) -> None:
    # the packer rasterizes valid charts from their outline plus a winding-number fill; it must
    # give exactly the texels of the per-triangle kernel, holes and concave outlines included
    rng = np.random.default_rng(seed)
    shapes = [
        disc(int(rng.integers(5, 30)), 3, aspect=rng.uniform(0.2, 1)),
        grid(7, 5, lambda i, j: (i < 2) | (j < 2)),  # an L
        grid(6, 6, lambda i, j: (i < 2) | (i > 3) | (j < 2) | (j > 3)),  # a frame: one hole
    ]
    for uv, F in shapes:
        F = ccw(uv, F)
        B = raster.boundary_edges(F)
        assert B is not None
        for _ in range(4):
            P = rotate(uv, rng.uniform(0, 2 * np.pi)) * rng.uniform(0.3, 9)
            P = P - P.min(axis=0) + rng.uniform(0, 1, 2)
            if rng.random() < 0.5:  # vertices on texel lines, the delicate cases
                P = np.round(P * 2) / 2 + 0.0
            shape = tuple(int(v) for v in np.floor(P.max(axis=0))[::-1] + 2)
            want = raster.rasterize_triangles(P, F, shape, 1e-4)
            got = raster.fill_outline(P, B, shape, 1e-4)
            assert np.array_equal(got, want)


def test_boundary_edges_refuses_meshes_the_fill_cannot_handle() -> None:
    uv, F = grid(2, 1)
    F = ccw(uv, F)
    assert len(raster.boundary_edges(F)) == 6  # the outline of two unit squares
    fan = np.array([[0, 1, 2], [0, 1, 3], [1, 0, 4]])  # edge 0-1 in three triangles
    assert raster.boundary_edges(fan) is None
    twice = np.array([[0, 1, 2], [0, 1, 3]])  # directed edge 0->1 used twice
    assert raster.boundary_edges(twice) is None


@pytest.fixture(scope="module")
def mixed() -> tuple[list, list, np.ndarray]:
    return mixed_charts(24, seed=1)


@pytest.fixture(scope="module", params=["raster", "rect"])
def packed(request, mixed) -> tuple[PackResult, list, np.ndarray]:
    uvs, faces, areas = mixed
    cfg = PackConfig(resolution=256, padding=2, method=request.param)
    return pack_charts(uvs, faces, areas, config=cfg), faces, areas


def test_no_overlap_with_padding(packed) -> None:
    res, faces, _ = packed
    assert_valid_layout(res, faces)
    assert footprint_conflicts(res.uvs, faces, resolution=res.size, padding=2) == 0


def test_texel_density_is_uniform(packed) -> None:
    res, faces, areas = packed
    assert_uniform_density(res, faces, areas)


def test_utilization_matches_recomputation(packed) -> None:
    res, faces, areas = packed
    total = sum(area_uv(uv, F) for uv, F in zip(res.uvs, faces, strict=True))
    assert res.utilization == pytest.approx(total, rel=1e-12)
    texel_area = (res.scale * res.width) ** 2 * areas.sum()
    assert res.utilization == pytest.approx(texel_area / (res.width * res.height), rel=1e-9)


def test_transforms_are_orientation_preserving_similarities(packed, mixed) -> None:
    res, _, _ = packed
    uvs_in = mixed[0]
    assert res.transforms.shape == (len(uvs_in), 2, 3)
    for A, T, uv_in, uv_out in zip(
        res.transforms, texel_transforms(res), uvs_in, res.uvs, strict=True
    ):
        np.testing.assert_allclose(uv_in @ A[:, :2].T + A[:, 2], uv_out, atol=1e-14)
        L = T[:, :2]  # in texels: a rotation times a uniform scale
        assert np.linalg.det(L) > 0
        np.testing.assert_allclose(L @ L.T / np.linalg.det(L), np.eye(2), atol=1e-12)


def test_charts_come_out_min_area_oriented() -> None:
    # a single long rectangle at 30 degrees must be packed axis-aligned (either way round)
    uv, F = grid(10, 1)
    res = pack_charts([rotate(uv, np.pi / 6)], [F], [10.0], config=PackConfig(resolution=128))
    w, h = np.ptp(res.uvs[0], axis=0)
    assert w * h == pytest.approx(area_uv(res.uvs[0], F), rel=1e-9)


def test_layout_is_deterministic() -> None:
    uvs, faces, areas = mixed_charts(12, seed=4)
    cfg = PackConfig(resolution=192)
    a = pack_charts(uvs, faces, areas, config=cfg)
    b = pack_charts([u.copy() for u in uvs], faces, areas.copy(), config=cfg)
    assert all(x.tobytes() == y.tobytes() for x, y in zip(a.uvs, b.uvs, strict=True))
    assert a.transforms.tobytes() == b.transforms.tobytes()
    assert a.utilization == b.utilization


def test_raster_beats_rect_on_mixed_shapes() -> None:
    # regression: the default (raster) packer's measured advantage on a 40-chart mixed atlas
    uvs, faces, areas = mixed_charts(40, seed=7)
    raster = pack_charts(uvs, faces, areas, config=PackConfig(resolution=512, method="raster"))
    rect = pack_charts(uvs, faces, areas, config=PackConfig(resolution=512, method="rect"))
    assert PackConfig().method == "raster"
    assert raster.utilization > rect.utilization
    assert raster.utilization > 0.62


def test_half_turns_let_two_trapezoids_tile_the_square() -> None:
    # a right trapezoid and its half-turned copy tile a square; quarter turns alone cannot make
    # them meet along the slanted side (0.43 at 128 texels with 0 and 90 degrees only)
    trap = np.array([[0, 0], [1, 0], [1, 0.1], [0, 0.9]])
    F = np.array([[0, 1, 2], [0, 2, 3]])
    uvs = [rotate(trap, 0.4), rotate(trap, 2.0) + 3]
    res = pack_charts(uvs, [F, F], [1.0, 1.0], config=PackConfig(resolution=128))
    assert_valid_layout(res, [F, F])
    assert res.utilization > 0.8
    turn = [np.arctan2(A[1, 0], A[0, 0]) for A in res.transforms]
    relative = np.degrees(turn[1] - turn[0] + 2.0 - 0.4) % 360
    assert relative == pytest.approx(180.0, abs=1e-6)


@pytest.mark.parametrize("steps", [1, 3, 6])
def test_angle_steps_keep_the_layout_valid(steps: int) -> None:
    uvs, faces, areas = mixed_charts(10, seed=9)
    res = pack_charts(uvs, faces, areas, config=PackConfig(resolution=160, angle_steps=steps))
    assert_valid_layout(res, faces)
    assert_uniform_density(res, faces, areas)


def _turns_off(uvs, transforms, period: float) -> np.ndarray:
    """Per chart, its packed rotation off its min-area frame modulo ``period`` degrees (90: off
    the frame's quarter turns; 360: off the frame itself), in [0, period / 2]."""
    turn = np.degrees([np.arctan2(A[1, 0], A[0, 0]) for A in transforms])
    frames = np.array([np.degrees(min_area_rotation(uv)[1]) for uv in uvs])
    off = (turn - frames) % period
    return np.minimum(off, period - off)


def test_round_charts_turn_by_fine_angles_and_rectangles_by_quarter_turns() -> None:
    # similar-sized ellipses (what organic surfaces give) and one rectangle, 30-degree steps:
    # some layouts turn ellipses by 30 or 60 degrees, the rectangle only ever by quarter turns,
    # every turn is a multiple of 30 degrees and every layout is valid
    strip, Fs = grid(5, 2)
    fine = 0
    for seed, resolution in [(0, 256), (1, 128), (2, 128)]:
        rng = np.random.default_rng(seed)
        uvs, faces = [], []
        for _ in range(10):
            uv, F = disc(aspect=rng.uniform(0.4, 0.7))
            uvs.append(rotate(uv, rng.uniform(0, 2 * np.pi)) * rng.uniform(0.5, 3))
            faces.append(F)
        uvs, faces = [*uvs, rotate(strip, 0.3)], [*faces, Fs]
        areas = np.r_[rng.uniform(0.8, 1.0, 10), 0.9]
        config = PackConfig(resolution=resolution, padding=2, angle_steps=3)
        res = pack_charts(uvs, faces, areas, config=config)
        assert_valid_layout(res, faces)
        off = _turns_off(uvs, texel_transforms(res), 90)
        assert off[-1] < 1e-6  # the rectangle
        assert np.all(np.isclose(off % 30, 0, atol=1e-6) | np.isclose(off % 30, 30, atol=1e-6))
        fine += int(np.sum(off > 29))
    assert fine > 0, "no ellipse used a 30 or 60 degree turn"


def test_no_fine_angles_with_one_step_or_without_rotation() -> None:
    uvs, faces, areas = mixed_charts(10, seed=9)
    configs = [PackConfig(resolution=160, angle_steps=1), PackConfig(resolution=160, rotate=False)]
    for cfg in configs:
        res = pack_charts(uvs, faces, areas, config=cfg)
        assert np.all(_turns_off(uvs, texel_transforms(res), 90) < 1e-6)


def test_a_folded_chart_packs_without_overlap() -> None:
    # a chart whose uv map folds over itself (one triangle flipped) cannot be filled from its
    # outline; the packer falls back to rasterizing every triangle and stays valid
    uv, F = grid(4, 4)
    uv = uv.copy()
    uv[6] = [2.6, 2.7]  # pull an interior vertex past its neighbours: some triangles flip
    uvs, faces = [uv, *mixed_charts(5, seed=3)[0]], [F, *mixed_charts(5, seed=3)[1]]
    areas = [2.0, *mixed_charts(5, seed=3)[2]]
    res = pack_charts(uvs, faces, areas, config=PackConfig(resolution=128))
    assert_valid_layout(res, faces)


# ----------------------------------------------------------------------------------------------
# edge cases


def test_single_chart_fills_the_square() -> None:
    uv, F = grid(4, 4)
    res = pack_charts([rotate(uv, 0.4) * 7], [F], [3.0], config=PackConfig(resolution=128))
    assert_valid_layout(res, [F])
    # a square chart at 128 texels with 2 texels of padding per side: (124 - ~1) / 128 squared
    assert res.utilization > 0.9


def test_a_chart_as_long_as_the_texture_packs_in_one_trial_at_its_full_width(monkeypatch) -> None:
    """A 2:1 chart is bound by its length, not its area: the first trial is just under the side
    bound, it fits, and the search stops there with the box spanning the texture's width (at
    0.88 of the bound the search took six trials to come within 0.6% of it)."""
    from segparam import pack

    tried = []
    real = pack._trial_at_scale
    monkeypatch.setattr(pack, "_trial_at_scale", lambda *a: tried.append(a[3]) or real(*a))
    uv, F = grid(8, 4)
    res = pack_charts([rotate(uv, 0.3)], [F], [2.0], config=PackConfig(resolution=128))
    assert_valid_layout(res, [F])
    assert len(tried) == 1
    u = res.uvs[0][:, 0] * 128
    assert u.max() - u.min() > 124 - 1  # inner width 124, less the box's rounding
    assert res.utilization > 0.45  # half the square, less the padding: 124 * 62 / 128^2 = 0.469


def test_a_fit_that_fills_the_texture_is_followed_by_a_small_step(monkeypatch) -> None:
    """With few charts, a first fit whose layout fills the texture's height is followed by a
    trial ``_FULL_STEP`` larger, not by the bisection towards the area bound; here every larger
    scale fails, and the first fit's layout is the answer. The step is within the search's
    tolerance, so its failure ends the search: two trials."""
    from segparam import pack

    tried = []
    real = pack._trial_at_scale

    def trial(pool, setup, charts, s, G, p, k):
        tried.append(s)
        if len(tried) > 1:
            return None, 0.9, G + 40  # every larger scale overflows
        placed, _, _ = real(pool, setup, charts, s, G, p, k)
        return placed, 1.0, G  # the first fit fills the texture

    monkeypatch.setattr(pack, "_trial_at_scale", trial)
    uvs = [rotate(grid(3, 2)[0], 0.2 * i) for i in range(5)]
    faces = [grid(3, 2)[1]] * 5
    res = pack_charts(uvs, faces, [1.0] * 5, config=PackConfig(resolution=256))
    assert tried[1] == pytest.approx(tried[0] * (1 + pack._FULL_STEP))
    assert res.scale * 256 == tried[0]
    assert len(tried) == 2


def test_a_fit_that_fills_the_texture_after_a_failure_is_followed_by_a_small_step(
    monkeypatch,
) -> None:
    """The same small step after a search that has already failed (the bone scan's 20 charts:
    the first guess overflows, the second fits loosely, the third fills the texture): the next
    trial is ``_FULL_STEP`` above the filling fit, not the bisection towards the failed scale,
    and its failure ends the search with the filling fit's layout: four trials, not six."""
    from segparam import pack

    tried = []
    real = pack._trial_at_scale

    def trial(pool, setup, charts, s, G, p, k):
        tried.append(s)
        if len(tried) == 1 or len(tried) > 3:
            return None, 0.9, G + 100  # the first guess and every larger scale overflow
        placed, _, _ = real(pool, setup, charts, s, G, p, k)
        return placed, 1.0, (G - 60 if len(tried) == 2 else G)  # loose fit, then a filling one

    monkeypatch.setattr(pack, "_trial_at_scale", trial)
    uvs = [rotate(grid(3, 2)[0], 0.2 * i) for i in range(5)]
    faces = [grid(3, 2)[1]] * 5
    res = pack_charts(uvs, faces, [1.0] * 5, config=PackConfig(resolution=256))
    assert tried[1] < tried[2] < tried[0]
    assert tried[3] == pytest.approx(tried[2] * (1 + pack._FULL_STEP))
    assert res.scale * 256 == tried[2]
    assert len(tried) == 4


def test_many_tiny_charts() -> None:
    rng = np.random.default_rng(3)
    uvs, faces, areas = [], [], []
    for i in range(100):
        uv, F = disc(8, 1) if i % 2 else grid(1, 1)
        uvs.append(uv * rng.uniform(0.5, 2))
        faces.append(F)
        areas.append(rng.uniform(0.5, 1.5))
    res = pack_charts(uvs, faces, areas, config=PackConfig(resolution=192, padding=1))
    assert footprint_conflicts(res.uvs, faces, resolution=192, padding=1) == 0
    assert res.utilization > 0.3


def test_many_charts_start_the_scale_search_near_its_answer(monkeypatch) -> None:
    """With ``_MODEL_CHARTS`` charts or more, the first scale tried comes from their areas and
    padding (``_first_scale``), within a few percent of the scale the search ends at on 600
    random triangles, where the fixed fraction of the bound overshoots by more than 10%; with
    fewer charts the search starts from that fraction."""
    from segparam import pack

    rng = np.random.default_rng(0)
    uvs = [rng.normal(0.0, 1.0, (3, 2)) for _ in range(600)]
    twice = [(u[1, 0] - u[0, 0]) * (u[2, 1] - u[0, 1]) - (u[1, 1] - u[0, 1]) * (u[2, 0] - u[0, 0])
             for u in uvs]  # fmt: skip
    faces = [np.array([[0, 1, 2]] if t > 0 else [[0, 2, 1]]) for t in twice]
    areas = [0.5 * abs(t) for t in twice]
    tried = []
    real = pack._trial_at_scale
    monkeypatch.setattr(
        pack, "_trial_at_scale", lambda *a: tried.append(a[3]) or real(*a)
    )  # a[3]: the scale
    res = pack_charts(uvs, faces, areas)
    assert footprint_conflicts(res.uvs, faces, resolution=1024, padding=2) == 0
    final = res.scale * 1024
    by_area, by_side = pack._scale_bounds(pack._prepare(uvs, faces, areas), 1024, 2)
    assert by_area < by_side
    assert abs(tried[0] / final - 1) < 0.05
    assert pack._FIRST_GUESS * by_area / final > 1.10
    few = pack._prepare(uvs[:50], faces[:50], areas[:50])
    assert pack._first_scale(few, 1024, 2, by_area, by_side) == pack._FIRST_GUESS * by_area


def test_after_a_failed_trial_many_charts_aim_at_the_full_window() -> None:
    """Before any layout fitted, a failed raster trial's secant step is aimed at ``_AIM`` of the
    texture's side (the middle of the "full" stop's window) with ``_MODEL_CHARTS`` charts or
    more, just under the failed scale at most; with fewer charts too after a near miss (at
    most ``_NEAR_MISS`` over the side), else it stays 3% under the failed scale."""
    from segparam import pack

    G, p, s = 1024, 2, 64.0
    far = 1070  # the height the failed trial needed, border included: 4.5% over the side
    aimed = pack._next_scale(s, 0.0, s, False, 1.0, far, G, p, many=True)
    assert aimed == pytest.approx(s * np.sqrt(pack._AIM * (G - 2 * p) / (far - 2 * p)))
    assert pack._UNDER_FAILED * s < aimed < s
    assert pack._next_scale(s, 0.0, s, False, 1.0, far, G, p) == pytest.approx(
        pack._UNDER_FAILED * s
    )
    near = 1034  # 1% over: few charts aim too (a 3% step would land on a loose fit)
    for many in (True, False):
        aimed = pack._next_scale(s, 0.0, s, False, 1.0, near, G, p, many=many)
        assert aimed == pytest.approx(s * np.sqrt(pack._AIM * (G - 2 * p) / (near - 2 * p)))
    edge = 2 * p + int((1 + pack._NEAR_MISS) * (G - 2 * p))  # the last height that is near
    assert pack._next_scale(s, 0.0, s, False, 1.0, edge, G, p) > pack._UNDER_FAILED * s
    assert pack._next_scale(s, 0.0, s, False, 1.0, edge + 1, G, p) == pytest.approx(
        pack._UNDER_FAILED * s
    )
    # a failure by a hair: the aimed step still moves down, by half the scale tolerance
    close = pack._next_scale(s, 0.0, s, False, 1.0, G + 1, G, p, many=True)
    assert close == pytest.approx(s / (1 + pack._SCALE_TOL / 2))
    # a rectangle trial reports no height: the fraction rule as before (placed 81% of the area)
    assert pack._next_scale(s, 0.0, s, False, 0.81, None, G, p, many=True) == pytest.approx(0.9 * s)


def test_long_thin_chart_and_wildly_different_areas() -> None:
    strip, Fs = grid(200, 1)
    big, Fb = disc()
    small, Fm = grid(1, 1)
    uvs, faces = [rotate(strip, 1.0), big, small], [Fs, Fb, Fm]
    areas = np.array([0.02, 1.0, 1e-5])
    res = pack_charts(uvs, faces, areas, config=PackConfig(resolution=256, padding=2))
    assert_valid_layout(res, faces)
    assert_uniform_density(res, faces, areas)


def test_without_rotation_every_chart_keeps_its_minimum_area_frame() -> None:
    # rotate=False: every transform is the rotation into the chart's minimum-area frame (no
    # quarter turn, no finer turn) times a uniform scale, so each packed chart lies wider than
    # tall, as min_area_rotation leaves it. The same charts with quarter turns allowed turn by
    # 90 and by 180 degrees, so the check tells the frames apart.
    uvs, faces, areas = mixed_charts(8, seed=1)
    res = pack_charts(uvs, faces, areas, config=PackConfig(resolution=128, rotate=False))
    assert_valid_layout(res, faces)
    A = texel_transforms(res)[:, :, :2]
    det = np.linalg.det(A)
    assert np.all(det > 0)  # no mirror
    # in texels, a rotation times a uniform scale: A A^T / det(A) is the identity
    np.testing.assert_allclose(
        A @ A.transpose(0, 2, 1) / det[:, None, None], [np.eye(2)] * 8, atol=1e-12
    )
    assert np.all(_turns_off(uvs, texel_transforms(res), 360) < 1e-6)
    width = np.array([np.ptp(uv, axis=0) for uv in in_texels(res)])
    assert np.all(width[:, 0] >= width[:, 1] * (1 - 1e-9))
    quarter = PackConfig(resolution=128, angle_steps=1)
    off = _turns_off(uvs, texel_transforms(pack_charts(uvs, faces, areas, config=quarter)), 360)
    assert np.isclose(off, 90).any() and np.isclose(off, 180).any()


# ----------------------------------------------------------------------------------------------
# errors


def test_empty_list_raises() -> None:
    with pytest.raises(InvalidMeshError, match="empty"):
        pack_charts([], [], [])


def test_zero_area_chart_raises_with_numbers() -> None:
    uv, F = grid(2, 2)
    with pytest.raises(InvalidMeshError, match=r"chart 1 has 3-D area 0\.0"):
        pack_charts([uv, uv], [F, F], [1.0, 0.0])


def test_flat_uv_chart_raises() -> None:
    uv = np.array([[0, 0], [1, 1], [2, 2.0]])
    with pytest.raises(InvalidMeshError, match="chart 0"):
        pack_charts([uv], [np.array([[0, 1, 2]])], [1.0])


@pytest.mark.parametrize(
    "uvs, faces, areas, match",
    [
        ([np.zeros((3, 2))], [], [1.0], "face arrays"),
        ([np.eye(3)], [np.array([[0, 1, 2]])], [1.0], r"\(n, 2\)"),
        ([np.eye(3)[:, :2]], [np.array([[0, 1, 3]])], [1.0], "indices span"),
        ([np.eye(3)[:, :2]], [np.array([[0, 1, 2]])], [1.0, 2.0], "2 3-D areas"),
        ([np.eye(3)[:, :2]], [np.array([[0, 1, 2]])], [np.nan], "3-D area nan"),
    ],
)
def test_bad_input_raises(uvs, faces, areas, match) -> None:
    with pytest.raises(InvalidMeshError, match=match):
        pack_charts(uvs, faces, areas)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"resolution": 0},
        {"padding": -1},
        {"resolution": 4, "padding": 2},
        {"method": "skyline"},
        {"angle_steps": 0},
        {"angle_steps": 1.5},
    ],
)
def test_bad_config_raises(kwargs) -> None:
    with pytest.raises(ConfigError):
        PackConfig(**kwargs)


# ----------------------------------------------------------------------------------------------
# property: random rectangles and triangles never overlap after packing

_chart = st.tuples(
    st.sampled_from(["rect", "tri"]),
    st.floats(0.05, 20.0),  # aspect ratio or triangle shape
    st.floats(0.0, 2 * np.pi),
    st.floats(1e-3, 1.0),  # 3-D area
)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    charts=st.lists(_chart, min_size=1, max_size=7),
    padding=st.integers(0, 3),
    method=st.sampled_from(["raster", "rect"]),
)
def test_random_charts_never_overlap(charts, padding, method) -> None:
    uvs, faces, areas = [], [], []
    for kind, shape, angle, a3 in charts:
        if kind == "rect":
            uv = np.array([[0, 0], [shape, 0], [shape, 1], [0, 1]], dtype=float)
            F = np.array([[0, 1, 2], [0, 2, 3]])
        else:
            uv = np.array([[0, 0], [1, 0], [shape / 4, 1 / shape]], dtype=float)
            F = np.array([[0, 1, 2]])
        uvs.append(rotate(uv, angle))
        faces.append(F)
        areas.append(a3)
    res = pack_charts(
        uvs, faces, areas, config=PackConfig(resolution=96, padding=padding, method=method)
    )
    assert_valid_layout(res, faces)
    assert_uniform_density(res, faces, areas)


def test_outlines_are_the_boundary_edges_and_refuse_bad_edges() -> None:
    # pack._outlines against a plain count of each chart's edges: a boundary edge has one face;
    # an edge of three faces, or of two faces running it the same way, gives no outline
    from collections import Counter

    from segparam.pack import _outlines

    uv, F = grid(3, 3)  # a valid disk
    n = len(uv)
    wrong_way = np.array([[0, 1, 4], [0, 1, 5]])  # both run 0 -> 1
    three = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])  # edge 0-1 has three faces
    charts = [F, wrong_way, three, F[:5]]
    G = np.concatenate([c + i * n for i, c in enumerate(charts)])
    fchart = np.repeat(np.arange(len(charts)), [len(c) for c in charts])
    voff = np.arange(len(charts)) * n
    got = _outlines(G, fchart, voff, np.ones(len(charts), dtype=bool), len(charts) * n)
    for c, out in zip(charts, got, strict=True):
        directed = Counter(map(tuple, np.concatenate([c[:, [0, 1]], c[:, [1, 2]], c[:, [2, 0]]])))
        undirected = Counter(tuple(sorted(e)) for e in directed.elements())
        if max(directed.values()) > 1 or max(undirected.values()) > 2:
            assert out is None
            continue
        want = sorted(e for e in directed if undirected[tuple(sorted(e))] == 1)
        assert sorted(map(tuple, out.tolist())) == want
    assert got[0] is not None and got[1] is None and got[2] is None and got[3] is not None


# ----------------------------------------------------------------------------------------------
# round charts turn by quarter turns only


def _ring(n_theta: int = 48, inner: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """A washer: two concentric n-gons of radii `inner` and 1, one band of triangles."""
    theta = 2 * np.pi * np.arange(n_theta) / n_theta
    c = np.stack([np.cos(theta), np.sin(theta)], 1)
    uv = np.vstack([inner * c, c])
    j = np.arange(n_theta)
    jn = (j + 1) % n_theta
    F = np.vstack([np.stack([j, n_theta + j, n_theta + jn], 1), np.stack([j, n_theta + jn, jn], 1)])
    return uv, F.astype(np.int64)


def test_round_charts_are_measured_and_only_they() -> None:
    from segparam import pack

    uv_gear, F_gear = disc(48, 3)
    uv_gear[1 + 2 * 48 :: 2] *= 0.9  # every other outer vertex pulled in: a round hull, teeth
    shapes = [disc(48, 3), _ring(), disc(48, 3, aspect=1.1), (uv_gear, F_gear), disc(12, 2)]
    charts = pack._prepare(  # at their uv areas: 3-D units are uv units
        [uv for uv, _ in shapes], [F for _, F in shapes], [area_uv(*shape) for shape in shapes]
    )
    gap = 1 - np.cos(np.pi / 48)  # a regular 48-gon of radius 1 lies between 1 - gap and 1
    assert [c.roundness for c in charts[:2]] == pytest.approx([gap, gap], rel=1e-3)
    # an ellipse, teeth on the outline, a 12-gon (3.5% of its radius): not round
    assert all(np.isinf(c.roundness) for c in charts[2:])


def test_round_charts_turn_by_quarter_turns_at_scales_where_angles_move_no_texel() -> None:
    from segparam import pack

    uv, F = _ring()
    charts = pack._prepare(
        [uv, disc(24, 3, aspect=1.5)[0]], [F, disc(24, 3, aspect=1.5)[1]], [3, 3]
    )
    ring = charts[0].roundness
    steps = lambda scale: np.diff(pack._Angles(charts, 6, scale).entry_ptr).tolist()  # noqa: E731
    assert steps(0.9 / ring) == [1, 6]  # under a texel at every scale tried: quarter turns
    assert steps(1.1 / ring) == [6, 6]  # over it at the largest: fine angles, as any chart


def test_round_charts_pack_as_with_every_angle(monkeypatch) -> None:
    from segparam import pack

    rng = np.random.default_rng(3)
    uvs, faces = [], []
    for _ in range(12):
        uv, F = _ring(48, rng.uniform(0.2, 0.7)) if rng.random() < 0.5 else disc(48, 3)
        uvs.append(uv * rng.uniform(0.5, 2.0))
        faces.append(F)
    areas = np.array([area_uv(u, f) for u, f in zip(uvs, faces, strict=True)])
    fast = pack_charts(uvs, faces, areas, config=PackConfig(resolution=512))
    monkeypatch.setattr(pack, "_ROUND_TEXELS", -1.0)  # every round chart at every angle
    slow = pack_charts(uvs, faces, areas, config=PackConfig(resolution=512))
    assert_valid_layout(fast, faces)
    assert fast.utilization >= slow.utilization - 0.005


# ---------------------------------------------------------------------------------------------
# trimming (PackConfig.trim): the same layout, in a texture cut to the rows it uses


def test_a_long_chart_gets_a_trimmed_texture_with_the_same_layout() -> None:
    # a 4:1 strip binds the scale by its length: it fills the width and a quarter of the height
    uv, F = grid(8, 2)
    square = pack_charts([uv], [F], [1.0], config=PackConfig(resolution=256, trim=False))
    trimmed = pack_charts([uv], [F], [1.0], config=PackConfig(resolution=256))
    assert square.size == (256, 256)
    (W, H), p = trimmed.size, trimmed.padding
    assert W == 256 and H % pack.TRIM_MULTIPLE == 0 and H <= 256 * (1 - pack.TRIM_LEAST)
    assert_valid_layout(trimmed, [F])  # padding kept to the new border too
    assert footprint_conflicts(trimmed.uvs, [F], resolution=(W, H), padding=p) == 0
    # the same layout in texels, the same density; the texture is smaller by H / 256
    np.testing.assert_allclose(in_texels(trimmed)[0], in_texels(square)[0], atol=1e-9)
    assert trimmed.scale * W == pytest.approx(square.scale * 256, rel=1e-12)
    assert trimmed.utilization == pytest.approx(square.utilization * 256 / H, rel=1e-9)
    # the strip's texels reach within padding + TRIM_MULTIPLE of the top, not closer than p
    top = in_texels(trimmed)[0][:, 1].max()
    assert H - pack.TRIM_MULTIPLE - p <= top < H - p


def test_a_layout_that_fills_its_square_is_not_trimmed() -> None:
    uvs, faces, areas = mixed_charts(30, seed=0)
    plain = pack_charts(uvs, faces, areas, config=PackConfig(resolution=192, trim=False))
    trimmed = pack_charts(uvs, faces, areas, config=PackConfig(resolution=192))
    assert trimmed.size == (192, 192)
    assert all(a.tobytes() == b.tobytes() for a, b in zip(plain.uvs, trimmed.uvs, strict=True))
    assert plain.transforms.tobytes() == trimmed.transforms.tobytes()


@pytest.mark.parametrize(
    ("top", "size"),
    [
        ((100.0, 300.0), (104, 304)),  # 100 + 1 + 2 = 103 columns, rounded up to 104
        ((99.5, 299.999), (104, 304)),  # the texel under a top of 99.5 is column 99
        ((1019.5, 500.0), (1024, 504)),  # a top on a texel line touches that texel: 501 + 2
        ((700.0, 890.0), (704, 896)),  # 893 -> 896 rows: an eighth empty, trimmed
        ((700.0, 900.0), (704, 1024)),  # 903 -> 904 rows leave less than an eighth empty
    ],
)
def test_trimmed_sides_keep_the_padding_and_round_to_blocks(top, size) -> None:
    assert pack._trimmed(np.array(top), 1024, 2) == size


def test_trimmed_layouts_stay_valid() -> None:
    # long and small charts of random shapes: whatever side is trimmed, no footprint comes
    # within the padding of another or of the texture's border
    rng = np.random.default_rng(3)
    for _ in range(6):
        uvs, faces = [], []
        for _ in range(int(rng.integers(1, 5))):
            uv, F = grid(int(rng.integers(4, 12)), int(rng.integers(1, 3)))
            uvs.append(rotate(uv * rng.uniform(0.5, 2), rng.uniform(0, np.pi)))
            faces.append(F)
        areas = [area_uv(u, F) for u, F in zip(uvs, faces, strict=True)]
        res = pack_charts(uvs, faces, areas, config=PackConfig(resolution=128, padding=2))
        assert_valid_layout(res, faces)
        assert_uniform_density(res, faces, areas)


def test_max_chart_size_keeps_the_density_of_a_trimmed_search() -> None:
    # a 9:1 strip and a square: the search stands the strip up and leaves columns empty, so its
    # texture is trimmed in width; the limited packing must keep the search's texels per unit
    # (not its uv scale times the resolution) for the chart under the limit
    strip, Fs = grid(1, 9)
    square, Fq = grid(3, 3)
    uvs, faces = [rotate(strip * 1.266, 1.71), rotate(square * 1.905, 1.01)], [Fs, Fq]
    areas = [area_uv(u, F) for u, F in zip(uvs, faces, strict=True)]
    free = pack_charts(uvs, faces, areas, config=PackConfig(resolution=128))
    assert free.width < 128  # the premise: the search's texture is trimmed in width
    sides = np.array([np.ptp(min_area_rotation(u)[0], axis=0).max() for u in in_texels(free)])
    limit = int(0.7 * sides.max())
    assert sides[1] < limit < sides[0]
    res = pack_charts(uvs, faces, areas, config=PackConfig(resolution=128, max_chart_size=limit))
    assert_valid_layout(res, faces)
    assert res.texels_per_unit == pytest.approx(free.texels_per_unit, rel=1e-9)
    square_area = area_uv(in_texels(res)[1], Fq)
    assert np.sqrt(square_area / areas[1]) == pytest.approx(free.texels_per_unit, rel=1e-9)
