from __future__ import annotations

import json
import logging

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from meshes import tri_grid

from segparam import mesh
from segparam.clean import CleanResult, clean
from segparam.errors import InvalidMeshError


def soup(V, F):
    """An STL-like triangle soup: every face gets its own three vertices."""
    return V[F].reshape(-1, 3), np.arange(3 * len(F)).reshape(-1, 3)


def sphere(subdivisions=2, center=(0.0, 0.0, 0.0), radius=1.0):
    S = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(S.vertices) + center, np.asarray(S.faces, dtype=np.int64)


def moebius(n=24, w=1):
    """A Moebius strip, ``n`` quads around and ``w`` across (``w > 1`` has interior vertices)."""
    i, j = np.meshgrid(np.arange(n), np.arange(w + 1), indexing="ij")
    t, s = 2 * np.pi * i / n, j / w - 0.5
    r = 1 + 0.5 * s * np.cos(t / 2)
    V = np.stack([r * np.cos(t), r * np.sin(t), 0.5 * s * np.sin(t / 2)], -1).reshape(-1, 3)
    idx = np.arange(n * (w + 1)).reshape(n, w + 1)
    nxt = np.vstack([idx[1:], idx[:1, ::-1]])  # the half twist
    a, b, c, d = idx[:, :-1], nxt[:, :-1], nxt[:, 1:], idx[:, 1:]
    F = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    return V, F


def klein_bottle(n=24, m=15, r=2.0):
    """The figure-8 Klein bottle: closed and non-orientable (``m`` odd keeps vertices apart)."""
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    u, v = 2 * np.pi * i / n, 2 * np.pi * j / m
    a = r + np.cos(u / 2) * np.sin(v) - np.sin(u / 2) * np.sin(2 * v)
    z = np.sin(u / 2) * np.sin(v) + np.cos(u / 2) * np.sin(2 * v)
    V = np.stack([a * np.cos(u), a * np.sin(u), z], -1).reshape(-1, 3)
    idx = np.arange(n * m).reshape(n, m)
    nxt = np.vstack([idx[1:], idx[:1, (-np.arange(m)) % m]])  # (u + 2 pi, v) ~ (u, -v)
    c, d = np.roll(nxt, -1, 1), np.roll(idx, -1, 1)
    F = np.concatenate([np.stack([idx, nxt, c], -1), np.stack([idx, c, d], -1)]).reshape(-1, 3)
    return V, F


def assert_valid(r: CleanResult, n_in: int, m_in: int):
    """Manifold, consistently oriented, and every input face and vertex accounted for."""
    assert r.F.dtype == np.int64 and r.V.dtype == np.float64
    assert mesh.is_edge_manifold(r.F)  # also checks that neighbours traverse edges oppositely
    assert mesh.is_vertex_manifold(r.F, len(r.V)).all()
    assert np.bincount(r.F.ravel(), minlength=len(r.V)).min() > 0  # no unreferenced vertex
    everything = np.sort(np.concatenate([r.face_index, r.removed_faces]))
    np.testing.assert_array_equal(everything, np.arange(m_in))
    assert np.all(np.diff(r.face_index) > 0)
    assert len(r.removed_reasons) == len(r.removed_faces)
    assert r.input_faces == m_in and r.input_vertices == n_in
    assert n_in == r.merged_vertices + r.removed_unreferenced + len(r.V) - r.split_vertices
    assert r.components == mesh.connected_components(r.F)[0]


