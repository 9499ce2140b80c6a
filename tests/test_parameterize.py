from pathlib import Path

import numpy as np
import pytest
from meshes import (
    cone_patch,
    cylinder_patch,
    folded_strip,
    procrustes_residual,
    rigid,
    saddle,
    spherical_cap,
    tri_grid,
)

from segparam.errors import InvalidMeshError
from segparam.mesh import edges, face_areas, vertex_adjacency
from segparam.parameterize import (
    HessianSolver,
    _design,
    _groups,
    hessian_matrix,
    ill_conditioned,
    local_hessians,
    neighbourhoods,
    parameterize_chart,
    tangent_frames,
    vertex_weights,
)
from segparam.quality import signed_areas


def _parcel(name: str) -> tuple[np.ndarray, np.ndarray]:
    """A cortical parcel kept as data (``tests/data/parcels.npz``): ``"folded"``, whose pair of
    eq. 3 folds it over globally (a thin curved band) and which the pairs (0, 2) and (0, 3)
    map, not (1, 3); ``"plain"``, which the pair of eq. 3 maps; ``"dependent"``, whose second
    eigenvector is nearly a function of the first. Cut by
    ``brain_like_parcels(80, mean_faces=460, min_faces=380, max_faces=560,
    connectivity="icosahedral", seed=s)[i]`` (folded and plain: s = 4, i = 52 and 0; dependent:
    s = 0, i = 33) under numpy 2.4.6 and scipy 1.17.1, and stored: that generator's recursive
    spectral bisection (ARPACK) cuts other parcels under other library versions, and the parcel
    these tests once took from it stopped folding after an upgrade."""
    with np.load(Path(__file__).parent / "data" / "parcels.npz") as data:
        return data[f"{name}_V"], data[f"{name}_F"].astype(np.int64)


def test_plane_is_isometric_up_to_rigid_motion():
    V, F = tri_grid(15, 15)
    chart = parameterize_chart(V, F)
    assert chart.bijective
    assert chart.uv.shape == (len(V), 2) and chart.uv.dtype == np.float64
    assert procrustes_residual(chart.uv, V[:, :2]) < 1e-8
    assert chart.quality.angle_distortion == pytest.approx(1, abs=1e-6)


def test_large_plane_goes_through_the_sparse_solver():
    V, F = tri_grid(30, 30)  # 900 vertices: above the dense limit
    chart = parameterize_chart(rigid(V, seed=3), F)
    assert chart.bijective and procrustes_residual(chart.uv, V[:, :2]) < 1e-6


@pytest.mark.parametrize("shape", [cylinder_patch, cone_patch])
def test_developable_patches_unroll_with_low_distortion(shape):
    V, F = shape()
    chart = parameterize_chart(V, F)
    assert chart.bijective
    assert chart.quality.angle_distortion < 1.01
    assert chart.quality.l2_stretch < 1.01


@pytest.mark.parametrize("shape, bound", [(spherical_cap, 1.1), (saddle, 1.1)])
def test_doubly_curved_patches_are_bijective_with_low_distortion(shape, bound):
    V, F = shape()
    chart = parameterize_chart(V, F)
    assert chart.bijective and chart.quality.angle_distortion < bound


def test_folded_strip_unfolds():
    V, F = folded_strip()
    chart = parameterize_chart(V, F)
    assert chart.bijective and chart.quality.angle_distortion < 1.02


def test_classic_hlle_is_worse_on_a_folded_strip():
    # The paper's comparison: the raw eigenmaps, without the ARAP refinement.
    V, F = folded_strip()
    ours = parameterize_chart(V, F, refine="none")
    classic = parameterize_chart(V, F, method="classic-hlle", refine="none")
    assert ours.bijective and not classic.bijective
    assert classic.quality.n_flipped > 10 * max(ours.quality.n_flipped, 1)


def test_refinement_lowers_distortion_and_is_kept_only_when_not_worse():
    V, F = spherical_cap()
    raw = parameterize_chart(V, F, refine="none")
    refined = parameterize_chart(V, F)
    assert raw.bijective and refined.bijective and refined.refined and not raw.refined
    assert refined.quality.angle_distortion < raw.quality.angle_distortion
    assert refined.quality.symmetric_dirichlet < raw.quality.symmetric_dirichlet


def test_arap_refine_keeps_an_isometric_map():
    V, F = cylinder_patch()
    chart = parameterize_chart(V, F, refine="none")
    from segparam.parameterize import arap_refine

    uv = arap_refine(V, F, chart.uv, iterations=5)
    assert procrustes_residual(uv, chart.uv) < 1e-2 * np.ptp(chart.uv)


def test_refinement_is_skipped_on_a_rigid_map_but_not_on_a_flipped_one():
    from segparam.parameterize import _arap

    V, F = tri_grid(8, 8)
    uv = V[:, :2].copy()
    same, steps = _arap(V, F, uv, iterations=10, tol=1e-4, min_decrease=0.01)
    assert steps == 0 and np.array_equal(same, uv - uv[0])
    # One interior vertex pushed across its neighbours: the map is nearly rigid by area but has
    # flipped triangles, so the iterations still run and undo the flips.
    centre = np.argmin(np.linalg.norm(V[:, :2] - V[:, :2].mean(axis=0), axis=1))
    bent = uv.copy()
    bent[centre] += 2.5 * np.linalg.norm(V[F[0, 1]] - V[F[0, 0]]) * np.array([1.0, 0.3])
    fixed, steps = _arap(V, F, bent, iterations=10, tol=1e-4, min_decrease=0.01)
    assert steps > 0
    assert (signed_areas(bent, F) < 0).any() and (signed_areas(fixed, F) > 0).all()


def test_solver_skips_refinement_of_a_developable_chart():
    V, F = cylinder_patch()
    chart = parameterize_chart(V, F)
    assert chart.bijective and not chart.refined


def test_pca_tangent_option_runs_and_is_recorded():
    V, F = saddle()
    chart = parameterize_chart(V, F, tangent="pca")
    assert chart.tangent == "pca" and chart.bijective


