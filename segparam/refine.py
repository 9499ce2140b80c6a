"""Flip-free distortion refinement of chart maps: SLIM iterations on the symmetric Dirichlet
energy, optionally with a conformal term.

Not in the paper. The Hessian eigenmap (and the ARAP iterations after it, see
:mod:`segparam.parameterize`) leaves charts close to isometric, balancing angle and area
distortion as ARAP does; textures are judged by both (a checkerboard's squares should stay
square and the same size). This module minimises, per chart, with a free boundary,

    E(uv) = sum_t A_t [s1^2 + s2^2 + s1^-2 + s2^-2 + mu (s1/s2 + s2/s1 - 2)] / sum_t A_t

(4 for an isometry; ``s1 >= s2`` the singular values of triangle t's Jacobian, ``mu`` the
``angle_weight``, a quarter of it on charts of fewer than 32 faces: 0 is the symmetric
Dirichlet energy, larger values buy less angle distortion with some area distortion), started
from a map with every triangle positive, and keeps every triangle positive at every step, so the
map stays locally injective by construction:

* direction (Rabinovich et al. 2017, "Scalable Locally Injective Mappings", sec. 4): with
  ``J_t = U S V^T``, ``R_t = U V^T`` and ``W_t = U diag(w(s1), w(s2)) U^T``,
  ``w(s)^2 = (s + 1)(s^2 + 1) / s^3`` (``f'(s) / (2 (s - 1))`` for ``f(s) = s^2 + s^-2``), SLIM's
  proxy ``sum_t A_t ||W_t (J_t - R_t)||_F^2`` is a quadratic ``x^T H x - 2 b^T x`` in the stacked
  ``x = (u, v)`` whose gradient is the symmetric Dirichlet energy's. The step is
  ``d = -H^-1 grad E / 2``: exactly SLIM's step when ``mu = 0``, and a descent direction
  preconditioned by SLIM's matrix otherwise (``H`` is positive definite once a vertex per chart
  is pinned). One numeric Cholesky factorization per iteration, the symbolic one kept while the
  pattern stays (:class:`segparam.linalg.FixedPattern`);
* flip-free line search (Smith & Schaefer 2015, "Bijective Parameterization with Free
  Boundaries", sec. 3.1): along ``d`` the signed area of each triangle is a quadratic in the
  step ``tau``; its smallest positive root bounds the step, and ``tau = min(1, 0.8 * root)``
  (their 0.8) is halved until the energy decreases (the energy is infinite at a flip, so any
  decrease keeps every triangle positive).

Both terms are barriers against flips but not against the boundary overlapping itself, so the
caller checks the result (:func:`segparam.quality.chart_quality`) and keeps the starting map
when it is not bijective. Charts of a disjoint union are refined together: the system is
block-diagonal, the step and the stopping rule are per chart (no Python loop over vertices or
faces).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .linalg import FixedPattern
from .mesh import face_areas
from .quality import inverse_frames, jacobians, triangle_frames
from .topology import number_marked

__all__ = [
    "ANGLE_WEIGHT",
    "MAX_STRETCH_INCREASE",
    "SMALL_CHART_FACES",
    "slim_refine",
    "symmetric_dirichlet",
]

#: Default weight of the conformal term (see :func:`slim_refine`). Measured on brain-20k's 8
#: charts (``benchmarks/bench_quality.py``): 0 -> L2 1.0037 / angle 1.0600, 4 -> 1.0067 / 1.0297,
#: 16 -> 1.0083 / 1.0182 (xatlas, 13 charts: 1.0379 / 1.0087).
ANGLE_WEIGHT = 16.0
#: On charts of fewer than ``SMALL_CHART_FACES`` faces the refined map is kept only if its L2
#: stretch is at most ``MAX_STRETCH_INCREASE`` above the starting map's (checked by the caller,
#: :mod:`segparam.parameterize`). Larger charts that the conformal term stretches past the
#: stretch target are split (``[split] max_stretch``, from the same size up). This was 64 faces,
#: which exempted the 40-face hemispheres of small spheres and most pieces of the realistic 2k
#: brain (L2 1.026 / angle 1.244 and 1.035 / 1.205 in bench_atlas); now that the split stage
#: solves small pieces in batches they are refined and split like any chart (1.005 / 1.093 with
#: 1,203 charts, 1.007 / 1.077 with 108; xatlas 1.005 / 1.077 with 1,794, 1.021 / 1.057 with
#: 134). 8 is the default ``[split] min_faces``: at the defaults the guard no longer applies.
MAX_STRETCH_INCREASE = 0.01
SMALL_CHART_FACES = 8

#: Iterations stop for a chart once one lowers its energy's excess over the isometry's (4) by
#: less than this fraction (measured: on a saddle, a brain parcel and a spherical cap the energy
#: is within 1e-4 of its limit after 5-10 iterations, where this rule stops). 1e-2 until the
#: small charts were refined too: the realistic 2k brain's 108 charts (mostly under 64 faces)
#: stopped early, at angle 1.0775 (xatlas + 0.02 = 1.0773); 5e-3 gives 1.0770, fsaverage5 and
#: brain-20k move by <= 0.0003, no stage time measurably more (parameterize_charts, CPU, loaded
#: machine); 1e-3 gives 1.0754 on the brain at +25% of its stage time.
SLIM_TOL = 5e-3
#: ... or once that excess is below this: every triangle within ~0.1% of an isometry (a
#: developable chart; the excess is about ``8 eps^2`` for singular values ``1 +- eps``).
SLIM_FLOOR = 1e-5
#: Most iterations; a chart that has not converged keeps its best map so far.
SLIM_ITERATIONS = 30
#: Fraction of the largest flip-free step taken (Smith & Schaefer 2015 use 0.8), so no triangle
#: reaches zero area in one step.
STEP_FRACTION = 0.8
#: Halvings of the step before a chart gives up (the direction is then useless).
MAX_HALVINGS = 12
#: Charts of fewer faces are refined with ``SMALL_CHART_ANGLE_SCALE`` times the angle weight:
#: on a chart of few faces (most vertices on its boundary) the conformal term buys little angle
#: for the stretch it costs. The 300 small spheres of bench_atlas (charts of 20 faces; angle
#: weight 16 -> 4 on them): L2 1.0053 -> 1.0044 (xatlas 1.0048), angle 1.0933 -> 1.0948 (xatlas
#: + 0.02: 1.0970); brain-20k's 8 whole charts at weight 16 -> 4 (section 8 of BENCHMARKS.md):
#: L2 1.0083 -> 1.0067 but angle 1.0182 -> 1.0297. The realistic 2k brain (many charts under 32
#: faces): 117 -> 111 charts, L2 1.0062 -> 1.0066, angle 1.0659 -> 1.0714 (goal 1.0773);
#: brain-20k's 9 such charts move its figures by less than 1e-6; the other meshes of
#: ``bench_atlas.py --quick`` have none but single triangles (exact maps).
#: Thresholds 24 and 48 gave the spheres the same figures (brain-2k angle 1.0717, 1.0719); a
#: scale of 1/8 (weight 2) took brain-2k's angle to 1.0829, 3/8 (weight 6) left the spheres at
#: L2 1.0046.
SMALL_CHART_ANGLE_FACES = 32
SMALL_CHART_ANGLE_SCALE = 0.25


def _energy_terms(J: np.ndarray, angle_weight: float | np.ndarray = 0.0) -> np.ndarray:
    """Per Jacobian, ``s1^2 + s2^2 + s1^-2 + s2^-2`` (``||J||_F^2 (1 + det^-2)``) plus
    ``angle_weight`` (one number or one per Jacobian) times the conformal term
    ``s1 / s2 + s2 / s1 - 2`` (``||J||_F^2 / det - 2``); ``inf`` where ``det J <= 0``."""
    det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
    fro = (J**2).sum(axis=(1, 2))
    good = det > 0
    inv = 1.0 / np.where(good, det, 1.0)
    return np.where(good, fro * (1.0 + inv**2) + angle_weight * (fro * inv - 2.0), np.inf)


def symmetric_dirichlet(
    V: np.ndarray,
    F: np.ndarray,
    uv: np.ndarray,
    inv_frames: np.ndarray | None = None,
    *,
    angle_weight: float = 0.0,
) -> float:
    """Area-weighted mean symmetric Dirichlet energy of ``(V, F) -> uv`` as it is (not rescaled),
    plus ``angle_weight`` times the mean conformal term ``s1 / s2 + s2 / s1 - 2``: the energy
    :func:`slim_refine` lowers (which gives a chart of fewer than ``SMALL_CHART_ANGLE_FACES``
    faces ``SMALL_CHART_ANGLE_SCALE`` times the ``angle_weight`` it is given).

    ``4`` for an isometry, ``inf`` if a triangle is flipped or degenerate.
    """
    area = face_areas(V, F)
    terms = _energy_terms(jacobians(V, F, uv, inv_frames), angle_weight)
    return float(area @ terms / area.sum())


# ----------------------------------------------------------------------------------------------
# one iteration's per-triangle arithmetic, compiled: a loop over the faces of the charts still
# moving instead of ~40 numpy calls on small arrays (SLIM's time on the solver calls of brain-2k
# and brain-20k 0.40 -> 0.25 s; the maps agree with the array forms to 3e-14, BENCHMARKS.md
# section 0.1, session 12). ``frames[f]`` is the inverse frame of face ``f``
# (:func:`segparam.quality.inverse_frames`), so ``J = [uv1 - uv0, uv2 - uv0] frames[f]``.


@njit(cache=True, nogil=True)
def _jacobian(F, f, x, frames):  # pragma: no cover - compiled
    """Face ``f``'s Jacobian ``(j00, j01, j10, j11)`` at the map ``x``."""
    i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
    q00, q01 = x[i1, 0] - x[i0, 0], x[i2, 0] - x[i0, 0]
    q10, q11 = x[i1, 1] - x[i0, 1], x[i2, 1] - x[i0, 1]
    a, b, c, d = frames[f, 0, 0], frames[f, 0, 1], frames[f, 1, 0], frames[f, 1, 1]
    return q00 * a + q01 * c, q00 * b + q01 * d, q10 * a + q11 * c, q10 * b + q11 * d


