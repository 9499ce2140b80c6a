"""The chart solver: Hessian eigenfunctions for triangular mesh parameterization.

This module follows the paper ("Hessian Eigenfunctions for Triangular Mesh Parameterization"),
a variant of Hessian LLE (Donoho & Grimes 2003), section by section:

* 3.1 tangent plane at every vertex from the average of its adjacent triangle normals (averaged
  again over a few rings, ``NORMAL_SMOOTHING``, and turned where it would project an adjacent
  triangle flat or flipped, ``FOLD_MIN_COS``: not in the paper, measured on cortical parcels),
  and local coordinates ``(u, v)`` of its neighbourhood ``N_i`` in that plane
  (:func:`neighbourhoods`, :func:`tangent_frames`, :func:`unfolded_normals`);
* 3.2 quadratic least-squares interpolation on ``N_i``; its quadratic coefficients ``alpha, beta,
  gamma`` give the tangent Hessian (eq. 5) and ``C_i = 4 a a^T + 2 b b^T + 4 g g^T`` (eq. 6)
  (:func:`local_hessians`);
* 3.3 partition of unity: ``C_i`` is weighted by ``(1/3) sum_j A_ij`` (eq. 8, 9) and scattered into
  the global ``K`` (:func:`hessian_matrix`);
* 3.4 the two eigenvectors of ``K`` after the constant one are the coordinates (eq. 3)
  (:func:`hessian_eigenmap`), unless the second is nearly a function of the first and the third
  is not (``DEPENDENT_R2``, :func:`explained_by_first`: not in the paper).

Eigenvectors are only defined up to a 2x2 linear map; :func:`isometric_fit` picks the map that makes
the chart closest to isometric, and :func:`orient` keeps the input winding (no mirrored chart).
Then (not in the paper, on by default, ``refine="none"`` turns it off) :func:`arap_refine` runs a
few as-rigid-as-possible iterations from that map and keeps them only if they do not make the map
worse: measured on folded cortex-like parcels, it turns most of the eigenmap's few boundary flips
into bijective maps and brings the median angle distortion close to 1 (see BENCHMARKS.md). A
refined map of a disk that is still not bijective is refined again from the next pairs of
eigenvectors (``FALLBACK_PAIRS``).
``refine="slim"`` (the pipeline's default, ``[split] refine``) then runs the flip-free
distortion refinement of :mod:`segparam.refine` on a map with no flipped triangle.

``method="classic-hlle"`` is the Donoho-Grimes estimator (PCA tangent, k nearest neighbours,
Hessian estimator from a Gram-Schmidt of ``[1, u, v, u^2, uv, v^2]``): the paper's baseline.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numba import njit
from scipy.sparse.csgraph import connected_components as graph_components
from scipy.spatial import cKDTree

from .errors import InvalidMeshError, check_choice, check_int, check_number
from .linalg import (
    lowest_pairs,
    one_blas_thread,
    smallest_eigenpairs,
    spd_solver,
    spd_solver_entries,
)
from .mesh import (
    boundary_edges,
    boundary_loops,
    check_mesh,
    edges,
    face_areas,
    face_normals,
    group_by_label,
    is_edge_manifold,
    is_vertex_manifold,
    label_topology,
    mesh_arrays,
    plane_basis,
    vertex_adjacency,
    vertex_normals,
)
from .quality import (
    DEGENERATE_AREA,
    ChartQuality,
    angle_sum_violations,
    chart_quality,
    inverse_frames,
    jacobians,
    signed_areas,
    singular_values,
    triangle_frames,
)
from .refine import (
    ANGLE_WEIGHT,
    MAX_STRETCH_INCREASE,
    SMALL_CHART_FACES,
    _gradient_coefficients,
    gradient_row,
    gradient_transpose,
    poisson_entries,
    slim_refine,
)
from .topology import boundary_half_edges, boundary_pieces

log = logging.getLogger(__name__)

__all__ = [
    "ChartMap",
    "ChartMaps",
    "HessianSolver",
    "charts_quality",
    "check_chart",
    "classic_hlle_matrix",
    "explained_by_first",
    "hessian_eigenmap",
    "hessian_matrix",
    "isometric_fit",
    "local_hessians",
    "neighbourhoods",
    "orient",
    "parameterize_chart",
    "quality_records",
    "solve_charts",
    "tangent_frames",
    "unfolded_normals",
]

METHODS = ("hessian", "classic-hlle")
#: "slim": ARAP, then the symmetric Dirichlet refinement of :mod:`segparam.refine` on a
#: flip-free map; "arap": ARAP alone; "none": the paper's map.
REFINES = ("slim", "arap", "none")
TANGENTS = ("normals", "pca")
#: A quadratic in (u, v) has 6 coefficients, so a least-squares fit needs at least 6 points.
MIN_POINTS = 6
#: Worst accepted conditioning of a local quadratic fit (see :func:`hessian_matrix`).
MIN_RCOND = 0.03
#: Most points added to one neighbourhood for conditioning.
MAX_EXTEND = 6
#: Rounds of neighbour averaging of the vertex normals behind the tangent planes (issue 16; see
#: :func:`tangent_frames`). Raw map (``refine="none"``) on the 89 parcels of
#: ``bench_solver.py --part quality``, rounds 0 / 1 / 2 / 3 / 4 / 5 / 6 / 10: fsaverage5 (real)
#: 72 / 79 / 78 / 83 / 81 / 81 / 81 / 76, cortex 53 / 71 / 80 / 80 / 82 / 80 / 75 / 64,
#: cortex-ico 55 / 67 / 76 / 77 / 80 / 79 / 78 / 65 bijective: 4 has the best total.
NORMAL_SMOOTHING = 4
#: Extend only boundary neighbourhoods (issue 16). On folded cortex, a 1-ring squeezed by a fold
#: projects to a nearly degenerate design on the normals plane; extending it adds points on one
#: side of the fold and its Hessian flips triangles nearby, while the truncated pseudo-inverse of
#: the unextended fit (:func:`local_hessians`) stays benign. Measured on 89 fsaverage5 pial
#: parcels (``bench_solver.py --parcel-set fsaverage5``), raw map: see BENCHMARKS.md.
EXTEND_BOUNDARY_ONLY = True
#: Least cosine between a vertex's tangent-plane normal and the normal of any of its adjacent
#: triangles (issue 16; see :func:`unfolded_normals`): below it, the plane is turned towards the
#: normal that keeps every adjacent triangle best oriented, just far enough. A triangle projects
#: with ``cos`` times its area, so 0.35 (70 degrees) keeps a third or more of each. Raw map
#: (``refine="none"``, with ``DEPENDENT_R2``) on the 89 parcels of ``bench_solver.py --part
#: quality``, none / 0 / 0.17 / 0.26 / 0.30 / 0.35 / 0.40 / 0.45 / 0.50 / 0.60: fsaverage5 81 / 82
#: / 84 / 85 / 87 / 87 / 86 / 85 / 85 / 87, cortex 82 / 84 / 84 / 85 / 86 / 86 / 87 / 85 / 85 /
#: 82, cortex-ico 82 / 83 / 85 / 84 / 85 / 86 / 86 / 85 / 85 / 86 bijective; on three held-out
#: sets (the cortex sets with seed 1, fsaverage5 cut into 79: 255 charts) 217 / 222 / 237 / 235
#: / 234 / 234 / 232 / 233 / 233 / 227.
FOLD_MIN_COS = 0.35
#: Subgradient steps of the max-min normal search of :func:`unfolded_normals`, and candidate
#: planes between the averaged normal and the max-min one.
MAXMIN_STEPS = 40
MAXMIN_CANDIDATES = 10
#: The second eigenvector is replaced by the third when a polynomial of degree
#: ``DEPENDENT_DEGREE`` in the first explains more than this fraction of its variance and less
#: of the third's (see :func:`explained_by_first`; issue 16). Raw map, with ``FOLD_MIN_COS``, on
#: the 89 parcels of fsaverage5 / cortex / cortex-ico, threshold 0.6 / 0.65 / 0.7 / 0.75 / 0.8 /
#: 0.85 / 0.9 / never: 86 / 87 / 87 / 87 / 88 / 88 / 88 / 87, 87 / 86 / 86 / 85 / 85 / 85 / 85 /
#: 84, 85 / 86 / 86 / 86 / 85 / 85 / 84 / 82 bijective; on the held-out sets of
#: ``FOLD_MIN_COS`` 232 / 233 / 234 / 234 / 235 / 235 / 234 / 228 of 255. Any threshold from
#: 0.65 to 0.85 is as good overall; 0.65 and 0.7 bring all three sets to 86 or more.
DEPENDENT_R2 = 0.7
#: The first eigenvector is the constant when its overlap with ``1 / sqrt(n)`` is at least
#: ``1 - CONSTANT_FIRST_TOL`` (as it comes from LAPACK: 1 - 1e-15 or closer); below, the null
#: space is mixed (:func:`_constant_first`).
CONSTANT_FIRST_TOL = 1e-8
#: A column of :func:`explained_by_first`'s polynomial design whose part not in the lower
#: powers is smaller than this fraction of its norm is dropped (a power of a few-valued h1).
POLY_RANK_TOL = 1e-8
DEPENDENT_DEGREE = 4


@dataclass(frozen=True)
class ChartMap:
    """A chart's map to the plane.

    Attributes
    ----------
    uv : (n, 2) float64 ndarray
        Row ``i`` belongs to input vertex ``i``; scaled close to isometric (uv units = 3-D units).
    bijective : bool
        The map is one-to-one (see :mod:`segparam.quality`).
    quality : ChartQuality
        Flip, injectivity and distortion figures.
    method, tangent : str
        The options used.
    eigenvalues : (3,) float64 ndarray
        The three smallest eigenvalues of ``K`` (the first one belongs to the constant function).
    refined : bool
        The ARAP refinement was kept (see :meth:`HessianSolver.solve`).
    timings : dict
        Seconds spent in ``"assemble"``, ``"eigen"``, ``"post"`` and ``"refine"``.
    """

    uv: np.ndarray
    bijective: bool
    quality: ChartQuality
    method: str
    tangent: str
    eigenvalues: np.ndarray
    refined: bool = False
    timings: dict = field(default_factory=dict)

    @property
    def angle_distortion(self) -> float:
        return self.quality.angle_distortion

    @property
    def l2_stretch(self) -> float:
        return self.quality.l2_stretch

    @property
    def n_flipped(self) -> int:
        return self.quality.n_flipped


def check_chart(V, F) -> tuple[np.ndarray, np.ndarray]:
    """Validate a chart for the solver: a connected manifold surface with a boundary.

    Returns
    -------
    V : (n, 3) float64 ndarray
    F : (m, 3) int64 ndarray

    Raises
    ------
    InvalidMeshError
        With the reason: too few vertices, unreferenced vertices, several components,
        non-manifold, or closed.
    """
    V, F = check_mesh(V, F)
    n = len(V)
    used = np.bincount(F.ravel(), minlength=n) > 0
    if n < MIN_POINTS:
        raise InvalidMeshError(
            f"chart has {n} vertices; the Hessian solver needs at least {MIN_POINTS}"
        )
    if not used.all():
        raise InvalidMeshError(
            f"chart has {int((~used).sum())} unreferenced vertices; every vertex needs a face"
        )
    edge_index = edges(F)
    # Vertex-connected and vertex-manifold (checked below) implies connected through edges.
    A = vertex_adjacency(F, n, edge_index=edge_index)
    count = graph_components(A, directed=False, return_labels=False)
    if count != 1:
        raise InvalidMeshError(f"chart has {count} connected components; it must be one piece")
    if not is_edge_manifold(F, edge_index=edge_index):
        raise InvalidMeshError("chart is not edge-manifold or not consistently oriented")
    bad = ~is_vertex_manifold(F, n, edge_index=edge_index)
    if bad.any():
        raise InvalidMeshError(f"chart has {int(bad.sum())} non-manifold vertices")
    if len(boundary_edges(F, edge_index=edge_index)) == 0:
        raise InvalidMeshError("chart is closed (no boundary); cut it before parameterizing")
    return V, F


# ---------------------------------------------------------------------------------------------
# 3.1 Neighbourhoods N_i, tangent planes T_x M and local coordinates O_i
# ---------------------------------------------------------------------------------------------


def neighbourhoods(
    V: np.ndarray,
    F: np.ndarray,
    *,
    min_points: int = MIN_POINTS,
    extra: np.ndarray | None = None,
    adjacency: sp.csr_matrix | None = None,
    room: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The neighbourhood ``N_i`` of every vertex: itself and its 1-ring, minimally extended.

    A vertex whose closed 1-ring has fewer than ``min_points`` points (a boundary vertex) gets the
    nearest vertices of its next ring(s), just enough to reach ``min_points``, plus ``extra[i]``
    more. Growing every neighbourhood to the 2-ring smooths the Hessian and loses bijectivity on
    folded charts, so the extension is strictly local.

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray
    min_points : int
    extra : (n,) int ndarray, optional
        Points to add beyond ``max(min_points, 1-ring size)`` (see :func:`hessian_matrix`).
    adjacency : (n, n) scipy.sparse.csr_matrix, optional
        ``vertex_adjacency(F, n)``, when the caller already has it.
    room : (n,) int ndarray, optional
        The vertices of each vertex's component (its chart's, for a union of charts): a vertex
        that needs more points than that is *starved*. Without ``room`` that raises; with it,
        the neighbourhood stops at its component's vertices (see :func:`solve_charts`).

    Returns
    -------
    ptr : (n + 1,) int64 ndarray
    idx : (nnz,) int64 ndarray
        ``N_i = idx[ptr[i]:ptr[i + 1]]``, with ``i`` itself first.
    """
    n = len(V)
    A = vertex_adjacency(F, n) if adjacency is None else adjacency
    deg = np.diff(A.indptr)
    need = _points_needed(deg, min_points, extra)
    if room is not None:
        need = np.minimum(need, np.maximum(room - 1 - deg, 0))
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(1 + deg + need, out=ptr[1:])
    idx, short = _rings(
        A.indptr.astype(np.int64), A.indices.astype(np.int64), np.asarray(V, dtype=np.float64),
        need.astype(np.int64), ptr,
    )  # fmt: skip
    if short >= 0:
        raise InvalidMeshError(f"cannot find {min_points} points around every vertex")
    return ptr, idx