def test_tangent_planes_average_the_normals_over_rings():
    # smoothing=0 is the paper's plane (sec. 3.1): normal to the average of the adjacent
    # triangle normals; averaged again over rings, the planes of a flat chart are still its plane,
    # and those of a cylinder stay within 10 degrees of the radial normal.
    from segparam.mesh import vertex_normals

    V, F = cylinder_patch()
    ptr, idx = neighbourhoods(V, F)
    b1, b2 = tangent_frames(V, F, ptr, idx, smoothing=0)
    assert np.allclose(np.cross(b1, b2), vertex_normals(V, F))
    radial = V * [1, 1, 0] / np.linalg.norm(V[:, :2], axis=1, keepdims=True)
    for smoothing in (1, 4):
        b1, b2 = tangent_frames(V, F, ptr, idx, smoothing=smoothing)
        cos = np.abs((np.cross(b1, b2) * radial).sum(axis=1))
        assert cos.min() > np.cos(np.radians(10))  # 3.1 deg unsmoothed, 7.4 after 4 rounds
    V, F = tri_grid(8, 8)
    ptr, idx = neighbourhoods(V, F)
    b1, b2 = tangent_frames(rigid(V, seed=1), F, ptr, idx)
    n = np.cross(b1, b2)
    assert np.allclose(n, n[0]) and np.allclose(np.linalg.norm(n, axis=1), 1)


def test_eq6_local_hessian_on_exact_quadratics():
    # Seven points in the plane; quadratics are fitted exactly, so f^T C f = ||Hess f||_F^2.
    th = np.linspace(0, 2 * np.pi, 7)[:-1]
    P = np.vstack([[0, 0], np.stack([np.cos(th), np.sin(th)], 1) * 0.3])
    V = np.c_[P, np.zeros(7)]
    N = np.arange(7)[None]
    C = local_hessians(V, N, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))[0]
    u, v = P[:, 0], P[:, 1]
    cases = {
        "u^2": (u**2, 4.0),  # Hessian [[2, 0], [0, 0]]
        "uv": (u * v, 2.0),  # [[0, 1], [1, 0]]
        "v^2": (v**2, 4.0),
        "3u^2 - 2uv": (3 * u**2 - 2 * u * v, 36.0 + 2 * 4.0),
        "linear": (2 * u - v + 1, 0.0),
    }
    for name, (f, expected) in cases.items():
        assert f @ C @ f == pytest.approx(expected, abs=1e-9), name
    assert np.allclose(C, C.T)


def test_eq8_9_partition_of_unity_and_assembly():
    V, F = tri_grid(12, 10)
    w = vertex_weights(V, F)
    assert w.sum() == pytest.approx(face_areas(V, F).sum())  # phi_i sum to one (eq. 7, 8)
    K = hessian_matrix(V, F)
    assert abs(K - K.T).max() < 1e-9 * abs(K).max()
    one = np.ones(len(V))
    assert np.abs(K @ one).max() < 1e-9 * abs(K).max()
    x, y = V[:, 0], V[:, 1]
    assert abs(x @ K @ x) < 1e-9 * abs(K).max()  # linear functions: zero Hessian
    # f = x^2 has ||Hess||_F^2 = 4 everywhere, so f^T K f = sum_i w_i * 4 = 4 * area (eq. 9).
    f = x**2 + 0.5 * y
    assert f @ K @ f == pytest.approx(4 * face_areas(V, F).sum(), rel=1e-9)


def test_neighbourhoods_are_one_rings_with_minimal_extension():
    V, F = tri_grid(8, 8)
    ptr, idx = neighbourhoods(V, F)
    sizes = np.diff(ptr)
    E, _ = edges(F)
    degree = np.bincount(E.ravel(), minlength=len(V))
    assert (idx[ptr[:-1]] == np.arange(len(V))).all()  # the vertex itself first
    assert (sizes == np.maximum(degree + 1, 6)).all()
    for i in range(len(V)):
        N = idx[ptr[i] : ptr[i + 1]]
        assert len(set(N.tolist())) == len(N)


def test_neighbourhood_extension_takes_the_next_rings_nearest_first():
    # Brute force: hop distances from a shortest-path search; every extension point comes from
    # the nearest rings (a ring is used only when the previous one is exhausted), and from the
    # last ring it uses, the points nearest in space.
    from scipy.sparse.csgraph import shortest_path

    V, F = tri_grid(9, 7)
    V = V + 0.05 * np.random.default_rng(3).normal(size=V.shape)
    extra = np.random.default_rng(4).integers(0, 5, len(V))
    ptr, idx = neighbourhoods(V, F, min_points=7, extra=extra)
    A = vertex_adjacency(F, len(V))
    hops = shortest_path(A, unweighted=True)
    degree = np.diff(A.indptr)
    for i in range(len(V)):
        N = idx[ptr[i] : ptr[i + 1]]
        one = 1 + degree[i]
        assert N[0] == i and set(N[1:one].tolist()) == set(A[[i]].indices.tolist())
        assert len(N) == max(7, one) + extra[i] and len(set(N.tolist())) == len(N)
        ext = N[one:]
        if len(ext) == 0:
            continue
        h = hops[i, ext]
        assert (np.diff(h) >= 0).all() and h[0] >= 2
        last = h[-1]
        inner = np.flatnonzero((hops[i] >= 2) & (hops[i] < last))
        assert set(inner.tolist()) <= set(ext.tolist())
        ring = np.flatnonzero(hops[i] == last)
        taken = ext[h == last]
        d = np.linalg.norm(V[ring] - V[i], axis=1)
        assert np.linalg.norm(V[taken] - V[i], axis=1).max() <= np.sort(d)[len(taken) - 1]


@pytest.mark.parametrize("min_rcond", [0.03, 0.1, 0.16])
def test_ill_conditioned_matches_the_eigenvalue_definition(min_rcond):
    # A jittered cap: its boundary fits are poor, its interior ones spread around 0.1-0.2, so
    # every threshold here splits the vertices and the Cholesky screen must not change a verdict.
    V, F = spherical_cap()
    V = V + 0.2 * np.random.default_rng(0).normal(size=V.shape) * np.sqrt(face_areas(V, F).mean())
    ptr, idx = neighbourhoods(V, F)
    b1, b2 = tangent_frames(V, F, ptr, idx)
    rcond = np.empty(len(V))
    for rows, N in _groups(ptr, idx):
        u, v, _ = _design(V, N, b1[rows], b2[rows])
        P = np.stack([u * u, u * v, v * v, u, v, np.ones_like(u)], axis=2)
        sv = np.linalg.svd(P, compute_uv=False)
        rcond[rows] = sv[:, -1] / sv[:, 0]
    expected = rcond < min_rcond
    assert 0 < expected.sum() < len(V), expected.sum()
    assert np.array_equal(ill_conditioned(V, ptr, idx, b1, b2, min_rcond), expected)
    subset = np.arange(0, len(V), 3)
    only = ill_conditioned(V, ptr, idx, b1, b2, min_rcond, subset)
    assert (
        np.array_equal(only[subset], expected[subset]) and not only[np.arange(1, len(V), 3)].any()
    )


