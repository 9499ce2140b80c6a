"""The bulk paths for many small charts: every chart at once, the same charts as one by one.

A mesh of disjoint triangles and small closed parts (the case these paths exist for) is
segmented and parameterized; the bulk results are checked against the definitions (every face in
one chart, every chart a bijective, unmirrored disk) and against the per-chart path.
"""

import numpy as np
import pytest
import trimesh
from meshes import plate_with_holes, procrustes_residual, tri_grid

import segparam.split as split
from segparam.mesh import connected_components, disk_labels, is_disk, label_topology
from segparam.quality import chart_quality, signed_areas
from segparam.segment import segment
from segparam.split import SplitConfig, chart_face_cover, parameterize_charts


def soup(n_tri=50, n_parts=10, seed=0):
    """``n_tri`` disjoint random triangles, ``n_parts`` small spheres (80 faces) and two small
    tori (48 faces), scattered."""
    rng = np.random.default_rng(seed)
    centre = rng.uniform(0, 10, (n_tri, 1, 3))
    V = [(centre + rng.normal(0, 0.2, (n_tri, 3, 3))).reshape(-1, 3)]
    F = [np.arange(3 * n_tri).reshape(-1, 3)]
    s = trimesh.creation.icosphere(1)
    t = trimesh.creation.torus(0.6, 0.25, major_sections=8, minor_sections=3)
    parts = [s] * n_parts + [t, t]
    for k, part in enumerate(parts):
        offset = sum(len(v) for v in V)
        r = rng.uniform(0.3, 1.0) if k < n_parts else 1.0
        V.append(
            np.asarray(part.vertices) * r + rng.uniform(0, 10, 3) + [12.0 * (k >= n_parts), 0, 0]
        )
        F.append(np.asarray(part.faces) + offset)
    return np.vstack(V), np.vstack(F).astype(np.int64)


def per_chart(V, F, labels, **kw):
    """parameterize_charts with the bulk path off: every chart through _solve_source."""
    bulk = split._bulk_charts
    split._bulk_charts = lambda *a, **k: {}
    try:
        return parameterize_charts(V, F, labels, **kw)
    finally:
        split._bulk_charts = bulk


# --------------------------------------------------------------------------------------------------
# topology of many face sets at once


def _random_labels(V, F, rng, k, scatter=None):
    """``k`` random labels: scattered face by face, or Voronoi cells of random faces."""
    if scatter is None:
        scatter = rng.random() < 0.5
    if scatter:
        return np.unique(rng.integers(0, k, len(F)), return_inverse=True)[1].ravel()
    C = V[F].mean(axis=1)
    centres = C[rng.choice(len(F), k, replace=False)]
    return np.argmin(((C[:, None] - centres[None]) ** 2).sum(-1), axis=1)


@pytest.mark.parametrize(
    "make",
    [
        lambda: tri_grid(12, 12),
        plate_with_holes,
        lambda: (lambda m: (np.asarray(m.vertices), np.asarray(m.faces)))(
            trimesh.creation.torus(2.0, 0.7, major_sections=12, minor_sections=6)
        ),
    ],
)
def test_disk_labels_is_is_disk_per_label(make):
    V, F = make()
    rng = np.random.default_rng(0)
    for _ in range(12):
        labels = _random_labels(V, F, rng, int(rng.integers(1, 25)))
        ref = [is_disk(F[labels == c]) for c in range(labels.max() + 1)]
        assert np.array_equal(disk_labels(F, labels), ref)
        ref = [is_disk(F[labels == c], holes=False) for c in range(labels.max() + 1)]
        assert np.array_equal(disk_labels(F, labels, holes=False), ref)


