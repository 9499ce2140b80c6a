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
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from .errors import MeshFileError

log = logging.getLogger(__name__)

__all__ = ["atomic_path", "load_mesh", "save_uv_png", "write_obj", "SUPPORTED_SUFFIXES"]

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
        Missing file, a directory, no permission, unsupported format, or content that is not a
        triangle mesh; the message names the file.
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
        raise MeshFileError(f"{path}: contains no faces ({len(V)} points)")
    return V, F


def _load_trimesh(data: bytes, suffix: str) -> tuple[np.ndarray, np.ndarray]:
    import io as _io

    import trimesh

    loaded = trimesh.load(
        _io.BytesIO(data), file_type=suffix[1:], process=False, force="mesh", maintain_order=True
    )
    V = np.asarray(loaded.vertices, dtype=np.float64).reshape(-1, 3)
    F = np.asarray(loaded.faces, dtype=np.int64).reshape(-1, 3)
    return V, F


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


def save_uv_png(
    path: str | os.PathLike,
    uv: np.ndarray,
    F: np.ndarray,
    *,
    size: int = 1024,
    face_colors: np.ndarray | None = None,
    edges: bool = True,
) -> None:
    """Draw a uv layout (triangles filled, optionally outlined) into a PNG, atomically.

    Parameters
    ----------
    uv : (k, 2) float ndarray
        Coordinates; the drawing fits their bounding box (the unit square if they lie in it).
    F : (m, 3) int ndarray
        Triangles into ``uv``.
    face_colors : (m, 3) uint8 ndarray, optional
        Fill colour per triangle; default light grey.
    """
    from PIL import Image, ImageDraw

    lo = np.minimum(uv.min(axis=0), 0.0) if uv.min() >= -1e-9 else uv.min(axis=0)
    hi = np.maximum(uv.max(axis=0), 1.0) if uv.max() <= 1 + 1e-9 else uv.max(axis=0)
    span = float((hi - lo).max()) or 1.0
    P = (uv - lo) / span * (size - 1)
    P[:, 1] = size - 1 - P[:, 1]  # image rows grow downwards
    img = Image.new("RGB", (size, size), (255, 255, 255))
    draw = ImageDraw.Draw(img)
    colors = (
        np.full((len(F), 3), 200, dtype=np.uint8) if face_colors is None else face_colors
    ).tolist()
    outline = (60, 60, 60) if edges and len(F) < 200_000 else None
    tris = P[F].tolist()
    for tri, color in zip(tris, colors, strict=True):  # PIL draws one polygon per call
        draw.polygon([tuple(p) for p in tri], fill=tuple(color), outline=outline)
    with atomic_path(path) as tmp:
        img.save(tmp, format="PNG")