def test_invariant_under_rigid_motion_and_uniform_scale():
    V, F = spherical_cap(15, 15)
    base = parameterize_chart(V, F)
    for seed, scale in [(1, 1.0), (2, 1e3), (3, 1e-3)]:
        moved = parameterize_chart(rigid(V, seed=seed, scale=scale), F)
        assert moved.bijective
        assert procrustes_residual(moved.uv / scale, base.uv) < 1e-6 * np.ptp(base.uv)
        assert moved.quality.angle_distortion == pytest.approx(base.quality.angle_distortion)


def test_orientation_keeps_the_input_winding():
    V, F = saddle(12, 12)
    a = parameterize_chart(V, F)
    b = parameterize_chart(V, F[:, ::-1])  # reversed winding: the chart must not be mirrored
    assert a.bijective and b.bijective and a.quality.n_flipped == b.quality.n_flipped == 0


def test_deterministic_for_a_seed():
    V, F = saddle(30, 30)
    a = parameterize_chart(V, F, seed=5)
    b = HessianSolver(V, F).solve(seed=5)
    assert np.array_equal(a.uv, b.uv)


def tetra():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    return V, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def octahedron():
    V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    F = np.array(
        [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    )
    return V, F


def test_bad_charts_raise_with_the_reason():
    V, F = tri_grid(5, 5)
    with pytest.raises(InvalidMeshError, match="closed"):
        parameterize_chart(*octahedron())
    with pytest.raises(InvalidMeshError, match="at least 6"):
        parameterize_chart(*tetra())
    with pytest.raises(InvalidMeshError, match="2 connected components"):
        parameterize_chart(np.vstack([V, V + 5]), np.vstack([F, F + len(V)]))
    with pytest.raises(InvalidMeshError, match="unreferenced"):
        parameterize_chart(np.vstack([V, [[9, 9, 9]]]), F)
    with pytest.raises(InvalidMeshError, match="manifold"):
        Vb = np.vstack([V, V[[0, 1, 5]] + [0, 0, 1]])
        Fb = np.vstack([F, [[0, 1, len(V) + 2]]])  # a third face on a boundary edge... then a fin
        Fb = np.vstack([Fb, [[1, 0, len(V) + 1]], [[0, 1, len(V)]]])
        parameterize_chart(Vb, Fb)
    with pytest.raises(InvalidMeshError):
        parameterize_chart(V[:, :2], F)
    with pytest.raises(ValueError, match="method"):
        parameterize_chart(V, F, method="lscm")


# --------------------------------------------------------------------------------------------------
# many small charts at once


def _union(charts):
    """Disjoint union of (V, F) charts, chart by chart, and every vertex's chart."""
    offsets = np.cumsum([0] + [len(V) for V, _ in charts])
    V = np.vstack([V for V, _ in charts])
    F = np.vstack([F + o for (_, F), o in zip(charts, offsets, strict=False)])
    return V, F, np.repeat(np.arange(len(charts)), np.diff(offsets))


def _small_charts():
    """Charts of 16 to 49 vertices: caps, a saddle, a cylinder patch, a plane (rigidly moved)."""
    caps = [spherical_cap(n, n, extent=e) for n, e in ((5, 1.2), (6, 1.6), (7, 1.0), (5, 1.6))]
    V, F = tri_grid(5, 4)
    return caps + [saddle(6, 5, k=2.0), cylinder_patch(6, 4), (rigid(V, seed=2), F)]


@pytest.mark.parametrize("refine, tangent", [("arap", "normals"), ("none", "pca")])
def test_solve_charts_is_the_solver_chart_by_chart(refine, tangent):
    from segparam.parameterize import quality_records, solve_charts

    charts = _small_charts()
    V, F, vert_chart = _union(charts)
    maps = solve_charts(V, F, vert_chart, tangent=tangent, refine=refine)
    for k, ((Vc, Fc), q) in enumerate(zip(charts, quality_records(maps.quality), strict=True)):
        ref = parameterize_chart(Vc, Fc, tangent=tangent, refine=refine)
        uv = maps.uv[vert_chart == k]
        assert procrustes_residual(uv, ref.uv) < 1e-9 * np.ptp(ref.uv)  # up to a rigid motion
        assert uv.min(axis=0) == pytest.approx([0, 0], abs=1e-12)  # as ChartMap.uv
        assert maps.refined[k] == ref.refined
        assert maps.eigenvalues[k] == pytest.approx(ref.eigenvalues, rel=1e-6, abs=1e-9)
        for name, value in ref.quality.as_dict().items():
            assert getattr(q, name) == pytest.approx(value, rel=1e-9, abs=1e-12), name


def test_solve_charts_reports_the_charts_too_small_for_the_solver_and_maps_the_others():
    from segparam.parameterize import quality_records, solve_charts

    def bent(nx, ny):
        V, F = tri_grid(nx, ny)
        return np.c_[V[:, :2], 0.3 * np.sin(3 * V[:, 0]) * V[:, 1]], F

    # strips of two rows: a vertex cannot find 6 points, and the solver alone raises on them
    charts = [bent(4, 2), bent(3, 3), bent(5, 2), bent(4, 3), spherical_cap(5, 5)]
    starved = [True, False, True, False, False]
    V, F, vert_chart = _union(charts)
    maps = solve_charts(V, F, vert_chart, refine="slim")
    assert maps.starved.tolist() == starved
    for k, ((Vc, Fc), q) in enumerate(zip(charts, quality_records(maps.quality), strict=True)):
        if starved[k]:
            with pytest.raises(InvalidMeshError, match="cannot find"):
                parameterize_chart(Vc, Fc, refine="slim")
            assert not q.bijective
            continue
        ref = parameterize_chart(Vc, Fc, refine="slim")
        assert procrustes_residual(maps.uv[vert_chart == k], ref.uv) < 1e-9 * np.ptp(ref.uv)
        assert q.bijective == ref.quality.bijective and q.l2_stretch == pytest.approx(
            ref.quality.l2_stretch, rel=1e-9
        )


def test_charts_quality_is_chart_quality_chart_by_chart():
    from segparam.parameterize import charts_quality, quality_records
    from segparam.quality import chart_quality

    # Good and bad maps side by side: flipped triangles, a fold, a mirror, a hole, a crossing.
    V, F = tri_grid(6, 6)
    uv = V[:, :2].copy()
    folded = uv.copy()
    folded[V[:, 0] > 0.6, 0] = 1.2 - folded[V[:, 0] > 0.6, 0]  # fold the right part over
    bent = uv.copy()
    bent[14] += [0.5, 0.1]  # one vertex across its neighbours
    C = V[F].mean(axis=1)
    keep = np.hypot(C[:, 0] - 0.5, C[:, 1] - 0.45) > 0.15
    used, Fh = np.unique(F[keep], return_inverse=True)
    annulus = (V[used], Fh.reshape(-1, 3))  # a disk with a hole
    cases = [
        (V, F, uv),
        (V, F, folded),
        (V, F, bent),
        (V, F, uv * [-1.0, 1.0]),
        (annulus[0], annulus[1], annulus[0][:, :2]),
        (annulus[0], annulus[1], annulus[0][:, :2] * [1.0, -1.0]),
    ]
    Vu, Fu, vert_chart = _union([(v, f) for v, f, _ in cases])
    uvu = np.vstack([u for _, _, u in cases])
    got = quality_records(charts_quality(Vu, Fu, uvu, vert_chart, len(cases)))
    bijective = []
    for (v, f, u), q in zip(cases, got, strict=True):
        ref = chart_quality(v, f, u)
        bijective.append(ref.bijective)
        for name, value in ref.as_dict().items():
            assert type(getattr(q, name)) is type(value), name
            assert getattr(q, name) == pytest.approx(value, rel=1e-12, abs=1e-12), name
    assert bijective == [True, False, False, False, True, False]
    assert got[1].n_crossings > 0 and got[2].n_flipped > 0 and not got[3].loops_oriented
    # measured on some charts alone (the batched refinement's starting maps where ARAP's map
    # is not bijective): the same figures, bit for bit; the other charts keep `like`'s
    from segparam.parameterize import _some_charts_quality
    from segparam.quality import inverse_frames, triangle_frames

    full = charts_quality(Vu, Fu, uvu, vert_chart, len(cases))
    vstart = np.flatnonzero(np.r_[True, np.diff(vert_chart) > 0])
    n_faces = np.bincount(vert_chart[Fu[:, 0]], minlength=len(cases))
    frames = inverse_frames(triangle_frames(Vu, Fu))
    which = np.array([False, True, False, True, True, False])
    like = {k: np.zeros_like(v) for k, v in full.items()}
    some = _some_charts_quality(Vu, Fu, uvu, vert_chart, vstart, n_faces, frames, which, like)
    for name, value in full.items():
        np.testing.assert_array_equal(some[name][which], value[which], err_msg=name)
        np.testing.assert_array_equal(some[name][~which], like[name][~which], err_msg=name)


@pytest.mark.parametrize("seed", range(8))
def test_the_compiled_boundary_topology_is_the_sorted_one(seed):
    """``charts_quality``'s compiled boundary passes against the numpy and scipy forms they
    replaced: the boundary half-edges (``mesh.boundary_edges``, same order), their pieces
    (``mesh.boundary_pieces``: scipy's connected components, same numbering) and each chart's
    crossing count (``quality.boundary_crossings``: a k-d tree of the midpoints) on maps
    jittered until their boundaries cross many times, of charts with holes and pinched
    boundaries (two loops through one vertex)."""
    from segparam.mesh import boundary_edges, boundary_pieces
    from segparam.parameterize import _charts_crossings
    from segparam.quality import boundary_crossings
    from segparam.topology import boundary_half_edges as compiled_edges
    from segparam.topology import boundary_pieces as compiled_pieces

    rng = np.random.default_rng(seed)
    parts = []
    for _ in range(4):
        V, F = tri_grid(int(rng.integers(3, 9)), int(rng.integers(3, 9)))
        F = F[rng.random(len(F)) > 0.25]  # holes, pinches, pieces
        used, F = np.unique(F, return_inverse=True)
        parts.append((V[used], F.reshape(-1, 3)))
    Vu, Fu, vert_chart = _union(parts)
    n = len(Vu)
    B = compiled_edges(Fu, n)
    np.testing.assert_array_equal(B, boundary_edges(Fu))
    for got, want in zip(compiled_pieces(B, n), boundary_pieces(B), strict=True):
        np.testing.assert_array_equal(got, want)
    uv = Vu[:, :2] + rng.normal(scale=0.05 * (seed % 4), size=(n, 2))
    chart = vert_chart[B[:, 0]]
    want = [boundary_crossings(uv, B[chart == c]) for c in range(len(parts))]
    np.testing.assert_array_equal(_charts_crossings(uv, B, vert_chart, len(parts)), want)
    if seed % 4 == 3:
        assert sum(want) > 10


def test_the_compiled_segment_test_is_the_array_one():
    """``_segments_cross`` (one pair, compiled) against ``quality.segment_pairs_cross`` on every
    pair of 60 segments with small integer ends: many touch, overlap collinearly or share an
    endpoint index, where the tests' ``<=`` and ``==`` decide."""
    from segparam.parameterize import _segments_cross
    from segparam.quality import segment_pairs_cross

    rng = np.random.default_rng(0)
    B = rng.integers(0, 40, size=(60, 2))
    uv = rng.integers(0, 4, size=(40, 2)).astype(float)
    P0, P1 = uv[B[:, 0]], uv[B[:, 1]]
    i, j = np.triu_indices(len(B), 1)
    want = segment_pairs_cross(P0, P1, B, i, j)
    got = [_segments_cross(P0, P1, B, a, b) for a, b in zip(i.tolist(), j.tolist(), strict=True)]
    np.testing.assert_array_equal(got, want)
    assert want.sum() > 100


@pytest.mark.parametrize("seed", range(6))
def test_the_compiled_arap_steps_are_the_sparse_ones_bit_for_bit(seed):
    """ARAP's local step and right-hand side (``_arap_local``, ``gradient_transpose``) against
    the sparse and array forms they replaced, to the last bit: ``G = D uv``, the closest
    rotations, each chart's area-weighted energy and flip flag, ``D^T (w R^T)``; faces naming a
    vertex twice included (the matrix sums such entries)."""
    from segparam.parameterize import (
        _arap_local,
        _chart_sum,
        _gradient_operator,
    )
    from segparam.quality import inverse_frames, triangle_frames
    from segparam.refine import _gradient_coefficients, gradient_transpose

    rng = np.random.default_rng(seed)
    n, m, n_charts = 30, 80, 3
    V = rng.normal(size=(n, 3))
    F = np.array([rng.choice(n, 3, replace=False) for _ in range(m)])
    if seed % 2 == 0:
        F[:5, 1] = F[:5, 0]  # a repeated corner
    with np.errstate(divide="ignore", invalid="ignore"):  # the repeated corners' frames
        frames = inverse_frames(triangle_frames(V, F))
    frames[~np.isfinite(frames)] = 1.0
    D = _gradient_operator(V, F, frames)
    uv = rng.normal(size=(n, 2))
    area = rng.random(m)
    face_chart = np.sort(rng.integers(0, n_charts, size=m))
    G = (D @ uv).reshape(-1, 2, 2)
    p, q = G[:, 0, 0] + G[:, 1, 1], G[:, 0, 1] - G[:, 1, 0]
    r = np.hypot(p, q)
    r[r == 0] = 1.0
    p, q = p / r, q / r
    Rt = np.stack([np.stack([p, q], 1), np.stack([-q, p], 1)], 1)
    energy = _chart_sum(face_chart, ((G - Rt) ** 2).sum(axis=(1, 2)) * area, n_charts)
    det = G[:, 0, 0] * G[:, 1, 1] - G[:, 0, 1] * G[:, 1, 0]
    flipped = np.bincount(face_chart, weights=det <= 0, minlength=n_charts) > 0
    coef = _gradient_coefficients(frames)
    got_Rt, got_energy, got_flipped = _arap_local(F, coef, uv, area, face_chart, n_charts)
    assert got_Rt.tobytes() == Rt.tobytes() and got_energy.tobytes() == energy.tobytes()
    np.testing.assert_array_equal(got_flipped, flipped)
    rhs = D.T @ (np.repeat(area, 2)[:, None] * Rt.reshape(-1, 2))
    got_rhs = gradient_transpose(F, np.arange(m), coef, area[:, None, None] * Rt, n)
    assert got_rhs.tobytes() == rhs.tobytes()


@pytest.mark.parametrize("seed", range(6))
def test_the_compiled_poisson_matrix_is_the_sparse_one_bit_for_bit(seed):
    """ARAP's Poisson matrix over the free vertices (``poisson_entries``) against the sparse
    product it replaced, ``(D^T diag(w) D)[free][:, free]``, entry for entry and to the last
    bit: random faces (odd seeds: some naming a vertex twice), random areas, pinned vertices;
    and a grid of right triangles, whose diagonals' entries cancel to zeros scipy drops."""
    import scipy.sparse as sp

    from segparam.parameterize import _gradient_operator
    from segparam.quality import inverse_frames, triangle_frames
    from segparam.refine import _gradient_coefficients, poisson_entries

    rng = np.random.default_rng(seed)
    if seed < 5:
        n, m = 30, 80
        V = rng.normal(size=(n, 3))
        F = np.array([rng.choice(n, 3, replace=False) for _ in range(m)])
        if seed % 2:
            F[:5, 1] = F[:5, 0]  # a repeated corner
        area = rng.random(m)
    else:  # unit squares cut along a diagonal: the diagonals' entries cancel to exactly 0
        x, y = np.meshgrid(np.arange(4.0), np.arange(3.0))
        V = np.c_[x.ravel(), y.ravel(), np.zeros(12)]
        a = (np.arange(3) + 4 * np.arange(2)[:, None]).ravel()
        F = np.r_[np.c_[a, a + 1, a + 5], np.c_[a, a + 5, a + 4]]
        n, m = len(V), len(F)
        area = np.full(m, 0.5)
    with np.errstate(divide="ignore", invalid="ignore"):  # the repeated corners' frames
        frames = inverse_frames(triangle_frames(V, F))
    frames[~np.isfinite(frames)] = 1.0
    free = rng.random(n) > 0.1
    D = _gradient_operator(V, F, frames)
    want = (D.T @ sp.diags(np.repeat(area, 2)) @ D).tocsc()[free][:, free].tocoo()
    rank = np.where(free, np.cumsum(free) - 1, -1)
    rows, cols, vals = poisson_entries(F, _gradient_coefficients(frames), area, rank)
    want_entries = sorted(
        zip(want.row.tolist(), want.col.tolist(), want.data.tolist(), strict=True)
    )
    assert list(zip(rows.tolist(), cols.tolist(), vals.tolist(), strict=True)) == want_entries
    if seed == 5:  # the grid: pairs of free corners of a face whose entry summed to zero
        pairs = {(a, b) for f in rank[F].tolist() for a in f for b in f if a >= 0 and b >= 0}
        assert len(pairs) > len(want_entries)


def test_isometric_fit_undoes_a_stretch_by_hand():
    """Y = X R S (a rotation, then a stretch along the axes): M = S^-2 fits every triangle
    exactly (G_t^T M G_t = I), A = M^(1/2) = S^-1, so uv = Y S^-1 = X R, the flat chart rotated."""
    from segparam.parameterize import isometric_fit

    V, F = tri_grid(5, 4)  # z = 0: the 3-D chart is its own flat layout X = V[:, :2]
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, -s], [s, c]])
    S = np.diag([3.0, 0.25])
    uv = isometric_fit(V, F, V[:, :2] @ R @ S)
    np.testing.assert_allclose(uv, V[:, :2] @ R, atol=1e-12)
    # A rotation alone is already isometric: A = I.
    np.testing.assert_allclose(isometric_fit(V, F, V[:, :2] @ R), V[:, :2] @ R, atol=1e-12)