def fin_grid():
    """A grid with a fin: an extra triangle on an interior edge."""
    V, F = tri_grid(6, 6)
    E, count = mesh.edge_face_counts(F)
    u, v = E[np.flatnonzero(count == 2)[len(E) // 3]]
    top = (V[u] + V[v]) / 2 + [0, 0, 0.5]
    return np.vstack([V, top]), np.vstack([F, [u, v, len(V)]]), (u, v)


# ---------------------------------------------------------------------------------------------
# Each repair on its own
# ---------------------------------------------------------------------------------------------


def test_clean_grid_is_unchanged():
    V, F = tri_grid(9, 7)
    r = clean(V, F)
    np.testing.assert_array_equal(r.V, V)
    np.testing.assert_array_equal(r.F, F)
    np.testing.assert_array_equal(r.face_index, np.arange(len(F)))
    np.testing.assert_array_equal(r.vertex_index, np.arange(len(V)))
    assert len(r.removed_faces) == 0
    counts = r.summary()
    for key in ("merged_vertices", "removed_unreferenced", "split_edges", "split_vertices"):
        assert counts[key] == 0
    assert counts["flipped_faces"] == 0 and counts["cut_edges"] == 0
    assert counts["components"] == 1
    assert_valid(r, len(V), len(F))


def test_clean_closed_sphere_is_unchanged():
    V, F = sphere(3)
    r = clean(V, F)
    np.testing.assert_array_equal(r.V, V)
    np.testing.assert_array_equal(r.F, F)
    assert r.flipped_faces == 0


def test_soup_is_merged_back_to_the_original_topology():
    V, F = sphere(2)
    Vs, Fs = soup(V, F)
    r = clean(Vs, Fs)
    assert_valid(r, len(Vs), len(Fs))
    assert len(r.V) == len(V) and r.merged_vertices == len(Vs) - len(V)
    # Map output vertices back to the original ones by position: same faces, same order.
    back = np.empty(len(r.V), dtype=np.int64)
    back[np.lexsort(r.V.T[::-1])] = np.lexsort(V.T[::-1])
    np.testing.assert_array_equal(back[r.F], F)
    np.testing.assert_array_equal(Vs[r.vertex_index], r.V)


def test_merge_tolerance_is_relative_to_the_bounding_box():
    V, F = tri_grid(5, 5, width=1000.0)
    Vs, Fs = soup(V, F)
    Vs = Vs + np.random.default_rng(1).normal(scale=1e-8, size=Vs.shape)  # << 1e-9 * diag
    r = clean(Vs, Fs)
    assert len(r.V) == len(V)
    assert_valid(r, len(Vs), len(Fs))
    exact = clean(Vs, Fs, merge_tolerance=0.0)
    assert len(exact.V) == len(Vs) and exact.merged_vertices == 0


def test_negative_zero_equals_zero():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [-0.0, 0, 0], [1, 0, 0], [0, -1, 0]])
    r = clean(V, [[0, 1, 2], [3, 5, 4]], merge_tolerance=0.0)
    assert r.merged_vertices == 2 and len(r.V) == 4


def test_degenerate_faces_are_removed_with_reasons():
    V, F = tri_grid(5, 5)
    n = len(V)
    V = np.vstack([V, [[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.0, 0.0]]])  # collinear
    extra = np.array([[0, 0, 1], [n, n + 1, n + 2], [3, 4, 3]])
    r = clean(V, np.vstack([F, extra]))
    m = len(F)
    np.testing.assert_array_equal(r.removed_faces, [m, m + 1, m + 2])
    assert list(r.removed_reasons) == ["repeated vertex", "zero area", "repeated vertex"]
    np.testing.assert_array_equal(r.F, F)
    # The collinear vertex (0, 0, 0) duplicates vertex 0; the other two are left unreferenced.
    assert r.merged_vertices == 1 and r.removed_unreferenced == 2
    assert_valid(r, len(V), m + 3)


def test_faces_collapsed_by_merging_count_as_repeated_vertex():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1e-14, 0]])
    r = clean(V, [[0, 1, 2], [1, 3, 2]])
    assert list(r.removed_reasons) == ["repeated vertex"] and r.merged_vertices == 1


def test_duplicate_faces_are_removed_in_either_winding():
    V, F = tri_grid(5, 5)
    extra = np.array([F[3], F[3][[1, 2, 0]], F[7][::-1], F[0][[0, 2, 1]]])
    r = clean(V, np.vstack([F, extra]))
    m = len(F)
    np.testing.assert_array_equal(r.removed_faces, m + np.arange(4))
    assert set(r.removed_reasons) == {"duplicate face"}
    np.testing.assert_array_equal(r.F, F)
    np.testing.assert_array_equal(r.face_index, np.arange(m))
    assert r.summary()["removed_faces"] == {"duplicate face": list(range(m, m + 4))}


def test_fin_on_an_edge_is_split_off():
    V, F, (u, v) = fin_grid()
    assert not mesh.is_edge_manifold(F)
    r = clean(V, F)
    assert_valid(r, len(V), len(F))
    assert r.split_edges == 1 and r.split_vertices == 2 and r.components == 2
    np.testing.assert_array_equal(r.F[:-1], F[:-1])  # the grid keeps its vertices
    np.testing.assert_array_equal(np.sort(r.vertex_index[-2:]), np.sort([u, v]))
    np.testing.assert_array_equal(r.V[r.F[-1]], V[F[-1]])