def _points_needed(deg: np.ndarray, min_points: int, extra: np.ndarray | None) -> np.ndarray:
    """Points beyond the 1-ring each neighbourhood takes (:func:`neighbourhoods`): enough to reach
    ``min_points``, plus ``extra``."""
    need = np.maximum(min_points - 1 - deg, 0)
    return need if extra is None else need + extra


@njit(cache=True, nogil=True)
def _nearest_first(dist, vertex, n):  # pragma: no cover - compiled
    """The order of the first ``n`` candidates by (distance, vertex index): a bottom-up merge
    sort on that key. The keys are distinct (so any sort gives this order: the one of
    ``np.argsort(dist, kind="mergesort")`` over the candidates sorted by index, which this
    replaced; numba's sorts took 2.3 s of the first run's compile)."""
    order = np.arange(n)
    buf = np.empty(n, dtype=np.int64)
    width = 1
    while width < n:
        for lo in range(0, n, 2 * width):
            mid = min(lo + width, n)
            hi = min(lo + 2 * width, n)
            a, b, k = lo, mid, lo
            while a < mid and b < hi:
                x, y = order[a], order[b]
                if dist[y] < dist[x] or (dist[y] == dist[x] and vertex[y] < vertex[x]):
                    buf[k] = y
                    b += 1
                else:
                    buf[k] = x
                    a += 1
                k += 1
            while a < mid:
                buf[k] = order[a]
                a += 1
                k += 1
            while b < hi:
                buf[k] = order[b]
                b += 1
                k += 1
        order, buf = buf, order
        width *= 2
    return order


def kernels_loaded() -> bool:
    """Whether this process has the solver's compiled kernels yet (loaded from numba's cache,
    or compiled on a first run): the neighbourhood search's, which loads the other."""
    return bool(_rings.signatures)


@njit(cache=True, nogil=True)
def _rings(indptr, indices, V, need, ptr):  # pragma: no cover - compiled
    """Fill ``N_i`` (see :func:`neighbourhoods`) for every vertex: i, its 1-ring in adjacency
    order, then ``need[i]`` more points ring by ring (breadth-first), each ring's points taken
    nearest first (ties: lower index). Returns (idx, the first vertex whose component ran out
    of points, or -1)."""
    n = len(indptr) - 1
    idx = np.empty(ptr[n], dtype=np.int64)
    mark = np.full(n, -1, dtype=np.int64)  # mark[v] == i: v is already in N_i or its frontier
    ring = np.empty(n, dtype=np.int64)
    nxt = np.empty(n, dtype=np.int64)
    for i in range(n):
        p = ptr[i]
        idx[p] = i
        p += 1
        for t in range(indptr[i], indptr[i + 1]):
            idx[p] = indices[t]
            p += 1
        missing = need[i]
        if missing == 0:
            continue
        mark[i] = i
        n_ring = 0
        for t in range(indptr[i], indptr[i + 1]):
            mark[indices[t]] = i
            ring[n_ring] = indices[t]
            n_ring += 1
        while missing > 0:
            n_next = np.int64(0)  # not a literal 0: _nearest_first would compile twice
            for a in range(n_ring):
                u = ring[a]
                for t in range(indptr[u], indptr[u + 1]):
                    w = indices[t]
                    if mark[w] != i:
                        mark[w] = i
                        nxt[n_next] = w
                        n_next += 1
            if n_next == 0:
                return idx, i
            dist = np.empty(n_next)
            for a in range(n_next):
                d0 = V[nxt[a], 0] - V[i, 0]
                d1 = V[nxt[a], 1] - V[i, 1]
                d2 = V[nxt[a], 2] - V[i, 2]
                dist[a] = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            by = _nearest_first(dist, nxt, n_next)
            take = min(missing, n_next)
            for a in range(take):
                idx[p] = nxt[by[a]]
                p += 1
            missing -= take
            for a in range(n_next):
                ring[a] = nxt[a]
            n_ring = n_next
    return idx, -1


def _groups(ptr: np.ndarray, idx: np.ndarray, subset: np.ndarray | None = None):
    """Yield ``(rows, N)`` for each neighbourhood size ``k``: ``N`` is ``(g, k)``, self first.

    ``subset`` restricts the rows to those vertices.
    """
    subset = np.arange(len(ptr) - 1) if subset is None else subset
    sizes = ptr[subset + 1] - ptr[subset]
    for k in np.unique(sizes):
        rows = subset[sizes == k]
        yield rows, idx[ptr[rows][:, None] + np.arange(k)]