def test_classic_hlle_matrix_of_six_points_is_the_projector_off_affine_functions():
    """With 6 points every neighbourhood is all of them and Y = [1, u, v, u^2, uv, v^2] is
    square: its last three Gram-Schmidt columns span the complement of span(1, u, v), so each
    W_i = I - P with P the projector onto the affine functions, and K = 6 (I - P)."""
    from segparam.parameterize import classic_hlle_matrix

    X = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [2.0, 0.5], [0.3, 2.0]])  # on no conic
    tilt = np.array([[1.0, 0, 0.5], [0, 1, -0.25]])  # a plane through the origin, tilted
    V = X @ tilt + [3.0, -1, 2]
    A = np.column_stack([np.ones(6), X])
    P = A @ np.linalg.pinv(A)
    K = classic_hlle_matrix(V, n_neighbors=12).toarray()
    np.testing.assert_allclose(K, 6 * (np.eye(6) - P), atol=1e-10)
    np.testing.assert_allclose(K @ A, 0, atol=1e-10)  # constants and coordinates: no Hessian


def test_a_folded_eigenmap_is_refined_from_the_next_eigenvector_pair(monkeypatch):
    # A parcel of the realistic icosahedral cortex whose paper's pair folds over globally (a
    # thin curved band; without the eigenvector selection of DEPENDENT_R2): ARAP cannot undo it;
    # refined from the pair (0, 2) it is bijective (FALLBACK_PAIRS), in the chart-by-chart solver
    # and in the batched one alike.
    import segparam.parameterize as parameterize
    from segparam.parameterize import solve_charts

    V, F = _parcel("folded")
    monkeypatch.setattr(parameterize, "DEPENDENT_R2", 1.0)  # the pair of eq. 3, always
    solver = HessianSolver(V, F)
    assert not solver.solve(refine="none").bijective
    chart = solver.solve()
    assert chart.bijective and chart.refined
    maps = solve_charts(V, F, np.zeros(len(V), dtype=np.int64))
    assert maps.quality["bijective"][0] and maps.refined[0]
    assert procrustes_residual(maps.uv, chart.uv) < 1e-6 * np.ptp(chart.uv)
    # in a batch: this parcel twice around one the paper's pair maps (the fallback refines the
    # failing charts together), each chart the one-by-one solver's map
    pieces = [(V, F), _parcel("plain"), (V, F)]
    offsets = np.cumsum([0] + [len(p[0]) for p in pieces])
    Vb = np.concatenate([p[0] for p in pieces])
    Fb = np.concatenate([p[1] + o for p, o in zip(pieces, offsets, strict=False)])
    maps = solve_charts(Vb, Fb, np.repeat(np.arange(3), np.diff(offsets)))
    assert maps.quality["bijective"].all() and maps.refined[[0, 2]].all()
    for c, (Vc, Fc) in enumerate(pieces):
        alone = HessianSolver(Vc, Fc).solve()
        uv_c = maps.uv[offsets[c] : offsets[c + 1]]
        assert procrustes_residual(uv_c, alone.uv) < 1e-6 * np.ptp(alone.uv)
    monkeypatch.setattr(parameterize, "FALLBACK_PAIRS", ())
    assert not solver.solve().bijective