@njit(cache=True, nogil=True)
def _slim_terms(F, faces, x, frames, weight, area):  # pragma: no cover - compiled
    """Per face of ``faces`` (every triangle positive): SLIM's weights ``W^T W`` and the area
    times ``d/dJ`` of the energy term.

    ``W^T W = U diag(w(s1)^2, w(s2)^2) U^T`` with SLIM's symmetric Dirichlet weights
    ``w(s)^2 = (s + 1)(s^2 + 1) / s^3``, in closed form ``w2^2 I + (w1^2 - w2^2) u1 u1^T``,
    ``u1`` the leading eigenvector of ``J J^T`` and ``s1, s2`` the singular values from the
    conformal / anti-conformal split (:func:`segparam.quality.singular_values`). The gradient,
    with ``C = d det / dJ`` (the cofactor matrix): ``2 J (1 + det^-2) - 2 ||J||^2 det^-3 C`` and,
    for the conformal term times ``weight[f]``, ``2 J / det - ||J||^2 det^-2 C``.
    """
    k = len(faces)
    W2 = np.empty((k, 2, 2))
    g = np.empty((k, 2, 2))
    for t in range(k):
        f = faces[t]
        j00, j01, j10, j11 = _jacobian(F, f, x, frames)
        q = math.hypot(j00 + j11, j10 - j01)
        r = math.hypot(j00 - j11, j01 + j10)
        s1, s2 = (q + r) / 2, abs(q - r) / 2
        w1 = (s1 + 1) * (s1 * s1 + 1) / (s1 * s1 * s1)  # w(s1)^2
        w2 = (s2 + 1) * (s2 * s2 + 1) / (s2 * s2 * s2)  # w(s2)^2
        theta = 0.5 * math.atan2(
            2 * (j00 * j10 + j01 * j11), (j00 * j00 + j01 * j01) - (j10 * j10 + j11 * j11)
        )
        u0, u1 = math.cos(theta), math.sin(theta)
        W2[t, 0, 0] = w2 + (w1 - w2) * u0 * u0
        W2[t, 0, 1] = (w1 - w2) * u0 * u1
        W2[t, 1, 0] = W2[t, 0, 1]
        W2[t, 1, 1] = w2 + (w1 - w2) * u1 * u1
        det = j00 * j11 - j01 * j10
        fro = j00 * j00 + j01 * j01 + j10 * j10 + j11 * j11
        inv = 1.0 / det
        a, b = 2 * (1 + inv * inv), 2 * fro * inv * inv * inv  # the symmetric Dirichlet term
        a2, b2 = 2 * inv, fro * inv * inv  # the conformal term
        w, A = weight[f], area[f]
        g[t, 0, 0] = (a * j00 - b * j11 + w * (a2 * j00 - b2 * j11)) * A
        g[t, 0, 1] = (a * j01 + b * j10 + w * (a2 * j01 + b2 * j10)) * A
        g[t, 1, 0] = (a * j10 + b * j01 + w * (a2 * j10 + b2 * j01)) * A
        g[t, 1, 1] = (a * j11 - b * j00 + w * (a2 * j11 - b2 * j00)) * A
    return W2, g


