"""Developable charts unrolled (segparam.unfold) and their place in the split stage."""

import numpy as np
import pytest
import trimesh
from meshes import spherical_cap, tri_grid

from segparam.mesh import annulus_cut, boundary_edges, cut_along, face_normals, submesh
from segparam.quality import chart_quality, segment_pairs_cross
from segparam.segment import segment
from segparam.split import parameterize_charts
from segparam.unfold import EDGE_TOL, developable, unroll_charts


def _side_lengths(X, F):
    E = F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    return np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1)


def _turned(kind, sections):
    """A CAD turned part: a cylinder, or a frustum (the cylinder's rings scaled along its axis:
    the side's flat facets stay flat), subdivided twice."""
    m = trimesh.creation.cylinder(radius=1.0, height=3.0, sections=sections)
    m = m.subdivide().subdivide()
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    if kind == "frustum":
        V = V * np.c_[0.75 + V[:, 2:] / 6, 0.75 + V[:, 2:] / 6, np.ones(len(V))]
    return V, F


def _wall(kind="cylinder"):
    """A CAD turned part's side wall (flat facets, creases along the axis), as a closed tube."""
    V, F = _turned(kind, sections=24)
    side = np.flatnonzero(np.abs(face_normals(V, F)[:, 2]) < 0.99)
    verts, local_F = submesh(F, side)
    return V[verts], local_F


def _opened(V, F):
    F_cut, copy_of = cut_along(F, annulus_cut(V, F))
    return V[copy_of], F_cut


def _one(V):
    return np.zeros(len(V), dtype=np.int64)


def test_an_opened_cylinder_unrolls_into_an_exact_isometry():
    V, F = _opened(*_wall())
    assert developable(V, F, _one(V), 1)[0]
    uv, error = unroll_charts(V, F, _one(V), 1)
    assert error[0] < 1e-10
    assert np.allclose(_side_lengths(uv, F), _side_lengths(V, F), rtol=1e-10, atol=0)
    q = chart_quality(V, F, uv - uv.min(axis=0))
    assert q.bijective and q.l2_stretch == pytest.approx(1.0, abs=1e-10)


def test_the_check_catches_what_does_not_unroll():
    # A closed tube: going round it the faces come back a circumference away.
    V, F = _wall()
    assert unroll_charts(V, F, _one(V), 1)[1][0] > 1.0
    # A curved chart: a vertex reached along two paths lands at two places.
    Vc, Fc = spherical_cap(9, 9)
    assert not developable(Vc, Fc, _one(Vc), 1)[0]
    assert unroll_charts(Vc, Fc, _one(Vc), 1)[1][0] > 1e-3
    # A chart in two pieces: the second is never reached.
    V2, F2 = tri_grid(4, 4)
    F2 = np.concatenate([F2, F2 + len(V2)])
    V2 = np.concatenate([V2, V2 + [5.0, 0.0, 0.0]])
    uv, error = unroll_charts(V2, F2, _one(V2), 1)
    assert error[0] == np.inf and np.isnan(uv).any()


def test_a_strip_without_interior_vertices_is_left_to_the_solver():
    # One triangle wide: it always unrolls, whatever surface it lies on, so it proves nothing.
    V, F = tri_grid(12, 2)
    V[:, 2] = np.sin(3 * V[:, 0])
    assert len(np.setdiff1d(np.arange(len(V)), boundary_edges(F).ravel())) == 0
    assert not developable(V, F, _one(V), 1)[0]


def test_charts_of_a_union_unroll_each_as_alone():
    parts = [_opened(*_wall("cylinder")), _opened(*_wall("frustum")), spherical_cap(7, 7)]
    offset = np.cumsum([0] + [len(V) for V, _ in parts])
    V = np.concatenate([P for P, _ in parts])
    F = np.concatenate([Fp + o for (_, Fp), o in zip(parts, offset, strict=False)])
    vert_chart = np.repeat(np.arange(3), np.diff(offset))
    assert developable(V, F, vert_chart, 3).tolist() == [True, True, False]
    uv, error = unroll_charts(V, F, vert_chart, 3)
    for k, (Vp, Fp) in enumerate(parts):
        uv_k, error_k = unroll_charts(Vp, Fp, _one(Vp), 1)
        assert np.array_equal(uv[offset[k] : offset[k + 1]], uv_k)
        assert error[k] == error_k[0]
    assert (error[:2] < EDGE_TOL).all() and error[2] > EDGE_TOL


@pytest.mark.parametrize("kind", ["cylinder", "frustum"])
def test_turned_parts_walls_map_as_one_exact_developable_chart(kind):
    V, F = _turned(kind, sections=48)
    cs = parameterize_charts(V, F, segment(V, F).labels)
    (wall,) = [c for c in cs.charts if c.method == "developable"]
    assert len(wall.faces) == int((np.abs(face_normals(V, F)[:, 2]) < 0.99).sum())
    assert wall.quality.bijective
    assert wall.quality.l2_stretch == pytest.approx(1.0, abs=1e-9)
    assert wall.quality.angle_distortion == pytest.approx(1.0, abs=1e-9)
    E = wall.local_F
    assert np.allclose(_side_lengths(wall.uv, E), _side_lengths(V[wall.vertices], E), rtol=1e-9)


def test_nearly_collinear_disjoint_segments_do_not_cross():
    # The straight rim of an unrolled wall: segments along one line, off it by rounding only
    # (pair 0); two segments that cross (pair 1) and two that touch (pair 2) still meet.
    P0 = np.array([[0.512, 7.1e-16], [0.687, 1.6e-15], [0.0, 0.0], [0.0, 1.0], [0.5, 0.0]])
    P1 = np.array([[0.523, 7.7e-16], [0.698, 1.66e-15], [1.0, 1.0], [1.0, 0.0], [0.5, 0.5]])
    B = np.arange(10).reshape(5, 2)
    i, j = np.array([0, 2, 2]), np.array([1, 3, 4])
    assert segment_pairs_cross(P0, P1, B, i, j).tolist() == [False, True, True]


def test_a_hole_wall_one_quad_high_unrolls():
    # A drilled hole's wall in a CAD plate: a tube one quad high, no inner vertex. As an open
    # strip such a piece proves nothing (strips=False); cut open from a tube it is a wall.
    n = 32
    theta = 2 * np.pi * np.arange(n) / n
    V = np.concatenate([np.c_[np.cos(theta), np.sin(theta), np.full(n, z)] for z in (0.0, 1.5)])
    a, b = np.arange(n), (np.arange(n) + 1) % n
    F = np.concatenate([np.c_[a, b, b + n], np.c_[a, b + n, a + n]])
    (wall,) = parameterize_charts(V, F, np.zeros(len(F), dtype=np.int64)).charts
    assert wall.method == "developable" and wall.quality.bijective
    Vc = V[wall.vertices]
    assert not developable(Vc, wall.local_F, _one(Vc), 1)[0]
    assert developable(Vc, wall.local_F, _one(Vc), 1, strips=True)[0]
    assert np.allclose(_side_lengths(wall.uv, wall.local_F), _side_lengths(Vc, wall.local_F))


def test_a_side_of_length_zero_is_laid_and_left_to_the_checks():
    from segparam.split import _unrolled

    V, F = tri_grid(5, 5)
    V[7] = V[6]  # two corners at one point: the triangles on that side have no area
    uv, error = unroll_charts(V, F, _one(V), 1)  # no division by zero
    assert np.isfinite(uv).all() and error[0] < EDGE_TOL
    assert _unrolled(V, F) is None  # its triangles of no area: no map kept, the solver decides