def test_two_closed_parts_sharing_an_edge_stay_closed():
    """Four faces on one edge are glued in pairs, so both tetrahedra stay closed."""
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, -1, 0], [0, 0, -1]])
    A = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    B = np.array([0, 1, 4, 5])[A]  # A turned 180 degrees about the x axis
    F = np.vstack([A, B])
    r = clean(V, F)
    assert_valid(r, len(V), len(F))
    assert r.split_edges == 1 and r.split_vertices == 2 and r.components == 2
    assert len(mesh.boundary_edges(r.F)) == 0
    np.testing.assert_array_equal(r.F[:4], A)
    np.testing.assert_array_equal(r.vertex_index, [0, 1, 2, 3, 4, 5, 0, 1])
    assert r.flipped_faces == 0


@pytest.mark.parametrize("order", [range(7), [2, 3, 4, 0, 1, 5, 6], [4, 6, 2, 0, 5, 3, 1]])
def test_extra_face_joined_around_both_ends_is_still_split(order, caplog):
    """Three faces on edge (u, v), none a loose fin; the extra one is joined to the glued pair
    around u (through face 3) and around v (through face 4), so splitting by fans is not enough."""
    V = np.array(
        [[0.0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0.2], [0.5, -0.8, 1], [1, 1, 0], [0, 1, 0]]
    )
    F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [0, 3, 4], [1, 4, 3], [2, 1, 5], [0, 2, 6]])
    F = F[list(order)]
    with caplog.at_level(logging.DEBUG, logger="segparam.clean"):
        r = clean(V, F)
    assert_valid(r, len(V), len(F))
    assert r.split_edges == 1 and len(r.removed_faces) == 0
    assert "still non-manifold" in caplog.text


def test_bowtie_vertex_is_split():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]])
    F = np.array([[0, 1, 2], [0, 3, 4]])
    assert not mesh.is_vertex_manifold(F).all()
    r = clean(V, F)
    assert_valid(r, len(V), len(F))
    assert r.split_vertices == 1 and r.components == 2
    np.testing.assert_array_equal(r.vertex_index, [0, 1, 2, 3, 4, 0])
    np.testing.assert_array_equal(r.F, [[0, 1, 2], [5, 3, 4]])


def test_grid_touching_a_triangle_at_a_corner():
    V, F = tri_grid(5, 5)
    c = len(V) // 2  # an interior vertex
    V = np.vstack([V, V[c] + [[0.1, 0, 0.5], [0, 0.1, 0.5]]])
    F = np.vstack([F, [c, len(V) - 2, len(V) - 1]])
    r = clean(V, F)
    assert_valid(r, len(V), len(F))
    assert r.split_vertices == 1 and r.split_edges == 0


def test_inconsistent_orientation_is_fixed_and_outward():
    V, F = sphere(3)
    rng = np.random.default_rng(0)
    flip = rng.random(len(F)) < 0.5
    Fbad = np.where(flip[:, None], F[:, [0, 2, 1]], F)
    r = clean(V, Fbad)
    assert_valid(r, len(V), len(F))
    np.testing.assert_array_equal(r.F, F)  # flipping back restores the exact rows
    assert r.flipped_faces == flip.sum()


def test_inside_out_closed_mesh_is_turned_outward_and_open_keeps_majority():
    V, F = sphere(2)
    r = clean(V, F[:, ::-1])
    assert r.flipped_faces == len(F)
    P = r.V[r.F]
    assert np.einsum("ij,ij->i", P[:, 0], np.cross(P[:, 1], P[:, 2])).sum() > 0
    # An open grid: flip a minority of faces; the majority's winding wins.
    G, H = tri_grid(7, 7)
    flip = np.zeros(len(H), dtype=bool)
    flip[::3] = True
    r = clean(G, np.where(flip[:, None], H[:, ::-1], H))
    assert r.flipped_faces == flip.sum()
    np.testing.assert_array_equal(np.sort(r.F, axis=1), np.sort(H, axis=1))
    assert (mesh.face_normals(r.V, r.F)[:, 2] > 0).all()


