"""Sharp vertices survive remeshing: a cone's tip, a cube's corners.

A user's closed cone with a valence-500 tip was remeshed by ``--remesh auto`` (its slivers ask for
it) and pymeshlab's smoothing pulled the tip from z = 1.0 down to 0.924: no dihedral angle there
is sharp (500 faces meet at under a degree each), but the angle defect is. Vertices with a large
angle defect are features too.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from meshes import tri_grid
from scipy.spatial import cKDTree

from segparam.clean import clean
from segparam.pipeline import PipelineConfig, build_atlas
from segparam.remesh import RemeshConfig, remesh, sharp_vertices

TIP = np.array([0.0, 0.0, 1.0])


def closed_cone(n: int = 500) -> tuple[np.ndarray, np.ndarray]:
    """A closed cone of height 1 and radius 1: tip (valence n) at z = 1, a fan for the base."""
    t = 2 * np.pi * np.arange(n) / n
    ring = np.c_[np.cos(t), np.sin(t), np.zeros(n)]
    V = np.vstack([TIP, ring, [0.0, 0.0, 0.0]])
    i = np.arange(n)
    j = (i + 1) % n
    side = np.c_[np.zeros(n, dtype=np.int64), i + 1, j + 1]
    base = np.c_[np.full(n, n + 1), j + 1, i + 1]
    return V, np.vstack([side, base]).astype(np.int64)


def subdivided_box(times: int = 2) -> tuple[np.ndarray, np.ndarray]:
    box = trimesh.creation.box()
    V, F = np.asarray(box.vertices, dtype=np.float64), np.asarray(box.faces, dtype=np.int64)
    for _ in range(times):
        V, F = trimesh.remesh.subdivide(V, F)
    c = clean(V, F)
    return c.V, c.F


def tip_distance(V: np.ndarray) -> float:
    return float(np.linalg.norm(V - TIP, axis=1).min())


@pytest.mark.parametrize("mode", ["auto", "on"])
def test_cone_tip_stays_in_place(mode):
    V, F = closed_cone()
    before = remesh(V, F, config=RemeshConfig(mode="off")).before
    assert before.frac_small_angles == 1.0  # the policy would remesh this cone
    res = remesh(V, F, config=RemeshConfig(mode=mode))
    assert tip_distance(res.V) < 1e-9, res.reason
    assert res.V[:, 2].max() == pytest.approx(1.0, abs=1e-9)
    if res.remeshed:
        assert "1 sharp vertices kept in place" in res.reason
    assert mode == "auto" or res.remeshed  # "on" still remeshes the rest (the base)


def test_cone_tip_stays_through_the_pipeline():
    V, F = closed_cone(200)
    cfg = PipelineConfig().replace(pack={"resolution": 128}, remesh={"mode": "auto"})
    atlas = build_atlas(V, F, cfg)
    assert tip_distance(atlas.V) < 1e-9


def test_sharp_vertices_are_tips_and_corners_not_smooth_or_flat_points():
    V, F = closed_cone()
    assert sharp_vertices(V, F).tolist() == [0]  # the tip, not the flat base centre
    Vb, Fb = subdivided_box()
    corners = np.abs(np.abs(Vb) - 0.5).max(axis=1) < 1e-12
    assert sorted(sharp_vertices(Vb, Fb).tolist()) == np.flatnonzero(corners).tolist()
    sphere = trimesh.creation.icosphere(3)
    assert len(sharp_vertices(sphere.vertices, sphere.faces)) == 0
    # A smooth but uneven closed surface (an ellipsoid) has no point either. (The sample brain
    # is no such surface since it is folded like a real cortex: its sulcal fundi exceed 12.3
    # degrees of angle defect at 1,097 of 10,002 vertices, fsaverage5's pial at 928 of 10,242.)
    ellipsoid = trimesh.creation.icosphere(4).vertices * [1.0, 0.7, 0.5]
    assert len(sharp_vertices(ellipsoid, trimesh.creation.icosphere(4).faces)) == 0
    Vg, Fg = tri_grid(6, 5)  # boundary corners do not count
    assert len(sharp_vertices(Vg, Fg)) == 0
    assert len(sharp_vertices(V, F, feature_angle=180.0)) == 0


def test_cube_corners_stay_in_place():
    V, F = subdivided_box()
    res = remesh(V, F, config=RemeshConfig(mode="on"))
    assert res.remeshed, res.reason
    corners = V[sharp_vertices(V, F)]
    moved, _ = cKDTree(res.V).query(corners)
    assert len(corners) == 8 and moved.max() < 1e-9


def test_a_mesh_without_sharp_vertices_is_remeshed_as_before():
    """No sharp vertex: nothing is frozen, the reason does not mention them."""
    rng = np.random.default_rng(0)
    V, F = tri_grid(20, 20)
    V = V + np.c_[rng.normal(0, 0.01, (len(V), 2)), np.zeros(len(V))]
    res = remesh(V, F, config=RemeshConfig(mode="on"))
    assert res.remeshed and "sharp" not in res.reason


# ---------------------------------------------------------------------------------------------
# slivers where no solver runs


def test_exact_faces_are_the_planar_and_developable_regions():
    from segparam.remesh import exact_faces

    m = trimesh.creation.cylinder(radius=1.0, height=3.0, sections=48)
    # the side one quad high has no inner vertex: a strip proves nothing, it is not counted
    exact = exact_faces(m.vertices, m.faces)
    assert exact.any() and not exact.all()
    m = m.subdivide()
    assert exact_faces(m.vertices, m.faces).all()  # caps (planar) and side (developable)
    s = trimesh.creation.icosphere(3)
    assert not exact_faces(s.vertices, s.faces).any()
    V, F = closed_cone()
    exact = exact_faces(V, F)
    assert exact[500:].all() and not exact[:500].any()  # the base, not the side (its tip)


def test_a_capped_cylinders_slivers_are_not_remeshed():
    """The caps' fan triangles are slivers, which "auto" remeshes on a curved surface; here
    every face is mapped exactly (caps projected, side unrolled), so the mesh is kept."""
    m = trimesh.creation.cylinder(radius=1.0, height=3.0, sections=48).subdivide().subdivide()
    V, F = np.asarray(m.vertices), np.asarray(m.faces, dtype=np.int64)
    r = remesh(V, F, config=RemeshConfig(mode="auto"))
    assert not r.remeshed and "developable" in r.reason and "slivers" in r.reason
    a = build_atlas(V, F, PipelineConfig(), seed=0)  # the default policy, "auto"
    assert not a.remeshing.remeshed
    assert sorted(c.method for c in a.charts.charts) == ["developable", "planar", "planar"]


# ---------------------------------------------------------------------------------------------
# what cleaning split, and sharp vertices where creases meet


def _sample(name: str) -> tuple[np.ndarray, np.ndarray]:
    """A real mesh from pymeshlab's bundled samples (pymeshlab is a dependency), cleaned."""
    import importlib.util
    from pathlib import Path

    from segparam.io import load_mesh

    folder = Path(importlib.util.find_spec("pymeshlab").origin).parent / "tests" / "sample_meshes"
    if not (folder / name).is_file():
        pytest.skip(f"this pymeshlab wheel has no {name}")
    c = clean(*load_mesh(folder / name))
    return c.V, c.F


