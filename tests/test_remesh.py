"""Tests of segparam.remesh: quality measures, the auto policy, and remeshing invariants."""

from __future__ import annotations

import numpy as np
import pytest
from meshes import cylinder_patch, rigid, saddle, tri_grid
from scipy.spatial import Delaunay, cKDTree

from segparam.errors import ConfigError
from segparam.mesh import (
    boundary_edges,
    boundary_loops,
    connected_components,
    euler_characteristic,
    face_areas,
    face_normals,
    genus,
    is_edge_manifold,
    is_vertex_manifold,
)
from segparam.remesh import (
    RemeshConfig,
    closest_boundary_points,
    equal_area_edge,
    mesh_quality,
    remesh,
    should_remesh,
)


def equilateral_grid(nx: int = 12, ny: int = 11):
    """An exactly equilateral triangulation (unit edges) of a parallelogram-free strip."""
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    x = i + 0.5 * (j % 2)
    y = j * np.sqrt(3) / 2
    V = np.stack([x.ravel(), y.ravel(), np.zeros(nx * ny)], axis=1)
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    even = (np.arange(ny - 1) % 2 == 0)[None, :, None]
    t1 = np.where(even, np.stack([a, b, d], -1), np.stack([a, b, c], -1))
    t2 = np.where(even, np.stack([b, c, d], -1), np.stack([a, c, d], -1))
    return V, np.concatenate([t1.reshape(-1, 3), t2.reshape(-1, 3)]).astype(np.int64)


def square_grid(nx: int, ny: int):
    """The unit square, an ``nx`` x ``ny`` vertex grid, every cell cut along one diagonal."""
    i, j = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny), indexing="ij")
    V = np.stack([i.ravel(), j.ravel(), np.zeros(nx * ny)], axis=1)
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    F = np.r_[np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    return V, F.astype(np.int64)


def sliver_patch(n: int = 300, seed: int = 0, *, hole: bool = False):
    """Delaunay triangulation of random points on a bumpy square (many slivers), optionally
    with a square hole; wound counter-clockwise seen from +z."""
    rng = np.random.default_rng(seed)
    P = rng.random((n, 2))
    s = np.linspace(0, 1, 18, endpoint=False)
    z, o = np.zeros_like(s), np.ones_like(s)
    P = np.r_[np.c_[s, z], np.c_[o, s], np.c_[1 - s, o], np.c_[z, 1 - s], P]
    if hole:
        P = P[np.abs(P - 0.5).max(axis=1) > 0.15]
        t = np.linspace(0, 1, 6, endpoint=False)
        lo, hi = 0.35 + 0.3 * t, 0.65 - 0.3 * t
        c0, c1 = np.full_like(t, 0.35), np.full_like(t, 0.65)
        P = np.r_[P, np.c_[lo, c0], np.c_[c1, lo], np.c_[hi, c1], np.c_[c0, hi]]
    F = Delaunay(P).simplices
    if hole:
        F = F[np.abs(P[F].mean(axis=1) - 0.5).max(axis=1) > 0.15]
    a, b, c = P[F[:, 0]], P[F[:, 1]], P[F[:, 2]]
    cw = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]) < 0
    F[cw] = F[cw][:, ::-1]
    V = np.c_[P, 0.15 * np.sin(3 * P[:, 0]) * np.cos(2 * P[:, 1])]
    return V, F.astype(np.int64)


def topology(F):
    return (
        connected_components(F)[0],
        len(boundary_loops(F)),
        euler_characteristic(F),
        genus(F),
    )


# ---------------------------------------------------------------------------------------------
# mesh_quality: analytic values
# ---------------------------------------------------------------------------------------------


def test_quality_of_equilateral_grid():
    q = mesh_quality(*equilateral_grid())
    assert q.min_angle == pytest.approx(60.0)
    assert q.min_angle_p1 == pytest.approx(60.0)
    assert q.frac_small_angles == 0.0
    assert q.valence_std == 0.0 and q.frac_irregular == 0.0
    assert q.edge_cv == pytest.approx(0.0, abs=1e-12)
    assert q.mean_edge == pytest.approx(1.0)
    assert equal_area_edge(*equilateral_grid()) == pytest.approx(1.0)