@njit(cache=True, nogil=True)
def _chart_energies(F, faces, x, frames, weight, area, fc, total):  # pragma: no cover
    """Each chart's energy at the map ``x`` over the faces ``faces`` (the charts of none: 0):
    the area-weighted :func:`_energy_terms` summed per chart and divided by ``total``, the
    chart's area (``inf`` for a chart with a flipped or degenerate triangle)."""
    out = np.zeros(len(total))
    for t in range(len(faces)):
        f = faces[t]
        j00, j01, j10, j11 = _jacobian(F, f, x, frames)
        det = j00 * j11 - j01 * j10
        if det > 0:
            fro = j00 * j00 + j01 * j01 + j10 * j10 + j11 * j11
            inv = 1.0 / det
            out[fc[f]] += area[f] * (fro * (1.0 + inv * inv) + weight[f] * (fro * inv - 2.0))
        else:
            out[fc[f]] = np.inf
    return out / total


@njit(cache=True, nogil=True)
def _step_bounds(x, d, F, faces, fc, n_charts):  # pragma: no cover - compiled
    """Per chart, the smallest ``tau > 0`` at which a triangle of ``faces`` reaches zero signed
    area along ``x + tau d`` (``inf`` if none): area(tau) = a + b tau + c tau^2 (Smith &
    Schaefer 2015, sec. 3.1), both roots in the cancellation-free form ``2a / (-b -+ root)``."""
    tau = np.full(n_charts, np.inf)
    for t in range(len(faces)):
        f = faces[t]
        i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
        p1x, p1y = x[i1, 0] - x[i0, 0], x[i1, 1] - x[i0, 1]
        p2x, p2y = x[i2, 0] - x[i0, 0], x[i2, 1] - x[i0, 1]
        q1x, q1y = d[i1, 0] - d[i0, 0], d[i1, 1] - d[i0, 1]
        q2x, q2y = d[i2, 0] - d[i0, 0], d[i2, 1] - d[i0, 1]
        a = p1x * p2y - p1y * p2x
        b = (p1x * q2y - p1y * q2x) + (q1x * p2y - q1y * p2x)
        c = q1x * q2y - q1y * q2x
        best = tau[fc[f]]
        disc = b * b - 4 * a * c
        if disc >= 0:
            root = math.sqrt(disc)
            for den in (-b - root, -b + root):
                if den != 0:
                    r = 2 * a / den
                    if 0 < r < best:
                        best = r
        if b < 0 and abs(c) <= 1e-14 * b * b / max(abs(a), 1e-300):  # linear: a + b tau
            best = min(best, -a / b)
        tau[fc[f]] = best
    return tau


