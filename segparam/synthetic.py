"""Synthetic cortex-like meshes for tests and benchmarks.

`brain_like_surface` builds a closed, genus-0 surface shaped like a cortical hemisphere (an
ellipsoid, flattened on the medial side, carrying a labyrinth of deep sulci);
`brain_like_parcels` cuts it into compact disk-shaped regions like the parcels of a brain atlas;
`surface_statistics` measures how folded a surface is, and `save_gifti` writes a surface as
neuroimaging tools do.

Two fold styles. ``"cortex"`` (the default) is as folded as a real cortex: surface area / convex
hull area and integrated |Gaussian curvature| within 15 % of fsaverage5's pial surface (1.65 and
69 x 4 pi) at every size from 5k to 1M faces (``benchmarks/bench_brains.py``), with deep primary
sulci (18 mm, walls up to 70 degrees steep) and shallower secondary ones. ``"gentle"`` is the
earlier, much easier surface (1.03 and 4.6 at 20k faces).

The surface is a radial graph over the unit sphere, ``V = rho(u) u``: a well-shaped triangulation of
the sphere (golden-spiral points, convex hull, midpoint subdivision) is pushed onto it, then relaxed
tangentially. Because every vertex stays a radial graph over a non-flipped sphere triangulation, the
surface is embedded (no self-intersections) and keeps the outward winding.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg  # noqa: F401  (sp.linalg.eigsh)
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

# "cortex" style. Primary sulci: the zero set of a wave field of wavelength 38 mm, Gaussian grooves
# 17.9 mm deep and 5.7 mm wide (1/e half-width): the gyrification of fsaverage5's pial surface
# (area / hull 1.46-1.61 against 1.65, seeds 0-2, 5k-1M faces; deeper grooves raise it but push
# |K| past the band at 20k). Secondary sulci: a second field at 18 mm.
_CORTEX_WAVELENGTH = 38.0
_CORTEX_DEPTH_RATIO = 0.47
_CORTEX_WIDTH_RATIO = 0.15
_CORTEX_IRREGULARITY = 0.6
# Plane waves per fold field: with 10 (the gentle style's) the figures vary by +-15 % between
# seeds, because a few waves make a few long parallel folds; 32 make a homogeneous labyrinth.
_CORTEX_WAVES = 32
_SECONDARY_WAVELENGTH = 18.0
# Depth of the secondary grooves / their wavelength, per face count (interpolated in log size).
# The discrete integrated |K| of a mesh is the surface's plus its sampling error, which is large on
# coarse meshes and fades on fine ones; this depth was calibrated (seeds 0-2) so that the sum
# stays near fsaverage5 pial's 69 x 4 pi: without secondary grooves the mean over seeds 0-2
# measured 58 / 72 / 64 / 55 at 5k / 20k / 80k / 320k faces; with them 62-69, 67-78, 65-73,
# 69-74, and 62-66 at 1M (seeds 0-1).
_SECONDARY_DEPTH_TABLE = (
    (5_000.0, 20_000.0, 80_000.0, 320_000.0, 1_300_000.0),
    (0.08, 0.0, 0.025, 0.05, 0.05),
)
# Regular (icosahedral) meshes sample the folds with less error, so they measure less |K|
# (58-69 for seeds 0-2 from 5k to 320k faces with the table above): their secondary grooves are
# deeper by this much.
_ICOSAHEDRAL_SECONDARY_EXTRA = 0.015
_CORTEX_RELAX_ITERATIONS = 10  # at the base level (<= 20k faces); 2 more after each subdivision
_CORTEX_FINE_RELAX_ITERATIONS = 2
# Finer levels are not relaxed: midpoint subdivision of a relaxed mesh keeps its shapes, and
# relaxing 1M faces would triple the generation time.
_MAX_RELAX_FACES = 400_000
# White surface: 2.5 mm of cortex under the pial one (a typical cortical thickness), its grooves
# 1 mm wider (sulci open up, gyral crowns thin down). Widening by 1 mm measured |K| / 4 pi 57-60
# at 5k-80k faces (fsaverage5 white: 61) and area / hull 1.42-1.49 (1.60); by 2.5 mm 49-53 and
# 1.33-1.39; by 0, 65-72 and 1.49-1.56 (the pial surface's).
_THICKNESS = 2.5
_WHITE_WIDENING = 1.0


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


def _hull_sphere(U: np.ndarray) -> np.ndarray:
    """Outward-wound convex hull triangles of points on the unit sphere."""
    F = ConvexHull(U).simplices.astype(np.int64)
    normal = np.cross(U[F[:, 1]] - U[F[:, 0]], U[F[:, 2]] - U[F[:, 0]])
    flip = np.einsum("ij,ij->i", normal, U[F].sum(axis=1)) < 0
    F[flip] = F[flip][:, ::-1]
    return F


def _sphere_base(n_faces: int, connectivity: str) -> tuple[np.ndarray, np.ndarray, int]:
    """Base sphere triangulation and the number of subdivisions that bring it to ``n_faces``.

    ``"uniform"``: golden-spiral points (at most ``_MAX_HULL_FACES`` faces, then subdivided);
    ``"icosahedral"``: the icosahedron, subdivided like FreeSurfer's templates (20 4**k faces,
    the level nearest ``n_faces`` in log scale; every vertex of valence 6 but the 12 original).
    """
    if connectivity == "icosahedral":
        levels = max(0, int(round(np.log(n_faces / 20.0) / np.log(4.0))))
        t = (1.0 + np.sqrt(5.0)) / 2.0
        U = np.array(
            [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t]]
            + [[0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
            dtype=np.float64,
        )
        U /= np.linalg.norm(U, axis=1, keepdims=True)
        return U, _hull_sphere(U), levels
    levels = max(0, int(np.ceil(np.log(n_faces / _MAX_HULL_FACES) / np.log(4.0))))
    n_points = max(4, int(round(n_faces / 4**levels / 2.0)) + 2)
    U = _fibonacci_sphere(n_points)
    return U, _hull_sphere(U), levels


def _sphere_mesh(n_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit-sphere triangulation with ``n_faces`` faces (to within 4**levels), outward wound."""
    U, F, levels = _sphere_base(n_faces, "uniform")
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

    def __init__(
        self,
        rng: np.random.Generator,
        wavelength: float,
        irregularity: float,
        n_waves: int = _N_WAVES,
    ) -> None:
        base = rng.normal(size=3)
        dirs = rng.normal(size=(n_waves, 3))
        base /= np.linalg.norm(base)
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        # irregularity 0: parallel folds; 1: isotropic labyrinth with spread widths.
        dirs = (1.0 - irregularity) * base + irregularity * dirs
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        kmag = 2.0 * np.pi / wavelength * (1.0 + irregularity * rng.uniform(-0.35, 0.35, n_waves))
        self.k = dirs * kmag[:, None]
        self.phase = rng.uniform(0.0, 2.0 * np.pi, n_waves)
        self.amp = 1.0 + irregularity * rng.uniform(-0.5, 0.5, n_waves)
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