def test_label_topology_sees_orientation_and_empty_labels():
    V, F = tri_grid(6, 6)
    left = V[F].mean(axis=1)[:, 0] < 0.5
    labels = np.where(left, 0, 2)  # label 1 has no faces
    F = F.copy()
    f = np.flatnonzero(left)[len(np.flatnonzero(left)) // 2]
    F[f] = F[f, ::-1]  # against its neighbours' winding: label 0 is not edge-manifold
    t = label_topology(F, labels)
    assert t["faces"].tolist() == [left.sum(), 0, (~left).sum()]
    assert t["edge_manifold"].tolist() == [False, True, True]
    assert disk_labels(F, labels).tolist() == [False, False, True]
    assert not is_disk(F[labels == 0]) and is_disk(F[labels == 2])


@pytest.mark.parametrize("seed", range(12))
def test_label_topology_is_each_labels_own_topology(seed):
    """``label_topology`` (compiled, all labels at once) against the per-mesh functions on each
    label's faces alone: faces, vertices, edges, edge and vertex manifoldness, vertex-connected
    pieces, boundary loops, Euler characteristic. Grids and a torus cut in random labels, some
    faces turned against their neighbours, and face soups with repeated corners."""
    from segparam.mesh import (
        boundary_edges,
        boundary_pieces,
        edges,
        is_edge_manifold,
        is_vertex_manifold,
    )

    rng = np.random.default_rng(seed)
    if seed < 4:
        _, F = tri_grid(9, 7)
    elif seed < 8:
        m = trimesh.creation.torus(2.0, 0.7, major_sections=10, minor_sections=5)
        F = np.asarray(m.faces)
    else:
        F = rng.integers(0, 25, size=(120, 3))  # repeated corners, non-manifold everything
    F = F.copy()
    turn = rng.random(len(F)) < 0.05
    F[turn] = F[turn][:, ::-1]
    labels = rng.integers(0, int(rng.integers(1, 12)), len(F))
    n_labels = int(labels.max()) + 2  # and an empty label
    t = label_topology(F, labels, n_labels)
    for c in range(n_labels):
        Fc = F[labels == c]
        if len(Fc) == 0:
            assert t["faces"][c] == t["vertices"][c] == t["edges"][c] == 0
            continue
        used, Fc = np.unique(Fc, return_inverse=True)
        Fc = Fc.reshape(-1, 3)
        E, h2e = edges(Fc)
        B = boundary_edges(Fc)
        loops = boundary_pieces(B)[2] if len(B) else 0
        n_comp = connected_components(Fc, by="vertex")[0]
        want = [len(Fc), len(used), len(E), is_edge_manifold(Fc),
                bool(is_vertex_manifold(Fc, len(used)).all()), n_comp, loops,
                len(used) - len(E) + len(Fc)]  # fmt: skip
        got = [t[k][c] for k in ("faces", "vertices", "edges", "edge_manifold",
                                 "vertex_manifold", "components", "loops", "euler")]  # fmt: skip
        assert got == want, c


# --------------------------------------------------------------------------------------------------
# segment: small parts without spectral clustering


def test_small_parts_become_disks_in_bulk():
    V, F = soup()
    seg = segment(V, F)
    n_comp, comp = connected_components(F)
    assert (np.bincount(seg.labels) > 0).all()  # every face in exactly one chart, no empty one
    assert disk_labels(F, seg.labels).all()
    assert all(is_disk(F[seg.labels == c]) for c in range(seg.n_charts))
    for c in range(seg.n_charts):  # no chart spans two parts
        assert len(np.unique(comp[seg.labels == c])) == 1
    charts_per_part = np.array([len(np.unique(seg.labels[comp == k])) for k in range(n_comp)])
    faces = np.bincount(comp)
    assert (charts_per_part[faces == 1] == 1).all()  # a triangle is one chart
    assert (charts_per_part[faces > 1] >= 2).all()  # a closed part is cut
    # The spheres whose share is two charts are halved by count, as the Fiedler bisection does
    # (a larger one, three charts by its share of the area, is clustered).
    halved = (faces == 80) & (charts_per_part == 2)
    assert halved.sum() >= 5
    assert (np.bincount(seg.labels)[np.unique(seg.labels[halved[comp]])] == 40).all()


def test_halving_cuts_across_the_principal_axis():
    from segparam.segment import _halve_tiny, _within, face_affinity

    # A capsule-like closed part, long in x: the two halves are its two ends.
    m = trimesh.creation.capsule(height=3.0, radius=0.5, count=[8, 8])
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    labels = np.zeros(len(F), dtype=np.int64)
    W = face_affinity(V, F)
    C = V[F].mean(axis=1)
    axis = np.argmax(np.ptp(V, axis=0))
    out, n = _halve_tiny(C, labels, np.array([0]), _within(W, labels), 1)
    assert n == 2 and abs(np.bincount(out)[0] - np.bincount(out)[1]) <= 1
    assert C[out == 0, axis].max() <= C[out == 1, axis].min() or (
        C[out == 1, axis].max() <= C[out == 0, axis].min()
    )
    assert disk_labels(F, out).all()
    # Two pieces in one label: cut into its pieces first.
    labels = np.where(C[:, axis] < np.median(C[:, axis]) - 1.0, 0, 1)
    labels[C[:, axis] > np.median(C[:, axis]) + 1.0] = 0  # label 0: both ends, apart
    out, n = _halve_tiny(C, labels, np.array([0]), _within(W, labels), 2)
    assert n == 3 and set(np.unique(out)) == {0, 1, 2}
    assert np.array_equal(out == 1, labels == 1)


def test_spectral_clustering_gives_scikit_learns_labels():
    from sklearn.cluster import SpectralClustering

    from segparam.segment import _cluster, face_affinity
    from segparam.synthetic import brain_like_surface

    V, F = brain_like_surface(2000, seed=1)
    W = face_affinity(V, F)
    for k in (3, 6):
        ref = SpectralClustering(
            n_clusters=k,
            affinity="precomputed",
            assign_labels="cluster_qr",
            eigen_solver="arpack",
            random_state=0,
        ).fit_predict(W)
        assert np.array_equal(_cluster(W, k, 0), ref)


# --------------------------------------------------------------------------------------------------
# parameterize: small charts in bulk


def check_charts(V, F, cs):
    assert (chart_face_cover(cs.charts, len(F)) == 1).all()  # every face exactly once
    for c in cs.charts:
        assert np.array_equal(F[c.faces], c.vertices[c.local_F])
        assert is_disk(c.local_F)
        q = chart_quality(V[c.vertices], c.local_F, c.uv)  # bijective, loops oriented
        assert q.bijective and c.quality.bijective
        assert (signed_areas(c.uv, c.local_F) > 0).all()  # the input winding: no mirror
        for name, value in q.as_dict().items():
            assert getattr(c.quality, name) == pytest.approx(value, rel=1e-7, abs=1e-12), name


def assert_same_charts(a, b):
    """The bulk result ``a`` is the per-chart result ``b``: the same pieces, methods and
    figures; projections the same uv, solver maps the same up to a rigid motion."""
    assert np.array_equal(a.splits, b.splits)
    assert np.array_equal(a.first_pass_bijective, b.first_pass_bijective)
    assert len(a.charts) == len(b.charts)
    for x, y in zip(a.charts, b.charts, strict=True):
        assert (x.method, x.source, x.depth) == (y.method, y.source, y.depth)
        for name in ("faces", "vertices", "local_F"):
            assert np.array_equal(getattr(x, name), getattr(y, name))
            assert getattr(x, name).dtype == getattr(y, name).dtype
        scale = np.ptp(y.uv, axis=0).max()
        if x.method == "hessian":
            assert procrustes_residual(x.uv, y.uv) < 1e-9 * scale
        else:
            np.testing.assert_allclose(x.uv, y.uv, rtol=0, atol=1e-12 * scale)
        for name, value in y.quality.as_dict().items():
            got = getattr(x.quality, name)
            assert type(got) is type(value), name
            assert got == pytest.approx(value, rel=1e-9, abs=1e-12), name


def test_small_charts_map_in_bulk_as_one_by_one():
    V, F = soup()
    seg = segment(V, F)
    cs = parameterize_charts(V, F, seg.labels)
    check_charts(V, F, cs)
    methods = {c.method for c in cs.charts}
    assert methods == {"projection", "hessian"}  # triangles projected, halves solved
    assert_same_charts(cs, per_chart(V, F, seg.labels))


def test_bulk_and_per_chart_agree_on_failures_and_splits():
    # Small Voronoi cells of a CAD plate and of a torus: planar, projected, solved, pinched and
    # failing pieces (left to the per-chart path, which splits them) in one chart set.
    rng = np.random.default_rng(2)
    torus = trimesh.creation.torus(2.0, 0.7, major_sections=16, minor_sections=8)
    for (V, F), cells, cfg in (
        (plate_with_holes(), 20, SplitConfig()),
        (
            (np.asarray(torus.vertices), np.asarray(torus.faces)),
            16,
            SplitConfig(max_distortion=1.05),
        ),
    ):
        labels = _random_labels(V, F, rng, cells, scatter=False)
        labels = np.unique(labels, return_inverse=True)[1].ravel()
        cs = parameterize_charts(V, F, labels, config=cfg)
        assert cs.splits.any() and cs.first_pass_bijective.any()  # both paths have work
        check_charts(V, F, cs)
        assert_same_charts(cs, per_chart(V, F, labels, config=cfg))


def test_one_triangle_charts_keep_the_planar_method_conventions():
    V, F = soup(n_tri=30, n_parts=0)
    F = F[:30]
    cs = parameterize_charts(V, F, np.arange(30))
    assert [c.method for c in cs.charts] == ["projection"] * 30
    assert not cs.first_pass_bijective.any() and not cs.splits.any()  # as _try_piece says
    for c in cs.charts:
        assert c.uv.shape == (3, 2) and c.local_F.tolist() == [[0, 1, 2]]
        # Rigid: the uv triangle has the 3-D triangle's side lengths.
        P = V[F[c.faces[0]]]
        for i, j in ((0, 1), (1, 2), (0, 2)):
            assert np.linalg.norm(c.uv[i] - c.uv[j]) == pytest.approx(np.linalg.norm(P[i] - P[j]))


def test_pieces_past_max_depth_are_projected_in_bulk_as_one_by_one(monkeypatch):
    # Big Voronoi cells of a torus with a tight angle target and a shallow max_depth: the rounds'
    # pieces past max_depth are only projected (and split again where a projection fails), as
    # _try_piece does to each alone, but in one batch per round.
    rng = np.random.default_rng(2)
    torus = trimesh.creation.torus(2.0, 0.7, major_sections=24, minor_sections=12)
    V, F = np.asarray(torus.vertices), np.asarray(torus.faces)
    labels = np.unique(_random_labels(V, F, rng, 6, scatter=False), return_inverse=True)[1]
    cfg = SplitConfig(max_depth=2, max_distortion=1.02)
    alone = []
    try_piece = split._try_piece

    def counted(V, F, faces, src, depth, *args):
        alone.append(depth)
        return try_piece(V, F, faces, src, depth, *args)

    monkeypatch.setattr(split, "_try_piece", counted)
    cs = parameterize_charts(V, F, labels.ravel(), config=cfg)
    deep = [c for c in cs.charts if c.depth > cfg.max_depth]
    assert len(deep) > 20 and {c.method for c in deep} == {"projection"}
    assert max(len(c.faces) for c in deep) >= cfg.min_faces  # projected whatever their size
    assert not [d for d in alone if d > cfg.max_depth]  # none of them alone
    check_charts(V, F, cs)
    monkeypatch.setattr(split, "_try_piece", try_piece)
    assert_same_charts(cs, per_chart(V, F, labels.ravel(), config=cfg))
