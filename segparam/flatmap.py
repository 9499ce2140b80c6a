"""Flat maps for neuroimaging: the atlas as a flat GIfTI surface, and a pycortex-style picture.

:func:`flat_gifti` puts every atlas vertex (one per uv row: vertices on a seam appear once per
chart) at ``(u, v, 0)`` with the atlas's triangles, and carries per-vertex data as GIfTI data
arrays after the two geometry arrays, so nibabel and nilearn (``load_surf_mesh``) read the flat
surface and the data from the same file (``<stem>_flat.gii``), the flat counterpart of
pycortex's flatmaps that tools in the GIfTI world (Connectome Workbench, nilearn) can open.
:func:`data_gifti` holds the same data alone (``<stem>_flat.func.gii``), for readers that take
geometry and data from separate files (nilearn's ``load_surf_data``).

:func:`render_flatmap` draws a scalar in the uv layout over curvature shading, the way pycortex
draws cortical flatmaps: sulci dark grey, gyri light grey, the data's colours laid over them
with the curvature still showing through (``<stem>_flatmap.png``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping

import numpy as np

from .bake import bake, colorize, mean_curvature, value_range

__all__ = ["CURVATURE_WEIGHT", "data_gifti", "flat_gifti", "render_flatmap", "write_flat_gifti"]

# How much of the curvature shading shows through the data's colours (pycortex draws its data
# layer over the curvature layer with partial opacity; 0.3 keeps the colours readable).
CURVATURE_WEIGHT = 0.3
# The curvature shading's greys: sulci (concave, H < 0) dark, gyri (convex) light.
SULCUS_GREY, GYRUS_GREY = 90.0, 190.0


def flat_gifti(
    uv: np.ndarray,
    face_uv: np.ndarray,
    data: Mapping[str, np.ndarray] | None = None,
    *,
    vertex_of_uv: np.ndarray | None = None,
):
    """A GIfTI image of the flat atlas.

    Parameters
    ----------
    uv : (k, 2) float ndarray
        Atlas coordinates; vertex i of the flat surface is ``(u_i, v_i, 0)``.
    face_uv : (m, 3) int ndarray
        Triangles into ``uv``.
    data : mapping name -> (k,) float ndarray, optional
        Per-uv-vertex values, one data array each (intent NIFTI_INTENT_SHAPE, the name in the
        array's ``Name`` metadata).
    vertex_of_uv : (k,) int ndarray, optional
        The atlas mesh vertex of each uv row; stored as an int32 data array named
        ``vertex_index`` so values can be moved back onto the 3-D mesh.

    Returns
    -------
    nibabel.gifti.GiftiImage
        Arrays in order: POINTSET (float32 (k, 3)), TRIANGLE (int32 (m, 3)), then the data.
    """
    from nibabel.gifti import GiftiDataArray, GiftiImage, GiftiMetaData

    uv = np.asarray(uv, dtype=np.float64)
    points = np.zeros((len(uv), 3), dtype=np.float32)
    points[:, :2] = uv
    arrays = [
        GiftiDataArray(points, intent="NIFTI_INTENT_POINTSET", datatype="NIFTI_TYPE_FLOAT32"),
        GiftiDataArray(
            np.asarray(face_uv, dtype=np.int32),
            intent="NIFTI_INTENT_TRIANGLE",
            datatype="NIFTI_TYPE_INT32",
        ),
    ]
    for name, values in (data or {}).items():
        values = np.asarray(values, dtype=np.float32)
        if values.shape != (len(uv),):
            raise ValueError(f"data {name!r} has shape {values.shape}; expected ({len(uv)},)")
        arrays.append(
            GiftiDataArray(
                values,
                intent="NIFTI_INTENT_SHAPE",
                datatype="NIFTI_TYPE_FLOAT32",
                meta=GiftiMetaData({"Name": str(name)}),
            )
        )
    if vertex_of_uv is not None:
        arrays.append(
            GiftiDataArray(
                np.asarray(vertex_of_uv, dtype=np.int32),
                intent="NIFTI_INTENT_NONE",
                datatype="NIFTI_TYPE_INT32",
                meta=GiftiMetaData({"Name": "vertex_index"}),
            )
        )
    meta = GiftiMetaData({"AnatomicalStructureSecondary": "Flat", "GeometricType": "Flat"})
    return GiftiImage(darrays=arrays, meta=meta)


def data_gifti(data: Mapping[str, np.ndarray]):
    """Per-vertex data alone, one NIFTI_INTENT_SHAPE array each (named), as a GIfTI image:
    the ``<stem>_flat.func.gii`` beside ``<stem>_flat.gii``, for tools that read geometry and
    data from separate files (nilearn's ``load_surf_data`` gives a (k, arrays) matrix)."""
    from nibabel.gifti import GiftiDataArray, GiftiImage, GiftiMetaData

    arrays = [
        GiftiDataArray(
            np.asarray(values, dtype=np.float32),
            intent="NIFTI_INTENT_SHAPE",
            datatype="NIFTI_TYPE_FLOAT32",
            meta=GiftiMetaData({"Name": str(name)}),
        )
        for name, values in data.items()  # a loop over the few named arrays
    ]
    return GiftiImage(darrays=arrays)


def write_flat_gifti(
    path: str | os.PathLike,
    uv: np.ndarray,
    face_uv: np.ndarray,
    data: Mapping[str, np.ndarray] | None = None,
    *,
    vertex_of_uv: np.ndarray | None = None,
) -> None:
    """Write :func:`flat_gifti` to ``path`` (``<stem>_flat.gii``; base64-gzip encoded)."""
    import nibabel as nib

    nib.save(flat_gifti(uv, face_uv, data, vertex_of_uv=vertex_of_uv), os.fspath(path))


def render_flatmap(
    V: np.ndarray,
    F: np.ndarray,
    uv: np.ndarray,
    face_uv: np.ndarray,
    values: np.ndarray | None = None,
    *,
    resolution: int | tuple[int, int] = 1024,
    curvature: np.ndarray | None = None,
    vrange: tuple[float, float] | None = None,
    cmap: str | None = None,
) -> tuple[np.ndarray, dict | None]:
    """A scalar drawn in the uv layout over curvature shading (pycortex's flatmap look).

    Parameters
    ----------
    V, F, uv, face_uv : the atlas (positions, triangles, uv rows, uv row per face corner)
    values : (n,) float ndarray, optional
        Per mesh vertex; None draws the curvature alone.
    curvature : (n,) float ndarray, optional
        Default: the mean curvature of (V, F).
    vrange, cmap : see :func:`segparam.bake.colorize`.

    Returns
    -------
    rgb : (H, W, 3) uint8 ndarray
        Picture order (``resolution``: a side or a (width, height)); white outside the charts.
    scale : dict or None
        The data's colour map and range (None without values).
    """
    if curvature is None:
        curvature = mean_curvature(V, F)
    curv, covered = bake(V, F, uv, face_uv, curvature, resolution)
    # grey by the sign of the curvature, softened by its size (tanh of curvature / its spread)
    spread = float(np.percentile(np.abs(curvature), 90)) or 1.0
    grey = (SULCUS_GREY + GYRUS_GREY) / 2 + (GYRUS_GREY - SULCUS_GREY) / 2 * np.tanh(curv / spread)
    rgb = np.repeat(grey[..., None], 3, axis=2)
    scale = None
    if values is not None:
        data, _ = bake(V, F, uv, face_uv, values, resolution)
        vrange = value_range(values) if vrange is None else vrange
        colours, scale = colorize(data, vrange=vrange, cmap=cmap)
        rgb = (1 - CURVATURE_WEIGHT) * colours + CURVATURE_WEIGHT * rgb
    rgb = np.round(rgb).astype(np.uint8)
    rgb[~covered] = 255
    return rgb, scale