class _CortexField:
    """Radial depth of the "cortex" style: primary and secondary Gaussian grooves.

    Each family of sulci runs along the zero set of a random wave field ``c`` (`_Waves`);
    ``phi = c / |grad c|`` (tangential gradient, regularized where it vanishes) is a signed
    distance to that set, and a groove is ``depth exp(-(phi / width)^2)``. Depths add.
    """

    def __init__(
        self,
        rng: np.random.Generator,
        *,
        frequency: float,
        folding: float,
        irregularity: float,
        secondary: float,
        widen: float = 0.0,
    ) -> None:
        self.levels = []
        for wavelength, depth_ratio in (
            (_CORTEX_WAVELENGTH / frequency, _CORTEX_DEPTH_RATIO),
            (_SECONDARY_WAVELENGTH / frequency, secondary),
        ):
            waves = _Waves(rng, wavelength, irregularity, _CORTEX_WAVES)
            width = _CORTEX_WIDTH_RATIO * wavelength
            self.levels.append((waves, folding * depth_ratio * wavelength, width))
        self.widen = widen

    def with_widening(self, widen: float) -> _CortexField:
        """The same field with every groove wider by ``widen`` mm (the white surface's)."""
        other = object.__new__(_CortexField)
        other.levels, other.widen = self.levels, widen
        return other

    def __call__(self, E: np.ndarray, N: np.ndarray) -> np.ndarray:
        depth = np.zeros(len(E))
        for waves, amplitude, width in self.levels:
            c, g = waves(E)
            g -= np.einsum("ij,ij->i", g, N)[:, None] * N
            phi = c / np.sqrt(np.einsum("ij,ij->i", g, g) + (0.3 * waves.grad_scale) ** 2)
            depth += amplitude * np.exp(-((phi / (width + self.widen)) ** 2))
        return depth


