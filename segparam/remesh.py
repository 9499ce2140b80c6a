"""Isotropic remeshing, only where it helps the chart solver.

The Hessian solver (:mod:`segparam.parameterize`) fits a quadratic on every vertex's 1-ring, so it
needs well-shaped triangles: on slivers it folds. Remeshing is not free, though: on charts that are
already regular (valence ~6), isotropic remeshing creates valence-5 and valence-7 vertices whose
neighbourhoods then have to grow, and the solver gets worse. This module therefore

* measures the triangle quality (:func:`mesh_quality`: angles, valence, edge-length spread),
* decides from it (:func:`should_remesh`, thresholds measured by ``benchmarks/bench_remesh.py``;
  the ``"auto"`` policy, :func:`auto_policy`, leaves out the faces that the split stage maps
  exactly, without the solver, :func:`exact_faces`), and
* remeshes with pymeshlab's isotropic explicit remeshing at the edge length of an equilateral
  mesh with the input's area and face count (:func:`equal_area_edge`, so the vertex count stays
  about the same; the mean edge length overestimates it on slivers), keeping boundaries, sharp
  features and the orientation, then checks that the topology (components, boundary loops,
  Euler characteristic), manifoldness and boundary are unchanged; if not, the input is kept and
  the reason says why (:func:`remesh`).

Sharp features are edges (a dihedral angle above ``feature_angle``, which pymeshlab keeps) and
vertices (:func:`sharp_vertices`: a cone tip, a cube corner, where the angle defect is large while
every dihedral angle may be small: 500 triangles around a cone's tip meet at under a degree each,
and pymeshlab's smoothing pulled such a tip down from z = 1 to 0.92). The faces around every
sharp vertex are left out of the remeshing (pymeshlab's "remesh only selected faces"), so it
stays where it is (also where three or more sharp edges meet, which pymeshlab does not always
keep: on pymeshlab's bunny with holes one such vertex of the scan moved by 0.149); the result is
checked for every sharp vertex.

pymeshlab's remeshing first merges vertices at the same position, which undoes what cleaning did
to a non-manifold input (a vertex where two fans of faces touch becomes one copy per fan, at the
same point): the remeshed surface is then split again the way cleaning splits it
(:func:`segparam.clean.clean`) before it is checked.

References
----------
M. Botsch, L. Kobbelt, A remeshing approach to multiresolution modeling, SGP 2004.
P. Cignoni et al., MeshLab / VCGlib ``IsotropicRemeshing`` (the implementation used here).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components as _csgraph_components
from scipy.spatial import cKDTree

from .errors import ConfigError, InvalidMeshError, check_choice, check_int, check_number
from .mesh import (
    angle_defect,
    boundary_edges,
    boundary_loops,
    check_mesh,
    connected_components,
    corner_angles,
    edges,
    euler_characteristic,
    face_adjacency,
    face_areas,
    face_normals,
    interior_vertices,
    is_edge_manifold,
    is_vertex_manifold,
    mesh_arrays,
)

log = logging.getLogger(__name__)

__all__ = [
    "MeshQuality",
    "RemeshConfig",
    "RemeshResult",
    "auto_policy",
    "closest_boundary_points",
    "equal_area_edge",
    "exact_faces",
    "mesh_quality",
    "remesh",
    "sharp_vertices",
    "should_remesh",
]

MODES = ("auto", "on", "off")
#: A corner below this angle (degrees) counts as small (:attr:`MeshQuality.frac_small_angles`).
SMALL_ANGLE = 20.0

# The "auto" policy (see :func:`should_remesh`); measured by benchmarks/bench_remesh.py.
#: Remesh when at least this fraction of the faces has a corner below ``SMALL_ANGLE`` ...
MAX_FRAC_SMALL = 0.05
#: ... or when the 1st percentile of the faces' smallest angles is below this (degrees) ...
MIN_ANGLE_P1 = 10.0
#: ... but never when the connectivity is regular (interior valence std below this): the solver
#: maps regular meshes well even with thin triangles, and remeshing them made it worse (measured:
#: 4:1 and 6:1 anisotropic grids, 9/10 bijective as they are, 8/10 and 5/10 after remeshing).
REGULAR_VALENCE_STD = 0.5
#: Boundary vertices of the result may leave the input's boundary polyline by at most this
#: fraction of the target edge length (they are then snapped back onto it).
BOUNDARY_TOL = 0.05
#: Faces with an area below ``AREA_TOL * target_edge**2`` count as degenerate.
AREA_TOL = 1e-8
#: A sharp vertex of the result may be this far from its input position (times the target edge).
SHARP_TOL = 1e-6


@dataclass(frozen=True)
class RemeshConfig:
    """Options of the remesh stage.

    Attributes
    ----------
    mode : {"auto", "on", "off"}
        ``"auto"`` remeshes only when :func:`should_remesh` says so; ``"on"`` always; ``"off"``
        never (the input vertices are kept, ``--no-remesh``).
    target_edge : float or None
        Target edge length in mesh units (finite, > 0); ``None`` uses :func:`equal_area_edge`
        (the edge of an equilateral mesh with the input's area and face count), so that the
        vertex count stays about the same.
    feature_angle : float
        Edges whose dihedral angle exceeds this (degrees, 0 to 180) are sharp features and
        kept; so are vertices whose angle defect exceeds that of a cone whose opposite sides
        meet at this angle (:func:`sharp_vertices`).
    iterations : int
        Split / collapse / flip / smooth rounds, 1 to 1000 (default 5: against 10, the remeshing
        takes 30-45% less time and the atlases are as good: on 20 sliver meshes, real and
        decimated, L2 and angle distortion moved by 0.006 at most, either way, and
        ``benchmarks/bench_remesh.py`` maps as many charts bijectively; BENCHMARKS.md section
        0.1, session 21).

    Raises
    ------
    ConfigError
        If a field has the wrong type (an integer where a number is asked is fine, a bool never
        is) or is out of range; the message names the field.
    """

    mode: str = "auto"
    target_edge: float | None = None
    feature_angle: float = 30.0
    iterations: int = 5

    def __post_init__(self) -> None:
        # Every field, type first (bool is not a number here); numbers are stored as plain
        # int / float. Messages start with the key: config_from_dict adds the file and [remesh].
        checked = {
            "mode": check_choice("mode", self.mode, MODES),
            "target_edge": check_number(
                "target_edge", self.target_edge, low=0, low_open=True, optional=True
            ),
            "feature_angle": check_number("feature_angle", self.feature_angle, low=0, high=180),
            "iterations": check_int("iterations", self.iterations, low=1, high=1000),
        }
        for name, value in checked.items():
            object.__setattr__(self, name, value)


@dataclass(frozen=True)
class MeshQuality:
    """Measured triangle quality of a mesh.

    Attributes
    ----------
    min_angle_p1 : float
        1st percentile of the faces' smallest corner angles, degrees.
    min_angle : float
        Smallest corner angle, degrees.
    frac_small_angles : float
        Fraction of faces with a corner below 20 degrees.
    valence_std : float
        Standard deviation of the interior vertices' valence (0 on a regular mesh).
    frac_irregular : float
        Fraction of interior vertices whose valence is not 6.
    edge_cv : float
        Coefficient of variation (std / mean) of the edge lengths.
    mean_edge : float
        Mean edge length.
    """

    min_angle_p1: float
    min_angle: float
    frac_small_angles: float
    valence_std: float
    frac_irregular: float
    edge_cv: float
    mean_edge: float


@dataclass(frozen=True)
class RemeshResult:
    """Output of :func:`remesh`.

    Attributes
    ----------
    V : (n', 3) float64 ndarray
    F : (m', 3) int64 ndarray
        The remeshed surface, or the input arrays themselves when ``remeshed`` is False.
    remeshed : bool
    reason : str
        Why it was (not) remeshed, with the numbers.
    target_edge : float or None
        Target edge length used (None when not remeshed).
    before, after : MeshQuality
        Quality of the input and of the output (equal when not remeshed).
    """

    V: np.ndarray
    F: np.ndarray
    remeshed: bool
    reason: str
    target_edge: float | None
    before: MeshQuality
    after: MeshQuality


# ---------------------------------------------------------------------------------------------
# Quality and policy
# ---------------------------------------------------------------------------------------------


def mesh_quality(V, F) -> MeshQuality:
    """Measure the shape of a mesh's triangles and the regularity of its connectivity.

    Parameters
    ----------
    V : (n, 3) array_like of float
    F : (m, 3) array_like of int

    Returns
    -------
    MeshQuality

    Raises
    ------
    InvalidMeshError
        If the mesh is malformed (see :func:`segparam.mesh.check_mesh`).
    """
    V, F = check_mesh(V, F, allow_degenerate=True)
    return _quality(V, F)


def _quality(V: np.ndarray, F: np.ndarray) -> MeshQuality:
    min_angles = np.degrees(corner_angles(V, F).min(axis=1))
    edge_index = edges(F)  # once, for the lengths and the boundary
    E = edge_index[0]
    length = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    valence = np.bincount(E.ravel(), minlength=len(V))
    interior = interior_vertices(F, len(V), edge_index=edge_index)
    val = valence[interior]
    mean = float(length.mean())
    return MeshQuality(
        min_angle_p1=float(np.percentile(min_angles, 1)),
        min_angle=float(min_angles.min()),
        frac_small_angles=float(np.mean(min_angles < SMALL_ANGLE)),
        valence_std=float(val.std()) if len(val) else 0.0,
        frac_irregular=float(np.mean(val != 6)) if len(val) else 0.0,
        edge_cv=float(length.std() / mean) if mean > 0 else 0.0,
        mean_edge=mean,
    )


def equal_area_edge(V, F) -> float:
    """Edge length of an equilateral mesh with the same area and number of faces.

    ``sqrt(4 A / (sqrt(3) m))`` for total area ``A`` and ``m`` faces: the target that keeps the
    face count. It equals the mean edge length on an equilateral grid and is smaller on slivers
    (measured: 0.94x the mean on random Delaunay patches, 0.79x on stretched grids, where
    remeshing at the mean edge length lost 10% and 30% of the faces).

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray

    Returns
    -------
    float
    """
    return float(np.sqrt(4.0 * face_areas(V, F).sum() / (np.sqrt(3.0) * len(F))))


def should_remesh(q: MeshQuality) -> tuple[bool, str]:
    """The ``"auto"`` policy: remesh slivers, leave regular meshes alone.

    Remesh when the triangles are badly shaped (``frac_small_angles >= MAX_FRAC_SMALL`` or
    ``min_angle_p1 < MIN_ANGLE_P1``), unless the connectivity is regular
    (``valence_std < REGULAR_VALENCE_STD``): there the solver does well even on thin triangles,
    and remeshing only adds irregular (valence 5 and 7) vertices. ``edge_cv`` is reported but
    does not decide: folded regular grids reach 0.24 and map well.

    Parameters
    ----------
    q : MeshQuality

    Returns
    -------
    remesh : bool
    reason : str
        A sentence with the numbers that decided.
    """
    regular = q.valence_std < REGULAR_VALENCE_STD
    slivers = q.frac_small_angles >= MAX_FRAC_SMALL or q.min_angle_p1 < MIN_ANGLE_P1
    shape = (
        f"{100 * q.frac_small_angles:.1f}% of faces have an angle < {SMALL_ANGLE:g} deg "
        f"(limit {100 * MAX_FRAC_SMALL:g}%), 1st-percentile min angle {q.min_angle_p1:.1f} deg "
        f"(limit {MIN_ANGLE_P1:g})"
    )
    conn = (
        f"valence std {q.valence_std:.2f} (regular < {REGULAR_VALENCE_STD:g}), "
        f"{100 * q.frac_irregular:.0f}% irregular vertices, edge-length cv {q.edge_cv:.2f}"
    )
    if regular:
        return False, f"regular mesh, kept: {conn}; {shape}"
    if slivers:
        return True, f"slivers: {shape}; {conn}"
    return False, f"well-shaped triangles, kept: {shape}; {conn}"


def auto_policy(
    V: np.ndarray, F: np.ndarray, quality: MeshQuality, feature_angle: float = 30.0
) -> tuple[bool, str]:
    """The ``"auto"`` mode's decision for a checked mesh of this ``quality``
    (:func:`mesh_quality`): :func:`should_remesh`, unless the slivers lie where no solver runs:
    the faces of :func:`exact_faces` are left out of the count.

    Returns
    -------
    remesh : bool
    reason : str
    """
    return _auto_policy(V, F, quality, feature_angle)[:2]


def _auto_policy(
    V: np.ndarray, F: np.ndarray, quality: MeshQuality, feature_angle: float
) -> tuple[bool, str, np.ndarray | None]:
    """:func:`auto_policy`, and the :func:`exact_faces` it found (None when the triangles'
    quality alone decided), which :func:`remesh` then leaves out of the remeshing."""
    go, reason = should_remesh(quality)
    if not go:
        return go, reason, None
    exact = exact_faces(V, F, feature_angle)
    rest = _quality(V, F[~exact]) if exact.any() and not exact.all() else None
    if exact.all() or (rest is not None and not should_remesh(rest)[0]):
        others = "" if rest is None else f"; the other faces: {should_remesh(rest)[1]}"
        reason = (
            f"{reason}; but {100 * exact.mean():.0f}% of the faces lie in planar or developable "
            f"regions, mapped exactly whatever their shape{others}"
        )
        return False, reason, exact
    return go, reason, exact


def exact_faces(V, F, feature_angle: float = 30.0) -> np.ndarray:
    """Faces of the regions that the split stage maps exactly, without the solver, whatever the
    shape of their triangles: the regions between sharp edges (pymeshlab's test: normals more
    than ``feature_angle`` apart) whose every inner vertex is flat (angle defect within
    :data:`segparam.unfold.FLAT_TOL`): a CAD part's planar faces (projected) and its cylinders'
    and cones' sides (unrolled). A region with no inner vertex (a strip) is not counted.

    The ``"auto"`` policy counts slivers only on the other faces: the fan triangles of a turned
    part's caps are slivers that remeshing would only make curved to rounding (and the capped
    cylinder of ``benchmarks/bench_atlas.py`` 12x slower: 0.03 -> 0.39 s).

    Returns
    -------
    (m,) bool ndarray
    """
    from .unfold import FLAT_TOL

    V, F = np.asarray(V, dtype=np.float64), np.asarray(F)
    n, m = len(V), len(F)
    edge_index = edges(F)
    pairs, _, crease = _creases(V, F, feature_angle, edge_index)
    smooth = ~crease
    A = sp.coo_matrix((np.ones(int(smooth.sum())), tuple(pairs[smooth].T)), shape=(m, m))
    _, region = _csgraph_components(A, directed=False)
    # a vertex inside a region: every face around it in that region, not on the mesh boundary
    faces_region = np.repeat(region, 3)
    lo = np.full(n, region.max(initial=0) + 1)
    hi = np.full(n, -1)
    np.minimum.at(lo, F.ravel(), faces_region)
    np.maximum.at(hi, F.ravel(), faces_region)
    inner = lo == hi
    inner[boundary_edges(F, edge_index=edge_index).ravel()] = False
    total = np.bincount(F.ravel(), weights=corner_angles(V, F).ravel(), minlength=n)
    bent = inner & (np.abs(2 * np.pi - total) > FLAT_TOL)
    n_regions = int(region.max(initial=-1)) + 1
    flat = (np.bincount(lo[bent], minlength=n_regions) == 0) & (
        np.bincount(lo[inner], minlength=n_regions) > 0
    )
    return flat[region]


def sharp_vertices(V, F, feature_angle: float = 30.0) -> np.ndarray:
    """Interior vertices where the surface has a point: a cone tip, a cube corner, a spike.

    A vertex is sharp when the absolute value of its angle defect (``2 pi`` minus the sum of its
    corner angles) exceeds ``2 pi (1 - cos(feature_angle / 2))``, the defect of a circular cone
    whose opposite sides meet at ``feature_angle`` (12.3 degrees for 30; a cube corner has 90, the
    tip of a cone of half-angle 45 degrees 105). On a smooth surface the defect is the Gaussian
    curvature times the vertex's area, small at any sampling (below 4 degrees on the sample brain).
    Boundary vertices are not counted: pymeshlab keeps the boundary and its corners.

    Parameters
    ----------
    V : (n, 3) array_like of float
    F : (m, 3) array_like of int
    feature_angle : float
        Degrees; 180 or more: no vertex is sharp.

    Returns
    -------
    (k,) int64 ndarray
        The sharp vertices, sorted.
    """
    V, F = check_mesh(V, F, allow_degenerate=True)
    if feature_angle >= 180:
        return np.zeros(0, dtype=np.int64)
    limit = 2 * np.pi * (1 - np.cos(np.radians(feature_angle) / 2))
    defect = np.abs(angle_defect(V, F))
    sharp = defect > limit
    sharp[np.unique(boundary_edges(F))] = False
    sharp[np.bincount(F.ravel(), minlength=len(V)) == 0] = False
    return np.flatnonzero(sharp).astype(np.int64)


# ---------------------------------------------------------------------------------------------
# Remeshing
# ---------------------------------------------------------------------------------------------


def closest_boundary_points(
    V0: np.ndarray, F0: np.ndarray, P: np.ndarray, *, k: int = 8
) -> tuple[np.ndarray, np.ndarray]:
    """Closest points of a mesh's boundary polyline to query points.

    Checks the boundary segments incident to the ``k`` nearest boundary vertices of each point,
    which finds the closest segment unless boundary edge lengths vary by a large factor locally.

    Parameters
    ----------
    V0 : (n, 3) float ndarray
    F0 : (m, 3) int ndarray
        The mesh whose boundary is measured.
    P : (p, 3) float ndarray
        Query points.

    Returns
    -------
    distance : (p,) float64 ndarray
        ``inf`` if the mesh has no boundary.
    closest : (p, 3) float64 ndarray
        The closest boundary point (``P`` itself if the mesh has no boundary).
    """
    B = boundary_edges(F0)
    if len(B) == 0 or len(P) == 0:
        return np.full(len(P), np.inf), P.copy()
    # Index every segment by both end points, so both segments at a near vertex are tried.
    ends = np.r_[B[:, 0], B[:, 1]]
    seg = np.r_[np.arange(len(B)), np.arange(len(B))]
    k = min(k, len(ends))
    _, idx = cKDTree(V0[ends]).query(P, k=k)
    s = seg[idx.reshape(len(P), k)]
    A, D = V0[B[s, 0]], V0[B[s, 1]] - V0[B[s, 0]]
    t = ((P[:, None, :] - A) * D).sum(-1) / np.maximum((D * D).sum(-1), 1e-300)
    Q = A + np.clip(t, 0.0, 1.0)[..., None] * D
    dist = np.linalg.norm(P[:, None, :] - Q, axis=-1)
    best = dist.argmin(axis=1)
    rows = np.arange(len(P))
    return dist[rows, best], Q[rows, best]


def _creases(
    V: np.ndarray, F: np.ndarray, feature_angle: float, edge_index: tuple
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pairs of faces sharing an edge, their edge, and whether pymeshlab takes it for sharp
    (normals of the two faces more than ``feature_angle`` apart, and not folded flat back:
    cosine >= -0.98). ``edge_index`` is ``edges(F)``."""
    pairs, edge = face_adjacency(F, edge_index=edge_index)
    N = face_normals(V, F)
    cos = (N[pairs[:, 0]] * N[pairs[:, 1]]).sum(axis=1)
    return pairs, edge, (cos <= np.cos(np.radians(feature_angle))) & (cos >= -0.98)


def _topology(F: np.ndarray) -> tuple[int, int, int]:
    count, _ = connected_components(F)
    return count, len(boundary_loops(F)), euler_characteristic(F)


def _compact(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    used = np.zeros(len(V), dtype=bool)
    used[F.ravel()] = True
    new = np.cumsum(used) - 1
    return V[used], new[F]


def _run_pymeshlab(
    V: np.ndarray,
    F: np.ndarray,
    target: float,
    config: RemeshConfig,
    frozen: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """pymeshlab's isotropic explicit remeshing; faces where ``frozen`` is True are left out.

    With frozen faces only the others are selected and remeshed ("remesh only selected"): the
    filter then moves no vertex of a frozen face (its collapses need every face around the moving
    vertex selected, its smoothing only moves vertices inside the selection), and the final
    projection onto the input surface leaves points of the surface where they are.
    """
    import pymeshlab  # slow to import; only needed here

    ms = pymeshlab.MeshSet()
    only_selected = frozen is not None and bool(frozen.any())
    if only_selected:
        keep = (~frozen).astype(np.float64)
        ms.add_mesh(
            pymeshlab.Mesh(vertex_matrix=V, face_matrix=F.astype(np.int32), f_scalar_array=keep)
        )
        ms.compute_selection_by_condition_per_face(condselect="fq > 0.5")
    else:
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=V, face_matrix=F.astype(np.int32)))
    ms.meshing_isotropic_explicit_remeshing(
        iterations=int(config.iterations),
        adaptive=False,
        selectedonly=only_selected,
        targetlen=pymeshlab.PureValue(target),
        featuredeg=float(config.feature_angle),
        checksurfdist=True,
        # Keep the surface: a remeshed vertex stays within a fraction of an edge of the input.
        maxsurfdist=pymeshlab.PureValue(0.5 * target),
        splitflag=True,
        collapseflag=True,
        swapflag=True,
        smoothflag=True,
        reprojectflag=True,
    )
    m = ms.current_mesh()
    V2 = np.asarray(m.vertex_matrix(), dtype=np.float64)
    F2 = np.asarray(m.face_matrix(), dtype=np.int64)
    return _compact(V2, F2)


def _resplit(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Non-manifold edges and vertices of pymeshlab's result split the way
    :func:`segparam.clean.clean` splits an input's (its other repairs find nothing to do on a
    remeshed surface; :func:`_validate` then checks the topology against the input's)."""
    from .clean import clean

    cleaned = clean(V, F, merge_tolerance=0.0, area_tolerance=0.0)
    return cleaned.V, cleaned.F


def _orient_like(V0: np.ndarray, F0: np.ndarray, V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Flip whole components of ``(V, F)`` whose normals disagree with the input's.

    Each output face votes (area-weighted) with the sign of its normal's dot product with the
    normal of the input face nearest to its centroid; a consistently oriented component agrees
    or disagrees as a whole, so a majority vote per component is robust to the few faces whose
    nearest input face is on the other wall of a fold.

    Returns
    -------
    (m', 3) int64 ndarray
    """
    _, nearest = cKDTree(V0[F0].mean(axis=1)).query(V[F].mean(axis=1))
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    vote = (cross * face_normals(V0, F0)[nearest]).sum(axis=1)
    count, label = connected_components(F)
    flip = np.bincount(label, weights=vote, minlength=count) < 0
    if flip.any():
        log.debug("remesh: %d of %d components came back flipped", int(flip.sum()), count)
        F = np.where(flip[label, None], F[:, ::-1], F)
    return F


def _validate(
    V0: np.ndarray,
    F0: np.ndarray,
    V: np.ndarray,
    F: np.ndarray,
    target: float,
    sharp: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, str]:
    """Check the remeshed surface against the input.

    Returns ``V`` (boundary vertices snapped onto the input boundary polyline), ``F`` (with the
    input orientation) and a description of the first problem found ("" if none). ``sharp``:
    input vertices that must still be vertices of the result, in place.
    """
    if len(F) == 0:
        return V, F, "remeshing removed every face"
    if not is_edge_manifold(F) or not is_vertex_manifold(F, len(V)).all():
        return V, F, "remeshing produced a non-manifold or inconsistently oriented mesh"
    before, after = _topology(F0), _topology(F)
    if before != after:
        return (
            V,
            F,
            (
                "remeshing changed the topology (components, boundary loops, Euler characteristic) "
                f"from {before} to {after}"
            ),
        )
    F = _orient_like(V0, F0, V, F)
    B = np.unique(boundary_edges(F))
    if len(B):
        # Boundary vertices slide along the boundary and are reprojected onto the surface, not
        # onto the boundary polyline: on a curved boundary they end up off it by a sagitta
        # (measured: below 1% of an edge). Snap them back.
        dev, Q = closest_boundary_points(V0, F0, V[B])
        if dev.max() > BOUNDARY_TOL * target:
            return (
                V,
                F,
                (
                    f"a boundary vertex left the input boundary by {dev.max():.3g} "
                    f"(tolerance {BOUNDARY_TOL * target:.3g})"
                ),
            )
        V = V.copy()
        V[B] = Q
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    n_zero = int(np.sum(area <= AREA_TOL * target**2))
    if n_zero:
        return V, F, f"remeshing produced {n_zero} zero-area faces"
    if sharp is not None and len(sharp):
        moved, _ = cKDTree(V).query(V0[sharp])
        tol = SHARP_TOL * target + 1e-12 * float(np.abs(V0).max())
        if moved.max() > tol:
            n = int((moved > tol).sum())
            return V, F, f"remeshing moved {n} sharp vertices by up to {moved.max():.3g}"
    return V, F, ""


def remesh(V, F=None, *, config: RemeshConfig | None = None) -> RemeshResult:
    """Isotropic remeshing of a surface when (by ``config.mode``) it helps the chart solver.

    The result keeps the input's boundary loops (boundary vertices stay on the input boundary
    polyline), sharp edges (dihedral angle above ``config.feature_angle``), sharp vertices
    (:func:`sharp_vertices`: their faces are not remeshed), topology and face orientation. If
    pymeshlab's result breaks any of these, the input is returned unchanged and ``reason`` names
    the problem (and a warning is logged).

    Parameters
    ----------
    V : (n, 3) array_like of float
    F : (m, 3) array_like of int
        A manifold, consistently oriented triangle mesh.
    config : RemeshConfig, optional
        Defaults to ``RemeshConfig()`` (``mode="auto"``, target = :func:`equal_area_edge`).

    Returns
    -------
    RemeshResult
        With ``V``, ``F`` the very input arrays when not remeshed.

    Raises
    ------
    InvalidMeshError
        If the input mesh is malformed.
    ConfigError
        If ``config`` is not a :class:`RemeshConfig`.
    """
    config = RemeshConfig() if config is None else config
    if not isinstance(config, RemeshConfig):
        raise ConfigError(f"config must be a RemeshConfig, got {type(config).__name__}")
    V_in, F_in = V, F = mesh_arrays(V, F)  # or a trimesh.Trimesh alone
    V, F = check_mesh(V, F, allow_degenerate=True)
    before = _quality(V, F)

    def keep(reason: str) -> RemeshResult:
        log.info("remesh: input kept (%s)", reason)
        return RemeshResult(V_in, F_in, False, reason, None, before, before)

    if config.mode == "off":
        return keep("remeshing is off")
    exact = None  # the faces "auto" leaves as they are
    if config.mode == "auto":
        go, reason, exact = _auto_policy(V, F, before, config.feature_angle)
        if not go:
            return keep(reason)
    else:
        reason = "remeshing is on"
    target = float(config.target_edge) if config.target_edge is not None else equal_area_edge(V, F)
    if not target > 0:
        area = face_areas(V, F).sum()
        raise InvalidMeshError(f"the mesh has total area {area:.3g}; it cannot be remeshed")

    # Sharp vertices (cone tips, corners) stay: the faces around them are left out of the
    # remeshing. (pymeshlab keeps a vertex where three or more sharp edges meet, a cube's corner,
    # by itself, but not always: one on pymeshlab's bunny with holes moved by 0.149, and the
    # remeshing, 0.8 s, was thrown away.)
    sharp = sharp_vertices(V, F, config.feature_angle)
    frozen = np.isin(F, sharp).any(axis=1) if len(sharp) else np.zeros(len(F), dtype=bool)
    if len(sharp):
        reason = f"{reason}; {len(sharp)} sharp vertices kept in place"
    if exact is not None:
        # Under "auto" the planar and developable regions between sharp edges are left as they
        # are too: the split stage maps them exactly whatever their triangles (projected or
        # unrolled), and remeshed they are curved to rounding and go to the solver (a cone of
        # 1,536 faces whose tip is a fan of slivers: 3 charts mapped exactly in 0.14 s as it is,
        # 6 solved charts in 0.42 s remeshed).
        if exact.any():
            reason = f"{reason}; {100 * exact.mean():.0f}% of the faces (planar, developable) kept"
        frozen |= exact
    if frozen.all():
        return keep(f"{reason}: every face is kept, the input is kept")

    t0 = time.perf_counter()
    V2, F2 = _run_pymeshlab(V, F, target, config, frozen)
    if not (is_edge_manifold(F2) and is_vertex_manifold(F2, len(V2)).all()):
        # pymeshlab merged vertices at the same position: split them again as cleaning did
        # (pymeshlab's cow: the input's one non-manifold vertex, two copies after cleaning)
        V2, F2 = _resplit(V2, F2)
    V2, F2, problem = _validate(V, F, V2, F2, target, sharp)
    seconds = time.perf_counter() - t0
    if problem:
        log.warning("remesh: %s; the input is kept", problem)
        return keep(f"{problem}; the input is kept")
    after = _quality(V2, F2)
    if config.mode == "auto" and after.min_angle_p1 <= before.min_angle_p1:
        return keep(
            f"{reason}; but remeshing did not raise the 1st-percentile min angle "
            f"({before.min_angle_p1:.1f} -> {after.min_angle_p1:.1f} deg), the input is kept"
        )
    log.info(
        "remesh: %d -> %d faces in %.2f s, target edge %.4g, min-angle p1 %.1f -> %.1f deg",
        len(F),
        len(F2),
        seconds,
        target,
        before.min_angle_p1,
        after.min_angle_p1,
    )
    return RemeshResult(V2, F2, True, f"{reason}; target edge {target:.4g}", target, before, after)