@njit(cache=True, nogil=True)
def gradient_row(F, t, coef, k):  # pragma: no cover - compiled
    """Face ``t``'s distinct corners in ascending vertex order and row ``k`` of its gradient
    coefficients (:func:`_gradient_coefficients`) summed per corner: the entries of row
    ``2 t + k`` of the gradient operator ``D`` as a CSR matrix stores them (columns sorted, a
    vertex named twice summed; :func:`segparam.parameterize._gradient_operator`)."""
    v0, v1, v2 = F[t, 0], F[t, 1], F[t, 2]
    c0, c1, c2 = coef[t, k, 0], coef[t, k, 1], coef[t, k, 2]
    if v1 < v0:
        v0, v1, c0, c1 = v1, v0, c1, c0
    if v2 < v1:
        v1, v2, c1, c2 = v2, v1, c2, c1
        if v1 < v0:
            v0, v1, c0, c1 = v1, v0, c1, c0
    if v0 == v1 == v2:
        return 1, v0, v0, v0, c0 + c1 + c2, 0.0, 0.0
    if v0 == v1:
        return 2, v0, v2, v2, c0 + c1, c2, 0.0
    if v1 == v2:
        return 2, v0, v1, v1, c0, c1 + c2, 0.0
    return 3, v0, v1, v2, c0, c1, c2


@njit(cache=True, nogil=True)
def gradient_transpose(F, faces, coef, x, n):  # pragma: no cover - compiled
    """``D^T x`` for per-face rows ``x`` of the faces ``faces`` (``(k, 2, 2)``: face ``faces[t]``'s
    row ``k`` of ``D``, value ``c`` of the two uv coordinates), the other faces' rows 0: an
    ``(n, 2)`` array over the vertices, without the sparse matrix.

    The same bits as scipy's CSC product ``D.T @ x``: each vertex sums its terms from 0.0 face
    row after face row (``2 f + k``), a face naming a vertex twice adding its summed
    coefficients once (:func:`gradient_row`). SLIM's energy gradient and ARAP's right-hand side
    (:func:`segparam.parameterize._arap_charts`).
    """
    out = np.zeros((n, 2))
    for t in range(len(faces)):
        f = faces[t]
        for k in range(2):
            n_c, v0, v1, v2, a0, a1, a2 = gradient_row(F, f, coef, k)
            for c in range(2):
                out[v0, c] += a0 * x[t, k, c]
                if n_c > 1:
                    out[v1, c] += a1 * x[t, k, c]
                if n_c > 2:
                    out[v2, c] += a2 * x[t, k, c]
    return out