def two_spheres_touching() -> tuple[np.ndarray, np.ndarray]:
    """Two jittered icospheres sharing one vertex (a non-manifold point), as cleaning leaves
    them: two vertex copies at the same position, one per sphere."""
    s = trimesh.creation.icosphere(2)
    P, T = np.asarray(s.vertices), np.asarray(s.faces, dtype=np.int64)
    P = P + np.random.default_rng(0).normal(0, 0.02, P.shape)
    low = int(np.argmin(P[:, 2]))
    A = P - P[low]  # touches the origin with its lowest vertex
    B = -A  # ... and its mirror image, turned the right way out below
    V = np.vstack([A, B])
    F = np.vstack([T, T[:, ::-1] + len(P)])
    F[F == len(P) + low] = low  # one shared vertex
    c = clean(V, F)
    assert c.split_vertices == 1
    return c.V, c.F


def test_a_point_that_cleaning_split_is_split_again_after_remeshing():
    """pymeshlab merges vertices at the same position before it remeshes: the two copies that
    cleaning made of a non-manifold vertex became one again, the result was non-manifold and
    the remeshing was thrown away (pymeshlab's cow, 0.4 s). Now it is split again."""
    V, F = two_spheres_touching()
    res = remesh(V, F, config=RemeshConfig(mode="on"))
    assert res.remeshed, res.reason
    from segparam.mesh import connected_components, is_edge_manifold, is_vertex_manifold

    assert is_edge_manifold(res.F) and is_vertex_manifold(res.F, len(res.V)).all()
    assert connected_components(res.F)[0] == 2


def test_the_cow_is_remeshed_not_thrown_away():
    V, F = _sample("cow.obj")  # a non-manifold vertex, split by cleaning
    res = remesh(V, F, config=RemeshConfig(mode="auto"))
    assert res.remeshed, res.reason


def test_sharp_vertices_where_creases_meet_are_frozen_too():
    """pymeshlab keeps a vertex where three or more sharp edges meet by itself, but not always:
    on its bunny with holes one such vertex moved by 0.149 and the remeshing (0.8 s) was thrown
    away. Every sharp vertex's faces are now left out of the remeshing."""
    V, F = _sample("bunny10k_textured.obj")
    res = remesh(V, F, config=RemeshConfig(mode="auto"))
    assert res.remeshed, res.reason
    sharp = sharp_vertices(V, F)
    moved, _ = cKDTree(res.V).query(V[sharp])
    assert len(sharp) > 100 and moved.max() < 1e-9


def test_auto_leaves_planar_and_developable_regions_as_they_are():
    """Under "auto" the faces the split stage maps exactly (planar or developable regions) are
    not remeshed: a subdivided cone's base (planar slivers) comes back face for face while its
    side (curved at the tip) is remeshed; "on" remeshes the base too."""
    m = trimesh.creation.cone(radius=1.0, height=2.0, sections=48).subdivide().subdivide()
    V, F = np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)
    on_base = np.abs(V[F][:, :, 2]).max(axis=1) < 1e-12
    res = remesh(V, F, config=RemeshConfig(mode="auto"))
    assert res.remeshed and "(planar, developable) kept" in res.reason
    kept = np.abs(res.V[res.F][:, :, 2]).max(axis=1) < 1e-12
    assert kept.sum() == on_base.sum()
    moved, _ = cKDTree(res.V).query(V[np.unique(F[on_base])])
    assert moved.max() < 1e-12
    on = remesh(V, F, config=RemeshConfig(mode="on"))
    assert (np.abs(on.V[on.F][:, :, 2]).max(axis=1) < 1e-12).sum() != on_base.sum()
