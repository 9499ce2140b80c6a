"""Baking per-vertex data into the atlas texture, and the values worth baking.

:func:`bake` interpolates per-vertex values linearly over every face *in uv space* (the texel
centres inside a uv triangle take the barycentric mix of its three corners' values) and fills
every other texel by pull-push (Gortler et al., *The Lumigraph*, 1996: averages of the covered
texels over an image pyramid, pushed back down into the holes), so that bilinear lookups and
mipmaps near a chart's border never mix in a background colour.

What to bake: :func:`mean_curvature` / :func:`gaussian_curvature`, :func:`normal_colors`
(object space), vertex colours of the input file (:func:`load_vertex_colors`) or a per-vertex
data file (:func:`load_vertex_data`: GIfTI, FreeSurfer morph files, ``.npy``, one-column text).
:func:`carry_to_atlas` moves input-vertex data onto the atlas's vertices (one to one without
remeshing, closest-point interpolation with it). :func:`colorize` maps a scalar to colours and
says which range it used.

Conventions: images are ``(height, width, ...)`` arrays (``width = height = resolution`` unless
the atlas's texture was trimmed, ``PackResult.size``) in picture order, row 0 at the top (v = 1),
as the PNG files and as OBJ/glTF texture lookups see them: texel ``(i, j)`` has its centre at
``u = (j + 1/2) / width``, ``v = 1 - (i + 1/2) / height``.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from .errors import MeshFileError, SegparamError
from .mesh import angle_defect, corner_angles, face_areas, vertex_normals

__all__ = [
    "BAKE_NAMES",
    "BakeError",
    "Baked",
    "bake",
    "bake_label",
    "bake_named",
    "carry_to_atlas",
    "colorize",
    "gaussian_curvature",
    "load_vertex_colors",
    "load_vertex_data",
    "mean_curvature",
    "normal_colors",
    "pull_push",
    "value_range",
]

# The built-in sources of `--bake NAME`; anything else is a per-vertex data file.
BAKE_NAMES = ("curvature", "mean-curvature", "gaussian-curvature", "normals", "vertex-colors")

# A texel centre counts as inside a triangle when its smallest barycentric coordinate is above
# -BARY_EPS: texel centres exactly on a shared edge are baked (by either face, same value) and
# not left to the fill.
BARY_EPS = 1e-9

# Colour scales clip at these percentiles of the data (curvature has a few extreme vertices at
# creases and spikes that would otherwise squeeze every other value into the middle colour).
ROBUST_PERCENTILES = (2.0, 98.0)


class BakeError(SegparamError, ValueError):
    """Per-vertex data that cannot be baked (wrong length, not numbers, unknown name)."""


@njit(cache=True, nogil=True)
def _bake_kernel(P, F, W, out, covered):  # pragma: no cover - compiled
    """Write into ``out[row, col]`` the barycentric mix of ``W[F[t]]`` at every texel centre
    inside triangle t (texel coordinates P, x = u * R, y = v * R, rows counted along y).

    Loops over the texels of each triangle's bounding box: compiled, because the per-texel work
    is a few multiply-adds and a numpy version would build (faces x box) temporaries.
    """
    rows, cols = covered.shape
    C = W.shape[1]
    for t in range(F.shape[0]):
        a, b, c = F[t, 0], F[t, 1], F[t, 2]
        xa, ya = P[a, 0], P[a, 1]
        xb, yb = P[b, 0], P[b, 1]
        xc, yc = P[c, 0], P[c, 1]
        det = (xb - xa) * (yc - ya) - (xc - xa) * (yb - ya)
        if det == 0.0:
            continue
        inv = 1.0 / det
        r0 = max(int(np.ceil(min(ya, yb, yc) - 0.5)), 0)
        r1 = min(int(np.floor(max(ya, yb, yc) - 0.5)), rows - 1)
        c0 = max(int(np.ceil(min(xa, xb, xc) - 0.5)), 0)
        c1 = min(int(np.floor(max(xa, xb, xc) - 0.5)), cols - 1)
        for r in range(r0, r1 + 1):
            y = r + 0.5
            for q in range(c0, c1 + 1):
                x = q + 0.5
                lb = ((x - xa) * (yc - ya) - (xc - xa) * (y - ya)) * inv
                lc = ((xb - xa) * (y - ya) - (x - xa) * (yb - ya)) * inv
                if 1.0 - lb - lc < -BARY_EPS or lb < -BARY_EPS or lc < -BARY_EPS:
                    continue
                # W_a + lb (W_b - W_a) + lc (W_c - W_a): exact where the corners agree
                for k in range(C):
                    out[r, q, k] = W[a, k] + lb * (W[b, k] - W[a, k]) + lc * (W[c, k] - W[a, k])
                covered[r, q] = True


@njit(cache=True, nogil=True)
def _pull(img, w):  # pragma: no cover - compiled
    """One level up: per 2x2 block (the last row/column alone at odd sizes), the mean of the
    block's covered texels, and whether it had any."""
    h, wd, C = img.shape
    H, W = (h + 1) // 2, (wd + 1) // 2
    out = np.zeros((H, W, C))
    count = np.zeros((H, W), dtype=np.int32)
    for r in range(h):
        for q in range(wd):
            if w[r, q]:
                count[r // 2, q // 2] += 1
                for k in range(C):
                    out[r // 2, q // 2, k] += img[r, q, k]
    for r in range(H):
        for q in range(W):
            if count[r, q] > 0:
                for k in range(C):
                    out[r, q, k] /= count[r, q]
    return out, count > 0


@njit(cache=True, nogil=True)
def _push(img, w, coarse):  # pragma: no cover - compiled
    """Every texel of `img` outside `w` takes the value of its block in `coarse` (in place)."""
    h, wd, C = img.shape
    for r in range(h):
        for q in range(wd):
            if not w[r, q]:
                for k in range(C):
                    img[r, q, k] = coarse[r // 2, q // 2, k]


def _pull_push_in_place(img: np.ndarray, covered: np.ndarray) -> None:
    levels = [(img, covered)]
    while levels[-1][1].shape != (1, 1):  # log2(R) levels
        levels.append(_pull(*levels[-1]))
    for (fine, w), (coarse, _) in zip(levels[-2::-1], levels[:0:-1], strict=True):
        _push(fine, w, coarse)


def pull_push(image: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """Fill the texels outside ``covered`` from the covered ones (pull-push).

    Pull: each coarser level holds, per 2x2 block, the mean of the block's covered texels and
    whether it had any. Push: from the coarsest level down, every uncovered texel takes the
    value of its block one level up. A texel next to a chart thus takes the mean of the chart
    texels in its 2x2 block when there are any, else of the 4x4 block, and so on: every texel of
    the result is filled, with colours of the nearest charts only (never a background colour),
    as long as one texel is covered. Compiled loops (numba), so the memory is the image and
    its pyramid (4/3 of it), about 11 bytes per texel and channel.

    Parameters
    ----------
    image : (h, w, C) float ndarray
    covered : (h, w) bool ndarray

    Returns
    -------
    (h, w, C) float64 ndarray
        ``image`` where covered, filled elsewhere (zeros if nothing is covered).
    """
    img = np.array(image, dtype=np.float64, order="C")
    _pull_push_in_place(img, np.ascontiguousarray(covered, dtype=np.bool_))
    return img


def bake(
    V: np.ndarray,
    F: np.ndarray,
    uv: np.ndarray,
    face_uv: np.ndarray,
    values: np.ndarray,
    resolution: int | tuple[int, int] = 1024,
    padding: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-vertex values drawn into the texture of an atlas.

    Parameters
    ----------
    V : (n, 3) float ndarray
        Mesh positions (only their count is used: values belong to mesh vertices).
    F : (m, 3) int ndarray
        Mesh triangles.
    uv : (k, 2) float ndarray
        Atlas coordinates in ``[0, 1]^2``.
    face_uv : (m, 3) int ndarray
        Rows of ``uv`` at each face corner (``Atlas.uv_F``).
    values : (n,) or (n, C) float ndarray
        One value (or C channels) per mesh vertex.
    resolution : int or (int, int)
        Texels per side, or the texture's (width, height) (an atlas's ``packing.size``).
    padding : int, optional
        Kept for the API's symmetry with the packer; every texel outside the charts is filled
        by :func:`pull_push` whatever its distance, so the padding is always filled.

    Returns
    -------
    image : (H, W) or (H, W, C) float64 ndarray
        Picture order (row 0 is v = 1); interpolated values at the texel centres inside a uv
        triangle, pull-push fill elsewhere.
    covered : (H, W) bool ndarray
        Texels whose centre lies in a uv triangle (the others were filled).
    """
    V = np.asarray(V)
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    face_uv = np.asarray(face_uv, dtype=np.int64).reshape(-1, 3)
    values = np.asarray(values, dtype=np.float64)
    scalar = values.ndim == 1
    W = values[:, None] if scalar else values
    if W.ndim != 2 or len(W) != len(V):
        raise BakeError(f"{len(values)} values for {len(V)} vertices")
    if face_uv.shape != F.shape:
        raise BakeError(f"face_uv has shape {face_uv.shape}, F has {F.shape}")
    from .raster import texture_size

    width, height = texture_size(resolution)
    if min(width, height) < 1:
        raise BakeError(f"resolution is {resolution}; it must be at least 1")
    # one row per (face, corner): the values of the mesh vertex at the uv corner
    corner_values = np.ascontiguousarray(W[F.ravel()])
    texels = np.array([width, height], dtype=np.float64)
    P = np.ascontiguousarray(np.asarray(uv, dtype=np.float64)[face_uv.ravel()] * texels)
    out = np.zeros((height, width, W.shape[1]))
    covered = np.zeros((height, width), dtype=np.bool_)
    corners = np.arange(3 * len(F), dtype=np.int64).reshape(-1, 3)
    _bake_kernel(P, corners, corner_values, out, covered)
    _pull_push_in_place(out, covered)
    image = out[::-1]  # rows were along v: flip to picture order (a view)
    covered = covered[::-1]
    return (image[..., 0] if scalar else image), covered


# ---------------------------------------------------------------------------------------------
# What to bake
# ---------------------------------------------------------------------------------------------


def _mixed_areas(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """The mixed Voronoi area of every vertex (Meyer et al. 2003, fig. 4): the Voronoi region
    within each non-obtuse triangle, ``(|e_ij|^2 cot k + |e_ik|^2 cot j) / 8``, and for an
    obtuse triangle half its area at the obtuse corner, a quarter at the other two."""
    ang = corner_angles(V, F)
    area = face_areas(V, F)
    P = np.asarray(V, dtype=np.float64)[F]
    # squared length of the edge opposite corner k
    sq = np.stack([((P[:, (k + 2) % 3] - P[:, (k + 1) % 3]) ** 2).sum(axis=1) for k in range(3)], 1)
    cot = 1.0 / np.tan(np.clip(ang, 1e-8, np.pi - 1e-8))
    # corner k gets the two edges at it: opposite k+1 (cot at k+1) and opposite k+2 (cot at k+2)
    voronoi = np.stack(
        [
            (sq[:, (k + 1) % 3] * cot[:, (k + 1) % 3] + sq[:, (k + 2) % 3] * cot[:, (k + 2) % 3])
            / 8
            for k in range(3)
        ],
        axis=1,
    )
    obtuse = ang > np.pi / 2
    share = np.where(obtuse, area[:, None] / 2, area[:, None] / 4)
    corner = np.where(obtuse.any(axis=1)[:, None], share, voronoi)
    return np.bincount(F.ravel(), weights=corner.ravel(), minlength=len(V))


def gaussian_curvature(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Discrete Gaussian curvature: angle defect over the vertex's mixed area (1/length^2)."""
    A = _mixed_areas(V, F)
    return np.divide(angle_defect(V, F), A, out=np.zeros(len(V)), where=A > 0)


def mean_curvature(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Signed discrete mean curvature ``H = -(Delta x . n) / 2`` (cotangent Laplacian, 1/length).

    ``Delta x = (1 / 2A) sum_j (cot a_ij + cot b_ij)(x_j - x_i)`` with A the mixed area (Meyer
    et al. 2003) is the mean-curvature normal ``-2 H n``; ``H`` from its component along the
    area-weighted vertex normal n is positive where convex (a sphere seen from outside, the
    gyri of a cortical surface) and negative where concave (sulci). Taking the normal
    component, not ``|Delta x|``, keeps boundary vertices sensible: their one-sided ring adds
    a large tangential part to ``Delta x`` and little normal part.
    """
    V = np.asarray(V, dtype=np.float64)
    ang = corner_angles(V, F)
    cot = 1.0 / np.tan(np.clip(ang, 1e-8, np.pi - 1e-8))
    lap = np.zeros_like(V)
    for k in range(3):  # the edge opposite corner k joins corners k+1 and k+2
        i, j = F[:, (k + 1) % 3], F[:, (k + 2) % 3]
        d = cot[:, k, None] * (V[j] - V[i])
        for c in range(3):
            lap[:, c] += np.bincount(i, weights=d[:, c], minlength=len(V))
            lap[:, c] -= np.bincount(j, weights=d[:, c], minlength=len(V))
    A = _mixed_areas(V, F)
    lap = np.divide(lap, 2 * A[:, None], out=np.zeros_like(lap), where=A[:, None] > 0)
    N = vertex_normals(V, F, weighting="area")
    return -(lap * N).sum(axis=1) / 2


def normal_colors(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Object-space normal map colours: the unit vertex normal mapped from [-1, 1] to [0, 1]."""
    return (vertex_normals(V, F, weighting="area") + 1.0) / 2.0


# Viridis (matplotlib's default scale: perceptually uniform, readable in grey) at 9 stops, and a
# blue-white-red diverging scale for signed data (curvature), both interpolated linearly.
_VIRIDIS = np.array(
    [
        [68, 1, 84],
        [71, 44, 122],
        [59, 81, 139],
        [44, 113, 142],
        [33, 144, 141],
        [39, 173, 129],
        [92, 200, 99],
        [170, 220, 50],
        [253, 231, 37],
    ]
)
_DIVERGING = np.array(
    [[33, 102, 172], [146, 197, 222], [247, 247, 247], [244, 165, 130], [178, 24, 43]]
)
COLORMAPS = {"viridis": _VIRIDIS, "diverging": _DIVERGING}


def colorize(
    values: np.ndarray, *, cmap: str | None = None, vrange: tuple[float, float] | None = None
) -> tuple[np.ndarray, dict]:
    """Colours of scalar values and the scale used.

    Parameters
    ----------
    values : float ndarray, any shape
    cmap : "viridis", "diverging" or None
        None: "diverging" when the values take both signs (symmetric range around 0), else
        "viridis".
    vrange : (low, high), optional
        Default: the 2nd and 98th percentiles of the finite values (:data:`ROBUST_PERCENTILES`).

    Returns
    -------
    rgb : (..., 3) uint8 ndarray
    scale : dict
        ``{"colormap": name, "range": [low, high]}`` (values outside are clipped), for the report.
    """
    x = np.asarray(values, dtype=np.float64)
    finite = x[np.isfinite(x)]
    if vrange is None:
        if len(finite) == 0:
            lo, hi = 0.0, 1.0
        else:
            lo, hi = (float(p) for p in np.percentile(finite, ROBUST_PERCENTILES))
    else:
        lo, hi = float(vrange[0]), float(vrange[1])
    if cmap is None:
        cmap = "diverging" if lo < 0 < hi else "viridis"
    if cmap == "diverging" and vrange is None:
        lo, hi = -max(-lo, hi), max(-lo, hi)
    if cmap not in COLORMAPS:
        raise BakeError(f"unknown colour map {cmap!r}; known: {', '.join(COLORMAPS)}")
    span = hi - lo if hi > lo else 1.0
    t = (x - lo) * (COLOR_STEPS / span)
    np.clip(np.nan_to_num(t, copy=False, nan=0.0), 0, COLOR_STEPS, out=t)
    t += 0.5
    return _lut(cmap)[t.astype(np.intp)], {"colormap": cmap, "range": [lo, hi]}


# Colour scales are looked up in a table of COLOR_STEPS + 1 entries (even: 0 of a symmetric
# range is an exact entry): neighbouring entries differ by under one 8-bit level, and a lookup
# costs a few bytes per texel where interpolating the stops took ~100.
COLOR_STEPS = 1024


@functools.cache
def _lut(cmap: str) -> np.ndarray:
    stops = COLORMAPS[cmap].astype(np.float64)
    t = np.linspace(0.0, len(stops) - 1, COLOR_STEPS + 1)
    k = np.minimum(t.astype(np.int64), len(stops) - 2)
    f = (t - k)[:, None]
    return np.round(stops[k] * (1 - f) + stops[k + 1] * f).astype(np.uint8)


# ---------------------------------------------------------------------------------------------
# Data from files
# ---------------------------------------------------------------------------------------------

# FreeSurfer's per-vertex "morph" (curv-format) files, named <hemi>.<measure>
_MORPH_MEASURES = {"thickness", "curv", "sulc", "area", "volume", "jacobian_white", "inflated.H"}


def _data_kind(path: Path) -> str:
    name = path.name.lower()
    if name.endswith(".gii") or name.endswith(".gii.gz"):
        return "gifti"
    if name.endswith(".npy"):
        return "npy"
    if name.endswith((".csv", ".txt", ".tsv")):
        return "text"
    if name.startswith(("lh.", "rh.")) or path.suffix.lstrip(".") in _MORPH_MEASURES:
        return "morph"
    raise BakeError(
        f"{path}: unknown per-vertex data file (GIfTI .gii, FreeSurfer lh./rh. morph file, .npy, "
        ".csv, .txt)"
    )


def load_vertex_data(path: str | os.PathLike, n_vertices: int | None = None) -> np.ndarray:
    """One number per vertex from a file: GIfTI (``.func.gii``, ``.shape.gii``: the first data
    array), a FreeSurfer morph file (``lh.thickness``, ``rh.curv`` ...), ``.npy`` or a one-column
    ``.csv`` / ``.txt`` (an optional header line is skipped).

    Raises
    ------
    BakeError
        One line: unreadable, not one column of numbers, or not ``n_vertices`` long.
    """
    path = Path(path)
    if not path.is_file():
        raise MeshFileError(f"{path}: no such file")
    kind = _data_kind(path)
    try:
        if kind == "gifti":
            import nibabel as nib

            img = nib.load(str(path))
            arrays = [d for d in img.darrays if d.intent != 1008 and d.intent != 1009]
            if not arrays:  # 1008/1009 = NIFTI_INTENT_POINTSET/TRIANGLE: a surface, no data
                raise BakeError(f"{path}: a GIfTI file without a data array")
            x = np.asarray(arrays[0].data)
        elif kind == "morph":
            import nibabel.freesurfer as fs

            x = np.asarray(fs.read_morph_data(str(path)))
        elif kind == "npy":
            x = np.load(path, allow_pickle=False)
        else:
            x = _load_text_column(path)
    except SegparamError:
        raise
    except Exception as exc:  # nibabel/numpy raise many kinds on a broken file
        raise BakeError(f"{path}: cannot read {kind} data: {str(exc).splitlines()[0]}") from None
    x = np.squeeze(np.asarray(x))
    if x.ndim != 1:
        raise BakeError(f"{path}: expected one value per vertex, got an array of shape {x.shape}")
    if not np.issubdtype(x.dtype, np.number):
        raise BakeError(f"{path}: values are not numbers ({x.dtype})")
    if n_vertices is not None and len(x) != n_vertices:
        raise BakeError(f"{path}: {len(x)} values, but the input mesh has {n_vertices} vertices")
    return x.astype(np.float64)


def _load_text_column(path: Path) -> np.ndarray:
    """One number per line (numpy's text reader); a first line that is not a number is a header."""
    with open(path, encoding="utf-8", errors="replace") as f:
        first = next((line.strip() for line in f if line.strip()), "")
    if not first:
        raise BakeError(f"{path}: no values")
    delimiter = "," if "," in first else ("\t" if "\t" in first else None)
    header = 0 if _is_number(first.split(delimiter)[0].strip()) else 1
    try:
        x = np.loadtxt(path, delimiter=delimiter, skiprows=header, ndmin=2, dtype=np.float64)
    except ValueError as exc:
        raise BakeError(f"{path}: not one number per line: {str(exc).splitlines()[0]}") from None
    if x.shape[1] != 1:
        raise BakeError(f"{path}: {x.shape[1]} columns; one value per line expected")
    return x[:, 0]


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def load_vertex_colors(path: str | os.PathLike, V: np.ndarray) -> np.ndarray:
    """Vertex colours of a mesh file (PLY ``red green blue``, OBJ ``v x y z r g b``, GLB
    ``COLOR_0``) as (n, 3) floats in [0, 1], row for row with ``V`` (:func:`segparam.io.load_mesh`).

    Read with trimesh without processing; the positions must match ``V`` row for row, so the
    colours belong to the right vertices.
    """
    import trimesh

    try:
        loaded = trimesh.load(str(path), process=False, maintain_order=True, force="mesh")
    except Exception as exc:  # trimesh raises many kinds on files it cannot read
        raise BakeError(f"{path}: cannot read vertex colours: {str(exc).splitlines()[0]}") from None
    colors = getattr(getattr(loaded, "visual", None), "vertex_colors", None)
    kind = getattr(getattr(loaded, "visual", None), "kind", None)
    if colors is None or kind != "vertex":
        raise BakeError(f"{path}: the file has no vertex colours")
    P = np.asarray(loaded.vertices, dtype=np.float64)
    if P.shape != np.shape(V) or not np.allclose(P, V, rtol=1e-6, atol=1e-9):
        raise BakeError(f"{path}: vertex colours do not line up with the loaded vertices")
    return np.asarray(colors, dtype=np.float64)[:, :3] / 255.0


# ---------------------------------------------------------------------------------------------
# From the input's vertices to the atlas's
# ---------------------------------------------------------------------------------------------


def carry_to_atlas(atlas, values: np.ndarray) -> np.ndarray:
    """Input-vertex values moved onto ``atlas.V``.

    Cleaning keeps input positions (``cleaning.vertex_index`` names each cleaned vertex's input
    vertex), so without remeshing the values map one to one. With remeshing every atlas vertex
    takes the barycentric interpolation of the cleaned mesh's values at its closest point on
    the cleaned surface (:func:`interpolate_at_closest`).
    """
    values = np.asarray(values, dtype=np.float64)
    cleaning = atlas.cleaning
    if cleaning is None:  # packed from saved charts: the values must already be per atlas vertex
        if len(values) != len(atlas.V):
            raise BakeError(f"{len(values)} values for an atlas of {len(atlas.V)} vertices")
        return values
    on_clean = values[cleaning.vertex_index]
    remeshed = atlas.remeshing is not None and atlas.remeshing.remeshed
    if not remeshed:
        return on_clean
    return interpolate_at_closest(cleaning.V, cleaning.F, on_clean, atlas.V)


# Candidate faces per query point in the closest-point search: the faces with the nearest
# centroids. Remeshed vertices lie within a fraction of an edge of the input surface, where the
# closest face is always among the few nearest centroids; 16 leaves a wide margin.
CLOSEST_CANDIDATES = 16


def _closest_on_triangles(P, A, B, C):
    """Barycentric weights (..., 3) of the point of triangle ABC closest to P (Ericson,
    *Real-Time Collision Detection*, 5.1.5: vertex, edge or face region), all at once."""
    ab, ac, ap = B - A, C - A, P - A
    bp, cp = P - B, P - C

    def dot(x, y):
        return (x * y).sum(axis=-1)

    d1, d2 = dot(ab, ap), dot(ac, ap)
    d3, d4 = dot(ab, bp), dot(ac, bp)
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v = np.where(denom != 0, vb / denom, 1 / 3)
        w = np.where(denom != 0, vc / denom, 1 / 3)
        out = np.stack([1 - v - w, v, w], axis=-1)  # inside the face
        # edge and vertex regions; later assignments take precedence (Ericson's test order)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        t_ac = d2 / (d2 - d6)
        t_ab = d1 / (d1 - d3)
        zero = np.zeros_like(d1)
        regions = [
            ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), (zero, 1 - t_bc, t_bc)),
            ((vb <= 0) & (d2 >= 0) & (d6 <= 0), (1 - t_ac, zero, t_ac)),
            ((d6 >= 0) & (d5 <= d6), (zero, zero, zero + 1)),
            ((vc <= 0) & (d1 >= 0) & (d3 <= 0), (1 - t_ab, t_ab, zero)),
            ((d3 >= 0) & (d4 <= d3), (zero, zero + 1, zero)),
            ((d1 <= 0) & (d2 <= 0), (zero + 1, zero, zero)),
        ]
        for mask, weights in regions:  # six regions
            out = np.where(mask[..., None], np.stack(weights, axis=-1), out)
    return np.nan_to_num(out, nan=1 / 3)


def interpolate_at_closest(
    V: np.ndarray, F: np.ndarray, values: np.ndarray, Q: np.ndarray
) -> np.ndarray:
    """Per-vertex ``values`` of mesh (V, F) interpolated at the closest surface point of each Q.

    Candidates are the :data:`CLOSEST_CANDIDATES` faces with the nearest centroids (scipy's
    cKDTree); the exact closest point on each, the nearest of them wins, and the values of its
    three corners are mixed with that point's barycentric weights.
    """
    from scipy.spatial import cKDTree

    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    Q = np.asarray(Q, dtype=np.float64)
    k = min(CLOSEST_CANDIDATES, len(F))
    _, cand = cKDTree(V[F].mean(axis=1)).query(Q, k=k)
    cand = cand.reshape(len(Q), k)
    T = V[F[cand]]  # (q, k, 3 corners, 3)
    bary = _closest_on_triangles(Q[:, None], T[:, :, 0], T[:, :, 1], T[:, :, 2])
    points = np.einsum("qkc,qkcd->qkd", bary, T)
    best = np.argmin(((points - Q[:, None]) ** 2).sum(axis=-1), axis=1)
    rows = np.arange(len(Q))
    face, w = cand[rows, best], bary[rows, best]
    return np.einsum("qc,qc...->q...", w, np.asarray(values, dtype=np.float64)[F[face]])


@dataclass(frozen=True)
class Baked:
    """One baked texture: the picture, the per-atlas-vertex values and the scale used.

    ``rgb`` is (R, R, 3) uint8 in picture order; ``values`` the per-vertex data on the atlas's
    vertices (a scalar or colours); ``scale`` ``{"colormap", "range"}`` for scalars, else None.
    """

    name: str
    rgb: np.ndarray
    values: np.ndarray
    scalar: np.ndarray | None
    scale: dict | None
    source: str


def bake_named(
    atlas, name: str, *, input_path=None, resolution: int | tuple[int, int] | None = None
) -> Baked:
    """Bake a built-in source (:data:`BAKE_NAMES`) or a per-vertex data file onto an atlas.

    ``curvature`` is the mean curvature; ``normals`` object-space normals; ``vertex-colors`` the
    input file's (``input_path``); any other name is a data file whose length must equal the
    input's vertex count (the cleaning's ``input_vertices``). The image is the atlas's texture
    (``packing.size``) unless ``resolution`` says otherwise.
    """
    R = resolution or atlas.packing.size
    scalar = None
    scale = None
    if name in ("curvature", "mean-curvature"):
        scalar = mean_curvature(atlas.V, atlas.F)
        source = "mean curvature (cotangent Laplacian)"
    elif name == "gaussian-curvature":
        scalar = gaussian_curvature(atlas.V, atlas.F)
        source = "Gaussian curvature (angle defect / area)"
    elif name == "normals":
        values = normal_colors(atlas.V, atlas.F)
        source = "object-space normals"
    elif name == "vertex-colors":
        if input_path is None:
            raise BakeError("vertex-colors needs the input file")
        from .io import load_mesh

        V0, _ = load_mesh(input_path)
        values = carry_to_atlas(atlas, load_vertex_colors(input_path, V0))
        source = f"vertex colours of {Path(input_path).name}"
    else:
        n = atlas.cleaning.input_vertices if atlas.cleaning is not None else len(atlas.V)
        scalar = carry_to_atlas(atlas, load_vertex_data(name, n))
        source = str(name)
    if scalar is not None:
        image, _ = bake(atlas.V, atlas.F, atlas.uv, atlas.uv_F, scalar, R)
        rgb, scale = colorize(image, vrange=value_range(scalar))
        values = scalar
    else:
        image, _ = bake(atlas.V, atlas.F, atlas.uv, atlas.uv_F, values, R)
        np.clip(image, 0, 1, out=image)  # in place: the image is ours
        image *= 255
        image += 0.5
        rgb = image.astype(np.uint8)
    return Baked(bake_label(name), rgb, values, scalar, scale, source)


def value_range(x: np.ndarray) -> tuple[float, float]:
    """The colour range of per-vertex values: :data:`ROBUST_PERCENTILES`, symmetric about 0 when
    the values take both signs (so 0 is the diverging scale's white)."""
    lo, hi = (float(p) for p in np.percentile(x[np.isfinite(x)], ROBUST_PERCENTILES))
    if lo < 0 < hi:
        m = max(-lo, hi)
        return -m, m
    return (lo, hi) if hi > lo else (lo - 0.5, lo + 0.5)


def bake_label(name: str) -> str:
    """The file-name part of a bake: the built-in name, or the data file's name without its
    extensions (``lh.thickness`` stays, ``sub-01.func.gii`` -> ``sub-01``)."""
    if name in BAKE_NAMES:
        return "curvature" if name == "mean-curvature" else name
    base = Path(name).name
    for ext in (".func.gii", ".shape.gii", ".gii.gz", ".gii", ".npy", ".csv", ".txt", ".tsv"):
        if base.lower().endswith(ext):
            return base[: -len(ext)] or "data"
    return base
