"""Parameterize every chart; split the charts that fail and try again.

Each chart goes to the Hessian solver (:func:`segparam.parameterize.parameterize_chart`). A chart
whose map is not bijective, or misses the distortion target, is bisected along the Fiedler vector of
its face graph (with the segmentation's crease-aware affinities, so cuts prefer high curvature) and
both halves are solved again, recursively, up to a depth limit. Pieces too small for the solver,
and pieces past the depth limit, are projected onto their best-fit plane, and that projection is
kept only if it is bijective; otherwise they are bisected further. A single triangle always
projects bijectively, so the recursion ends and every chart that leaves this stage is bijective.

A planar chart (the face of a CAD part) skips the solver: its projection onto its plane is the
exact isometry the solver would return up to a rigid motion (method ``"planar"``). On the CAD
plate of ``benchmarks/bench_atlas.py`` (28 planar charts) the stage takes 0.8 s instead of 1.6 s.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .errors import ConfigError, InvalidMeshError
from .mesh import check_mesh, face_areas, face_normals, is_disk, unit_frame
from .parameterize import MIN_POINTS, parameterize_chart
from .quality import ChartQuality, chart_quality
from .segment import divide, face_affinity

log = logging.getLogger(__name__)

__all__ = ["Chart", "ChartSet", "SplitConfig", "parameterize_charts", "project_chart"]


#: Smaller meshes are parameterized in this process: starting workers costs about a second.
PARALLEL_MIN_FACES = 100_000
#: A chart is planar when no unit face normal differs from the first by more than this.
PLANAR_TOL = 1e-9


@dataclass(frozen=True)
class SplitConfig:
    """Options of :func:`parameterize_charts`.

    Attributes
    ----------
    method, tangent : str
        Passed to the solver.
    max_depth : int
        Most bisections of one segmentation chart before the planar fallback takes over.
    max_distortion : float or None
        Angle-distortion target: a bijective chart above it is split too (None: no target).
    min_faces : int
        Pieces with fewer faces skip the solver and use the planar projection.
    n_jobs : int
        Worker processes for meshes of at least ``PARALLEL_MIN_FACES`` faces (0: one per CPU,
        1: none). Charts are independent, so the result does not depend on it.
    """

    method: str = "hessian"
    tangent: str = "normals"
    max_depth: int = 6
    max_distortion: float | None = None
    min_faces: int = 8
    n_jobs: int = 0

    def __post_init__(self) -> None:
        if self.max_depth < 0:
            raise ConfigError(f"max_depth is {self.max_depth}; it must be >= 0")
        if self.max_distortion is not None and not self.max_distortion >= 1:
            raise ConfigError(f"max_distortion is {self.max_distortion}; it must be >= 1")
        if self.min_faces < 1:
            raise ConfigError(f"min_faces is {self.min_faces}; it must be >= 1")
        if self.n_jobs < 0:
            raise ConfigError(f"n_jobs is {self.n_jobs}; it must be >= 0 (0: one per CPU)")


@dataclass(frozen=True)
class Chart:
    """One bijectively mapped chart.

    Attributes
    ----------
    faces : (k,) int64 ndarray
        Indices into the mesh's ``F``.
    vertices : (n,) int64 ndarray
        Mesh vertex of each local vertex; ``F[faces]`` equals ``vertices[local_F]``.
    local_F : (k, 3) int64 ndarray
        The chart's faces in local vertex indices.
    uv : (n, 2) float64 ndarray
        Near-isometric coordinates of the local vertices.
    quality : ChartQuality
    source : int
        The segmentation chart it came from.
    depth : int
        Bisections from the segmentation chart to this piece.
    method : str
        ``"hessian"`` / ``"classic-hlle"`` (the solver), ``"planar"`` (a planar chart, projected
        onto its plane: exact) or ``"projection"`` (the fallback for small or failing pieces).
    """

    faces: np.ndarray
    vertices: np.ndarray
    local_F: np.ndarray
    uv: np.ndarray
    quality: ChartQuality
    source: int
    depth: int
    method: str


@dataclass(frozen=True)
class ChartSet:
    """The charts of a mesh after split and retry.

    Attributes
    ----------
    charts : tuple of Chart
        All bijective; together they hold every face exactly once.
    splits : (s,) int64 ndarray
        Number of bisections each segmentation chart needed (``len(pieces) - 1``).
    first_pass_bijective : (s,) bool ndarray
        Whether the solver mapped each segmentation chart bijectively on its first try.
    """

    charts: tuple[Chart, ...]
    splits: np.ndarray
    first_pass_bijective: np.ndarray


def _submesh(F: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    vertices, local = np.unique(F[faces].ravel(), return_inverse=True)
    return vertices.astype(np.int64), local.reshape(-1, 3).astype(np.int64)


def project_chart(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Orthogonal projection onto the least-squares plane, oriented to keep the winding.

    The normal is the area-weighted mean face normal (it faces the same way as the triangles), so
    a piece that is a height field over that plane maps without flips.

    Returns
    -------
    (n, 2) float64 ndarray
    """
    n = (face_normals(V, F) * face_areas(V, F)[:, None]).sum(axis=0)
    if np.linalg.norm(n) < 1e-300:
        n = np.linalg.svd(V - V.mean(axis=0), full_matrices=False)[2][-1]
    n = n / np.linalg.norm(n)
    helper = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    b1 = np.cross(n, helper)
    b1 /= np.linalg.norm(b1)
    b2 = np.cross(n, b1)
    X = V - V.mean(axis=0)
    return np.stack([X @ b1, X @ b2], axis=1)


