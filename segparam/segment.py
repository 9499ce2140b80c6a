"""Segment a mesh into charts by spectral clustering of its face graph.

Faces are nodes; two faces sharing an edge are joined with an affinity that falls with the angle
between their normals (concave creases cost more than convex ones, the "minima rule") and grows with
the length of the shared edge, so the normalized cut prefers short cuts along creases and high
curvature. The number of charts follows the mesh's integrated absolute Gaussian curvature (angle
defect). Large meshes are clustered on a coarse proxy graph (faces grouped into cells by a
multi-source Dijkstra, affinities summed) and the labels are carried back exactly.

Regions fenced in completely by sharp edges (:func:`feature_regions`: the faces of a CAD part) are
clustered separately, each into at least one chart, and fragments are merged only inside their
region, so no chart ever spans a closed feature outline. On the CAD plate of
``benchmarks/bench_atlas.py`` this gives planar charts only (L2 / Linf stretch 1.000 / 1.00, was
1.012 / 5.5); on organic meshes the labels are unchanged.

The clustered charts' borders are then cleaned up on the face graph, inside the feature regions
only: a majority filter removes saw-teeth, and threshold dynamics (diffuse every chart's indicator
near the borders, let each face join the chart that diffuses most into it) round the charts, so
that flattened they fill more of their convex hulls and pack tighter. On eight 100k-face brain-like
surfaces (default pipeline, 1024 texels, padding 2) the two took the mean packing utilization from
0.662 to 0.684, the mean convex-hull fill of the charts from 0.860 to 0.880 and the seam length
by 7%, at 0.27 s (1.5 s at 1M faces).

Afterwards every chart is made a connected, genus-0 surface with at least one boundary loop (a disk,
possibly with holes): fragments are merged into a neighbour and closed or handle-bearing pieces are
bisected along their Fiedler vector until they are disks.

Many small components cost no more than one big one: a component that is one chart by the
chart-count rule is not clustered, every chart is tested for being a disk at once
(:func:`segparam.mesh.disk_labels`), and charts of at most ``TINY_PART_FACES`` faces that are not
disks (small closed parts) are halved in bulk, by geometry (:func:`_halve_tiny`). 2,000 disjoint
triangles took 1.9 s, 300 small spheres 2.7 s; now 0.01 s and 0.1 s. The spectral embedding is
computed here (the labels of scikit-learn's ``SpectralClustering`` with ``cluster_qr``, without
importing it, which took 1.2 s of a fresh process) on a Cholesky factorization.
"""

from __future__ import annotations

import logging
from contextlib import nullcontext
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit
from scipy.sparse.csgraph import connected_components as _cc
from scipy.sparse.csgraph import dijkstra
from scipy.special import ive

from .errors import check_int, check_number
from .linalg import DENSE_LIMIT, lowest_pairs, one_blas_thread, smallest_eigenpairs, spd_solver
from .mesh import (
    check_mesh,
    corner_angles,
    curvature_shares,
    disk_labels,
    edges,
    face_adjacency,
    face_normals,
    interior_defect,
    is_disk,
    is_edge_manifold,
    mesh_arrays,
    unit_frame,
)

log = logging.getLogger(__name__)

__all__ = [
    "SegmentConfig",
    "Segmentation",
    "face_affinity",
    "divide",
    "divide_many",
    "fiedler_bisect",
    "integrated_curvature",
    "segment",
]


#: Smallest affinity factor of an edge (see :func:`face_affinity`).
AFFINITY_FLOOR = 0.05
#: Charts of at most this many faces that are not disks (a small closed part: a bead, a bolt, a
#: sphere of 80 or 320 faces) are cut in bulk, all at once, by a plane through their centroid
#: across their principal axis (see :func:`_halve_tiny`), not one Fiedler solve each: on 300
#: spheres of 80 faces the Fiedler loop took 2.7 s, mostly per-call overhead. A closed region
#: this small whose share of the chart count is at most 2 is not clustered either: halving it
#: gives its two charts. On 4 sets each of 150 spheres of 80 faces and 60 of 320, the atlases
#: matched the old ones (utilization 0.702 / 0.710 against 0.698 / 0.710, angle distortion
#: 1.201 / 1.141 against 1.201 / 1.141, seams -0.5% / +0.8%). Larger charts keep the Fiedler
#: cut, which follows the creases.
TINY_PART_FACES = 400
#: Shift of the shift-invert Lanczos iteration of the spectral embedding (scikit-learn's
#: choice: just below the Laplacian's zero eigenvalue, so ``L - sigma I`` is positive definite).
SPECTRAL_SHIFT = -1e-5
#: Relative accuracy of the spectral embedding's eigenpairs (ARPACK ``tol``; 0 is machine
#: precision). The labels only need the span of the eigenvectors to this accuracy: on the sample
#: brain, three 20k-face brain-like surfaces and a 100k one's proxy graph, for 7, 12 and 20
#: clusters, 1e-6 gives the same labels as 0 with 20-45% fewer solves.
SPECTRAL_TOL = 1e-6
#: Relative accuracy of the Fiedler vector's eigenvalue (ARPACK ``tol``) when a chart of more
#: than ``DENSE_LIMIT`` faces is bisected (:func:`_fiedler_vector`). Only the order of the
#: vector's entries matters (the median cut): at 1e-10 it agreed with the subspace iteration's
#: (residual 1e-12) to 5e-8 of its largest entry on the pieces measured, the same cuts.
FIEDLER_TOL = 1e-10
#: The spectral embedding's cost grows with the graph's nodes times the clusters asked for
#: (ARPACK keeps ``2 k + 1`` vectors of the graph's size, and each restart solves once per
#: vector), so a region cut into many charts is clustered on a proxy graph of at most
#: ``PROXY_BUDGET / k`` cells (never fewer than ``MIN_CELLS_PER_CHART`` per chart nor more than
#: ``proxy_faces``): a 20k-face region keeps every face up to 16 charts. Measured (default
#: pipeline, machine loaded, one run each; old -> new): the sample brain (111-113 charts) segment
#: 1.94 -> 0.59 s, L2 1.0108 -> 1.0108, angle 1.0467 -> 1.0461, utilization 0.701 -> 0.693, seams
#: 23.68 -> 23.16; the 20k brain bench mesh 0.87 -> 0.59 s, 93 charts both, utilization 0.695 ->
#: 0.706; fsaverage5's cortex 1.60 -> 0.50 s, 68 charts both, L2 1.0092 -> 1.0086, utilization
#: 0.705 -> 0.708; the wavy scan 2.31 -> 0.87 s, 70 -> 68 charts, utilization 0.686 -> 0.676.
#: The utilization moves by about a point either way, as it does between any two chart sets.
PROXY_BUDGET = 320_000
MIN_CELLS_PER_CHART = 100
#: A region is planar when no unit face normal differs from its first face's by more than this
#: (per coordinate; as ``segparam.split.PLANAR_TOL``, which maps such a chart by projection).
PLANAR_TOL = 1e-9
#: Largest ``n_charts`` / ``max_charts`` accepted (the CLI's ``--max-charts`` limit too).
MAX_CHARTS = 1_000_000


