"""The whole pipeline: clean -> remesh -> segment -> parameterize (split + retry) -> pack.

:func:`build_atlas` runs every stage on numpy arrays and returns an :class:`Atlas`; each stage is
also a public function of its own module. Configurations are frozen dataclasses gathered in
:class:`PipelineConfig`, loaded from the TOML files in ``pipelines/``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import logging
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__, warmup
from .clean import CleanResult, clean
from .errors import ConfigError, InvalidMeshError
from .instances import (
    Repeats,
    candidates,
    expand_labels,
    find_repeats,
    replicate,
    similarity,
)
from .mesh import boundary_edges, face_areas, mesh_arrays, submesh, unit_frame
from .pack import MAX_RESOLUTION, PackConfig, PackResult, pack_charts
from .quality import distortion, signed_areas
from .remesh import RemeshConfig, RemeshResult, remesh
from .segment import Segmentation, SegmentConfig, segment
from .split import (
    PARALLEL_MIN_FACES,
    ChartSet,
    SplitConfig,
    parameterize_charts,
    start_workers,
    stop_workers,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

log = logging.getLogger(__name__)

__all__ = [
    "MAX_FACES",
    "MAX_RESOLUTION",
    "MAX_SEED",
    "Atlas",
    "MultiAtlas",
    "PipelineConfig",
    "build_atlas",
    "build_atlases",
    "chart_room",
    "check_seed",
    "config_from_dict",
    "load_config",
    "pack_atlas",
]

#: Largest input accepted (faces): a guard against running out of memory (about 3 KB per face
#: peak in the stages; 24 GB machines manage ~5M faces).
MAX_FACES = 5_000_000
#: Seeds are 32-bit (numpy's legacy RandomState, which seeds the clustering, takes 0 .. 2**32 - 1).
MAX_SEED = 2**32 - 1


def check_seed(seed: Any) -> int:
    """``seed`` as an int, or a :class:`ConfigError` unless it is an integer in [0, MAX_SEED]."""
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise ConfigError(f"seed must be an integer from 0 to {MAX_SEED}, got {seed!r}")
    if not 0 <= seed <= MAX_SEED:
        raise ConfigError(f"seed must be an integer from 0 to {MAX_SEED}, got {seed}")
    return int(seed)


def chart_room(resolution: int, padding: int) -> int:
    """Most charts that can fit a ``resolution`` texture with ``padding``, whatever their shapes.

    Every chart covers at least one texel, at least ``padding`` texels from the border, and at a
    Chebyshev distance of at least ``padding + 1`` from every other chart's texels. Cut the
    ``resolution - 2 padding`` texels square inside the border into blocks of ``padding + 1``
    texels a side: no block can hold texels of two charts, so at most
    ``ceil((resolution - 2 padding) / (padding + 1))**2`` charts fit (and that many dots do).
    """
    inner = int(resolution) - 2 * int(padding)
    if inner <= 0:
        return 0
    blocks = -(-inner // (int(padding) + 1))  # ceil
    return blocks * blocks


def _check_room(n_charts: int, pack: PackConfig, what: str) -> None:
    """A :class:`ConfigError` when ``n_charts`` charts cannot fit the texture at all (the
    largest texture when the resolution follows from the texel density)."""
    G, p = pack.resolution or MAX_RESOLUTION, pack.padding
    room = chart_room(G, p)
    if n_charts > room:
        raise ConfigError(
            f"{what} {n_charts} charts, but a {G}x{G} texture with padding {p} has room for at "
            f"most {room} (one texel each, {p} texels apart); raise the resolution or lower "
            "the padding"
        )


def _check_density(area: float, pack: PackConfig, what: str = "the mesh") -> None:
    """A :class:`ConfigError` when charts of 3-D ``area`` cannot fit the texture at
    ``pack.texels_per_unit`` whatever their shapes (they need ``area * texels_per_unit**2``
    texels inside the padded border): known before any stage runs. Charts above
    ``pack.max_chart_size`` shrink, so then nothing is known before packing."""
    X = pack.texels_per_unit
    if X <= 0 or pack.max_chart_size > 0:
        return
    G, p = pack.resolution or MAX_RESOLUTION, pack.padding
    side = float(np.sqrt(area)) * X
    if side > G - 2 * p:
        raise ConfigError(
            f"at {X:g} texels per unit {what} ({area:.6g} square units) needs at least "
            f"{side:.0f}x{side:.0f} texels, more than a {G}x{G} texture with padding {p} holds; "
            "lower the texel density or raise the resolution"
        )


_SECTIONS = {
    "remesh": RemeshConfig,
    "segment": SegmentConfig,
    "split": SplitConfig,
    "pack": PackConfig,
}


@dataclass(frozen=True)
class PipelineConfig:
    """Every stage's options. Load from TOML with :func:`load_config`.

    Every field of every section is checked when the section is built (type, range, choices:
    :class:`~segparam.errors.ConfigError` naming the field); here, that each section is its
    config class.
    """

    remesh: RemeshConfig = field(default_factory=RemeshConfig)
    segment: SegmentConfig = field(default_factory=SegmentConfig)
    split: SplitConfig = field(default_factory=SplitConfig)
    pack: PackConfig = field(default_factory=PackConfig)

    def __post_init__(self) -> None:
        for name, cls in _SECTIONS.items():
            value = getattr(self, name)
            if not isinstance(value, cls):
                raise ConfigError(
                    f"[{name}] must be a {cls.__name__}, got {type(value).__name__} {value!r}"
                )

    def as_dict(self) -> dict[str, dict[str, Any]]:
        """Plain dictionary, one table per stage (the TOML layout)."""
        return {f.name: dataclasses.asdict(getattr(self, f.name)) for f in dataclasses.fields(self)}

    def replace(self, **sections: dict[str, Any]) -> PipelineConfig:
        """A copy with some options changed, e.g. ``replace(pack={"resolution": 2048})``."""
        data = self.as_dict()
        for name, values in sections.items():
            if name not in data:
                raise ConfigError(f"unknown config section [{name}]; known: {', '.join(data)}")
            if not isinstance(values, dict):
                raise ConfigError(f"[{name}] must be a table (a dict), got {values!r}")
            data[name].update(values)
        return config_from_dict(data)


def config_from_dict(data: dict[str, Any], *, source: str = "config") -> PipelineConfig:
    """Build a :class:`PipelineConfig` from ``{table: {key: value}}`` (the TOML layout).

    Unknown sections or keys, values of the wrong type and values out of range are a
    :class:`ConfigError` of one line naming ``source``, the ``[table]`` and the key.
    """
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: must be a table of tables, got {type(data).__name__}")
    kwargs = {}
    for name, values in data.items():
        if name not in _SECTIONS:
            raise ConfigError(f"{source}: unknown section [{name}]; known: {', '.join(_SECTIONS)}")
        if not isinstance(values, dict):
            raise ConfigError(f"{source}: [{name}] must be a table")
        cls = _SECTIONS[name]
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ConfigError(
                f"{source}: unknown key {unknown[0]!r} in [{name}]; "
                f"known: {', '.join(sorted(known))}"
            )
        try:
            kwargs[name] = cls(**values)
        except ConfigError as exc:
            raise ConfigError(f"{source}: [{name}] {exc}") from None
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{source}: [{name}] {exc}") from None
    try:
        return PipelineConfig(**kwargs)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None


def load_config(path: str | os.PathLike) -> PipelineConfig:
    """Read a pipeline TOML file (see ``pipelines/default.toml`` for every key)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such config file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML ({exc})") from None
    return config_from_dict(data, source=str(path))