def _cortex_positions(U: np.ndarray, field: _CortexField, inset: float = 0.0) -> np.ndarray:
    r, E, N = _ellipsoid(U)
    return U * (r - inset - field(E, N))[:, None]


def _relax_on_sphere(
    U: np.ndarray, F: np.ndarray, field: _CortexField, iterations: int
) -> tuple[np.ndarray, np.ndarray]:
    """Move the sphere directions towards the neighbours they are far from on the surface.

    Each step replaces every direction by the average of itself and of its neighbours weighted
    by the 3-D edge lengths, renormalized: vertices drift into the steep sulcal walls, which the
    radial graph stretches, so the wall triangles keep a fair shape. A convex combination of
    nearby directions keeps the sphere triangulation unflipped, so the surface stays embedded.
    """
    A = mesh.vertex_adjacency(F, len(U)).tocsr()
    rows = np.repeat(np.arange(len(U)), np.diff(A.indptr))
    cols = A.indices
    V = _cortex_positions(U, field)
    for _ in range(iterations):
        A.data = np.linalg.norm(V[rows] - V[cols], axis=1)
        P = (A @ U) / np.asarray(A.sum(axis=1))
        U = 0.5 * U + 0.5 * P
        U /= np.linalg.norm(U, axis=1, keepdims=True)
        V = _cortex_positions(U, field)
    return U, V


