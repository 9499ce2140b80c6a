import numpy as np
import pytest
import trimesh
from meshes import folded_strip, plate_with_holes, tri_grid

from segparam.errors import ConfigError, InvalidMeshError
from segparam.mesh import boundary_edges
from segparam.quality import chart_quality
from segparam.segment import divide, segment
from segparam.split import SplitConfig, chart_face_cover, parameterize_charts, project_chart


def check_chart_set(V, F, cs):
    assert (chart_face_cover(cs.charts, len(F)) == 1).all()  # every face exactly once
    for c in cs.charts:
        assert np.array_equal(F[c.faces], c.vertices[c.local_F])
        # Independent recomputation: the stored verdict is the quality module's verdict.
        q = chart_quality(V[c.vertices], c.local_F, c.uv)
        assert q.bijective and c.quality.bijective
        for name, value in q.as_dict().items():
            assert getattr(c.quality, name) == pytest.approx(value, rel=1e-7), name


@pytest.mark.parametrize(
    "mesh",
    [
        lambda: plate_with_holes(),
        lambda: (lambda m: (np.asarray(m.vertices), np.asarray(m.faces)))(
            trimesh.creation.torus(2.0, 0.7, major_sections=32, minor_sections=16)
        ),
    ],
)
def test_closed_surfaces_end_bijective(mesh):
    V, F = mesh()
    seg = segment(V, F)
    cs = parameterize_charts(V, F, seg.labels)
    check_chart_set(V, F, cs)
    assert len(cs.splits) == seg.n_charts


def test_failing_chart_is_split_until_bijective():
    # A helicoid-like ribbon turned 1.4 times round an axis: the planar fallback alone cannot
    # map it, and a distortion target the solver cannot meet forces splits.
    V, F = tri_grid(60, 6, width=6.0, height=0.5)
    th = V[:, 0] / 6.0 * 2 * np.pi * 1.4
    r = 1.0 + V[:, 1]
    V3 = np.stack([r * np.cos(th), r * np.sin(th), 0.05 * V[:, 0]], 1)
    labels = np.zeros(len(F), dtype=np.int64)
    cs = parameterize_charts(V3, F, labels, config=SplitConfig(max_distortion=1.0001))
    check_chart_set(V3, F, cs)
    assert cs.splits[0] >= 1 and len(cs.charts) == cs.splits[0] + 1
    assert max(c.depth for c in cs.charts) >= 1


def test_easy_chart_is_not_split():
    V, F = folded_strip()
    cs = parameterize_charts(V, F, np.zeros(len(F), dtype=np.int64))
    assert len(cs.charts) == 1 and cs.splits[0] == 0 and cs.first_pass_bijective[0]
    assert cs.charts[0].method == "hessian"


def test_planar_charts_are_projected_exactly_and_first_pass():
    from meshes import procrustes_residual, rigid

    V, F = tri_grid(12, 9)
    V3 = rigid(V, seed=4)  # a plane in general position
    cs = parameterize_charts(V3, F, np.zeros(len(F), dtype=np.int64))
    (chart,) = cs.charts
    assert chart.method == "planar" and cs.first_pass_bijective[0]
    assert procrustes_residual(chart.uv, V[chart.vertices, :2]) < 1e-12
    a, b, c = V3[F[0]]
    n = np.cross(b - a, c - a)
    off = 1e-3 * np.linalg.norm(b - a) * n / np.linalg.norm(n)
    # A corner a thousandth of an edge out of the plane: its triangle folds along an edge, the
    # chart is developable and unrolled, its side lengths kept exactly.
    bent = V3.copy()
    bent[F[0, 0]] += off
    (chart,) = parameterize_charts(bent, F, np.zeros(len(F), dtype=np.int64)).charts
    assert chart.method == "developable"
    E = chart.local_F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    lengths = np.linalg.norm(np.diff(bent[chart.vertices][E], axis=1)[:, 0], axis=1)
    assert np.allclose(np.linalg.norm(np.diff(chart.uv[E], axis=1)[:, 0], axis=1), lengths)
    # An interior vertex out of the plane: curved there, the solver runs.
    inner = np.setdiff1d(np.arange(len(V3)), boundary_edges(F).ravel())[0]
    V3[inner] += off
    cs = parameterize_charts(V3, F, np.zeros(len(F), dtype=np.int64))
    assert cs.charts[0].method == "hessian"


def test_depth_limit_falls_back_to_bijective_projection():
    V, F = tri_grid(20, 20)
    V[:, 2] = np.sin(6 * V[:, 0]) * 0.3
    cs = parameterize_charts(
        V, F, np.zeros(len(F), dtype=np.int64), config=SplitConfig(max_depth=0, max_distortion=1.0)
    )
    check_chart_set(V, F, cs)
    assert all(c.method == "projection" for c in cs.charts if c.depth > 0)


def test_projection_keeps_winding():
    V, F = tri_grid(5, 5)
    uv = project_chart(V, F)
    assert chart_quality(V, F, uv).bijective
    uv2 = project_chart(V, F[:, ::-1])
    assert chart_quality(V, F[:, ::-1], uv2).bijective


def test_config_errors():
    with pytest.raises(ConfigError, match="max_depth"):
        SplitConfig(max_depth=-1)
    with pytest.raises(ConfigError, match="max_distortion"):
        SplitConfig(max_distortion=0.5)
    with pytest.raises(ConfigError, match="n_jobs"):
        SplitConfig(n_jobs=-1)
    with pytest.raises(ConfigError, match="min_split_gain"):
        SplitConfig(min_split_gain=-1e-3)


def test_worker_processes_give_the_same_charts(monkeypatch):
    import segparam.split as split

    monkeypatch.setattr(split, "PARALLEL_MIN_FACES", 0)
    V, F = plate_with_holes()
    seg = segment(V, F)
    serial = parameterize_charts(V, F, seg.labels, config=SplitConfig(n_jobs=1))
    done = []
    parallel = parameterize_charts(
        V, F, seg.labels, config=SplitConfig(n_jobs=2), progress=done.append
    )
    assert done[-1] == seg.n_charts
    assert len(serial.charts) == len(parallel.charts)
    assert np.array_equal(serial.splits, parallel.splits)
    for a, b in zip(serial.charts, parallel.charts, strict=True):
        assert np.array_equal(a.faces, b.faces) and np.array_equal(a.uv, b.uv)