@pytest.mark.parametrize(
    "pairs, kept",
    [(((0, 3), (0, 2)), (0, 3)), (((0, 2), (0, 3)), (0, 2)), (((1, 3), (0, 3), (0, 2)), (0, 3))],
)
def test_the_batched_fallback_keeps_the_first_pair_that_maps_bijectively(monkeypatch, pairs, kept):
    # The folded parcel above maps bijectively from the pairs (0, 2) and (0, 3), not from (1, 3).
    # The batched solver refines every pair of every failing chart at once; each chart keeps
    # its first bijective pair in FALLBACK_PAIRS' order, as the chart-by-chart solver does.
    import segparam.parameterize as parameterize
    from segparam.parameterize import solve_charts

    monkeypatch.setattr(parameterize, "DEPENDENT_R2", 1.0)  # the pair of eq. 3, always
    V, F = _parcel("folded")
    monkeypatch.setattr(parameterize, "FALLBACK_PAIRS", (kept,))
    want = HessianSolver(V, F).solve()
    monkeypatch.setattr(parameterize, "FALLBACK_PAIRS", pairs)
    alone = HessianSolver(V, F).solve()
    assert want.bijective and procrustes_residual(alone.uv, want.uv) < 1e-6 * np.ptp(want.uv)
    other = next(p for p in ((0, 2), (0, 3)) if p != kept)
    monkeypatch.setattr(parameterize, "FALLBACK_PAIRS", (other,))
    assert procrustes_residual(HessianSolver(V, F).solve().uv, want.uv) > 0.01 * np.ptp(want.uv)
    monkeypatch.setattr(parameterize, "FALLBACK_PAIRS", pairs)
    pieces = [_parcel("plain"), (V, F)]
    offsets = np.cumsum([0] + [len(p[0]) for p in pieces])
    Vb = np.concatenate([p[0] for p in pieces])
    Fb = np.concatenate([p[1] + o for p, o in zip(pieces, offsets, strict=False)])
    maps = solve_charts(Vb, Fb, np.repeat(np.arange(2), np.diff(offsets)))
    assert maps.quality["bijective"].all() and maps.refined[1]
    uv = maps.uv[offsets[1] :]
    assert procrustes_residual(uv, want.uv) < 1e-6 * np.ptp(want.uv)