def _cortex_surface(
    n_faces: int,
    *,
    folding: float,
    frequency: float,
    irregularity: float,
    connectivity: str,
    seed: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Kernel of the "cortex" style: pial positions, white positions (same order), faces."""
    rng = np.random.default_rng(seed)
    U, F, levels = _sphere_base(n_faces, connectivity)
    final_faces = len(F) * 4**levels
    secondary = float(
        np.interp(np.log(final_faces), np.log(_SECONDARY_DEPTH_TABLE[0]), _SECONDARY_DEPTH_TABLE[1])
    )
    if connectivity == "icosahedral":
        secondary += _ICOSAHEDRAL_SECONDARY_EXTRA
    field = _CortexField(
        rng,
        frequency=frequency,
        folding=folding,
        irregularity=irregularity,
        secondary=secondary,
    )
    V = None
    for level in range(levels + 1):
        if level > 0:
            U, F = _subdivide(U, F)
            V = None
        if folding > 0.0 and len(F) <= _MAX_RELAX_FACES:
            n_iter = _CORTEX_RELAX_ITERATIONS if level == 0 else _CORTEX_FINE_RELAX_ITERATIONS
            U, V = _relax_on_sphere(U, F, field, n_iter)
    if V is None:
        V = _cortex_positions(U, field)
    W = _cortex_positions(U, field.with_widening(_WHITE_WIDENING), inset=_THICKNESS)
    logger.debug("cortex surface: %d faces, secondary depth ratio %.3f", len(F), secondary)
    return V, W, F


STYLES = ("cortex", "gentle")
CONNECTIVITIES = ("uniform", "icosahedral")
SURFACES = ("pial", "white")


def brain_like_surface(
    n_faces: int,
    *,
    style: str = "cortex",
    folding: float = 1.0,
    frequency: float = 1.0,
    irregularity: float | None = None,
    connectivity: str = "uniform",
    surface: str = "pial",
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """A closed cortex-like surface: a folded, half-flattened ellipsoid.

    The hemisphere (semi-axes 45 / 28 mm lateral / medial, 70 mm anterior-posterior, 55 mm
    superior-inferior) carries a labyrinth of sulci along the zero set of a seeded random wave
    field. The surface is a radial graph over a sphere triangulation that is never flipped, so it
    is embedded (no self-intersections) at every size.

    ``style="cortex"`` (default): as folded as a real cortex. Primary sulci every 38 mm, 17.9 mm
    deep, 9.5 mm wide at half depth (walls up to 70 degrees steep), and secondary sulci every
    18 mm. Measured against fsaverage5's pial surface (area / hull 1.65, integrated |K| / 4 pi
    69; ``benchmarks/bench_brains.py``, seeds 0-2): area / hull 1.46-1.61 and |K| / 4 pi 62-78
    from 5k to 1M faces (1M faces in about 10 s). The secondary depth is calibrated per size
    because the sampling error of a coarse mesh adds to its measured curvature (see
    ``_SECONDARY_DEPTH_TABLE``).

    ``style="gentle"``: the earlier surface, sulci 15 mm apart, 6 mm deep and 5.5 mm wide at
    half depth at ``folding=1``, made longer (same depth) on meshes too coarse to resolve them:
    area / hull 1.03 and |K| / 4 pi 4.6 at 20k faces.

    Parameters
    ----------
    n_faces : int
        Target number of faces (at least 100). ``connectivity="uniform"``: within 0.1 % (within
        1 face up to 20000, otherwise to within a multiple of 4**levels);
        ``"icosahedral"``: the nearest 20 x 4**k in log scale (5120, 20480, 81920, ...).
    style : {"cortex", "gentle"}
        Fold style (above).
    folding : float
        Depth of the sulci relative to the style's; 0 gives the smooth ellipsoid. The cortex
        style's statistics hold at ``folding=1``.
    frequency : float
        Fold frequency relative to the style's (the folds keep their depth-to-width ratio).
    irregularity : float or None
        0 gives parallel folds of constant width, 1 an isotropic labyrinth with varying widths;
        None: 0.6 for the cortex style, 0.5 for the gentle one.
    connectivity : {"uniform", "icosahedral"}
        ``"uniform"``: golden-spiral sphere points (valence std about 0.3 below 20k faces).
        ``"icosahedral"``: a subdivided icosahedron deformed onto the folds, like FreeSurfer's
        registered templates (fsaverage): valence std below 0.1, min-angle 1st / 5th percentiles
        about 16 / 19 degrees (fsaverage5 pial: 13.5 / 20.2). Cortex style only.
    surface : {"pial", "white"}
        ``"white"``: the grey/white matter boundary of the same hemisphere, 2.5 mm (one cortical
        thickness) under the pial surface with grooves 1 mm wider; same vertices in the same
        order and the same faces as the ``"pial"`` surface of the same arguments, as FreeSurfer
        writes ``lh.white`` and ``lh.pial``. Cortex style only.
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
    if style not in STYLES:
        raise InvalidMeshError(f"style is {style!r}; choose one of {', '.join(STYLES)}")
    if connectivity not in CONNECTIVITIES:
        raise InvalidMeshError(
            f"connectivity is {connectivity!r}; choose one of {', '.join(CONNECTIVITIES)}"
        )
    if surface not in SURFACES:
        raise InvalidMeshError(f"surface is {surface!r}; choose one of {', '.join(SURFACES)}")
    if style == "gentle" and (connectivity, surface) != ("uniform", "pial"):
        raise InvalidMeshError("the gentle style has only uniform connectivity and a pial surface")
    if irregularity is None:
        irregularity = _CORTEX_IRREGULARITY if style == "cortex" else 0.5
    if not (np.isfinite(folding) and folding >= 0.0):
        raise InvalidMeshError(f"folding is {folding}; it must be finite and >= 0")
    if not (np.isfinite(frequency) and frequency > 0.0):
        raise InvalidMeshError(f"frequency is {frequency}; it must be finite and > 0")
    if not (0.0 <= irregularity <= 1.0):
        raise InvalidMeshError(f"irregularity is {irregularity}; it must lie in [0, 1]")
    if style == "gentle":
        V, F, _ = _brain_surface(
            n_faces, folding=folding, frequency=frequency, irregularity=irregularity, seed=seed
        )
        return V, F
    V, W, F = _cortex_surface(
        n_faces,
        folding=folding,
        frequency=frequency,
        irregularity=irregularity,
        connectivity=connectivity,
        seed=seed,
    )
    return (W if surface == "white" else V), F


