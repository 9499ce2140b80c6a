"""Developable charts unrolled: the exact isometry, without the solver.

A chart whose every interior vertex has zero angle defect (the wall of a drilled hole cut open,
a pipe's or a cylinder's side, a cone's side: the developable surfaces of CAD parts) is
isometric to a planar region, and on a disk that isometry is found by laying its triangles
flat one after the other: each triangle reached across an edge whose two ends are already in
the plane puts its third corner where the triangle's own side lengths put it. The Hessian
solver finds the same map (up to a rigid motion and its rounding: its eigenfunctions are
affine on a flat chart, paper sec. 2), and the refinement then has nothing to do; unrolling
costs one pass over the faces instead (the pipe of ``benchmarks/bench_atlas.py``: each of its
two walls, 2,048 faces, in 0.8 ms instead of ~0.07 s for the solver; BENCHMARKS.md, section
0.1, session 20). It is to a developable chart what the projection onto its plane is to a planar one
(``segparam.split``, method ``"planar"``).

Every chart is checked, not trusted: the kernel reports the largest relative change of a
side length over the chart's triangles, which is rounding on a developable disk and large on
a curved one (a vertex reached along two paths lands at two places) or on a closed tube (the
circumference). The caller keeps a chart only where that is under `EDGE_TOL` and the map
passes the usual bijectivity checks (an unrolled strip may overlap itself, e.g. a cone's side
whose angle sum exceeds a turn).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .mesh import boundary_edges, corner_angles

__all__ = ["EDGE_TOL", "FLAT_TOL", "developable", "unroll_charts"]

#: Largest angle defect (radians) at an interior vertex of a chart taken as developable: CAD
#: meshes are flat there to rounding (the bench's turned parts: 9e-16 at most), organic
#: surfaces are not, at nearly any vertex (the realistic 2k brain's median 0.31, its least 8e-4;
#: the 20k brain's least 7e-7, at one vertex of 10,000), and every inner vertex must be.
FLAT_TOL = 1e-9
#: Largest relative change of a triangle side an unrolled chart may have: rounding is ~1e-15
#: per triangle laid, so even a chart of a million faces stays orders of magnitude under it.
EDGE_TOL = 1e-7


def developable(
    V: np.ndarray,
    F: np.ndarray,
    vert_chart: np.ndarray,
    n_charts: int,
    *,
    strips: bool = False,
    euler: int | None = None,
) -> np.ndarray:
    """Per chart of a disjoint union (``vert_chart``: each vertex's chart), whether it has
    interior vertices and every one of them has an angle defect within `FLAT_TOL` (boundary
    vertices are free: a chart's boundary may turn).

    A chart without interior vertices (a strip one triangle wide) always unrolls, whatever the
    surface it lies on, so that says nothing: such pieces of curved surfaces are left to the
    solver. Unrolled, the thin pieces of the realistic brains of ``benchmarks/bench_atlas.py``
    changed their atlases for the worse (utilization -0.75 and -1.2 points on the 5k and 2k
    brains of seeds 2 and 1), where the solver's maps of them were within the targets anyway.
    ``strips=True`` takes them as developable: for a tube cut open, which the split stage
    already found to be a wall (its loops turn as a cylinder's do), such as a drilled hole's
    wall in a CAD plate, one quad high.

    ``euler``, the least Euler characteristic the charts can have (1: disks; 0: disks or
    annuli), screens them first: a manifold chart of V vertices and F faces has ``2 V - F - 2
    chi`` boundary vertices, so one with more vertices off a full turn than that has a bent inner
    vertex. That rules out every chart of an organic surface before the boundary pass (an edge
    sort), which then covers only the charts left.
    """
    total = np.bincount(F.ravel(), weights=corner_angles(V, F).ravel(), minlength=len(V))
    used = np.bincount(F.ravel(), minlength=len(V)) > 0
    off = used & (np.abs(2 * np.pi - total) > FLAT_TOL)
    left = np.ones(n_charts, dtype=bool)
    if euler is not None:
        n_v = np.bincount(vert_chart, weights=used, minlength=n_charts)
        n_f = np.bincount(vert_chart[F[:, 0]], minlength=n_charts)
        left = np.bincount(vert_chart, weights=off, minlength=n_charts) <= 2 * n_v - n_f - 2 * euler
        if not left.any():
            return left
    interior = used.copy()
    interior[boundary_edges(F[left[vert_chart[F[:, 0]]]]).ravel()] = False
    inner = np.bincount(vert_chart, weights=interior, minlength=n_charts)
    flat = np.bincount(vert_chart, weights=interior & off, minlength=n_charts) == 0
    return left & flat & (strips | (inner > 0))


def unroll_charts(
    V: np.ndarray, F: np.ndarray, vert_chart: np.ndarray, n_charts: int
) -> tuple[np.ndarray, np.ndarray]:
    """Unroll every chart of a disjoint union (vertices and faces ordered by chart): each
    chart's triangles laid flat breadth-first from its first face.

    Returns
    -------
    uv : (n, 2) float ndarray
        In ``V``'s units; a chart whose faces are not all reached (it falls apart) keeps NaN at
        the vertices left.
    error : (n_charts,) float ndarray
        Per chart, the largest relative change of a triangle side (see `EDGE_TOL`); infinite for
        a chart not reached whole, NaN where a side of length 0 left a corner unplaceable.
    """
    face_chart = vert_chart[F[:, 0]]
    fstart = np.searchsorted(face_chart, np.arange(n_charts + 1))
    return _unroll(
        np.ascontiguousarray(V, dtype=np.float64),
        np.ascontiguousarray(F, dtype=np.int64),
        fstart.astype(np.int64),
    )


@njit(cache=True, nogil=True)
def _unroll(V, F, fstart):  # pragma: no cover - compiled
    """:func:`unroll_charts`' kernel. Half-edges are matched to their twins by one sort of the
    keys ``a * n + b``; each face reached across the half-edge ``(a, b)`` of a laid face has the
    twin ``(b, a)`` and its third corner ``c`` goes to the left of ``b -> a`` (faces are
    oriented), at the along/across coordinates it has in 3-D."""
    n, m = V.shape[0], F.shape[0]
    n_charts = len(fstart) - 1
    uv = np.full((n, 2), np.nan)
    error = np.zeros(n_charts)
    keys = np.empty(3 * m, dtype=np.int64)
    for t in range(m):
        for k in range(3):
            keys[3 * t + k] = F[t, k] * n + F[t, (k + 1) % 3]
    order = np.argsort(keys)
    sorted_keys = keys[order]
    laid = np.zeros(m, dtype=np.bool_)
    queue = np.empty(m, dtype=np.int64)
    for ch in range(n_charts):
        f0, f1 = fstart[ch], fstart[ch + 1]
        if f1 <= f0:
            continue
        # the first face: its first corner at the origin, its first side along u
        a, b, c = F[f0, 0], F[f0, 1], F[f0, 2]
        uv[a, 0], uv[a, 1] = 0.0, 0.0
        uv[b, 0], uv[b, 1] = np.sqrt(_d2(V, a, b)), 0.0
        _third(V, uv, a, b, c)
        laid[f0] = True
        head, tail = 0, 1
        queue[0] = f0
        while head < tail:
            t = queue[head]
            head += 1
            for k in range(3):
                p, q = F[t, k], F[t, (k + 1) % 3]
                twin = q * n + p
                i = np.searchsorted(sorted_keys, twin)
                if i >= 3 * m or sorted_keys[i] != twin:
                    continue  # a boundary side
                g = order[i] // 3
                if laid[g]:
                    continue
                # in g the side runs q -> p; its third corner follows p
                j = order[i] % 3
                r = F[g, (j + 2) % 3]
                if np.isnan(uv[r, 0]):
                    _third(V, uv, q, p, r)
                laid[g] = True
                queue[tail] = g
                tail += 1
        worst = 0.0
        for t in range(f0, f1):
            if not laid[t]:
                worst = np.inf
                break
            for k in range(3):
                p, q = F[t, k], F[t, (k + 1) % 3]
                d3 = np.sqrt(_d2(V, p, q))
                du, dv = uv[p, 0] - uv[q, 0], uv[p, 1] - uv[q, 1]
                d2 = np.sqrt(du * du + dv * dv)
                change = abs(d2 - d3) / max(d3, 1e-300)
                if not change <= worst:  # NaN too (a side of length 0 laid nothing): kept
                    worst = change
        error[ch] = worst
    return uv, error


@njit(cache=True, nogil=True)
def _d2(V, p, q):  # pragma: no cover - compiled
    """Squared distance of vertices p and q."""
    x, y, z = V[p, 0] - V[q, 0], V[p, 1] - V[q, 1], V[p, 2] - V[q, 2]
    return x * x + y * y + z * z


@njit(cache=True, nogil=True)
def _third(V, uv, p, q, r):  # pragma: no cover - compiled
    """Lay vertex r of the oriented triangle (p, q, r) given p and q in the plane: to the left
    of p -> q, at its 3-D coordinates along the side and across it; not at all if the side has
    length 0 (in 3-D or as laid)."""
    ex, ey, ez = V[q, 0] - V[p, 0], V[q, 1] - V[p, 1], V[q, 2] - V[p, 2]
    wx, wy, wz = V[r, 0] - V[p, 0], V[r, 1] - V[p, 1], V[r, 2] - V[p, 2]
    length = np.sqrt(ex * ex + ey * ey + ez * ez)
    du, dv = uv[q, 0] - uv[p, 0], uv[q, 1] - uv[p, 1]
    flat = np.sqrt(du * du + dv * dv)
    if not (length > 0 and flat > 0):  # a side of length 0: r stays unplaced (NaN)
        return
    along = (wx * ex + wy * ey + wz * ez) / length
    across = np.sqrt(max(wx * wx + wy * wy + wz * wz - along * along, 0.0))
    ux, uy = du / flat, dv / flat
    uv[r, 0] = uv[p, 0] + along * ux - across * uy
    uv[r, 1] = uv[p, 1] + along * uy + across * ux