def parameterize_charts(
    V: np.ndarray,
    F: np.ndarray,
    labels: np.ndarray,
    *,
    config: SplitConfig | None = None,
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
) -> ChartSet:
    """Map every chart of a segmentation bijectively, splitting the ones that fail.

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray
    labels : (m,) int ndarray
        Chart of each face (see :func:`segparam.segment.segment`).
    config : SplitConfig, optional
    seed : int
    progress : callable, optional
        Called with the number of segmentation charts finished so far.

    Returns
    -------
    ChartSet
    """
    cfg = config or SplitConfig()
    V, F = check_mesh(V, F)
    labels = np.asarray(labels)
    if labels.shape != (len(F),) or labels.dtype.kind not in "iu" or labels.min() < 0:
        raise InvalidMeshError(
            f"labels must be {len(F)} non-negative integers (one chart per face), "
            f"got shape {labels.shape} and dtype {labels.dtype}"
        )
    labels = labels.astype(np.int64)
    center, size = unit_frame(V)
    V = (V - center) / size  # scale-free; chart uvs are scaled back below
    n_src = int(labels.max()) + 1
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(n_src + 1))
    sources = [order[bounds[s] : bounds[s + 1]] for s in range(n_src)]
    submeshes = [_submesh(F, faces) for faces in sources]  # (mesh vertices, local faces)
    jobs = cfg.n_jobs or os.cpu_count() or 1
    parallel = jobs > 1 and n_src > 1 and len(F) >= PARALLEL_MIN_FACES
    # The crease-aware face affinity splits failing charts. It is normalized over the whole mesh,
    # so it is built here once (lazily when serial) and each chart gets its restriction: the
    # result does not depend on n_jobs.
    W = face_affinity(V, F) if parallel else None

    def task(src: int) -> tuple:
        faces = sources[src]
        vertices, local_F = submeshes[src]
        W_src = None if W is None else W[faces][:, faces]
        return V[vertices], local_F, W_src, src

    results: dict[int, tuple[list[Chart], bool]] = {}
    if parallel:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        ctx = multiprocessing.get_context("spawn")  # no fork after BLAS threads have started
        by_size = sorted(range(n_src), key=lambda s: -len(sources[s]))  # big ones first
        with ProcessPoolExecutor(max_workers=min(jobs, n_src), mp_context=ctx) as pool:
            futures = {pool.submit(_solve_source, *task(s), cfg, seed): s for s in by_size}
            try:
                for done, future in enumerate(as_completed(futures), 1):
                    results[futures[future]] = future.result()
                    if progress is not None:
                        progress(done)
            except BaseException:
                pool.shutdown(cancel_futures=True)
                raise
    else:
        cache: list[sp.csr_matrix] = []

        def affinity_of(src: int):  # built on the first chart that must be split
            def restricted() -> sp.csr_matrix:
                if not cache:
                    cache.append(face_affinity(V, F))
                return cache[0][sources[src]][:, sources[src]]

            return restricted

        for src in range(n_src):  # loop over charts
            Vs, Fs, _, _ = task(src)
            results[src] = _solve_source(Vs, Fs, affinity_of(src), src, cfg, seed)
            if progress is not None:
                progress(src + 1)

    charts: list[Chart] = []
    splits = np.zeros(n_src, dtype=np.int64)
    first = np.zeros(n_src, dtype=bool)
    for src in range(n_src):  # back to mesh indices and units
        faces = sources[src]
        vertices = submeshes[src][0]
        pieces, first[src] = results[src]
        splits[src] = len(pieces) - 1
        charts.extend(
            dataclasses.replace(
                c, faces=faces[c.faces], vertices=vertices[c.vertices], uv=c.uv * size
            )
            for c in pieces
        )
    return ChartSet(charts=tuple(charts), splits=splits, first_pass_bijective=first)