def test_several_components_each_oriented():
    V1, F1 = sphere(1)
    V2, F2 = sphere(2, center=(5.0, 0, 0))
    V3, F3 = tri_grid(4, 4)
    V = np.vstack([V1, V2, V3 + [0, 5, 0]])
    F = np.vstack([F1, F2[:, ::-1] + len(V1), F3 + len(V1) + len(V2)])
    r = clean(V, F)
    assert_valid(r, len(V), len(F))
    assert r.components == 3 and r.flipped_faces == len(F2)
    labels = mesh.connected_components(r.F)[1]
    for c in range(3):
        Fc = r.F[labels == c]
        if len(mesh.boundary_edges(Fc)) == 0:
            P = r.V[Fc] - r.V[Fc].reshape(-1, 3).mean(0)
            assert np.einsum("ij,ij->i", P[:, 0], np.cross(P[:, 1], P[:, 2])).sum() > 0


@pytest.mark.parametrize("w", [1, 3])
def test_moebius_strip_is_cut_open(w):
    V, F = moebius(w=w)
    r = clean(V, F)
    assert_valid(r, len(V), len(F))
    assert r.cut_edges >= 1 and r.split_vertices >= 2
    assert r.components == 1
    assert len(r.removed_faces) == 0  # cut, not deleted


def test_klein_bottle_is_cut_along_a_cycle():
    V, F = klein_bottle()
    perm = np.random.default_rng(3).permutation(len(F))
    r = clean(V, F[perm])
    assert_valid(r, len(V), len(F))
    assert r.cut_edges > 0 and len(r.removed_faces) == 0 and r.components == 1
    assert len(mesh.boundary_loops(r.F)) >= 1


# ---------------------------------------------------------------------------------------------
# Everything at once, accounting, properties
# ---------------------------------------------------------------------------------------------


def messy_mesh(seed=0):
    """Soup of a grid with a fin, a bowtie, flips, duplicates, degenerate faces, a second part."""
    rng = np.random.default_rng(seed)
    V, F, _ = fin_grid()
    V2, F2 = sphere(1, center=(3.0, 0, 0), radius=0.5)
    V = np.vstack([V, V2, [[-1.0, -1, 0], [-1, 0, 0]]])
    F = np.vstack([F, F2 + (len(V) - len(V2) - 2), [[0, len(V) - 2, len(V) - 1]]])  # bowtie at 0
    flip = rng.random(len(F)) < 0.4
    F = np.where(flip[:, None], F[:, ::-1], F)
    F = np.vstack([F, F[[2, 9]][:, ::-1], F[[4]], [[1, 1, 2], [5, 6, 5]]])
    Vs, Fs = soup(V, F)
    return Vs, Fs[rng.permutation(len(Fs))]


def test_messy_mesh_nothing_is_lost():
    V, F = messy_mesh()
    r = clean(V, F)
    assert_valid(r, len(V), len(F))
    reasons = dict(zip(*np.unique(r.removed_reasons, return_counts=True), strict=True))
    assert reasons == {"duplicate face": 3, "repeated vertex": 2}
    assert r.split_edges == 1 and r.split_vertices == 3  # fin: 2 copies, bowtie: 1
    assert r.components == 4  # grid, fin, bowtie triangle, sphere
    s = r.summary()
    assert json.loads(json.dumps(s)) == s
    assert sum(len(v) for v in s["removed_faces"].values()) == len(r.removed_faces)
    assert s["output_faces"] + len(r.removed_faces) == len(F)
    # Idempotent: a cleaned mesh is clean.
    again = clean(r.V, r.F)
    np.testing.assert_array_equal(again.F, r.F)
    np.testing.assert_array_equal(again.V, r.V)


def test_result_is_frozen():
    V, F = tri_grid(3, 3)
    r = clean(V, F)
    with pytest.raises(AttributeError):
        r.F = F  # type: ignore[misc]
    with pytest.raises(ValueError):
        r.F[0, 0] = 1


@settings(max_examples=40, deadline=None)
@given(
    keep=st.lists(st.booleans(), min_size=50, max_size=50),
    flip=st.lists(st.booleans(), min_size=50, max_size=50),
    dups=st.lists(st.tuples(st.integers(0, 49), st.booleans()), max_size=10),
    as_soup=st.booleans(),
)
def test_property_random_grid_pieces(keep, flip, dups, as_soup):
    V, F = tri_grid(6, 6)
    F = np.where(np.array(flip)[:, None], F[:, [0, 2, 1]], F)
    F = F[np.array(keep)]
    if len(F) == 0:
        return
    extra = [F[i % len(F)][::-1] if rev else F[i % len(F)] for i, rev in dups]
    F = np.vstack([F, *extra]) if extra else F
    if as_soup:
        V, F = soup(V, F)
    r = clean(V, F)
    assert_valid(r, len(V), len(F))
    assert len(r.removed_faces) == len(extra) and set(r.removed_reasons) <= {"duplicate face"}
    assert (mesh.face_normals(r.V, r.F)[:, 2] != 0).all()
    # Each output face is its input face, possibly reversed.
    np.testing.assert_array_equal(np.sort(r.V[r.F], axis=1), np.sort(V[F[r.face_index]], axis=1))


