"""Mesh files in and out: every file format segparam reads or writes lives here.

Reading: OBJ, PLY, STL, OFF, GLB/GLTF (trimesh) and GIfTI surfaces ``.gii`` / ``.gii.gz``
(nibabel, for cortical surfaces). Writing is atomic: each file is written under a temporary name in
the destination folder and renamed into place, so a failed run leaves no partial file.
"""

from __future__ import annotations

import contextlib
import gzip
import logging
import os
import re
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from .errors import InvalidMeshError, MeshFileError
from .mesh import check_mesh

log = logging.getLogger(__name__)

__all__ = [
    "SUPPORTED_SUFFIXES",
    "atomic_path",
    "checker_image",
    "load_mesh",
    "render_uv_layout",
    "save_atlas",
    "staged_outputs",
    "write_obj",
]

SUPPORTED_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf", ".gii", ".gii.gz")


def _suffix(path: Path) -> str:
    name = path.name.lower()
    return ".gii.gz" if name.endswith(".gii.gz") else path.suffix.lower()


def load_mesh(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle mesh; polygons are triangulated, nothing is merged or removed.

    Parameters
    ----------
    path : str or PathLike

    Returns
    -------
    V : (n, 3) float64 ndarray
    F : (m, 3) int64 ndarray
        Possibly with defects: run :func:`segparam.clean.clean` before the pipeline.

    Raises
    ------
    MeshFileError
        Missing file, a directory, no permission, unsupported format, content that is not a
        triangle mesh, NaN or infinite coordinates, or face indices out of range; the message
        names the file.
    """
    path = Path(path)
    if not path.exists():
        raise MeshFileError(f"{path}: no such file")
    if path.is_dir():
        raise MeshFileError(f"{path}: is a directory, not a mesh file")
    suffix = _suffix(path)
    if suffix not in SUPPORTED_SUFFIXES:
        raise MeshFileError(
            f"{path}: unsupported format {suffix or '(none)'}; "
            f"supported: {', '.join(SUPPORTED_SUFFIXES)}"
        )
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise MeshFileError(f"{path}: cannot read ({exc.strerror})") from None
    if not data:
        raise MeshFileError(f"{path}: file is empty")
    try:
        if suffix in (".gii", ".gii.gz"):
            V, F = _load_gifti(data, gz=suffix == ".gii.gz")
        else:
            V, F = _load_trimesh(data, suffix)
    except MeshFileError as exc:
        raise MeshFileError(f"{path}: {exc}") from None
    except Exception as exc:  # parsers raise anything on garbage
        raise MeshFileError(f"{path}: not a readable {suffix[1:].upper()} mesh ({exc})") from None
    if len(F) == 0:
        points = f" (only {len(V)} points)" if len(V) else ""
        raise MeshFileError(f"{path}: contains no faces{points}")
    try:  # checked here so that the message names the file
        V, F = check_mesh(V, F, allow_degenerate=True)
    except InvalidMeshError as exc:
        raise MeshFileError(f"{path}: {exc}") from None
    return V, F


# An OBJ face corner whose vertex index is 0: OBJ counts from 1 (or from -1 backwards), and
# trimesh would silently read 0 as a wrong (degenerate) face.
_OBJ_ZERO_INDEX = re.compile(rb"(?m)^[ \t]*f[ \t][^\n]*?(?<=[ \t])-?0+(?=[/ \t\r\n]|$)")


def _check_obj_indices(data: bytes) -> None:
    """Refuse an OBJ with a face vertex index of 0, naming the line."""
    match = _OBJ_ZERO_INDEX.search(data)
    if match:
        line = data.count(b"\n", 0, match.start()) + 1
        raise MeshFileError(f"face on line {line} uses vertex index 0; OBJ indices start at 1")


def _load_trimesh(data: bytes, suffix: str) -> tuple[np.ndarray, np.ndarray]:
    import io as _io

    import trimesh

    if suffix in (".obj", ".off"):
        if b"\0" in data:
            raise MeshFileError(f"not a readable {suffix[1:].upper()} mesh (binary data, not text)")
        # trimesh decodes non-UTF-8 text with the optional charset_normalizer (ImportError
        # without it); the numbers are ASCII, so undecodable bytes can only be in names.
        data = data.decode("utf-8", errors="replace").encode("utf-8")
        if suffix == ".obj":
            _check_obj_indices(data)
    elif suffix == ".stl":
        data = _stl_bytes(data)
    # trimesh logs tracebacks for parts we drop (normals, colours): keep them off stderr.
    trimesh_log = logging.getLogger("trimesh")
    level = trimesh_log.level
    trimesh_log.setLevel(logging.CRITICAL)
    try:
        loaded = trimesh.load(
            _io.BytesIO(data),
            file_type=suffix[1:],
            process=False,
            force="mesh",
            maintain_order=True,
        )
    finally:
        trimesh_log.setLevel(level)
    V = np.asarray(loaded.vertices, dtype=np.float64).reshape(-1, 3)
    F = np.asarray(loaded.faces, dtype=np.int64).reshape(-1, 3)
    return V, F


def _stl_bytes(data: bytes) -> bytes:
    """STL bytes trimesh can parse, or a clear error for a truncated or corrupt binary STL.

    trimesh parses a binary STL whose length disagrees with its header as ASCII STL, which
    fails with a misleading message (or an ImportError of the optional charset_normalizer).
    """
    count = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0]) if len(data) >= 84 else -1
    if count >= 0 and len(data) == 84 + 50 * count:
        return data  # binary STL
    if b"\0" not in data:  # text: binary STL headers and counts have zero bytes
        # ASCII STL (or text that is not one: trimesh finds no faces); names may be non-UTF-8
        return data.decode("utf-8", errors="replace").encode("utf-8")
    if count < 0:
        raise MeshFileError(
            f"truncated binary STL: {len(data)} bytes, less than its 84-byte header"
        )
    raise MeshFileError(
        f"truncated or corrupt binary STL: {len(data)} bytes, but its header announces "
        f"{count} triangles ({84 + 50 * count} bytes)"
    )


def _load_gifti(data: bytes, *, gz: bool) -> tuple[np.ndarray, np.ndarray]:
    import nibabel as nib

    if gz:
        data = gzip.decompress(data)
    img = nib.GiftiImage.from_bytes(data)
    points = img.get_arrays_from_intent("NIFTI_INTENT_POINTSET")
    tris = img.get_arrays_from_intent("NIFTI_INTENT_TRIANGLE")
    if not points or not tris:
        raise MeshFileError("GIfTI file has no POINTSET and TRIANGLE arrays (not a surface)")
    return (
        np.asarray(points[0].data, dtype=np.float64).reshape(-1, 3),
        np.asarray(tris[0].data, dtype=np.int64).reshape(-1, 3),
    )


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp creates 0600; give the file the usual mode
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    finally:
        tmp_path.unlink(missing_ok=True)


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
    lines = ["# written by segparam"]
    if mtl:
        lines.append(f"mtllib {mtl}")
    body = [_rows("v", V, "%.9g")]
    if uv is not None:
        body.append(_rows("vt", uv, "%.9g"))
        T = F if uv_faces is None else uv_faces
        corners = np.stack([F + 1, T + 1], axis=2).reshape(len(F), 6)
        faces = _rows("f", corners, "%d", sep=("/", " "))
    else:
        faces = _rows("f", F + 1, "%d")
    if mtl:
        body.append(f"usemtl {material}\n")
    body.append(faces)
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline="\n") as fh:
        fh.write("\n".join(lines) + "\n")
        fh.writelines(body)


def _rows(tag: str, A: np.ndarray, fmt: str, sep: tuple[str, str] | None = None) -> str:
    """Format a 2-D array as OBJ lines ``tag a b c`` without a Python loop over rows."""
    A = np.asarray(A)
    if len(A) == 0:
        return ""
    if sep is None:
        row = " ".join([fmt] * A.shape[1])
    else:  # pairs joined by sep[0], pairs separated by sep[1]: "f 1/1 2/2 3/3"
        row = sep[1].join([sep[0].join([fmt, fmt])] * (A.shape[1] // 2))
    import io as _io

    buf = _io.StringIO()
    np.savetxt(buf, A, fmt=f"{tag} {row}")
    return buf.getvalue()


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
    size: int = 1024,
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

    Returns
    -------
    PIL.Image.Image
    """
    from PIL import Image, ImageDraw

    from .mesh import boundary_loops
    from .pack import rasterize_footprint

    labels = np.zeros(len(F), dtype=np.int64) if labels is None else np.asarray(labels)
    n = int(labels.max()) + 1
    colors = _palette(n).astype(np.uint8)
    img = np.full((size, size, 3), 255, dtype=np.uint8)
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(n + 1))
    groups = [order[bounds[k] : bounds[k + 1]] for k in range(n)]
    for k, faces in enumerate(groups):  # loop over charts
        img[rasterize_footprint(uv, F[faces], resolution=size, eps=0.0)] = colors[k]
    image = Image.fromarray(img[::-1])  # row 0 of the mask is v = 0: flip so v grows upwards
    if outline:
        draw = ImageDraw.Draw(image)
        P = uv * size
        P[:, 1] = size - P[:, 1]
        for faces in groups:  # loop over charts, then over their few boundary loops
            for loop in boundary_loops(F[faces]):
                pts = P[np.r_[loop, loop[:1]]]
                draw.line(list(map(tuple, pts.tolist())), fill=(40, 40, 40), width=1)
    return image


