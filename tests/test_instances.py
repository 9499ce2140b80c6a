"""Repeated parts are charted once (segparam.instances): copies found exactly, charts shared."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from segparam.clean import clean
from segparam.instances import candidates, expand_labels, find_repeats
from segparam.pack import footprint_conflicts
from segparam.pipeline import PipelineConfig, build_atlas
from segparam.quality import signed_areas


def bumpy_part(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A closed, irregular part (a jittered icosphere): no symmetry for a copy to hide in."""
    s = trimesh.creation.icosphere(2)
    V = np.asarray(s.vertices) * np.random.default_rng(seed).uniform(0.8, 1.2, (len(s.vertices), 1))
    return V, np.asarray(s.faces, dtype=np.int64)


def placed(V: np.ndarray, k: int, *, scale: float = 1.0, mirror: bool = False) -> np.ndarray:
    R = Rotation.random(random_state=k).as_matrix()
    if mirror:
        R = R @ np.diag([1.0, 1.0, -1.0])
    return scale * V @ R.T + [5.0 * k, 0.0, 0.0]


def union(parts) -> tuple[np.ndarray, np.ndarray]:
    Vs, Fs, n = [], [], 0
    for V, F in parts:
        Vs.append(V)
        Fs.append(F + n)
        n += len(V)
    return np.vstack(Vs), np.vstack(Fs)


def test_copies_moved_turned_and_scaled_are_found():
    V, F = bumpy_part()
    other = bumpy_part(seed=1)  # same faces, other shape: not a copy
    parts = [(placed(V, k, scale=0.5 + 0.3 * k), F) for k in range(5)] + [other]
    Vm, Fm = union(parts)
    rep = find_repeats(Vm, Fm)
    assert rep is not None and len(rep.faces) == 1
    faces, verts, scale = rep.faces[0], rep.vertices[0], rep.scale[0]
    assert faces.shape == (5, len(F))
    np.testing.assert_allclose(scale, (0.5 + 0.3 * np.arange(5)) / 0.5, rtol=1e-12)
    # rows correspond: face i of each copy is face i of the part, in its copy's vertices
    for k in range(5):
        np.testing.assert_array_equal(Fm[faces[k]] - k * len(V), F)
        assert verts[k].min() == k * len(V)


def test_mirror_images_and_moved_vertices_are_not_copies():
    V, F = bumpy_part()
    bent = V.copy()
    bent[3] += 1e-3  # one vertex off by about 1e-3 of the radius
    Vm, Fm = union([(placed(V, 0), F), (placed(V, 1, mirror=True), F[:, ::-1]), (bent, F)])
    assert find_repeats(Vm, Fm) is None
    # ... and a mesh of one piece, or of pieces that all differ, has none
    assert find_repeats(V, F) is None
    rng = np.random.default_rng(0)
    tri = rng.normal(size=(300, 3, 3)) + 10 * rng.uniform(size=(300, 1, 3))
    assert find_repeats(tri.reshape(-1, 3), np.arange(900).reshape(-1, 3)) is None


def test_flat_copies_turned_over_are_copies():
    """A flat piece turned over is the same piece (a rotation by half a turn), not a mirror
    image: the best proper rotation fits it."""
    g = trimesh.creation.box().subdivide()  # any face list: take one side, a flat piece
    V, F = np.asarray(g.vertices), np.asarray(g.faces)
    top = np.flatnonzero(np.isclose(V[F].mean(axis=1)[:, 2], 0.5))
    used, Ft = np.unique(F[top], return_inverse=True)
    Vt, Ft = V[used], Ft.reshape(-1, 3)
    flipped = Vt @ np.diag([1.0, -1.0, -1.0]) + [3.0, 0, 0]  # half a turn about x
    rep = find_repeats(*union([(Vt, Ft), (flipped, Ft)]))
    assert rep is not None and rep.faces[0].shape[0] == 2