def brain_like_pair(n_faces: int, **options) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """White and pial surfaces of one cortex-style hemisphere: ``(V_white, V_pial, F)``.

    Same connectivity (one ``F``) and vertex order, so vertex ``i`` of the white surface lies
    under vertex ``i`` of the pial one, as in FreeSurfer's ``lh.white`` / ``lh.pial``. Options as
    :func:`brain_like_surface` (``style`` must stay ``"cortex"``, ``surface`` is not taken).
    """
    if "surface" in options:
        raise InvalidMeshError("brain_like_pair returns both surfaces; do not pass surface=")
    V, F = brain_like_surface(n_faces, surface="pial", **options)
    W, _ = brain_like_surface(n_faces, surface="white", **options)
    return W, V, F


def save_gifti(
    path: str | Path,
    V: np.ndarray,
    F: np.ndarray,
    *,
    structure: str = "CortexLeft",
    geometric_type: str = "Anatomical",
) -> Path:
    """Write a surface as a GIfTI file, as FreeSurfer and the neuroimaging tools write them.

    Two data arrays: the vertices (``NIFTI_INTENT_POINTSET``, float32, with the
    ``AnatomicalStructurePrimary`` and ``GeometricType`` metadata and a scanner-space identity
    transform) and the triangles (``NIFTI_INTENT_TRIANGLE``, int32). A name ending in ``.gz``
    (``lh.pial.gii.gz``) is gzip-compressed. Written to a temporary file and renamed, so a
    failure never leaves a partial file.

    Returns
    -------
    Path
        The path written.
    """
    import gzip

    import nibabel as nib

    path = Path(path)
    V = np.asarray(V, dtype=np.float32)
    F = np.asarray(F, dtype=np.int32)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise InvalidMeshError(f"need V (n, 3) and F (m, 3), got {V.shape} and {F.shape}")
    if len(F) and (F.min() < 0 or F.max() >= len(V)):
        raise InvalidMeshError("F refers to vertices that V does not have")
    meta = nib.gifti.GiftiMetaData(
        {"AnatomicalStructurePrimary": structure, "GeometricType": geometric_type}
    )
    xform = nib.gifti.GiftiCoordSystem(dataspace=3, xformspace=3, xform=np.eye(4))
    points = nib.gifti.GiftiDataArray(
        V,
        intent="NIFTI_INTENT_POINTSET",
        datatype="NIFTI_TYPE_FLOAT32",
        meta=meta,
        coordsys=xform,
    )
    triangles = nib.gifti.GiftiDataArray(
        F, intent="NIFTI_INTENT_TRIANGLE", datatype="NIFTI_TYPE_INT32"
    )
    image = nib.gifti.GiftiImage(darrays=[points, triangles])
    data = image.to_bytes()
    if path.name.lower().endswith(".gz"):
        data = gzip.compress(data, mtime=0)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_bytes(data)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


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