def _design(V, N, b1, b2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local coordinates ``(u, v)`` of ``N`` in the tangent planes, divided by their RMS radius."""
    D = V[N] - V[N[:, :1]]
    u = np.einsum("gkd,gd->gk", D, b1)
    v = np.einsum("gkd,gd->gk", D, b2)
    s = np.sqrt((u**2 + v**2).sum(axis=1) / (N.shape[1] - 1))[:, None]
    return u / s, v / s, s


def ill_conditioned(
    V: np.ndarray,
    ptr: np.ndarray,
    idx: np.ndarray,
    b1: np.ndarray,
    b2: np.ndarray,
    min_rcond: float,
    subset: np.ndarray | None = None,
) -> np.ndarray:
    """Vertices whose quadratic fit is worse conditioned than `min_rcond` (sec. 3.2).

    The conditioning is ``sigma_min / sigma_max`` of the normalized design
    ``P = [u^2, uv, v^2, u, v, 1]``, i.e. ``sqrt(lambda_min / lambda_max)`` of ``G = P^T P``. Most
    neighbourhoods are far from the threshold (interior vertices of a regular mesh score
    0.13-0.18 against 0.03), so they are cleared by a Cholesky test: with ``r = min_rcond``, if
    ``G - r^2 trace(G) I`` is positive definite then ``lambda_min > r^2 trace(G) >= r^2
    lambda_max``. Only the rest (mostly boundary vertices) get an eigenvalue decomposition; the
    answer is that of computing every ``lambda_min / lambda_max``, at 60% of its cost.

    Returns
    -------
    (n,) bool ndarray
        True for the ill-conditioned vertices of `subset` (all vertices by default).
    """
    rows = np.arange(len(V)) if subset is None else np.asarray(subset, dtype=np.int64)
    G = np.empty((len(rows), 6, 6))  # only the unsure ones' are written (pages untouched)
    unsure = _cholesky_screen(V, ptr, idx, b1, b2, float(min_rcond), rows, G)
    lam = np.linalg.eigvalsh(G[: len(unsure)])
    out = np.zeros(len(V), dtype=bool)
    out[rows[unsure]] = lam[:, 0] < min_rcond**2 * lam[:, -1]
    return out


@njit(cache=True, nogil=True)
def _cholesky_screen(V, ptr, idx, b1, b2, min_rcond, rows, Gs):  # pragma: no cover - compiled
    """:func:`ill_conditioned`'s Cholesky test of the vertices `rows`, vertex after vertex: the
    positions in `rows` it leaves unsure, their Gram matrices ``G`` in `Gs`, in order. Compiled:
    the batched numpy form cost 1 ms a call in groups of neighbourhood sizes, most of brain-2k's
    49 calls being small; the eigenvalues of the unsure stay with numpy (numba's LAPACK
    bindings took 1.5 s to compile on the first run)."""
    r2 = min_rcond * min_rcond
    most = 1
    for i in rows:
        most = max(most, ptr[i + 1] - ptr[i])
    u = np.empty(most)
    v = np.empty(most)
    unsure = np.empty(len(rows), dtype=np.int64)
    n_unsure = 0
    G = np.empty((6, 6))
    H = np.empty((6, 6))
    p = np.empty(6)
    for t in range(len(rows)):
        i = rows[t]
        start, k = ptr[i], ptr[i + 1] - ptr[i]
        c = idx[start]
        # the normalized design (as _design): tangent coordinates over their RMS radius
        squares = 0.0
        for a in range(k):
            w = idx[start + a]
            d0, d1, d2 = V[w, 0] - V[c, 0], V[w, 1] - V[c, 1], V[w, 2] - V[c, 2]
            u[a] = d0 * b1[i, 0] + d1 * b1[i, 1] + d2 * b1[i, 2]
            v[a] = d0 * b2[i, 0] + d1 * b2[i, 1] + d2 * b2[i, 2]
            squares += u[a] * u[a] + v[a] * v[a]
        scale = np.sqrt(squares / (k - 1))
        G[:] = 0.0
        for a in range(k):
            x, y = u[a] / scale, v[a] / scale
            p[0], p[1], p[2], p[3], p[4], p[5] = x * x, x * y, y * y, x, y, 1.0
            for r in range(6):
                for q in range(r, 6):
                    G[r, q] += p[r] * p[q]
        trace = 0.0
        for r in range(6):
            trace += G[r, r]
            for q in range(r):
                G[r, q] = G[q, r]
        # the Cholesky test of G - r^2 trace(G) I (see ill_conditioned)
        for r in range(6):
            for q in range(6):
                H[r, q] = G[r, q]
            H[r, r] -= r2 * trace
        definite = True
        for j in range(6):
            if not H[j, j] > 0:
                definite = False
                break
            root = np.sqrt(H[j, j])
            for a in range(j + 1, 6):
                H[a, j] /= root
            for a in range(j + 1, 6):
                for b in range(j + 1, 6):
                    H[a, b] -= H[a, j] * H[b, j]
        if not definite:
            # element by element: an array assigned to a slice (``Gs[n] = G``) made numba
            # compile its shape-mismatch message (string formatting, ~3 s on a first run)
            for r in range(6):
                for q in range(6):
                    Gs[n_unsure, r, q] = G[r, q]
            unsure[n_unsure] = t
            n_unsure += 1
    return unsure[:n_unsure]


def _pca_normals(V: np.ndarray, ptr: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Normal of the least-squares plane of each neighbourhood (classic HLLE's tangent)."""
    normals = np.empty((len(V), 3))
    for rows, N in _groups(ptr, idx):
        X = V[N] - V[N].mean(axis=1, keepdims=True)
        normals[rows] = np.linalg.svd(X, full_matrices=False)[2][:, -1]
    return normals


def tangent_frames(
    V: np.ndarray,
    F: np.ndarray,
    ptr: np.ndarray,
    idx: np.ndarray,
    *,
    tangent: str = "normals",
    smoothing: int = NORMAL_SMOOTHING,
    min_cos: float | None = FOLD_MIN_COS,
    adjacency: sp.csr_matrix | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """An orthonormal basis ``[b1, b2]`` of the tangent plane ``T_x M`` at every vertex (sec. 3.1).

    ``tangent="normals"`` (the paper): the plane normal to the average of the adjacent triangle
    normals ``n_bar_i``, then averaged `smoothing` times with the neighbours' (``n_i <- n_i +
    sum_{j ~ i} n_j``, normalized), so the plane follows the surface over a few rings rather than
    the adjacent triangles alone. On folded cortex the adjacent triangles of a vertex in a sulcal
    fold or on a chart's boundary give a plane tilted against its neighbours', and the
    projections ``O_i`` of neighbouring vertices then disagree; the averaged planes raised the
    raw map from 72 to 81 of 89 bijective on real fsaverage5 parcels and from 53-55 to 80-82 on
    the synthetic cortex sets (``NORMAL_SMOOTHING``). Then, where a plane would project one of
    the vertex's adjacent triangles at more than ``arccos(min_cos)`` from its own normal (nearly
    flat or folded), the plane is turned just enough (:func:`unfolded_normals`); ``min_cos=None``
    keeps the averaged planes. ``smoothing=0, min_cos=None`` is the paper's plane.
    ``tangent="pca"`` (classic HLLE): the least-squares plane of ``N_i``.

    Parameters
    ----------
    min_cos : float or None
        ``FOLD_MIN_COS`` by default (``tangent="normals"`` only).
    adjacency : (n, n) scipy.sparse.csr_matrix, optional
        ``vertex_adjacency(F, n)``, when the caller already has it.

    Returns
    -------
    b1, b2 : (n, 3) float64 ndarray
    """
    tangent = check_choice("tangent", tangent, TANGENTS)
    if tangent == "normals":
        fn = face_normals(V, F)  # for the vertex normals and the fold test
        normal = vertex_normals(V, F, face_normal=fn)
        flat = np.linalg.norm(normal, axis=1) < 0.5  # adjacent normals cancel: fall back to PCA
        if flat.any():
            normal[flat] = _pca_normals(V, ptr, idx)[flat]
        if smoothing:
            A = vertex_adjacency(F, len(V)) if adjacency is None else adjacency
            for _ in range(smoothing):  # rounds over all vertices at once
                total = normal + A @ normal
                norm = np.linalg.norm(total, axis=1, keepdims=True)
                normal = np.divide(total, norm, out=normal, where=norm > 1e-12)
        if min_cos is not None:
            normal = unfolded_normals(V, F, normal, min_cos, face_normal=fn)
    else:  # "pca"
        normal = _pca_normals(V, ptr, idx)
    return plane_basis(normal)


def unfolded_normals(
    V: np.ndarray,
    F: np.ndarray,
    normal: np.ndarray,
    min_cos: float = FOLD_MIN_COS,
    face_normal: np.ndarray | None = None,
) -> np.ndarray:
    """Tangent-plane normals turned so that the plane keeps every adjacent triangle's orientation.

    Section 3.1 projects ``N_i`` onto ``T_x M`` to get the local parameterization ``O_i``, and
    notes that "local non-bijectivity results in a folding of the surface in the global
    parameterization". A triangle ``t`` adjacent to ``x_i`` projects onto the plane of normal
    ``n_i`` with ``n_i . n_t`` times its area, negative when the projection flips it. On folded
    cortex the averaged planes (``NORMAL_SMOOTHING``) of vertices on sulcal walls can stand at
    70-90 degrees to some adjacent triangles, which then project flat or flipped, and the raw map
    flips 1-2 triangles there (BENCHMARKS.md, section 1). At every vertex whose least
    ``n_i . n_t`` over its adjacent triangles is below `min_cos`: the normal ``m_i`` that
    maximizes that least cosine (the centre of the smallest spherical cap holding the adjacent
    normals) is found by ``MAXMIN_STEPS`` subgradient steps from ``n_i`` (each towards the worst
    triangle's normal, step ``0.5 / sqrt(k)``, best iterate kept), and the new normal is the first
    of ``normalize((1 - s) n_i + s m_i)``, ``s = 1 / MAXMIN_CANDIDATES, ..., 1``, whose least
    cosine reaches `min_cos` (``m_i`` itself if none does): the least turn that unfolds the 1-ring.
    Vertices above `min_cos` keep their plane. Compiled, vertex after vertex.

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray
    normal : (n, 3) float ndarray
        Unit normals (the averaged ones of :func:`tangent_frames`).
    min_cos : float
    face_normal : (m, 3) float ndarray, optional
        ``face_normals(V, F)``, when the caller already has it.

    Returns
    -------
    (n, 3) float64 ndarray
        Unit normals; rows of the vertices not turned are `normal`'s.
    """
    n = len(V)
    fn = np.ascontiguousarray(face_normals(V, F) if face_normal is None else face_normal)
    F = np.ascontiguousarray(F, dtype=np.int64)
    least = _least_cosines(np.ascontiguousarray(normal, dtype=np.float64), fn, F, n)
    turn = np.flatnonzero(least < min_cos)
    if len(turn) == 0:
        return normal
    # each vertex to turn and its adjacent faces, in face order
    local = np.full(n, -1, dtype=np.int64)
    local[turn] = np.arange(len(turn))
    corner = np.flatnonzero(local[F.ravel()] >= 0)
    order, bounds = group_by_label(local[F.ravel()[corner]], len(turn))
    normal = normal.copy()
    normal[turn] = _turned_normals(
        np.ascontiguousarray(normal[turn]), fn, bounds, corner[order] // 3, least[turn], min_cos,
        MAXMIN_STEPS, MAXMIN_CANDIDATES,
    )  # fmt: skip
    return normal


@njit(cache=True, nogil=True)
def _face_least_cos(m0, m1, m2, fn, faces):  # pragma: no cover - compiled
    """The least ``m . fn[f]`` over `faces` and the last face (in their order) attaining it."""
    least = np.inf
    worst = 0
    for f in faces:
        c = m0 * fn[f, 0] + m1 * fn[f, 1] + m2 * fn[f, 2]
        if c <= least:
            least = c
            worst = f
    return least, worst


@njit(cache=True, nogil=True)
def _least_cosines(normal, fn, F, n):  # pragma: no cover - compiled
    """Per vertex v of the n, the least ``normal[v] . fn[f]`` over its faces f (inf for a vertex
    without faces)."""
    out = np.full(n, np.inf)
    for f in range(len(F)):
        for corner in range(3):
            v = F[f, corner]
            c = normal[v, 0] * fn[f, 0] + normal[v, 1] * fn[f, 1] + normal[v, 2] * fn[f, 2]
            out[v] = min(out[v], c)
    return out


@njit(cache=True, nogil=True)
def _turned_normals(
    start, fn, bounds, faces, least, min_cos, steps, candidates
):  # pragma: no cover - compiled
    """:func:`unfolded_normals`' search for each vertex to turn, one after the other: vertex t
    starts at ``start[t]`` (least cosine ``least[t]``) with adjacent faces ``faces[bounds[t] :
    bounds[t + 1]]``. The arithmetic of the batched numpy form, term by term."""
    out = np.empty_like(start)
    for t in range(len(start)):
        own = faces[bounds[t] : bounds[t + 1]]
        s0, s1, s2 = start[t, 0], start[t, 1], start[t, 2]
        m0, m1, m2 = s0, s1, s2
        b0, b1, b2 = s0, s1, s2
        best_cos = least[t]
        for k in range(steps):  # subgradient ascent on the least cosine
            cos, worst = _face_least_cos(m0, m1, m2, fn, own)
            if cos > best_cos:
                b0, b1, b2, best_cos = m0, m1, m2, cos
            step = 0.5 / np.sqrt(k + 1)
            m0 = m0 + step * fn[worst, 0]
            m1 = m1 + step * fn[worst, 1]
            m2 = m2 + step * fn[worst, 2]
            norm = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
            m0, m1, m2 = m0 / norm, m1 / norm, m2 / norm
        out[t, 0], out[t, 1], out[t, 2] = b0, b1, b2
        for i in range(1, candidates + 1):  # the least turn towards it that unfolds the ring
            s = i / candidates
            c0 = (1 - s) * s0 + s * b0
            c1 = (1 - s) * s1 + s * b1
            c2 = (1 - s) * s2 + s * b2
            norm = max(np.sqrt(c0 * c0 + c1 * c1 + c2 * c2), 1e-300)
            c0, c1, c2 = c0 / norm, c1 / norm, c2 / norm
            if _face_least_cos(c0, c1, c2, fn, own)[0] >= min_cos:
                out[t, 0], out[t, 1], out[t, 2] = c0, c1, c2
                break
    return out


# ---------------------------------------------------------------------------------------------
# 3.2 Tangent Hessian by quadratic interpolation, C_i (eq. 4-6)
# ---------------------------------------------------------------------------------------------


def local_hessians(V: np.ndarray, N: np.ndarray, b1: np.ndarray, b2: np.ndarray) -> np.ndarray:
    """``C_i`` of eq. 6 for a stack of neighbourhoods of one size.

    The interpolation functions ``N_ij(u, v) = alpha_j u^2 + beta_j uv + gamma_j v^2 + ...`` (eq. 4)
    are fitted in the least-squares sense, and ``alpha_i, beta_i, gamma_i`` are the rows of the map
    from the values ``f_i`` to the fitted quadratic coefficients. The fit is done in two steps, the
    linear part ``[u, v, 1]`` first and the quadratic part ``Q = [u^2, uv, v^2]`` on what the linear
    part leaves (``Pi = I - L L^+``): that is the ordinary least-squares fit when the 6-point design
    has full rank, and when it does not (collinear boundary points) it still maps every linear
    function to a zero Hessian, so ``K`` keeps the coordinates in its null space.
    Coordinates are divided by the neighbourhood's RMS radius ``s`` first (conditioning) and the
    coefficients scaled back by ``1 / s^2``.

    Parameters
    ----------
    V : (n, 3) float ndarray
    N : (g, k) int ndarray
        Neighbourhoods, centre vertex first.
    b1, b2 : (g, 3) float ndarray
        Tangent bases at the centres.

    Returns
    -------
    C : (g, k, k) float64 ndarray
        ``4 alpha alpha^T + 2 beta beta^T + 4 gamma gamma^T``, so that
        ``||H^tan f||_F^2 ~ f_i^T C_i f_i`` (eq. 5, 6).
    """
    u, v, s = _design(V, N, b1, b2)
    L = np.stack([u, v, np.ones_like(u)], axis=2)
    Q = np.stack([u * u, u * v, v * v], axis=2)
    residual = Q - L @ (_pinv(L) @ Q)  # Pi Q, Pi = I - L L^+
    coef = _pinv(residual) / (s**2)[:, :, None]  # (g, 3, k): rows alpha, beta, gamma
    a, b, c = coef[:, 0], coef[:, 1], coef[:, 2]
    return (
        4 * a[:, :, None] * a[:, None, :]
        + 2 * b[:, :, None] * b[:, None, :]
        + 4 * c[:, :, None] * c[:, None, :]
    )


def _pinv(A: np.ndarray, rcond: float = 1e-10) -> np.ndarray:
    """Batched pseudo-inverse of tall ``(g, k, 3)`` matrices through their 3x3 Gram matrices.

    Much faster than ``np.linalg.pinv`` (an SVD per matrix) on millions of tiny problems; the
    coordinates are normalized, so the Gram matrices are well scaled. A Gram matrix ``G`` with
    ``det G / trace(G)^3 > rcond`` has ``lambda_min / lambda_max > rcond`` and is inverted in closed
    form (cofactors); the others, rank-deficient or nearly, go through ``eigh`` and have their
    eigenvalues below ``rcond * lambda_max`` dropped.
    """
    At = A.transpose(0, 2, 1)
    G = At @ A
    a, b, c = G[:, 0, 0], G[:, 1, 1], G[:, 2, 2]
    d, e, f = G[:, 0, 1], G[:, 1, 2], G[:, 0, 2]
    cof = np.stack(
        [
            np.stack([b * c - e * e, f * e - d * c, d * e - f * b], axis=1),
            np.stack([f * e - d * c, a * c - f * f, d * f - a * e], axis=1),
            np.stack([d * e - f * b, d * f - a * e, a * b - d * d], axis=1),
        ],
        axis=1,
    )
    det = a * cof[:, 0, 0] + d * cof[:, 0, 1] + f * cof[:, 0, 2]
    trace = a + b + c
    good = det > rcond * trace**3
    inv = cof / np.where(good, det, 1.0)[:, None, None]
    bad = np.flatnonzero(~good)
    if len(bad):
        lam, U = np.linalg.eigh(G[bad])
        keep = lam > rcond * lam[:, -1:]
        lam_inv = np.where(keep, 1.0 / np.where(keep, lam, 1.0), 0.0)
        inv[bad] = (U * lam_inv[:, None, :]) @ U.transpose(0, 2, 1)
    return inv @ At


# ---------------------------------------------------------------------------------------------
# 3.3 Partition of unity and assembly of K (eq. 7-9)
# ---------------------------------------------------------------------------------------------


def vertex_weights(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``int_M phi_i dA = (1/3) sum_j A_ij`` for the hat functions ``phi_i`` of eq. 7 (eq. 8)."""
    return np.bincount(F.ravel(), weights=np.repeat(face_areas(V, F), 3), minlength=len(V)) / 3


def _scatter(n: int, blocks: list[tuple[np.ndarray, np.ndarray]]) -> sp.csr_matrix:
    """Sum ``(g, k, k)`` blocks at the indices ``(N_i, N_i)`` into one ``n x n`` CSR matrix."""
    rows, cols, vals = [], [], []
    for N, W in blocks:
        k = N.shape[1]
        rows.append(np.repeat(N, k, axis=1).ravel())
        cols.append(np.tile(N, (1, k)).ravel())
        vals.append(W.ravel())
    K = sp.coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
    ).tocsr()
    K.sum_duplicates()
    return K


def hessian_matrix(
    V: np.ndarray,
    F: np.ndarray,
    *,
    tangent: str = "normals",
    min_points: int = MIN_POINTS,
    min_rcond: float = MIN_RCOND,
) -> sp.csr_matrix:
    """The global Hessian estimator ``K = sum_i (1/3 sum_j A_ij) C_i`` (eq. 2, 9; sec. 3.4).

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray
    tangent : {"normals", "pca"}
    min_points : int
        Smallest neighbourhood (see :func:`neighbourhoods`).
    min_rcond : float
        A neighbourhood whose quadratic fit is worse conditioned than this (smallest over largest
        singular value of the normalized design ``[u^2, uv, v^2, u, v, 1]``) gets its next-nearest
        point, one at a time, up to ``MAX_EXTEND`` points. This is what keeps boundary vertices
        (whose few neighbours are nearly collinear) from blowing up ``K``; interior vertices of a
        regular mesh score 0.13-0.18 and are never extended.

    Returns
    -------
    K : (n, n) scipy.sparse.csr_matrix
        Symmetric positive semi-definite; ``K @ 1 = 0``.
    """
    return _hessian_matrix(V, F, tangent, min_points, min_rcond)[0]


def _hessian_matrix(V, F, tangent, min_points, min_rcond, room=None):
    """:func:`hessian_matrix`, and which vertices were starved (see :func:`neighbourhoods`'
    ``room``; all False without it, where a starved vertex raises InvalidMeshError)."""
    extra = np.zeros(len(V), dtype=np.int64)
    on_boundary = np.zeros(len(V), dtype=bool)
    on_boundary[boundary_half_edges(F, len(V)).ravel()] = True  # as mesh.boundary_edges
    check = None  # vertices whose neighbourhood changed: all of them at first
    A = vertex_adjacency(F, len(V))
    nbr = dict(min_points=min_points, adjacency=A, room=room)
    ptr, idx = neighbourhoods(V, F, extra=extra, **nbr)
    # Averaged-normal frames do not depend on N_i (only their rare flat-vertex fallback uses the
    # first N_i): they are computed once. PCA frames follow every extension.
    b1, b2 = tangent_frames(V, F, ptr, idx, tangent=tangent, adjacency=A)
    for _ in range(MAX_EXTEND):
        bad = ill_conditioned(V, ptr, idx, b1, b2, min_rcond, check)
        if EXTEND_BOUNDARY_ONLY:
            bad &= on_boundary
        if not bad.any():
            break
        extra[bad] += 1
        check = np.flatnonzero(bad)
        ptr, idx = neighbourhoods(V, F, extra=extra, **nbr)
        if tangent == "pca":
            b1, b2 = tangent_frames(V, F, ptr, idx, tangent=tangent)
    w = vertex_weights(V, F)
    blocks = []
    for rows, N in _groups(ptr, idx):
        C = local_hessians(V, N, b1[rows], b2[rows])
        blocks.append((N, w[rows][:, None, None] * C))
    starved = np.zeros(len(V), dtype=bool)
    if room is not None:  # a vertex that needed more points than its chart has, at any round
        deg = np.diff(A.indptr)
        starved = _points_needed(deg, min_points, extra) > room - 1 - deg
    return _scatter(len(V), blocks), starved


def classic_hlle_matrix(V: np.ndarray, *, n_neighbors: int = 12) -> sp.csr_matrix:
    """Donoho & Grimes' Hessian estimator: the paper's baseline (section 2.1).

    Neighbourhoods are the ``n_neighbors`` nearest points (the vertex included), local coordinates
    the top two principal directions; the Hessian estimator is the last three columns of the
    Gram-Schmidt orthonormalization of ``[1, u, v, u^2, uv, v^2]``, ``W_i = H_i H_i^T``.

    Returns
    -------
    K : (n, n) scipy.sparse.csr_matrix
    """
    k = min(n_neighbors, len(V))
    if k < MIN_POINTS:
        raise InvalidMeshError(f"classic HLLE needs at least {MIN_POINTS} neighbours, got {k}")
    _, N = cKDTree(V).query(V, k=k)
    X = V[N] - V[N].mean(axis=1, keepdims=True)
    basis = np.linalg.svd(X, full_matrices=False)[2][:, :2]  # (n, 2, 3)
    U = np.einsum("nkd,ncd->nkc", X, basis)
    U = U / np.sqrt((U**2).sum(axis=(1, 2)) / k)[:, None, None]
    u, v = U[..., 0], U[..., 1]
    Y = np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=2)
    Q = np.linalg.qr(Y)[0][:, :, 3:]  # (n, k, 3)
    return _scatter(len(V), [(N, Q @ Q.transpose(0, 2, 1))])


# ---------------------------------------------------------------------------------------------
# 3.4 Eigenvectors of K, then the 2x2 map and the orientation
# ---------------------------------------------------------------------------------------------


def explained_by_first(vectors: np.ndarray) -> np.ndarray:
    """How much of each later eigenvector's variance a function of the first one explains.

    ``vectors`` are the smallest eigenvectors of ``K`` in ascending order, the constant first, for
    a stack of charts: ``(g, s, k)``. On a long curved chart the Hessian energy of a quadratic of
    the long coordinate can undercut that of the short coordinate (whose Hessian is not zero on a
    surface that is not developable), and the pair of eq. 3 is then ``h1`` and nearly ``g(h1)``:
    the map folds the chart over a curve (BENCHMARKS.md, section 1). For every ``h_j``, ``j >= 2``,
    this is the ``R^2`` of its least-squares fit by a polynomial of degree ``DEPENDENT_DEGREE`` in
    ``h1`` (the test of repeated eigendirections of spectral embeddings: Dsilva et al.,
    "Parsimonious representation of nonlinear dynamical systems through manifold learning", 2018,
    with a global polynomial instead of a local linear regression).

    Returns
    -------
    (g, k - 2) float64 ndarray
    """
    vectors = np.ascontiguousarray(vectors, dtype=np.float64)
    return _explained(vectors, DEPENDENT_DEGREE, POLY_RANK_TOL)


@njit(cache=True, nogil=True)
def _dot(a, b):  # pragma: no cover - compiled
    """``a . b`` of two vectors, in order."""
    total = 0.0
    for i in range(len(a)):
        total += a[i] * b[i]
    return total


@njit(cache=True, nogil=True)
def _take_out(w, q):  # pragma: no cover - compiled
    """``w -= (q . w) q`` (q a unit vector)."""
    c = _dot(q, w)
    for i in range(len(w)):
        w[i] -= c * q[i]


@njit(cache=True, nogil=True)
def _explained(vectors, degree, rank_tol):  # pragma: no cover - compiled
    """:func:`explained_by_first`, chart after chart (compiled: batched numpy cost 0.16 ms a
    call, mostly on one chart at a time). The powers of h1 are orthonormalized by Gram-Schmidt,
    twice over, in plain loops (numba's LAPACK bindings and array expressions took 5-9 s to
    compile on the first run): a power whose residual is below `rank_tol` of its norm stays in
    the basis, as in a QR factorization, but explains nothing."""
    g, s, k = vectors.shape
    out = np.empty((g, k - 2))
    Q = np.empty((degree + 1, s))
    X = np.empty((k, s))
    w = np.empty(s)
    for b in range(g):
        for j in range(k):  # centred, one row per eigenvector
            mean = 0.0
            for i in range(s):
                mean += vectors[b, i, j]
            mean /= s
            for i in range(s):
                X[j, i] = vectors[b, i, j] - mean
        rms = max(np.sqrt(_dot(X[1], X[1]) / s), 1e-300)
        n_basis = 0
        kept = np.zeros(degree + 1, dtype=np.bool_)
        for p in range(min(s, degree + 1)):
            for i in range(s):
                w[i] = (X[1, i] / rms) ** float(p)
            norm = np.sqrt(_dot(w, w))
            for _ in range(2):
                for q in range(n_basis):
                    _take_out(w, Q[q])
            r = np.sqrt(_dot(w, w))
            if r > 0:
                for i in range(s):
                    Q[n_basis, i] = w[i] / r
                kept[n_basis] = r > rank_tol * norm
                n_basis += 1
        for j in range(2, k):
            total = max(_dot(X[j], X[j]), 1e-300)
            for i in range(s):
                w[i] = X[j, i]
            for q in range(n_basis):
                if kept[q]:
                    _take_out(w, Q[q])
            out[b, j - 2] = 1 - _dot(w, w) / total
    return out


def _select(vectors: np.ndarray, more) -> np.ndarray:
    """``vectors`` (the three smallest, ``(g, s, 3)``) with the second coordinate replaced by the
    third where it is explained by the first above ``DEPENDENT_R2`` and the third is less so.
    ``more(b)`` gives chart ``b``'s four smallest eigenvectors (``(s, 4)``)."""
    vectors = _constant_first(vectors)
    for b in np.flatnonzero(explained_by_first(vectors)[:, 0] > DEPENDENT_R2):  # rare
        four = _constant_first(more(b)[None])[0]
        if _second(explained_by_first(four[None])[0]) == 2:
            vectors[b] = four[:, [0, 1, 3]]
    return vectors


def _constant_first(vectors: np.ndarray) -> np.ndarray:
    """The smallest eigenvectors ``(g, s, k)`` (a copy), each stack with the constant first and
    the others in order, orthonormal to it.

    ``K`` maps constants to 0, and usually the constant is the first eigenvector as it comes.
    When another function is as exactly in the null space (a developable chart's linear
    coordinate, e.g. a cylinder's wall cut open), the eigensolver returns any rotation of the
    two: the constant is then put first and the other vectors, in order, orthogonalized against
    it and each other, the one that only held the constant's part dropped. (Read as it came, the
    mixture made :func:`explained_by_first` measure the wrong coordinate: the 6 one-row hole
    walls of the CAD plate, cut open, all took the wrong pair and needed the fallback pairs.)
    """
    vectors = vectors.copy()
    s, k = vectors.shape[1:]
    c = np.full(s, 1.0 / np.sqrt(s))
    mixed = np.abs(vectors[:, :, 0] @ c) < 1.0 - CONSTANT_FIRST_TOL
    for b in np.flatnonzero(mixed):  # loop over the charts (rare) whose null space is mixed
        basis = [c]
        for v in vectors[b].T:  # k vectors: keep the k - 1 that add a direction
            w = v - np.column_stack(basis) @ (np.column_stack(basis).T @ v)
            if len(basis) < k and np.linalg.norm(w) > 0.5:
                basis.append(w / np.linalg.norm(w))
        vectors[b] = np.column_stack(basis)
    return vectors


def _second(r2: np.ndarray) -> int:
    """The eigenvector paired with ``h1`` (1: the second, 2: the third) from the ``R^2`` of
    ``h2, h3`` on ``h1`` (:func:`explained_by_first`)."""
    return 2 if r2[0] > DEPENDENT_R2 and r2[1] < r2[0] else 1


def _coordinates(vectors: np.ndarray) -> np.ndarray:
    """The 2-D span of eigenvectors ``[1-ish, h1, h]`` with the constant projected out,
    orthonormal (``(g, s, 3)`` in, ``(g, s, 2)`` out)."""
    X = vectors - vectors.mean(axis=1, keepdims=True)
    return np.linalg.svd(X, full_matrices=False)[0][:, :, :2]


def hessian_eigenmap(
    K: sp.spmatrix, *, seed: int = 0, guess: np.ndarray | None = None, select: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates ``h1, h2`` (orthonormal, orthogonal to 1) from the near-null space of K (eq. 3).

    The near-null space is 3-dimensional (the constant and two coordinates) and nearly degenerate,
    so the three smallest eigenvectors are taken together, the constant is projected out and the
    remaining 2-D span is orthonormalized. When the second coordinate is nearly a function of the
    first and the next is less so (:func:`explained_by_first`, ``DEPENDENT_R2``), the fourth
    smallest eigenvector takes its place (unless
    ``select=False``: classic HLLE, the paper's baseline, takes the pair of eq. 3 as it is).
    ``guess`` (for example ``[1, x, y, z]``: on a nearly developable chart the coordinates are
    close to the null space) only speeds up the solver.

    Returns
    -------
    Y : (n, 2) float64 ndarray
    values : (3,) float64 ndarray
        The three smallest eigenvalues of ``K``.
    """
    values, vectors = smallest_eigenpairs(K, 3, seed=seed, guess=guess)
    if select and K.shape[0] > 4:
        spare = np.random.default_rng(seed + 1).standard_normal(K.shape[0])
        start = np.column_stack([vectors, spare])  # (+ 1 random) a block of 5 for 4 pairs
        vectors = _select(
            vectors[None], lambda b: smallest_eigenpairs(K, 4, seed=seed, guess=start)[1]
        )[0]
    return _coordinates(vectors[None])[0], values


def _metric_design(
    V: np.ndarray, F: np.ndarray, Y: np.ndarray, inv_frames: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """The least-squares design of :func:`isometric_fit`, per triangle, and its weights.

    ``design[t] @ (m11, m12, m22)`` is ``G_t^T M G_t`` as its entries ``(xx, yy, sqrt2 xy)``
    (``G_t`` the Jacobian of triangle t into ``Y``); the weights are the triangle areas. Returns
    ``design`` (m, 3, 3) and ``w`` (m,).
    """
    G = jacobians(V, F, Y, inv_frames)
    r1, r2 = G[:, 0, :], G[:, 1, :]  # rows of G_t

    def sym(p, q):  # entries (xx, yy, sqrt2 xy) of p q^T + q p^T, / 2
        return np.stack(
            [
                p[:, 0] * q[:, 0],
                p[:, 1] * q[:, 1],
                np.sqrt(0.5) * (p[:, 0] * q[:, 1] + p[:, 1] * q[:, 0]),
            ],
            axis=1,
        )

    design = np.stack([sym(r1, r1), 2 * sym(r1, r2), sym(r2, r2)], axis=2)  # (m, 3, 3)
    return design, face_areas(V, F)


def isometric_fit(
    V: np.ndarray, F: np.ndarray, Y: np.ndarray, inv_frames: np.ndarray | None = None
) -> np.ndarray:
    """The linear map ``uv = Y A`` that makes the chart closest to isometric.

    With ``G_t`` the Jacobian of triangle ``t`` into ``Y``, the map's metric is
    ``G_t^T M G_t`` with ``M = A A^T``; ``M`` minimizes ``sum_t A_t ||G_t^T M G_t - I||_F^2``, a
    linear least-squares problem in its three entries; ``A = M^{1/2}``.

    Returns
    -------
    uv : (n, 2) float64 ndarray
    """
    design, w = _metric_design(V, F, Y, inv_frames)
    target = np.array([1.0, 1.0, 0.0])
    lhs = np.einsum("m,mij,mik->jk", w, design, design)
    rhs = np.einsum("m,mij,i->j", w, design, target)
    m11, m12, m22 = np.linalg.solve(lhs, rhs)
    vals, vecs = np.linalg.eigh(np.array([[m11, m12], [m12, m22]]))
    vals = np.maximum(vals, 1e-12 * max(vals.max(), 1e-300))
    A = (vecs * np.sqrt(vals)) @ vecs.T
    return Y @ A


def orient(uv: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Mirror ``uv`` if most of its area has the input's opposite winding (no mirrored chart)."""
    if signed_areas(uv, F).sum() < 0:
        uv = uv * np.array([-1.0, 1.0])
    return uv


# ---------------------------------------------------------------------------------------------
# Refinement (not in the paper): as-rigid-as-possible iterations started from the Hessian map
# ---------------------------------------------------------------------------------------------


def _gradient_operator(
    V: np.ndarray, F: np.ndarray, inv_frames: np.ndarray | None = None
) -> sp.csr_matrix:
    """``D`` (2m x n): row ``2t + k`` gives column ``k`` of triangle ``t``'s Jacobian from the
    per-vertex values of one uv coordinate (see :func:`segparam.quality.jacobians`)."""
    m = len(F)
    # J = [q1 q2] @ Pinv, q_j = uv[F_j] - uv[F_0]
    Pinv = inverse_frames(triangle_frames(V, F)) if inv_frames is None else inv_frames
    rows = np.repeat(2 * np.arange(m)[:, None] + np.arange(2), 3, axis=1)  # (m, 2) -> (m, 6)
    rows = rows.reshape(m, 2, 3)
    cols = np.broadcast_to(F[:, None, :], (m, 2, 3))
    vals = np.stack([-Pinv[:, 0, :] - Pinv[:, 1, :], Pinv[:, 0, :], Pinv[:, 1, :]], axis=2)
    return sp.csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(2 * m, len(V)))


#: ARAP stops once the area-weighted mean of ``||J_t - R_t||_F^2`` is below this (every Jacobian
#: within about 1% of a rotation) and no triangle is flipped, ...
ARAP_TOL = 1e-4
#: ... or once an iteration lowers that energy by less than this fraction.
ARAP_MIN_DECREASE = 0.01


def arap_refine(
    V: np.ndarray,
    F: np.ndarray,
    uv: np.ndarray,
    *,
    iterations: int = 10,
    tol: float = ARAP_TOL,
    min_decrease: float = ARAP_MIN_DECREASE,
) -> np.ndarray:
    """As-rigid-as-possible iterations (Liu et al. 2008) from a starting map ``uv``.

    Local step: the rotation closest to each triangle's Jacobian (determinant +1, so flipped
    triangles are pulled back to the input's winding); global step: the map whose Jacobians are
    closest to those rotations, a Poisson problem with a fixed, once-factorized matrix.

    The iterations stop early when the map is already rigid to within `tol` (area-weighted mean of
    ``||J_t - R_t||_F^2``, no flipped triangle) or when an iteration gains less than `min_decrease`
    of the energy: the count of bijective maps on the 89 cortex-like parcels is the same (87) for
    2 to 20 iterations, and a near-isometric eigenmap (a developable chart) skips the refinement,
    its factorization included. Lengths must be in units of the typical edge (as in
    :class:`HessianSolver`) for `tol` to mean the same on every chart; the energy itself is
    scale-free.

    Returns
    -------
    (n, 2) float64 ndarray
    """
    return _arap(V, F, uv, iterations=iterations, tol=tol, min_decrease=min_decrease)[0]


def _arap(
    V, F, uv, *, iterations=10, tol=ARAP_TOL, min_decrease=ARAP_MIN_DECREASE, inv_frames=None
) -> tuple[np.ndarray, int]:
    """:func:`arap_refine`, also returning the number of global steps taken."""
    D = _gradient_operator(V, F, inv_frames)
    w = np.repeat(face_areas(V, F), 2)
    w_total = w.sum() / 2
    free = np.arange(1, len(V))  # vertex 0 is pinned: the energy ignores translations
    solve = None
    uv = uv - uv[0]
    previous = np.inf
    for step in range(iterations + 1):
        G = (D @ uv).reshape(-1, 2, 2)  # G[t][k, c] = J_t[c, k]
        # Closest rotation [[p, -q], [q, p]] to J = [[a, b], [c, d]]: (p, q) ~ (a + d, c - b).
        p = G[:, 0, 0] + G[:, 1, 1]
        q = G[:, 0, 1] - G[:, 1, 0]
        r = np.hypot(p, q)
        r[r == 0] = 1.0
        p, q = p / r, q / r
        Rt = np.stack([np.stack([p, q], 1), np.stack([-q, p], 1)], 1)  # R^T, rows k
        energy = float(((G - Rt) ** 2).sum(axis=2).ravel() @ w) / w_total
        flipped = bool((G[:, 0, 0] * G[:, 1, 1] - G[:, 0, 1] * G[:, 1, 0] <= 0).any())
        if (
            step == iterations
            or (energy < tol and not flipped)
            or previous - energy < min_decrease * previous
        ):
            return uv, step
        previous = energy
        if solve is None:
            DT = D.T  # once: a transpose is a new matrix object each time
            L = (DT @ sp.diags(w) @ D).tocsc()
            solve = spd_solver(L[free][:, free])
        rhs = DT @ (w[:, None] * Rt.reshape(-1, 2))
        uv = np.zeros_like(uv)
        uv[free] = solve(rhs[free])
    raise AssertionError("unreachable")  # pragma: no cover


#: Eigenvector pairs tried, in this order, when the refined map of the paper's pair (the two
#: smallest non-constant eigenvectors, 0 and 1 here) is not bijective (issue 16), among the four
#: smallest. On the 89-parcel sets of ``bench_solver.py --part quality`` the default's failures
#: were global folds of the eigenmap (one coordinate nearly a function of the other, a thin
#: curved band); the refinement cannot undo them, and started from the pair (0, 2) it ended
#: bijective on both charts the default failed (fsaverage5 and cortex-ico). With all five pairs
#: of the four smallest, ``build_atlas`` on the 2k / 20k realistic brains (``bench_atlas.py``'s
#: brain-2k, ``data/brain.obj``) tried 6 / 3 charts and rescued one each, from (0, 2) / (1, 3);
#: no other pair rescued a chart, and every pair tried costs a refinement (brain-2k's
#: parameterize stage 0.30 -> 0.55 s with five pairs): so these two.
FALLBACK_PAIRS = ((0, 2), (1, 3))
#: ... tried on charts with one boundary loop only. On the 15 meshes of a session-12 count
#: (``bench_atlas.py --quick``'s, and realistic brains of seeds 1-3 at 2k and 20k faces) the
#: pairs rescued 9 of 25 failing charts, every one a disk, and none of the 13 with two or more
#: loops (the CAD plate's 6 hole walls, 7 brain pieces): their tries cost the plate's stage
#: 0.037 s of 0.18 (BENCHMARKS.md, section 0.1, session 12).


def _other_pairs(
    V: np.ndarray, F: np.ndarray, K, frames: np.ndarray, *, seed: int = 0, select: bool = True
):
    """Yield the start maps of ``FALLBACK_PAIRS`` (isometric fit, oriented) for one chart.

    The four smallest non-constant eigenvectors of ``K`` (eq. 3 with two more functions): the
    five smallest eigenvectors with the constant projected out, rotated by a Rayleigh-Ritz step
    so that they come in the order of their Hessian energy. Where :func:`hessian_eigenmap` took
    the pair (0, 2) (``select``, ``DEPENDENT_R2``), the pair of eq. 3, (0, 1), takes its place.
    """
    n = len(V)
    if n < 6:
        return
    _, vectors = smallest_eigenpairs(K, 5, seed=seed)
    pairs = FALLBACK_PAIRS
    if select and _second(explained_by_first(vectors[None])[0]) == 2:
        pairs = tuple((0, 1) if pair == (0, 2) else pair for pair in pairs)
    X = vectors - vectors.mean(axis=0)
    U = np.linalg.svd(X, full_matrices=False)[0][:, :4]
    U = U @ np.linalg.eigh(U.T @ (K @ U))[1]
    for i, j in pairs:
        yield orient(isometric_fit(V, F, U[:, [i, j]], frames), F)


def _refine_map(
    V, F, uv, frames, refine, refine_iterations, angle_weight, boundary=None, slim_below=None
):
    """The refinement of :meth:`HessianSolver.solve` from the start map ``uv`` of one chart (in
    units of its typical edge): returns (uv, quality, refined). ``boundary``: the chart's
    boundary edges and loops, when the caller has them (see :func:`chart_quality`);
    ``slim_below``: no ``"slim"`` step for a map stretching more than this (L2)."""
    refined = False
    quality = None
    steps = 0
    if refine in ("arap", "slim"):
        uv_r, steps = _arap(V, F, uv, iterations=refine_iterations, inv_frames=frames)
    if steps:
        q_r = chart_quality(V, F, uv_r, frames, boundary=boundary)
        if q_r.bijective:
            uv, quality, refined = uv_r, q_r, True
        else:
            quality = chart_quality(V, F, uv, frames, boundary=boundary)
            if not quality.bijective and q_r.n_flipped < quality.n_flipped:
                uv, quality, refined = uv_r, q_r, True
    if quality is None:
        quality = chart_quality(V, F, uv, frames, boundary=boundary)
    if (
        refine == "slim"
        and quality.n_flipped == 0
        and quality.n_degenerate == 0
        and (slim_below is None or quality.l2_stretch <= slim_below)
    ):
        uv_s, moved = slim_refine(V, F, uv, inv_frames=frames, angle_weight=angle_weight)
        q_s = chart_quality(V, F, uv_s, frames, boundary=boundary) if moved[0] else None
        if (
            q_s is not None
            and q_s.bijective
            and (
                len(F) >= SMALL_CHART_FACES
                or q_s.l2_stretch <= quality.l2_stretch + MAX_STRETCH_INCREASE
            )
        ):
            uv, quality, refined = uv_s, q_s, True
    return uv, quality, refined


class HessianSolver:
    """Keeps a chart's Hessian matrix ``K`` so it can be inspected or solved again.

    Examples
    --------
    >>> solver = HessianSolver(V, F)          # doctest: +SKIP
    >>> chart = solver.solve(seed=0)          # doctest: +SKIP
    """

    def __init__(
        self,
        V,
        F=None,
        *,
        method: str = "hessian",
        tangent: str = "normals",
        min_points: int = MIN_POINTS,
        n_neighbors: int = 12,
    ) -> None:
        method = check_choice("method", method, METHODS)
        tangent = check_choice("tangent", tangent, TANGENTS)
        min_points = check_int("min_points", min_points, low=MIN_POINTS)
        n_neighbors = check_int("n_neighbors", n_neighbors, low=MIN_POINTS)
        self.V, self.F = check_chart(*mesh_arrays(V, F))  # or a trimesh.Trimesh alone
        self.method, self.tangent = method, tangent
        # Work in units of the typical edge length, centred: the map is invariant under rigid
        # motion and uniform scaling, and K's entries (~ length^-2) stay far from over/underflow
        # whether the input is in metres, nanometres or light years.
        self.scale = float(np.sqrt(face_areas(self.V, self.F).mean()))
        self._Vn = (self.V - self.V.mean(axis=0)) / self.scale
        t0 = time.perf_counter()
        if method == "hessian":
            self.K = hessian_matrix(self._Vn, self.F, tangent=tangent, min_points=min_points)
        else:
            self.K = classic_hlle_matrix(self._Vn, n_neighbors=n_neighbors)
        self.assemble_seconds = time.perf_counter() - t0

    def solve(
        self,
        *,
        seed: int = 0,
        refine: str = "arap",
        refine_iterations: int = 10,
        angle_weight: float = ANGLE_WEIGHT,
        slim_below: float | None = None,
    ) -> ChartMap:
        """Eigenvectors of ``K``, isometric 2x2 fit, orientation, optional refinement, quality.

        ``refine="arap"`` runs :func:`arap_refine` from the Hessian map and keeps the refined map
        unless it is worse: it is kept when it is bijective, or when neither map is and it has
        fewer flipped triangles. A map that is already rigid (see :func:`arap_refine`) is not
        refined. ``refine="slim"`` then lowers the symmetric Dirichlet energy of a map with no
        flipped triangle (:func:`segparam.refine.slim_refine`; ``angle_weight`` trades stretch
        for angle distortion), kept when bijective (and, on charts of fewer than
        ``SMALL_CHART_FACES`` faces, when its L2 stretch is at most ``MAX_STRETCH_INCREASE``
        above the map's before).
        ``refine="none"`` returns the paper's map as it is. With a refinement, a map of a disk
        (one boundary loop) that still is not bijective is refined again from the next pairs of
        eigenvectors of ``K`` (``FALLBACK_PAIRS``, first bijective kept): the paper's pair can
        fold a chart over globally, which the refinement cannot undo.

        ``slim_below``: a map that stretches more than this (L2) before ``"slim"`` is returned
        unrefined. The split stage passes its stretch target: the conformal term trades stretch
        for angle, so such a chart is split anyway (of 706 first-pass charts over the 1.02
        target on five bench_atlas meshes, one came under it after the refinement).
        """
        seed = check_int("seed", seed, low=0)
        refine = check_choice("refine", refine, REFINES)
        refine_iterations = check_int("refine_iterations", refine_iterations, low=0)
        angle_weight = check_number("angle_weight", angle_weight, low=0)
        t0 = time.perf_counter()
        guess = np.column_stack([np.ones(len(self._Vn)), self._Vn])
        Y, values = hessian_eigenmap(
            self.K, seed=seed, guess=guess, select=self.method == "hessian"
        )
        t1 = time.perf_counter()
        frames = inverse_frames(triangle_frames(self._Vn, self.F))  # shared by every measure
        B = boundary_edges(self.F)
        boundary = (B, boundary_loops(self.F, boundary=B))  # F's alone: once for every measure
        uv = orient(isometric_fit(self._Vn, self.F, Y, frames), self.F)
        t2 = time.perf_counter()
        args = (frames, refine, refine_iterations, angle_weight, boundary, slim_below)
        uv, quality, refined = _refine_map(self._Vn, self.F, uv, *args)
        if not quality.bijective and refine != "none" and len(boundary[1]) == 1:  # a disk
            select = self.method == "hessian"
            for uv_p in _other_pairs(self._Vn, self.F, self.K, frames, seed=seed, select=select):
                uv_p, q_p, _ = _refine_map(self._Vn, self.F, uv_p, *args)
                if q_p.bijective:
                    uv, quality, refined = uv_p, q_p, True
                    break
        t3 = time.perf_counter()
        return ChartMap(
            uv=(uv - uv.min(axis=0)) * self.scale,
            bijective=quality.bijective,
            quality=quality,
            method=self.method,
            tangent=self.tangent if self.method == "hessian" else "pca",
            eigenvalues=values,
            refined=refined,
            timings={
                "assemble": self.assemble_seconds,
                "eigen": t1 - t0,
                "post": t2 - t1,
                "refine": t3 - t2,
            },
        )


def parameterize_chart(
    V,
    F=None,
    *,
    method: str = "hessian",
    tangent: str = "normals",
    seed: int = 0,
    min_points: int = MIN_POINTS,
    n_neighbors: int = 12,
    refine: str = "arap",
    angle_weight: float = ANGLE_WEIGHT,
    slim_below: float | None = None,
) -> ChartMap:
    """Map one disk-like chart to the plane with the Hessian-eigenfunction solver.

    Parameters
    ----------
    V : (n, 3) array_like of float
    F : (m, 3) array_like of int
        A connected, manifold chart with at least one boundary loop and every vertex in a face.
    method : {"hessian", "classic-hlle"}
        The paper's solver, or Donoho & Grimes' classic HLLE (the paper's baseline).
    tangent : {"normals", "pca"}
        Tangent planes from averaged triangle normals (paper, sec. 3.1) or PCA (``"hessian"`` only).
    seed : int
        Seeds the sparse eigen-solver's start vector.
    min_points : int
        Smallest neighbourhood for the quadratic fit (``"hessian"``).
    n_neighbors : int
        Neighbourhood size of ``"classic-hlle"``.
    refine : {"slim", "arap", "none"}
        ``"arap"`` (default): as-rigid-as-possible iterations from the eigenmap, kept only when
        they do not make the map worse (:meth:`HessianSolver.solve`); ``"slim"``: the same, then
        the flip-free symmetric Dirichlet refinement (:mod:`segparam.refine`), kept when
        bijective; ``"none"``: the paper's map. With ``"arap"`` or ``"slim"`` a map that is not
        bijective is refined again from the next eigenvector pairs if the chart is a disk
        (``FALLBACK_PAIRS``).
    angle_weight : float
        ``refine="slim"`` only: weight (>= 0) of the conformal term added to the symmetric
        Dirichlet energy (:func:`segparam.refine.slim_refine`); higher trades L2 stretch for
        less angle distortion. A chart of fewer than ``refine.SMALL_CHART_ANGLE_FACES`` (32)
        faces is refined with ``refine.SMALL_CHART_ANGLE_SCALE`` (a quarter) of it.
    slim_below : float, optional
        ``refine="slim"`` only: a map stretching more than this (L2) before the refinement is
        returned unrefined (see :meth:`HessianSolver.solve`).

    Returns
    -------
    ChartMap

    Raises
    ------
    InvalidMeshError
        If the chart cannot be parameterized (closed, several components, non-manifold, fewer
        than 6 vertices, ...), with the reason.
    ConfigError
        If an option is not one of its choices, not an integer where one is asked (a bool is
        not), or out of range (``min_points`` and ``n_neighbors`` at least 6, ``seed`` >= 0);
        checked before any work. Also a ``ValueError``.

    References
    ----------
    Hessian Eigenfunctions for Triangular Mesh Parameterization, sections 3.1-3.4, eq. 2-9.
    D. L. Donoho, C. Grimes, Hessian eigenmaps, PNAS 100(10), 2003.
    """
    solver = HessianSolver(
        V, F, method=method, tangent=tangent, min_points=min_points, n_neighbors=n_neighbors
    )
    return solver.solve(seed=seed, refine=refine, angle_weight=angle_weight, slim_below=slim_below)


# ---------------------------------------------------------------------------------------------
# Many small charts at once
# ---------------------------------------------------------------------------------------------
#
# A chart of a few dozen vertices costs the solver about 10 ms, almost all of it Python and
# library-call overhead (the eigenproblem of a 30 x 30 matrix takes 30 us): 600 hemispheres of
# small closed parts took 6 s. The functions below take a disjoint union of charts (every chart
# its own vertices, numbered consecutively, chart by chart) and do every step once for all of
# them: the union's K is block-diagonal, ARAP's Laplacian too, and every measure of
# :func:`segparam.quality.chart_quality` is a sum, a maximum or a count per chart.

#: Most entries of the dense ``(g, n, n)`` stack handed to one batched ``eigh`` (32 MB).
BLOCK_ENTRIES = 4_000_000


def _chart_sum(ids: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Sum of ``values`` (``(k,)`` or ``(k, d)``) over each id ``0 .. n - 1``."""
    if values.ndim == 1:
        return np.bincount(ids, weights=values, minlength=n)
    flat = values.reshape(len(values), -1)
    out = np.stack(
        [np.bincount(ids, weights=flat[:, j], minlength=n) for j in range(flat.shape[1])], 1
    )
    return out.reshape((n,) + values.shape[1:])


def _segment_means(values: np.ndarray, start: np.ndarray, count: np.ndarray) -> np.ndarray:
    """``values[start[c] : start[c] + count[c]].mean()`` for every segment ``c``, bit for bit.

    NumPy sums a contiguous row pairwise, so a row's sum depends on its length's blocking, not
    just its values; rows of one length are summed as one ``(g, length)`` array, which numpy
    sums row by row in that same order (one call per distinct length). The solver's scale must
    be exact: its neighbourhoods are extended by a conditioning threshold, and a last-bit change
    of the coordinates can move a vertex across it (K of a 40-face hemisphere changed by 30%).
    """
    out = np.empty(len(count))
    for n in np.unique(count):
        seg = np.flatnonzero(count == n)
        out[seg] = values[start[seg][:, None] + np.arange(n)].mean(axis=1)
    return out


def _chart_max(ids: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Largest of ``values`` over each id (``-inf`` where there is none; NaN propagates)."""
    out = np.full(n, -np.inf)
    np.maximum.at(out, ids, values)
    return out


def charts_quality(
    V: np.ndarray,
    F: np.ndarray,
    uv: np.ndarray,
    vert_chart: np.ndarray,
    n_charts: int,
    inv_frames: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """:func:`segparam.quality.chart_quality` of every chart of a disjoint union, at once.

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray
        Charts that share no vertex; each is connected, manifold, with a boundary.
    uv : (n, 2) float ndarray
    vert_chart : (n,) int ndarray
        Chart of every vertex, ``0 .. n_charts - 1``.
    inv_frames : (m, 2, 2) float ndarray, optional
        ``inverse_frames(triangle_frames(V, F))``, if already computed.

    Returns
    -------
    dict of (n_charts,) ndarrays
        One per field of :class:`segparam.quality.ChartQuality`, same names and meanings
        (equal up to rounding: the sums run in another order; see :func:`quality_records`).
    """
    n = len(V)
    face_chart = vert_chart[F[:, 0]]
    sa = signed_areas(uv, F)
    total_uv = _chart_sum(face_chart, np.abs(sa), n_charts)
    degenerate = (
        np.abs(sa) <= DEGENERATE_AREA * np.maximum(total_uv, np.finfo(float).tiny)[face_chart]
    )
    flipped = (sa < 0) & ~degenerate

    B = boundary_half_edges(F, n)
    interior_bad, boundary_bad, _ = angle_sum_violations(uv, F, n, boundary=B)

    out = {
        "n_flipped": np.bincount(face_chart, weights=flipped, minlength=n_charts).astype(np.int64),
        "n_degenerate": np.bincount(face_chart, weights=degenerate, minlength=n_charts).astype(
            np.int64
        ),
        "n_branch": np.bincount(
            vert_chart, weights=interior_bad | boundary_bad, minlength=n_charts
        ).astype(np.int64),
        "n_crossings": _charts_crossings(uv, B, vert_chart, n_charts),
        "loops_oriented": _charts_loops_oriented(uv, B, vert_chart, n_charts),
    }
    out["bijective"] = (
        (out["n_flipped"] == 0)
        & (out["n_degenerate"] == 0)
        & (out["n_branch"] == 0)
        & (out["n_crossings"] == 0)
        & out["loops_oriented"]
    )
    out.update(_charts_distortion(V, F, uv, vert_chart, n_charts, inv_frames))
    return out


def _charts_crossings(
    uv: np.ndarray, B: np.ndarray, vert_chart: np.ndarray, n_charts: int
) -> np.ndarray:
    """:func:`segparam.quality.boundary_crossings` of every chart: the boundary segments of all
    charts swept once along u (:func:`_sweep_crossings`)."""
    if len(B) < 2:
        return np.zeros(n_charts, dtype=np.int64)
    chart = vert_chart[B[:, 0]]
    P0, P1 = uv[B[:, 0]], uv[B[:, 1]]
    low, high = np.minimum(P0, P1), np.maximum(P0, P1)
    order = np.lexsort((low[:, 0], chart))
    return _sweep_crossings(P0, P1, B, chart, order, low, high, n_charts)


@njit(cache=True, nogil=True)
def _sweep_crossings(P0, P1, B, chart, order, low, high, n_charts):  # pragma: no cover
    """Per chart, the pairs of its boundary segments that meet (sharing no endpoint index).

    The segments, ordered by chart then by their least u (``order``), are swept: segment ``i``
    is tested against the next ones of its chart while their least u is at most its greatest,
    and their boxes overlap in v too; a pair is tested as ``(lower index, higher index)`` with
    :func:`segparam.quality.segment_pairs_cross`'s arithmetic, term by term (it replaced a k-d
    tree of the midpoints and that function over the pairs it found: the same counts on every
    captured call, BENCHMARKS.md section 0.1, session 17).
    """
    out = np.zeros(n_charts, dtype=np.int64)
    k = len(order)
    for p in range(k):
        i = order[p]
        for q in range(p + 1, k):
            j = order[q]
            if chart[j] != chart[i] or low[j, 0] > high[i, 0]:
                break
            if low[j, 1] > high[i, 1] or low[i, 1] > high[j, 1]:
                continue
            a, b = (i, j) if i < j else (j, i)
            if _segments_cross(P0, P1, B, a, b):
                out[chart[i]] += 1
    return out


@njit(cache=True, nogil=True)
def _orient(px, py, qx, qy, sx, sy):  # pragma: no cover - compiled
    return (qx - px) * (sy - py) - (qy - py) * (sx - px)


@njit(cache=True, nogil=True)
def _segments_cross(P0, P1, B, i, j):  # pragma: no cover - compiled
    """:func:`segparam.quality.segment_pairs_cross` of the one pair ``(i, j)``."""
    if B[i, 0] == B[j, 0] or B[i, 0] == B[j, 1] or B[i, 1] == B[j, 0] or B[i, 1] == B[j, 1]:
        return False
    ax, ay, bx, by = P0[i, 0], P0[i, 1], P1[i, 0], P1[i, 1]
    cx, cy, dx, dy = P0[j, 0], P0[j, 1], P1[j, 0], P1[j, 1]
    d1, d2 = _orient(cx, cy, dx, dy, ax, ay), _orient(cx, cy, dx, dy, bx, by)
    d3, d4 = _orient(ax, ay, bx, by, cx, cy), _orient(ax, ay, bx, by, dx, dy)
    if not (d1 * d2 <= 0 and d3 * d4 <= 0):
        return False
    if d1 == 0 and d2 == 0:  # collinear: they meet if their projections on the line overlap
        tx, ty = bx - ax, by - ay
        pa, pb = ax * tx + ay * ty, bx * tx + by * ty
        pc, pd = cx * tx + cy * ty, dx * tx + dy * ty
        # np.minimum / np.maximum: NaN propagates as in the array form
        lo = np.maximum(np.minimum(pa, pb), np.minimum(pc, pd))
        return lo <= np.minimum(np.maximum(pa, pb), np.maximum(pc, pd))
    return True


def _charts_loops_oriented(
    uv: np.ndarray, B: np.ndarray, vert_chart: np.ndarray, n_charts: int
) -> np.ndarray:
    """Per chart: its largest uv boundary loop counter-clockwise, all others clockwise.

    Loops are the pieces of the boundary graph (:func:`segparam.topology.boundary_pieces`); a
    loop's signed area is the shoelace sum over its directed edges, in any order (needs a
    manifold boundary, as :func:`segparam.mesh.boundary_loops` does).
    """
    out = np.zeros(n_charts, dtype=bool)
    if len(B) == 0:
        return out
    verts, idx, n_loops, loop = boundary_pieces(B, len(uv))
    p, q = uv[B[:, 0]], uv[B[:, 1]]
    area = 0.5 * np.bincount(
        loop[idx[:, 0]], weights=p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0], minlength=n_loops
    )
    loop_chart = np.empty(n_loops, dtype=np.int64)
    loop_chart[loop] = vert_chart[verts]
    order = np.lexsort((-np.abs(area), loop_chart))
    first = np.r_[True, loop_chart[order][1:] != loop_chart[order][:-1]]
    outer = np.zeros(n_loops, dtype=bool)
    outer[order[first]] = True
    wrong = np.where(outer, ~(area > 0), ~(area < 0))
    bad = np.bincount(loop_chart, weights=wrong, minlength=n_charts)
    has = np.bincount(loop_chart, minlength=n_charts) > 0
    return has & (bad == 0)


def _charts_distortion(
    V: np.ndarray,
    F: np.ndarray,
    uv: np.ndarray,
    vert_chart: np.ndarray,
    n_charts: int,
    inv_frames: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """:func:`segparam.quality.distortion` of every chart (each scaled to its own 3-D area)."""
    face_chart = vert_chart[F[:, 0]]
    area3 = face_areas(V, F)
    total3 = _chart_sum(face_chart, area3, n_charts)
    total_uv = _chart_sum(face_chart, np.abs(signed_areas(uv, F)), n_charts)
    scale = np.sqrt(np.divide(total3, total_uv, out=np.ones(n_charts), where=total_uv > 0))
    s1, s2 = singular_values(jacobians(V, F, uv * scale[vert_chart][:, None], inv_frames))
    w = area3 / total3[face_chart]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv1, inv2 = 1.0 / s1, 1.0 / s2
        return {
            "l2_stretch": np.sqrt(_chart_sum(face_chart, w * (inv1**2 + inv2**2) / 2, n_charts)),
            "linf_stretch": _chart_max(face_chart, inv2, n_charts),
            "angle_distortion": _chart_sum(face_chart, w * (s1 / s2), n_charts),
            "area_distortion": _chart_sum(face_chart, w * np.abs(np.log(s1 * s2)), n_charts),
            "symmetric_dirichlet": _chart_sum(
                face_chart, w * (s1**2 + s2**2 + inv1**2 + inv2**2), n_charts
            ),
        }


_QUALITY_FIELDS = (
    "n_flipped",
    "n_degenerate",
    "n_branch",
    "n_crossings",
    "loops_oriented",
    "bijective",
    "l2_stretch",
    "linf_stretch",
    "angle_distortion",
    "area_distortion",
    "symmetric_dirichlet",
)


def quality_records(q: dict[str, np.ndarray], charts: np.ndarray | None = None) -> list:
    """:class:`segparam.quality.ChartQuality` objects (plain Python numbers) from
    :func:`charts_quality`'s arrays, for the given charts (all by default)."""
    cols = [q[name] if charts is None else q[name][charts] for name in _QUALITY_FIELDS]
    return [ChartQuality(*row) for row in zip(*(c.tolist() for c in cols), strict=True)]


def _block_eigenmaps(
    K: sp.csr_matrix, vstart: np.ndarray, size: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`hessian_eigenmap` of every diagonal block of a block-diagonal ``K``.

    Block ``c`` is rows ``vstart[c] .. vstart[c] + size[c]``. Blocks of one size are assembled
    together and each solved by a dense ``eigh`` of its three smallest pairs (each is at most
    ``DENSE_LIMIT`` rows, where :func:`segparam.linalg.smallest_eigenpairs` is dense too, with
    the same LAPACK driver), on one BLAS thread.

    Returns
    -------
    Y : (n, 2) float64 ndarray
        Each block's two coordinates, orthonormal and orthogonal to 1.
    values : (c, 3) float64 ndarray
        Each block's three smallest eigenvalues.
    """
    n_charts = len(size)
    chart = np.repeat(np.arange(n_charts), size)
    C = K.tocoo()
    r, c, v = C.row, C.col, C.data
    Y = np.zeros((K.shape[0], 2))
    values = np.zeros((n_charts, 3))
    entry_size = size[chart[r]]
    by_size = np.argsort(entry_size, kind="stable")
    sizes, first = np.unique(entry_size[by_size], return_index=True)
    bounds = np.r_[first, len(by_size)]
    with one_blas_thread():
        for k, s in enumerate(sizes):  # one batch per block size, not per block
            e = by_size[bounds[k] : bounds[k + 1]]
            charts = np.flatnonzero(size == s)
            slot = np.empty(n_charts, dtype=np.int64)
            slot[charts] = np.arange(len(charts))
            step = max(1, BLOCK_ENTRIES // (s * s))
            for lo in range(0, len(charts), step):
                part = charts[lo : lo + step]
                sel = e[(slot[chart[r[e]]] >= lo) & (slot[chart[r[e]]] < lo + step)]
                A = np.zeros((len(part), s, s))
                g = slot[chart[r[sel]]] - lo
                A[g, r[sel] - vstart[chart[r[sel]]], c[sel] - vstart[chart[r[sel]]]] = v[sel]
                # the three smallest pairs only, as `smallest_eigenpairs` takes them (LAPACK's
                # MRRR on a subset: 3-4x faster than a full eigh at 130-330 rows), block by block
                lam = np.empty((len(part), 3))
                vec = np.empty((len(part), s, 3))
                for b in range(len(part)):  # loop over the blocks of one batch
                    lam[b], vec[b] = lowest_pairs(A[b], 3)
                vec = _select(vec, lambda b, A=A: lowest_pairs(A[b], 4)[1])
                U = _coordinates(vec)
                rows = vstart[part][:, None] + np.arange(s)
                Y[rows] = U
                values[part] = lam[:, :3]
    return Y, values


def _isometric_fit_charts(
    V: np.ndarray,
    F: np.ndarray,
    Y: np.ndarray,
    inv_frames: np.ndarray,
    vert_chart: np.ndarray,
    n_charts: int,
) -> np.ndarray:
    """:func:`isometric_fit` of every chart: one 3 x 3 least-squares problem per chart."""
    face_chart = vert_chart[F[:, 0]]
    design, w = _metric_design(V, F, Y, inv_frames)
    lhs = _chart_sum(face_chart, np.einsum("m,mij,mik->mjk", w, design, design), n_charts)
    rhs = _chart_sum(face_chart, np.einsum("m,mij,i->mj", w, design, [1.0, 1.0, 0.0]), n_charts)
    m11, m12, m22 = np.linalg.solve(lhs, rhs[:, :, None])[:, :, 0].T
    vals, vecs = np.linalg.eigh(np.stack([np.stack([m11, m12], 1), np.stack([m12, m22], 1)], 1))
    vals = np.maximum(vals, 1e-12 * np.maximum(vals.max(axis=1, keepdims=True), 1e-300))
    A = (vecs * np.sqrt(vals)[:, None, :]) @ vecs.transpose(0, 2, 1)
    return np.einsum("nk,nkl->nl", Y, A[vert_chart])


def _arap_charts(
    V: np.ndarray,
    F: np.ndarray,
    uv: np.ndarray,
    vert_chart: np.ndarray,
    vstart: np.ndarray,
    n_charts: int,
    *,
    iterations: int = 10,
    tol: float = ARAP_TOL,
    min_decrease: float = ARAP_MIN_DECREASE,
    inv_frames: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_arap` of every chart: one factorization of the block-diagonal Poisson matrix.

    Every chart stops on its own rule (see :func:`arap_refine`) and keeps its map from then on;
    the others go on. Returns the maps and every chart's number of global steps.
    """
    face_chart = vert_chart[F[:, 0]]
    frames = inverse_frames(triangle_frames(V, F)) if inv_frames is None else inv_frames
    coef = _gradient_coefficients(frames)  # the rows of the gradient operator D, per face
    all_faces = np.arange(len(F))
    area = face_areas(V, F)
    w_total = _chart_sum(face_chart, area, n_charts)
    free = np.ones(len(V), dtype=bool)
    free[vstart] = False  # every chart's first vertex is pinned
    solve = None
    uv = uv - uv[vstart][vert_chart]
    previous = np.full(n_charts, np.inf)
    active = np.ones(n_charts, dtype=bool)
    steps = np.zeros(n_charts, dtype=np.int64)
    for step in range(iterations + 1):
        Rt, energy, flipped = _arap_local(F, coef, uv, area, face_chart, n_charts)
        energy /= w_total
        stop = (
            (step == iterations)
            | ((energy < tol) & ~flipped)
            | (previous - energy < min_decrease * previous)
        )
        done = active & stop
        steps[done] = step
        active &= ~stop
        if not active.any():
            break
        previous = np.where(active, energy, previous)
        if solve is None:  # the Poisson matrix D^T diag(area, twice) D over the free vertices
            rank = np.where(free, np.cumsum(free) - 1, -1)
            solve = spd_solver_entries(*poisson_entries(F, coef, area, rank), int(free.sum()))
        rhs = gradient_transpose(F, all_faces, coef, area[:, None, None] * Rt, len(V))
        new = np.zeros_like(uv)
        new[free] = solve(rhs[free])
        move = active[vert_chart]
        uv[move] = new[move]
    return uv, steps


@njit(cache=True, nogil=True)
def _arap_local(F, coef, uv, area, face_chart, n_charts):  # pragma: no cover - compiled
    """ARAP's local step over every face of a disjoint union (:func:`_arap_charts`): each
    triangle's closest rotation ``R^T`` (rows ``k``) to its Jacobian ``G = D uv`` (``G[t][k, c] =
    J_t[c, k]``), and per chart the area-weighted sum of ``||G - R^T||_F^2`` and whether a
    triangle is flipped (``det G <= 0``).

    The arithmetic of the sparse and array forms it replaced, term by term: ``D @ uv`` row by
    row over the sorted columns from 0.0 (scipy's CSR product, ``refine.gradient_row``),
    ``(p, q) / hypot(p, q)``, each face's four squares summed in order and scaled by its area, the
    faces summed per chart in order (``np.bincount``): the same bits.
    """
    m = len(F)
    Rt = np.empty((m, 2, 2))
    energy = np.zeros(n_charts)
    flipped = np.zeros(n_charts, dtype=np.bool_)
    G = np.empty((2, 2))
    for t in range(m):
        for k in range(2):
            n_c, v0, v1, v2, a0, a1, a2 = gradient_row(F, t, coef, k)
            for c in range(2):
                acc = 0.0 + a0 * uv[v0, c]
                if n_c > 1:
                    acc += a1 * uv[v1, c]
                if n_c > 2:
                    acc += a2 * uv[v2, c]
                G[k, c] = acc
        p = G[0, 0] + G[1, 1]
        q = G[0, 1] - G[1, 0]
        r = np.hypot(p, q)
        if r == 0:
            r = 1.0
        p, q = p / r, q / r
        Rt[t, 0, 0], Rt[t, 0, 1], Rt[t, 1, 0], Rt[t, 1, 1] = p, q, -q, p
        e00, e01, e10, e11 = G[0, 0] - p, G[0, 1] - q, G[1, 0] - (-q), G[1, 1] - p
        e = e00 * e00 + e01 * e01 + e10 * e10 + e11 * e11
        energy[face_chart[t]] += e * area[t]
        if G[0, 0] * G[1, 1] - G[0, 1] * G[1, 0] <= 0:
            flipped[face_chart[t]] = True
    return Rt, energy, flipped


@dataclass(frozen=True)
class ChartMaps:
    """Maps of many charts from :func:`solve_charts`.

    Attributes
    ----------
    uv : (n, 2) float64 ndarray
        Every chart's map, as :attr:`ChartMap.uv` (near-isometric, lower corner at 0).
    quality : dict of (c,) ndarrays
        :func:`charts_quality` of the maps.
    refined : (c,) bool ndarray
        The ARAP refinement was kept.
    eigenvalues : (c, 3) float64 ndarray
    starved : (c,) bool ndarray
        Charts too small for a neighbourhood the solver needs (a vertex that needs more points
        than its chart has, at some extension round): :class:`HessianSolver` raises
        InvalidMeshError on such a chart alone; here its map is meaningless and ``quality``
        says it is not bijective.
    """

    uv: np.ndarray
    quality: dict
    refined: np.ndarray
    eigenvalues: np.ndarray
    starved: np.ndarray


def _refine_charts(
    Vn, F, uv, vert_chart, vstart, n_faces, frames, refine, refine_iterations, angle_weight,
    slim_below,
):  # fmt: skip
    """:func:`_refine_map` of every chart of a disjoint union (:func:`solve_charts`' layout), all
    at once: returns (uv, quality, refined)."""
    n_charts = len(vstart)
    use_r = np.zeros(n_charts, dtype=bool)
    if refine in ("arap", "slim"):
        uv_r, steps = _arap_charts(
            Vn, F, uv, vert_chart, vstart, n_charts, iterations=refine_iterations,
            inv_frames=frames,
        )  # fmt: skip
    if refine in ("arap", "slim") and steps.any():
        q_r = charts_quality(Vn, F, uv_r, vert_chart, n_charts, frames)
        # The starting map's quality only matters where ARAP's map is not bijective (usually
        # no chart): measured there alone, chart by chart the same figures.
        use_r = (steps > 0) & q_r["bijective"]
        q = _some_charts_quality(Vn, F, uv, vert_chart, vstart, n_faces, frames, ~use_r, q_r)
        use_r |= (steps > 0) & ~q["bijective"] & (q_r["n_flipped"] < q["n_flipped"])
        q = {k: np.where(use_r, q_r[k], q[k]) for k in q}
        uv = np.where(use_r[vert_chart][:, None], uv_r, uv)
    else:
        q = charts_quality(Vn, F, uv, vert_chart, n_charts, frames)
    if refine == "slim":
        go = (q["n_flipped"] == 0) & (q["n_degenerate"] == 0)  # others: energy infinite
        if slim_below is not None:
            go &= q["l2_stretch"] <= slim_below
        uv_s, moved = slim_refine(
            Vn, F, uv, vert_chart=vert_chart, n_charts=n_charts, inv_frames=frames, charts=go,
            angle_weight=angle_weight,
        )  # fmt: skip
        if moved.any():
            q_s = charts_quality(Vn, F, uv_s, vert_chart, n_charts, frames)
            use_s = (
                (moved > 0)
                & q_s["bijective"]
                & (
                    (n_faces >= SMALL_CHART_FACES)
                    | (q_s["l2_stretch"] <= q["l2_stretch"] + MAX_STRETCH_INCREASE)
                )
            )
            q = {k: np.where(use_s, q_s[k], q[k]) for k in q}
            uv = np.where(use_s[vert_chart][:, None], uv_s, uv)
            use_r |= use_s
    return uv, q, use_r


def _sub_union(F, vstart, size, fstart, n_faces, charts):
    """Some charts of a :func:`solve_charts` union (``charts``: their positions, a chart twice
    gives two copies) as a union of their own: ``(verts, faces, F_sub, vert_chart, sub_vstart)``,
    the union's vertex and face of each of its vertices and faces, its faces in its own
    indices, each vertex's chart (position in ``charts``) and each chart's first vertex."""
    verts = np.concatenate([np.arange(vstart[c], vstart[c] + size[c]) for c in charts])
    faces = np.concatenate([np.arange(fstart[c], fstart[c] + n_faces[c]) for c in charts])
    sub_vstart = np.r_[0, np.cumsum(size[charts])[:-1]]
    F_sub = F[faces] - np.repeat(vstart[charts] - sub_vstart, n_faces[charts])[:, None]
    vert_chart = np.repeat(np.arange(len(charts)), size[charts])
    return verts, faces, F_sub, vert_chart, sub_vstart


def _some_charts_quality(Vn, F, uv, vert_chart, vstart, n_faces, frames, which, like):
    """:func:`charts_quality` of the charts ``which`` (a boolean mask) of a :func:`solve_charts`
    union, measured on those charts alone; the other charts' entries are ``like``'s."""
    if which.all():
        return charts_quality(Vn, F, uv, vert_chart, len(vstart), frames)
    out = {k: v.copy() for k, v in like.items()}
    todo = np.flatnonzero(which)
    if len(todo) == 0:
        return out
    size = np.diff(np.r_[vstart, len(Vn)])
    fstart = np.r_[0, np.cumsum(n_faces)[:-1]]
    verts, faces, F_sub, vc, _ = _sub_union(F, vstart, size, fstart, n_faces, todo)
    some = charts_quality(Vn[verts], F_sub, uv[verts], vc, len(todo), frames[faces])
    for k in out:
        out[k][todo] = some[k]
    return out


def _fallback_pairs(Vn, F, K, vstart, fstart, frames, uv, q, refined, starved, args):
    """``FALLBACK_PAIRS`` for the charts of a :func:`solve_charts` union that are still not
    bijective (and not starved), as :meth:`HessianSolver.solve` tries them on one chart: each
    chart's start maps from its next eigenvector pairs (:func:`_other_pairs`, one small dense
    problem per chart), all of them refined together; each chart keeps the map of its first
    pair that ends bijective: ``uv``, ``q`` and ``refined`` are updated in place."""
    fail = np.flatnonzero(~q["bijective"] & ~starved)
    if len(fail) == 0:
        return
    size = np.diff(np.r_[vstart, len(Vn)])
    n_faces = np.diff(np.r_[fstart, len(F)])
    # Only disks: the other pairs never gave a chart with a hole (the wall around a drilled
    # hole) a bijective map (0 of 13, see FALLBACK_PAIRS).
    fail_faces = np.concatenate([np.arange(fstart[c], fstart[c] + n_faces[c]) for c in fail])
    owner = np.repeat(np.arange(len(fail)), n_faces[fail])
    fail = fail[label_topology(F[fail_faces], owner, len(fail))["loops"] == 1]
    if len(fail) == 0:
        return
    starts = {}
    for c in fail.tolist():  # loop over the few charts left: their next eigenvector pairs
        v_c = slice(vstart[c], vstart[c] + size[c])
        F_c = F[fstart[c] : fstart[c] + n_faces[c]] - vstart[c]
        frames_c = frames[fstart[c] : fstart[c] + n_faces[c]]
        starts[c] = list(_other_pairs(Vn[v_c], F_c, K[v_c, v_c], frames_c))
    refine, refine_iterations, angle_weight, slim_below = args
    limits = None if slim_below is None else np.broadcast_to(slim_below, (len(vstart),))
    # Every pair of every chart refined at once (one pass, not one per pair: a pass over a
    # few small charts costs ~10 ms whatever their size), then each chart keeps its first
    # bijective map, as the pairs tried in turn would give.
    cand = [(c, t) for c in fail.tolist() for t in range(len(starts[c]))]
    if not cand:
        return
    todo = np.array([c for c, _ in cand])
    verts, faces, f_local, vc, first = _sub_union(F, vstart, size, fstart, n_faces, todo)
    n_v = size[todo]
    uv_t, q_t, _ = _refine_charts(
        Vn[verts], f_local, np.concatenate([starts[c][t] for c, t in cand]), vc, first,
        n_faces[todo], frames[faces], refine, refine_iterations, angle_weight,
        None if limits is None else limits[todo],
    )  # fmt: skip
    for k in range(len(cand)):  # loop over the candidates (a few): the first bijective
        c = cand[k][0]
        if not q_t["bijective"][k] or q["bijective"][c]:
            continue
        uv[vstart[c] : vstart[c] + size[c]] = uv_t[first[k] : first[k] + n_v[k]]
        for name in q:
            q[name][c] = q_t[name][k]
        refined[c] = True


def solve_charts(
    V: np.ndarray,
    F: np.ndarray,
    vert_chart: np.ndarray,
    *,
    tangent: str = "normals",
    refine: str = "arap",
    refine_iterations: int = 10,
    angle_weight: float = ANGLE_WEIGHT,
    slim_below: np.ndarray | float | None = None,
) -> ChartMaps:
    """``HessianSolver(V_c, F_c, tangent=tangent).solve(refine=...)`` for every chart ``c`` of a
    disjoint union of small charts, all at once.

    Each chart is centred and scaled to its typical edge as in :class:`HessianSolver`; the
    union's ``K`` (:func:`hessian_matrix`: every neighbourhood stays in its chart) is
    block-diagonal, and so are the eigenproblems (:func:`_block_eigenmaps`), the isometric fits,
    the orientation, the ARAP iterations (:func:`_arap_charts`) and the quality checks
    (:func:`charts_quality`). A chart's map is its own solver's map up to a rigid motion and
    rounding (an eigenbasis is only defined up to a rotation).

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray
        Charts that share no vertex, ordered by chart, every one of which :func:`check_chart`
        accepts, with at most ``DENSE_LIMIT`` vertices. A chart too small for the neighbourhoods
        the solver needs is reported (``ChartMaps.starved``) rather than raising, as
        :class:`HessianSolver` does on it alone; the others' maps do not depend on it.
    vert_chart : (n,) int ndarray
        Chart of every vertex: ``0, 0, ..., 1, 1, ...`` (a chart's vertices are consecutive).
    slim_below : float or (n_charts,) float array_like, optional
        With ``refine="slim"``, a chart whose map before it stretches more than this (L2) is
        not refined (see :meth:`HessianSolver.solve`).

    Returns
    -------
    ChartMaps
    """
    tangent = check_choice("tangent", tangent, TANGENTS)
    refine = check_choice("refine", refine, REFINES)
    refine_iterations = check_int("refine_iterations", refine_iterations, low=0)
    angle_weight = check_number("angle_weight", angle_weight, low=0)
    vert_chart = np.asarray(vert_chart, dtype=np.int64)
    n_charts = int(vert_chart[-1]) + 1
    size = np.bincount(vert_chart, minlength=n_charts)
    vstart = np.r_[0, np.cumsum(size)[:-1]]
    face_chart = vert_chart[F[:, 0]]
    if np.any(np.diff(vert_chart) < 0) or np.any(np.diff(face_chart) < 0):
        raise ValueError("vertices and faces must be ordered by chart")
    n_faces = np.bincount(face_chart, minlength=n_charts)
    fstart = np.r_[0, np.cumsum(n_faces)[:-1]]
    # As HessianSolver, to the last bit: the mean face area summed as numpy sums a chart's
    # areas, the centre as numpy sums rows (one after the other, as bincount does).
    scale = np.sqrt(_segment_means(face_areas(V, F), fstart, n_faces))
    centre = _chart_sum(vert_chart, V, n_charts) / size[:, None]
    Vn = (V - centre[vert_chart]) / scale[vert_chart][:, None]
    K, starved = _hessian_matrix(Vn, F, tangent, MIN_POINTS, MIN_RCOND, room=size[vert_chart])
    starved = np.bincount(vert_chart, weights=starved, minlength=n_charts) > 0
    Y, values = _block_eigenmaps(K, vstart, size)
    frames = inverse_frames(triangle_frames(Vn, F))
    uv = _isometric_fit_charts(Vn, F, Y, frames, vert_chart, n_charts)
    mirror = _chart_sum(face_chart, signed_areas(uv, F), n_charts) < 0  # orient()
    uv[mirror[vert_chart], 0] *= -1.0
    args = (refine, refine_iterations, angle_weight, slim_below)
    uv, q, use_r = _refine_charts(Vn, F, uv, vert_chart, vstart, n_faces, frames, *args)
    if refine != "none":
        _fallback_pairs(Vn, F, K, vstart, fstart, frames, uv, q, use_r, starved, args)
    q["bijective"] = q["bijective"] & ~starved  # no map: HessianSolver would have raised
    low = np.minimum.reduceat(uv, vstart, axis=0)
    uv = (uv - low[vert_chart]) * scale[vert_chart][:, None]
    return ChartMaps(uv=uv, quality=q, refined=use_r, eigenvalues=values, starved=starved)