def checker_image(size: int = 1024, squares: int = 16):
    """A checkerboard texture with a colour ramp (so flips and rotations show), PIL image."""
    from PIL import Image

    i, j = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
    cell = size // squares
    dark = ((i // cell + j // cell) % 2).astype(bool)
    img = np.empty((size, size, 3), dtype=np.uint8)
    img[..., 0] = (80 + 150 * j / size).astype(np.uint8)
    img[..., 1] = (80 + 150 * (1 - i / size)).astype(np.uint8)
    img[..., 2] = 200
    img[dark] = (img[dark] * 0.35).astype(np.uint8)
    return Image.fromarray(img)


def save_atlas(atlas, outdir: str | os.PathLike, *, stem: str = "mesh", size: int | None = None):
    """Write an atlas into ``outdir``: ``<stem>.obj/.mtl/_checker.png``, ``<stem>.glb``,
    ``<stem>_uv.png`` and ``report.json``.

    Every file is first written into a staging folder inside ``outdir`` and moved into place only
    when all of them were written, so a failure leaves no partial output.

    Returns
    -------
    list of Path
        The files written.
    """
    import json

    import trimesh

    outdir = Path(outdir)
    size = size or atlas.packing.resolution
    names = {
        "obj": f"{stem}.obj",
        "mtl": f"{stem}.mtl",
        "checker": f"{stem}_checker.png",
        "glb": f"{stem}.glb",
        "uv": f"{stem}_uv.png",
        "report": "report.json",
    }
    with staged_outputs(outdir) as stage:
        checker = checker_image(1024)
        checker.save(stage / names["checker"], format="PNG")
        (stage / names["mtl"]).write_text(
            f"# written by segparam\nnewmtl atlas\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\n"
            f"map_Kd {names['checker']}\n",
            encoding="utf-8",
        )
        write_obj(
            stage / names["obj"],
            atlas.V,
            atlas.F,
            uv=atlas.uv,
            uv_faces=atlas.uv_F,
            mtl=names["mtl"],
        )
        mesh = trimesh.Trimesh(
            vertices=atlas.V[atlas.uv_vertex],
            faces=atlas.uv_F,
            visual=trimesh.visual.TextureVisuals(uv=atlas.uv, image=checker),
            process=False,
        )
        (stage / names["glb"]).write_bytes(mesh.export(file_type="glb"))
        render_uv_layout(atlas.uv, atlas.uv_F, labels=atlas.chart_of_face, size=size).save(
            stage / names["uv"], format="PNG"
        )
        (stage / names["report"]).write_text(
            json.dumps(atlas.report(), indent=1, sort_keys=False) + "\n", encoding="utf-8"
        )
    return [outdir / name for name in names.values()]


@contextlib.contextmanager
def staged_outputs(outdir: str | os.PathLike) -> Iterator[Path]:
    """Yield a staging folder inside ``outdir``; move everything in it into ``outdir`` only if
    the block succeeds, all or nothing (also on Ctrl-C between two moves)."""
    import shutil

    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=".segparam-", dir=outdir))
    try:
        yield stage
        written: list[Path] = []
        try:
            for path in sorted(stage.iterdir()):  # every file exists: move them into place
                os.replace(path, outdir / path.name)
                written.append(outdir / path.name)
        except BaseException:
            for done in written:
                done.unlink(missing_ok=True)
            raise
    finally:
        shutil.rmtree(stage, ignore_errors=True)
