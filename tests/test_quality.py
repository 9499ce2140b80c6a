import numpy as np
import pytest
from meshes import tri_grid

from segparam.quality import boundary_crossings, chart_quality, signed_areas


def fan(n=7, turns=1.0):
    """A disk of n triangles around vertex 0; in uv the ring winds `turns` times around it."""
    th = 2 * np.pi * np.arange(n) / n
    V = np.c_[np.zeros((1, 3)), np.zeros((1, 0))].reshape(1, 3)
    V = np.vstack([V, np.stack([np.cos(th), np.sin(th), 0 * th], 1)])
    F = np.stack([np.zeros(n, int), 1 + np.arange(n), 1 + (np.arange(n) + 1) % n], 1)
    phi = turns * th
    uv = np.vstack([[0, 0], np.stack([np.cos(phi), np.sin(phi)], 1)])
    return V, F, uv


def test_identity_map_is_bijective_and_isometric():
    V, F = tri_grid(8, 8)
    q = chart_quality(V, F, V[:, :2] * 3.0)  # scale does not count: uv area is normalized
    assert q.bijective and q.n_flipped == q.n_branch == q.n_crossings == 0
    assert q.l2_stretch == pytest.approx(1) and q.linf_stretch == pytest.approx(1)
    assert q.angle_distortion == pytest.approx(1) and q.area_distortion == pytest.approx(
        0, abs=1e-12
    )
    assert q.symmetric_dirichlet == pytest.approx(4)


def test_anisotropic_scaling_analytic_distortion():
    V, F = tri_grid(8, 8)
    q = chart_quality(V, F, V[:, :2] * [2.0, 1.0])
    # After area normalization s1 = sqrt 2, s2 = 1 / sqrt 2.
    assert q.bijective
    assert q.angle_distortion == pytest.approx(2.0)
    assert q.area_distortion == pytest.approx(0, abs=1e-12)
    assert q.l2_stretch == pytest.approx(np.sqrt((0.5 + 2) / 2))
    assert q.linf_stretch == pytest.approx(np.sqrt(2))
    assert q.symmetric_dirichlet == pytest.approx(2 + 0.5 + 0.5 + 2)


def test_mirrored_map_is_all_flipped():
    V, F = tri_grid(6, 6)
    q = chart_quality(V, F, V[:, :2] * [-1.0, 1.0])
    assert q.n_flipped == len(F) and not q.bijective


def test_single_flipped_triangle_is_detected():
    V, F = tri_grid(6, 6)
    uv = V[:, :2].copy()
    inner = 2 * 6 + 2  # an interior vertex pushed across its ring
    uv[inner] += [0.5, 0.0]
    q = chart_quality(V, F, uv)
    assert q.n_flipped > 0 and not q.bijective
    assert (signed_areas(uv, F) < 0).sum() == q.n_flipped


def test_branch_point_is_detected():
    V, F, uv = fan(7, turns=2.0)
    assert (signed_areas(uv, F) > 0).all()  # no flip: only the angle sum shows the problem
    q = chart_quality(V, F, uv)
    assert q.n_flipped == 0 and q.n_branch >= 1 and not q.bijective


def test_boundary_crossing_is_detected():
    # A helical strip whose uv (polar) image winds 1.25 times: no flip, no branch point.
    V, F = tri_grid(40, 4)
    th = 2.5 * np.pi * V[:, 0]
    r = 1.3 - V[:, 1] / V[:, 1].max() * 0.3  # r falls with y: counter-clockwise
    uv = np.stack([r * np.cos(th), r * np.sin(th)], 1)
    V3 = np.stack([r * np.cos(th), r * np.sin(th), V[:, 0]], 1)
    q = chart_quality(V3, F, uv)
    assert q.n_flipped == 0 and q.n_branch == 0
    assert q.n_crossings > 0 and not q.bijective


def test_boundary_crossings_counts_simple_cases():
    uv = np.array([[0, 0], [1, 1], [0, 1], [1, 0], [2, 2], [3, 3]], float)
    assert boundary_crossings(uv, np.array([[0, 1], [2, 3]])) == 1
    assert boundary_crossings(uv, np.array([[0, 1], [4, 5]])) == 0
    assert boundary_crossings(uv, np.array([[0, 1], [1, 4]])) == 0  # shared endpoint


def test_hole_with_wrong_orientation_is_not_bijective():
    # An annulus whose inner loop is mapped outside (reflected radius): loops wrongly oriented.
    n = 16
    th = 2 * np.pi * np.arange(n) / n
    ring = lambda r: np.stack([r * np.cos(th), r * np.sin(th), 0 * th], 1)  # noqa: E731
    V = np.vstack([ring(1.0), ring(2.0)])
    a, b = np.arange(n), (np.arange(n) + 1) % n
    F = np.concatenate([np.stack([a, b + n, b], 1), np.stack([a, a + n, b + n], 1)])
    q = chart_quality(V, F, V[:, :2])
    assert q.bijective and q.loops_oriented
    uv = V[:, :2] * np.r_[np.full(n, 3.0), np.full(n, 1.0)][:, None]  # inner ring pushed outside
    q2 = chart_quality(V, F, uv)
    assert not q2.bijective