@dataclass(frozen=True)
class Atlas:
    """A packed UV atlas of a mesh, with every stage's result.

    Attributes
    ----------
    V : (n, 3) float64 ndarray
        Positions of the mesh that was charted (cleaned; remeshed if the remesh stage ran).
    F : (m, 3) int64 ndarray
    uv : (k, 2) float64 ndarray
        Atlas coordinates in ``[0, 1]^2``, split along seams (one row per chart vertex). The
        texture is ``packing.width x packing.height`` texels (a square unless trimmed): a uv
        ``(u, v)`` is the texel point ``(u * width, v * height)`` (:attr:`texel_uv`).
    uv_F : (m, 3) int64 ndarray
        Rows of ``uv`` for each face corner.
    uv_vertex : (k,) int64 ndarray
        Mesh vertex of each ``uv`` row (``F == uv_vertex[uv_F]``).
    chart_of_face : (m,) int64 ndarray
    charts : ChartSet
    packing : PackResult
    segmentation, cleaning, remeshing : Segmentation, CleanResult, RemeshResult or None
        The stage results (None when the atlas was packed from saved charts).
    timings : dict
        Seconds per stage.
    config : PipelineConfig
    seed : int
    """

    V: np.ndarray
    F: np.ndarray
    uv: np.ndarray
    uv_F: np.ndarray
    uv_vertex: np.ndarray
    chart_of_face: np.ndarray
    charts: ChartSet
    packing: PackResult
    segmentation: Segmentation | None
    cleaning: CleanResult | None
    remeshing: RemeshResult | None
    timings: dict
    config: PipelineConfig
    seed: int

    @property
    def n_charts(self) -> int:
        return len(self.charts.charts)

    @property
    def texel_uv(self) -> np.ndarray:
        """``uv`` in texels of the ``packing.width x packing.height`` texture: where the
        texture is not square, the coordinates in which lengths and angles are the texture's
        (distortion is measured on these)."""
        return self.uv * np.array(self.packing.size, dtype=np.float64)

    def seam_length(self) -> float:
        """Total 3-D length of the seams (edges whose two faces have different uv rows)."""
        B3 = boundary_edges(self.F)
        Buv = boundary_edges(self.uv_F)
        cut = float(np.linalg.norm(self.V[B3[:, 0]] - self.V[B3[:, 1]], axis=1).sum())
        P = self.uv_vertex[Buv]
        total = float(np.linalg.norm(self.V[P[:, 0]] - self.V[P[:, 1]], axis=1).sum())
        return (total - cut) / 2  # each seam edge borders two charts

    def report(self) -> dict[str, Any]:
        """The figures written to ``report.json`` (JSON-ready)."""
        return build_report(self)

    def save(self, outdir: str | os.PathLike, *, stem: str = "mesh", **kwargs: Any) -> list[Path]:
        """Write the OBJ/MTL/checker PNG, GLB, uv-layout PNG and ``report.json`` (atomically).

        A stem too long for the file system is shortened (``<beginning>~<hash>``); the paths
        written are returned. A folder that cannot take the files (read-only, a file in the
        way, disk full...) raises :class:`~segparam.errors.MeshFileError` (a
        :class:`~segparam.errors.SegparamError` and an ``OSError``) with one line, and leaves no
        file (see :func:`segparam.export.save_atlas`).
        """
        from .export import save_atlas

        return save_atlas(self, outdir, stem=stem, **kwargs)

    def to_trimesh(self, image: Any = None) -> Any:
        """A ``trimesh.Trimesh`` split along the seams with ``TextureVisuals`` (uv and the
        checker texture, or ``image``); see :func:`segparam.interop.atlas_to_trimesh`."""
        from .interop import atlas_to_trimesh

        return atlas_to_trimesh(self, image)