def test_a_tube_is_not_tried_again_from_other_eigenvector_pairs(monkeypatch):
    """A chart with two boundary loops (the wall of a drilled hole: an open tube) has no
    bijective near-isometric map; neither solver refines it again from other pairs
    (``FALLBACK_PAIRS`` are for disks), and its map is reported as not bijective."""
    import segparam.parameterize as parameterize
    from segparam.parameterize import solve_charts

    n_theta, n_z = 24, 6
    theta = 2 * np.pi * np.arange(n_theta) / n_theta
    z = np.linspace(0.0, 1.5, n_z)
    V = np.stack([np.repeat(np.cos(theta)[None], n_z, 0), np.repeat(np.sin(theta)[None], n_z, 0),
                  np.repeat(z[:, None], n_theta, 1)], -1).reshape(-1, 3)  # fmt: skip
    i, j = (a.ravel() for a in np.meshgrid(np.arange(n_z - 1), np.arange(n_theta), indexing="ij"))
    a, b = i * n_theta + j, i * n_theta + (j + 1) % n_theta
    F = np.concatenate(
        [np.stack([a, b, b + n_theta], 1), np.stack([a, b + n_theta, a + n_theta], 1)]
    )
    tried = []
    real = parameterize._other_pairs
    monkeypatch.setattr(
        parameterize, "_other_pairs", lambda *a, **k: tried.append(1) or real(*a, **k)
    )
    assert not HessianSolver(V, F).solve(refine="slim").bijective
    maps = solve_charts(V, F, np.zeros(len(V), dtype=np.int64), refine="slim")
    assert not maps.quality["bijective"][0]
    assert tried == []


