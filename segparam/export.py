"""The files of an atlas: OBJ + MTL + checker PNG, GLB, the uv-layout PNG and ``report.json``.

:func:`save_atlas` writes them all at once into a folder (through
:func:`segparam.io.staged_outputs`: all or nothing); :func:`write_obj`, :func:`render_uv_layout`
and :func:`checker_image` are the pieces, also used by ``segparam chart``. Coordinates keep their
float64 value: OBJ text with 17 significant digits; a GLB far from the origin stores its offset
as a float64 node translation. Mesh files in (and the output-folder checks) are
:mod:`segparam.io`.
"""

from __future__ import annotations

import functools
import os
import struct
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .errors import MeshFileError
from .io import (
    all_file_names,
    atlas_file_names,
    atlas_stem,
    atomic_path,
    check_output_folder,
    error_reason,
    multi_atlas_file_names,
    staged_outputs,
)

__all__ = ["checker_image", "render_uv_layout", "save_atlas", "save_atlases", "write_obj"]


# 17 significant digits write every float64 so that it reads back bit for bit (9 digits moved a
# 3-unit object 1e7 from the origin by 0.05); uvs too, so that no reloaded sliver flips.
_FLOAT_FORMAT = "%.17g"
# Rows formatted by one ``%`` call: bounds the tuple of Python numbers it needs.
_ROW_CHUNK = 65536


def write_obj(
    path: str | os.PathLike,
    V: np.ndarray,
    F: np.ndarray,
    *,
    uv: np.ndarray | None = None,
    uv_faces: np.ndarray | None = None,
    mtl: str | None = None,
    material: str = "atlas",
) -> None:
    """Write an OBJ with optional texture coordinates (``vt``) and a material library.

    Coordinates are written with 17 significant digits: :func:`segparam.io.load_mesh` reads back
    the same float64 values bit for bit.

    Parameters
    ----------
    V : (n, 3) float ndarray
    F : (m, 3) int ndarray
    uv : (k, 2) float ndarray, optional
        Texture coordinates; with ``uv_faces`` they may be split along seams.
    uv_faces : (m, 3) int ndarray, optional
        Rows of ``uv`` per face corner; default ``F`` (one uv per vertex).
    mtl : str, optional
        Name of an MTL file to reference (``mtllib``), with ``usemtl material``.
    """
    F = np.asarray(F)
    head = "# written by segparam\n" + (f"mtllib {mtl}\n" if mtl else "")
    body = [head.encode(), _rows("v", V, _FLOAT_FORMAT)]
    if uv is not None:
        body.append(_rows("vt", uv, _FLOAT_FORMAT))
        T = F if uv_faces is None else np.asarray(uv_faces)
        corners = np.stack([F + 1, T + 1], axis=2).reshape(len(F), 6)
        faces = _rows("f", corners, "%d", sep=("/", " "))
    else:
        faces = _rows("f", F + 1, "%d")
    if mtl:
        body.append(f"usemtl {material}\n".encode())
    body.append(faces)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.writelines(body)


def _rows(tag: str, A: np.ndarray, fmt: str, sep: tuple[str, str] | None = None) -> bytes:
    """A 2-D array as OBJ lines ``tag a b c`` (ASCII), each number formatted with ``fmt``.

    The text is what ``np.savetxt(A, fmt=f"{tag} {row}")`` writes. Whole numbers that are not
    negative are laid out digit by digit with numpy (:func:`_index_text`); other numbers go
    through one ``%`` formatting call per block of rows, not one per row.
    """
    A = np.asarray(A)
    if A.size == 0:
        return b""
    k = A.shape[1]
    if sep is None:
        seps = [" "] * (k - 1)
    else:  # pairs joined by sep[0], pairs separated by sep[1]: "f 1/1 2/2 3/3"
        seps = [sep[i % 2] for i in range(k - 1)]
    if fmt == "%d" and A.dtype.kind in "iu" and A.min() >= 0:
        return _index_text(f"{tag} ", A, "".join(seps) + "\n")
    line = f"{tag} " + "".join(fmt + s for s in [*seps, "\n"])
    parts = []
    for start in range(0, len(A), _ROW_CHUNK):
        block = A[start : start + _ROW_CHUNK]
        parts.append((line * len(block)) % tuple(block.ravel().tolist()))
    return "".join(parts).encode("ascii")