@dataclass(frozen=True)
class SegmentConfig:
    """Options of :func:`segment`.

    Attributes
    ----------
    n_charts : int or None
        Fixed number of charts (1 to ``MAX_CHARTS``); default from the curvature.
    curvature_per_chart : float
        Integrated ``|K|`` (radians, > 0) per chart when ``n_charts`` is None: a hemisphere
        carries ``2 pi``.
    max_charts : int
        Upper bound on the number of clustered charts (1 to ``MAX_CHARTS``; the split stage may
        add more).
    max_chart_faces : int
        Clustering makes at least ``faces / max_chart_faces`` charts (keeps each solve fast).
    concave_weight, convex_weight : float
        Scale (> 0) of the angular distance for concave and convex edges.
    proxy_faces : int
        Above this many faces (>= 1), cluster a proxy graph of about this many cells (fewer for
        a region cut into many charts, see ``PROXY_BUDGET``).
    smoothing : int
        Passes of the majority filter that straightens chart borders (0: none).
    rounding : float
        Diffusion time (finite, >= 0), in random-walk steps on the face graph, of the threshold
        dynamics that round the charts after clustering (0: none). Borders are smoothed over about
        ``sqrt(rounding)`` rings of faces: lobes and spurs recede, so the flattened charts fill
        more of their convex hulls and pack tighter. The scale is in faces, so on finer meshes
        it rounds relatively less (and costs no more per face).
    feature_angle : float
        Degrees, in (0, 180]. Edges whose faces' normals differ by more than this are sharp;
        regions that sharp edges enclose completely (the faces of a CAD part) are charted
        separately, never across their outline. 180 turns this off.

    Raises
    ------
    ConfigError
        If a field has the wrong type (an integer where a number is asked is fine, a bool never
        is) or is out of range; the message names the field.
    """

    n_charts: int | None = None
    curvature_per_chart: float = 2 * np.pi
    max_charts: int = 256
    max_chart_faces: int = 20_000
    concave_weight: float = 1.0
    convex_weight: float = 0.2
    proxy_faces: int = 20_000
    smoothing: int = 4
    feature_angle: float = 60.0
    rounding: float = 128.0

    def __post_init__(self) -> None:
        # Every field, type first (bool is not a number here); numbers are stored as plain
        # int / float. Messages start with the key: config_from_dict adds the file and [segment].
        checked = {
            "n_charts": check_int("n_charts", self.n_charts, low=1, high=MAX_CHARTS, optional=True),
            "max_charts": check_int("max_charts", self.max_charts, low=1, high=MAX_CHARTS),
            "max_chart_faces": check_int("max_chart_faces", self.max_chart_faces, low=1),
            "proxy_faces": check_int("proxy_faces", self.proxy_faces, low=1),
            "smoothing": check_int("smoothing", self.smoothing, low=0),
        }
        for name in ("curvature_per_chart", "concave_weight", "convex_weight"):
            checked[name] = check_number(name, getattr(self, name), low=0, low_open=True)
        checked["rounding"] = check_number("rounding", self.rounding, low=0)
        checked["feature_angle"] = check_number(
            "feature_angle", self.feature_angle, low=0, high=180, low_open=True
        )
        for name, value in checked.items():
            object.__setattr__(self, name, value)


@dataclass(frozen=True)
class Segmentation:
    """Charts of a mesh.

    Attributes
    ----------
    labels : (m,) int64 ndarray
        Chart of every face, ``0 .. n_charts - 1``; every chart is a disk (possibly with holes).
    n_charts : int
    target_charts : int
        The number of charts asked of the clustering (from the curvature or the config).
    curvature : float
        Integrated absolute Gaussian curvature (see :func:`integrated_curvature`).
    affinity : (m, m) scipy.sparse.csr_matrix or None
        The face affinity the charts were cut on (:func:`face_affinity` with the config's
        weights). :func:`segparam.split.parameterize_charts` splits failing charts on it, so
        splits follow the same creases and the mesh's affinity is not built twice (1.3 s of
        the 1M-face brain's 36 s); :func:`segparam.pipeline.build_atlas` drops it once the
        charts are mapped.
    copies : int
        Pieces of the mesh cut and mapped as copies of another piece (:mod:`segparam.instances`:
        set by :func:`segparam.pipeline.build_atlas`; 0 from :func:`segment`).
    face_curvature : (m,) float64 ndarray or None
        Each face's share of the Gaussian curvature (:func:`segparam.mesh.curvature_shares`),
        which :func:`segparam.split.parameterize_charts` takes to tell the caps it need not
        solve; dropped with the affinity.
    """

    labels: np.ndarray
    n_charts: int
    target_charts: int
    curvature: float
    affinity: sp.csr_matrix | None = field(default=None, repr=False, compare=False)
    copies: int = 0
    face_curvature: np.ndarray | None = field(default=None, repr=False, compare=False)


def face_affinity(
    V: np.ndarray,
    F: np.ndarray,
    *,
    concave_weight: float = 1.0,
    convex_weight: float = 0.2,
    edge_index: tuple | None = None,
    normals: np.ndarray | None = None,
) -> sp.csr_matrix:
    """Symmetric face-graph affinity: ``w_ij = (l_ij / mean l) max(exp(-d_ij / mean d), floor)``.

    ``d_ij = eta (1 - cos theta_ij)`` with ``theta`` the angle between the two faces' normals and
    ``eta`` the concave or convex weight; ``l_ij`` the length of the shared edge.
    ``edge_index`` is ``edges(F)`` and ``normals`` ``face_normals(V, F)`` when the caller already
    has them.

    Returns
    -------
    W : (m, m) scipy.sparse.csr_matrix
    """
    m = len(F)
    if edge_index is None:
        edge_index = edges(F)
    E, h2e = edge_index
    pairs, edge = face_adjacency(F, edge_index=edge_index)
    if len(pairs) == 0:
        return sp.csr_matrix((m, m))
    N = face_normals(V, F) if normals is None else normals
    i, j = pairs[:, 0], pairs[:, 1]
    d, length = _affinity_terms(
        np.ascontiguousarray(V, dtype=np.float64),
        np.ascontiguousarray(F, dtype=np.int64),
        np.ascontiguousarray(N, dtype=np.float64),
        np.ascontiguousarray(i),
        np.ascontiguousarray(j),
        E[edge, 0],
        E[edge, 1],
        float(concave_weight),
        float(convex_weight),
    )
    # The floor keeps a few faces between two sharp creases from becoming an island that the
    # normalized cut would rather cut off than make a real chart boundary.
    w = (length / length.mean()) * np.maximum(np.exp(-d / max(d.mean(), 1e-12)), AFFINITY_FLOOR)
    W = sp.coo_matrix((np.r_[w, w], (np.r_[i, j], np.r_[j, i])), shape=(m, m)).tocsr()
    W.sum_duplicates()
    return W


@njit(cache=True, nogil=True)
def _affinity_terms(V, F, N, i, j, a, b, concave_weight, convex_weight):  # pragma: no cover
    """:func:`face_affinity`'s angular distance ``d`` and shared-edge length of every face pair
    ``(i, j)`` sharing the edge ``(a, b)``, compiled: one pass over the pairs instead of a
    dozen gathers of (k, 3) arrays (face_affinity 11 -> 6 ms on the sample brain, 0.67 -> 0.30 s
    at 1M faces). The same float64 operations in the same order as the array form (a test
    checks the bits): centroids ``(V[F0] + V[F1] + V[F2]) / 3`` as ``V[F].mean(axis=1)``, dot
    products summed from 0.0 coordinate by coordinate as the row sums of (k, 3) products.

    Returns
    -------
    d, length : (k,) float64 ndarrays
    """
    k = len(i)
    d = np.empty(k)
    length = np.empty(k)
    for q in range(k):
        fi, fj = i[q], j[q]
        dot = 0.0 + N[fi, 0] * N[fj, 0] + N[fi, 1] * N[fj, 1] + N[fi, 2] * N[fj, 2]
        cos = min(max(dot, -1.0), 1.0)
        side = 0.0  # > 0: j's centroid above i's plane, a concave edge
        for c in range(3):
            ci = (V[F[fi, 0], c] + V[F[fi, 1], c] + V[F[fi, 2], c]) / 3
            cj = (V[F[fj, 0], c] + V[F[fj, 1], c] + V[F[fj, 2], c]) / 3
            side += (cj - ci) * N[fi, c]
        d[q] = (concave_weight if side > 0 else convex_weight) * (1.0 - cos)
        e0, e1, e2 = V[a[q], 0] - V[b[q], 0], V[a[q], 1] - V[b[q], 1], V[a[q], 2] - V[b[q], 2]
        length[q] = np.sqrt(0.0 + e0 * e0 + e1 * e1 + e2 * e2)
    return d, length


def integrated_curvature(
    V: np.ndarray,
    F: np.ndarray,
    *,
    passes: int = 2,
    edge_index: tuple | None = None,
    defect: np.ndarray | None = None,
) -> float:
    """Integrated absolute Gaussian curvature, robust to noise: ``sum_v |(S^p K)_v|``.

    ``K`` is the angle defect at interior vertices (a boundary's turning angle is not curvature);
    ``S`` spreads each vertex's defect evenly over its closed 1-ring (column-stochastic, so the
    total signed curvature is kept). Curvature of one sign over a region keeps its integral, while
    scanner noise, whose defects alternate in sign from vertex to vertex, cancels: on a noisy
    36k-face sheet two passes cut the figure from 1361 pi to 135 pi, on a folded 100k-face
    hemisphere from 155 pi to 91 pi, and on a sphere or a CAD part not at all.
    ``edge_index`` is ``edges(F)`` and ``defect`` ``interior_defect(V, F)[0]`` when the caller
    already has them.
    """
    if edge_index is None:
        edge_index = edges(F)
    if defect is None:  # the angle defect of segparam.mesh.angle_defect, zero on the boundary
        defect = interior_defect(V, F, edge_index=edge_index)[0]
    return float(np.abs(_spread(edge_index[0], len(V), defect, passes)).sum())