def test_a_second_eigenvector_that_is_a_function_of_the_first_is_replaced(monkeypatch):
    # A parcel whose second eigenvector is nearly a quadratic of the first (the pair of
    # eq. 3 folds it over a curve); the selection takes the third and the raw map is bijective,
    # in the chart-by-chart solver and in the batched one alike.
    import segparam.parameterize as parameterize
    from segparam.linalg import smallest_eigenpairs
    from segparam.parameterize import DEPENDENT_R2, explained_by_first, solve_charts
    from segparam.quality import chart_quality, inverse_frames, triangle_frames

    V, F = _parcel("dependent")
    solver = HessianSolver(V, F)
    r2 = explained_by_first(smallest_eigenpairs(solver.K, 4)[1][None])[0]  # of h2, h3 on h1
    assert r2[0] > DEPENDENT_R2 and r2[1] < r2[0]
    chart = solver.solve(refine="none")
    assert chart.bijective
    maps = solve_charts(V, F, np.zeros(len(V), dtype=np.int64), refine="none")
    assert maps.quality["bijective"][0]
    assert procrustes_residual(maps.uv, chart.uv) < 1e-6 * np.ptp(chart.uv)
    # the fallback then starts from the pair of eq. 3 instead of the (0, 2) already taken
    frames = inverse_frames(triangle_frames(solver._Vn, F))
    first = next(parameterize._other_pairs(solver._Vn, F, solver.K, frames))
    assert chart_quality(solver._Vn, F, first).n_flipped > 0
    first = next(parameterize._other_pairs(solver._Vn, F, solver.K, frames, select=False))
    assert chart_quality(solver._Vn, F, first).bijective
    monkeypatch.setattr(parameterize, "DEPENDENT_R2", 1.0)
    assert not solver.solve(refine="none").bijective


def test_explained_by_first_is_the_r2_of_a_function_of_the_first():
    from segparam.parameterize import DEPENDENT_R2, explained_by_first

    rng = np.random.default_rng(0)
    x = rng.uniform(-1, 1, 300)
    cases = [
        (x**2 - 2 * x**4, True),  # a polynomial of h1: R^2 = 1
        (np.cos(3 * x) + 0.1 * rng.normal(size=300), True),  # a smooth function, noisy
        (rng.uniform(-1, 1, 300), False),  # a second coordinate
        (x**2 + rng.uniform(-1, 1, 300), False),  # a fold of one, over a band's width
    ]
    vectors = np.column_stack([np.ones(300), x] + [h for h, _ in cases])[None]
    r2 = explained_by_first(vectors)[0]
    assert r2[0] == pytest.approx(1.0)
    assert list(r2 > DEPENDENT_R2) == [dependent for _, dependent in cases]
    assert np.all((r2 >= 0) & (r2 <= 1 + 1e-12))


def test_explained_by_first_of_a_stack_is_each_charts_own():
    # charts of one size are measured together: each gets what it gets alone
    from segparam.parameterize import explained_by_first

    rng = np.random.default_rng(2)
    x = rng.uniform(-1, 1, (3, 40))
    vectors = np.stack(
        [
            np.column_stack([np.ones(40), x[b], x[b] ** 2 + b * rng.uniform(-1, 1, 40)])
            for b in range(3)
        ]
    )
    together = explained_by_first(vectors)
    alone = np.concatenate([explained_by_first(vectors[b : b + 1]) for b in range(3)])
    np.testing.assert_array_equal(together, alone)
    assert together[0, 0] == pytest.approx(1.0) and together[2, 0] < 0.7