def _index_text(prefix: str, A: np.ndarray, seps: str) -> bytes:
    """Rows ``prefix a0 s0 a1 s1 ... a(k-1) s(k-1)`` of non-negative integers ``A`` (r, k), in
    decimal; ``seps`` holds one ASCII character per column (the last one ends the line).

    Every number is first written with as many digits as the largest one, into a byte table of
    fixed-width rows; then its leading zeros (and nothing else) are dropped in one pass. numpy
    loops over digit positions, never over rows; blocks of rows bound the memory.
    """
    r, k = A.shape
    top = int(A.max())
    D = len(str(top))  # digits of the largest number
    dtype = np.uint32 if top < 2**32 else np.uint64  # division is faster on narrow integers
    head = len(prefix)
    width = head + k * (D + 1)
    parts = []
    for start in range(0, r, _ROW_CHUNK):
        B = A[start : start + _ROW_CHUNK].astype(dtype)
        n = len(B)
        text = np.empty((n, width), dtype=np.uint8)
        keep = np.ones((n, width), dtype=bool)
        text[:, :head] = np.frombuffer(prefix.encode("ascii"), np.uint8)
        cells = text[:, head:].reshape(n, k, D + 1)  # D digits and the separator per number
        cells[:, :, D] = np.frombuffer(seps.encode("ascii"), np.uint8)
        q = B
        for j in range(D - 1, -1, -1):  # loop over digit positions, lowest first
            q, digit = np.divmod(q, dtype(10))
            np.add(digit, ord("0"), out=cells[:, :, j], casting="unsafe")
        leading = keep[:, head:].reshape(n, k, D + 1)
        for j in range(D - 1):  # digit j is a leading zero when the number is below 10**(D-1-j)
            np.greater_equal(B, dtype(10 ** (D - 1 - j)), out=leading[:, :, j])
        parts.append(text[keep].tobytes())
    return b"".join(parts)


def _palette(k: int) -> np.ndarray:
    """``k`` distinct, reproducible light colours (golden-ratio hues), uint8 (k, 3)."""
    import colorsys

    hues = (np.arange(k) * 0.618033988749895) % 1.0
    return np.array([colorsys.hsv_to_rgb(h, 0.45, 0.95) for h in hues]) * 255  # loop over charts


def render_uv_layout(
    uv: np.ndarray,
    F: np.ndarray,
    *,
    labels: np.ndarray | None = None,
    size: int | tuple[int, int] = 1024,
    outline: bool = True,
):
    """Picture of a uv layout in the unit square: charts filled in distinct colours, outlined.

    Triangles are rasterized chart by chart with the packer's conservative rasterizer (no
    per-triangle drawing calls); each chart's boundary loops are drawn as polylines.

    Parameters
    ----------
    uv : (k, 2) float ndarray
        Coordinates in ``[0, 1]^2``.
    F : (m, 3) int ndarray
        Triangles into ``uv``.
    labels : (m,) int ndarray, optional
        Chart of each face (default: one chart).
    size : int or (int, int)
        Pixels per side, or the picture's (width, height): an atlas's ``packing.size``, the
        texture's texels.

    Returns
    -------
    PIL.Image.Image
    """
    from PIL import Image, ImageDraw

    from .mesh import boundary_loops, group_by_label
    from .raster import rasterize_triangles, texture_size

    width, height = texture_size(size)
    wh = np.array([width, height], dtype=np.float64)
    labels = np.zeros(len(F), dtype=np.int64) if labels is None else np.asarray(labels)
    n = int(labels.max()) + 1
    # colour of each chart's number + 1; 0 (no chart) is white
    lut = np.vstack([[255, 255, 255], _palette(n)]).astype(np.uint8)
    chart = np.zeros((height, width), dtype=np.uint8 if n < 255 else np.int64)
    order, bounds = group_by_label(labels, n)
    groups = [order[bounds[k] : bounds[k + 1]] for k in range(n)]
    P = np.asarray(uv, dtype=np.float64) * wh
    for k, faces in enumerate(groups):  # loop over charts
        if len(faces) == 0:
            continue
        rows, cols = _texel_box(P[F[faces].ravel()], (width, height))  # the chart's texels
        corner = np.array([cols.start, rows.start], dtype=np.float64)  # exact: 0 <= it <= P
        shape = (rows.stop - rows.start, cols.stop - cols.start)
        mask = rasterize_triangles(P - corner, F[faces], shape, 0.0)
        np.copyto(chart[rows, cols], k + 1, where=mask)
    image = Image.fromarray(lut.take(chart[::-1], axis=0))  # row 0 is v = 0: flip, v grows up
    if outline:
        draw = ImageDraw.Draw(image)
        P = uv * wh
        P[:, 1] = height - P[:, 1]
        # the loops of all charts at once: one colour, so the order they are drawn in is moot
        for loop in boundary_loops(np.asarray(F)):  # loop over boundary loops
            pts = P[np.r_[loop, loop[:1]]]
            draw.line(list(map(tuple, pts.tolist())), fill=(40, 40, 40), width=1)
    return image