def test_candidates_are_the_differently_cut_pieces():
    V, F = bumpy_part()
    Vm, Fm = union([(placed(V, k), F) for k in range(4)])
    rep = find_repeats(Vm, Fm)
    n = len(F)
    half = (np.arange(n) < n // 2).astype(np.int64)
    labels = np.concatenate([half, half + 2, 1 - half + 4, half + 6])  # the third cut otherwise
    assert candidates(labels, rep)[0].tolist() == [0, 2]
    assert candidates(labels, rep, most=1)[0].tolist() == [0]
    out = expand_labels(labels, rep, [2])
    # every piece now cut as the third: its two charts, fresh labels, compact
    assert len(np.unique(out)) == 8 and out.max() == 7
    for k in range(4):
        mine = out[k * n : (k + 1) * n]
        assert len(np.unique(mine)) == 2
        assert (mine[: n // 2] != mine[n // 2]).all() or (mine == mine[0]).sum() == n - n // 2


def test_an_atlas_of_copies_gives_each_copy_the_same_charts():
    V, F = bumpy_part()
    parts = [(placed(V, k, scale=1.0 + 0.25 * k), F) for k in range(6)]
    Vm, Fm = union(parts + [bumpy_part(seed=2)])
    cfg = PipelineConfig().replace(pack={"resolution": 256}, remesh={"mode": "off"})
    atlas = build_atlas(Vm, Fm, cfg, seed=0)
    charts = atlas.charts.charts
    per_piece = np.bincount([c.faces[0] // len(F) for c in charts], minlength=7)
    assert len(set(per_piece[:6].tolist())) == 1  # the six copies: as many charts each
    # each face once, every chart bijective, nothing mirrored, no two footprints overlapping
    faces = np.sort(np.concatenate([c.faces for c in charts]))
    np.testing.assert_array_equal(faces, np.arange(len(Fm)))
    assert all(c.quality.bijective for c in charts)
    assert (signed_areas(atlas.uv, atlas.uv_F) > 0).all()
    uvs = [atlas.uv[atlas.uv_F[c.faces]].reshape(-1, 2) for c in charts]
    tris = [np.arange(3 * len(c.faces)).reshape(-1, 3) for c in charts]
    assert footprint_conflicts(uvs, tris, resolution=256, padding=0) == 0
    # a copy's charts are its original's, scaled: the same stretch and angle distortion
    by_piece = {}
    for c in charts:
        by_piece.setdefault(int(c.faces[0] // len(F)), []).append(
            (round(c.quality.l2_stretch, 9), round(c.quality.angle_distortion, 9))
        )
    assert all(sorted(by_piece[k]) == sorted(by_piece[0]) for k in range(6))
    # the segmentation's labels and chart counts follow
    assert atlas.segmentation.n_charts == int(atlas.segmentation.labels.max()) + 1
    assert len(atlas.charts.splits) == atlas.segmentation.n_charts


def test_the_solver_sees_a_few_copies_only(monkeypatch):
    """Of 12 copies the split stage gets those the segmentation cut differently, `CANDIDATES`
    at most (rounding can cut copies of one part differently), and the part that is no copy."""
    import segparam.pipeline as pipeline
    from segparam.instances import CANDIDATES

    seen = []
    real = pipeline.parameterize_charts

    def spy(V, F, labels, **kw):
        seen.append(len(F))
        return real(V, F, labels, **kw)

    monkeypatch.setattr(pipeline, "parameterize_charts", spy)
    V, F = bumpy_part()
    other = bumpy_part(seed=3)
    cfg = PipelineConfig().replace(pack={"resolution": 512}, remesh={"mode": "off"})
    atlas = build_atlas(*union([(placed(V, k), F) for k in range(12)] + [other]), cfg, seed=0)
    assert len(seen) == 1 and 2 * len(F) <= seen[0] <= (CANDIDATES + 1) * len(F)
    per_piece = np.bincount([c.faces[0] // len(F) for c in atlas.charts.charts])
    assert len(set(per_piece[:12].tolist())) == 1


def test_clean_counts_pieces_for_the_early_exit():
    V, F = bumpy_part()
    assert clean(*union([(V, F), (placed(V, 1), F)])).components == 2


def test_meshes_that_copy_an_earlier_one_are_charted_as_it_is(monkeypatch, tmp_path):
    """build_atlases (a GLB scene's nodes placing one mesh several times): a mesh with the same
    faces as an earlier one and its vertices moved, turned and scaled is charted as that one,
    in its own coordinates, exactly as given."""
    import segparam.pipeline as pipeline
    from segparam.pipeline import build_atlases

    calls = []
    real = pipeline._chart_mesh

    def spy(*args, **kw):
        calls.append(1)
        return real(*args, **kw)

    monkeypatch.setattr(pipeline, "_chart_mesh", spy)
    V, F = bumpy_part()
    W = placed(V, 2, scale=2.0)
    B = bumpy_part(seed=5)
    cfg = PipelineConfig().replace(pack={"resolution": 256}, remesh={"mode": "off"})
    multi = build_atlases([(V, F), (W, F), B], cfg, names=["a", "b", "c"])
    assert len(calls) == 2  # a and c; b is a copy of a
    a, b, c = multi.atlases
    assert len(b.charts.charts) == len(a.charts.charts)
    np.testing.assert_array_equal(b.V, W)  # its own vertices, bit for bit
    assert "a copy of a" in b.remeshing.reason
    for x, y in zip(a.charts.charts, b.charts.charts, strict=True):
        np.testing.assert_allclose(y.uv, 2.0 * x.uv)
    # one texture: no flips, every chart's footprint apart from every other's
    uvs, tris = [], []
    for atlas in multi.atlases:
        assert (signed_areas(atlas.uv, atlas.uv_F) > 0).all()
        for ch in atlas.charts.charts:
            uvs.append(atlas.uv[atlas.uv_F[ch.faces]].reshape(-1, 2))
            tris.append(np.arange(3 * len(ch.faces)).reshape(-1, 3))
    assert footprint_conflicts(uvs, tris, resolution=256, padding=0) == 0
    # b's texels per unit of length are a's: twice the size, four times the uv area
    area = [np.abs(signed_areas(m.uv, m.uv_F)).sum() for m in (a, b)]
    assert area[1] == pytest.approx(4 * area[0], rel=1e-6)
    multi.save(tmp_path / "out")
    assert (tmp_path / "out" / "b.obj").is_file()