def test_a_first_coordinate_of_two_values_explains_nothing_it_is_not():
    """Across a one-row strip the first coordinate takes two values (x^2 = 1): its higher powers
    add nothing, and the rounding noise left of them must not explain the second coordinate."""
    from segparam.parameterize import explained_by_first

    rng = np.random.default_rng(1)
    s = 130
    h1 = np.where(np.arange(s) % 2 == 0, 1.0, -1.0)
    h2 = np.repeat(np.linspace(-1.0, 1.0, s // 2), 2)  # along the strip
    h1_noisy = h1 + 1e-10 * h2 + 1e-12 * rng.normal(size=s)  # an eigensolver's rounding
    vectors = np.column_stack([np.ones(s), h1_noisy, h2, h1_noisy * 0.5 + h2**2])[None]
    r2 = explained_by_first(vectors)[0]
    assert r2[0] < 1e-6  # along the strip: nothing of it is a function of the two rows
    assert r2[1] == pytest.approx(0.25 / (0.25 + np.var(h2**2) / np.var(h1_noisy)), rel=1e-3)


def test_a_mixed_null_space_is_read_with_the_constant_first():
    """A developable chart's linear coordinate is as exactly in K's null space as the constant,
    and an eigensolver returns any rotation of the two: the selection reads them with the
    constant first (the other vectors in order, orthonormal), and leaves a null space that comes
    with the constant first as it is, bit for bit."""
    from segparam.parameterize import _constant_first

    rng = np.random.default_rng(2)
    s = 50
    c = np.full(s, 1 / np.sqrt(s))
    basis = np.linalg.qr(np.column_stack([c, rng.normal(size=(s, 3))]))[0]
    basis[:, 0] = c  # the constant, h1, h2, h3: orthonormal
    t = 0.6
    mixed = basis.copy()
    mixed[:, 0] = np.cos(t) * basis[:, 0] + np.sin(t) * basis[:, 1]
    mixed[:, 1] = -np.sin(t) * basis[:, 0] + np.cos(t) * basis[:, 1]
    out = _constant_first(np.stack([mixed, basis]))
    np.testing.assert_allclose(out[0, :, 0], c, atol=1e-12)
    for j in range(1, 4):  # each coordinate up to its sign
        assert abs(out[0, :, j] @ basis[:, j]) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_array_equal(out[1], basis)


def test_a_one_row_hole_wall_cut_open_maps_from_the_papers_pair():
    """The wall of a drilled hole one row of triangles high (the CAD plate's), cut open: its
    null space holds the constant and the height, both exactly; the selection keeps the
    height and the length round the hole, whose raw map is bijective, so no fallback pair is
    tried."""
    import segparam.parameterize as parameterize
    from segparam.mesh import annulus_cut, cut_along

    n = 64
    t = 2 * np.pi * np.arange(n) / n
    V = np.concatenate([np.stack([np.cos(t), np.sin(t), np.full(n, z)], 1) for z in (-0.8, 0.8)])
    a, b = np.arange(n), (np.arange(n) + 1) % n
    F = np.concatenate([np.stack([a, b, b + n], 1), np.stack([a, b + n, a + n], 1)])
    F_cut, src = cut_along(F, annulus_cut(V, F))
    solver = HessianSolver(V[src], F_cut)
    assert solver.solve(refine="none").bijective
    maps = parameterize.solve_charts(V[src], F_cut, np.zeros(len(src), dtype=np.int64))
    assert maps.quality["bijective"][0] and maps.quality["l2_stretch"][0] < 1.001


def test_unfolded_normals_turn_only_planes_that_fold_an_adjacent_triangle():
    # A flat grid (every triangle normal +z) with every normal +z but one, tilted 80 degrees: only
    # that one is turned, towards +z, just past FOLD_MIN_COS (candidates in steps of 1/10).
    from segparam.parameterize import FOLD_MIN_COS, unfolded_normals

    V, F = tri_grid(6, 6)
    normal = np.tile([0.0, 0.0, 1.0], (len(V), 1))
    i = 17
    tilt = np.radians(80)
    normal[i] = [np.sin(tilt), 0.0, np.cos(tilt)]
    out = unfolded_normals(V, F, normal)
    others = np.arange(len(V)) != i
    np.testing.assert_array_equal(out[others], normal[others])
    assert np.linalg.norm(out[i]) == pytest.approx(1.0)
    assert FOLD_MIN_COS <= out[i, 2] < np.cos(np.radians(60))
    assert out[i, 1] == pytest.approx(0.0, abs=1e-12)  # turned in the plane of tilt and +z
    assert unfolded_normals(V, F, out) is out  # nothing left to turn


def _unfolded_normals_batched(V, F, normal, min_cos):
    """unfolded_normals as batched numpy (its form before the search was compiled): every vertex
    to turn at once, 40 subgradient steps, 10 candidate planes."""
    from segparam.mesh import face_normals

    fn = face_normals(V, F)
    n = len(V)

    def least_cos(nrm, iv, jf, count):
        cos = np.einsum("ij,ij->i", nrm[iv], fn[jf])
        least = np.full(count, np.inf)
        np.minimum.at(least, iv, cos)
        worst = np.zeros(count, dtype=np.int64)
        hit = cos <= least[iv]
        worst[iv[hit]] = jf[hit]
        return least, worst

    iv, jf = F.ravel(), np.repeat(np.arange(len(F)), 3)
    least, _ = least_cos(normal, iv, jf, n)
    turn = np.flatnonzero(least < min_cos)
    local = np.full(n, -1)
    local[turn] = np.arange(len(turn))
    keep = local[iv] >= 0
    iv, jf = local[iv[keep]], jf[keep]
    start = normal[turn]
    m, best, best_cos = start.copy(), start.copy(), least[turn].copy()
    for k in range(40):
        cos, worst = least_cos(m, iv, jf, len(turn))
        better = cos > best_cos
        best[better], best_cos[better] = m[better], cos[better]
        m = m + (0.5 / np.sqrt(k + 1)) * fn[worst]
        m /= np.linalg.norm(m, axis=1, keepdims=True)
    out, done = best.copy(), np.zeros(len(turn), dtype=bool)
    for s in np.arange(1, 11) / 10:
        c = (1 - s) * start + s * best
        c /= np.maximum(np.linalg.norm(c, axis=1, keepdims=True), 1e-300)
        take = ~done & (least_cos(c, iv, jf, len(turn))[0] >= min_cos)
        out[take], done = c[take], done | take
    normal = normal.copy()
    normal[turn] = out
    return normal, len(turn)


def test_unfolded_normals_are_the_batched_search_bit_for_bit():
    # the max-min search runs vertex by vertex, compiled: the same numbers as the batched form
    from segparam.parameterize import (
        FOLD_MIN_COS,
        MAXMIN_CANDIDATES,
        MAXMIN_STEPS,
        unfolded_normals,
    )

    assert (MAXMIN_STEPS, MAXMIN_CANDIDATES) == (40, 10)
    rng = np.random.default_rng(3)
    V, F = tri_grid(12, 12)
    V = np.column_stack([V[:, :2], 0.3 * rng.standard_normal(len(V))])  # a crumpled sheet
    normal = rng.standard_normal((len(V), 3)) + [0.0, 0.0, 2.0]
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    want, n_turned = _unfolded_normals_batched(V, F, normal, FOLD_MIN_COS)
    assert n_turned > 20
    np.testing.assert_array_equal(unfolded_normals(V, F, normal), want)


def test_the_eigenvector_selection_on_a_large_chart_is_the_dense_one(monkeypatch):
    # Above DENSE_LIMIT the fourth eigenvector comes from the sparse solver, started from the
    # three already found: forced on a 1,600-vertex strip (every chart switches whose third
    # eigenvector is less a function of the first than the second), it spans (h1, h3) as the
    # dense solve does.
    import segparam.parameterize as parameterize
    from segparam.linalg import smallest_eigenpairs
    from segparam.parameterize import hessian_eigenmap

    V, F = folded_strip()
    solver = HessianSolver(V, F)
    assert len(V) > 400  # linalg.DENSE_LIMIT
    monkeypatch.setattr(parameterize, "DEPENDENT_R2", -1.0)
    Y = hessian_eigenmap(solver.K, guess=np.column_stack([np.ones(len(V)), solver._Vn]))[0]
    _, vectors = smallest_eigenpairs(solver.K, 4, dense_limit=len(V))
    X = vectors[:, [1, 3]] - vectors[:, [1, 3]].mean(axis=0)
    X /= np.linalg.norm(X, axis=0)
    assert np.linalg.norm(Y @ (Y.T @ X) - X) < 1e-5
