"""Synthetic cortex-like meshes for tests and benchmarks.

`brain_like_surface` builds a closed, genus-0 surface shaped like a cortical hemisphere (an
ellipsoid, flattened on the medial side, carrying a labyrinth of deep sulci);
`brain_like_parcels` cuts it into compact disk-shaped regions like the parcels of a brain atlas.

The surface is a radial graph over the unit sphere, ``V = rho(u) u``: a well-shaped triangulation of
the sphere (golden-spiral points, convex hull, midpoint subdivision) is pushed onto it, then relaxed
tangentially. Because every vertex stays a radial graph over a non-flipped sphere triangulation, the
surface is embedded (no self-intersections) and keeps the outward winding.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import ConvexHull

from segparam import mesh
from segparam.errors import InvalidMeshError

logger = logging.getLogger(__name__)

# Hemisphere semi-axes in mm: x lateral (medial side flatter), y anterior, z superior.
_RADII = np.array([45.0, 70.0, 55.0])
_MEDIAL_RADIUS = 28.0
_WAVELENGTH = 30.0  # wavelength of the fold field at frequency 1 (sulci about 15 mm apart)
_WIDTH_RATIO = 0.11  # Gaussian sulcus half-width / wavelength (FWHM about 5.5 mm)
_DEPTH_RATIO = 0.2  # sulcus depth / wavelength (6 mm deep, 1.1 x its FWHM)
_MIN_WIDTH_EDGES = 3.0  # a sulcus half-width spans at least this many mean edge lengths
_N_WAVES = 10
_RELAX_ITERATIONS = 5
_RELAX_STEP = 0.6
_MAX_HULL_FACES = 20000  # larger spheres are built by midpoint subdivision of a smaller hull


# --------------------------------------------------------------------------------------------------
# sphere triangulation


def _fibonacci_sphere(n: int) -> np.ndarray:
    i = np.arange(n, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    theta = np.pi * (1.0 + np.sqrt(5.0)) * i
    return np.column_stack([r * np.cos(theta), r * np.sin(theta), z])


def _subdivide(U: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split every triangle in 4 at its edge midpoints, projected onto the unit sphere."""
    nv = len(U)
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = np.minimum(E[:, 0], E[:, 1]) * nv + np.maximum(E[:, 0], E[:, 1])
    ukey, inv = np.unique(key, return_inverse=True)
    M = U[ukey // nv] + U[ukey % nv]
    M /= np.linalg.norm(M, axis=1, keepdims=True)
    m = inv.reshape(3, -1).T + nv  # midpoints of edges 01, 12, 20
    F2 = np.concatenate(
        [
            np.column_stack([F[:, 0], m[:, 0], m[:, 2]]),
            np.column_stack([F[:, 1], m[:, 1], m[:, 0]]),
            np.column_stack([F[:, 2], m[:, 2], m[:, 1]]),
            m,
        ]
    )
    return np.vstack([U, M]), F2


def _sphere_mesh(n_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit-sphere triangulation with ``n_faces`` faces (to within 4**levels), outward wound."""
    levels = max(0, int(np.ceil(np.log(n_faces / _MAX_HULL_FACES) / np.log(4.0))))
    n_points = max(4, int(round(n_faces / 4**levels / 2.0)) + 2)
    U = _fibonacci_sphere(n_points)
    F = ConvexHull(U).simplices.astype(np.int64)
    normal = np.cross(U[F[:, 1]] - U[F[:, 0]], U[F[:, 2]] - U[F[:, 0]])
    flip = np.einsum("ij,ij->i", normal, U[F].sum(axis=1)) < 0
    F[flip] = F[flip][:, ::-1]
    for _ in range(levels):
        U, F = _subdivide(U, F)
    return U, F


# --------------------------------------------------------------------------------------------------
# geometry


def _ellipsoid(U: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Radius, point and unit normal of the (half-flattened) ellipsoid in directions ``U``."""
    ax = np.where(U[:, 0] > 0.0, _RADII[0], _MEDIAL_RADIUS)
    r = 1.0 / np.sqrt((U[:, 0] / ax) ** 2 + (U[:, 1] / _RADII[1]) ** 2 + (U[:, 2] / _RADII[2]) ** 2)
    E = U * r[:, None]
    N = np.column_stack([E[:, 0] / ax**2, E[:, 1] / _RADII[1] ** 2, E[:, 2] / _RADII[2] ** 2])
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    return r, E, N


class _Waves:
    """Sum of plane waves ``c(x) = sum_k a_k cos(k_k . x + phase_k)`` with its gradient."""

    def __init__(self, rng: np.random.Generator, wavelength: float, irregularity: float) -> None:
        base = rng.normal(size=3)
        dirs = rng.normal(size=(_N_WAVES, 3))
        base /= np.linalg.norm(base)
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        # irregularity 0: parallel folds; 1: isotropic labyrinth with spread widths.
        dirs = (1.0 - irregularity) * base + irregularity * dirs
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        kmag = 2.0 * np.pi / wavelength * (1.0 + irregularity * rng.uniform(-0.35, 0.35, _N_WAVES))
        self.k = dirs * kmag[:, None]
        self.phase = rng.uniform(0.0, 2.0 * np.pi, _N_WAVES)
        self.amp = 1.0 + irregularity * rng.uniform(-0.5, 0.5, _N_WAVES)
        self.grad_scale = float(np.sqrt(np.sum(self.amp**2 * kmag**2) / 2.0))

    def __call__(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        arg = X[:, 0, None] * self.k[:, 0] + X[:, 1, None] * self.k[:, 1]
        arg += X[:, 2, None] * self.k[:, 2] + self.phase
        c = np.cos(arg) @ self.amp
        g = -(np.sin(arg) * self.amp) @ self.k
        return c, g


class _FoldField:
    """Radial depth of the sulci as a function of the ellipsoid point.

    Sulci run along the zero set of a random wave field ``c``; ``phi = c / |grad c|`` is a signed
    distance to that set (to first order), and the depth is a Gaussian groove in ``phi``. Hot spots
    blend in a field of higher frequency (narrower and proportionally shallower grooves).
    """

    def __init__(
        self,
        rng: np.random.Generator,
        *,
        wavelength: float,
        depth: float,
        irregularity: float,
        hot_centers: np.ndarray,
        hot_radius: float,
        hot_factor: float,
    ) -> None:
        self.width = _WIDTH_RATIO * wavelength
        self.depth = depth
        self.irregularity = irregularity
        self.low = _Waves(rng, wavelength, irregularity)
        self.width_k = rng.normal(size=3) * (2.0 * np.pi / (3.0 * wavelength))
        self.width_phase = rng.uniform(0.0, 2.0 * np.pi)
        self.hot_centers = hot_centers
        self.hot_radius = hot_radius
        self.hot_factor = hot_factor
        self.high = _Waves(rng, wavelength / hot_factor, irregularity) if len(hot_centers) else None

    def hot_weight(self, E: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        beta = np.zeros(len(E))
        dbeta = np.zeros_like(E)
        for c in self.hot_centers:
            d = E - c
            b = np.exp(-np.einsum("ij,ij->i", d, d) / (2.0 * self.hot_radius**2))
            beta += b
            dbeta -= d * (b / self.hot_radius**2)[:, None]
        over = beta > 1.0
        beta[over] = 1.0
        dbeta[over] = 0.0
        return beta, dbeta

    def __call__(self, E: np.ndarray, N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Depth (n,) and hot-spot weight (n,) at ellipsoid points ``E`` with normals ``N``."""
        c, g = self.low(E)
        scale = self.low.grad_scale
        width = np.full(len(E), self.width)
        beta = np.zeros(len(E))
        if self.high is not None:
            beta, dbeta = self.hot_weight(E)
            ch, gh = self.high(E)
            # rescale the fast field to the slow one's gradient so phi stays a distance
            ch /= self.hot_factor
            gh /= self.hot_factor
            g = (1.0 - beta)[:, None] * g + beta[:, None] * gh + (ch - c)[:, None] * dbeta
            c = (1.0 - beta) * c + beta * ch
            width *= 1.0 - beta + beta / self.hot_factor
        g -= np.einsum("ij,ij->i", g, N)[:, None] * N
        phi = c / np.sqrt(np.einsum("ij,ij->i", g, g) + (0.3 * scale) ** 2)
        width *= 1.0 + 0.3 * self.irregularity * np.cos(E @ self.width_k + self.width_phase)
        depth = self.depth * (width / self.width) * np.exp(-((phi / width) ** 2))
        return depth, beta


def _radial_surface(U: np.ndarray, field: _FoldField) -> tuple[np.ndarray, np.ndarray]:
    r, E, N = _ellipsoid(U)
    depth, beta = field(E, N)
    return U * (r - depth)[:, None], beta


def _mean_neighbor_operator(F: np.ndarray, n: int) -> sp.csr_matrix:
    A = mesh.vertex_adjacency(F, n)
    return sp.diags(1.0 / np.asarray(A.sum(axis=1)).ravel()) @ A


def _ellipsoid_area() -> float:
    # Knud Thomsen's approximation, averaged over the lateral and medial halves
    p = 1.6075
    area = 0.0
    for ax in (_RADII[0], _MEDIAL_RADIUS):
        a, b, c = ax, _RADII[1], _RADII[2]
        area += 0.5 * 4 * np.pi * (((a * b) ** p + (a * c) ** p + (b * c) ** p) / 3) ** (1 / p)
    return float(area)


def _brain_surface(
    n_faces: int,
    *,
    folding: float,
    frequency: float,
    irregularity: float,
    seed: int,
    n_hot: int = 0,
    hot_radius: float = 8.0,
    hot_factor: float = 2.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Kernel of `brain_like_surface`; also returns the per-vertex hot-spot weight (n,)."""
    rng = np.random.default_rng(seed)
    U, F = _sphere_mesh(n_faces)
    # mean edge length of the folded surface (folding adds roughly 40 % area)
    edge = np.sqrt(4.0 * 1.4 * _ellipsoid_area() / (np.sqrt(3.0) * len(F)))
    nominal = _WAVELENGTH / frequency
    # the groove must stay resolved: on coarse meshes lengthen the folds, keep their depth
    wavelength = max(nominal, _MIN_WIDTH_EDGES * edge / _WIDTH_RATIO)
    depth = folding * _DEPTH_RATIO * nominal
    hot_factor = float(np.clip(_WIDTH_RATIO * wavelength / (2.0 * edge), 1.0, hot_factor))
    hot_dirs = np.empty((0, 3))
    if n_hot > 0:
        # one hot spot at the frontal pole, the others anywhere
        pole = np.array([0.35, 1.0, 0.1]) + 0.2 * rng.normal(size=3)
        hot_dirs = np.vstack([pole, rng.normal(size=(n_hot - 1, 3))])
        hot_dirs /= np.linalg.norm(hot_dirs, axis=1, keepdims=True)
    field = _FoldField(
        rng,
        wavelength=wavelength,
        depth=depth,
        irregularity=irregularity,
        hot_centers=_ellipsoid(hot_dirs)[1] if n_hot > 0 else hot_dirs,
        hot_radius=hot_radius,
        hot_factor=hot_factor,
    )
    logger.debug(
        "brain surface: %d faces, edge %.2f mm, wavelength %.1f mm, depth %.1f mm",
        len(F),
        edge,
        wavelength,
        depth,
    )
    V, beta = _radial_surface(U, field)
    if folding > 0.0:
        # tangential relaxation: walls of sulci are stretched radially, pull vertices onto them
        L = _mean_neighbor_operator(F, len(U))
        for _ in range(_RELAX_ITERATIONS):
            N = mesh.vertex_normals(V, F, weighting="area")
            D = L @ V - V
            D -= np.einsum("ij,ij->i", D, N)[:, None] * N
            P = V + _RELAX_STEP * D
            U = P / np.linalg.norm(P, axis=1, keepdims=True)
            V, beta = _radial_surface(U, field)
    return V, F, beta


def brain_like_surface(
    n_faces: int,
    *,
    folding: float = 1.0,
    frequency: float = 1.0,
    irregularity: float = 0.5,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """A closed cortex-like surface: a folded, half-flattened ellipsoid.

    The hemisphere (semi-axes 45 / 28 mm lateral / medial, 70 mm anterior-posterior, 55 mm
    superior-inferior) carries a labyrinth of sulci along the zero set of a seeded random wave
    field. At ``folding=1`` and ``frequency=1`` sulci are about 15 mm apart, 6 mm deep and 5.5 mm
    wide at half depth. On meshes too coarse to resolve them the folds are made longer (same
    depth), so every size stays well shaped. The area gained by folding therefore depends on the
    resolution: at ``folding=1`` (seed 3) the folded area is 0.99x the smooth ellipsoid's at
    20000 faces, 1.10x at 50000 and 1.22x at 100000 (real cortex: about 2.5x).

    Parameters
    ----------
    n_faces : int
        Target number of faces (at least 100); the result has ``n_faces`` faces to within 0.1 %
        (within 1 face up to 20000, otherwise to within a multiple of 4**levels).
    folding : float
        Depth of the sulci relative to the default; 0 gives the smooth ellipsoid. Triangle quality
        is tuned for ``folding <= 1``; deeper folds give steeper walls and thinner triangles.
    frequency : float
        Fold frequency relative to the default (the folds keep their depth-to-width ratio).
    irregularity : float
        0 gives parallel folds of constant width, 1 an isotropic labyrinth with varying widths.
    seed : int
        Seed of the random fold field; the same arguments give the same bytes.

    Returns
    -------
    V : (n, 3) float ndarray
        Vertex positions in mm, centred on the origin.
    F : (m, 3) int ndarray
        Triangles, wound counter-clockwise seen from outside.

    Raises
    ------
    InvalidMeshError
        If ``n_faces < 100`` or an option is out of range.
    """
    n_faces = int(n_faces)
    if n_faces < 100:
        raise InvalidMeshError(f"n_faces is {n_faces}; a brain-like surface needs at least 100")
    if not (np.isfinite(folding) and folding >= 0.0):
        raise InvalidMeshError(f"folding is {folding}; it must be finite and >= 0")
    if not (np.isfinite(frequency) and frequency > 0.0):
        raise InvalidMeshError(f"frequency is {frequency}; it must be finite and > 0")
    if not (0.0 <= irregularity <= 1.0):
        raise InvalidMeshError(f"irregularity is {irregularity}; it must lie in [0, 1]")
    V, F, _ = _brain_surface(
        n_faces, folding=folding, frequency=frequency, irregularity=irregularity, seed=seed
    )
    return V, F


# --------------------------------------------------------------------------------------------------
# statistics


def surface_statistics(V: np.ndarray, F: np.ndarray) -> dict[str, float]:
    """Figures that tell how folded and how well triangulated a cortex-like surface is.

    Used to compare synthetic brains with a real cortex (issue 16, ``benchmarks/bench_brains.py``):

    * ``area_over_hull``: surface area / area of the convex hull (the gyrification index of
      neuroimaging; fsaverage5's pial surface: 1.65, white: 1.60);
    * ``abs_curvature``: integrated absolute Gaussian curvature / 4 pi, summing the absolute
      angle defects (``mesh.angle_defect``); 1 for any convex surface (fsaverage5 pial: 69);
    * ``min_angle_p1``, ``min_angle_p5``: 1st and 5th percentiles of the smallest angle of each
      triangle, in degrees (60 for equilateral triangles);
    * ``valence_std``: standard deviation of the vertex valence (0 for a regular mesh; 0.03 for
      an icosahedral template, whose 12 original vertices have valence 5).

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray

    Returns
    -------
    dict
        The figures above plus ``faces`` and ``vertices``.
    """
    area = float(mesh.face_areas(V, F).sum())
    hull = float(ConvexHull(V).area)
    min_angle = np.degrees(mesh.corner_angles(V, F).min(axis=1))
    valence = np.bincount(F.ravel(), minlength=len(V))
    p1, p5 = np.percentile(min_angle, [1.0, 5.0])
    return {
        "faces": int(len(F)),
        "vertices": int(len(V)),
        "area_over_hull": area / hull,
        "abs_curvature": float(np.abs(mesh.angle_defect(V, F)).sum() / (4.0 * np.pi)),
        "min_angle_p1": float(p1),
        "min_angle_p5": float(p5),
        "valence_std": float(valence.std()),
    }


# --------------------------------------------------------------------------------------------------
# topology helpers


def _is_disk(F: np.ndarray) -> bool:
    """A topological disk with exactly one boundary loop."""
    return mesh.is_disk(F, holes=False)


# --------------------------------------------------------------------------------------------------
# parcels


def _clean_region(R: np.ndarray, F: np.ndarray, adj: np.ndarray, n_rings: int = 3) -> np.ndarray:
    """Turn a face set of a closed genus-0 mesh into a topological disk (face ids, sorted).

    Works on a band of ``n_rings`` face rings around the region: drops ears and dangling pieces,
    fills notches, pinched vertices and holes enclosed by the region.
    """
    S = R
    for _ in range(n_rings):
        S = np.union1d(S, adj[S].ravel())
    local = np.full(len(F), -1, dtype=np.int64)
    local[S] = np.arange(len(S))
    ladj = local[adj[S]]  # -1 outside the band
    rim = np.any(ladj < 0, axis=1)
    LF = F[S]
    inside = np.zeros(len(S), dtype=bool)
    inside[local[R]] = True
    safe_adj = np.where(ladj < 0, len(S), ladj)
    for _ in range(20):
        before = inside.copy()
        ext = np.append(inside, False)
        n_in = ext[safe_adj].sum(axis=1)
        inside &= ~(n_in <= 1)  # ears and isolated faces
        inside |= (n_in >= 2) & ~rim  # notches
        # pinched vertices: more than two boundary edges meet there -> absorb their faces
        ext = np.append(inside, False)
        nb_in = ext[safe_adj]
        bnd = inside[:, None] & ~nb_in
        ends = np.concatenate([LF[:, [0, 1]][bnd[:, 0]], LF[:, [1, 2]][bnd[:, 1]]])
        ends = np.concatenate([ends, LF[:, [2, 0]][bnd[:, 2]]]).ravel()
        if len(ends):
            verts, deg = np.unique(ends, return_counts=True)
            pinched = verts[deg > 2]
            if len(pinched):
                inside |= np.isin(LF, pinched).any(axis=1) & ~rim
        # keep the largest piece of the region, fill holes (outside pieces not reaching the rim)
        i = np.repeat(np.arange(len(S)), 3)
        j = ladj.ravel()
        ok = j >= 0
        i, j = i[ok], j[ok]
        same = inside[i] == inside[j]
        G = sp.coo_matrix((np.ones(same.sum()), (i[same], j[same])), shape=(len(S), len(S)))
        _, lab = connected_components(G, directed=False)
        in_sizes = np.bincount(lab[inside], minlength=lab.max() + 1)
        if in_sizes.max() == 0:
            return np.empty(0, dtype=np.int64)
        inside &= lab == np.argmax(in_sizes)
        outer = np.unique(lab[rim & ~inside])
        inside |= ~np.isin(lab, outer) & ~inside
        if np.array_equal(before, inside):
            break
    return np.sort(S[inside])


def _submesh(V: np.ndarray, F: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    sub = F[faces]
    verts, inv = np.unique(sub, return_inverse=True)
    return V[verts].copy(), inv.reshape(-1, 3).astype(np.int64)


def _brain_parcels(
    n: int,
    *,
    mean_faces: int,
    min_faces: int,
    max_faces: int,
    seed: int,
    folding: float = 1.0,
    frequency: float = 1.0,
) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray]:
    """Kernel of `brain_like_parcels`; also returns per parcel whether it has a hot corner."""
    rng = np.random.default_rng(seed)
    n_regions = int(np.ceil(1.4 * n)) + 4
    n_hot = max(1, int(round(0.08 * n)))
    V, F, beta = _brain_surface(
        n_regions * mean_faces,
        folding=folding,
        frequency=frequency,
        irregularity=0.6,
        seed=int(rng.integers(2**31)),
        n_hot=n_hot,
        hot_radius=0.3 * np.sqrt(mean_faces * 0.45),
        hot_factor=2.0,
    )
    adj = mesh.face_neighbors(F)
    C = V[F].mean(axis=1)
    i = np.repeat(np.arange(len(F)), 3)
    j = adj.ravel()
    w = np.linalg.norm(C[i] - C[j], axis=1)
    G = sp.csr_matrix((w, (i, j)), shape=(len(F), len(F)))
    seeds = rng.choice(len(F), size=n_regions, replace=False)
    _, _, source = dijkstra(G, indices=seeds, min_only=True, return_predecessors=True)
    order = np.argsort(source, kind="stable")
    bounds = np.searchsorted(source[order], seeds[np.argsort(seeds)])
    groups = np.split(order, bounds[1:])
    hot_face = beta[F].mean(axis=1) > 0.5
    parcels: list[tuple[np.ndarray, np.ndarray]] = []
    hot: list[bool] = []
    for R in groups:
        faces = _clean_region(np.sort(R), F, adj)
        if not (min_faces <= len(faces) <= max_faces):
            continue
        Vp, Fp = _submesh(V, F, faces)
        if not _is_disk(Fp):
            continue
        frac = hot_face[faces].mean()
        parcels.append((Vp, Fp))
        hot.append(bool(0.05 <= frac))
    hot_arr = np.array(hot, dtype=bool)
    if len(parcels) < n:
        raise InvalidMeshError(
            f"only {len(parcels)} of {n} parcels fit in [{min_faces}, {max_faces}] faces; "
            "widen the bounds or move mean_faces towards their middle"
        )
    # keep every hot parcel up to 20 % of n, fill up with the others in seeded random order
    perm = rng.permutation(len(parcels))
    hot_idx = perm[hot_arr[perm]][: max(1, int(0.2 * n))]
    rest = perm[~np.isin(perm, hot_idx)]
    chosen = np.sort(np.concatenate([hot_idx, rest])[:n])
    return [parcels[k] for k in chosen], hot_arr[chosen]


def brain_like_parcels(
    n: int = 89,
    *,
    mean_faces: int = 1000,
    min_faces: int = 300,
    max_faces: int = 3000,
    folding: float = 1.0,
    frequency: float = 1.0,
    seed: int = 0,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Disk-shaped sub-meshes cut from a folded hemisphere like the regions of a brain atlas.

    One `brain_like_surface`-style hemisphere (about ``1.4 n mean_faces`` faces, with a few hot
    spots of doubled fold frequency, one at the frontal pole) is split into geodesic Voronoi
    regions around seeded random face seeds (multi-source Dijkstra on the face graph); each region
    is cleaned into a topological disk, and ``n`` of those within the size bounds are returned.
    About 10-20 % of them carry high-frequency folding in part of their area, like the frontal
    pole parcel of the Desikan atlas.

    Parameters
    ----------
    n : int
        Number of parcels (the Desikan atlas has 89 in the paper's set-up).
    mean_faces : int
        Target mean face count of a parcel.
    min_faces, max_faces : int
        Bounds on each parcel's face count.
    folding, frequency : float
        Fold depth and frequency of the hemisphere (see :func:`brain_like_surface`).
    seed : int
        Seed; the same arguments give the same bytes.

    Returns
    -------
    parcels : list of (V, F)
        ``V`` (k, 3) float ndarray and ``F`` (l, 3) int ndarray with only referenced vertices,
        wound outward. Each is connected, manifold, with Euler characteristic 1 and one boundary
        loop.

    Raises
    ------
    InvalidMeshError
        If the options are inconsistent or too few regions fit the bounds.
    """
    n, mean_faces, min_faces, max_faces = int(n), int(mean_faces), int(min_faces), int(max_faces)
    if n < 1:
        raise InvalidMeshError(f"n is {n}; at least 1 parcel is needed")
    if not (20 <= min_faces <= mean_faces <= max_faces):
        raise InvalidMeshError(
            f"need 20 <= min_faces ({min_faces}) <= mean_faces ({mean_faces}) "
            f"<= max_faces ({max_faces})"
        )
    parcels, _ = _brain_parcels(
        n,
        mean_faces=mean_faces,
        min_faces=min_faces,
        max_faces=max_faces,
        seed=seed,
        folding=folding,
        frequency=frequency,
    )
    return parcels
