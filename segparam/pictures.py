"""The pictures and data files of an atlas folder, made in memory for the atlas writer.

Which files (:class:`PictureOptions`): ``<stem>_preview.png`` (:mod:`segparam.render`),
``<stem>.html`` (:mod:`segparam.viewer`), ``<stem>_<NAME>.png`` per bake (:mod:`segparam.bake`)
and, for cortical surfaces, ``<stem>_flat.gii``, ``<stem>_flat.func.gii`` and
``<stem>_flatmap.png``
(:mod:`segparam.flatmap`). :func:`check_bakes` refuses a bad ``--bake`` before any work;
:func:`make_pictures` returns every file's bytes and the report's ``pictures`` section, so that
the writer can put them into its staging folder with the other files (all or nothing).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .bake import (
    BAKE_NAMES,
    BakeError,
    bake_label,
    bake_named,
    load_vertex_colors,
    load_vertex_data,
    mean_curvature,
)

__all__ = [
    "SHARED_BAKES",
    "MeshSet",
    "PictureOptions",
    "check_bakes",
    "check_several",
    "flat_default",
    "make_pictures",
    "merge_atlases",
]

#: The bakes made for several meshes sharing one texture (``segparam atlas a.obj b.obj``): they
#: need only the charted meshes. Vertex colours and data files belong to one input file each.
SHARED_BAKES = ("curvature", "mean-curvature", "gaussian-curvature", "normals")


@dataclass(frozen=True)
class PictureOptions:
    """What :func:`make_pictures` makes.

    Attributes
    ----------
    preview : bool
        ``<stem>_preview.png`` (4 views, checker, seams).
    viewer : bool
        ``<stem>.html``.
    bakes : tuple of str
        Built-in names (:data:`segparam.bake.BAKE_NAMES`) or per-vertex data files.
    flat : bool
        ``<stem>_flat.gii``, ``<stem>_flat.func.gii`` and ``<stem>_flatmap.png``.
    input_path : str, optional
        The input mesh file (``vertex-colors`` reads it).
    """

    preview: bool = True
    viewer: bool = True
    bakes: tuple[str, ...] = ()
    flat: bool = False
    input_path: str | None = None

    def file_names(self, stem: str) -> dict[str, str]:
        """The files made, by role (``bake:<label>`` for bakes)."""
        names = {}
        if self.preview:
            names["preview"] = f"{stem}_preview.png"
        if self.viewer:
            names["viewer"] = f"{stem}.html"
        for name in self.bakes:
            names[f"bake:{bake_label(name)}"] = f"{stem}_{bake_label(name)}.png"
        if self.flat:
            names["flat"] = f"{stem}_flat.gii"
            names["flat_data"] = f"{stem}_flat.func.gii"
            names["flatmap"] = f"{stem}_flatmap.png"
        return names


def check_bakes(bakes, input_path: str | os.PathLike | None, V_input: np.ndarray) -> None:
    """Refuse, before any work, a bake that would fail at the end: a data file that cannot be
    read or whose length is not the input's vertex count, an input without vertex colours, two
    bakes with the same file name. One line each (:class:`~segparam.bake.BakeError`)."""
    labels = {}
    for name in bakes:
        label = bake_label(name)
        if label in labels:
            raise BakeError(
                f"--bake {name} and --bake {labels[label]} would both write _{label}.png"
            )
        if label in ("checker", "uv", "preview", "flat", "flatmap"):
            raise BakeError(f"--bake {name}: _{label}.png is an atlas file of its own")
        labels[label] = name
        if name == "vertex-colors":
            if input_path is None:
                raise BakeError("--bake vertex-colors needs an input file")
            load_vertex_colors(input_path, V_input)
        elif name not in BAKE_NAMES:
            load_vertex_data(name, len(V_input))


def check_several(options: PictureOptions, n_meshes: int) -> None:
    """Refuse, before any work, the pictures that several meshes in one texture cannot have:
    ``--flat`` (a flat map is one surface's) and bakes other than :data:`SHARED_BAKES`
    (vertex colours and per-vertex data files are per input). One line
    (:class:`~segparam.bake.BakeError`)."""
    if n_meshes <= 1:
        return
    if options.flat:
        raise BakeError(f"--flat makes the flat map of one mesh, got {n_meshes} meshes")
    for name in options.bakes:
        if name not in SHARED_BAKES:
            raise BakeError(
                f"--bake {name}: per-input data, but {n_meshes} meshes share the texture; "
                f"with several meshes bake {', '.join(SHARED_BAKES)}"
            )


@dataclass(frozen=True)
class MeshSet:
    """Several atlases that share one texture, seen as one mesh of disjoint parts: what
    :func:`make_pictures` and :func:`segparam.export.render_uv_layout` read of an atlas (``V``,
    ``F``, ``uv``, ``uv_F``, ``uv_vertex``, ``chart_of_face``, ``packing``), so that the set
    gets the pictures of one atlas from the same code (:func:`merge_atlases`)."""

    V: np.ndarray
    F: np.ndarray
    uv: np.ndarray
    uv_F: np.ndarray
    uv_vertex: np.ndarray
    chart_of_face: np.ndarray
    packing: Any
    cleaning: None = None  # no one input file: no vertex colours or data files to carry
    remeshing: None = None


def merge_atlases(atlases, packing) -> MeshSet:
    """The :class:`MeshSet` of ``atlases`` packed together into ``packing``: each atlas's rows
    after the previous ones' (vertices, uv rows, charts numbered on)."""
    sizes = np.array([[len(a.V), len(a.uv), a.n_charts] for a in atlases], dtype=np.int64)
    starts = np.vstack([np.zeros((1, 3), dtype=np.int64), np.cumsum(sizes, axis=0)[:-1]])
    v0, r0, c0 = (starts[:, j] for j in range(3))
    return MeshSet(
        V=np.concatenate([a.V for a in atlases]),
        F=np.concatenate([a.F + o for a, o in zip(atlases, v0, strict=True)]),
        uv=np.concatenate([a.uv for a in atlases]),
        uv_F=np.concatenate([a.uv_F + o for a, o in zip(atlases, r0, strict=True)]),
        uv_vertex=np.concatenate([a.uv_vertex + o for a, o in zip(atlases, v0, strict=True)]),
        chart_of_face=np.concatenate(
            [a.chart_of_face + o for a, o in zip(atlases, c0, strict=True)]
        ),
        packing=packing,
    )


def _png(pixels: np.ndarray) -> bytes:
    from .export import _png_bytes

    return _png_bytes(np.ascontiguousarray(pixels, dtype=np.uint8))


def make_pictures(
    atlas, stem: str, options: PictureOptions, *, checker_png: bytes, uv_png: bytes
) -> tuple[dict[str, bytes], dict[str, Any]]:
    """Every picture file of ``options`` for ``atlas``: ``{file name: bytes}`` and the report's
    ``pictures`` section (per bake: file, source, colour map and range; seconds per picture)."""
    from .flatmap import data_gifti, flat_gifti, render_flatmap
    from .render import render_preview
    from .viewer import viewer_html

    names = options.file_names(stem)
    files: dict[str, bytes] = {}
    seconds: dict[str, float] = {}
    info: dict[str, Any] = {"seconds": seconds}
    checker = None
    if options.preview:
        from .export import CHECKER_SQUARES, _checker_pixels, checker_size

        t = time.perf_counter()
        checker = _checker_pixels(checker_size(atlas.packing.size), CHECKER_SQUARES)
        files[names["preview"]] = _png(
            render_preview(atlas.V, atlas.F, atlas.uv, atlas.uv_F, checker)
        )
        seconds["preview"] = time.perf_counter() - t
    baked = []
    for name in options.bakes:
        t = time.perf_counter()
        b = bake_named(atlas, name, input_path=options.input_path)
        baked.append(b)
        files[names[f"bake:{b.name}"]] = _png(b.rgb)
        seconds[f"bake {b.name}"] = time.perf_counter() - t
    info["bakes"] = [
        {"file": names[f"bake:{b.name}"], "source": b.source, **(b.scale or {})} for b in baked
    ]
    if options.flat:
        t = time.perf_counter()
        curvature = mean_curvature(atlas.V, atlas.F)
        data = {"curvature": curvature[atlas.uv_vertex]}
        for b in baked:
            if b.scalar is not None:
                data[b.name] = b.scalar[atlas.uv_vertex]
        # the flat surface in the texture's proportions (u over [0, 1], v over height / width)
        flat_uv = atlas.packing.isotropic(atlas.uv)
        img = flat_gifti(flat_uv, atlas.uv_F, data, vertex_of_uv=atlas.uv_vertex)
        files[names["flat"]] = img.to_xml()
        files[names["flat_data"]] = data_gifti(data).to_xml()
        # the first baked scalar other than curvature over the curvature shading (else none)
        shown = next((b for b in baked if b.scalar is not None and "curvature" not in b.name), None)
        rgb, scale = render_flatmap(
            atlas.V,
            atlas.F,
            atlas.uv,
            atlas.uv_F,
            None if shown is None else shown.scalar,
            resolution=atlas.packing.size,
            curvature=curvature,
        )
        files[names["flatmap"]] = _png(rgb)
        info["flatmap"] = {"file": names["flatmap"], "data": None if shown is None else shown.name}
        if scale:
            info["flatmap"].update(scale)
        seconds["flat"] = time.perf_counter() - t
    if options.viewer:
        t = time.perf_counter()
        textures: dict[str, object] = {"checker": checker_png}
        for b in baked:
            textures[b.name] = files[names[f"bake:{b.name}"]]
        textures["uv layout"] = uv_png
        page = viewer_html(atlas.V, atlas.F, atlas.uv, atlas.uv_F, textures, title=stem)
        files[names["viewer"]] = page.encode("utf-8")
        seconds["viewer"] = time.perf_counter() - t
    return files, info


def flat_default(input_path: str | os.PathLike | None) -> bool:
    """Flat maps by default for cortical surfaces: GIfTI inputs (``.gii``, ``.gii.gz``)."""
    if input_path is None:
        return False
    name = Path(input_path).name.lower()
    return name.endswith(".gii") or name.endswith(".gii.gz")