def test_rigid_motion_does_not_change_the_topology():
    V, F = messy_mesh(1)
    Q, _ = np.linalg.qr(np.random.default_rng(2).standard_normal((3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    a, b = clean(V, F), clean(V @ Q.T * 7 + 3, F)
    np.testing.assert_array_equal(a.F, b.F)
    np.testing.assert_array_equal(a.face_index, b.face_index)


# ---------------------------------------------------------------------------------------------
# Errors
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "V, F, message",
    [
        ([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]], [[0, 1, 2]], "1 of 3 vertices have NaN"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]], r"span \[0, 3\] but the mesh has 3"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, -1]], r"span \[-1, 1\]"),
        (np.zeros((3, 2)), [[0, 1, 2]], "shape"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.zeros((0, 3), int), "no faces"),
        (
            [[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]],
            [[0, 1, 2], [1, 2, 0], [3, 3, 0]],
            "no faces left after cleaning: of 3 faces, 1 repeated vertex, 2 zero area",
        ),
    ],
)
def test_clean_rejects_bad_input(V, F, message):
    with pytest.raises(InvalidMeshError, match=message):
        clean(V, F)


def test_negative_tolerance_is_rejected():
    V, F = tri_grid(3, 3)
    with pytest.raises(InvalidMeshError, match="tolerances must be >= 0"):
        clean(V, F, merge_tolerance=-1.0)


# ---------------------------------------------------------------------------------------------
# Helpers against the computations they replace
# ---------------------------------------------------------------------------------------------


def test_apart_only_when_the_kd_tree_and_grouping_find_nothing():
    """The sweep that lets merging skip grouping and the k-d tree never misses a close pair or
    a duplicate; it does answer True on generic points."""
    from scipy.spatial import cKDTree

    from segparam.clean import _apart

    rng = np.random.default_rng(4)
    grid = tri_grid(30, 30)[0]
    answers = set()
    for t in range(80):
        P = rng.normal(size=(int(rng.integers(2, 400)), 3)) * 10.0 ** rng.integers(-3, 4)
        if t % 3 == 0:  # near-duplicates, some closer than the tolerance, some just beyond
            k = int(rng.integers(1, len(P) + 1))
            P = np.vstack([P, P[:k] + rng.normal(size=(k, 3)) * 10.0 ** rng.integers(-12, -6)])
        if t % 4 == 1:  # exact duplicates, -0.0
            P = np.vstack([P, P[: int(rng.integers(1, len(P) + 1))], -0.0 * P[:1]])
        if t % 5 == 0:
            P = grid + rng.normal(size=grid.shape) * 1e-12 * (t % 2)
        P = P + 0.0
        diag = float(np.linalg.norm(np.ptp(P, axis=0)))
        tol = 1e-9 * diag * 10.0 ** rng.integers(0, 4) * (t % 7 != 0)  # and 0
        close = len(cKDTree(P).query_pairs(tol)) > 0 if tol > 0 else False
        equal = len(np.unique(P, axis=0)) < len(P)
        apart = _apart(P, tol)
        assert not (apart and (close or equal))
        answers.add((apart, close or equal))
    assert answers == {(True, False), (False, True), (False, False)}
    assert not _apart(np.array([[0.0, 0, 0], [1e-170, 0, 0], [1, 1, 1]]), 1e-160)