@functools.lru_cache(maxsize=1)
def _versions() -> dict[str, str]:
    """The versions in the report, looked up once per process (13-24 ms a lookup: the CLI
    built the report twice, for the file and for its summary)."""
    import importlib.metadata as md

    out = {"segparam": __version__, "python": sys.version.split()[0]}
    for name in ("numpy", "scipy", "numba", "cvxopt", "pymeshlab", "trimesh"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:  # pragma: no cover
            out[name] = "missing"
    return out


def _cut_untried(charts: ChartSet) -> int | None:
    """How many segmentation charts the split stage cut before any solve (None: not recorded)."""
    return None if charts.cut_untried is None else int(charts.cut_untried.sum())


def build_report(atlas: Atlas) -> dict[str, Any]:
    """Per-chart and global figures of an atlas (see the README's "Outputs")."""
    # Figures are computed in the unit frame (scale-free ones as they are, areas and lengths
    # scaled back), so that any input units work.
    center, size = unit_frame(atlas.V)
    V, F = (atlas.V - center) / size, atlas.F
    area = face_areas(V, F) * size**2
    charts = []
    for k, c in enumerate(atlas.charts.charts):
        q = c.quality
        charts.append(
            {
                "chart": k,
                "faces": int(len(c.faces)),
                "area": float(area[c.faces].sum()),
                "source_chart": int(c.source),
                "depth": int(c.depth),
                "splits_of_source": int(atlas.charts.splits[c.source]),
                "method": c.method,
                # vertices the chart holds twice: a slit's or an opened tube's cut, both sides seams
                "cut_vertices": int(len(c.vertices) - len(np.unique(c.vertices))),
                "bijective": bool(q.bijective),
                "flipped": int(q.n_flipped),
                "l2_stretch": q.l2_stretch,
                "linf_stretch": q.linf_stretch,
                "angle_distortion": q.angle_distortion,
                "area_distortion": q.area_distortion,
                "symmetric_dirichlet": q.symmetric_dirichlet,
            }
        )
    flipped = int((signed_areas(atlas.uv, atlas.uv_F) <= 0).sum())
    total_area = float(area.sum())
    report = {
        "segparam": dict(_versions()),  # a copy: the cached one stays as it is
        "seed": atlas.seed,
        "settings": atlas.config.as_dict(),
        "timings": atlas.timings,
        "input": None
        if atlas.cleaning is None
        else {"vertices": atlas.cleaning.input_vertices, "faces": atlas.cleaning.input_faces},
        "cleaning": None if atlas.cleaning is None else atlas.cleaning.summary(),
        "remeshing": None
        if atlas.remeshing is None
        else {
            "remeshed": atlas.remeshing.remeshed,
            "reason": atlas.remeshing.reason,
            "target_edge": atlas.remeshing.target_edge,
            "vertices": int(len(V)),
            "faces": int(len(F)),
        },
        "segmentation": {
            "charts": len(atlas.charts.splits),
            "target_charts": None
            if atlas.segmentation is None
            else atlas.segmentation.target_charts,
            "curvature": None if atlas.segmentation is None else atlas.segmentation.curvature,
            "first_pass_bijective": int(atlas.charts.first_pass_bijective.sum()),
            "cut_untried": _cut_untried(atlas.charts),
            "copies": 0 if atlas.segmentation is None else atlas.segmentation.copies,
        },
        "atlas": {
            "charts": atlas.n_charts,
            "faces": int(len(F)),
            "flipped_triangles": flipped,
            "bijective_charts": int(sum(c.quality.bijective for c in atlas.charts.charts)),
            "charts_cut_open": int(sum(r["cut_vertices"] > 0 for r in charts)),
            "utilization": atlas.packing.utilization,
            "resolution": atlas.packing.resolution,
            "width": atlas.packing.width,
            "height": atlas.packing.height,
            "padding": atlas.packing.padding,
            "texels_per_unit": atlas.packing.texels_per_unit,
            "seam_length_over_sqrt_area": atlas.seam_length() / np.sqrt(total_area),
            # on texels of one size in u and v (the distortion's scale does not matter)
            **distortion(V[atlas.uv_vertex], atlas.uv_F, atlas.packing.isotropic(atlas.uv)),
        },
        "charts": charts,
    }
    from .io import json_safe

    return json_safe(report)


def build_atlas(
    V,
    F=None,
    config: PipelineConfig | None = None,
    *,
    seed: int = 0,
    progress: Callable[[str, int, int], None] | None = None,
) -> Atlas:
    """Run every stage and pack the charts into one atlas.

    Parameters
    ----------
    V : (n, 3) array_like of float, or a trimesh.Trimesh (then no F)
    F : (m, 3) array_like of int
        Any triangle mesh (it is cleaned first; defects are repaired or reported).
    config : PipelineConfig, optional
    seed : int
        The one source of randomness: the same input, config and seed give the same atlas.
    progress : callable, optional
        ``progress(stage, done, total)``, called as stages and charts finish.

    Returns
    -------
    Atlas

    Raises
    ------
    InvalidMeshError
        On input that cannot be made into a mesh (see :func:`segparam.clean.clean`), or more
        than :data:`MAX_FACES` faces.
    ConfigError
        A seed out of range, or more charts than the texture has room for at any scale
        (:func:`chart_room`): checked as soon as the count is known (connected pieces after
        cleaning, charts after segmentation), not after packing.
    """
    cfg = config or PipelineConfig()
    seed = check_seed(seed)
    charted = _chart_mesh(V, F, cfg, seed, progress or (lambda stage, done, total: None))
    return pack_atlas(
        charted.V,
        charted.F,
        charted.charts,
        config=cfg,
        seed=seed,
        timings=charted.timings,
        segmentation=charted.segmentation,
        cleaning=charted.cleaning,
        remeshing=charted.remeshing,
    )


@dataclass(frozen=True)
class MultiAtlas:
    """Several meshes packed into one texture at one texel density (:func:`build_atlases`).

    Attributes
    ----------
    atlases : tuple of Atlas
        Per mesh, in input order, a whole :class:`Atlas` (its own vertices, faces, charts and
        stage results) whose ``uv`` lies in the shared texture; its ``packing`` holds its own
        charts' part of the shared one (same scale, resolution and padding; its utilization is
        its charts' share).
    packing : PackResult
        The one packing of every mesh's charts (mesh by mesh, chart by chart).
    names : tuple of str
        Per mesh, the name of its report section and of its files (unique).
    """

    atlases: tuple[Atlas, ...]
    packing: PackResult
    names: tuple[str, ...]

    def report(self) -> dict[str, Any]:
        """``report.json`` of the shared texture: the texture's figures, then a section per
        mesh (what :meth:`Atlas.report` says about it alone)."""
        from .io import json_safe

        packing = self.packing
        return json_safe(
            {
                "texture": {
                    "meshes": len(self.atlases),
                    "charts": len(packing.uvs),
                    "resolution": packing.resolution,
                    "width": packing.width,
                    "height": packing.height,
                    "padding": packing.padding,
                    "utilization": packing.utilization,
                    "texels_per_unit": packing.texels_per_unit,
                },
                "meshes": [
                    {"name": name, **atlas.report()}
                    for name, atlas in zip(self.names, self.atlases, strict=True)
                ],
            }
        )

    def save(self, outdir: str | os.PathLike, *, stem: str = "atlas", **kwargs: Any) -> list[Path]:
        """Write one OBJ and one GLB per mesh (``<name>.obj``, ``<name>.glb``; ``scenes=[(name,
        indices)]`` puts meshes into one GLB of named nodes instead) sharing ``<stem>.mtl``,
        ``<stem>_checker.png``, ``<stem>_uv.png`` (every chart), the preview and viewer of the
        whole set (``pictures=``) and one ``report.json``; all or nothing (see
        :func:`segparam.export.save_atlases`)."""
        from .export import save_atlases

        return save_atlases(self, outdir, stem=stem, **kwargs)


def build_atlases(
    meshes: Sequence[Any],
    config: PipelineConfig | None = None,
    *,
    seed: int = 0,
    names: Sequence[str] | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> MultiAtlas:
    """Chart several meshes and pack all their charts into one texture (one texel density).

    Each mesh goes through every stage of :func:`build_atlas` on its own (same config and
    seed); then one :func:`segparam.pack.pack_charts` call packs the charts of all of them, so
    they never overlap and every chart has the same texels per unit of 3-D length.

    Parameters
    ----------
    meshes : sequence of (V, F) pairs or trimesh.Trimesh
    config : PipelineConfig, optional
    seed : int
    names : sequence of str, optional
        Per mesh, its report section and file names; default ``mesh0``, ``mesh1``, ...
        Names met twice get ``_2``, ``_3``... .
    progress : callable, optional
        ``progress(stage, done, total)`` as in :func:`build_atlas`, for each mesh in turn.

    Returns
    -------
    MultiAtlas

    Raises
    ------
    InvalidMeshError, ConfigError, SolverError
        As :func:`build_atlas`; a mesh's error names the mesh (``mesh 2: ...``). No mesh is an
        :class:`InvalidMeshError`.
    """
    cfg = config or PipelineConfig()
    seed = check_seed(seed)
    meshes = list(meshes)
    if not meshes:
        raise InvalidMeshError("build_atlases needs at least one mesh")
    if names is None:
        names = [f"mesh{i}" for i in range(len(meshes))]
    from .io import unique_names

    names = unique_names([str(n) for n in names])
    if len(names) != len(meshes):
        raise ConfigError(f"{len(names)} names for {len(meshes)} meshes")
    report = progress or (lambda stage, done, total: None)
    charted: list[_Charted] = []
    inputs: list[tuple[np.ndarray, np.ndarray] | None] = []  # meshes a later one may copy
    for name, mesh in zip(names, meshes, strict=True):  # loop over meshes
        pair = (mesh, None) if hasattr(mesh, "faces") else tuple(mesh)
        if len(pair) != 2:
            raise InvalidMeshError(f"{name}: expected a (V, F) pair or a trimesh.Trimesh")
        try:
            copied = _chart_as_copy(pair, charted, inputs, names)
            charted.append(copied or _chart_mesh(*pair, cfg, seed, report))
        except (InvalidMeshError, ConfigError) as exc:
            raise type(exc)(f"{name}: {exc}") from None
        kept = copied is None and not charted[-1].remeshing.remeshed
        inputs.append(_input_arrays(pair) if kept else None)
    sets = [c.charts.charts for c in charted]
    total = sum(len(s) for s in sets)
    _check_room(total, cfg.pack, "the meshes have")
    _check_density(sum(float(face_areas(c.V, c.F).sum()) for c in charted), cfg.pack, "the meshes")
    timings: dict[str, float] = {}
    with _timed(timings, "pack"):
        uvs, faces, areas = [], [], []
        for c, charts in zip(charted, sets, strict=True):  # loop over meshes
            area = face_areas(c.V, c.F)
            uvs += [ch.uv for ch in charts]
            faces += [ch.local_F for ch in charts]
            areas += [float(area[ch.faces].sum()) for ch in charts]
        packing = pack_charts(uvs, faces, areas, config=cfg.pack)
    atlases = []
    start = 0
    for c, charts in zip(charted, sets, strict=True):  # loop over meshes
        stop = start + len(charts)
        part = dataclasses.replace(
            packing,
            uvs=packing.uvs[start:stop],
            transforms=packing.transforms[start:stop],
            utilization=float(
                sum(
                    np.abs(signed_areas(u, ch.local_F)).sum()
                    for u, ch in zip(packing.uvs[start:stop], charts, strict=True)
                )
            ),
        )
        atlases.append(
            _assemble(
                c.V,
                c.F,
                c.charts,
                part,
                config=cfg,
                seed=seed,
                timings={**c.timings, **timings},
                segmentation=c.segmentation,
                cleaning=c.cleaning,
                remeshing=c.remeshing,
            )
        )
        start = stop
    return MultiAtlas(atlases=tuple(atlases), packing=packing, names=tuple(names))


def _input_arrays(pair) -> tuple[np.ndarray, np.ndarray] | None:
    """A mesh's (V, F) as float64 / int64 arrays, or None when they are not such arrays (the
    stages then say what is wrong)."""
    try:
        V, F = mesh_arrays(*pair)
        return np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64)
    except (TypeError, ValueError, InvalidMeshError):
        return None


def _chart_as_copy(pair, charted: list, inputs: list, names: Sequence[str]) -> _Charted | None:
    """A mesh of :func:`build_atlases` charted as an earlier one, of which it is a copy: the
    same faces, its vertices the earlier mesh's moved by one rotation, uniform scale and
    translation (:func:`segparam.instances.similarity`), and cleaning leaving both alike (a
    GLB scene's nodes that place one mesh several times). Its own cleaned vertices, the earlier
    mesh's segmentation and charts, each map scaled by the size ratio. None when it is no copy
    (or the earlier mesh was remeshed, which moved its vertices)."""
    mine = _input_arrays(pair)
    if mine is None:
        return None
    V, F = mine
    for k, theirs in enumerate(inputs):  # loop over the meshes before it
        if theirs is None or theirs[1].shape != F.shape or not np.array_equal(theirs[1], F):
            continue
        scale = similarity(theirs[0], V)
        if scale is None:
            continue
        t0 = time.perf_counter()
        cleaned = clean(V, F)
        other = charted[k]
        if cleaned.F.shape != other.F.shape or not np.array_equal(cleaned.F, other.F):
            continue
        charts = [dataclasses.replace(c, uv=c.uv * scale) for c in other.charts.charts]
        chart_set = dataclasses.replace(other.charts, charts=tuple(charts))
        reason = f"{other.remeshing.reason}; a copy of {names[k]}, charted as it is"
        remeshed = dataclasses.replace(other.remeshing, V=cleaned.V, F=cleaned.F, reason=reason)
        log.info("%s: a copy of %s (scale %.6g), charted as it is", names[len(charted)],
                 names[k], scale)  # fmt: skip
        timings = {"clean": time.perf_counter() - t0}
        return _Charted(cleaned.V, cleaned.F, chart_set, timings, other.segmentation, cleaned,
                        remeshed)  # fmt: skip
    return None


@dataclass(frozen=True)
class _Charted:
    """A mesh through every stage but packing."""

    V: np.ndarray
    F: np.ndarray
    charts: ChartSet
    timings: dict
    segmentation: Segmentation
    cleaning: CleanResult
    remeshing: RemeshResult


def _chart_mesh(
    V: Any, F: Any, cfg: PipelineConfig, seed: int, report: Callable[[str, int, int], None]
) -> _Charted:
    """Clean, remesh, segment and parameterize one mesh (:func:`build_atlas` before packing),
    with the checks that can fail early (size, room for the charts, texel density)."""
    V, F = mesh_arrays(V, F)
    n_faces = len(F) if hasattr(F, "__len__") else 0
    if n_faces > MAX_FACES:
        raise InvalidMeshError(
            f"mesh has {n_faces} faces; the limit is {MAX_FACES} (about 3 KB of memory per face)"
        )
    # The split stage's worker processes start now: their start-up (2 s of CPU each) overlaps
    # with cleaning and segmenting, which run on one core. On the first run after installing,
    # so does the compilation of the packer's kernels (segparam.warmup), which the pack stage
    # then finds in numba's cache.
    compiling = warmup.start() if cfg.pack.method == "raster" else None
    workers = start_workers(cfg.split) if n_faces >= PARALLEL_MIN_FACES else None
    try:
        charted = _chart_stages(V, F, cfg, seed, report, workers)
    except BaseException:
        stop_workers(workers, now=True)
        warmup.stop(compiling, now=True)
        raise
    stop_workers(workers)
    if compiling is not None:  # the first run: the wait for the packer's kernels, if any
        with _timed(charted.timings, "compile"):
            warmup.stop(compiling)
    return charted


def _chart_stages(
    V: np.ndarray,
    F: np.ndarray,
    cfg: PipelineConfig,
    seed: int,
    report: Callable[[str, int, int], None],
    workers,
) -> _Charted:
    """:func:`_chart_mesh`'s stages, with the split stage's ``workers`` (or None)."""
    timings: dict[str, float] = {}
    with _timed(timings, "clean"):
        cleaned = clean(V, F)
    report("clean", 1, 1)
    if len(cleaned.F) > chart_room(cfg.pack.resolution or MAX_RESOLUTION, cfg.pack.padding):
        # Charts are connected: at least one per connected piece (clean counted them).
        pieces = cleaned.components
        _check_room(pieces, cfg.pack, f"the mesh has {pieces} connected pieces, so at least")
    _check_density(float(face_areas(cleaned.V, cleaned.F).sum()), cfg.pack)

    with _timed(timings, "remesh"):
        remeshed = remesh(cleaned.V, cleaned.F, config=cfg.remesh)
    Vm, Fm = remeshed.V, remeshed.F
    report("remesh", 1, 1)

    with _timed(timings, "segment"):
        seg = segment(Vm, Fm, config=cfg.segment, seed=seed)
        # pieces that are copies of another are charted as that one is (segparam.instances)
        repeats = find_repeats(Vm, Fm) if cleaned.components > 1 else None
    report("segment", 1, 1)
    _check_room(seg.n_charts, cfg.pack, "the segmentation made")  # splitting only adds charts

    with _timed(timings, "parameterize"):
        if repeats is None:
            chart_set = parameterize_charts(
                Vm,
                Fm,
                seg.labels,
                config=cfg.split,
                seed=seed,
                progress=lambda done: report("parameterize", done, seg.n_charts),
                affinity=seg.affinity,
                workers=workers,
                curvature=seg.face_curvature,
            )
        else:
            chart_set, seg = _parameterize_once(Vm, Fm, seg, repeats, cfg, seed, report, workers)
    # an (m, m) matrix and an (m,) array the atlas need not keep
    seg = dataclasses.replace(seg, affinity=None, face_curvature=None)
    return _Charted(Vm, Fm, chart_set, timings, seg, cleaned, remeshed)


def _parameterize_once(
    V: np.ndarray,
    F: np.ndarray,
    seg: Segmentation,
    repeats: Repeats,
    cfg: PipelineConfig,
    seed: int,
    report: Callable[[str, int, int], None],
    workers,
) -> tuple[ChartSet, Segmentation]:
    """:func:`segparam.split.parameterize_charts` of a mesh whose pieces repeat: every piece of
    no group, and a few of each group (:func:`segparam.instances.candidates`), in one call; the
    candidate whose charts distort least (area-weighted ``(L2^2 - 1) + (angle - 1)``) is copied
    to the other pieces of its group (:func:`segparam.instances.replicate`). Returns the chart
    set of the whole mesh and the segmentation with every piece cut as its group's choice."""
    tried = candidates(seg.labels, repeats)
    solve = np.ones(len(F), dtype=bool)
    for faces, rows in zip(repeats.faces, tried, strict=True):  # loop over groups
        solve[np.delete(faces, rows, axis=0).ravel()] = False
    solved = np.flatnonzero(solve)
    used, local_F = submesh(F, solved)
    sources, sub_labels = np.unique(seg.labels[solved], return_inverse=True)
    part = parameterize_charts(
        V[used],
        local_F,
        sub_labels.reshape(-1),
        config=cfg.split,
        seed=seed,
        progress=lambda done: report("parameterize", done, len(sources)),
        affinity=None if seg.affinity is None else seg.affinity[solved][:, solved],
        workers=workers,
        # whole pieces left out: the faces kept keep their shares
        curvature=None if seg.face_curvature is None else seg.face_curvature[solved],
    )
    charts = [
        dataclasses.replace(c, faces=solved[c.faces], vertices=used[c.vertices])
        for c in part.charts
    ]
    # per group, the candidate whose charts distort least (ties: the first)
    area = face_areas(V, F)
    excess = np.zeros(len(F))  # per face: its chart's (L2^2 - 1) + (angle - 1)
    for c in charts:  # loop over charts
        excess[c.faces] = (c.quality.l2_stretch**2 - 1) + (c.quality.angle_distortion - 1)
    chosen = []
    for faces, rows in zip(repeats.faces, tried, strict=True):  # loop over groups
        cost = (excess[faces[rows]] * area[faces[rows]]).sum(axis=1) / area[faces[rows]].sum(1)
        chosen.append(int(rows[np.argmin(cost)]))
    labels = expand_labels(seg.labels, repeats, chosen)
    charts = [dataclasses.replace(c, source=int(labels[c.faces[0]])) for c in charts]
    charts = replicate(charts, repeats, chosen, len(F), len(V), labels)
    n = int(labels.max()) + 1
    first, cut = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    first[labels[solved]] = part.first_pass_bijective[sub_labels.reshape(-1)]
    cut[labels[solved]] = part.cut_untried[sub_labels.reshape(-1)]
    for faces, c in zip(repeats.faces, chosen, strict=True):  # loop over groups
        first[labels[faces]] = first[labels[faces[c]]][None, :]
        cut[labels[faces]] = cut[labels[faces[c]]][None, :]
    splits = np.bincount([c.source for c in charts], minlength=n) - 1
    chart_set = ChartSet(
        charts=tuple(charts), splits=splits, first_pass_bijective=first, cut_untried=cut
    )
    copies = repeats.n_pieces - len(repeats.faces)
    log.info("instances: %d pieces charted as copies of %d parts", copies, len(repeats.faces))
    return chart_set, dataclasses.replace(seg, labels=labels, n_charts=n, copies=copies)


@contextlib.contextmanager
def _timed(timings: dict[str, float], stage: str) -> Iterator[None]:
    """Record the wall seconds of the block as ``timings[stage]``."""
    start = time.perf_counter()
    yield
    timings[stage] = time.perf_counter() - start


def pack_atlas(
    V: np.ndarray,
    F: np.ndarray,
    chart_set: ChartSet,
    *,
    config: PipelineConfig | None = None,
    seed: int = 0,
    timings: dict | None = None,
    segmentation: Segmentation | None = None,
    cleaning: CleanResult | None = None,
    remeshing: RemeshResult | None = None,
) -> Atlas:
    """Pack a chart set and assemble the :class:`Atlas` (the last stage of :func:`build_atlas`).

    The stage results that produced the charts are optional: they only feed the report.

    Raises
    ------
    ConfigError
        A seed out of range, or more charts than the texture has room for (:func:`chart_room`),
        before any packing.
    SolverError
        The packer found no scale at which the charts fit.
    """
    cfg = config or PipelineConfig()
    seed = check_seed(seed)
    timings = dict(timings or {})
    charts = chart_set.charts
    _check_room(len(charts), cfg.pack, "there are")
    with _timed(timings, "pack"):
        area = face_areas(V, F)
        packing = pack_charts(
            [c.uv for c in charts],
            [c.local_F for c in charts],
            [float(area[c.faces].sum()) for c in charts],
            config=cfg.pack,
        )
    return _assemble(
        V,
        F,
        chart_set,
        packing,
        config=cfg,
        seed=seed,
        timings=timings,
        segmentation=segmentation,
        cleaning=cleaning,
        remeshing=remeshing,
    )


def _assemble(
    V: np.ndarray,
    F: np.ndarray,
    chart_set: ChartSet,
    packing: PackResult,
    *,
    config: PipelineConfig,
    seed: int,
    timings: dict,
    segmentation: Segmentation | None,
    cleaning: CleanResult | None,
    remeshing: RemeshResult | None,
) -> Atlas:
    """The :class:`Atlas` of a chart set whose charts ``packing`` placed (in chart order)."""
    charts = chart_set.charts
    cfg = config
    sizes = np.array([len(c.vertices) for c in charts])
    offsets = np.r_[0, np.cumsum(sizes)[:-1]]
    uv = np.concatenate(packing.uvs)
    uv_vertex = np.concatenate([c.vertices for c in charts])
    n_faces = np.array([len(c.faces) for c in charts])
    faces = np.concatenate([c.faces for c in charts])  # every face once
    uv_F = np.empty_like(F)
    uv_F[faces] = np.concatenate([c.local_F for c in charts]) + np.repeat(offsets, n_faces)[:, None]
    chart_of_face = np.empty(len(F), dtype=np.int64)
    chart_of_face[faces] = np.repeat(np.arange(len(charts)), n_faces)
    return Atlas(
        V=V,
        F=F,
        uv=uv,
        uv_F=uv_F,
        uv_vertex=uv_vertex,
        chart_of_face=chart_of_face,
        charts=chart_set,
        packing=packing,
        segmentation=segmentation,
        cleaning=cleaning,
        remeshing=remeshing,
        timings=timings,
        config=cfg,
        seed=seed,
    )
