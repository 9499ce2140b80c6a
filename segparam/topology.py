"""Compiled combinatorics of face sets: the kernel behind :func:`segparam.mesh.label_topology`,
and the edge, boundary and union-find helpers it shares with the solver's quality checks
(:func:`segparam.parameterize.charts_quality`) and SLIM's system layout
(:func:`segparam.refine.proxy_layout`).

It lives apart from :mod:`segparam.mesh` so that importing the mesh utilities (every command
does) does not import numba; the stages that call it (segment, split, parameterize) load numba
anyway.

Every label gets its own copy of its vertices, so the union is a disjoint set of small meshes;
one pass over the faces grouped by label numbers the copies, finds each half-edge's edge among
the edges of its lower vertex (no sort of the mesh's edges), and three union-find passes give the
vertex-connected pieces, the boundary loops and the links of the vertices. The counts are those
of :func:`segparam.mesh.is_edge_manifold`, :func:`segparam.mesh.is_vertex_manifold`,
:func:`segparam.mesh.connected_components` and the boundary pieces on each label's faces alone
(a test checks them label by label). It replaced a numpy form built on a sort of the copies'
keys, an edge sort and scipy's connected components: 1.5-6 ms a call, 22-62 ms a build of
brain-2k, the spheres and the CAD plate (BENCHMARKS.md section 0.1, session 17).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = [
    "boundary_half_edges",
    "boundary_pieces",
    "find_root",
    "half_edge_edges",
    "join_sets",
    "label_counts",
    "number_marked",
]


@njit(cache=True, nogil=True)
def find_root(parent, a):  # pragma: no cover - compiled
    """Union-find's root of ``a``, halving the path on the way."""
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@njit(cache=True, nogil=True)
def join_sets(parent, a, b):  # pragma: no cover - compiled
    """Union of the sets of ``a`` and ``b`` (the lower root becomes the root)."""
    a, b = find_root(parent, a), find_root(parent, b)
    if a < b:
        parent[b] = a
    elif b < a:
        parent[a] = b


@njit(cache=True, nogil=True)
def number_marked(index):  # pragma: no cover - compiled
    """Number the entries of ``index`` marked 0 (the others are -1) 0, 1, 2, ... in ascending
    order, in place, and return the marked positions in that order (the numbering's inverse):
    the vertices a set of faces or edges uses, compactly."""
    m = 0
    for v in range(len(index)):
        if index[v] == 0:
            index[v] = m
            m += 1
    marked = np.empty(m, dtype=np.int64)
    for v in range(len(index)):
        if index[v] >= 0:
            marked[index[v]] = v
    return marked


@njit(cache=True, nogil=True)
def half_edge_edges(F, n):  # pragma: no cover - compiled
    """The undirected edge of every half-edge ``3 f + k`` (``F[f, k] -> F[f, k + 1]``) of faces
    ``F`` on ``n`` vertices, each found among the edges of its lower end (a vertex has few), with
    no sort of the mesh's edges: ``(h2e, e_lo, e_hi, count)``, the edges numbered by lower end and
    then as met, ``e_lo <= e_hi`` their ends and ``count`` their half-edges (a face naming a
    vertex twice gives an edge from the vertex to itself, as :func:`segparam.mesh.edges`)."""
    m = len(F)
    ptr = np.zeros(n + 1, dtype=np.int64)
    for f in range(m):
        for k in range(3):
            a, b = F[f, k], F[f, (k + 1) % 3]
            ptr[(a if a < b else b) + 1] += 1
    for v in range(n):
        ptr[v + 1] += ptr[v]
    slot = np.empty(n, dtype=np.int64)
    for v in range(n):
        slot[v] = ptr[v]
    upper = np.empty(3 * m, dtype=np.int64)
    half = np.empty(3 * m, dtype=np.int64)
    for f in range(m):
        for k in range(3):
            a, b = F[f, k], F[f, (k + 1) % 3]
            lo, hi = (a, b) if a < b else (b, a)
            upper[slot[lo]] = hi
            half[slot[lo]] = 3 * f + k
            slot[lo] += 1
    h2e = np.empty(3 * m, dtype=np.int64)
    e_lo = np.empty(3 * m, dtype=np.int64)
    e_hi = np.empty(3 * m, dtype=np.int64)
    n_e = 0
    for v in range(n):
        for p in range(ptr[v], ptr[v + 1]):
            e = -1
            for q in range(ptr[v], p):  # the same edge met before
                if upper[q] == upper[p]:
                    e = h2e[half[q]]
                    break
            if e < 0:
                e = n_e
                e_lo[e], e_hi[e] = v, upper[p]
                n_e += 1
            h2e[half[p]] = e
    count = np.zeros(n_e, dtype=np.int64)
    for h in range(3 * m):
        count[h2e[h]] += 1
    return h2e, e_lo[:n_e].copy(), e_hi[:n_e].copy(), count