@njit(cache=True, nogil=True)
def poisson_entries(F, coef, area, rank):  # pragma: no cover - compiled
    """The entries of ``L[free][:, free]`` for ``L = D^T diag(w) D`` (``w``: each face's
    ``area`` for both of its rows of ``D``, the gradient operator), without the sparse matrices:
    ARAP's Poisson matrix (:func:`segparam.parameterize._arap_charts`). ``rank`` numbers the
    free vertices ``0 ..`` (-1: pinned).

    The same bits as scipy's ``(D.T @ sp.diags(w) @ D)[free][:, free]``: entry ``(i, j)`` sums
    ``D[r, j] * (w[r] * D[r, i])`` from 0.0 over the rows ``r`` of ``D`` in order (a face naming
    a vertex twice as one corner, :func:`gradient_row`), and entries that sum to zero are
    dropped, as scipy's product drops them.

    Returns
    -------
    rows, cols : (e,) int64 ndarrays
    vals : (e,) float64 ndarray
        Both triangles, each entry once, by row then column.
    """
    m = len(F)
    n = 0
    for v in range(len(rank)):
        n = max(n, rank[v] + 1)
    vs = np.empty(3, dtype=np.int64)
    cs = np.empty(3)
    # each row's terms in the order of D's rows (two passes: count, then fill)
    ptr = np.zeros(n + 1, dtype=np.int64)
    for t in range(m):
        for k in range(2):
            n_c, vs[0], vs[1], vs[2], cs[0], cs[1], cs[2] = gradient_row(F, t, coef, k)
            for a in range(n_c):
                i = rank[vs[a]]
                if i >= 0:
                    for b in range(n_c):
                        if rank[vs[b]] >= 0:
                            ptr[i + 1] += 1
    for i in range(n):
        ptr[i + 1] += ptr[i]
    fill = ptr[:-1].copy()
    col = np.empty(ptr[n], dtype=np.int64)
    term = np.empty(ptr[n])
    for t in range(m):
        w = area[t]
        for k in range(2):
            n_c, vs[0], vs[1], vs[2], cs[0], cs[1], cs[2] = gradient_row(F, t, coef, k)
            for a in range(n_c):
                i = rank[vs[a]]
                if i < 0:
                    continue
                wa = w * cs[a]
                for b in range(n_c):
                    j = rank[vs[b]]
                    if j >= 0:
                        col[fill[i]] = j
                        term[fill[i]] = cs[b] * wa
                        fill[i] += 1
    # per row, the terms by column (a stable insertion sort: a row holds a few dozen), summed
    rows = np.empty(ptr[n], dtype=np.int64)
    cols = np.empty(ptr[n], dtype=np.int64)
    vals = np.empty(ptr[n])
    out = 0
    for i in range(n):
        lo, hi = ptr[i], ptr[i + 1]
        for q in range(lo + 1, hi):
            cq, tq = col[q], term[q]
            p = q - 1
            while p >= lo and col[p] > cq:
                col[p + 1], term[p + 1] = col[p], term[p]
                p -= 1
            col[p + 1], term[p + 1] = cq, tq
        q = lo
        while q < hi:
            j = col[q]
            acc = 0.0
            while q < hi and col[q] == j:
                acc += term[q]
                q += 1
            if acc != 0.0:
                rows[out], cols[out], vals[out] = i, j, acc
                out += 1
    return rows[:out], cols[:out], vals[:out]