def _voronoi_regions(
    V: np.ndarray,
    F: np.ndarray,
    adj: np.ndarray,
    n_regions: int,
    rng: np.random.Generator,
) -> list[np.ndarray]:
    """Geodesic Voronoi regions of the face graph around ``n_regions`` random seed faces.

    Multi-source Dijkstra over face-centroid distances; returns the face ids of every region.
    """
    C = V[F].mean(axis=1)
    i = np.repeat(np.arange(len(F)), 3)
    j = adj.ravel()
    w = np.linalg.norm(C[i] - C[j], axis=1)
    G = sp.csr_matrix((w, (i, j)), shape=(len(F), len(F)))
    seeds = rng.choice(len(F), size=n_regions, replace=False)
    _, _, source = dijkstra(G, indices=seeds, min_only=True, return_predecessors=True)
    order = np.argsort(source, kind="stable")
    bounds = np.searchsorted(source[order], np.sort(seeds))
    return np.split(order, bounds[1:])


# fsaverage5 cut into 89 parcels of about 460 faces: 45 per 20,480-face hemisphere. A parcel's
# share of its hemisphere sets how many folds it straddles, so the cortex-style parcels keep it.
_PARCELS_PER_HEMISPHERE = 45


def _cortex_parcels(
    n: int,
    rng: np.random.Generator,
    *,
    mean_faces: int,
    min_faces: int,
    max_faces: int,
    folding: float,
    frequency: float,
    connectivity: str,
) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray]:
    """Parcels of the cortex style: whole hemispheres cut by `atlas_parcels`, ``n`` kept."""
    parcels: list[tuple[np.ndarray, np.ndarray]] = []
    for _ in range(int(np.ceil(n / _PARCELS_PER_HEMISPHERE))):
        V, _, F = _cortex_surface(
            _PARCELS_PER_HEMISPHERE * mean_faces,
            folding=folding,
            frequency=frequency,
            irregularity=_CORTEX_IRREGULARITY,
            connectivity=connectivity,
            seed=int(rng.integers(2**31)),
        )
        k = max(1, int(round(len(F) / mean_faces)))
        parcels += [p for p in atlas_parcels(V, F, k) if min_faces <= len(p[1]) <= max_faces]
    if len(parcels) < n:
        raise InvalidMeshError(
            f"only {len(parcels)} of {n} parcels fit in [{min_faces}, {max_faces}] faces; "
            "widen the bounds or move mean_faces towards their middle"
        )
    chosen = np.sort(rng.choice(len(parcels), size=n, replace=False))
    return [parcels[k] for k in chosen], np.zeros(n, dtype=bool)


def _brain_parcels(
    n: int,
    *,
    mean_faces: int,
    min_faces: int,
    max_faces: int,
    seed: int,
    folding: float = 1.0,
    frequency: float = 1.0,
    style: str = "cortex",
    connectivity: str = "uniform",
) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray]:
    """Kernel of `brain_like_parcels`; also returns per parcel whether it has a hot corner."""
    rng = np.random.default_rng(seed)
    n_regions = int(np.ceil(1.4 * n)) + 4
    if style == "cortex":
        return _cortex_parcels(
            n,
            rng,
            mean_faces=mean_faces,
            min_faces=min_faces,
            max_faces=max_faces,
            folding=folding,
            frequency=frequency,
            connectivity=connectivity,
        )
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
    groups = _voronoi_regions(V, F, adj, n_regions, rng)
    hot_face = beta[F].mean(axis=1) > 0.5
    parcels: list[tuple[np.ndarray, np.ndarray]] = []
    hot: list[bool] = []
    for R in groups:
        faces = _clean_region(np.sort(R), F, adj)
        if not (min_faces <= len(faces) <= max_faces):
            continue
        verts, Fp = mesh.submesh(F, faces)
        Vp = V[verts]
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


def _fiedler_order(faces: np.ndarray, adj: np.ndarray) -> np.ndarray:
    """``faces`` sorted along the Fiedler vector of the face graph they induce."""
    local = np.full(len(adj), -1, dtype=np.int64)
    local[faces] = np.arange(len(faces))
    i = np.repeat(np.arange(len(faces)), 3)
    j = local[adj[faces]].ravel()
    ok = j >= 0
    n = len(faces)
    A = sp.csr_matrix((np.ones(ok.sum()), (i[ok], j[ok])), shape=(n, n))
    L = sp.diags(np.asarray(A.sum(axis=1)).ravel()) - A
    # shift-invert near 0 on L + eps I: the two smallest eigenpairs (0 and the Fiedler value)
    rng = np.random.default_rng(len(faces))
    _, vec = sp.linalg.eigsh(
        L + 1e-8 * sp.identity(n), k=2, sigma=0.0, which="LM", v0=rng.uniform(size=n)
    )
    fiedler = vec[:, 1] * np.sign(vec[np.argmax(np.abs(vec[:, 1])), 1])
    return faces[np.argsort(fiedler, kind="stable")]