@njit(cache=True, nogil=True)
def _spread(E, n, K, passes):  # pragma: no cover - compiled
    """``S^passes K`` for :func:`integrated_curvature`'s ``S``: vertex ``i`` receives
    ``K_j / |ring_j|`` from every ``j`` of its closed 1-ring (the vertices of the edges ``E``).

    Compiled (2.8 -> 0.6 ms on the sample brain; integrated_curvature 0.43 -> 0.32 s at 1M
    faces), the same bits as the sparse product ``(A + I) @ diag(1 / colsum) @ K`` it
    replaces: each ring summed from 0.0 in decreasing vertex order, the order in which scipy's
    product ``A @ diag`` leaves each row of ``S``.
    """
    size = np.ones(n, dtype=np.int64)  # closed ring sizes: the column sums of A + I
    for e in range(len(E)):
        size[E[e, 0]] += 1
        size[E[e, 1]] += 1
    start = np.zeros(n + 1, dtype=np.int64)
    for v in range(n):
        start[v + 1] = start[v] + size[v]
    ring = np.empty(start[n], dtype=np.int64)
    fill = start[:-1].copy()
    for v in range(n):
        ring[fill[v]] = v
        fill[v] += 1
    for e in range(len(E)):
        a, b = E[e, 0], E[e, 1]
        ring[fill[a]] = b
        fill[a] += 1
        ring[fill[b]] = a
        fill[b] += 1
    for v in range(n):  # each ring in decreasing order (insertion sort: rings are short)
        for p in range(start[v] + 1, start[v + 1]):
            u, q = ring[p], p
            while q > start[v] and ring[q - 1] < u:
                ring[q] = ring[q - 1]
                q -= 1
            ring[q] = u
    share = 1.0 / size.astype(np.float64)
    for _ in range(passes):
        out = np.empty(n)
        for v in range(n):
            acc = 0.0
            for p in range(start[v], start[v + 1]):
                acc += share[ring[p]] * K[ring[p]]
            out[v] = acc
        K = out
    return K


def fiedler_bisect(W: np.ndarray | sp.spmatrix, *, seed: int = 0) -> np.ndarray:
    """Split a connected graph in two halves by the median of its Fiedler vector.

    Parameters
    ----------
    W : (m, m) sparse matrix
        Symmetric non-negative affinity.

    Returns
    -------
    (m,) bool ndarray
        True for the nodes of one half; both halves are non-empty for ``m >= 2``.
    """
    W = sp.csr_matrix(W)
    m = W.shape[0]
    if m < 2:
        return np.zeros(m, dtype=bool)
    d = np.asarray(W.sum(axis=1)).ravel()
    d_safe = np.where(d > 0, d, 1.0)
    Dm = sp.diags(1 / np.sqrt(d_safe))
    L = sp.identity(m) - Dm @ W @ Dm  # normalized Laplacian
    if m <= 2:
        return np.arange(m) == 0
    return _median_side(_fiedler_vector(L.tocsr(), seed) / np.sqrt(d_safe))


def _fiedler_vector(L: sp.csr_matrix, seed: int) -> np.ndarray:
    """The eigenvector of the second smallest eigenvalue of a connected graph's normalized
    Laplacian ``L`` (the smallest is 0).

    Up to ``DENSE_LIMIT`` nodes a dense ``eigh`` (:func:`segparam.linalg.smallest_eigenpairs`);
    above, ARPACK's Lanczos iteration in shift-invert mode on one Cholesky factorization of
    ``L + I / m``: a mesh graph's second eigenvalue is about ``c / m`` (c of order 1-10), so the
    shift keeps the two wanted eigenvalues apart from the rest after inversion at any size.
    Measured against the subspace iteration of ``smallest_eigenpairs`` (built for the Hessian's
    nearly degenerate null spaces) on the 18 pieces of 412-612 faces the split stage cut on
    ``data/brain.obj``: 0.141 -> 0.061 s in all, and 0.20 -> 0.07 s on face graphs of 3.4k and
    20k nodes, the vectors agreeing to 5e-8 or better. Falls back to the subspace iteration when
    ARPACK does not converge.
    """
    m = L.shape[0]
    if m <= DENSE_LIMIT:
        return smallest_eigenpairs(L, 2, seed=seed)[1][:, 1]
    shift = 1.0 / m
    solve = spd_solver((L + shift * sp.identity(m, format="csr")).tocsc())
    op = spla.LinearOperator((m, m), matvec=solve, dtype=np.float64)
    v0 = np.random.RandomState(seed).uniform(-1, 1, m)
    try:
        values, vectors = spla.eigsh(
            L, k=2, sigma=-shift, which="LM", OPinv=op, tol=FIEDLER_TOL, v0=v0
        )
    except spla.ArpackNoConvergence:
        return smallest_eigenpairs(L, 2, seed=seed)[1][:, 1]
    return vectors[:, np.argmax(values)]