def _worker_blas_threads() -> list[int]:
    from threadpoolctl import threadpool_info

    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


@pytest.mark.slow
def test_workers_share_the_cores_instead_of_each_running_a_blas_thread_per_core():
    import os

    import segparam.split as split

    pool = split._new_pool(2)
    try:
        threads = pool.submit(_worker_blas_threads).result()
    finally:
        split.stop_workers(pool)
    assert threads and all(t == max(1, (os.cpu_count() or 1) // 2) for t in threads)


def test_chart_affinity_is_the_mesh_wide_one_restricted_and_built_on_first_use(monkeypatch):
    import segparam.split as split
    from segparam.segment import face_affinity

    V, F = plate_with_holes()
    faces = np.array([7, 3, 11, 12, 4])
    built = []
    monkeypatch.setattr(split, "face_affinity", lambda V, F: built.append(1) or face_affinity(V, F))
    affinity = split._MeshAffinity(V, F)
    later = affinity.of_chart(faces, now=False)
    assert built == []  # nothing built until a chart must be split
    W = later()
    expected = face_affinity(V, F)[faces][:, faces]
    assert (W != expected).nnz == 0
    now = affinity.of_chart(faces, now=True)  # what a worker process gets, already restricted
    assert (now() != expected).nnz == 0 and built == [1]  # built once for the mesh


def test_the_segmentations_affinity_is_split_on_and_not_built_again(monkeypatch):
    import segparam.split as split
    from segparam.errors import InvalidMeshError
    from segparam.mesh import unit_frame
    from segparam.segment import face_affinity

    m = trimesh.creation.torus(2.0, 0.7, major_sections=32, minor_sections=16)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    seg = segment(V, F)
    center, size = unit_frame(V)
    # The segmentation's affinity is the one the split stage would build (both scale-free).
    assert (seg.affinity != face_affinity((V - center) / size, F)).nnz == 0
    tight = SplitConfig(max_stretch=1.0001)  # forces splits, so the affinity is needed
    own = parameterize_charts(V, F, seg.labels, config=tight)
    assert own.splits.sum() > 0
    monkeypatch.setattr(split, "face_affinity", lambda V, F: pytest.fail("built again"))
    given = parameterize_charts(V, F, seg.labels, config=tight, affinity=seg.affinity)
    assert np.array_equal(own.splits, given.splits)
    for a, b in zip(own.charts, given.charts, strict=True):
        assert np.array_equal(a.faces, b.faces) and np.array_equal(a.uv, b.uv)
    with pytest.raises(InvalidMeshError, match="affinity must be"):
        parameterize_charts(V, F, seg.labels, affinity=seg.affinity[:-1])


def test_small_charts_are_exempt_from_the_stretch_target_only_below_a_ceiling():
    from segparam.split import (
        SMALL_CHART_MAX_STRETCH,
        STRETCH_MIN_FACES,
        SplitConfig,
        _within_targets,
    )

    cfg = SplitConfig(max_stretch=1.02)
    small, big = STRETCH_MIN_FACES - 1, STRETCH_MIN_FACES
    l2 = np.array([1.01, 1.1, SMALL_CHART_MAX_STRETCH + 0.01, 1.01, 1.1])
    faces = np.array([small, small, small, big, big])
    ok = _within_targets(np.ones(5), l2, faces, cfg)
    assert ok.tolist() == [True, True, False, True, False]
    assert _within_targets(np.ones(5), l2, faces, SplitConfig(max_stretch=None)).all()


@pytest.mark.parametrize("cells", [1, 6])
def test_first_pass_counts_bijective_maps_split_for_a_target(cells):
    # A spherical cap is mapped bijectively on the first try but stretched past a tight L2
    # target, so it is split: that is still a first-pass success of the solver (the paper's
    # measure), whether it went through the bulk pass (small cells) or the per-chart path.
    from meshes import spherical_cap

    V, F = spherical_cap(20, 20)
    C = V[F].mean(axis=1)
    labels = np.minimum((C[:, 0] - C[:, 0].min()) / np.ptp(C[:, 0]) * cells, cells - 1)
    labels = labels.astype(np.int64)
    cfg = SplitConfig(max_stretch=1.0 + 1e-6)
    loose = parameterize_charts(
        V, F, labels, config=SplitConfig(max_stretch=None, min_split_gain=None)
    )
    assert loose.first_pass_bijective.all() and not loose.splits.any()
    tight = parameterize_charts(V, F, labels, config=cfg)
    assert tight.splits.any()  # the target split charts the solver had mapped bijectively
    assert tight.first_pass_bijective.all()


def _atlas_excess(V, F, cs):
    from segparam.mesh import face_areas
    from segparam.split import _excess

    return float(_excess(list(cs.charts), face_areas(V, F)).sum())


def test_a_chart_distorted_at_one_spot_is_bisected_for_the_gain():
    # A flat square with its centre vertex raised: a cone, its distortion around the apex. It
    # meets the stretch target, but cutting it through the apex removes most of its distortion.
    from segparam.split import MIN_SPLIT_GAIN

    V, F = tri_grid(10, 10)
    V = np.c_[V[:, :2], np.zeros(len(V))]
    V[np.argmin(((V[:, :2] - 0.5) ** 2).sum(axis=1)), 2] = 0.2
    labels = np.zeros(len(F), dtype=np.int64)
    plain = parameterize_charts(V, F, labels, config=SplitConfig(min_split_gain=None))
    cs = parameterize_charts(V, F, labels)
    check_chart_set(V, F, cs)
    added = len(cs.charts) - len(plain.charts)
    assert added >= 1 and cs.splits[0] == len(cs.charts) - 1
    assert _atlas_excess(V, F, cs) <= _atlas_excess(V, F, plain) - MIN_SPLIT_GAIN * added


def test_a_chart_above_the_size_bound_is_not_tried_for_the_gain(monkeypatch):
    # GAIN_MAX_FACES bounds the pass's cost: the cone of the test above is cut into pieces for
    # the targets, and the gain pass bisects some of them; with the bound one face under the
    # smallest it bisected, none of those is bisected (the others are as before).
    import segparam.split as split

    V, F = tri_grid(10, 10)
    V = np.c_[V[:, :2], np.zeros(len(V))]
    V[np.argmin(((V[:, :2] - 0.5) ** 2).sum(axis=1)), 2] = 0.2
    labels = np.zeros(len(F), dtype=np.int64)
    plain = parameterize_charts(V, F, labels, config=SplitConfig(min_split_gain=None))
    kept = {tuple(sorted(c.faces)) for c in parameterize_charts(V, F, labels).charts}
    bisected = [c for c in plain.charts if tuple(sorted(c.faces)) not in kept]
    assert bisected
    smallest = min(len(c.faces) for c in bisected)
    monkeypatch.setattr(split, "GAIN_MAX_FACES", smallest - 1)
    bound = {tuple(sorted(c.faces)) for c in parameterize_charts(V, F, labels).charts}
    for c in plain.charts:
        if len(c.faces) >= smallest:
            assert tuple(sorted(c.faces)) in bound  # left whole


def test_a_chart_curved_all_over_is_not_bisected_for_the_gain(monkeypatch):
    # A spherical cap: a bisection leaves most of its distortion in both halves, so it stays
    # whole, though a bisection would lower the atlas's distortion by more than the gain asked.
    from meshes import spherical_cap

    import segparam.split as split

    V, F = spherical_cap(10, 10, extent=2.2)
    monkeypatch.setattr(split, "GAIN_MAX_FACES", len(F))  # tried: the share rule keeps it whole
    labels = np.zeros(len(F), dtype=np.int64)
    cs = parameterize_charts(V, F, labels)
    assert len(cs.charts) == 1
    monkeypatch.setattr(split, "GAIN_MIN_SHARE", 0.0)
    halves = parameterize_charts(V, F, labels)
    check_chart_set(V, F, halves)
    assert len(halves.charts) > 1
    assert _atlas_excess(V, F, halves) < _atlas_excess(V, F, cs) - split.MIN_SPLIT_GAIN


def _tube(
    n_theta: int = 24, n_z: int = 5, height: float = 0.8, radius: float = 1.0, bulge: float = 0.0
):
    """An open cylinder (two boundary loops, each a geodesic: turning 0): a prism's wall, flat
    facets and developable, or with ``bulge`` a barrel, its radius that much larger half way up
    (curved at every inner vertex)."""
    theta = 2 * np.pi * np.arange(n_theta) / n_theta
    z = np.linspace(0.0, height, n_z)
    r = radius * (1 + bulge * np.sin(np.pi * z / height))[:, None]
    V = np.stack(
        [r * np.cos(theta)[None], r * np.sin(theta)[None], z[:, None].repeat(n_theta, 1)], -1,
    ).reshape(-1, 3)  # fmt: skip
    i, j = (a.ravel() for a in np.meshgrid(np.arange(n_z - 1), np.arange(n_theta), indexing="ij"))
    a, b = i * n_theta + j, i * n_theta + (j + 1) % n_theta
    F = np.concatenate(
        [np.stack([a, b, b + n_theta], 1), np.stack([a, b + n_theta, a + n_theta], 1)]
    )
    return V, F


def _washer(n_theta: int = 24, n_r: int = 4):
    """A flat annulus (outer loop turning 2 pi, inner -2 pi)."""
    V, F = _tube(n_theta, n_r)
    r = 1.0 + V[:, 2] / V[:, 2].max()  # the tube's height becomes the radius
    V = np.stack([r * V[:, 0], r * V[:, 1], np.zeros(len(V))], 1)
    return V, F


def test_tubes_are_told_from_washers_and_disks():
    """``_tubes``: a chart with two or more loops, each turning by less than TUBE_TURNING, per
    chart of a union; a washer (flat annulus) and a disk are not."""
    from segparam.split import _tubes

    tube, washer, disk = _tube(), _washer(), tri_grid(6, 6)
    parts = [tube, washer, disk, tube]
    offsets = np.cumsum([0] + [len(V) for V, _ in parts])
    V = np.concatenate([V for V, _ in parts])
    F = np.concatenate([F + o for (_, F), o in zip(parts, offsets, strict=False)])
    face_chart = np.repeat(np.arange(4), [len(F) for _, F in parts])
    assert _tubes(V, F, face_chart, 4).tolist() == [True, False, False, True]


@pytest.mark.parametrize("batched", [True, False], ids=["batched", "alone"])
def test_a_tube_is_cut_open_into_one_chart(monkeypatch, batched):
    """The wall of a drilled hole is never solved as it is (its map would fold): the solver only
    sees it cut open along one path between its loops, a disk, and keeps it as one chart (one
    cut, where a bisection gave two charts and two cuts), whether it goes through the batched
    path or alone (too big for a batch). Its vertices on the cut come twice."""
    import segparam.split as split
    from segparam.mesh import boundary_loops

    V, F = _tube(n_theta=32, n_z=6, height=1.5, bulge=0.01)  # 6.3 round, 1.5 high: 4.2:1
    loops = []
    batched_solver, alone = split.solve_charts, split.parameterize_chart

    def spy_batch(V, F, vert_chart, **kw):
        face_chart = vert_chart[F[:, 0]]
        loops.extend(len(boundary_loops(F[face_chart == c])) for c in np.unique(face_chart))
        return batched_solver(V, F, vert_chart, **kw)

    def spy_alone(V, F, **kw):
        loops.append(len(boundary_loops(F)))
        return alone(V, F, **kw)

    monkeypatch.setattr(split, "solve_charts", spy_batch)
    monkeypatch.setattr(split, "parameterize_chart", spy_alone)
    if not batched:
        monkeypatch.setattr(split, "BATCH_MAX_VERTICES", 10)
    out = parameterize_charts(V, F, np.zeros(len(F), dtype=np.int64), config=SplitConfig(n_jobs=1))
    assert loops == [1]
    (chart,) = out.charts
    assert chart.quality.bijective and chart.quality.l2_stretch < 1.001
    assert np.array_equal(chart.vertices[chart.local_F], F[chart.faces])
    assert len(chart.vertices) == len(V) + 6  # the cut: 6 vertices from loop to loop, twice
    assert np.array_equal(chart_face_cover(out.charts, len(F)), np.ones(len(F)))


@pytest.mark.parametrize("batched", [True, False], ids=["batched", "alone"])
def test_a_developable_tube_is_cut_open_and_unrolled(monkeypatch, batched):
    """A prism's wall (a drilled hole's in a CAD part) is developable: cut open, it is unrolled
    (segparam.unfold), an exact isometry, and the solver never runs, batched or alone."""
    import segparam.split as split

    def no_solver(*args, **kwargs):
        raise AssertionError("the solver ran")

    monkeypatch.setattr(split, "solve_charts", no_solver)
    monkeypatch.setattr(split, "parameterize_chart", no_solver)
    if not batched:
        monkeypatch.setattr(split, "BATCH_MAX_VERTICES", 10)
    V, F = _tube(n_theta=32, n_z=6, height=1.5)
    out = parameterize_charts(V, F, np.zeros(len(F), dtype=np.int64), config=SplitConfig(n_jobs=1))
    (chart,) = out.charts
    assert chart.method == "developable" and out.first_pass_bijective[0]
    assert chart.quality.bijective and chart.quality.l2_stretch == pytest.approx(1.0, abs=1e-12)
    assert len(chart.vertices) == len(V) + 6  # the cut: 6 vertices from loop to loop, twice
    check_chart_set(V, F, out)


@pytest.mark.parametrize("batched", [True, False], ids=["batched", "alone"])
def test_a_tube_too_long_to_open_is_split(monkeypatch, batched):
    """A bushing's wall, 6.3 round and 0.3 high, would open into a 21:1 strip that binds the
    texture's side (TUBE_MAX_ASPECT): it is split into pieces that share no vertex twice."""
    import segparam.split as split

    V, F = _tube(n_theta=32, n_z=3, height=0.3)
    if not batched:
        monkeypatch.setattr(split, "BATCH_MAX_VERTICES", 10)
    out = parameterize_charts(V, F, np.zeros(len(F), dtype=np.int64), config=SplitConfig(n_jobs=1))
    assert len(out.charts) >= 2
    assert all(len(np.unique(c.vertices)) == len(c.vertices) for c in out.charts)
    assert all(c.quality.bijective for c in out.charts)
    assert np.array_equal(chart_face_cover(out.charts, len(F)), np.ones(len(F)))
    monkeypatch.setattr(split, "TUBE_MAX_ASPECT", 30.0)  # allowed: one chart
    assert len(parameterize_charts(V, F, np.zeros(len(F), dtype=np.int64)).charts) == 1


@pytest.mark.slow
def test_the_gain_pass_drops_a_bisection_between_rounds_once_it_fails_anyway(monkeypatch):
    """After each round a bisection is judged again, with its pieces mapped so far and the ones
    still to map (each adds excess and a chart): on the quick start's brain, with charts of up
    to 256 faces tried, the pass drops one that way (a chart was being halved down to 8-face
    pieces, one round each), and the atlas is the one mapping every piece gives."""
    import segparam.split as split
    from segparam.cli import DEFAULT_MESH_NAME, _data
    from segparam.io import load_mesh
    from segparam.pipeline import PipelineConfig, build_atlas

    V, F = load_mesh(_data(DEFAULT_MESH_NAME))
    cfg = PipelineConfig().replace(remesh={"mode": "off"})
    # the bisection dropped is of a chart above today's size bound (tried up to session 25)
    monkeypatch.setattr(split, "GAIN_MAX_FACES", 256)
    dropped = []
    real = split._hopeless

    def spy(known_so_far, **kw):
        out = real(known_so_far, **kw)
        dropped.extend(g for g, (_, pending) in known_so_far.items() if pending and out[g])
        return out

    monkeypatch.setattr(split, "_hopeless", spy)
    a = build_atlas(V, F, cfg, seed=0)
    assert dropped, "no bisection dropped between rounds"
    monkeypatch.setattr(split, "_hopeless", lambda known, owner, **kw: np.zeros(len(owner), bool))
    b = build_atlas(V, F, cfg, seed=0)
    assert a.n_charts == b.n_charts
    np.testing.assert_array_equal(a.uv_F, b.uv_F)
    np.testing.assert_array_equal(a.uv, b.uv)


def test_the_gain_pass_skips_only_bisections_that_fail_anyway(monkeypatch):
    """A bisection whose halves, as far as the batched pass mapped them, already hold too much
    excess is not mapped to the end (``_hopeless``): the atlas is the one mapping every piece
    gives, and some groups were skipped on the realistic 2k-face brain."""
    import segparam.split as split
    from segparam.pipeline import PipelineConfig, build_atlas
    from segparam.synthetic import brain_like_surface

    V, F = brain_like_surface(2000)
    cfg = PipelineConfig().replace(remesh={"mode": "off"})
    skipped = []
    real = split._hopeless

    def spy(first, **kw):
        out = real(first, **kw)
        skipped.append(int(out.sum()))
        return out

    monkeypatch.setattr(split, "_hopeless", spy)
    a = build_atlas(V, F, cfg, seed=0)
    assert sum(skipped) > 0
    monkeypatch.setattr(split, "_hopeless", lambda first, owner, **kw: np.zeros(len(owner), bool))
    b = build_atlas(V, F, cfg, seed=0)
    assert a.n_charts == b.n_charts
    np.testing.assert_array_equal(a.uv_F, b.uv_F)
    np.testing.assert_array_equal(a.uv, b.uv)


def test_piece_vertex_counts_match_one_unique_per_piece():
    """The split rounds' vertex count of every piece, all at once, is what ``np.unique`` of each
    piece's corners gives (charts of a grid cut in random labels, random subsets of them)."""
    from segparam.split import _piece_vertex_counts, _submeshes

    _, F = tri_grid(12, 9)
    rng = np.random.default_rng(5)
    labels = rng.integers(0, 7, len(F))
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(8))
    sub = _submeshes(F, labels, order, bounds)
    srcs, pieces = [], []
    for _ in range(40):
        src = int(rng.integers(0, 7))
        n = bounds[src + 1] - bounds[src]
        srcs.append(src)
        pieces.append(np.sort(rng.choice(n, int(rng.integers(1, n + 1)), replace=False)))
    want = [len(np.unique(sub.of(s)[1][f])) for s, f in zip(srcs, pieces, strict=True)]
    assert _piece_vertex_counts(sub, srcs, pieces).tolist() == want


def _halves(subdivisions):
    """An icosphere cut in two at its equator: the faces' labels by the sign of their z."""
    m = trimesh.creation.icosphere(subdivisions)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    return V, F, (V[F].mean(axis=1)[:, 2] > 0).astype(np.int64)


def _cap_of(V, F, degrees):
    """The faces of a unit sphere's mesh within ``degrees`` of its pole, on their own vertices."""
    cap = F[V[F].mean(axis=1)[:, 2] > np.cos(np.radians(degrees))]
    used, cap = np.unique(cap, return_inverse=True)
    return V[used], cap.reshape(-1, 3)


def _bumpy_cap(subdivisions, degrees):
    """The faces of an icosphere within ``degrees`` of its pole, every vertex moved radially by
    1% noise (seeded): a cap whose inner defects hold saddles and bumps beside their net sum."""
    m = trimesh.creation.icosphere(subdivisions)
    V, F = _cap_of(np.asarray(m.vertices), np.asarray(m.faces), degrees)
    rng = np.random.default_rng(0)
    return V * (1 + 0.01 * rng.standard_normal(len(V)))[:, None], F


def _recording_solves(monkeypatch, split):
    """The face count of every piece the split stage solves from now on, in bulk or alone."""
    solved = []
    in_bulk, alone = split.solve_charts, split._solved

    def record_bulk(V_, F_, vert_chart, **kw):
        solved.extend(np.bincount(vert_chart[F_[:, 0]]).tolist())
        return in_bulk(V_, F_, vert_chart, **kw)

    def record_alone(V_, F_, *args):
        solved.append(len(F_))
        return alone(V_, F_, *args)

    monkeypatch.setattr(split, "solve_charts", record_bulk)
    monkeypatch.setattr(split, "_solved", record_alone)
    return solved


@pytest.mark.parametrize("subdivisions", [2, 4])  # solved in bulk (162 faces), alone (2,560)
def test_caps_are_cut_without_a_solve_into_the_charts_a_solve_would_have_led_to(
    monkeypatch, subdivisions
):
    # A hemisphere holds 2 pi of curvature, past any map within the stretch target: it is
    # bisected at once, not solved first, and ends in the same charts as when it was solved.
    import segparam.split as split

    V, F, labels = _halves(subdivisions)
    solved = _recording_solves(monkeypatch, split)
    one = SplitConfig(n_jobs=1)  # every solve in this process, where it is recorded
    cs = parameterize_charts(V, F, labels, config=one)
    check_chart_set(V, F, cs)
    halves = np.bincount(labels).tolist()
    assert solved and max(solved) < min(halves)  # only pieces of the halves were solved
    assert (cs.splits >= 1).all() and not cs.first_pass_bijective.any()  # never tried

    solved.clear()
    monkeypatch.setattr(split, "CAP_CURVATURE", np.inf)  # no caps: the halves are solved first
    monkeypatch.setattr(split, "CAP_NET", np.inf)
    monkeypatch.setattr(split, "CONFORMAL_STRETCH_CUT", np.inf)
    plain = parameterize_charts(V, F, labels, config=one)
    assert set(halves) <= set(solved) and plain.first_pass_bijective.all()
    assert len(plain.charts) == len(cs.charts)
    for a, b in zip(plain.charts, cs.charts, strict=True):
        assert np.array_equal(a.faces, b.faces) and np.array_equal(a.uv, b.uv)


def _polar_disk(rings):
    """A unit disk in the z = 0 plane: rings of 6 k points about its centre, triangulated."""
    from scipy.spatial import Delaunay

    r = np.repeat(np.arange(1, rings + 1), 6 * np.arange(1, rings + 1)) / rings
    theta = np.concatenate([np.arange(6 * k) * 2 * np.pi / (6 * k) for k in range(1, rings + 1)])
    P = np.r_[[[0.0, 0.0]], np.c_[r * np.cos(theta), r * np.sin(theta)]]
    return np.c_[P, np.zeros(len(P))], Delaunay(P).simplices.astype(np.int64)


def test_conformal_stretch_is_that_of_the_stereographic_map_on_a_spherical_cap():
    # On a cap of the unit sphere the conformal flattening with u = 0 on the rim is the
    # stereographic projection, rescaled: area factor ((1 + r^2) / (1 + r0^2))^2 at r = tan(t /
    # 2). Its L2 stretch by quadrature against the discrete one, on caps of 60 and 80 degrees;
    # two caps in one union get their own values; a flat disk flattens without stretch.
    from scipy.integrate import quad

    import segparam.split as split

    def stereographic(t0):
        r0 = np.tan(t0 / 2)

        def s(t):
            return ((1 + np.tan(t / 2) ** 2) / (1 + r0**2)) ** 2

        area = quad(np.sin, 0, t0)[0]
        shrink = quad(lambda t: np.sin(t) / s(t), 0, t0)[0]
        grow = quad(lambda t: np.sin(t) * s(t), 0, t0)[0]
        return np.sqrt(shrink * grow) / area

    def stretch(V, F, vert_chart, which):
        return split._conformal_stretch(V, F, vert_chart, len(which), np.asarray(which))

    m = trimesh.creation.icosphere(4)
    caps = [_cap_of(np.asarray(m.vertices), np.asarray(m.faces), d) for d in (60, 80)]
    for Vc, Fc in caps:
        rim = np.unique(boundary_edges(Fc))
        t0 = np.arccos(Vc[rim, 2]).mean()  # the rim's mean angle from the pole
        got = stretch(Vc, Fc, np.zeros(len(Vc), dtype=np.int64), [True])[0]
        assert got - 1 == pytest.approx(stereographic(t0) - 1, rel=0.03)
    (V0, F0), (V1, F1) = caps
    Vu, Fu = np.concatenate([V0, V1]), np.concatenate([F0, F1 + len(V0)])
    vc = np.repeat([0, 1], [len(V0), len(V1)])
    both = stretch(Vu, Fu, vc, [True, True])
    one = stretch(Vu, Fu, vc, [False, True])
    assert one[0] == 1.0 and one[1] == pytest.approx(both[1], rel=1e-12)
    assert 1.01 < both[0] < both[1] < 1.06
    Vd, Fd = _polar_disk(6)
    assert stretch(Vd, Fd, np.zeros(len(Vd), dtype=np.int64), [True])[0] == pytest.approx(1.0)
    # a closed surface has no rim to hold u = 0: its system is singular (a factorization fails,
    # or its solution runs off along the constants, which the stretch ignores): no bound
    s = trimesh.creation.icosphere(1)
    V, F = np.asarray(s.vertices), np.asarray(s.faces)
    assert stretch(V, F, np.zeros(len(V), np.int64), [True])[0] == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("height, cut", [(0.8, True), (0.3, False)])
def test_a_bump_too_stretched_to_map_is_cut_without_a_solve(monkeypatch, height, cut):
    # A Gaussian bump on a disk holds no net curvature inside (its top's and its skirt's
    # cancel), so no curvature rule takes it; a tall one's conformal flattening stretches by
    # 1.39, far past any map within the target: it is cut at once, into the charts its solve
    # leads to. A low one (1.008) is solved, and kept whole.
    import segparam.split as split

    V, F = _polar_disk(8)
    V[:, 2] = height * np.exp(-(V[:, 0] ** 2 + V[:, 1] ** 2) / 0.3**2)
    labels = np.zeros(len(F), dtype=np.int64)
    one = SplitConfig(n_jobs=1)
    solved = _recording_solves(monkeypatch, split)
    cs = parameterize_charts(V, F, labels, config=one)
    check_chart_set(V, F, cs)
    assert (len(F) not in solved) == cut and cs.first_pass_bijective[0] == (not cut)
    assert cs.cut_untried.tolist() == [cut]
    if not cut:
        assert len(cs.charts) == 1
        return
    solved.clear()
    monkeypatch.setattr(split, "CONFORMAL_STRETCH_CUT", np.inf)  # solved first
    plain = parameterize_charts(V, F, labels, config=one)
    assert len(F) in solved and plain.first_pass_bijective[0]
    assert len(plain.charts) == len(cs.charts) > 1
    for a, b in zip(plain.charts, cs.charts, strict=True):
        assert np.array_equal(a.faces, b.faces) and np.array_equal(a.uv, b.uv)


@pytest.mark.parametrize(
    "subdivisions, degrees",
    [(3, 85), (4, 80)],  # 576 faces in bulk; 2,120 alone
)
def test_a_bumpy_cap_is_cut_without_a_solve_into_the_charts_a_solve_would_have_led_to(
    monkeypatch, subdivisions, degrees
):
    # Over 5 rad of net curvature inside, but with saddles: the one-sign test of the caps does
    # not take it (its net sum is about half its absolute sum or less); CAP_NET does. Solved
    # first, it maps bijectively but over the stretch target and is bisected: the same charts.
    import segparam.split as split
    from segparam.mesh import inner_curvature

    V, F = _bumpy_cap(subdivisions, degrees)
    net, absolute = inner_curvature(V, F, np.zeros(len(V), dtype=np.int64), 1)
    assert net[0] >= split.CAP_NET + 0.5 and net[0] < split.CAP_ONE_SIGN * absolute[0]
    labels = np.zeros(len(F), dtype=np.int64)
    one = SplitConfig(n_jobs=1)  # every solve in this process, where it is recorded
    solved = _recording_solves(monkeypatch, split)
    cs = parameterize_charts(V, F, labels, config=one)
    check_chart_set(V, F, cs)
    assert solved and len(F) not in solved and not cs.first_pass_bijective[0]  # never tried
    assert cs.cut_untried.tolist() == [True]

    solved.clear()
    monkeypatch.setattr(split, "CAP_NET", np.inf)  # solved first
    plain = parameterize_charts(V, F, labels, config=one)
    assert len(F) in solved and plain.first_pass_bijective[0]  # bijective, over the target
    assert plain.cut_untried.tolist() == [False]
    assert len(plain.charts) == len(cs.charts) > 1
    for a, b in zip(plain.charts, cs.charts, strict=True):
        assert np.array_equal(a.faces, b.faces) and np.array_equal(a.uv, b.uv)


def test_a_disk_of_negative_curvature_is_not_a_cap(monkeypatch):
    # A monkey saddle holds 7 rad of negative curvature inside: pieces like it map within the
    # stretch target (the range scan's -6.3 rad piece at L2 1.002), so it is solved first.
    import segparam.split as split

    V, F = _polar_disk(6)
    V[:, 2] = 0.8 * np.real((V[:, 0] + 1j * V[:, 1]) ** 3)
    solved = _recording_solves(monkeypatch, split)
    cs = parameterize_charts(V, F, np.zeros(len(F), dtype=np.int64), config=SplitConfig(n_jobs=1))
    check_chart_set(V, F, cs)
    assert len(F) in solved and cs.first_pass_bijective[0]


def test_a_cap_within_reach_of_the_stretch_target_is_solved_whole():
    # A 68-degree cap holds 3.9 rad: the solver maps it within L2 1.02 (1.018), so it is not
    # taken for a cap; and without a stretch target no chart is ever a cap.
    m = trimesh.creation.icosphere(4)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    cap = V[F].mean(axis=1)[:, 2] > np.cos(np.radians(68))
    sub_V, sub_F = V, F[cap]
    used = np.unique(sub_F)
    remap = np.full(len(V), -1)
    remap[used] = np.arange(len(used))
    sub_V, sub_F = V[used], remap[sub_F]
    cs = parameterize_charts(sub_V, sub_F, np.zeros(len(sub_F), dtype=np.int64))
    assert len(cs.charts) == 1 and cs.first_pass_bijective[0]
    assert cs.charts[0].quality.l2_stretch <= 1.02

    V, F, labels = _halves(2)
    loose = parameterize_charts(
        V, F, labels, config=SplitConfig(max_stretch=None, min_split_gain=None)
    )
    assert len(loose.charts) == 2 and loose.first_pass_bijective.all()


def test_worker_processes_cut_caps_without_a_solve_too(monkeypatch):
    # The per-chart tasks of worker processes (large meshes) skip the caps' solves as the
    # rounds do: the same charts, and the same first-pass verdicts, whichever path maps them
    # (the rounds solve the quarters in one batch, a worker one by one: the same maps to
    # rounding).
    import segparam.split as split

    monkeypatch.setattr(split, "PARALLEL_MIN_FACES", 0)
    V, F, labels = _halves(2)
    serial = parameterize_charts(V, F, labels, config=SplitConfig(n_jobs=1))
    parallel = parameterize_charts(V, F, labels, config=SplitConfig(n_jobs=2))
    assert not parallel.first_pass_bijective.any()  # not tried: cut at once
    assert serial.cut_untried.all() and parallel.cut_untried.all()  # and counted as such
    assert np.array_equal(serial.first_pass_bijective, parallel.first_pass_bijective)
    assert np.array_equal(serial.splits, parallel.splits)
    for a, b in zip(serial.charts, parallel.charts, strict=True):
        assert np.array_equal(a.faces, b.faces) and np.allclose(a.uv, b.uv, atol=1e-9)


def _cut_edges(F, charts):
    """Mesh edges between two charts."""
    from segparam.mesh import face_adjacency

    chart = np.empty(len(F), dtype=np.int64)
    for k, c in enumerate(charts):
        chart[c.faces] = k
    i, j = face_adjacency(F)[0].T
    return int((chart[i] != chart[j]).sum())


def test_bisections_of_large_pieces_are_straightened_in_the_rounds_and_in_the_workers(
    monkeypatch,
):
    # A jittered sphere's hemispheres (640 faces, caps: bisected at once) are cut along the
    # Fiedler vector's median with teeth; from STRAIGHTEN_MIN_FACES faces the split stage
    # straightens the cut (segment.divide's `straighten`): fewer mesh edges between charts
    # than with the median cuts, and the same charts whether the rounds or a worker's task
    # cut them.
    import segparam.split as split

    V, F, labels = _halves(3)
    V = V + np.random.default_rng(1).normal(0, 0.02, V.shape)
    assert min(np.bincount(labels)) >= split.STRAIGHTEN_MIN_FACES
    one = SplitConfig(n_jobs=1)
    cs = parameterize_charts(V, F, labels, config=one)
    check_chart_set(V, F, cs)
    monkeypatch.setattr(split, "PARALLEL_MIN_FACES", 0)
    parallel = parameterize_charts(V, F, labels, config=SplitConfig(n_jobs=2))
    assert len(parallel.charts) == len(cs.charts)
    for a, b in zip(cs.charts, parallel.charts, strict=True):
        assert np.array_equal(a.faces, b.faces)
    monkeypatch.undo()
    monkeypatch.setattr(split, "_STRAIGHTEN", (len(F) + 1, split.STRAIGHTEN_PASSES))
    plain = parameterize_charts(V, F, labels, config=one)
    check_chart_set(V, F, plain)
    assert _cut_edges(F, cs.charts) < _cut_edges(F, plain.charts)


def test_the_segmentations_curvature_is_the_one_the_split_stage_would_compute():
    from segparam.mesh import curvature_shares

    V, F = plate_with_holes()
    seg = segment(V, F)
    assert np.allclose(seg.face_curvature, curvature_shares(V, F), atol=1e-12)
    with pytest.raises(InvalidMeshError, match="curvature must be"):
        parameterize_charts(V, F, seg.labels, curvature=np.zeros(3))


def _with_slits(monkeypatch, on):
    import segparam.split as split

    monkeypatch.setattr(split, "SLIT_MIN_DEPTH", 1 if on else 10**6)


def test_slit_candidates_at_once_are_the_pieces_the_one_by_one_test_takes():
    # The batched screen of the failed pieces (their inner curvature from one union of their
    # charts) against the curvature test of each piece alone, on the pieces of a folded
    # surface's charts cut in quarters, at depths in and out of the slit range.
    import segparam.split as split
    from segparam.mesh import inner_curvature, submesh
    from segparam.synthetic import brain_like_surface

    V, F = brain_like_surface(2000, seed=1)
    seg = segment(V, F)
    W = seg.affinity
    pieces, want = [], []
    for c in range(seg.n_charts):  # loop over the charts: quarters of each
        faces = np.flatnonzero(seg.labels == c)
        vertices, local_F = submesh(F, faces)
        where = np.full(len(F), -1)
        where[faces] = np.arange(len(faces))
        for half in divide(W, faces, seed=0):
            for quarter in divide(W, half, seed=0) if len(half) > 1 else [half]:
                depth = 2 if len(pieces) % 5 else SplitConfig().max_depth + 1  # too deep
                pieces.append((V[vertices], local_F, where[quarter], c, depth))
                Vq, Fq = submesh(local_F, where[quarter])
                net, absolute = inner_curvature(
                    V[vertices][Vq], Fq, np.zeros(len(Vq), dtype=np.int64), 1
                )
                inside = net[0] >= max(split.SLIT_MIN_CURVATURE, split.SLIT_ONE_SIGN * absolute[0])
                deep = split.SLIT_MIN_DEPTH <= depth <= SplitConfig().max_depth
                want.append(bool(inside and deep and len(quarter) >= split.STRETCH_MIN_FACES))
    got = split._slit_candidates(pieces, SplitConfig())
    assert got.tolist() == want
    assert 0 < sum(want) < len(want)  # some pieces are candidates, some are not


def test_a_knob_whose_halves_fail_gets_a_slit_instead_of_a_second_bisection(monkeypatch):
    # A sphere from its pole past the equator: its halves hold 4.6 rad each and miss the
    # stretch target; cut along a slit from their middle to their rim they map within it, one
    # chart each, where a second bisection made two.
    from meshes import bulb

    V, F = bulb(120)
    labels = np.zeros(len(F), dtype=np.int64)
    cfg = SplitConfig(min_split_gain=None, n_jobs=1)
    _with_slits(monkeypatch, False)
    plain = parameterize_charts(V, F, labels, config=cfg)
    _with_slits(monkeypatch, True)
    cs = parameterize_charts(V, F, labels, config=cfg)
    check_chart_set(V, F, cs)
    assert len(plain.charts) == 4 and len(cs.charts) == 2
    for c in cs.charts:
        assert c.depth == 1 and c.quality.l2_stretch <= 1.02
        # the slit: vertices that come twice, in a path from the rim inwards
        twice = np.flatnonzero(np.bincount(c.vertices) == 2)
        rim = np.unique(boundary_edges(F[c.faces]))
        assert len(twice) >= 2 and np.isin(twice, rim).sum() >= 1
    # the worker processes' per-chart task slits the same pieces
    import segparam.split as split

    monkeypatch.setattr(split, "PARALLEL_MIN_FACES", 0)
    parallel = parameterize_charts(V, F, labels, config=SplitConfig(min_split_gain=None, n_jobs=2))
    assert len(parallel.charts) == 2
    for a, b in zip(cs.charts, parallel.charts, strict=True):
        assert np.array_equal(a.faces, b.faces) and np.array_equal(a.vertices, b.vertices)
        assert np.allclose(a.uv, b.uv, atol=1e-6)


def _cone_by_the_rim(height=0.15):
    """A flat 6 x 6 grid (50 faces) with the vertex one row in from the middle of its lower
    side raised: a cone of 1.4 rad one edge from the rim. Returns V, F and the apex."""
    V, F = tri_grid(6, 6)
    V = np.c_[V[:, :2], np.zeros(len(V))]
    apex = int(np.argmin(((V[:, :2] - [0.5, 0.2]) ** 2).sum(axis=1)))
    V[apex, 2] = height
    return V, F, apex


def test_a_cone_by_the_rim_is_freed_by_a_slit_not_a_new_chart():
    # The chart meets the targets with its cone inside; cut along the one edge from the apex to
    # the rim, the apex is on the boundary, whose turning takes up its defect: the same one
    # chart, with most of its distortion gone.
    import segparam.split as split

    V, F, apex = _cone_by_the_rim()
    labels = np.zeros(len(F), dtype=np.int64)
    plain = parameterize_charts(
        V, F, labels, config=SplitConfig(min_split_gain=None, slit_above=None)
    )
    cs = parameterize_charts(V, F, labels, config=SplitConfig(min_split_gain=None))
    check_chart_set(V, F, cs)
    (p,), (c,) = plain.charts, cs.charts
    assert p.quality.angle_distortion > split.SLIT_ABOVE
    assert len(c.vertices) == len(np.unique(c.vertices)) + 1  # the slit's rim vertex, twice
    assert apex in c.vertices[np.unique(boundary_edges(c.local_F))]
    own = split._excess([p, c], np.empty(0), own=True)
    assert own[1] <= (1 - split.CONE_SLIT_GAIN) * own[0]
    assert c.quality.angle_distortion < p.quality.angle_distortion
    assert c.quality.l2_stretch < p.quality.l2_stretch
    # a bound above the chart's angle distortion: no slit
    high = SplitConfig(min_split_gain=None, slit_above=p.quality.angle_distortion + 1e-6)
    (h,) = parameterize_charts(V, F, labels, config=high).charts
    assert len(h.vertices) == len(np.unique(h.vertices))


@pytest.mark.parametrize(
    "gate, value",
    [
        ("CONE_MIN_DEFECT", 1.5),  # the cone (1.44 rad) is too weak to be worth a seam
        ("CONE_SLIT_MAX_FACES", 49),  # the chart (50 faces) is too large to be tried
        ("CONE_SLIT_MAX_EDGES", 0),  # the slit (one edge) is too long
        ("CONE_SLIT_MIN_GAIN", 1.0),  # no slit can lower the atlas's excess that much
        ("CONE_SLIT_GAIN", 0.99),  # the slit removes less than that of the chart's excess
        ("CONE_SLIT_MOST", 1e-6),  # not even all of the chart's excess would gain enough
        ("CONE_SLIT_ROUNDS", 0),  # no round
    ],
)
def test_a_cone_slit_is_tried_and_kept_only_within_its_bounds(monkeypatch, gate, value):
    import segparam.split as split

    V, F, _ = _cone_by_the_rim()
    labels = np.zeros(len(F), dtype=np.int64)
    cfg = SplitConfig(min_split_gain=None)
    assert len(parameterize_charts(V, F, labels, config=cfg).charts[0].vertices) == 37
    monkeypatch.setattr(split, gate, value)
    (c,) = parameterize_charts(V, F, labels, config=cfg).charts
    assert len(c.vertices) == len(np.unique(c.vertices)) == 36  # no slit


def test_slits_free_the_cones_of_a_coarse_brain_without_adding_charts():
    # The realistic 2k-face brain of bench_atlas.py (seed 1): its small charts hold cones of
    # 0.5-1.7 rad; slits bring its angle distortion and L2 stretch down, the charts the same.
    from segparam.mesh import face_areas
    from segparam.quality import distortion, signed_areas
    from segparam.synthetic import brain_like_surface

    V, F = brain_like_surface(2000, seed=1)
    seg = segment(V, F)
    plain = parameterize_charts(V, F, seg.labels, config=SplitConfig(slit_above=None))
    cs = parameterize_charts(V, F, seg.labels)
    check_chart_set(V, F, cs)
    assert len(cs.charts) == len(plain.charts)
    slit = sum(len(c.vertices) > len(np.unique(c.vertices)) for c in cs.charts)
    assert slit >= 10

    def figures(charts):
        """The atlas's L2 stretch and angle distortion, every chart at its 3-D area (as the
        packer scales them)."""
        A = face_areas(V, F)
        uv, faces, offset = [], [], 0
        for c in charts:  # loop over the charts
            uv.append(
                c.uv * np.sqrt(A[c.faces].sum() / np.abs(signed_areas(c.uv, c.local_F)).sum())
            )
            faces.append(c.local_F + offset)
            offset += len(c.uv)
        V3 = np.concatenate([V[c.vertices] for c in charts])
        d = distortion(V3, np.concatenate(faces), np.concatenate(uv))
        return d["l2_stretch"], d["angle_distortion"]

    l2_plain, angle_plain = figures(plain.charts)
    l2, angle = figures(cs.charts)
    assert angle < angle_plain - 0.01 and l2 < l2_plain