def test_glue_pairs_without_sort_are_the_sorted_pairs():
    """On edge-manifold faces the pairs come from each edge's first and last half-edge; they are
    the pairs of the sort by edge, interior edges of the face (more first) and half-edge."""
    from segparam.clean import _glue_pairs

    rng = np.random.default_rng(5)
    for _ in range(40):
        V, F = tri_grid(int(rng.integers(2, 9)), int(rng.integers(2, 9)))
        F = F[rng.random(len(F)) < 0.8]
        F = np.where((rng.random(len(F)) < 0.3)[:, None], F[:, ::-1], F)[rng.permutation(len(F))]
        if len(F) == 0:
            continue
        E, h2e = mesh.edges(F)
        count = np.bincount(h2e, minlength=len(E))
        regular = (count[h2e] == 2).reshape(-1, 3).sum(axis=1)
        h = np.arange(len(h2e))
        order = np.lexsort((h, -regular[h // 3], h2e))
        lead = np.flatnonzero(count[h2e[order]] == 2)[::2]
        want = np.stack([order[lead], order[lead + 1]], axis=1)
        glue, nonmanifold, _ = _glue_pairs(F)
        np.testing.assert_array_equal(glue, want)
        assert nonmanifold == 0


def test_cross_into_is_numpys_cross_bit_for_bit():
    from segparam.mesh import cross_into

    rng = np.random.default_rng(6)
    a = rng.normal(size=(500, 3)) * 10.0 ** rng.integers(-8, 9, size=(500, 1))
    b = rng.normal(size=(500, 3)) * 10.0 ** rng.integers(-8, 9, size=(500, 1))
    out = np.empty((500, 3))
    assert cross_into(a.T, b.T, out) is out
    assert out.tobytes() == np.cross(a, b).tobytes()


def test_duplicates_from_the_edges_are_the_grouped_triples():
    """Duplicate faces found through the faces across each edge (edge-manifold faces) or by
    grouping sorted triples (otherwise) are the later faces of equal sorted triples."""
    from segparam.clean import _duplicates, _edge_table

    rng = np.random.default_rng(8)
    seen = set()
    for t in range(60):
        V, F = tri_grid(int(rng.integers(2, 8)), int(rng.integers(2, 8)))
        F = F[rng.random(len(F)) < 0.8]
        if len(F) == 0:
            continue
        k = int(rng.integers(0, 4))
        extra = F[rng.integers(0, len(F), k)]  # copies, some rotated or reversed
        extra = np.where((rng.random(k) < 0.5)[:, None], extra[:, ::-1], extra[:, [1, 2, 0]])
        if t % 3 == 0:  # a third face on an edge: the grouping path
            extra = np.vstack([extra, [F[0, 0], F[0, 1], len(V) - 1]])
        F = np.vstack([F, extra])[rng.permutation(len(F) + len(extra))]
        S = np.sort(F, axis=1)
        _, first = np.unique(S, axis=0, return_index=True)
        want = np.ones(len(F), dtype=bool)
        want[first] = False
        got = _duplicates(F, _edge_table(mesh.edges(F)))
        np.testing.assert_array_equal(got, want)
        seen.add((bool(want.any()), bool(mesh.edge_face_counts(F)[1].max() > 2)))
    assert len(seen) == 4  # with and without duplicates, on both paths


def test_split_corners_graph_as_csr_gives_the_same_fans():
    """Consistently oriented faces build the corner graph as CSR directly; the fans are those of
    the graph of glued pairs (pinched vertices included)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    from segparam.clean import _glue_pairs
    from segparam.mesh import split_corners

    def reference(F, glue):
        m, flat = len(F), F.ravel()
        ha, hb = glue[:, 0], glue[:, 1]
        na, nb = ha - ha % 3 + (ha % 3 + 1) % 3, hb - hb % 3 + (hb % 3 + 1) % 3
        rows, cols = np.concatenate([ha, na]), np.concatenate([nb, hb])
        G = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(3 * m, 3 * m))
        k, lab = connected_components(G, directed=False)
        first = np.full(k, 3 * m)
        np.minimum.at(first, lab, np.arange(3 * m))
        src = flat[first]
        o = np.lexsort((first, src))
        primary = np.ones(k, dtype=bool)
        primary[1:] = src[o][1:] != src[o][:-1]
        final = np.concatenate([o[primary], o[~primary]])
        newid = np.empty(k, dtype=np.int64)
        newid[final] = np.arange(k)
        return newid[lab].reshape(m, 3), src[final]

    rng = np.random.default_rng(9)
    pinched = 0
    for _ in range(30):
        V, F = tri_grid(int(rng.integers(3, 8)), int(rng.integers(3, 8)))
        F = F[rng.random(len(F)) < 0.75]  # holes: vertices where two fans touch
        if len(F) == 0:
            continue
        F = F[rng.permutation(len(F))]
        glue, _, _ = _glue_pairs(F)
        Fs, src = split_corners(F, glue)
        want_F, want_src = reference(F, glue)
        np.testing.assert_array_equal(Fs, want_F)
        np.testing.assert_array_equal(src, want_src)
        pinched += len(src) > len(np.unique(F))
    assert pinched > 0