def _texel_box(Q: np.ndarray, size: tuple[int, int]) -> tuple[slice, slice]:
    """Rows and columns of a ``(width, height)`` grid that hold every texel a conservative
    rasterization of points ``Q`` (texel units) can touch: their bounding box and one texel
    around it."""
    width, height = size
    lo, hi = Q.min(axis=0), Q.max(axis=0)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        return slice(0, height), slice(0, width)
    c0, r0 = np.clip(np.floor(lo) - 1, 0, [width, height]).astype(np.int64)
    c1, r1 = np.clip(np.floor(hi) + 2, 0, [width, height]).astype(np.int64)
    return slice(int(r0), int(r1)), slice(int(c0), int(c1))


#: The checker texture's pixels along u (its squares: ``CHECKER_SIZE / CHECKER_SQUARES`` each).
CHECKER_SIZE = 1024
CHECKER_SQUARES = 16


def checker_size(texture: tuple[int, int]) -> tuple[int, int]:
    """The checker texture's (width, height) for an atlas texture of ``(width, height)``
    texels: `CHECKER_SIZE` wide, as tall as keeps its squares square on the atlas."""
    width, height = texture
    return CHECKER_SIZE, max(1, int(round(CHECKER_SIZE * height / width)))


def checker_image(size: int | tuple[int, int] = CHECKER_SIZE, squares: int = CHECKER_SQUARES):
    """A checkerboard texture with a colour ramp (so flips and rotations show), PIL image;
    ``size`` is its side or its (width, height), and ``squares`` how many squares span its
    width."""
    from PIL import Image

    return Image.fromarray(_checker_pixels(size, squares))


