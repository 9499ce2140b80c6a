"""Bijectivity and distortion of a chart map ``(V, F) -> uv``.

Bijectivity is decided from three vectorized checks, each with its own count:

* flipped or degenerate uv triangles, relative to the input winding;
* local injectivity: the uv angle sum is ``2 pi`` at interior vertices and below ``2 pi`` at
  boundary vertices (a flip-free map can still wrap twice around a branch point);
* the uv boundary loops are simple, disjoint, the outer one counter-clockwise and holes clockwise.

With every triangle positive, the number of uv pre-images of a point equals the sum of the
winding numbers of the uv boundary loops around it; the loop checks make that sum 0 or 1, so the
three checks together prove the map one-to-one.

Distortion follows Sander et al. 2001 and the usual definitions, from the singular values
``s1 >= s2`` of each triangle's Jacobian (surface -> uv) after the uv are scaled so that the total
uv area equals the total 3-D area, weighted by 3-D triangle area.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial import cKDTree

from .mesh import boundary_edges, boundary_loops, corner_angles, face_areas

__all__ = [
    "ChartQuality",
    "boundary_crossings",
    "chart_quality",
    "distortion",
    "inverse_frames",
    "jacobians",
    "seam_length",
    "signed_areas",
    "triangle_frames",
]

#: Relative uv area below which a triangle counts as degenerate.
DEGENERATE_AREA = 1e-12
#: Tolerance on uv angle sums (radians).
ANGLE_TOL = 1e-6


@dataclass(frozen=True)
class ChartQuality:
    """Quality figures of one chart map.

    Attributes
    ----------
    n_flipped : int
        uv triangles with the opposite orientation of the input winding.
    n_degenerate : int
        uv triangles of (near) zero area.
    n_branch : int
        Vertices whose uv angle sum breaks local injectivity.
    n_crossings : int
        Pairs of uv boundary edges that intersect (not counting shared endpoints).
    loops_oriented : bool
        Outer uv loop counter-clockwise, every other loop clockwise.
    bijective : bool
        None of the above fails.
    l2_stretch, linf_stretch : float
        Sander's L2 and L-infinity stretch of the map uv -> surface (1 for an isometry).
    angle_distortion : float
        Area-weighted mean of ``s1 / s2`` (1 for a conformal map).
    area_distortion : float
        Area-weighted mean of ``|log(s1 s2)|`` (0 for an area-preserving map).
    symmetric_dirichlet : float
        Area-weighted mean of ``s1^2 + s2^2 + s1^-2 + s2^-2`` (4 for an isometry).
    """

    n_flipped: int
    n_degenerate: int
    n_branch: int
    n_crossings: int
    loops_oriented: bool
    bijective: bool
    l2_stretch: float
    linf_stretch: float
    angle_distortion: float
    area_distortion: float
    symmetric_dirichlet: float

    def as_dict(self) -> dict:
        """Plain-Python dictionary (for JSON reports)."""
        return {k: (v.item() if isinstance(v, np.generic) else v) for k, v in asdict(self).items()}


def signed_areas(uv: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Signed uv triangle areas, positive for counter-clockwise.

    Returns
    -------
    (m,) float64 ndarray
    """
    a = uv[F[:, 1]] - uv[F[:, 0]]
    b = uv[F[:, 2]] - uv[F[:, 0]]
    return 0.5 * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])