def slim_refine(
    V: np.ndarray,
    F: np.ndarray,
    uv: np.ndarray,
    *,
    vert_chart: np.ndarray | None = None,
    n_charts: int = 1,
    inv_frames: np.ndarray | None = None,
    iterations: int = SLIM_ITERATIONS,
    tol: float = SLIM_TOL,
    charts: np.ndarray | None = None,
    angle_weight: float = ANGLE_WEIGHT,
) -> tuple[np.ndarray, np.ndarray]:
    """Lower the symmetric Dirichlet energy of every chart, never flipping a triangle.

    The step direction is ``-H^-1 grad E`` with ``H`` SLIM's reweighted system at the current map
    (for the symmetric Dirichlet energy alone this is exactly SLIM's step: SLIM's proxy has the
    energy's gradient); with ``angle_weight > 0`` the same ``H`` preconditions the gradient of
    the energy plus ``angle_weight`` times the conformal term ``s1 / s2 + s2 / s1 - 2`` (also
    infinite at a flip), which trades area distortion (L2 stretch) for angle distortion.

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray
        One chart, or a disjoint union of charts (``vert_chart``); each connected.
    uv : (n, 2) float ndarray
        Starting map, in the units of ``V`` (near-isometric: the energy is not scale-free). A
        chart with a flipped or degenerate triangle is left as it is.
    vert_chart : (n,) int ndarray, optional
        Chart of every vertex, ``0 .. n_charts - 1`` (default: one chart).
    inv_frames : (m, 2, 2) float ndarray, optional
        ``inverse_frames(triangle_frames(V, F))``, if already computed.
    iterations : int
        Most SLIM iterations.
    tol : float
        A chart stops once an iteration lowers its energy's excess over 4 (the isometry's) by
        less than this fraction.
    charts : (n_charts,) bool ndarray, optional
        The charts to refine (default all); the others are left as they are.
    angle_weight : float
        Weight of the conformal term (>= 0; 0: the symmetric Dirichlet energy alone); charts of
        fewer than ``SMALL_CHART_ANGLE_FACES`` faces get ``SMALL_CHART_ANGLE_SCALE`` times it.

    Returns
    -------
    uv : (n, 2) float64 ndarray
        Every triangle positive where the start had every triangle positive; each chart's
        energy at most its starting energy.
    steps : (n_charts,) int64 ndarray
        Iterations that moved each chart (0: unchanged).

    References
    ----------
    M. Rabinovich, R. Poranne, D. Panozzo, O. Sorkine-Hornung, Scalable Locally Injective
    Mappings, ACM TOG 36(2), 2017. J. Smith, S. Schaefer, Bijective Parameterization with Free
    Boundaries, ACM TOG 34(4), 2015.
    """
    uv = np.array(uv, dtype=np.float64)
    n = len(V)
    vc = np.zeros(n, dtype=np.int64) if vert_chart is None else np.asarray(vert_chart, np.int64)
    F = np.asarray(F, dtype=np.int64)
    fc = vc[F[:, 0]]
    frames = inverse_frames(triangle_frames(V, F)) if inv_frames is None else inv_frames
    frames = np.ascontiguousarray(frames, dtype=np.float64)
    area = face_areas(V, F)
    total = np.bincount(fc, weights=area, minlength=n_charts)
    total = np.where(total > 0, total, 1.0)
    g3 = _gradient_coefficients(frames)  # (m, 2, 3)
    local = np.einsum("mki,mkj->mij", g3, g3)  # sum_k g_k g_k^T: the triangle's stiffness
    # each face's weight: its chart's (a quarter of it on charts of few faces)
    few = np.bincount(fc, minlength=n_charts)[fc] < SMALL_CHART_ANGLE_FACES
    weight = angle_weight * np.where(few, SMALL_CHART_ANGLE_SCALE, 1.0)

    def energy(x: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """Each chart's energy at the map ``x``: the charts of ``faces`` (all of their faces),
        the others 0."""
        return _chart_energies(F, faces, x, frames, weight, area, fc, total)

    E = energy(uv, np.arange(len(F)))
    active = np.isfinite(E) & (E - 4.0 > SLIM_FLOOR)
    if charts is not None:
        active &= np.asarray(charts, dtype=bool)
    steps = np.zeros(n_charts, dtype=np.int64)
    # one pinned vertex per chart (the lowest index): the energy ignores translations
    pin = np.zeros(n, dtype=bool)
    first = np.full(n_charts, n)
    np.minimum.at(first, vc, np.arange(n))
    pin[first[first < n]] = True
    stiffness = local * area[:, None, None]
    system = None
    for _ in range(iterations):
        if not active.any():
            break
        faces = np.flatnonzero(active[fc])
        W2, g = _slim_terms(F, faces, uv, frames, weight, area)
        # g[t, c, k]: coordinate c's d/dJ in column k, i.e. row k of D for coordinate c
        grad = gradient_transpose(F, faces, g3, np.ascontiguousarray(g.transpose(0, 2, 1)), n)
        grad = grad.T.ravel()  # (u, v) stacked
        move = active[vc] & ~pin
        if system is None or move.sum() < SYSTEM_REUSE * system.size:
            system = _ProxySystem(F, faces, n, stiffness)
        # SLIM's proxy sum A ||W (J - R)||^2 has gradient 2 (H x - rhs) = grad E, so its
        # minimiser is x - H^-1 grad E / 2; pinned vertices stay
        delta = -0.5 * system.solve(faces, W2, move, grad)
        d = np.stack([delta[:n], delta[n:]], axis=1)
        tau_max = _step_bounds(uv, d, F, faces, fc, n_charts)
        tau = np.where(active, np.minimum(1.0, STEP_FRACTION * tau_max), 0.0)
        new_E = np.full(n_charts, np.inf)
        trial, trial_faces = active.copy(), faces
        for _ in range(MAX_HALVINGS):  # loop over step halvings, all charts at once
            cand = uv + tau[vc][:, None] * d
            e = energy(cand, trial_faces)  # the charts still trying only
            ok = trial & (e < E)
            new_E = np.where(ok, e, new_E)
            uv = np.where(ok[vc][:, None], cand, uv)
            trial &= ~ok
            if not trial.any():
                break
            trial_faces = np.flatnonzero(trial[fc])
            tau = np.where(trial, tau / 2, tau)
        moved = np.isfinite(new_E)
        excess = np.maximum(E - 4.0, 1e-12)  # 4: the isometry's energy, the least possible
        gain = np.zeros(n_charts)
        gain[moved] = (E[moved] - new_E[moved]) / excess[moved]
        steps += moved
        E = np.where(moved, new_E, E)
        active &= moved & (gain >= tol) & (E - 4.0 > SLIM_FLOOR)
    return uv, steps


#: SLIM's system keeps its pattern (and symbolic factorization) while the charts still moving
#: hold at least this fraction of its vertices; the others' rows are identity rows meanwhile.
#: Below it the system is rebuilt over the moving charts only, so a long tail of iterations on
#: a few charts does not refactorize the whole batch.
SYSTEM_REUSE = 0.5


@njit(cache=True, nogil=True)
def proxy_layout(F, faces, n):  # pragma: no cover - compiled
    """The layout of :class:`_ProxySystem`'s matrix over the vertices of ``F[faces]``, for
    :class:`segparam.linalg.FixedPattern`, read off the faces' vertex rings (one pass each, no
    sort of the entries: ``np.unique`` of 21 keys per face was 6% of the 1M-face brain's
    parameterize stage, and its numpy replacement from the edges most of a small system's set-up).

    The matrix is ``[[A, B^T], [B, C]]`` over ``(u, v)`` of the ``m`` vertices, each block with
    the pattern of the vertex graph and its diagonal. Its lower triangle holds, in column
    ``q < m``, the rows ``r >= q`` of the ring ``nb(q)`` (``q`` and its neighbours, ascending),
    then ``m + nb(q)``; in column ``m + q``, the rows ``m + r``, ``r >= q``: column-major, rows
    ascending, exactly what ``np.unique`` of the entries' column-major keys gives. An entry's
    slot is its column's start plus its row's rank there.

    Parameters
    ----------
    F : (m_all, 3) int ndarray
    faces : (k,) int ndarray
        The faces of the system (a face may name a vertex twice).
    n : int
        Number of vertices ``F`` indexes.

    Returns
    -------
    verts : (m,) int ndarray
        The vertices of the faces, ascending (the system's vertex ``i`` is ``verts[i]``).
    local : (k, 3) int ndarray
        The faces in those indices.
    entry : (e,) int ndarray
        The lower-triangle entries of the ``(k, 36)`` table (``(a, b, i, j)`` row-major: row
        ``local[t, i] + a m``, column ``local[t, j] + b m``), in table order ...
    rows, cols : (e,) int ndarrays
        ... their rows and columns ...
    slot : (e + 2 m,) int ndarray
        ... and their slots in the pattern, followed by the ``2 m`` diagonal entries' slots.
    pattern_rows, pattern_cols : int ndarrays
        The pattern, column-major.
    """
    k = len(faces)
    index = np.full(n, -1, dtype=np.int64)
    for t in range(k):
        for c in range(3):
            index[F[faces[t], c]] = 0
    verts = number_marked(index)
    m = len(verts)
    local = np.empty((k, 3), dtype=np.int64)
    for t in range(k):
        for c in range(3):
            local[t, c] = index[F[faces[t], c]]
    # rings: each vertex itself, then the other corners of its faces; sorted, repeats dropped
    cap = np.ones(m, dtype=np.int64)
    for t in range(k):
        for c in range(3):
            cap[local[t, c]] += 2
    ring_ptr = np.zeros(m + 1, dtype=np.int64)
    for v in range(m):
        ring_ptr[v + 1] = ring_ptr[v] + cap[v]
    ring = np.empty(ring_ptr[m], dtype=np.int64)
    size = np.ones(m, dtype=np.int64)
    for v in range(m):
        ring[ring_ptr[v]] = v
    for t in range(k):
        for c in range(3):
            v = local[t, c]
            for d in range(3):
                w = local[t, d]
                if w != v:
                    ring[ring_ptr[v] + size[v]] = w
                    size[v] += 1
    below = np.zeros(m, dtype=np.int64)  # ring members under the vertex: its rank in its ring
    for v in range(m):
        a, length = ring_ptr[v], 0
        for p in range(a, a + size[v]):  # insertion of ring[p] into the sorted distinct prefix
            u, q = ring[p], a + length
            while q > a and ring[q - 1] > u:
                q -= 1
            if q > a and ring[q - 1] == u:
                continue
            for r in range(a + length, q, -1):
                ring[r] = ring[r - 1]
            ring[q] = u
            length += 1
        size[v] = length
        while ring[a + below[v]] < v:
            below[v] += 1
    start = np.zeros(2 * m + 1, dtype=np.int64)
    for v in range(m):
        above = size[v] - below[v]  # rows r >= v of the ring
        start[v + 1] = above + size[v]
        start[m + v + 1] = above
    for c in range(2 * m):
        start[c + 1] += start[c]
    pattern_rows = np.empty(start[2 * m], dtype=np.int64)
    pattern_cols = np.empty(start[2 * m], dtype=np.int64)
    for v in range(m):
        a, above = ring_ptr[v], size[v] - below[v]
        for r in range(above):
            pattern_rows[start[v] + r] = ring[a + below[v] + r]
            pattern_rows[start[m + v] + r] = m + ring[a + below[v] + r]
            pattern_cols[start[v] + r] = v
            pattern_cols[start[m + v] + r] = m + v
        for r in range(size[v]):
            pattern_rows[start[v] + above + r] = m + ring[a + r]
            pattern_cols[start[v] + above + r] = v
    # the entries: blocks (0, 0) and (1, 1) where p >= q, block (1, 0) always, (0, 1) never
    count = 0
    for t in range(k):
        for i in range(3):
            for j in range(3):
                count += 1 + 2 * (local[t, i] >= local[t, j])
    entry = np.empty(count, dtype=np.int64)
    rows = np.empty(count, dtype=np.int64)
    cols = np.empty(count, dtype=np.int64)
    slot = np.empty(count + 2 * m, dtype=np.int64)
    e = 0
    for t in range(k):
        for a in range(2):
            for b in range(2):
                for i in range(3):
                    for j in range(3):
                        p, q = local[t, i], local[t, j]
                        if a < b or (a == b and p < q):
                            continue
                        rank = 0  # of p in q's ring
                        while ring[ring_ptr[q] + rank] != p:
                            rank += 1
                        entry[e] = t * 36 + ((2 * a + b) * 3 + i) * 3 + j
                        rows[e], cols[e] = p + a * m, q + b * m
                        if a == b:
                            slot[e] = start[q + a * m] + rank - below[q]
                        else:
                            slot[e] = start[q] + size[q] - below[q] + rank
                        e += 1
    for c in range(2 * m):
        slot[count + c] = start[c]  # each column's first row is its diagonal
    return verts, local, entry, rows, cols, slot, pattern_rows, pattern_cols


#: The (k, 36) table of :class:`_ProxySystem`'s entries per face, ``(a, b, i, j)`` row-major:
#: each entry's block ``2 a + b`` and its corners ``i``, ``j``.
_A, _B, _I, _J = (x.ravel() for x in np.indices((2, 2, 3, 3)))
_BLOCK = 2 * _A + _B


class _ProxySystem:
    """Quadratic part ``H`` of SLIM's proxy ``sum_t A_t ||W_t (J_t - R_t)||_F^2`` over the stacked
    ``x = (u, v)`` of the vertices of some faces (the proxy is ``x^T H x - 2 rhs^T x + const``),
    with a fixed pattern (:class:`segparam.linalg.FixedPattern`) across iterations.

    Column ``k`` of ``J_t`` is ``c_k = (g_k . u_t, g_k . v_t)`` (``g_k`` the triangle's gradient
    coefficients, ``u_t`` its corners' values) and the term is ``sum_k (c_k - R e_k)^T W^T W
    (c_k - R e_k)``: block ``(a, b)`` of ``H`` gathers ``A_t (W^T W)_ab sum_k g_k g_k^T``, the
    triangle's stiffness (given times ``A_t``) scaled by one weight. A vertex that does not
    move (pinned, or its chart has stopped) gets an identity row and column, so its step is 0.
    """

    def __init__(self, F: np.ndarray, faces: np.ndarray, n: int, stiffness: np.ndarray) -> None:
        self.faces = faces
        verts, _, self._entry, self._rows, self._cols, slot, p_rows, p_cols = proxy_layout(
            F, faces, n
        )
        self.verts = verts
        self.size = m = len(verts)
        self._where = np.full(len(F), -1)
        self._where[faces] = np.arange(len(faces))
        self._pattern = FixedPattern(self._rows, self._cols, 2 * m, slots=(slot, p_rows, p_cols))
        # per face, entry (a, b, i, j) of the (k, 36) table: row F_i + a m, column F_j + b m
        self._stiffness = stiffness[faces][:, _I, _J]  # (k, 36), reordered like (a, b, i, j)
        self._dofs = np.concatenate([verts, verts + n])

    def solve(self, faces: np.ndarray, W2: np.ndarray, move: np.ndarray, rhs: np.ndarray):
        """``H^-1 rhs`` over all ``2 n`` values (0 for the vertices that do not move), ``H`` at
        the weights ``W2`` of ``faces`` (a subset of the system's faces)."""
        weights = np.zeros((len(self.faces), 4))
        weights[self._where[faces]] = W2.reshape(-1, 4)
        values = (weights[:, _BLOCK] * self._stiffness).ravel()[self._entry]
        free = np.concatenate([move[self.verts], move[self.verts]])
        values = values * (free[self._rows] & free[self._cols])
        solve = self._pattern.solver(np.concatenate([values, (~free).astype(np.float64)]))
        out = np.zeros(len(rhs))
        out[self._dofs] = solve(np.where(free, rhs[self._dofs], 0.0))
        return out


def _gradient_coefficients(frames: np.ndarray) -> np.ndarray:
    """``g`` (m, 2, 3): column ``k`` of triangle t's Jacobian is ``sum_j g[t, k, j] x[F[t, j]]``
    for one uv coordinate ``x`` (``J = [q1 q2] frames[t]``, ``q_j = uv[F_j] - uv[F_0]``)."""
    return np.stack([-frames[:, 0, :] - frames[:, 1, :], frames[:, 0, :], frames[:, 1, :]], axis=2)