def _checker_pixels(size: int | tuple[int, int], squares: int) -> np.ndarray:
    """The pixels of :func:`checker_image`, (height, width, 3) uint8.

    Red ramps along the columns, green down the rows, blue is constant, and dark squares take
    35% of each: every channel is a lookup by row or by column, broadcast over the image.
    """
    from .raster import texture_size

    width, height = texture_size(size)
    a, b = np.arange(width), np.arange(height)
    cell = max(1, width // squares)
    col_parity, row_parity = (a // cell) % 2 == 1, (b // cell) % 2 == 1
    dark = row_parity[:, None] != col_parity[None, :]  # (i // cell + j // cell) is odd
    red = (80 + 150 * a / width).astype(np.uint8)  # by column
    green = (80 + 150 * (1 - b / height)).astype(np.uint8)  # by row
    blue = np.full(1, 200, dtype=np.uint8)
    img = np.empty((height, width, 3), dtype=np.uint8)
    img[..., 0] = np.where(dark, (red * 0.35).astype(np.uint8), red)
    img[..., 1] = np.where(dark, (green * 0.35).astype(np.uint8)[:, None], green[:, None])
    img[..., 2] = np.where(dark, (blue * 0.35).astype(np.uint8), blue)
    return img


@functools.lru_cache(maxsize=4)
def _checker_png(
    size: tuple[int, int] = (CHECKER_SIZE, CHECKER_SIZE), squares: int = CHECKER_SQUARES
) -> bytes:
    """:func:`checker_image` as PNG bytes, made once per size (the atlas writes it twice: the
    ``_checker.png`` file and the texture inside the GLB)."""
    return _png_bytes(_checker_pixels(size, squares))


def _png_bytes(pixels: np.ndarray) -> bytes:
    """A PNG file of an (h, w, 3) uint8 RGB image (Pillow, its default compression: the 1024 x
    1024 checker in 16 ms and 10 KB; a zlib-level-1 encoder of our own took 5 ms for 30 KB)."""
    import io as _io

    from PIL import Image

    pixels = np.asarray(pixels)
    if pixels.dtype != np.uint8 or pixels.ndim != 3 or pixels.shape[2] != 3:
        raise ValueError(f"expected an (h, w, 3) uint8 image, got {pixels.dtype} {pixels.shape}")
    buf = _io.BytesIO()
    Image.fromarray(pixels, mode="RGB").save(buf, format="PNG")
    return buf.getvalue()


def _write_material(
    stage: Path, mtl_name: str, checker_name: str, texture: tuple[int, int]
) -> bytes:
    """The checker texture (for an atlas texture of ``(width, height)`` texels) and the MTL
    file that maps it; returns the PNG bytes (the GLB embeds them too)."""
    checker = _checker_png(checker_size(texture))
    (stage / checker_name).write_bytes(checker)
    (stage / mtl_name).write_text(
        f"# written by segparam\nnewmtl atlas\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\n"
        f"map_Kd {checker_name}\n",
        encoding="utf-8",
    )
    return checker


def _write_mesh(
    stage: Path, atlas, obj_name: str, glb_name: str | None, mtl_name: str, checker: bytes
) -> None:
    """One atlas's mesh files: the OBJ with its uvs (material ``mtl_name``) and, when named,
    the GLB with the ``checker`` texture."""
    write_obj(stage / obj_name, atlas.V, atlas.F, uv=atlas.uv, uv_faces=atlas.uv_F, mtl=mtl_name)
    if glb_name is not None:
        (stage / glb_name).write_bytes(
            _glb_bytes(atlas.V[atlas.uv_vertex], atlas.uv_F, atlas.uv, checker)
        )


def _write_tail(stage: Path, uv_name: str, uv_png: bytes, extra: dict, report_name: str, report):
    """The files every atlas folder ends with: the uv picture, the pictures, ``report.json``."""
    import json

    (stage / uv_name).write_bytes(uv_png)
    for name, data in extra.items():
        (stage / name).write_bytes(data)
    (stage / report_name).write_text(
        json.dumps(report, indent=1, sort_keys=False) + "\n", encoding="utf-8"
    )


def _cannot_write(outdir: Path, exc: OSError) -> MeshFileError:
    """The one-line error of a write that failed (disk full, ...), naming the folder."""
    return MeshFileError(f"{outdir}: cannot write the atlas files: {error_reason(exc)}")


def save_atlas(
    atlas, outdir: str | os.PathLike, *, stem: str = "mesh", size: int | None = None, pictures=None
):
    """Write an atlas into ``outdir``: ``<stem>.obj/.mtl/_checker.png``, ``<stem>.glb``,
    ``<stem>_uv.png``, the pictures of ``pictures`` (:class:`segparam.pictures.PictureOptions`;
    default ``<stem>_preview.png`` and ``<stem>.html``) and ``report.json``. The uv picture is
    the texture's size (``atlas.packing.size``), or ``size`` pixels wide at its aspect.

    The folder is checked first (:func:`check_output_folder`); a stem too long for the file
    system is shortened (:func:`atlas_stem`). Every file is then written into a staging folder
    inside ``outdir`` and moved into place only when all of them were written, all or nothing
    (:func:`staged_outputs`): a failure leaves no partial output, and a rerun into the folder of
    an earlier atlas that fails or is interrupted (Ctrl-C) leaves the earlier files exactly.

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    MeshFileError
        The folder cannot take the files (see :func:`check_output_folder`), or writing failed
        (disk full, ...); one line naming the folder, never a bare OSError.
    """

    outdir = Path(outdir)
    stem = str(stem)
    if not stem or stem in (".", "..") or "/" in stem or os.sep in stem:
        raise MeshFileError(f"stem {stem!r} is not a file name")
    stem = atlas_stem(stem, outdir)
    from .pictures import PictureOptions

    pictures = PictureOptions() if pictures is None else pictures
    names = atlas_file_names(stem, pictures)
    check_output_folder(outdir, names.values())
    size = _picture_size(size, atlas.packing)
    try:
        # the pictures are made before anything is written: a failure leaves no file
        uv_png, extra, pictures_info, seconds = _picture_files(atlas, stem, pictures, size)
        report = atlas.report()
        report["timings"] = {**report.get("timings", {}), **seconds}
        report["pictures"] = pictures_info
        with staged_outputs(outdir) as stage:
            checker = _write_material(stage, names["mtl"], names["checker"], atlas.packing.size)
            _write_mesh(stage, atlas, names["obj"], names["glb"], names["mtl"], checker)
            _write_tail(stage, names["uv"], uv_png, extra, names["report"], report)
    except MeshFileError:
        raise
    except OSError as exc:
        raise _cannot_write(outdir, exc) from None
    return [outdir / name for name in names.values()]


def _picture_size(size: int | None, packing) -> tuple[int, int]:
    """The uv picture's (width, height): the texture's (``packing.size``), or ``size`` pixels
    wide at the texture's aspect."""
    width, height = packing.size
    if not size:
        return width, height
    return int(size), max(1, int(round(size * height / width)))


def _picture_files(atlas, stem: str, pictures, size: tuple[int, int]):
    """The uv-layout PNG and the pictures of ``pictures`` for ``atlas`` (an :class:`Atlas` or
    the :class:`~segparam.pictures.MeshSet` of several): ``(uv png bytes, {file name: bytes},
    the report's pictures section, {"picture <name>": seconds})``. One function for
    :func:`save_atlas` and :func:`save_atlases`."""
    from .pictures import make_pictures

    layout = render_uv_layout(atlas.uv, atlas.uv_F, labels=atlas.chart_of_face, size=size)
    uv_png = _png_bytes(np.asarray(layout))
    checker = _checker_png(checker_size(atlas.packing.size))
    extra, info = make_pictures(atlas, stem, pictures, checker_png=checker, uv_png=uv_png)
    seconds = {f"picture {k}": v for k, v in info.pop("seconds").items()}
    return uv_png, extra, info, seconds


def save_atlases(
    multi,
    outdir: str | os.PathLike,
    *,
    stem: str = "atlas",
    pictures=None,
    scenes: Sequence[tuple[str, Sequence[int]]] = (),
) -> list[Path]:
    """Write a :class:`~segparam.pipeline.MultiAtlas` (several meshes, one texture) into
    ``outdir``.

    Per mesh ``<name>.obj`` and ``<name>.glb``; per scene of ``scenes`` (``(scene name, mesh
    indices)``, e.g. the meshes of one GLB input) one ``<scene name>.glb`` holding those meshes
    as named nodes, instead of their own GLBs; shared by all, ``<stem>.mtl`` (every OBJ's
    material), ``<stem>_checker.png`` (every GLB's texture), ``<stem>_uv.png`` (the layout of
    every chart of every mesh), the pictures of ``pictures`` of the whole set (a
    :class:`~segparam.pictures.PictureOptions`; default ``<stem>_preview.png`` and
    ``<stem>.html``; bakes are :data:`~segparam.pictures.SHARED_BAKES` only, no flat map) and
    ``report.json`` (:meth:`MultiAtlas.report`, a section per mesh, and ``pictures``).

    Checked first and written all or nothing as :func:`save_atlas`.

    Returns
    -------
    list of Path
        The files written.
    """

    from .pictures import PictureOptions, check_several, merge_atlases

    outdir = Path(outdir)
    pictures = PictureOptions() if pictures is None else pictures
    atlases = multi.atlases
    check_several(pictures, len(atlases))
    names = multi_atlas_file_names(str(stem), multi.names, outdir, pictures=pictures, scenes=scenes)
    files = all_file_names(names)
    check_output_folder(outdir, files)
    shared_stem = Path(names["mtl"]).stem
    try:
        # the pictures of the whole set, from the code of one atlas, before anything is written
        merged = merge_atlases(atlases, multi.packing)
        uv_png, extra, pictures_info, seconds = _picture_files(
            merged, shared_stem, pictures, multi.packing.size
        )
        report = multi.report()
        report["pictures"] = pictures_info
        report["timings"] = seconds
        with staged_outputs(outdir) as stage:
            checker = _write_material(stage, names["mtl"], names["checker"], multi.packing.size)
            for atlas, files_of in zip(atlases, names["meshes"], strict=True):  # per mesh
                glb = files_of.get("glb")
                _write_mesh(stage, atlas, files_of["obj"], glb, names["mtl"], checker)
            for scene in names["scenes"]:  # one GLB per scene, a node per mesh
                parts = [
                    (
                        multi.names[i],
                        atlases[i].V[atlases[i].uv_vertex],
                        atlases[i].uv_F,
                        atlases[i].uv,
                    )
                    for i in scene["meshes"]
                ]
                (stage / scene["glb"]).write_bytes(_glb_scene_bytes(parts, checker))
            _write_tail(stage, names["uv"], uv_png, extra, names["report"], report)
    except MeshFileError:
        raise
    except OSError as exc:
        raise _cannot_write(outdir, exc) from None
    return [outdir / name for name in files]


# glTF stores positions as float32 (24-bit mantissa). Up to this many times its size from the
# origin an object keeps them to 8 * 2**-24 < 1e-6 of its size; farther away, positions are stored
# relative to the bounding-box centre and the centre becomes the node's float64 translation.
_GLB_MAX_OFFSET = 8.0

# glTF 2.0 numbers (https://registry.khronos.org/glTF/specs/2.0/glTF-2.0.html)
_GL_UNSIGNED_INT, _GL_FLOAT = 5125, 5126
_GL_ARRAY_BUFFER, _GL_ELEMENT_ARRAY_BUFFER = 34962, 34963
_GL_TRIANGLES = 4
_GL_LINEAR, _GL_LINEAR_MIPMAP_LINEAR, _GL_REPEAT = 9729, 9987, 10497

# The GLB's material shows the texture as the MTL does (Kd 1 1 1, Ks 0): base colour white
# times the texture, not metallic, fully rough (no highlight). (trimesh's export, used before,
# darkened it to a 0.4 grey and left it metallic.)
_GLB_MATERIAL = {
    "pbrMetallicRoughness": {
        "baseColorTexture": {"index": 0},
        "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
        "metallicFactor": 0.0,
        "roughnessFactor": 1.0,
    }
}


def _glb_bytes(V: np.ndarray, F: np.ndarray, uv: np.ndarray, png: bytes) -> bytes:
    """A binary glTF 2.0 of one textured triangle mesh (:func:`_glb_scene_bytes` with one
    unnamed part).

    Parameters
    ----------
    V : (n, 3) float ndarray
        One position per uv vertex.
    F : (m, 3) int ndarray
        Triangles into ``V`` and ``uv``.
    uv : (n, 2) float ndarray
        Texture coordinates, origin bottom-left (as in OBJ).
    png : bytes
        The texture, a PNG file.
    """
    return _glb_scene_bytes([(None, V, F, uv)], png)


def _glb_scene_bytes(parts, png: bytes) -> bytes:
    """A binary glTF 2.0 scene of textured triangle meshes sharing one texture, keeping float64
    placement.

    One scene; per part ``(name, V, F, uv)`` one node (named ``name`` unless None) and one mesh
    with one triangle primitive: ``POSITION`` (float32), ``TEXCOORD_0`` (float32, ``v``
    flipped: glTF's uv origin is the top-left corner) and uint32 indices. Every primitive uses
    the one material, whose base colour is the PNG ``png``, embedded once. A part far from the
    origin (1e7 away, say) would lose up to half a unit to float32 positions: its positions are
    written relative to its bounding-box centre and its node carries the centre as its
    ``translation``, which glTF keeps as a JSON (double) number. The same input gives the same
    bytes.

    Parameters
    ----------
    parts : sequence of (str or None, (n, 3) float, (m, 3) int, (n, 2) float)
        Per mesh: node name, one position per uv vertex, triangles into both, and texture
        coordinates with the origin bottom-left (as in OBJ).
    png : bytes
        The texture, a PNG file.
    """
    import json

    from . import __version__

    nodes, meshes, accessors, blobs, targets = [], [], [], [], []
    for k, (name, V, F, uv) in enumerate(parts):  # loop over meshes (a few)
        V = np.asarray(V, dtype=np.float64)
        uv = np.asarray(uv, dtype=np.float64)
        if len(uv) != len(V):
            raise ValueError(f"{len(V)} positions but {len(uv)} texture coordinates")
        node: dict = {"mesh": k} if name is None else {"name": str(name), "mesh": k}
        lo, hi = V.min(axis=0), V.max(axis=0)
        size = float((hi - lo).max())
        if np.abs(V).max() > _GLB_MAX_OFFSET * size:
            centre = (lo + hi) / 2
            V = V - centre
            node["translation"] = centre.tolist()
        positions = V.astype("<f4")
        texcoords = np.empty((len(uv), 2), dtype="<f4")
        texcoords[:, 0] = uv[:, 0]
        texcoords[:, 1] = 1.0 - uv[:, 1]
        indices = np.asarray(F).astype("<u4")
        first = 3 * k  # this part's accessors and buffer views: indices, positions, uvs
        mesh: dict = {
            "primitives": [
                {
                    "attributes": {"POSITION": first + 1, "TEXCOORD_0": first + 2},
                    "indices": first,
                    "material": 0,
                    "mode": _GL_TRIANGLES,
                }
            ]
        }
        if name is not None:
            mesh = {"name": str(name), **mesh}
        nodes.append(node)
        meshes.append(mesh)
        accessors += [
            _accessor(first, _GL_UNSIGNED_INT, indices.size, "SCALAR"),
            _accessor(
                first + 1,
                _GL_FLOAT,
                len(positions),
                "VEC3",
                min=positions.min(axis=0).tolist(),  # required for POSITION
                max=positions.max(axis=0).tolist(),
            ),
            _accessor(first + 2, _GL_FLOAT, len(texcoords), "VEC2"),
        ]
        blobs += [indices.tobytes(), positions.tobytes(), texcoords.tobytes()]
        targets += [_GL_ELEMENT_ARRAY_BUFFER, _GL_ARRAY_BUFFER, _GL_ARRAY_BUFFER]
    blobs.append(png)
    targets.append(None)
    views, offset = [], 0
    for blob, target in zip(blobs, targets, strict=True):
        view = {"buffer": 0, "byteOffset": offset, "byteLength": len(blob)}
        views.append(view if target is None else {**view, "target": target})
        offset += len(blob)  # a multiple of 4 up to the image: 4-byte indices, 12-, 8-byte vertices
    binary = _pad(b"".join(blobs), b"\0")
    gltf = {
        "asset": {"version": "2.0", "generator": f"segparam {__version__}"},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": meshes,
        "accessors": accessors,
        "materials": [_GLB_MATERIAL],
        "textures": [{"sampler": 0, "source": 0}],
        "samplers": [
            {
                "magFilter": _GL_LINEAR,
                "minFilter": _GL_LINEAR_MIPMAP_LINEAR,
                "wrapS": _GL_REPEAT,
                "wrapT": _GL_REPEAT,
            }
        ],
        "images": [{"bufferView": len(blobs) - 1, "mimeType": "image/png"}],
        "bufferViews": views,
        "buffers": [{"byteLength": len(binary)}],
    }
    content = _pad(json.dumps(gltf, separators=(",", ":")).encode("ascii"), b" ")
    return b"".join(
        [
            struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(content) + 8 + len(binary)),
            struct.pack("<I4s", len(content), b"JSON"),
            content,
            struct.pack("<I4s", len(binary), b"BIN\0"),
            binary,
        ]
    )


def _accessor(view: int, component: int, count: int, kind: str, **bounds) -> dict:
    return {"bufferView": view, "componentType": component, "count": count, "type": kind, **bounds}


def _pad(data: bytes, fill: bytes) -> bytes:
    """``data`` followed by ``fill`` bytes up to a multiple of 4 (glTF chunks are 4-aligned)."""
    return data + fill * (-len(data) % 4)