def test_quality_of_right_isoceles_grid():
    # Angles 45, 45, 90; valence 6 inside; 2 n (n - 1) unit edges and (n - 1)^2 diagonals.
    n = 6
    V, F = square_grid(n, n)
    q = mesh_quality(V * (n - 1), F)
    assert q.min_angle == pytest.approx(45.0)
    assert q.valence_std == 0.0
    lengths = np.r_[np.ones(2 * n * (n - 1)), np.full((n - 1) ** 2, np.sqrt(2))]
    assert q.mean_edge == pytest.approx(lengths.mean())
    assert q.edge_cv == pytest.approx(lengths.std() / lengths.mean())


def test_quality_is_rigid_invariant():
    V, F = sliver_patch()
    q0, q1 = mesh_quality(V, F), mesh_quality(rigid(V, seed=3), F)
    assert q1.min_angle_p1 == pytest.approx(q0.min_angle_p1)
    assert q1.valence_std == q0.valence_std and q1.edge_cv == pytest.approx(q0.edge_cv)


# ---------------------------------------------------------------------------------------------
# Policy
# ---------------------------------------------------------------------------------------------


def test_policy_keeps_regular_grids():
    for V, F in (tri_grid(20, 20), saddle(20, 20), cylinder_patch(30, 20)):
        go, reason = should_remesh(mesh_quality(V, F))
        assert not go
        assert "regular" in reason and "valence std 0.00" in reason


def test_policy_keeps_thin_but_regular_grid():
    V, F = tri_grid(8, 80, height=1.0)  # squeezed ~10:1, valence 6 inside
    q = mesh_quality(V, F)
    assert q.frac_small_angles > 0.5
    assert not should_remesh(q)[0]


def test_policy_remeshes_slivers():
    go, reason = should_remesh(mesh_quality(*sliver_patch()))
    assert go
    assert reason.startswith("slivers")


def test_auto_mode_follows_policy():
    V, F = saddle(20, 20)
    res = remesh(V, F)
    assert not res.remeshed and res.V is V and res.F is F and res.target_edge is None
    assert res.after == res.before
    assert remesh(*sliver_patch()).remeshed


# ---------------------------------------------------------------------------------------------
# Remeshing: improvement and invariants
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sliver_result():
    V, F = sliver_patch(400, seed=1, hole=True)
    return V, F, remesh(V, F, config=RemeshConfig(mode="on"))


def test_remesh_improves_min_angle(sliver_result):
    V, F, res = sliver_result
    assert res.remeshed
    assert res.before.min_angle_p1 < 10.0
    assert res.after.min_angle_p1 > 2 * res.before.min_angle_p1
    assert res.after.frac_small_angles < res.before.frac_small_angles / 3
    # The default target keeps the face count within 20%.
    assert 0.8 < len(res.F) / len(F) < 1.25


def test_remesh_preserves_topology_and_boundary(sliver_result):
    V, F, res = sliver_result
    assert topology(res.F) == topology(F) == (1, 2, 0, 0)
    assert is_edge_manifold(res.F) and is_vertex_manifold(res.F, len(res.V)).all()
    assert face_areas(res.V, res.F).min() > 1e-6 * res.target_edge**2
    assert np.bincount(res.F.ravel(), minlength=len(res.V)).min() > 0
    # Every boundary vertex lies on the input boundary polyline ...
    B = np.unique(boundary_edges(res.F))
    dist, _ = closest_boundary_points(V, F, res.V[B])
    assert dist.max() < 1e-9
    # ... and every input boundary vertex (the corners included) is still covered by it.
    B0 = np.unique(boundary_edges(F))
    dist0, _ = closest_boundary_points(res.V, res.F, V[B0])
    assert dist0.max() < 0.05 * res.target_edge
    # Holes stay holes: both loops keep about their length.
    loops = [
        [np.linalg.norm(X[lp] - X[np.roll(lp, 1)], axis=1).sum() for lp in boundary_loops(G)]
        for X, G in ((V, F), (res.V, res.F))
    ]
    assert np.allclose(loops[0], loops[1], rtol=0.02), loops