def triangle_frames(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Edge vectors of every triangle in its own orthonormal frame (x along the first edge).

    Returns
    -------
    (m, 2, 2) float64 ndarray
        Columns are ``V[F1] - V[F0]`` and ``V[F2] - V[F0]`` in the triangle's frame.
    """
    e1 = V[F[:, 1]] - V[F[:, 0]]
    e2 = V[F[:, 2]] - V[F[:, 0]]
    len1 = np.linalg.norm(e1, axis=1)
    x = e1 / len1[:, None]
    y = np.cross(np.cross(e1, e2), x)
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    P = np.zeros((len(F), 2, 2))
    P[:, 0, 0] = len1
    P[:, 0, 1] = (e2 * x).sum(axis=1)
    P[:, 1, 1] = (e2 * y).sum(axis=1)
    return P


def jacobians(
    V: np.ndarray, F: np.ndarray, uv: np.ndarray, inv_frames: np.ndarray | None = None
) -> np.ndarray:
    """Jacobian of the affine map from each 3-D triangle (in its own orthonormal frame) to uv.

    `inv_frames`, ``inverse_frames(triangle_frames(V, F))``, may be passed when the same
    triangles are measured several times (it is most of the cost).

    Returns
    -------
    (m, 2, 2) float64 ndarray
        ``J[f] @ p`` maps a vector ``p`` of triangle ``f``'s frame to uv; ``det J < 0`` on flips.
    """
    Q = np.stack([uv[F[:, 1]] - uv[F[:, 0]], uv[F[:, 2]] - uv[F[:, 0]]], axis=2)
    if inv_frames is None:
        inv_frames = inverse_frames(triangle_frames(V, F))
    return Q @ inv_frames


def inverse_frames(P: np.ndarray) -> np.ndarray:
    """Inverses of the upper-triangular ``(m, 2, 2)`` frames of :func:`triangle_frames`.

    ``[[a, b], [0, c]]^-1 = [[1/a, -b/(a c)], [0, 1/c]]``: closed form, several times faster than
    ``np.linalg.inv`` on stacks of 2x2 matrices.
    """
    a, b, c = P[:, 0, 0], P[:, 0, 1], P[:, 1, 1]
    out = np.zeros_like(P)
    out[:, 0, 0] = 1.0 / a
    out[:, 0, 1] = -b / (a * c)
    out[:, 1, 1] = 1.0 / c
    return out


def singular_values(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Singular values ``s1 >= s2 >= 0`` of stacked 2x2 matrices, in closed form.

    ``s1, s2 = (|z1| +- |z2|) / 2`` with ``z1 = (a + d, c - b)``, ``z2 = (a - d, b + c)`` (the
    conformal / anti-conformal split), which stays accurate near isometries, where the textbook
    ``sqrt(tr^2 - 4 det^2)`` form cancels.
    """
    a, b = J[:, 0, 0], J[:, 0, 1]
    c, d = J[:, 1, 0], J[:, 1, 1]
    q = np.hypot(a + d, c - b)
    r = np.hypot(a - d, b + c)
    return (q + r) / 2, np.abs(q - r) / 2


def boundary_crossings(uv: np.ndarray, B: np.ndarray) -> int:
    """Count intersecting pairs among uv boundary segments that share no endpoint.

    Candidate pairs come from a k-d tree on segment midpoints (two segments can only meet if their
    midpoints are closer than the longest segment), so the cost is near-linear.

    Parameters
    ----------
    uv : (n, 2) float ndarray
    B : (b, 2) int ndarray
        Boundary segments (vertex pairs).
    """
    if len(B) < 2:
        return 0
    P0, P1 = uv[B[:, 0]], uv[B[:, 1]]
    mid = 0.5 * (P0 + P1)
    r = float(np.linalg.norm(P1 - P0, axis=1).max())
    pairs = cKDTree(mid).query_pairs(r * (1 + 1e-9), output_type="ndarray")
    if len(pairs) == 0:
        return 0
    return int(segment_pairs_cross(P0, P1, B, pairs[:, 0], pairs[:, 1]).sum())


def segment_pairs_cross(
    P0: np.ndarray, P1: np.ndarray, B: np.ndarray, i: np.ndarray, j: np.ndarray
) -> np.ndarray:
    """Whether segments ``i`` and ``j`` (``P0[k] -> P1[k]``, edge ``B[k]``) meet, per pair;
    pairs that share an endpoint index are not crossings (False)."""
    shared = (
        (B[i, 0] == B[j, 0]) | (B[i, 0] == B[j, 1]) | (B[i, 1] == B[j, 0]) | (B[i, 1] == B[j, 1])
    )
    a, b, c, d = P0[i], P1[i], P0[j], P1[j]

    def orient(p, q, s):
        return (q[:, 0] - p[:, 0]) * (s[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (s[:, 0] - p[:, 0])

    d1, d2 = orient(c, d, a), orient(c, d, b)
    d3, d4 = orient(a, b, c), orient(a, b, d)
    # Segments that meet have overlapping boxes. The orientation signs alone are rounding for
    # nearly collinear segments: the straight borders of an exact isometry (an unrolled
    # cylinder's rim) read as crossing disjoint segments further along the same line.
    boxes = (
        np.maximum(np.minimum(a, b), np.minimum(c, d))
        <= np.minimum(np.maximum(a, b), np.maximum(c, d))
    ).all(axis=1)
    hit = (d1 * d2 <= 0) & (d3 * d4 <= 0) & boxes
    collinear = (d1 == 0) & (d2 == 0)
    if collinear.any():
        # Collinear segments meet only if their projections on the common line overlap.
        t = b - a
        pa, pb = (a * t).sum(1), (b * t).sum(1)
        pc, pd = (c * t).sum(1), (d * t).sum(1)
        overlap = np.maximum(np.minimum(pa, pb), np.minimum(pc, pd)) <= np.minimum(
            np.maximum(pa, pb), np.maximum(pc, pd)
        )
        hit &= ~collinear | overlap
    return hit & ~shared


def _loop_area(uv: np.ndarray, loop: np.ndarray) -> float:
    p, q = uv[loop], uv[np.roll(loop, -1)]
    return 0.5 * float((p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]).sum())


def angle_sum_violations(
    uv: np.ndarray, F: np.ndarray, n: int, *, boundary: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices where the uv map is not locally injective, from the uv angle sums around them.

    Returns (interior_bad, boundary_bad, B): an interior vertex whose angles do not sum to 2 pi
    (within `ANGLE_TOL`), a boundary vertex whose angles sum to more than 2 pi, and the boundary
    edges ``B`` (of any number of charts: the faces ``F`` may hold several; ``boundary`` when
    the caller already has them).
    """
    angle_sum = np.bincount(F.ravel(), weights=corner_angles(uv, F).ravel(), minlength=n)
    B = boundary_edges(F) if boundary is None else boundary
    on_boundary = np.zeros(n, dtype=bool)
    on_boundary[B.ravel()] = True
    used = np.bincount(F.ravel(), minlength=n) > 0
    interior_bad = used & ~on_boundary & (np.abs(angle_sum - 2 * np.pi) > ANGLE_TOL)
    boundary_bad = on_boundary & (angle_sum > 2 * np.pi + ANGLE_TOL)
    return interior_bad, boundary_bad, B


def chart_quality(
    V: np.ndarray,
    F: np.ndarray,
    uv: np.ndarray,
    inv_frames: np.ndarray | None = None,
    *,
    boundary: tuple[np.ndarray, list[np.ndarray]] | None = None,
) -> ChartQuality:
    """Bijectivity checks and distortion of the chart map ``(V, F) -> uv``.

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray
        A connected, manifold chart with at least one boundary loop.
    uv : (n, 2) float ndarray
    inv_frames : (m, 2, 2) float ndarray, optional
        ``inverse_frames(triangle_frames(V, F))``, if already computed (see :func:`jacobians`).
    boundary : (B, loops), optional
        ``boundary_edges(F)`` and ``boundary_loops(F)``, if already computed (they depend on
        ``F`` alone: a caller measuring several maps of one chart computes them once).

    Returns
    -------
    ChartQuality
    """
    sa = signed_areas(uv, F)
    total_uv = float(np.abs(sa).sum())
    degenerate = np.abs(sa) <= DEGENERATE_AREA * max(total_uv, np.finfo(float).tiny)
    flipped = (sa < 0) & ~degenerate

    # Local injectivity from uv angle sums.
    n = len(V)
    B, loops = (None, None) if boundary is None else boundary
    interior_bad, boundary_bad, B = angle_sum_violations(uv, F, n, boundary=B)
    n_branch = int((interior_bad | boundary_bad).sum())

    n_cross = boundary_crossings(uv, B)
    loops = boundary_loops(F, boundary=B) if loops is None else loops
    areas = np.array([_loop_area(uv, loop) for loop in loops])
    if len(areas):
        outer = int(np.argmax(np.abs(areas)))
        oriented = bool(areas[outer] > 0 and np.all(np.delete(areas, outer) < 0))
    else:
        oriented = False

    bijective = (
        not flipped.any() and not degenerate.any() and n_branch == 0 and n_cross == 0 and oriented
    )

    d = distortion(V, F, uv, inv_frames)
    return ChartQuality(
        n_flipped=int(flipped.sum()),
        n_degenerate=int(degenerate.sum()),
        n_branch=n_branch,
        n_crossings=n_cross,
        loops_oriented=oriented,
        bijective=bool(bijective),
        **d,
    )


def distortion(
    V: np.ndarray, F: np.ndarray, uv: np.ndarray, inv_frames: np.ndarray | None = None
) -> dict[str, float]:
    """Area-weighted distortion of ``(V, F) -> uv`` after scaling uv area to 3-D area.

    Works on any set of triangles (one chart or a whole atlas with seams): each face is measured
    on its own. `inv_frames` as in :func:`jacobians`.

    Returns
    -------
    dict
        ``l2_stretch``, ``linf_stretch`` (Sander et al. 2001, of the map uv -> surface, 1 for an
        isometry), ``angle_distortion`` (mean ``s1 / s2``), ``area_distortion`` (mean
        ``|log(s1 s2)|``), ``symmetric_dirichlet`` (mean ``s1^2 + s2^2 + s1^-2 + s2^-2``).
    """
    area3 = face_areas(V, F)
    total3 = float(area3.sum())
    total_uv = float(np.abs(signed_areas(uv, F)).sum())
    scale = np.sqrt(total3 / total_uv) if total_uv > 0 else 1.0
    s1, s2 = singular_values(jacobians(V, F, uv * scale, inv_frames))
    w = area3 / total3
    with np.errstate(divide="ignore", invalid="ignore"):
        inv1, inv2 = 1.0 / s1, 1.0 / s2  # singular values of the inverse map uv -> surface
        return {
            "l2_stretch": float(np.sqrt((w * (inv1**2 + inv2**2) / 2).sum())),
            "linf_stretch": float(inv2.max()),
            "angle_distortion": float((w * (s1 / s2)).sum()),
            "area_distortion": float((w * np.abs(np.log(s1 * s2))).sum()),
            "symmetric_dirichlet": float((w * (s1**2 + s2**2 + inv1**2 + inv2**2)).sum()),
        }


def seam_length(V: np.ndarray, F: np.ndarray, uv_F: np.ndarray, uv_vertex: np.ndarray) -> float:
    """Total 3-D length of an atlas' seams: mesh edges whose two faces have different uv rows.

    An edge of the uv mesh ``uv_F`` with one face is a seam side or a boundary edge of the
    mesh; the mesh's own boundary is subtracted and every seam has two sides. Divide by
    ``sqrt`` of the surface area for a scale-free figure (a unit square cut once across has 1).

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray
        The mesh (edge-manifold).
    uv_F : (m, 3) int ndarray
        The atlas' faces in uv rows, in the order of ``F``.
    uv_vertex : (k,) int ndarray
        Mesh vertex of every uv row.
    """
    B3 = boundary_edges(F)
    P = uv_vertex[boundary_edges(uv_F)]
    cut = np.linalg.norm(V[B3[:, 0]] - V[B3[:, 1]], axis=1).sum()
    total = np.linalg.norm(V[P[:, 0]] - V[P[:, 1]], axis=1).sum()
    return float(total - cut) / 2
