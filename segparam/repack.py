"""Repacking uv layouts that a mesh already has (xatlas #14, #18, #90, #97).

:func:`uv_islands` finds the islands of a layout (faces connected through shared uv vertices);
:func:`repack` packs them with the pipeline's packer (:func:`segparam.pack.pack_charts`): one
texel density (each island's uv area proportional to its 3-D area), the packer's padding,
rotations and uniform scales only (no mirroring added, an island mirrored in the input stays
mirrored). ``mode="repair"`` first checks every island and re-charts with the parameterize stage
(:func:`segparam.split.parameterize_charts`) the islands that overlap (themselves or another
island), flip (faces wound against the island, or of zero uv area) or leave the unit square,
and keeps the others as they are.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .errors import ConfigError, InvalidMeshError, check_choice, check_int
from .mesh import check_mesh, face_areas, mesh_arrays
from .pack import PackConfig, PackResult, pack_charts
from .quality import signed_areas
from .split import ChartSet, SplitConfig, parameterize_charts

__all__ = ["MODES", "REASONS", "RepackConfig", "RepackResult", "repack", "uv_islands"]

MODES = ("keep", "repair")
#: Why an island is re-charted in ``mode="repair"`` (the reasons an island can have).
REASON_OVERLAP = "overlaps itself"
REASON_OVERLAP_OTHER = "overlaps another island"
REASON_FLIP = "flipped faces"
REASON_OUTSIDE = "outside the unit square"
REASONS = (REASON_OVERLAP, REASON_OVERLAP_OTHER, REASON_FLIP, REASON_OUTSIDE)

#: Two uv triangles overlap when their interiors share more than this depth, relative to the
#: layout's extent: touching islands and neighbouring faces (a shared edge or corner) stay
#: apart at float64 rounding (~1e-16), real overlaps are many orders above.
OVERLAP_TOL = 1e-9
#: A uv face of at most this share of its island's uv area counts as degenerate (a flip): the
#: threshold :data:`segparam.quality.DEGENERATE_AREA` of the charts' bijectivity check.
DEGENERATE_SHARE = 1e-12
#: Candidate pairs per separating-axis batch: ~300 bytes of temporaries per pair (80 MB).
SAT_CHUNK = 262_144


@dataclass(frozen=True)
class RepackConfig:
    """Options of :func:`repack`.

    Attributes
    ----------
    mode : {"keep", "repair"}
        ``"keep"`` packs every island as it is; ``"repair"`` re-charts the islands that
        overlap, flip or leave the unit square (see the module docstring).
    pack : PackConfig
        Resolution, padding, method and rotations of the packer.
    split : SplitConfig
        Options of the parameterize stage that re-charts islands (``"repair"``).
    seed : int
        Seeds the re-charting.
    """

    mode: str = "keep"
    pack: PackConfig = PackConfig()
    split: SplitConfig = SplitConfig()
    seed: int = 0

    def __post_init__(self) -> None:
        check_choice("mode", self.mode, MODES)
        if not isinstance(self.pack, PackConfig):
            raise ConfigError(f"pack must be a PackConfig, got {type(self.pack).__name__}")
        if not isinstance(self.split, SplitConfig):
            raise ConfigError(f"split must be a SplitConfig, got {type(self.split).__name__}")
        object.__setattr__(self, "seed", check_int("seed", self.seed, low=0, high=2**32 - 1))


@dataclass(frozen=True)
class RepackResult:
    """A repacked layout, in the input's face order.

    Attributes
    ----------
    uv : (k, 2) float64 ndarray
        Packed coordinates in ``[0, 1]^2``: the kept islands' uv rows first (input row order),
        then the re-charted charts' rows.
    uv_F : (m, 3) int64 ndarray
        Rows of ``uv`` at each face corner, input face order.
    uv_vertex : (k,) int64 ndarray
        The input vertex of each ``uv`` row.
    island_of_face : (m,) int64 ndarray
        The input island of each face (:func:`uv_islands`).
    kept : (n_islands,) bool ndarray
        Islands packed as they were (every island in ``"keep"`` mode).
    reasons : tuple of tuple of str
        Per island, why it was re-charted (:data:`REASONS`); empty for the kept ones.
    chart_of_face : (m,) int64 ndarray
        The packed chart of each face: kept islands first (in island order), then the
        re-charted pieces.
    packing : PackResult
        The packer's result (``packing.transforms[c]`` maps chart ``c``'s input uv).
    recharted : ChartSet or None
        The parameterize stage's charts of the re-charted faces, or None.
    V, F : ndarray
        The mesh (checked), so that the result saves like an atlas (:meth:`save`).
    mode : str
        The :class:`RepackConfig` mode it was made with.
    """

    uv: np.ndarray
    uv_F: np.ndarray
    uv_vertex: np.ndarray
    island_of_face: np.ndarray
    kept: np.ndarray
    reasons: tuple[tuple[str, ...], ...]
    chart_of_face: np.ndarray
    packing: PackResult
    recharted: ChartSet | None
    V: np.ndarray | None = None
    F: np.ndarray | None = None
    mode: str = "keep"

    def report(self) -> dict[str, Any]:
        """JSON-ready: per island its faces, whether it was kept and why not; the packing."""
        faces = np.bincount(self.island_of_face, minlength=len(self.kept))
        return {
            "mode": self.mode,
            "islands": [
                {"island": i, "faces": int(faces[i]), "kept": bool(k), "reasons": list(r)}
                for i, (k, r) in enumerate(zip(self.kept, self.reasons, strict=True))
            ],
            "kept_islands": int(self.kept.sum()),
            "recharted_islands": int((~self.kept).sum()),
            "charts": int(len(self.packing.uvs)),
            "utilization": self.packing.utilization,
            "resolution": self.packing.resolution,
            "width": self.packing.width,
            "height": self.packing.height,
            "padding": self.packing.padding,
            "texels_per_unit": self.packing.texels_per_unit,
        }

    def save(self, outdir: Any, *, stem: str = "mesh") -> list:
        """Write the usual atlas files (OBJ/MTL/checker PNG, GLB, uv-layout PNG and
        ``report.json`` with :meth:`report`) into ``outdir``, all or nothing
        (:func:`segparam.export.save_atlas`)."""
        if self.V is None or self.F is None:
            raise ConfigError("this RepackResult has no mesh to save (V, F)")
        from .export import save_atlas

        return save_atlas(self, outdir, stem=stem)


def _face_uv(face_uv: Any, n_uv: int | None = None) -> tuple[np.ndarray | None, np.ndarray]:
    """``(uv, F_uv)`` from either uv indices per corner ``(m, 3)`` int (``uv`` is None then)
    or uv coordinates per corner ``(m, 3, 2)`` float, whose equal corners are welded."""
    a = np.asarray(face_uv)
    if a.ndim == 3 and a.shape[1:] == (3, 2) and a.dtype.kind == "f":
        if not np.isfinite(a).all():
            raise InvalidMeshError("face uv corners have NaN or infinite coordinates")
        uv, inverse = np.unique(a.reshape(-1, 2), axis=0, return_inverse=True)
        return uv, inverse.reshape(-1, 3).astype(np.int64)
    if a.ndim != 2 or a.shape[1] != 3 or a.dtype.kind not in "iu":
        raise InvalidMeshError(
            "face uv must be (m, 3) integer rows of uv or (m, 3, 2) uv corners, "
            f"got shape {a.shape} and dtype {a.dtype}"
        )
    if len(a) and (a.min() < 0 or (n_uv is not None and a.max() >= n_uv)):
        raise InvalidMeshError(
            f"face uv indices span [{a.min()}, {a.max()}] but there are {n_uv} uv rows"
        )
    return None, a.astype(np.int64)


def uv_islands(face_uv: Any) -> np.ndarray:
    """The island of each face: faces are in one island when a chain of faces sharing uv
    vertices joins them (a shared corner is enough, as in Blender's and xatlas's islands).

    Parameters
    ----------
    face_uv : (m, 3) int array_like, or (m, 3, 2) float array_like
        Per face corner, the row of its uv (OBJ ``vt`` indices, glTF per-vertex
        ``TEXCOORD_0`` with the faces), or the uv itself (equal corners are one uv vertex).

    Returns
    -------
    (m,) int64 ndarray
        Islands numbered 0, 1, ... in the order of their first face.
    """
    _, Fu = _face_uv(face_uv)
    if len(Fu) == 0:
        return np.zeros(0, dtype=np.int64)
    n = int(Fu.max()) + 1
    rows = Fu[:, [0, 1, 2]].ravel()
    cols = Fu[:, [1, 2, 0]].ravel()
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    face_comp = comp[Fu[:, 0]]
    # renumber by first face: np.unique's first occurrences, ranked
    _, first, inverse = np.unique(face_comp, return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first)] = np.arange(len(first))
    return rank[inverse.ravel()]


def _overlapping_pairs(uv: np.ndarray, Fu: np.ndarray, live: np.ndarray) -> np.ndarray:
    """Pairs of faces (of the ``live`` ones) whose uv triangles' interiors overlap, ``(p, 2)``.

    Candidates are faces whose centroids are closer than twice the largest centroid-to-corner
    distance (a k-d tree) and whose bounding boxes overlap; each candidate pair gets the
    separating-axis test on the six edge normals, which is exact for two triangles (two convex
    sets whose interiors are disjoint are separated by a line along an edge of one of them).
    """
    idx = np.flatnonzero(live)
    if len(idx) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    T = uv[Fu[idx]]  # (f, 3, 2)
    c = T.mean(axis=1)
    radius = float(np.linalg.norm(T - c[:, None], axis=2).max())
    tol = OVERLAP_TOL * float(np.ptp(T.reshape(-1, 2), axis=0).max())
    pairs = cKDTree(c).query_pairs(2 * radius * (1 + 1e-9), output_type="ndarray")
    lo, hi = T.min(axis=1), T.max(axis=1)
    a, b = pairs[:, 0], pairs[:, 1]
    boxes = ((np.minimum(hi[a], hi[b]) - np.maximum(lo[a], lo[b])) > tol).all(axis=1)
    pairs = pairs[boxes]
    hits = [np.zeros((0, 2), dtype=np.int64)]
    for k in range(0, len(pairs), SAT_CHUNK):  # batches of pairs, bounded memory
        batch = pairs[k : k + SAT_CHUNK]
        hits.append(batch[_sat_overlap(T, batch, tol)])
    return idx[np.concatenate(hits)]


def _sat_overlap(T: np.ndarray, pairs: np.ndarray, tol: float) -> np.ndarray:
    """Whether triangles ``T[pairs[:, 0]]`` and ``T[pairs[:, 1]]`` overlap deeper than ``tol``
    along each of their six edge normals (the separating-axis test)."""
    A, B = T[pairs[:, 0]], T[pairs[:, 1]]
    E = np.concatenate([A[:, [1, 2, 0]] - A, B[:, [1, 2, 0]] - B], axis=1)  # (p, 6, 2) edges
    length = np.hypot(E[..., 0], E[..., 1])
    scale = np.where(length > 0, length, 1.0)
    nx, ny = -E[..., 1] / scale, E[..., 0] / scale  # unit normals (p, 6)
    pa = nx[:, :, None] * A[:, None, :, 0] + ny[:, :, None] * A[:, None, :, 1]  # (p, 6, 3)
    pb = nx[:, :, None] * B[:, None, :, 0] + ny[:, :, None] * B[:, None, :, 1]
    depth = np.minimum(pa.max(axis=2), pb.max(axis=2)) - np.maximum(pa.min(axis=2), pb.min(axis=2))
    depth[length == 0] = np.inf  # a zero edge separates nothing
    return depth.min(axis=1) > tol


def _island_checks(
    uv: np.ndarray, Fu: np.ndarray, island: np.ndarray, n_islands: int
) -> tuple[tuple[str, ...], ...]:
    """Per island, the reasons (:data:`REASONS`) it is not a valid piece of a layout."""
    sa = signed_areas(uv, Fu)
    net = np.bincount(island, weights=sa, minlength=n_islands)
    total = np.bincount(island, weights=np.abs(sa), minlength=n_islands)
    sign = np.where(net[island] < 0, -1.0, 1.0)  # the island's winding: its area's majority
    degenerate = np.abs(sa) <= DEGENERATE_SHARE * np.maximum(total[island], np.finfo(float).tiny)
    flip = np.bincount(island, weights=(sa * sign < 0) | degenerate, minlength=n_islands) > 0
    corners = uv[Fu].reshape(len(Fu), -1)
    out = ((corners < 0) | (corners > 1)).any(axis=1)
    outside = np.bincount(island, weights=out, minlength=n_islands) > 0
    pairs = _overlapping_pairs(uv, Fu, ~degenerate)
    ia, ib = island[pairs[:, 0]], island[pairs[:, 1]]
    self_overlap = np.zeros(n_islands, dtype=bool)
    self_overlap[ia[ia == ib]] = True
    other_overlap = np.zeros(n_islands, dtype=bool)
    other_overlap[np.concatenate([ia[ia != ib], ib[ia != ib]])] = True
    flags = np.column_stack([self_overlap, other_overlap, flip, outside])
    return tuple(tuple(r for r, f in zip(REASONS, row, strict=True) if f) for row in flags)


def repack(
    V: Any,
    F: Any = None,
    uv: Any = None,
    face_uv: Any = None,
    *,
    config: RepackConfig | None = None,
) -> RepackResult:
    """Pack a mesh's existing uv islands into a new atlas (``mode="repair"``: fixing the broken
    islands first).

    Parameters
    ----------
    V : (n, 3) array_like of float, or a trimesh.Trimesh (then no F; ``uv`` defaults to its
        ``visual.uv``, one per vertex)
    F : (m, 3) array_like of int
    uv : (k, 2) array_like of float
        The existing uv coordinates (any range: the packer moves and scales the islands).
    face_uv : (m, 3) array_like of int, or (m, 3, 2) array_like of float, optional
        Per face corner, the row of ``uv`` (OBJ ``f v/vt``); default ``F`` (one uv per vertex,
        as glTF and trimesh store them). Or the uv of every corner (then ``uv`` is None):
        corners with equal uv are one uv vertex.
    config : RepackConfig, optional

    Returns
    -------
    RepackResult
        Every island kept (``"keep"``), or the valid ones kept and the others re-charted with
        the reasons (``"repair"``); the packed layout in the input's face order.

    Raises
    ------
    InvalidMeshError
        A malformed mesh or uv (shapes, NaN, indices out of range); no uv; in ``"keep"`` mode
        an island with no uv area; an island with no 3-D area.
    ConfigError
        A bad option.
    SolverError
        The islands do not fit the texture at any scale.
    """
    cfg = RepackConfig() if config is None else config
    if not isinstance(cfg, RepackConfig):
        raise ConfigError(f"config must be a RepackConfig, got {type(cfg).__name__}")
    if uv is None and F is None and hasattr(V, "visual"):  # a trimesh.Trimesh with its uv
        uv = getattr(V.visual, "uv", None)
        if uv is None:
            raise InvalidMeshError("the mesh has no uv coordinates to repack")
    V, F = check_mesh(*mesh_arrays(V, F), allow_degenerate=True)
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float64)
        if uv.ndim != 2 or uv.shape[1] != 2:
            raise InvalidMeshError(f"uv must have shape (k, 2), got {uv.shape}")
        if not np.isfinite(uv).all():
            raise InvalidMeshError("uv has NaN or infinite coordinates")
    welded, Fu = _face_uv(F if face_uv is None else face_uv, None if uv is None else len(uv))
    if welded is not None:  # uv given per corner
        uv = welded
    if uv is None:
        raise InvalidMeshError("no uv coordinates to repack (uv is None)")
    if Fu.shape != F.shape:
        raise InvalidMeshError(f"face uv has {len(Fu)} faces but the mesh has {len(F)}")

    island = uv_islands(Fu)
    n_islands = int(island.max()) + 1
    area3d = np.bincount(island, weights=face_areas(V, F), minlength=n_islands)
    flat = ~(area3d > 0)
    if flat.any():
        i = int(np.flatnonzero(flat)[0])
        raise InvalidMeshError(f"island {i} has no 3-D area; it cannot get texels")
    if cfg.mode == "repair":
        reasons = _island_checks(uv, Fu, island, n_islands)
    else:
        reasons = ((),) * n_islands
        area_uv = np.bincount(island, weights=np.abs(signed_areas(uv, Fu)), minlength=n_islands)
        if not (area_uv > 0).all():
            i = int(np.flatnonzero(~(area_uv > 0))[0])
            raise InvalidMeshError(
                f"island {i} has no uv area; repack it with mode='repair' to re-chart it"
            )
    kept = np.array([not r for r in reasons], dtype=bool)

    # Kept islands: their own uv rows, renumbered island by island (one sort, no face loop).
    # Islands share no uv row, so each used row has one island.
    kept_ids = np.flatnonzero(kept)
    faces_kept = np.flatnonzero(kept[island])
    faces_kept = faces_kept[np.argsort(island[faces_kept], kind="stable")]
    row_island = np.zeros(len(uv), dtype=np.int64)
    row_island[Fu] = island[:, None]
    used = np.unique(Fu[faces_kept])
    used = used[np.argsort(row_island[used], kind="stable")]
    new_row = np.empty(len(uv), dtype=np.int64)
    new_row[used] = np.arange(len(used))
    corner_row = np.empty(F.shape, dtype=np.int64)  # packed uv row of every face corner
    corner_row[faces_kept] = new_row[Fu[faces_kept]]
    rows_at = np.r_[np.searchsorted(row_island[used], kept_ids), len(used)]  # island bounds
    faces_at = np.r_[np.searchsorted(island[faces_kept], kept_ids), len(faces_kept)]
    chart_uvs = [uv[used[a:b]] for a, b in zip(rows_at[:-1], rows_at[1:], strict=True)]
    chart_faces = [
        corner_row[faces_kept[a:b]] - r
        for a, b, r in zip(faces_at[:-1], faces_at[1:], rows_at[:-1], strict=True)
    ]
    chart_area = list(area3d[kept_ids])
    chart_of_face = np.empty(len(F), dtype=np.int64)
    chart_of_face[faces_kept] = np.searchsorted(kept_ids, island[faces_kept])

    # Re-charted islands: the parameterize stage on their faces, one chart per island to start
    # (it bisects the ones that do not map bijectively).
    recharted = None
    redo = np.flatnonzero(~kept[island])
    if len(redo):
        vertices, Fl = np.unique(F[redo], return_inverse=True)
        recharted = parameterize_charts(
            V[vertices],
            Fl.reshape(-1, 3),
            np.unique(island[redo], return_inverse=True)[1].ravel(),
            config=cfg.split,
            seed=cfg.seed,
        )
        areas = face_areas(V, F)
        offset = len(used)
        for c in recharted.charts:  # loop over charts
            faces = redo[c.faces]
            chart_of_face[faces] = len(chart_uvs)
            corner_row[faces] = c.local_F + offset
            offset += len(c.uv)
            chart_uvs.append(c.uv)
            chart_faces.append(c.local_F)
            chart_area.append(float(areas[faces].sum()))

    packing = pack_charts(chart_uvs, chart_faces, chart_area, config=cfg.pack)
    # Output uv vertices: one per (input vertex, packed row) met at a corner, so that
    # F == uv_vertex[uv_F] even where the input shared a uv row between vertices.
    packed = np.concatenate(packing.uvs)
    key = F.ravel() * len(packed) + corner_row.ravel()
    pairs, inverse = np.unique(key, return_inverse=True)
    return RepackResult(
        uv=packed[pairs % len(packed)],
        uv_F=inverse.reshape(-1, 3).astype(np.int64),
        uv_vertex=(pairs // len(packed)).astype(np.int64),
        island_of_face=island,
        kept=kept,
        reasons=reasons,
        chart_of_face=chart_of_face,
        packing=packing,
        recharted=recharted,
        V=V,
        F=F,
        mode=cfg.mode,
    )