def atlas_parcels(V: np.ndarray, F: np.ndarray, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Cut a connected closed surface into ``n`` parcels of nearly equal face counts.

    Recursive spectral bisection of the face graph: a region meant for ``k`` parcels is split
    along its Fiedler vector at the ``floor(k/2) / k`` quantile of its faces, down to one parcel
    per region; each is then cleaned into a topological disk (ears dropped, holes filled), which
    moves its size by a few faces. Used to cut real cortical surfaces (fsaverage5's pial, in
    ``benchmarks/bench_solver.py``) like the 89-parcel set of issue 16. The loop runs over
    regions (``n`` of them), not over faces.

    Returns
    -------
    list of (V, F)
        The parcels that are disks (one boundary loop), in bisection order.
    """
    F = np.asarray(F, dtype=np.int64)
    adj = mesh.face_neighbors(F)
    stack = [(np.arange(len(F)), int(n))]
    regions = []
    while stack:
        faces, k = stack.pop()
        if k == 1:
            regions.append(faces)
            continue
        order = _fiedler_order(faces, adj)
        cut = int(round(len(faces) * (k // 2) / k))
        stack.append((np.sort(order[cut:]), k - k // 2))
        stack.append((np.sort(order[:cut]), k // 2))
    parcels = []
    for R in regions:
        faces = _clean_region(R, F, adj)
        verts, Fp = mesh.submesh(F, faces)
        Vp = V[verts]
        if len(Fp) and _is_disk(Fp):
            parcels.append((Vp, Fp))
    return parcels


def brain_like_parcels(
    n: int = 89,
    *,
    mean_faces: int = 1000,
    min_faces: int = 300,
    max_faces: int = 3000,
    folding: float = 1.0,
    frequency: float = 1.0,
    style: str = "cortex",
    connectivity: str = "uniform",
    seed: int = 0,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Disk-shaped sub-meshes cut from a folded hemisphere like the regions of a brain atlas.

    ``style="cortex"`` (default): hemispheres as folded as a real cortex, of
    ``45 mean_faces`` faces each, are cut whole into 45 parcels each by :func:`atlas_parcels`
    (recursive spectral bisection, equal face counts), like fsaverage5's two 20,480-face
    hemispheres cut into 89 parcels of about 460 faces; ``n`` of those within the size bounds
    are returned (seeded choice). A parcel's share of its hemisphere, hence the folds it
    straddles, is the real set's.

    ``style="gentle"``: one hemisphere of about ``1.4 n mean_faces`` faces with a few hot spots
    of doubled fold frequency (one at the frontal pole), split into geodesic Voronoi regions
    around seeded random face seeds (multi-source Dijkstra on the face graph), each cleaned
    into a topological disk; ``n`` of those within the size bounds are returned, about 10-20 %
    of them carrying a hot spot in part of their area.

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
    style, connectivity : str
        Fold style and mesh kind of the hemisphere (see :func:`brain_like_surface`).
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
    if style not in STYLES:
        raise InvalidMeshError(f"style is {style!r}; choose one of {', '.join(STYLES)}")
    if connectivity not in CONNECTIVITIES or (style == "gentle" and connectivity != "uniform"):
        raise InvalidMeshError(f"connectivity {connectivity!r} is not available for {style!r}")
    parcels, _ = _brain_parcels(
        n,
        mean_faces=mean_faces,
        min_faces=min_faces,
        max_faces=max_faces,
        seed=seed,
        folding=folding,
        frequency=frequency,
        style=style,
        connectivity=connectivity,
    )
    return parcels