def _median_side(f: np.ndarray) -> np.ndarray:
    """The nodes below the median of a Fiedler vector ``f`` (``len(f) // 2`` of them, ties by
    index). An eigenvector's sign is arbitrary (each eigensolver, and each LAPACK build, picks
    its own), and with an odd count it decides which half gets the middle node: ``f`` is
    first turned so that its entry of largest magnitude is positive, so the halves are the
    same whatever the solver."""
    if f[np.argmax(np.abs(f))] < 0:
        f = -f
    side = np.zeros(len(f), dtype=bool)
    side[np.argsort(f, kind="stable")[: len(f) // 2]] = True
    return side


def divide(
    W: sp.spmatrix, faces: np.ndarray, *, seed: int = 0, straighten: tuple[int, int] | None = None
) -> list[np.ndarray]:
    """Cut a set of faces in pieces: its connected components if it has several, else the two
    halves of :func:`fiedler_bisect` (either half may itself fall apart).

    Parameters
    ----------
    W : (m, m) sparse matrix
        Face affinity of the whole mesh.
    faces : (k,) int ndarray
        The faces to cut, ``k >= 2``.
    straighten : (min_faces, passes), optional
        A set of at least ``min_faces`` faces gets its two halves' border straightened by
        ``passes`` of the segmentation's majority filter (:func:`_straightened`).

    Returns
    -------
    list of int ndarray
        Disjoint subsets of `faces` covering it.
    """
    sub = W[faces][:, faces]
    n_comp, comp = _cc(sub, directed=False)
    if n_comp > 1:
        return [faces[comp == k] for k in range(n_comp)]
    side = fiedler_bisect(sub, seed=seed)
    if straighten is not None and len(faces) >= straighten[0]:
        side = _straightened(_neighbor_table(sp.csr_matrix(sub))[0], side, straighten[1])
    return [faces[side], faces[~side]]


def _straightened(nbr: np.ndarray, side: np.ndarray, passes: int) -> np.ndarray:
    """A bisection's sides (``side``, over the nodes of the neighbour table ``nbr``) after
    ``passes`` of the majority filter that smooths the segmentation's borders
    (:func:`_majority_passes`): the median of a Fiedler vector cuts through a band of faces and
    leaves one-face teeth along the cut. Kept only if both sides keep faces. Each node's
    neighbours are taken in descending order (the filter lets the first three vote), so the
    sides do not depend on how the caller's sparse matrix ordered them."""
    nbr = -np.sort(-nbr, axis=1)  # -1 (no neighbour) last
    labels = _majority_passes(nbr, side.astype(np.int64), passes)
    return labels.astype(bool) if 0 < labels.sum() < len(labels) else side


def divide_many(
    W: sp.spmatrix,
    groups: list[np.ndarray],
    *,
    seed: int = 0,
    straighten: tuple[int, int] | None = None,
) -> list[list[np.ndarray]]:
    """:func:`divide` of every face set in ``groups`` (each of 2+ faces, disjoint), the small
    ones (up to ``DENSE_LIMIT`` faces) at once: one restriction of ``W``, one
    connected-components pass, then a dense eigenproblem per group. The split stage cuts many
    small pieces per round (the 600 halves of 300 small spheres): one :func:`divide` each cost
    1.6 ms, mostly sparse-matrix overhead. Same pieces as :func:`divide`, in the same order
    (``straighten`` as there).
    """
    out: list[list[np.ndarray] | None] = [None] * len(groups)
    small = [i for i, g in enumerate(groups) if len(g) <= DENSE_LIMIT]
    for i in sorted(set(range(len(groups))) - set(small)):  # loop over the few large ones
        out[i] = divide(W, groups[i], seed=seed, straighten=straighten)
    if small:
        sizes = np.array([len(groups[i]) for i in small])
        bounds = np.r_[0, np.cumsum(sizes)]
        gid = np.repeat(np.arange(len(small)), sizes)
        every = np.concatenate([groups[i] for i in small])
        sub = W[every][:, every].tocoo()
        keep = gid[sub.row] == gid[sub.col]  # no edge between two groups
        sub = sp.csr_matrix(
            (sub.data[keep], (sub.row[keep], sub.col[keep])), shape=(len(every), len(every))
        )
        _, comp = _cc(sub, directed=False)
        # the groups in pieces, all at once (np.any per group: 16 ms for 1,200 sphere pieces)
        apart = np.minimum.reduceat(comp, bounds[:-1]) != np.maximum.reduceat(comp, bounds[:-1])
        d = np.asarray(sub.sum(axis=1)).ravel()
        # each group's rows of `sub` hold its entries only: its dense block is read off them,
        # without a sparse slice per group (0.1 ms each; 600 sphere halves: 0.09 s)
        row = np.repeat(np.arange(len(every)), np.diff(sub.indptr))
        nbr = None if straighten is None else _neighbor_table(sub)[0]  # within groups only
        with one_blas_thread():
            for j, i in enumerate(small):  # loop over small groups: one dense eigh each
                a, b = int(bounds[j]), int(bounds[j + 1])
                faces, c = groups[i], comp[a:b]
                if apart[j]:  # components, numbered as connected_components numbers them
                    labels, first = np.unique(c, return_index=True)
                    out[i] = [faces[c == k] for k in labels[np.argsort(first)]]
                    continue
                block = np.zeros((b - a, b - a))
                e = slice(sub.indptr[a], sub.indptr[b])
                block[row[e] - a, sub.indices[e] - a] = sub.data[e]
                side = _half_side(block, d[a:b])
                if straighten is not None and b - a >= straighten[0]:
                    local = np.where(nbr[a:b] >= 0, nbr[a:b] - a, -1)
                    side = _straightened(local, side, straighten[1])
                out[i] = [faces[side], faces[~side]]
    return out  # type: ignore[return-value]


def _half_side(Wg: np.ndarray, d: np.ndarray) -> np.ndarray:
    """:func:`fiedler_bisect`'s side of a small connected set (its dense affinity ``Wg``, row
    sums ``d``): the same normalized Laplacian, entry for entry."""
    m = len(d)
    if m <= 2:
        return np.arange(m) == 0
    d_safe = np.where(d > 0, d, 1.0)
    dm = 1 / np.sqrt(d_safe)
    L = np.eye(m) - (dm[:, None] * Wg) * dm[None, :]
    return _median_side(lowest_pairs(L, 2)[1][:, 1] / np.sqrt(d_safe))


def _proxy_cells(W: sp.csr_matrix, n_cells: int, seed: int) -> np.ndarray:
    """Group graph nodes into ``n_cells`` connected cells: Voronoi cells of random seed nodes."""
    m = W.shape[0]
    rng = np.random.default_rng(seed)
    seeds = np.sort(rng.choice(m, size=min(n_cells, m), replace=False))
    D = W.copy()
    D.data = 1.0 / np.maximum(D.data, 1e-12)  # strong affinity = short distance
    _, _, source = dijkstra(D, indices=seeds, min_only=True, return_predecessors=True)
    rank = np.zeros(m, dtype=np.int64)  # the cell of every seed: its rank among the seeds
    rank[seeds] = np.arange(len(seeds))
    cell = rank[np.maximum(source, 0)]
    unreached = source < 0  # another component without a seed: its own cells
    if unreached.any():
        _, comp = _cc(W[unreached][:, unreached], directed=False)
        cell[unreached] = len(seeds) + comp
    return _compact(cell)


def _spectral_embedding(W: sp.csr_matrix, k: int, seed: int) -> np.ndarray:
    """The ``k`` smallest eigenvectors of the normalized Laplacian, divided by ``sqrt(degree)``.

    The embedding of scikit-learn's ``spectral_embedding`` (``norm_laplacian=True``,
    ``drop_first=False``, ARPACK in shift-invert mode at ``SPECTRAL_SHIFT`` from the same start
    vector), with the shifted Laplacian factorized once by :func:`segparam.linalg.spd_solver`
    (CHOLMOD's Cholesky instead of SuperLU's LU), and dense ``eigh`` for graphs of at most
    ``DENSE_LIMIT`` nodes. Only the span matters to :func:`_cluster_qr`.

    Returns
    -------
    (m, k) float ndarray
    """
    m = W.shape[0]
    d = np.asarray(W.sum(axis=1)).ravel()
    dd = np.sqrt(np.where(d > 0, d, 1.0))
    Dm = sp.diags(1.0 / dd)
    L = (sp.identity(m, format="csr") - Dm @ W @ Dm).tocsr()
    L.setdiag(1.0)
    if m <= DENSE_LIMIT:
        vectors = scipy.linalg.eigh(L.toarray(), subset_by_index=[0, k - 1])[1]
    else:
        solve = spd_solver((L - SPECTRAL_SHIFT * sp.identity(m, format="csr")).tocsc())
        op = spla.LinearOperator((m, m), matvec=solve, dtype=np.float64)
        v0 = np.random.RandomState(seed).uniform(-1, 1, m)  # scikit-learn's start vector
        vectors = spla.eigsh(
            L, k=k, sigma=SPECTRAL_SHIFT, which="LM", OPinv=op, tol=SPECTRAL_TOL, v0=v0
        )[1]
    return vectors / dd[:, None]


def _cluster_qr(vectors: np.ndarray) -> np.ndarray:
    """Damle, Minden and Ying's CPQR clustering of a spectral embedding (scikit-learn's
    ``cluster_qr``): the same labels for any orthonormal basis of the embedding's span."""
    k = vectors.shape[1]
    piv = scipy.linalg.qr(vectors.T, pivoting=True)[2]
    ut, _, v = scipy.linalg.svd(vectors[piv[:k], :].T)
    return np.abs(vectors @ (ut @ v)).argmax(axis=1)


def _cluster(W: sp.csr_matrix, k: int, seed: int) -> np.ndarray:
    """Spectral clustering of one connected graph into ``k`` clusters.

    The labels of scikit-learn's ``SpectralClustering(affinity="precomputed",
    assign_labels="cluster_qr", eigen_solver="arpack")`` (the same on the brain and brain-like
    surfaces, where the eigenvalues are distinct; with a repeated eigenvalue, a sphere's, any
    basis of its eigenspace is as good), without importing scikit-learn (1.2 s, the better part
    of segmenting a 20k-face mesh from a fresh process) and with a Cholesky factorization.
    """
    m = W.shape[0]
    if k <= 1 or m <= k:
        return np.arange(m) if m <= k else np.zeros(m, dtype=np.int64)
    return _cluster_qr(_spectral_embedding(W, k, seed)).astype(np.int64)


def _smooth_boundaries(nbr: np.ndarray, labels: np.ndarray, passes: int) -> np.ndarray:
    """Majority filter on chart labels: a face whose edge neighbours mostly belong to one other
    chart joins it. Clustering on faces leaves saw-tooth chart borders; straighter borders mean
    shorter seams and charts that pack tighter.

    Parameters
    ----------
    nbr : (m, w) int64 ndarray
        Neighbours of every face, -1 in unused slots (see :func:`_neighbor_table`).
    labels : (m,) int64 ndarray
    passes : int
        Most passes; stops early at a fixed point.

    Returns
    -------
    (m,) int64 ndarray
    """
    return _majority_passes(nbr, np.asarray(labels, dtype=np.int64), passes)


@njit(cache=True, nogil=True)
def _majority_passes(nbr, labels, passes):  # pragma: no cover - compiled
    """:func:`_smooth_boundaries`' passes, compiled (both calls of a segmentation: the sample
    brain 8.2 -> 1.7 ms, 1M faces 0.64 -> 0.09 s; the same labels as the array form it
    replaced, a test checks).

    Each pass updates all faces at once from the labels before it: a face joins the chart of
    the first of its neighbour pairs (slots 0-1, 0-2, 1-2) that agree on another chart. Two
    neighbours that would trade labels (each one an ear of the other's chart) would swap back
    and forth forever under simultaneous updates: only the lower index moves. Without this,
    4 passes left 80% of the ears of the 100k brain in place.
    """
    m, width = nbr.shape
    votes = min(width, 3)
    labels = labels.copy()
    new = np.empty_like(labels)
    stay = np.zeros(m, dtype=np.bool_)
    for _ in range(passes):
        for i in range(m):
            own = labels[i]
            new[i] = own
            for a in range(votes):
                for b in range(a + 1, votes):
                    ga, gb = nbr[i, a], nbr[i, b]
                    if new[i] == own and ga >= 0 and gb >= 0:
                        if labels[ga] == labels[gb] and labels[ga] != own:
                            new[i] = labels[ga]
        for i in range(m):  # the higher index of a trading pair keeps its label
            stay[i] = False
            if new[i] != labels[i]:
                for s in range(width):
                    g = nbr[i, s]
                    if 0 <= g < i and labels[g] == new[i] and new[g] == labels[i]:
                        stay[i] = True
        changed = False
        for i in range(m):
            if stay[i]:
                new[i] = labels[i]
            changed |= new[i] != labels[i]
        if not changed:
            break
        labels, new = new, labels
    return labels


def _neighbor_table(W: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    """Padded neighbour table of a graph and its random-walk transition probabilities.

    Returns
    -------
    nbr : (m, w) int64 ndarray
        Neighbours of every node, -1 in unused slots (``w``: the largest degree).
    P : (m, w) float ndarray
        ``W[i, nbr[i, s]] / sum_j W[i, j]``, 0 in unused slots.
    """
    m = W.shape[0]
    deg = np.diff(W.indptr)
    width = int(deg.max()) if m else 0
    if m and (deg == width).all():  # a closed manifold: every face has three neighbours
        nbr = W.indices.astype(np.int64).reshape(m, width)
        wgt = W.data.reshape(m, width)
    else:
        slot = np.arange(len(W.indices)) - np.repeat(W.indptr[:-1], deg)
        rows = np.repeat(np.arange(m), deg)
        nbr = np.full((m, width), -1, dtype=np.int64)
        wgt = np.zeros((m, width))
        nbr[rows, slot] = W.indices
        wgt[rows, slot] = W.data
    d = wgt.sum(axis=1, keepdims=True)
    return nbr, wgt / np.where(d > 0, d, 1.0)


@njit(cache=True, nogil=True)
def _band(nbr, labels, n_labels, rings):  # pragma: no cover - compiled
    """The pairs (face ``f``, chart ``k``) with ``f`` within ``rings`` rings of the border of
    chart ``k`` (on either side; ring 0 is the faces that touch it), and how they neighbour.

    A breadth-first search per chart, chart after chart, from its ring 0: the faces of the
    chart that touch another chart and the faces of other charts that touch it. Compiled:
    the same pairs as rings of sorted keys grown with ``np.unique`` and ``np.isin`` (and a
    ``searchsorted`` of every pair's neighbours among them), 0.044 -> 0.005 s on the sample
    brain (98k pairs), 0.76 -> 0.30 s at 1M faces (1.2M pairs).

    Parameters
    ----------
    nbr : (m, w) int64 ndarray
        Neighbours of every face, -1 in unused slots (symmetric: see :func:`_neighbor_table`).
    labels : (m,) int64 ndarray
    n_labels, rings : int

    Returns
    -------
    keys : (n,) int64 ndarray
        ``f * n_labels + k`` of every pair, ascending (by face, then chart).
    col : (n, w) int64 ndarray
        ``col[i, s]``: the pair of face ``nbr[f_i, s]`` and chart ``k_i`` (an index into
        ``keys``), or -1 where that face is not in the band of ``k_i`` (or the slot is unused).
    """
    m, width = nbr.shape
    # Ring 0 of every chart, grouped by chart (a counting sort); a face may be listed twice
    # for a chart, the search takes it once.
    start = np.zeros(n_labels + 1, dtype=np.int64)
    for f in range(m):
        border = False
        for s in range(width):
            g = nbr[f, s]
            if g >= 0 and labels[g] != labels[f]:
                start[labels[g] + 1] += 1
                border = True
        if border:
            start[labels[f] + 1] += 1
    for k in range(n_labels):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    seeds = np.empty(start[n_labels], dtype=np.int64)
    for f in range(m):
        border = False
        for s in range(width):
            g = nbr[f, s]
            if g >= 0 and labels[g] != labels[f]:
                seeds[fill[labels[g]]] = f
                fill[labels[g]] += 1
                border = True
        if border:
            seeds[fill[labels[f]]] = f
            fill[labels[f]] += 1
    # The pairs in search order (chart by chart) and their neighbours in that order; a chart's
    # band has at most m faces, room for which is made before each chart.
    mark = np.full(m, -1, dtype=np.int64)  # mark[f] == k: f is in chart k's band ...
    where = np.empty(m, dtype=np.int64)  # ... as pair where[f]
    face = np.empty(2 * m, dtype=np.int64)
    chart = np.empty(2 * m, dtype=np.int64)
    link = np.empty((2 * m, width), dtype=np.int64)
    n = np.int64(0)  # not a literal 0: _chart_band would be compiled twice (0.23 s more)
    for k in range(n_labels):
        if len(face) < n + m:
            face = np.concatenate((face[:n], np.empty(n + 2 * m, dtype=np.int64)))
            chart = np.concatenate((chart[:n], np.empty(n + 2 * m, dtype=np.int64)))
            link = np.concatenate((link[:n], np.empty((n + 2 * m, width), dtype=np.int64)))
        band = seeds[start[k] : start[k + 1]]
        n = _chart_band(nbr, band, k, rings, mark, where, face, chart, link, n)
    # Sorted by face, each face's pairs by chart: a counting sort of the search order.
    pos = np.zeros(m + 1, dtype=np.int64)
    for p in range(n):
        pos[face[p] + 1] += 1
    for f in range(m):
        pos[f + 1] += pos[f]
    order = np.empty(n, dtype=np.int64)
    keys = np.empty(n, dtype=np.int64)
    for p in range(n):
        order[p] = pos[face[p]]
        keys[order[p]] = face[p] * n_labels + chart[p]
        pos[face[p]] += 1
    col = np.empty((n, width), dtype=np.int64)
    for p in range(n):
        for s in range(width):
            q = link[p, s]
            col[order[p], s] = order[q] if q >= 0 else -1
    return keys, col


@njit(cache=True, nogil=True)
def _chart_band(nbr, seeds, k, rings, mark, where, face, chart, link, n):  # pragma: no cover
    """:func:`_band`'s search of chart ``k``'s band from its ring 0 ``seeds``: appends its pairs
    to ``face``, ``chart`` and ``link`` (neighbour pairs in search order, -1 outside the band)
    from row ``n`` on; returns the new number of rows."""
    width = nbr.shape[1]
    first = n
    for f in seeds:
        if mark[f] != k:
            mark[f] = k
            where[f] = n
            face[n] = f
            chart[n] = k
            n += 1
    done = first
    for _ in range(rings):  # ring r + 1: the unmarked neighbours of ring r
        end = n
        if done == end:
            break
        for p in range(done, end):
            for s in range(width):
                g = nbr[face[p], s]
                if g >= 0 and mark[g] != k:
                    mark[g] = k
                    where[g] = n
                    face[n] = g
                    chart[n] = k
                    n += 1
        done = end
    for p in range(first, n):
        for s in range(width):
            g = nbr[face[p], s]
            link[p, s] = where[g] if g >= 0 and mark[g] == k else -1
    return n


@njit(cache=True, nogil=True)
def _heat_band(keys, col, nbr, P, labels, n_labels, coef):  # pragma: no cover - compiled
    """:func:`_round_charts`' diffusion of the band of :func:`_band` (``keys``, ``col``): every
    chart's indicator, ``sum_d coef[d] T_d(x) start``, by the Chebyshev recurrence
    ``T_d+1 = 2 x T_d - T_d-1`` for ``x (v, a) = (-(A v + a held), -a)`` on the state (band
    values, held value ``a``: 1, then -1, 1, ...). ``A`` is the band's part of the transition
    probabilities ``P`` (as float32), ``held`` each pair's probability of stepping out of the
    band into its chart (neighbours outside the band lie deep inside the chart, indicator 1, or
    outside, 0), ``start`` the indicator itself.

    In float32, operation for operation as with a sparse matrix ``A`` and row sums of ``(n, w)``
    arrays (each row summed from 0 in increasing column, which is slot order for ``nbr`` rows
    ascending, as :func:`_neighbor_table` gives), so the same bits, in one pass per term
    instead of a sparse product and five array operations (0.027 -> 0.012 s on the sample
    brain's 98k pairs, 42 terms), and the set-up (``held``, ``start``) in one pass instead of
    six gathers. Rows are summed slot by slot over all pairs (the long loop inside), absent
    slots as a zero weight on an extra zero entry, which leaves every sum as it is.

    Returns
    -------
    (n,) float32 ndarray
    """
    n, width = col.shape
    index = np.empty((width, n), dtype=np.int64)
    wt = np.empty((width, n), dtype=np.float32)
    held = np.empty(n, dtype=np.float32)
    two = np.float32(2.0)
    t_prev = np.zeros(n + 1, dtype=np.float32)  # entry n: the absent slots' zero
    for i in range(n):
        f, k = keys[i] // n_labels, keys[i] % n_labels
        t_prev[i] = 1.0 if labels[f] == k else 0.0
        h = np.float32(0.0)
        for s in range(width):
            p = np.float32(P[f, s])
            g = nbr[f, s]
            index[s, i] = col[i, s] if col[i, s] >= 0 else n
            wt[s, i] = p if col[i, s] >= 0 else 0.0
            h += p if g >= 0 and col[i, s] < 0 and labels[g] == k else np.float32(0.0)
        held[i] = h
    t_cur = np.zeros(n + 1, dtype=np.float32)
    t_next = np.zeros(n + 1, dtype=np.float32)
    value = np.empty(n, dtype=np.float32)
    _band_product(index, wt, t_prev, t_cur)
    for i in range(n):
        t_cur[i] = -(t_cur[i] + held[i])
        value[i] = coef[0] * t_prev[i] + coef[1] * t_cur[i]
    a_prev, a_cur = np.float32(1.0), np.float32(-1.0)
    for d in range(2, len(coef)):
        _band_product(index, wt, t_cur, t_next)
        for i in range(n):
            t_next[i] = -two * (t_next[i] + a_cur * held[i]) - t_prev[i]
            value[i] += coef[d] * t_next[i]
        t_prev, t_cur, t_next = t_cur, t_next, t_prev
        a_prev, a_cur = a_cur, -two * a_cur - a_prev
    return value


@njit(cache=True, nogil=True)
def _vote(keys, value, labels, n_labels):  # pragma: no cover - compiled
    """:func:`_round_charts`' vote: every face of the band joins the chart of its largest
    value, its own chart first by a bonus of 1e-6 (added in float64, rounded to float32, as
    ``value += 1e-6 * own``), then the lowest chart (the first of the face's pairs, which
    ``keys`` lists by face, then chart)."""
    new = labels.copy()
    i, n = 0, len(keys)
    while i < n:
        f = keys[i] // n_labels
        best, win = np.float32(-np.inf), i
        while i < n and keys[i] // n_labels == f:
            v = value[i]
            if keys[i] % n_labels == labels[f]:
                v = np.float32(np.float64(v) + 1e-6)
            if v > best:
                best, win = v, i
            i += 1
        new[f] = keys[win] % n_labels
    return new


@njit(cache=True, nogil=True)
def _band_product(index, wt, x, out):  # pragma: no cover - compiled
    """``out[:n] = A x`` for :func:`_heat_band`'s column-major rows, each summed from 0."""
    width, n = index.shape
    for i in range(n):
        out[i] = 0.0
    for s in range(width):
        for i in range(n):
            out[i] += wt[s, i] * x[index[s, i]]


def _heat_coefficients(t: float, tol: float = 1e-4) -> np.ndarray:
    """Chebyshev coefficients of the heat kernel ``exp(-t (1 + x))`` on ``[-1, 1]``.

    ``c_0 = e^-t I_0(t)``, ``c_k = 2 (-1)^k e^-t I_k(t)`` with ``I_k`` the modified Bessel
    functions (from ``e^(-t x) = I_0(t) + 2 sum_k (-1)^k I_k(t) T_k(x)``), up to the last one
    above ``tol``: 30 terms for ``t = 64``, 42 for ``t = 128``.

    Returns
    -------
    (d,) float ndarray
    """
    k = np.arange(int(4 * np.sqrt(t) + 20))
    c = 2.0 * ive(k, t) * (-1.0) ** k
    c[0] /= 2.0
    return c[: int(np.flatnonzero(np.abs(c) > tol).max()) + 1]


def _round_charts(
    nbr: np.ndarray,
    P: np.ndarray,
    labels: np.ndarray,
    *,
    diffusion_time: float,
    rings: int | None = None,
    iterations: int = 1,
    min_faces: int = 1,
) -> np.ndarray:
    """Round the charts by threshold dynamics (MBO) on the face graph, near their borders only.

    Each chart's indicator function is diffused by the heat kernel ``exp(-t L)`` of the
    random-walk Laplacian ``L = I - P``; every face then joins the chart whose diffused indicator
    is largest there. This moves the borders by their curvature (Merriman, Bence and Osher):
    spurs and lobes recede, notches fill, jagged outlines straighten. Only the pairs (face,
    chart) with the face within ``rings`` rings of that chart's border are diffused, as one
    sparse system for all charts; beyond them a chart's indicator is held at 1 inside and 0
    outside. The kernel is a Chebyshev expansion: about ``3.5 sqrt(t)`` sparse products instead
    of the ``2 t`` steps of a lazy random walk.

    Parameters
    ----------
    nbr : (m, w) int64 ndarray
        Neighbours of every face, -1 in unused slots (see :func:`_neighbor_table`); labels
        only spread along these edges.
    P : (m, w) float ndarray
        Random-walk transition probabilities along ``nbr``.
    labels : (m,) int64 ndarray
    diffusion_time : float
        ``t``, in random-walk steps: borders are smoothed over about ``sqrt(t)`` rings.
    rings : int, optional
        Band width; default ``ceil(1.5 sqrt(t))``, where the result no longer changes (on the
        100k brain: 12 faces of 2423 differ at ``1.4 sqrt(t)`` from a 40-ring band).
    iterations : int
        Rounds of diffuse-and-vote.
    min_faces : int
        A chart that would drop below this many faces (or below half its size) keeps its faces.

    Returns
    -------
    (m,) int64 ndarray
        New labels, same label set. A chart may fall into pieces (see
        :func:`_relabel_components`) and leave ear triangles (see :func:`_smooth_boundaries`).

    References
    ----------
    B. Merriman, J. Bence, S. Osher, "Motion of multiple junctions: a level set approach",
    J. Comput. Phys. 112 (1994).
    """
    n_labels = int(labels.max()) + 1 if len(labels) else 0
    if diffusion_time <= 0 or iterations <= 0 or n_labels < 2 or nbr.shape[1] == 0:
        return labels
    if rings is None:
        rings = int(np.ceil(1.5 * np.sqrt(diffusion_time)))
    coef = _heat_coefficients(diffusion_time).astype(np.float32)
    for _ in range(iterations):
        keys, col = _band(nbr, labels, n_labels, rings)
        if len(keys) == 0:
            break
        value = _heat_band(keys, col, nbr, P, labels, n_labels, coef)
        new = _vote(keys, value, labels, n_labels)
        old_size = np.bincount(labels, minlength=n_labels)
        new_size = np.bincount(new, minlength=n_labels)
        shrunk = (new_size < np.maximum(min_faces, old_size // 2))[labels]
        new[shrunk] = labels[shrunk]
        if np.array_equal(new, labels):
            break
        labels = new
    return labels


def feature_regions(
    V: np.ndarray,
    F: np.ndarray,
    W: sp.csr_matrix,
    feature_angle: float,
    min_faces: int,
    normals: np.ndarray | None = None,
) -> np.ndarray:
    """Regions of the face graph that sharp edges enclose completely.

    An edge is sharp when its two faces' normals differ by more than ``feature_angle`` degrees.
    The regions are the connected components of the face graph without the sharp edges, so
    sharp edges that do not close a curve (noise on a scan, a crease that fades out) separate
    nothing; regions smaller than ``min_faces`` (a face or two fenced in by noise) join the
    neighbour they share most affinity with. On a smooth surface this is the affinity graph's
    components. ``W`` is the (symmetric) face affinity; ``normals`` is ``face_normals(V, F)``,
    if the caller has it.

    Returns
    -------
    (m,) int64 ndarray
        Region of every face, ``0 .. r - 1``.
    """
    N = face_normals(V, F) if normals is None else normals
    # Every edge once, its normals' dot product coordinate by coordinate (the same bits as the
    # row sum of (k, 3) products): 0.42 -> 0.12 s of CPU at 1M faces.
    i, j = _edge_pairs(W)
    Nt = np.ascontiguousarray(N.T)
    Ni, Nj = [c.take(i) for c in Nt], [c.take(j) for c in Nt]  # 1-D takes (see mesh._face_cross)
    dot = 0.0 + Ni[0] * Nj[0] + Ni[1] * Nj[1] + Ni[2] * Nj[2]
    smooth = dot >= np.cos(np.radians(feature_angle))
    regions = _components(i[smooth], j[smooth], W.shape[0])
    regions = _merge_small(regions, W, min_faces)
    return _compact(regions)


def _within(W: sp.csr_matrix, labels: np.ndarray) -> sp.csr_matrix:
    """``W`` without the entries that join two different labels.

    Read off ``W``'s arrays (rows in order, each row's columns ascending): the matrix that
    rebuilding it from the kept entries gives, without the rebuild's sort (20k faces 2.4 ->
    0.5 ms).
    """
    if not W.has_canonical_format:  # duplicates or unsorted columns: rebuild (sum and sort)
        C = W.tocoo()
        same = labels[C.row] == labels[C.col]
        return sp.csr_matrix((C.data[same], (C.row[same], C.col[same])), shape=W.shape)
    m = W.shape[0]
    rows = np.repeat(np.arange(m), np.diff(W.indptr))
    same = labels[rows] == labels[W.indices]
    indptr = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(np.bincount(rows[same], minlength=m), out=indptr[1:])
    return sp.csr_matrix((W.data[same], W.indices[same], indptr), shape=W.shape)


def _compact(labels: np.ndarray) -> np.ndarray:
    """``np.unique(labels, return_inverse=True)[1]`` of non-negative integer labels, as int64:
    every label replaced by its rank among the labels in use, by a count instead of a sort
    (20k faces: 1.3 -> 0.1 ms; five of these per segmentation)."""
    used = np.bincount(labels) > 0
    return (np.cumsum(used) - 1)[labels].astype(np.int64, copy=False)


def _relabel_components(labels: np.ndarray, W: sp.csr_matrix) -> np.ndarray:
    """Split every label into its edge-connected components (one new label each).

    ``W``'s pattern is the face adjacency (every affinity is positive).
    """
    i, j = _edge_pairs(W)
    same = labels[i] == labels[j]
    return _components(i[same], j[same], W.shape[0])


def _edge_pairs(W: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    """Every edge of a symmetric graph once: the entries ``(i, j)`` of ``W`` above the
    diagonal, row by row."""
    rows = np.repeat(np.arange(W.shape[0]), np.diff(W.indptr))
    upper = rows < W.indices
    return rows[upper], W.indices[upper]


def _components(i: np.ndarray, j: np.ndarray, m: int) -> np.ndarray:
    """Connected components of the graph on ``m`` nodes with the edges ``(i, j)``, ``i``
    ascending (as :func:`_edge_pairs` gives them), numbered in the order of their first node
    (as ``connected_components`` numbers them, whichever direction an edge is given in). Half
    the edges of a symmetric matrix, put in a CSR matrix as they are (no sort): components of
    the 1M-face brain's charts 0.17 -> 0.15 s, the sample brain's 1.9 -> 1.5 ms."""
    indptr = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(np.bincount(i, minlength=m), out=indptr[1:])
    G = sp.csr_matrix((np.ones(len(i)), j, indptr), shape=(m, m))
    return _cc(G, directed=False)[1].astype(np.int64)


def _merge_small(labels: np.ndarray, W: sp.csr_matrix, min_faces: int) -> np.ndarray:
    """Merge charts smaller than ``min_faces`` into the neighbour they share most affinity with."""
    C = W.tocoo()
    for _ in range(8):  # a few passes; each merges every small chart at once
        size = np.bincount(labels)
        small = size[labels] < min_faces
        if not small.any():
            break
        li, lj = labels[C.row], labels[C.col]
        mask = small[C.row] & (li != lj)
        if not mask.any():
            break
        n = labels.max() + 1
        S = sp.coo_matrix((C.data[mask], (li[mask], lj[mask])), shape=(n, n)).tocsr()
        target = np.asarray(S.argmax(axis=1)).ravel()
        has = np.asarray(S.max(axis=1).todense()).ravel() > 0
        # Only merge into a chart that is not itself merging away this pass (avoid cycles),
        # unless it is bigger.
        mapping = np.arange(n)
        src = np.flatnonzero(has & (size < min_faces))
        keep = (
            (size[target[src]] >= min_faces)
            | (size[target[src]] > size[src])
            | ((size[target[src]] == size[src]) & (target[src] < src))
        )
        mapping[src[keep]] = target[src[keep]]
        # Resolve chains a -> b -> c.
        for _ in range(int(np.ceil(np.log2(max(n, 2)))) + 1):
            mapping = mapping[mapping]
        labels = _compact(mapping[labels])
    return labels.astype(np.int64)


def _halve_tiny(
    C: np.ndarray, labels: np.ndarray, bad: np.ndarray, W_in: sp.csr_matrix, next_label: int
) -> tuple[np.ndarray, int]:
    """One bulk cut of every chart in ``bad`` (none of them a disk), all at once.

    A chart in several edge-connected pieces is cut into its pieces (as :func:`divide` does);
    a connected one is halved by a plane through its centroid across its principal axis: the
    faces whose centroids project below the median of its principal axis keep the label, the
    others get a new one (as the two halves of :func:`fiedler_bisect`, cut by geometry instead
    of a Fiedler vector). Both halves are non-empty, so repeated cuts end at disks.

    Parameters
    ----------
    C : (m, 3) float ndarray
        Face centroids.
    labels : (m,) int64 ndarray
    bad : (b,) int ndarray
        The labels to cut.
    W_in : (m, m) sparse matrix
        Face adjacency without the edges between different labels.
    next_label : int
        First unused label.

    Returns
    -------
    labels : (m,) int64 ndarray
    next_label : int
    """
    labels = labels.copy()
    in_bad = np.zeros(next_label, dtype=bool)
    in_bad[bad] = True
    faces = np.flatnonzero(in_bad[labels])
    lab = labels[faces]
    # Edge-connected pieces of each chart (pieces never span two charts: W_in has no such edge).
    _, piece = _cc(W_in[faces][:, faces], directed=False)
    pieces_per = np.bincount(lab[np.unique(piece, return_index=True)[1]], minlength=next_label)
    split = pieces_per[lab] > 1
    # Disconnected charts: the piece of the chart's first face keeps the label, every other
    # piece gets a new one.
    labs, first = np.unique(lab, return_index=True)
    keep = np.full(next_label, -1)
    keep[labs] = piece[first]
    moved = split & (piece != keep[lab])
    if moved.any():
        ids, inv = np.unique(piece[moved], return_inverse=True)
        labels[faces[moved]] = next_label + inv.ravel()
        next_label += len(ids)
    # Connected charts: halve across the principal axis, by count like fiedler_bisect.
    whole = ~split
    if whole.any():
        f, k = faces[whole], lab[whole]
        ks, kinv = np.unique(k, return_inverse=True)
        kinv = kinv.ravel()
        count = np.bincount(kinv).astype(float)
        X = C[f]
        mean = np.stack([np.bincount(kinv, X[:, j]) for j in range(3)], 1) / count[:, None]
        X = X - mean[kinv]
        outer = (X[:, :, None] * X[:, None, :]).reshape(-1, 9)
        cov = np.stack([np.bincount(kinv, outer[:, j]) for j in range(9)], 1).reshape(-1, 3, 3)
        axis = np.linalg.eigh(cov)[1][:, :, -1]
        t = (X * axis[kinv]).sum(axis=1)
        order = np.lexsort((np.arange(len(f)), t, kinv))
        start = np.searchsorted(kinv[order], np.arange(len(ks)))
        rank = np.empty(len(f), dtype=np.int64)
        rank[order] = np.arange(len(f)) - start[kinv[order]]
        upper = rank >= (count.astype(np.int64) // 2)[kinv]
        labels[f[upper]] = next_label + kinv[upper]
        next_label += len(ks)
    return labels, next_label


def _make_disks(
    V: np.ndarray,
    F: np.ndarray,
    labels: np.ndarray,
    W: sp.csr_matrix,
    seed: int,
    edge_index: tuple | None = None,
) -> np.ndarray:
    """Cut every chart that is not a disk until all are.

    All charts are tested at once (:func:`segparam.mesh.disk_labels`). Charts of at most
    ``TINY_PART_FACES`` faces are cut in bulk (:func:`_halve_tiny`), round after round, every
    round testing only the charts it cut; larger ones are bisected along their Fiedler vector
    (:func:`divide`), one at a time (a loop over the few charts that are not disks).
    ``edge_index`` is ``edges(F)`` of a manifold, oriented ``F`` (as clean leaves a mesh), for
    the fast test of all charts (``disk_labels(..., manifold_edges=)``), or None.
    """
    labels = labels.copy()
    n = int(labels.max()) + 1
    ok = disk_labels(F, labels, n, manifold_edges=edge_index)
    size = np.bincount(labels, minlength=n)
    tiny = np.flatnonzero(~ok & (size <= TINY_PART_FACES))
    queue = np.flatnonzero(~ok & (size > TINY_PART_FACES)).tolist()
    next_label = n
    if len(tiny):
        C = V[F].mean(axis=1)
        for _ in range(2 * int(np.log2(TINY_PART_FACES)) + 2):  # each round halves at least
            if len(tiny) == 0:
                break
            W_in = _within(W, labels)
            first_new = next_label
            labels, next_label = _halve_tiny(C, labels, tiny, W_in, next_label)
            cut = np.r_[tiny, np.arange(first_new, next_label)]
            in_cut = np.zeros(next_label, dtype=bool)
            in_cut[cut] = True
            sel = np.flatnonzero(in_cut[labels])
            local = np.full(next_label, -1)
            local[cut] = np.arange(len(cut))
            ok_cut = disk_labels(F[sel], local[labels[sel]], len(cut))
            tiny = cut[~ok_cut]
        queue = tiny.tolist() + queue  # not expected: the Fiedler loop finishes them
    while queue:
        c = queue.pop()
        faces = np.flatnonzero(labels == c)
        if len(faces) == 0 or is_disk(F[faces]):
            continue
        if len(faces) == 1:
            continue  # a single triangle is always a disk; unreachable in practice
        parts = divide(W, faces, seed=seed)  # a half may fall apart: pieces are checked alone
        for part in parts[1:]:
            labels[part] = next_label
            queue.append(next_label)
            next_label += 1
        queue.append(c)
    return _compact(labels)


def _cluster_components(
    W: sp.csr_matrix,
    comp: np.ndarray,
    big: np.ndarray,
    share: np.ndarray,
    labels: np.ndarray,
    n_comp: int,
    cfg: SegmentConfig,
    seed: int,
) -> np.ndarray:
    """Spectral clustering of each region in ``big`` into its ``share`` of charts (a loop over
    the few regions that need it), on a proxy graph above ``proxy_faces``; the new labels
    start at ``n_comp``."""
    offset = 0
    for c in big:
        faces = np.flatnonzero(comp == c)
        # a region of the whole mesh (a closed surface): W itself, not a copy (1M faces: 0.04 s)
        sub = W if len(faces) == W.shape[0] else W[faces][:, faces]
        k = int(min(share[c], len(faces)))
        cells = min(cfg.proxy_faces, max(PROXY_BUDGET // max(k, 1), MIN_CELLS_PER_CHART * k))
        if len(faces) > cells:
            cell = _proxy_cells(sub, cells, seed)
            P = sp.csr_matrix(
                (np.ones(len(faces)), (np.arange(len(faces)), cell)),
                shape=(len(faces), cell.max() + 1),
            )
            coarse = (P.T @ sub @ P).tocsr()
            coarse.setdiag(0)
            coarse.eliminate_zeros()
            sub_labels = _cluster(coarse, k, seed)[cell]
        else:
            sub_labels = _cluster(sub, k, seed)
        labels[faces] = n_comp + offset + sub_labels
        offset += k
    return labels


def segment(
    V: np.ndarray,
    F: np.ndarray | None = None,
    *,
    config: SegmentConfig | None = None,
    seed: int = 0,
) -> Segmentation:
    """Cut a (cleaned, manifold) mesh into disk-like charts by spectral clustering.

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray
        Edge- and vertex-manifold, consistently oriented: as :func:`segparam.clean.clean` leaves
        a mesh.
    config : SegmentConfig, optional
    seed : int
        Seeds the proxy cells and the clustering.

    Returns
    -------
    Segmentation
    """
    cfg = config or SegmentConfig()
    V, F = check_mesh(*mesh_arrays(V, F))  # or a trimesh.Trimesh alone
    center, size = unit_frame(V)
    V = (V - center) / size  # scale-free from here on
    m = len(F)
    edge_index = edges(F)  # shared by the curvature, the affinity and the disk test
    # The input is vertex-manifold (clean's output); the disk test's fast path also needs every
    # edge on at most two faces, traversed oppositely, which is cheap to check.
    manifold = is_edge_manifold(F, edge_index=edge_index)
    angles = corner_angles(V, F)
    defect = interior_defect(V, F, angles=angles, edge_index=edge_index)
    curvature = integrated_curvature(V, F, edge_index=edge_index, defect=defect[0])
    # for the split stage's caps (segparam.split._caps): 0.2 ms at 20k faces, 0.02 s at 1M
    face_curvature = curvature_shares(V, F, angles=angles, defect=defect)
    if cfg.n_charts is not None:
        target = cfg.n_charts
    else:
        target = int(np.ceil(curvature / cfg.curvature_per_chart))
        target = max(target, int(np.ceil(m / cfg.max_chart_faces)), 1)
    target = min(target, cfg.max_charts, m)
    # shared by the affinity, the feature regions and the planar test; the areas by the shares
    N, area = face_normals(V, F, return_areas=True)
    W = face_affinity(
        V,
        F,
        concave_weight=cfg.concave_weight,
        convex_weight=cfg.convex_weight,
        edge_index=edge_index,
        normals=N,
    )

    # Feature regions (the faces of a CAD part) are charted apart; a smooth surface is one region
    # per connected component. Regions of fewer than 16 faces (or 0.2% of a small mesh) are noise
    # and join a neighbour; the wall of a drilled hole in a CAD mesh has 30 or more.
    comp = feature_regions(V, F, W, cfg.feature_angle, min(16, max(2, int(0.002 * m))), N)
    n_comp = int(comp.max()) + 1
    comp_area = np.bincount(comp, weights=area, minlength=n_comp)
    # Charts per component, proportional to area (every component gets at least one).
    share = np.maximum(1, np.round(target * comp_area / comp_area.sum())).astype(int)
    # A planar region (the face of a CAD part) maps exactly as one chart, whatever its area: the
    # split stage projects it onto its plane (the CAD plate's top and bottom were 6 charts each).
    first = np.full(n_comp, m)
    np.minimum.at(first, comp, np.arange(m))
    bent = np.abs(N - N[first[comp]]).max(axis=1) >= PLANAR_TOL
    share[np.bincount(comp, weights=bent, minlength=n_comp) == 0] = 1
    # Border clean-up sees only the edges inside feature regions: no label crosses an outline.
    W_in = _within(W, comp)
    # A tiny closed region whose share is two charts is not clustered: as one chart it is no
    # disk, and _make_disks halves it, in bulk. (Cut geometrically into three or more pieces,
    # tiny spheres packed 2% worse with 4-8% longer seams than clustered: those are clustered.)
    # Closed: every face has three neighbours inside the region.
    comp_faces = np.bincount(comp, minlength=n_comp)
    open_faces = np.bincount(comp, weights=np.diff(W_in.indptr) < 3, minlength=n_comp)
    tiny_closed = (comp_faces <= TINY_PART_FACES) & (open_faces == 0) & (share <= 2)
    labels = np.empty(m, dtype=np.int64)
    # An open region whose share is two charts is tried whole: the split stage bisects it along
    # its Fiedler vector if its map misses the stretch target, as clustering would have cut it.
    # The noisy 3k-face sheet of bench_atlas (1.16 hemispheres' curvature) maps as one chart at
    # L2 1.0008, and was cut in two.
    pair_open = (share == 2) & (open_faces > 0)
    single = (share <= 1) | tiny_closed | pair_open
    big = np.flatnonzero(~single)
    labels[single[comp]] = comp[single[comp]] + 0  # temporary: unique per component
    # Lanczos' and CPQR's BLAS calls are thin (20k x 20) and the dense eigenproblems small:
    # threads only add overhead (on a busy 2-core machine they doubled the CPU time of the 20k
    # brain's clustering); one limit for all components.
    limit = one_blas_thread() if len(big) else nullcontext()
    with limit:
        labels = _cluster_components(W, comp, big, share, labels, n_comp, cfg, seed)
    labels = _compact(labels)
    nbr, P = _neighbor_table(W_in)
    labels = _smooth_boundaries(nbr, labels, cfg.smoothing)
    min_faces = max(2, int(0.1 * m / max(target, n_comp)))
    if cfg.rounding > 0:
        labels = _round_charts(nbr, P, labels, diffusion_time=cfg.rounding, min_faces=min_faces)
        labels = _smooth_boundaries(nbr, labels, cfg.smoothing)  # the vote leaves ears
    labels = _relabel_components(labels, W)
    # Small charts join a neighbour inside their own feature region, never across its outline.
    labels = _merge_small(labels, W_in, min_faces)
    labels = _make_disks(V, F, labels, W, seed, edge_index if manifold else None)
    n = int(labels.max()) + 1
    log.info("segment: %d faces -> %d charts (target %d)", m, n, target)
    return Segmentation(
        labels=labels, n_charts=n, target_charts=target, curvature=curvature, affinity=W,
        face_curvature=face_curvature,
    )  # fmt: skip