def test_remesh_keeps_orientation(sliver_result):
    V, F, res = sliver_result
    _, nearest = cKDTree(V[F].mean(axis=1)).query(res.V[res.F].mean(axis=1))
    dots = (face_normals(res.V, res.F) * face_normals(V, F)[nearest]).sum(axis=1)
    assert np.mean(dots > 0) > 0.99
    # The same after flipping the input: the output follows.
    res2 = remesh(V, F[:, ::-1], config=RemeshConfig(mode="on"))
    _, nearest = cKDTree(V[F].mean(axis=1)).query(res2.V[res2.F].mean(axis=1))
    dots = (face_normals(res2.V, res2.F) * face_normals(V, F)[nearest]).sum(axis=1)
    assert np.mean(dots < 0) > 0.99


def test_remesh_keeps_sharp_feature():
    # A square grid of thin triangles folded by 90 degrees along its middle column x = 1.
    V, F = square_grid(17, 40)
    x = 2 * V[:, 0]
    V = np.c_[np.minimum(x, 1.0), V[:, 1], np.maximum(x - 1.0, 0.0)]
    res = remesh(V, F, config=RemeshConfig(mode="on", feature_angle=30.0))
    assert res.remeshed
    # Every vertex stays on one of the two planes (smoothing did not cut the corner) ...
    assert np.all((res.V[:, 0] > 1.0 - 1e-9) | (res.V[:, 2] < 1e-9))
    # ... and the crease is still a line of edges: its vertices span it.
    crease = res.V[(np.abs(res.V[:, 0] - 1.0) < 1e-9) & (res.V[:, 2] < 1e-9)]
    assert len(crease) >= 5 and np.ptp(crease[:, 1]) > 0.99


def test_remesh_off_returns_input():
    V, F = sliver_patch()
    res = remesh(V, F, config=RemeshConfig(mode="off"))
    assert res.V is V and res.F is F and not res.remeshed and res.reason == "remeshing is off"


@pytest.mark.parametrize("scale", [0.7, 1.3])
def test_remesh_honours_target_edge(scale):
    V, F = cylinder_patch(30, 20)
    target = scale * mesh_quality(V, F).mean_edge
    res = remesh(V, F, config=RemeshConfig(mode="on", target_edge=target))
    assert res.target_edge == target
    assert abs(res.after.mean_edge / target - 1) < 0.25


def test_remesh_rigid_invariant_counts():
    V, F = sliver_patch(300, seed=4)
    a = remesh(V, F, config=RemeshConfig(mode="on"))
    b = remesh(rigid(V, seed=5, scale=3.0), F, config=RemeshConfig(mode="on"))
    assert abs(len(a.F) - len(b.F)) < 0.05 * len(a.F)
    assert b.target_edge == pytest.approx(3.0 * a.target_edge)


# ---------------------------------------------------------------------------------------------
# Configuration errors
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, text",
    [
        ({"mode": "always"}, "'always'"),
        ({"target_edge": -0.5}, "-0.5"),
        ({"target_edge": 0.0}, "0.0"),
        ({"feature_angle": 200.0}, "200.0"),
        ({"iterations": 0}, "iterations is 0"),
        ({"iterations": 2.5}, "2.5"),
    ],
)
def test_bad_config_raises(kwargs, text):
    with pytest.raises(ConfigError, match=text.replace(".", r"\.")):
        RemeshConfig(**kwargs)


def test_bad_config_type_raises():
    with pytest.raises(ConfigError, match="RemeshConfig"):
        remesh(*tri_grid(5, 5), config={"mode": "on"})
