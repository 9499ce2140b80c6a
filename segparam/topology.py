"""The topology of many labelled face sets at once, compiled: the kernel behind
:func:`segparam.mesh.label_topology`.

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

__all__ = ["label_counts"]


@njit(cache=True, nogil=True)
def _root(parent, a):  # pragma: no cover - compiled
    """Union-find's root of ``a``, halving the path on the way."""
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@njit(cache=True, nogil=True)
def _join(parent, a, b):  # pragma: no cover - compiled
    """Union of the sets of ``a`` and ``b`` (the lower root becomes the root)."""
    a, b = _root(parent, a), _root(parent, b)
    if a < b:
        parent[b] = a
    elif b < a:
        parent[a] = b


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
    n_v = 0
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
    # edges: each half-edge 3 f + k (local[f, k] -> local[f, k + 1]) among its lower end's
    ptr = np.zeros(n_v + 1, dtype=np.int64)
    for f in range(m):
        for k in range(3):
            a, b = local[f, k], local[f, (k + 1) % 3]
            ptr[(a if a < b else b) + 1] += 1
    for v in range(n_v):
        ptr[v + 1] += ptr[v]
    slot = np.empty(n_v, dtype=np.int64)
    for v in range(n_v):
        slot[v] = ptr[v]
    upper = np.empty(3 * m, dtype=np.int64)
    half = np.empty(3 * m, dtype=np.int64)
    for f in range(m):
        for k in range(3):
            a, b = local[f, k], local[f, (k + 1) % 3]
            lo, hi = (a, b) if a < b else (b, a)
            upper[slot[lo]] = hi
            half[slot[lo]] = 3 * f + k
            slot[lo] += 1
    h2e = np.empty(3 * m, dtype=np.int64)
    e_lo = np.empty(3 * m, dtype=np.int64)
    e_hi = np.empty(3 * m, dtype=np.int64)
    n_e = 0
    for v in range(n_v):
        for p in range(ptr[v], ptr[v + 1]):
            e = -1
            for q in range(ptr[v], p):  # the same edge met before (a vertex has few edges)
                if upper[q] == upper[p]:
                    e = h2e[half[q]]
                    break
            if e < 0:
                e = n_e
                e_lo[e], e_hi[e] = v, upper[p]
                n_e += 1
            h2e[half[p]] = e
    count = np.zeros(n_e, dtype=np.int64)
    forward = np.zeros(n_e, dtype=np.int64)
    for f in range(m):
        for k in range(3):
            e = h2e[3 * f + k]
            count[e] += 1
            if local[f, k] < local[f, (k + 1) % 3]:
                forward[e] += 1
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
        _join(piece, e_lo[e], e_hi[e])
    for f in range(m):
        for k in range(3):
            if count[h2e[3 * f + k]] == 1:
                a, b = local[f, k], local[f, (k + 1) % 3]
                _join(loop, a, b)
                on_boundary[a] = 1
                on_boundary[b] = 1
    for v in range(n_v):
        if _root(piece, v) == v:
            components[vlabel[v]] += 1
        if on_boundary[v] == 1 and _root(loop, v) == v:
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
            _join(link, a, b)
    pieces = np.zeros(n_v, dtype=np.int64)
    for node in range(2 * n_e):
        if _root(link, node) == node:
            e = node // 2
            pieces[e_hi[e] if node % 2 == 1 else e_lo[e]] += 1
    for v in range(n_v):
        if pieces[v] > 1:
            bad_vertices[vlabel[v]] += 1
    return faces, vertices, n_edges, bad_edges, bad_vertices, components, loops