def _solve_source(
    V: np.ndarray,
    F: np.ndarray,
    W: sp.csr_matrix | Callable[[], sp.csr_matrix],
    src: int,
    cfg: SplitConfig,
    seed: int,
) -> tuple[list[Chart], bool]:
    """Map one segmentation chart, bisecting the pieces that fail (the per-chart task).

    ``V, F`` are the chart's own vertices and faces; ``W`` its face affinity, or a function that
    builds it (called only if the chart must be split). Returns the bijective pieces, in
    chart-local indices, and whether the first try succeeded.
    """
    stack = [(np.arange(len(F)), 0)]
    pieces: list[Chart] = []
    first = False
    while stack:
        faces, depth = stack.pop()
        chart = _try_piece(V, F, faces, src, depth, cfg, seed)
        if depth == 0:
            first = chart is not None and chart.method != "projection"
        if chart is not None:
            pieces.append(chart)
            continue
        if callable(W):
            W = W()
        parts = divide(W, faces, seed=seed)
        stack.extend((p, depth + 1) for p in reversed(parts) if len(p))
    return pieces, first


def _try_piece(
    V: np.ndarray,
    F: np.ndarray,
    faces: np.ndarray,
    src: int,
    depth: int,
    cfg: SplitConfig,
    seed: int,
) -> Chart | None:
    """A bijective chart for these faces, or None if the piece must be split."""
    vertices, local_F = _submesh(F, faces)
    Vl = V[vertices]
    small = len(faces) < cfg.min_faces or len(vertices) < MIN_POINTS
    if not small and depth <= cfg.max_depth:
        N = face_normals(Vl, local_F)
        if np.abs(N - N[0]).max() < PLANAR_TOL:
            uv = project_chart(Vl, local_F)
            quality = chart_quality(Vl, local_F, uv)
            if quality.bijective:
                return Chart(faces, vertices, local_F, uv, quality, src, depth, "planar")
        try:
            result = parameterize_chart(
                Vl, local_F, method=cfg.method, tangent=cfg.tangent, seed=seed
            )
        except InvalidMeshError as exc:  # not a disk (e.g. a half that pinches): split it
            log.debug("chart %d depth %d: %s", src, depth, exc)
            return None
        ok = result.bijective and (
            cfg.max_distortion is None or result.quality.angle_distortion <= cfg.max_distortion
        )
        if ok:
            return Chart(
                faces, vertices, local_F, result.uv, result.quality, src, depth, result.method
            )
        return None
    if len(faces) > 1 and not is_disk(local_F):
        return None
    uv = project_chart(Vl, local_F)
    quality = chart_quality(Vl, local_F, uv)
    if quality.bijective or len(faces) == 1:
        return Chart(faces, vertices, local_F, uv, quality, src, depth, "projection")
    return None


def chart_face_cover(charts: tuple[Chart, ...], m: int) -> np.ndarray:
    """How many charts hold each face (1 everywhere for a valid chart set)."""
    if not charts:
        return np.zeros(m, dtype=np.int64)
    return np.bincount(np.concatenate([c.faces for c in charts]), minlength=m)