@njit(cache=True, nogil=True)
def boundary_half_edges(F, n):  # pragma: no cover - compiled
    """:func:`segparam.mesh.boundary_edges` of faces ``F`` on ``n`` vertices, compiled: the
    half-edges ``F[f, k] -> F[f, k + 1]`` whose edge no other half-edge has, in half-edge order
    ``3 f + k`` (:func:`half_edge_edges`; ``charts_quality`` measures each batch of charts two to
    six times)."""
    h2e, _, _, count = half_edge_edges(F, n)
    n_b = 0
    for h in range(len(h2e)):
        n_b += count[h2e[h]] == 1
    B = np.empty((n_b, 2), dtype=np.int64)
    e = 0
    for h in range(len(h2e)):
        if count[h2e[h]] == 1:
            B[e, 0], B[e, 1] = F[h // 3, h % 3], F[h // 3, (h + 1) % 3]
            e += 1
    return B


@njit(cache=True, nogil=True)
def boundary_pieces(B, n):  # pragma: no cover - compiled
    """:func:`segparam.mesh.boundary_pieces` of half-edges ``B`` on ``n`` vertices, compiled
    (union-find): the boundary vertices (ascending), ``B`` in their positions, the number of
    pieces and each vertex's piece, pieces numbered by their lowest vertex as scipy's
    connected components number them."""
    pos = np.full(n, -1, dtype=np.int64)
    for e in range(len(B)):
        pos[B[e, 0]] = 0
        pos[B[e, 1]] = 0
    verts = number_marked(pos)
    nb = len(verts)
    idx = np.empty((len(B), 2), dtype=np.int64)
    parent = np.arange(nb)
    for e in range(len(B)):
        idx[e, 0], idx[e, 1] = pos[B[e, 0]], pos[B[e, 1]]
        join_sets(parent, idx[e, 0], idx[e, 1])
    label = np.full(nb, -1, dtype=np.int64)
    piece = np.empty(nb, dtype=np.int64)
    n_pieces = 0
    for v in range(nb):
        r = find_root(parent, v)
        if label[r] < 0:
            label[r] = n_pieces
            n_pieces += 1
        piece[v] = label[r]
    return verts, idx, n_pieces, piece


@njit(cache=True, nogil=True)
def label_counts(F, labels, order, start, n_vertices):  # pragma: no cover - compiled
    """Per label ``0 .. n_labels - 1`` (``F`` on ``n_vertices`` vertices; the faces grouped by
    label, :func:`segparam.mesh.group_by_label`: those of label ``k`` are
    ``order[start[k] : start[k + 1]]``): faces, vertex copies, edges, edges that are not
    manifold (more than two faces, or two that traverse it the same way), vertex copies that are
    not manifold (their link, the opposite edges of their corners, in more than one piece),
    vertex-connected pieces and boundary loops (pieces of the graph of the half-edges whose edge
    has one face).

    Returns
    -------
    faces, vertices, edges, bad_edges, bad_vertices, components, loops : (n_labels,) int64
    """
    m = len(F)
    n_labels = len(start) - 1
    # one copy of a vertex per label that uses it, numbered as met
    last = np.full(n_vertices, -1, dtype=np.int64)
    copy = np.empty(n_vertices, dtype=np.int64)
    local = np.empty((m, 3), dtype=np.int64)
    vlabel = np.empty(3 * m, dtype=np.int64)
    n_v = np.int64(0)  # not a literal 0 (see canvas.new_canvas): passed to half_edge_edges
    for p in range(m):
        f = order[p]
        lab = labels[f]
        for c in range(3):
            v = F[f, c]
            if last[v] != lab:
                last[v] = lab
                copy[v] = n_v
                vlabel[n_v] = lab
                n_v += 1
            local[f, c] = copy[v]
    h2e, e_lo, e_hi, count = half_edge_edges(local, n_v)
    n_e = len(count)
    forward = np.zeros(n_e, dtype=np.int64)
    for h in range(3 * m):
        if local[h // 3, h % 3] < local[h // 3, (h + 1) % 3]:
            forward[h2e[h]] += 1
    faces = np.zeros(n_labels, dtype=np.int64)
    vertices = np.zeros(n_labels, dtype=np.int64)
    n_edges = np.zeros(n_labels, dtype=np.int64)
    bad_edges = np.zeros(n_labels, dtype=np.int64)
    bad_vertices = np.zeros(n_labels, dtype=np.int64)
    components = np.zeros(n_labels, dtype=np.int64)
    loops = np.zeros(n_labels, dtype=np.int64)
    for lab in range(n_labels):
        faces[lab] = start[lab + 1] - start[lab]
    for v in range(n_v):
        vertices[vlabel[v]] += 1
    for e in range(n_e):
        lab = vlabel[e_lo[e]]
        n_edges[lab] += 1
        if count[e] > 2 or (count[e] == 2 and forward[e] != 1):
            bad_edges[lab] += 1
    # vertex-connected pieces, and boundary loops: union-find over the copies
    piece = np.arange(n_v)
    loop = np.arange(n_v)
    on_boundary = np.zeros(n_v, dtype=np.int64)
    for e in range(n_e):
        join_sets(piece, e_lo[e], e_hi[e])
    for f in range(m):
        for k in range(3):
            if count[h2e[3 * f + k]] == 1:
                a, b = local[f, k], local[f, (k + 1) % 3]
                join_sets(loop, a, b)
                on_boundary[a] = 1
                on_boundary[b] = 1
    for v in range(n_v):
        if find_root(piece, v) == v:
            components[vlabel[v]] += 1
        if on_boundary[v] == 1 and find_root(loop, v) == v:
            loops[vlabel[v]] += 1
    # links: node 2 e + s is the end s of edge e (s = 1 at its higher vertex); corner k of face
    # f, at vertex v, joins its two edges' ends at v (mesh.is_vertex_manifold's graph)
    link = np.arange(2 * n_e)
    for f in range(m):
        for k in range(3):
            v = local[f, k]
            e_next, e_prev = h2e[3 * f + k], h2e[3 * f + (k + 2) % 3]
            a = 2 * e_next + (1 if e_hi[e_next] == v else 0)
            b = 2 * e_prev + (1 if e_hi[e_prev] == v else 0)
            join_sets(link, a, b)
    pieces = np.zeros(n_v, dtype=np.int64)
    for node in range(2 * n_e):
        if find_root(link, node) == node:
            e = node // 2
            pieces[e_hi[e] if node % 2 == 1 else e_lo[e]] += 1
    for v in range(n_v):
        if pieces[v] > 1:
            bad_vertices[vlabel[v]] += 1
    return faces, vertices, n_edges, bad_edges, bad_vertices, components, loops
