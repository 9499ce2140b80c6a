"""Mesh files in, and where outputs go.

Reading (:func:`load_mesh`): OBJ, PLY and OFF (readers of our own, numpy over the whole file:
relative OBJ indices, any whitespace, polygons triangulated inside their outline, PLY element
counts checked against the data), STL and GLB/GLTF (trimesh) and GIfTI surfaces ``.gii`` /
``.gii.gz`` (nibabel, for cortical surfaces).

Writing safely, for every file segparam writes: output folders and names are checked before any
work (:func:`check_output_folder`, :func:`fit_name`); a file is written under a temporary name and
renamed into place (:func:`atomic_path`); a set of files replaces an earlier set all or nothing
(:func:`staged_outputs`). What an atlas writes is :mod:`segparam.export`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import gzip
import hashlib
import logging
import math
import os
import re
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from .errors import InvalidMeshError, MeshFileError
from .mesh import check_mesh

log = logging.getLogger(__name__)

__all__ = [
    "ATLAS_SUFFIXES",
    "DEFAULT_NAME_MAX",
    "SUPPORTED_SUFFIXES",
    "atlas_file_names",
    "atlas_stem",
    "atomic_path",
    "check_output_files",
    "check_output_folder",
    "error_reason",
    "file_safe",
    "fit_name",
    "json_safe",
    "load_mesh",
    "load_scene",
    "MeshUV",
    "NamedMesh",
    "SCENE_SUFFIXES",
    "all_file_names",
    "multi_atlas_file_names",
    "mesh_stem",
    "name_max",
    "split_suffix",
    "staged_outputs",
    "unique_names",
]

SUPPORTED_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf", ".gii", ".gii.gz")
_GII_GZ = ".gii.gz"


def split_suffix(path: str | os.PathLike) -> tuple[str, str]:
    """A file name's stem and its mesh suffix, lower-case: ``("lh.pial", ".gii.gz")`` for
    ``lh.pial.GII.GZ``, ``("scan", ".obj")`` for ``scan.OBJ`` (``.gii.gz`` is the one suffix of
    two parts). The one place that knows it: reading, output names and batch inputs use it."""
    name = Path(path).name
    if name.lower().endswith(_GII_GZ):
        return name[: -len(_GII_GZ)], _GII_GZ
    plain = Path(name)
    return plain.stem, plain.suffix.lower()


class MeshUV(NamedTuple):
    """A mesh with the uv layout its file holds (:func:`load_mesh` with ``uvs=True``).

    ``uv`` and ``uv_F`` are None when the file has no uv for every face (no OBJ ``vt`` on some
    corner, no glTF ``TEXCOORD_0``, or a format without uvs); they are what
    :func:`segparam.repack.repack` takes as ``uv`` and ``face_uv``.
    """

    V: np.ndarray
    F: np.ndarray
    uv: np.ndarray | None
    uv_F: np.ndarray | None


#: Formats whose uv :func:`load_mesh` reads (OBJ ``vt``, glTF/GLB ``TEXCOORD_0``).
UV_SUFFIXES = (".obj", ".glb", ".gltf")


def load_mesh(path: str | os.PathLike, *, uvs: bool = False) -> Any:
    """Read a triangle mesh; polygons are triangulated, nothing is merged or removed.

    Parameters
    ----------
    path : str or PathLike
    uvs : bool
        Also return the file's uv layout (see :class:`MeshUV`): OBJ ``vt`` with the ``f
        v/vt`` corner indices (a polygon's triangles keep their corners' uvs), glTF/GLB
        ``TEXCOORD_0`` (one uv per vertex). Other formats have none.

    Returns
    -------
    V : (n, 3) float64 ndarray
    F : (m, 3) int64 ndarray
        Possibly with defects: run :func:`segparam.clean.clean` before the pipeline.
    (with ``uvs=True`` a :class:`MeshUV` ``(V, F, uv, uv_F)``)

    Raises
    ------
    MeshFileError
        Missing file, a directory, no permission, unsupported format, content that is not a
        triangle mesh, NaN or infinite coordinates, or face indices out of range; the message
        names the file.
    """
    path = Path(path)
    data, suffix = _read_mesh_file(path)
    uv = uv_F = None
    try:
        if suffix in (".gii", _GII_GZ):
            V, F = _load_gifti(data, gz=suffix == _GII_GZ)
        elif uvs and suffix == ".obj":
            V, F, uv, uv_F = _load_obj(data, uvs=True)
        elif suffix in _READERS:
            V, F = _READERS[suffix](data)
        elif uvs:
            V, F, uv = _load_trimesh(data, suffix, uvs=True)
            uv_F = None if uv is None else F
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
    if uvs:
        return MeshUV(V, F, uv, uv_F)
    return V, F


def _read_mesh_file(path: Path) -> tuple[bytes, str]:
    """The bytes of a mesh file and its suffix, or the one-line reason it cannot be read."""
    if not path.exists():
        raise MeshFileError(f"{path}: no such file")
    if path.is_dir():
        raise MeshFileError(f"{path}: is a directory, not a mesh file")
    suffix = split_suffix(path)[1]
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
    return data, suffix


#: Formats that hold a scene of several placed meshes (:func:`load_scene`).
SCENE_SUFFIXES = (".glb", ".gltf")


class NamedMesh(NamedTuple):
    """One mesh of a file (:func:`load_scene`): its name, positions and triangles."""

    name: str
    V: np.ndarray
    F: np.ndarray


def load_scene(path: str | os.PathLike) -> list[NamedMesh]:
    """The meshes of a file, each named: a glTF/GLB scene whose nodes place several meshes
    gives one mesh per node, else the file's one mesh (:func:`load_mesh`, named after the file).

    A node's mesh is moved by the node's world transform (float64, the parents' transforms
    included), and its triangles are turned around where the transform mirrors (negative
    determinant; glTF then reverses the winding), so that each mesh sits and faces as the scene
    shows it. Names are the node names (a node without a name has trimesh's, e.g.
    ``geometry_0``); meshes come in the order of the file's meshes. A node that places no
    triangles (points, lines) is left out. A scene with one mesh reads exactly as
    :func:`load_mesh`.

    Raises
    ------
    MeshFileError
        As :func:`load_mesh`; a bad mesh in a scene names its node.
    """
    path = Path(path)
    data, suffix = _read_mesh_file(path)
    if suffix not in SCENE_SUFFIXES:
        return [NamedMesh(mesh_stem(path), *load_mesh(path))]
    try:
        parts = _scene_parts(data, suffix)
    except MeshFileError as exc:
        raise MeshFileError(f"{path}: {exc}") from None
    except Exception as exc:  # parsers raise anything on garbage
        raise MeshFileError(f"{path}: not a readable {suffix[1:].upper()} mesh ({exc})") from None
    if len(parts) <= 1:
        return [NamedMesh(mesh_stem(path), *load_mesh(path))]
    meshes = []
    for name, V, F in parts:  # loop over the scene's meshes
        try:
            meshes.append(NamedMesh(name, *check_mesh(V, F, allow_degenerate=True)))
        except InvalidMeshError as exc:
            raise MeshFileError(f"{path}: node {name}: {exc}") from None
    return meshes


def _trimesh_quietly(data: bytes, suffix: str, force: str):
    """``trimesh.load`` of a file's bytes as a ``"mesh"`` or a ``"scene"``, file order kept.

    trimesh logs tracebacks for parts we drop (normals, colours): they are kept off stderr.
    """
    import io as _io

    import trimesh

    trimesh_log = logging.getLogger("trimesh")
    level = trimesh_log.level
    trimesh_log.setLevel(logging.CRITICAL)
    try:
        return trimesh.load(
            _io.BytesIO(data), file_type=suffix[1:], process=False, force=force,
            maintain_order=True,
        )  # fmt: skip
    finally:
        trimesh_log.setLevel(level)


def _scene_parts(data: bytes, suffix: str) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """``(node name, world positions, triangles)`` per node of a glTF/GLB scene that places a
    mesh with faces (trimesh reads the file; :func:`load_scene` says what is done)."""

    scene = _trimesh_quietly(data, suffix, "scene")
    order = {name: k for k, name in enumerate(scene.geometry)}  # the file's mesh order
    nodes = []
    for node in scene.graph.nodes_geometry:  # loop over the scene's nodes
        transform, geometry = scene.graph[node]
        mesh = scene.geometry[geometry]
        faces = getattr(mesh, "faces", None)
        if faces is not None and len(faces):
            nodes.append((order[geometry], str(node), transform, mesh))
    nodes.sort(key=lambda item: (item[0], item[1]))
    parts = []
    for _, name, transform, mesh in nodes:  # loop over the scene's meshes
        T = np.asarray(transform, dtype=np.float64)
        V = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]
        F = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
        if np.linalg.det(T[:3, :3]) < 0:
            F = F[:, ::-1].copy()
        parts.append((name, V, F))
    return parts


def _load_trimesh(data: bytes, suffix: str, *, uvs: bool = False) -> Any:
    """STL, GLB and glTF through trimesh (OBJ, PLY and OFF have readers of their own below)."""

    if suffix == ".stl":
        data = _stl_bytes(data)
    loaded = _trimesh_quietly(data, suffix, "mesh")
    V = np.asarray(loaded.vertices, dtype=np.float64).reshape(-1, 3)
    F = np.asarray(loaded.faces, dtype=np.int64).reshape(-1, 3)
    if not uvs:
        return V, F
    uv = getattr(loaded.visual, "uv", None)  # TEXCOORD_0, one per vertex (trimesh's v up)
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float64)
        if uv.shape != (len(V), 2):
            uv = None
        elif not np.isfinite(uv).all():
            raise MeshFileError("TEXCOORD_0 has NaN or infinite coordinates")
    return V, F, uv


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


# ---------------------------------------------------------------------------------------------
# Text: OBJ, OFF and ASCII PLY are read with numpy over the whole file, never line by line
# ---------------------------------------------------------------------------------------------

_NEWLINE = ord("\n")
_SPACE = ord(" ")
# The byte-order mark Windows editors put in front of UTF-8 text; it is not part of line 1.
_UTF8_BOM = b"\xef\xbb\xbf"
# Tab, vertical tab and form feed separate tokens like a space: mapped to spaces so that token
# boundaries are one test on the bytes.
_TO_SPACE = bytes.maketrans(b"\t\v\f", b"   ")
_OTHER_SPACE = re.compile(rb"[\t\v\f]")
# A comment runs from '#' to the end of the line (OBJ and OFF; also after data on a line).
_COMMENT = re.compile(rb"#[^\n]*")
_LEADING_SPACES = re.compile(rb"(?m)^ +")
# OBJ: a backslash at the end of a line continues it on the next line. A run of continued lines
# is matched from its first line (anchored, so the scan stays linear).
_OBJ_CONTINUED = re.compile(rb"(?m)^(?:[^\n]*\\ *\n)+[^\n]*")
_OBJ_LINE_BREAK = re.compile(rb"\\ *\n")
# A token that is not a number (searched only to name the line once parsing has failed).
_FLOAT_TOKEN = rb"[+-]?(?:\d+\.?\d*(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?|(?i:nan|inf|infinity))"
_INT_TOKEN = rb"[+-]?\d+"
_NOT_A_FLOAT = re.compile(rb"(?<![^ \n])(?!" + _FLOAT_TOKEN + rb"(?![^ \n]))[^ \n]+")
_NOT_AN_INT = re.compile(rb"(?<![^ \n])(?!" + _INT_TOKEN + rb"(?![^ \n]))[^ \n]+")


def _clean_text(data: bytes, fmt: str, *, comments: bool) -> bytes:
    """Text as lines that each end in ``\\n``, tokens separated by single-byte spaces.

    A UTF-8 byte-order mark is dropped, CRLF and CR line ends become LF, tabs (and vertical tabs,
    form feeds) become spaces, spaces at line starts go and, with ``comments``, so does everything
    from a ``#`` to the line end. The number of lines does not change, so line numbers in messages
    are the file's. Bytes that are not UTF-8 (names in another encoding) stay as they are.
    """
    if data.startswith(_UTF8_BOM):
        data = data[len(_UTF8_BOM) :]
    if b"\0" in data:
        raise MeshFileError(f"not a readable {fmt} mesh (binary data, not text)")
    if b"\r" in data:
        data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    if _OTHER_SPACE.search(data):
        data = data.translate(_TO_SPACE)
    if comments and b"#" in data:
        data = _COMMENT.sub(b"", data)
    if not data.endswith(b"\n"):
        data += b"\n"
    if data.startswith(b" ") or b"\n " in data:
        data = _LEADING_SPACES.sub(b"", data)
    return data


def _token_table(text: bytes) -> tuple[np.ndarray, np.ndarray]:
    """The line of every token and the number of tokens on every line of clean text.

    Returns
    -------
    token_line : (k,) int64 ndarray
        Line (0-based) of each token, in order.
    counts : (lines,) int64 ndarray
    """
    b = np.frombuffer(text, dtype=np.uint8)
    sep = (b == _SPACE) | (b == _NEWLINE)
    start = ~sep
    start[1:] &= sep[:-1]
    newlines = np.flatnonzero(b == _NEWLINE)
    token_line = np.searchsorted(newlines, np.flatnonzero(start))
    return token_line, np.bincount(token_line, minlength=len(newlines))


def _numbers(text: bytes, count: int, dtype) -> np.ndarray | None:
    """The ``count`` numbers of clean text in order, or None if a token is not one number.

    ``np.fromstring`` parses in C and stops at the first token it cannot read: a ValueError, or
    on older numpy a DeprecationWarning (an exception where warnings are errors) and a short
    array, so comparing with the token count catches every bad token. (No ``catch_warnings``:
    it changes process-wide state, and batch workers read meshes in threads.)
    """
    if count == 0:
        return np.zeros(0, dtype=dtype)
    try:
        values = np.fromstring(text, dtype=dtype, sep=" ")
    except (ValueError, DeprecationWarning):
        return None
    return values if len(values) == count else None


def _bad_token(text: bytes, pattern: re.Pattern) -> tuple[int, str]:
    """Line (0-based) and text of the first token of clean text that is not a number, or -1."""
    match = pattern.search(text)
    if match is None:
        return -1, ""
    return text.count(b"\n", 0, match.start()), match.group().decode("utf-8", "replace")[:40]


def _ragged_arange(counts: np.ndarray) -> np.ndarray:
    """``0 .. c - 1`` for every ``c`` in ``counts``, concatenated."""
    starts = np.cumsum(counts) - counts
    return np.arange(int(counts.sum()), dtype=np.int64) - np.repeat(starts, counts)


def _load_obj(data: bytes, *, uvs: bool = False) -> Any:
    """Vertices and triangulated faces of an OBJ file; every other kind of line is ignored.

    ``v`` lines give vertices (x y z, further values such as w or colours ignored), ``f`` lines
    faces with corners ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``. Positive indices count from 1,
    negative ones back from the last vertex read *before* that face line (streaming exporters
    interleave ``v`` and ``f -3 -2 -1``). Faces keep the file's order; polygons are triangulated
    by :func:`_triangulate`.

    With ``uvs``, also ``uv`` (the ``vt`` lines' u v) and ``uv_F`` (the ``vt`` index of every
    triangle corner, same triangulation), or None for both when some corner has no ``vt``.
    """
    text = _clean_text(data, "OBJ", comments=True)
    if b"\\" in text:
        text = _OBJ_CONTINUED.sub(_join_continued, text)
    buf = np.frombuffer(text, dtype=np.uint8)
    newlines = np.flatnonzero(buf == _NEWLINE)
    starts = np.zeros(len(newlines), dtype=np.int64)
    starts[1:] = newlines[:-1] + 1
    # Keyword of each line: 'v' or 'f' followed by a space or the line end ('vt' too for uvs).
    first = buf[starts]
    second = buf[np.minimum(starts + 1, len(buf) - 1)]
    bare = np.isin(second, (_SPACE, _NEWLINE))
    kind = np.zeros(len(starts), dtype=np.uint8)
    kind[bare & (first == ord("v"))] = 1
    kind[bare & (first == ord("f"))] = 2
    if uvs:
        third = buf[np.minimum(starts + 2, len(buf) - 1)]
        is_vt = (first == ord("v")) & (second == ord("t")) & np.isin(third, (_SPACE, _NEWLINE))
        kind[is_vt] = 3
        buf = buf.copy()
        buf[starts[is_vt] + 1] = _SPACE  # 'vt' -> '  ': the second keyword byte goes too
    work = buf.copy()
    work[starts[kind > 0]] = _SPACE  # the keyword goes, the numbers stay
    per_byte = np.repeat(kind, newlines - starts + 1)
    V = _obj_vertices(work[per_byte == 1].tobytes(), np.flatnonzero(kind == 1) + 1)
    is_v = kind == 1
    face_text = work[per_byte == 2].tobytes()
    face_lines = np.flatnonzero(kind == 2) + 1
    F, corners, counts = _obj_faces(face_text, face_lines, np.cumsum(is_v)[kind == 2], V)
    if not uvs:
        return V, F
    uv, uv_F = _obj_uvs(
        work[per_byte == 3].tobytes(),
        np.flatnonzero(kind == 3) + 1,
        face_text,
        face_lines,
        np.cumsum(kind == 3)[kind == 2],
    )
    if uv is not None:  # the vertex triangulation, applied to the corners' vt indices
        T = _triangulate(V[corners], np.arange(len(corners)), counts)
        uv_F = uv_F[T]
    return V, F, uv, uv_F


#: An OBJ face corner's ``vt`` field: ``v/vt``, ``v/vt/vn`` -> ``vt``, ``v``, ``v//vn`` -> ``0``
#: (an index OBJ never uses: the corner has no uv).
_NO_VT_CORNER = re.compile(rb"(?<![^ \n])[^ /\n]+(?:/(?:/[^ \n]*)?)?(?![^ \n])")
_VT_FIELD = re.compile(rb"(?<![^ \n])[^ /\n]*/([^ /\n]+)[^ \n]*")


def _obj_uvs(
    vt_text: bytes, vt_lines: np.ndarray, face_text: bytes, face_lines: np.ndarray, before
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """``vt`` coordinates ``(k, 2)`` (u v; a third w ignored) and the ``vt`` index of every face
    corner, in corner order (0-based, negative indices resolved against ``before``: ``vt``
    lines above each face line); ``(None, None)`` when some corner has no ``vt``."""
    if not vt_text:
        return None, None
    token_line, counts = _token_table(vt_text)
    short = np.flatnonzero(counts < 2)
    if len(short):
        i = short[0]
        raise MeshFileError(f"texture vertex on line {vt_lines[i]} has {counts[i]} coordinates")
    values = _numbers(vt_text, len(token_line), np.float64)
    if values is None:
        row, token = _bad_token(vt_text, _NOT_A_FLOAT)
        where = f" on line {vt_lines[row]}" if row >= 0 else ""
        raise MeshFileError(
            f"texture vertex{where} has a coordinate that is not a number: {token!r}"
        )
    first = np.cumsum(counts) - counts
    uv = values[first[:, None] + np.arange(2)]
    if not np.isfinite(uv).all():
        raise MeshFileError("texture vertices (vt) have NaN or infinite coordinates")
    text = _VT_FIELD.sub(rb"\1", _NO_VT_CORNER.sub(b"0", face_text))
    raw, token_line, _ = _obj_rows(
        text,
        face_lines,
        np.int64,
        element="face",
        items="corners",
        need="a face needs at least 3",
        number="a texture index that is not a whole number",
    )
    if (raw == 0).any():
        return None, None
    base = before[token_line]
    idx = np.where(raw > 0, raw - 1, base + raw)
    bad = np.flatnonzero((idx < 0) | (idx >= len(uv)))
    if len(bad):
        j = bad[0]
        raise MeshFileError(
            f"face on line {face_lines[token_line[j]]} uses texture index {raw[j]}, "
            f"out of range ({len(uv)} vt lines)"
        )
    return uv, idx


def _join_continued(match: re.Match) -> bytes:
    """One logical OBJ line from lines ending in a backslash, followed by the newlines it ate."""
    run = match.group()
    return _OBJ_LINE_BREAK.sub(b" ", run) + b"\n" * run.count(b"\n")


def _obj_rows(
    text: bytes, lines: np.ndarray, dtype, *, element: str, items: str, need: str, number: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The numbers of one kind of OBJ line (keyword blanked) on file lines ``lines``, each line
    checked to hold at least 3 of them.

    ``element``, ``items``, ``need`` and ``number`` word the errors: "``element`` on line 7 has 2
    ``items``; ``need``" and "``element`` on line 7 has ``number``: 'x'".

    Returns
    -------
    values : (k,) ndarray of ``dtype``
        Every number, in order.
    token_line : (k,) int64 ndarray
        Row (0-based, among these lines) of each number.
    counts : (rows,) int64 ndarray
        Numbers per row.
    """
    token_line, counts = _token_table(text)
    short = np.flatnonzero(counts < 3)
    if len(short):
        i = short[0]
        raise MeshFileError(f"{element} on line {lines[i]} has {counts[i]} {items}; {need}")
    values = _numbers(text, len(token_line), dtype)
    if values is None:
        pattern = _NOT_A_FLOAT if np.dtype(dtype).kind == "f" else _NOT_AN_INT
        row, token = _bad_token(text, pattern)
        where = f" on line {lines[row]}" if row >= 0 else ""
        raise MeshFileError(f"{element}{where} has {number}: {token!r}")
    return values, token_line, counts


def _obj_vertices(text: bytes, lines: np.ndarray) -> np.ndarray:
    """(n, 3) coordinates of the ``v`` lines (keyword blanked) on file lines ``lines``."""
    values, _, counts = _obj_rows(
        text,
        lines,
        np.float64,
        element="vertex",
        items="coordinates",
        need="a vertex needs x y z",
        number="a coordinate that is not a number",
    )
    if (counts == 3).all():
        return values.reshape(-1, 3)
    first = np.cumsum(counts) - counts
    return values[first[:, None] + np.arange(3)]


def _obj_faces(
    text: bytes, lines: np.ndarray, before: np.ndarray, V: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Triangles of the ``f`` lines (keyword blanked) on file lines ``lines``, with the vertex
    index of every corner and the corners per face (to triangulate the uvs the same way).

    ``before`` holds, per face line, the number of ``v`` lines above it: the base of negative
    indices.
    """
    if b"/" in text:  # keep the vertex index of every corner, drop /vt and /vn
        lone = re.search(rb"(?<![^ \n])/", text)
        if lone:
            line = lines[text.count(b"\n", 0, lone.start())]
            raise MeshFileError(f"face on line {line} has a corner without a vertex index")
        text = re.sub(rb"/[^ \n]*", b"", text)
    raw, token_line, counts = _obj_rows(
        text,
        lines,
        np.int64,
        element="face",
        items="corners",
        need="a face needs at least 3",
        number="a vertex index that is not a whole number",
    )
    zero = np.flatnonzero(raw == 0)
    if len(zero):
        line = lines[token_line[zero[0]]]
        raise MeshFileError(f"face on line {line} uses vertex index 0; OBJ indices start at 1")
    base = before[token_line]
    idx = np.where(raw > 0, raw - 1, base + raw)
    bad = np.flatnonzero((idx < 0) | (idx >= len(V)))
    if len(bad):
        j = bad[0]
        line = lines[token_line[j]]
        known = f"the file has {len(V)}" if raw[j] > 0 else f"{base[j]} precede that line"
        raise MeshFileError(
            f"face on line {line} uses vertex index {raw[j]}, out of range ({known} vertices)"
        )
    return _triangulate(V, idx, counts), idx, counts


# OFF header keywords: OFF, with optional per-vertex texture (ST), colour (C), normal (N) columns.
_OFF_KEYWORD = re.compile(rb"(?:ST)?C?N?OFF")
_FIRST_LINE = re.compile(rb"\s*([^\n]*)\n")


def _load_off(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangulated faces of an OFF file (one vertex or face per line).

    Face lines are ``k i1 .. ik`` with optional colour values after the indices. The header's
    counts must match the lines of data.
    """
    text = _clean_text(data, "OFF", comments=True)
    head = _FIRST_LINE.match(text)
    words = head.group(1).split() if head else []
    if not words or not _OFF_KEYWORD.fullmatch(words[0]):
        first = words[0].decode("utf-8", "replace")[:20] if words else ""
        raise MeshFileError(f"not a readable OFF mesh (starts with {first!r}, not OFF)")
    counts_words, pos = words[1:], head.end()
    if not counts_words:  # the counts are on the next non-blank line
        line = _FIRST_LINE.match(text, pos)
        counts_words, pos = (line.group(1).split(), line.end()) if line else ([], pos)
    try:
        nv, nf = (int(w) for w in counts_words[:2])
    except ValueError:
        nv = nf = -1
    if len(counts_words) < 2 or min(nv, nf) < 0:
        raise MeshFileError("not a readable OFF mesh (no vertex and face counts after OFF)")
    body, line0 = text[pos:], text.count(b"\n", 0, pos)
    token_line, _, rows, values, row_counts, row_first = _data_table(
        body, [("vertex", nv), ("face", nf)], line0, ""
    )
    row_line = line0 + rows + 1
    short = np.flatnonzero(row_counts[:nv] < 3)
    if len(short):
        raise MeshFileError(f"vertex on line {row_line[short[0]]} has fewer than 3 coordinates")
    V = values[row_first[:nv, None] + np.arange(3)]
    first, size = row_first[nv:] + 1, values[row_first[nv:]]
    bad = ~(size >= 3) | (size != np.floor(size)) | (size > row_counts[nv:] - 1)
    if bad.any():
        i = np.flatnonzero(bad)[0]
        raise MeshFileError(
            f"face on line {row_line[nv + i]} announces {values[row_first[nv + i]]:g} corners "
            f"and holds {row_counts[nv + i] - 1} values; a face needs at least 3 corners"
        )
    size = size.astype(np.int64)
    token = np.repeat(first, size) + _ragged_arange(size)
    idx = values[token]
    bad = (idx != np.floor(idx)) | ~(idx >= 0) | ~(idx < nv)
    if bad.any():
        j = np.flatnonzero(bad)[0]
        line = line0 + token_line[token[j]] + 1
        raise MeshFileError(
            f"face on line {line} has a vertex index that is not a whole number: {idx[j]:g}"
            if idx[j] != np.floor(idx[j])
            else f"face on line {line} uses vertex index {idx[j]:g}, out of range "
            f"({nv} vertices, counted from 0)"
        )
    return V, _triangulate(V, idx.astype(np.int64), size)


# ---------------------------------------------------------------------------------------------
# PLY: ASCII and binary, every element's count checked against the data
# ---------------------------------------------------------------------------------------------

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
_PLY_FORMATS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}
_PLY_END_HEADER = re.compile(rb"(?m)^end_header[ \t]*\r?$\n?")
# Names exporters give the list of a face's vertices.
_PLY_FACE_LISTS = ("vertex_indices", "vertex_index")


@dataclasses.dataclass
class _PlyProperty:
    name: str
    dtype: np.dtype  # of the value, or of the list items
    count: np.dtype | None = None  # of a list's length; None for a single value


@dataclasses.dataclass
class _PlyElement:
    name: str
    size: int
    props: list[_PlyProperty] = dataclasses.field(default_factory=list)


def _load_ply(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangulated faces of an ASCII or binary PLY file.

    Every element the header announces must be in the data, row by row, and the data must end
    where the last element ends: a header that announces more (or fewer) vertices or faces than
    the data holds is an error, never a mesh read from the wrong bytes.
    """
    fmt, elements, body_start, line0 = _ply_header(data)
    named = {e.name: e for e in elements}
    vertex = named.get("vertex")
    if vertex is None:
        raise MeshFileError("PLY header has no vertex element")
    scalars = {p.name for p in vertex.props if p.count is None}
    if not {"x", "y", "z"} <= scalars:
        raise MeshFileError("PLY vertex element has no x, y and z properties")
    face = named.get("face")
    face_list = None
    if face is not None:
        lists = [p.name for p in face.props if p.count is not None]
        known = [name for name in _PLY_FACE_LISTS if name in lists]
        face_list = known[0] if known else lists[0] if len(lists) == 1 else None
        if face_list is None:
            raise MeshFileError("PLY face element has no vertex_indices list")
    wanted = {"vertex": {"x", "y", "z"}, "face": {face_list}}
    body = data[body_start:]
    if fmt == "ascii":
        columns = _ply_ascii(body, elements, line0, wanted)
    else:
        columns = _ply_binary(body, elements, wanted)
    V = np.stack([columns["vertex"][c] for c in "xyz"], axis=1).astype(np.float64)
    if face is None:
        return V, np.zeros((0, 3), dtype=np.int64)
    idx, size = columns["face"][face_list]
    few = np.flatnonzero(size < 3)
    if len(few):
        raise MeshFileError(
            f"face {few[0]} has {size[few[0]]} corners (a face needs at least 3): corrupt data, "
            f"or the header, which announces {_announced([(e.name, e.size) for e in elements])}, "
            "does not match it"
        )
    bad = (idx != np.floor(idx)) | ~(idx >= 0) | ~(idx < len(V))
    if bad.any():
        j = np.flatnonzero(bad)[0]
        face_of = np.repeat(np.arange(len(size)), size)
        raise MeshFileError(
            f"face {face_of[j]} has a vertex index that is not a whole number: {idx[j]:g}"
            if idx[j] != np.floor(idx[j])
            else f"face indices out of range: face {face_of[j]} uses vertex {idx[j]:g}, "
            f"the file has {len(V)} vertices (counted from 0)"
        )
    return V, _triangulate(V, idx.astype(np.int64), size)


def _ply_header(data: bytes) -> tuple[str, list[_PlyElement], int, int]:
    """Format, elements, where the data starts and how many lines the header has."""
    if not data.startswith(b"ply"):
        raise MeshFileError("not a readable PLY mesh (it does not start with 'ply')")
    end = _PLY_END_HEADER.search(data)
    if end is None:
        raise MeshFileError("PLY header has no end_header line (truncated or not a PLY file)")
    fmt = None
    elements: list[_PlyElement] = []
    lines = data[: end.start()].decode("latin-1").replace("\r", "").split("\n")
    for number, line in enumerate(lines[1:], 2):  # the header's few lines
        words = line.split()
        key = words[0] if words else "comment"
        try:
            if key in ("comment", "obj_info"):
                continue
            if key == "format":
                fmt = words[1]
                if fmt not in _PLY_FORMATS:
                    raise ValueError(f"unknown format {fmt!r}")
            elif key == "element":
                name, size = words[1], int(words[2])
                if size < 0 or len(words) != 3:
                    raise ValueError("expected 'element <name> <count>'")
                elements.append(_PlyElement(name, size))
            elif key == "property":
                if not elements:
                    raise ValueError("property before any element")
                order = _PLY_FORMATS.get(fmt or "ascii", "")
                if words[1] == "list":
                    count, item, name = words[2:5]
                    elements[-1].props.append(
                        _PlyProperty(
                            name,
                            np.dtype(order + _PLY_TYPES[item]),
                            np.dtype(order + _PLY_TYPES[count]),
                        )
                    )
                else:
                    elements[-1].props.append(
                        _PlyProperty(words[2], np.dtype(order + _PLY_TYPES[words[1]]))
                    )
            else:
                raise ValueError(f"unknown keyword {key!r}")
        except (ValueError, IndexError, KeyError) as exc:
            what = (
                f"unknown type {exc}"
                if isinstance(exc, KeyError)
                else "too few words"
                if isinstance(exc, IndexError)
                else str(exc)
            )
            raise MeshFileError(f"PLY header line {number}: {what}") from None
    if fmt is None:
        raise MeshFileError("PLY header has no format line")
    return fmt, elements, end.end(), data.count(b"\n", 0, end.end())


def _data_table(text: bytes, announced: list[tuple[str, int]], line0: int, prefix: str):
    """The data lines after an ASCII header (OFF, PLY): ``(token_line, counts, rows, values,
    row_counts, row_first)`` -- the line of each token, tokens per line, the non-blank lines,
    every token as a float, and per non-blank line its token count and first token.

    The header's ``announced`` (name, count) pairs must add up to the non-blank lines, and every
    token must be a number (else one line naming the first bad one; ``line0`` lines precede
    ``text`` in the file, ``prefix`` starts the message).
    """
    token_line, counts = _token_table(text)
    rows = np.flatnonzero(counts)  # non-blank lines
    expected = sum(n for _, n in announced)
    if len(rows) != expected:
        raise MeshFileError(
            f"header announces {_announced(announced)} "
            f"({expected} lines of data), data holds {len(rows)} lines"
        )
    values = _numbers(text, len(token_line), np.float64)
    if values is None:
        row, token = _bad_token(text, _NOT_A_FLOAT)
        where = f"line {line0 + row + 1} holds" if row >= 0 else "data holds"
        raise MeshFileError(f"{prefix}{where} a value that is not a number: {token!r}")
    row_counts = counts[rows]
    row_first = np.cumsum(row_counts) - row_counts
    return token_line, counts, rows, values, row_counts, row_first


def _announced(counts: list[tuple[str, int]]) -> str:
    """'3 vertices and 1 face' from [('vertex', 3), ('face', 1)]."""
    words = [
        f"{n} {name if n == 1 else name[:-2] + 'ices' if name.endswith('ex') else name + 's'}"
        for name, n in counts
    ]
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]


def _ply_ascii(body: bytes, elements, line0: int, wanted) -> dict:
    """Columns of an ASCII PLY's elements: one element per line, values separated by spaces.

    Returns ``{element: {property: values}}`` for the wanted properties; a list property gives
    ``(items, lengths)``.
    """
    text = _clean_text(body, "PLY", comments=False)
    _, counts, rows, values, row_counts, row_first = _data_table(
        text, [(e.name, e.size) for e in elements], line0, "PLY "
    )
    out: dict[str, dict] = {}
    done = 0
    for e in elements:  # the header's few elements and properties
        rows_e = slice(done, done + e.size)
        done += e.size
        cur, end = row_first[rows_e].copy(), row_first[rows_e] + row_counts[rows_e]
        columns = {}
        for p in e.props:
            if p.count is None:
                bad = cur >= end
                if not bad.any() and p.name in wanted.get(e.name, ()):
                    columns[p.name] = values[cur]
                step = 1
            else:
                n = values[np.minimum(cur, len(values) - 1)]
                bad = (cur >= end) | ~(n >= 0) | (n != np.floor(n)) | (cur + 1 + n > end)
                step = 1 + np.where(bad, 0, n).astype(np.int64)
                if not bad.any() and p.name in wanted.get(e.name, ()):
                    k = step - 1
                    columns[p.name] = (values[np.repeat(cur + 1, k) + _ragged_arange(k)], k)
            if bad.any():
                raise _ply_row_error(e, np.flatnonzero(bad)[0], rows, line0, rows_e, counts)
            cur = cur + step
        if (cur != end).any():
            raise _ply_row_error(e, np.flatnonzero(cur != end)[0], rows, line0, rows_e, counts)
        out[e.name] = columns
    return out


def _ply_row_error(e, i, rows, line0, rows_e, counts) -> MeshFileError:
    """An ASCII PLY row whose values do not fit its element's properties."""
    line = rows[rows_e][i]
    return MeshFileError(
        f"header announces {_announced([(e.name, e.size)])}, but line {line0 + line + 1} "
        f"({e.name} {i}) holds {counts[line]} values that do not fit the {e.name} properties"
    )


def _gather(u8: np.ndarray, pos: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """Values of ``dtype`` stored at byte offsets ``pos`` of a byte array."""
    raw = u8[pos[:, None] + np.arange(dtype.itemsize)]
    return raw.view(dtype).reshape(-1)


def _ply_binary(body: bytes, elements, wanted) -> dict:
    """Columns of a binary PLY's elements (as :func:`_ply_ascii`); the data must end where the
    last element ends."""
    u8 = np.frombuffer(body, dtype=np.uint8)
    out: dict[str, dict] = {}
    pos = 0
    for e in elements:  # the header's few elements and properties
        starts, pos = _ply_rows(u8, pos, e, elements)
        cur = starts.copy()
        columns = {}
        for p in e.props:
            take = p.name in wanted.get(e.name, ())
            if p.count is None:
                if take:
                    columns[p.name] = _gather(u8, cur, p.dtype)
                cur += p.dtype.itemsize
                continue
            k = _gather(u8, cur, p.count).astype(np.int64)
            cur += p.count.itemsize
            if take:
                at = np.repeat(cur, k) + _ragged_arange(k) * p.dtype.itemsize
                columns[p.name] = (_gather(u8, at, p.dtype), k)
            cur += k * p.dtype.itemsize
        out[e.name] = columns
    if pos != len(u8):
        raise MeshFileError(
            f"corrupt binary PLY: header announces "
            f"{_announced([(e.name, e.size) for e in elements])} ({pos} bytes of data), "
            f"data holds {len(u8)} bytes"
        )
    return out


def _ply_row_ends(u8: np.ndarray, pos: np.ndarray, e: _PlyElement) -> np.ndarray:
    """Where a row of element ``e`` starting at each byte offset ``pos`` ends; -1 if it would run
    past the data (or has a negative list length)."""
    cur = pos.astype(np.int64)
    ok = np.ones(len(cur), dtype=bool)
    for p in e.props:
        if p.count is None:
            cur = cur + p.dtype.itemsize
            continue
        inside = cur + p.count.itemsize <= len(u8)
        k = np.zeros(len(cur), dtype=np.int64)
        k[inside] = _gather(u8, cur[inside], p.count)
        ok &= inside & (k >= 0)
        cur = cur + p.count.itemsize + np.maximum(k, 0) * p.dtype.itemsize
    return np.where(ok & (cur <= len(u8)), cur, -1)


def _ply_rows(u8: np.ndarray, pos: int, e: _PlyElement, elements) -> tuple[np.ndarray, int]:
    """Byte offsets of the rows of element ``e`` whose data starts at ``pos``, and its end.

    Rows without lists, or whose lists all have the first row's length, are one arange. Lists of
    different lengths (triangles and quads) make every row's start depend on the one before: the
    chain is followed with numpy over every byte offset (see :func:`_follow`).
    """
    n = e.size
    fixed = all(p.count is None for p in e.props)
    if n == 0:
        return np.zeros(0, dtype=np.int64), pos
    if fixed:
        size = sum(p.dtype.itemsize for p in e.props)
        if size == 0:  # an element without properties takes no bytes
            return np.full(n, pos, dtype=np.int64), pos
    else:
        size = int(_ply_row_ends(u8, np.array([pos]), e)[0]) - pos
    if size > 0 and pos + n * size <= len(u8):
        starts = pos + size * np.arange(n, dtype=np.int64)
        if fixed or (_ply_row_ends(u8, starts, e) == starts + size).all():
            return starts, pos + n * size
    if not fixed and size > 0:
        # Row end at every byte offset from pos on, as an index relative to pos; the sentinel
        # (one past the data) stands for "runs past the data".
        sentinel = len(u8) - pos + 1
        ends = _ply_row_ends(u8, np.arange(pos, len(u8) + 1, dtype=np.int64), e)
        nxt = np.append(np.where(ends >= 0, ends - pos, sentinel), sentinel)
        rows = _follow(nxt, n)
        stop = int(nxt[rows[-1]])
        if stop != sentinel and not (rows == sentinel).any():
            return rows + pos, pos + stop
        held = int(np.argmax(rows == sentinel)) if (rows == sentinel).any() else n - 1
    else:
        held = max(0, (len(u8) - pos) // size) if size > 0 else 0
    raise MeshFileError(
        f"truncated or corrupt binary PLY: header announces "
        f"{_announced([(x.name, x.size) for x in elements])}, data holds only {held} "
        f"{_announced([(e.name, held)]).split(' ', 1)[1]}"
    )


def _follow(nxt: np.ndarray, n: int) -> np.ndarray:
    """The first ``n`` nodes of the chain ``0, nxt[0], nxt[nxt[0]], ...``.

    Square-root blocking: ``nxt`` composed with itself ``B ~ sqrt(n)`` times gives every B-th
    node (B scalar steps); B vectorized steps from those fill in the rest. Time
    ``O(len(nxt) log B + n)`` and three arrays of ``len(nxt)`` entries.
    """
    block = max(1, math.isqrt(n))
    jump = np.arange(len(nxt))
    base, e = nxt, block
    while e:  # jump = nxt applied `block` times, by repeated squaring
        if e & 1:
            jump = base[jump]
        base, e = base[base], e >> 1
    coarse = np.empty(-(-n // block), dtype=np.int64)
    node = 0
    for j in range(len(coarse)):  # ~sqrt(n) steps, each a block of rows
        coarse[j] = node
        node = jump[node]
    rows = np.empty((len(coarse), block), dtype=np.int64)
    for t in range(block):  # ~sqrt(n) vectorized steps
        rows[:, t] = coarse
        coarse = nxt[coarse]
    return rows.reshape(-1)[:n]


# ---------------------------------------------------------------------------------------------
# Polygons to triangles
# ---------------------------------------------------------------------------------------------

# A polygon whose Newell normal (twice its area, in units of its extent squared) is below this is
# flat to round-off: no plane to triangulate in, it is fanned (its triangles have no area).
_FLAT_POLYGON = 1e-12


def _triangulate(V: np.ndarray, idx: np.ndarray, size: np.ndarray) -> np.ndarray:
    """Triangles of polygons: ``size[i]`` corners each, their vertex indices one after another.

    A k-gon becomes k - 2 triangles, in the file's order and winding. A quad is split along the
    diagonal that keeps both triangles inside it and facing along its normal (so a concave quad
    is split at its reflex corner), the 0-2 diagonal when both do; larger polygons are ear-clipped
    in their best-fit plane (:func:`_ear_clip`).
    """
    size = np.asarray(size, dtype=np.int64)
    idx = np.asarray(idx, dtype=np.int64)
    if (size == 3).all():
        return idx.reshape(-1, 3)
    first = np.cumsum(size) - size
    count = size - 2
    out = np.cumsum(count) - count
    F = np.empty((int(count.sum()), 3), dtype=np.int64)
    tri = size == 3
    F[out[tri]] = idx[first[tri, None] + np.arange(3)]
    quad = np.flatnonzero(size == 4)
    if len(quad):
        Q = idx[first[quad, None] + np.arange(4)]
        F[out[quad]], F[out[quad] + 1] = _split_quads(V, Q)
    for p in np.flatnonzero(size > 4):  # the rare polygons with more than 4 corners
        corners = idx[first[p] : first[p] + size[p]]
        F[out[p] : out[p] + count[p]] = corners[_ear_clip(V[corners])]
    return F


def _split_quads(V: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two triangles per quad (q, 4): the first of each pair, then the second."""
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        P = V[Q] - V[Q[:, :1]]  # relative to corner 0 and scaled: no overflow, no offset
        scale = np.abs(P).max(axis=(1, 2))
        P = P / np.where(scale > 0, scale, 1.0)[:, None, None]
        normal = np.cross(P, np.roll(P, -1, axis=1)).sum(axis=1)  # Newell

        def facing(a, b, c):
            return np.einsum("ij,ij->i", normal, np.cross(P[:, b] - P[:, a], P[:, c] - P[:, a]))

        along_02 = (facing(0, 1, 2) > 0) & (facing(0, 2, 3) > 0)
        along_13 = (facing(0, 1, 3) > 0) & (facing(1, 2, 3) > 0)
    use_13 = (along_13 & ~along_02)[:, None]
    return (
        np.where(use_13, Q[:, [0, 1, 3]], Q[:, [0, 1, 2]]),
        np.where(use_13, Q[:, [1, 2, 3]], Q[:, [0, 2, 3]]),
    )


def _ear_clip(P: np.ndarray) -> np.ndarray:
    """k - 2 triangles (local corner numbers) of a polygon with corners ``P`` (k, 3).

    The polygon is projected onto the plane of its Newell normal, with axes such that its winding
    stays counter-clockwise, and triangulated by earcut (``mapbox_earcut``); triangles keep the
    polygon's winding. A polygon with no plane, or that earcut cannot cut into k - 2 triangles
    (repeated corners), is fanned from its first corner.
    """
    k = len(P)
    fan = np.stack([np.zeros(k - 2, dtype=np.int64), np.arange(1, k - 1), np.arange(2, k)], 1)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        P = P - P[0]
        scale = np.abs(P).max()
        if not (np.isfinite(scale) and scale > 0):
            return fan
        P = P / scale
        normal = np.cross(P, np.roll(P, -1, axis=0)).sum(axis=0)
        length = np.linalg.norm(normal)
        if not length > _FLAT_POLYGON:
            return fan
        normal = normal / length
        axis = np.zeros(3)
        axis[np.argmin(np.abs(normal))] = 1.0
        u = np.cross(normal, axis)
        u /= np.linalg.norm(u)
        w = np.cross(normal, u)  # (u, w, normal) right-handed: the winding stays positive
        uv = np.ascontiguousarray(np.stack([P @ u, P @ w], axis=1))
    import mapbox_earcut

    tris = mapbox_earcut.triangulate_float64(uv, np.array([k], dtype=np.uint32))
    tris = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    if len(tris) != k - 2:
        return fan
    a, b, c = uv[tris[:, 0]], uv[tris[:, 1]], uv[tris[:, 2]]
    flipped = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) < (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    tris[flipped] = tris[flipped][:, ::-1]
    return tris


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


# Formats read by segparam's own numpy readers; the others go through trimesh (or nibabel).
_READERS = {".obj": _load_obj, ".ply": _load_ply, ".off": _load_off}


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` only if the block succeeds.

    The temporary name starts with at most 64 bytes of the final name, so that it fits the file
    system whenever the final name does.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    prefix = f".{_clip(path.name, 64)}."
    fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=".part", dir=path.parent)
    tmp_path = Path(tmp)
    try:  # from here on the temporary file goes, whatever happens (a Ctrl-C included)
        os.close(fd)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp creates 0600; give the file the usual mode
        yield tmp_path
        os.replace(tmp_path, path)  # one rename: the old file or the new one, never neither
    finally:
        tmp_path.unlink(missing_ok=True)


def json_safe(value: Any) -> Any:
    """``value`` with what JSON cannot hold replaced: inf and nan become None, numpy scalars
    Python ones (dicts, lists and tuples are walked; tuples become lists). Used for the atlas
    report and the batch summaries."""
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


# ---------------------------------------------------------------------------------------------
# Where the outputs go: checked before any work, so that a run never fails at the end for it

#: What segparam appends to the stem of every file of an atlas folder (and ``report.json``).
ATLAS_SUFFIXES = (".obj", ".mtl", "_checker.png", ".glb", "_uv.png", "_preview.png", ".html")
#: File-name limit (bytes) assumed where the file system does not say (ext4, APFS, NTFS: 255).
DEFAULT_NAME_MAX = 255


def _nbytes(name: str) -> int:
    return len(os.fsencode(name))


def _clip(name: str, limit: int) -> str:
    """The longest prefix of ``name`` of at most ``limit`` bytes (whole characters only)."""
    raw = os.fsencode(name)
    if len(raw) <= limit:
        return name
    short = raw[:limit].decode("utf-8", errors="ignore")
    while _nbytes(short) > limit:  # non-UTF-8 names (surrogate escapes): one character at a time
        short = short[:-1]
    return short


def mesh_stem(path: str | os.PathLike) -> str:
    """A mesh file's name without its suffix (``lh.pial.gii.gz`` -> ``lh.pial``), or ``mesh``."""
    return split_suffix(path)[0] or "mesh"


def _existing(path: Path) -> Path:
    """``path`` made absolute, or its nearest ancestor that exists (a file or a folder)."""
    path = Path(os.path.abspath(path))
    for candidate in (path, *path.parents):
        if os.path.lexists(candidate):
            return candidate
    return Path(path.anchor or os.sep)  # pragma: no cover - the root always exists


def name_max(folder: str | os.PathLike) -> int:
    """Longest file name (bytes) the file system of ``folder`` (or of its nearest existing
    ancestor) takes; :data:`DEFAULT_NAME_MAX` where it does not say."""
    base = _existing(Path(folder))
    if not base.is_dir():
        base = base.parent
    try:
        limit = os.pathconf(base, "PC_NAME_MAX")
    except (AttributeError, OSError, ValueError):  # no pathconf (Windows), or no answer
        return DEFAULT_NAME_MAX
    return int(limit) if limit and limit > 0 else DEFAULT_NAME_MAX


def fit_name(stem: str, suffix: str = "", *, limit: int = DEFAULT_NAME_MAX) -> str:
    """``stem + suffix``, with the stem shortened when the whole exceeds ``limit`` bytes.

    A shortened stem keeps its beginning and gets ``~`` and 8 hex digits of the full stem's
    sha256, so that two long names with the same beginning still give different names:
    ``fit_name("a" * 300, ".obj")`` is ``"aaa...a~1b2c3d4e.obj"``, 255 bytes.
    """
    if _nbytes(stem + suffix) <= limit:
        return stem + suffix
    tag = "~" + hashlib.sha256(os.fsencode(stem)).hexdigest()[:8]
    room = limit - _nbytes(suffix) - len(tag)
    if room < 1:
        raise MeshFileError(f"{suffix}: a file name ending like this cannot fit {limit} bytes")
    return _clip(stem, room) + tag + suffix


def atlas_stem(stem: str, outdir: str | os.PathLike) -> str:
    """The stem of the atlas files in ``outdir``: ``stem``, or shortened by :func:`fit_name` so
    that its longest file name (``<stem>_checker.png``) fits the file system."""
    longest = max(_nbytes(suffix) for suffix in ATLAS_SUFFIXES)
    return fit_name(stem, limit=name_max(outdir) - longest)


def atlas_file_names(stem: str, pictures=None) -> dict[str, str]:
    """The files :func:`segparam.export.save_atlas` writes into its folder, by role;
    ``pictures`` (a :class:`segparam.pictures.PictureOptions`, default: preview and viewer) adds
    its files."""
    from .pictures import PictureOptions

    return {
        "obj": f"{stem}.obj",
        "mtl": f"{stem}.mtl",
        "checker": f"{stem}_checker.png",
        "glb": f"{stem}.glb",
        "uv": f"{stem}_uv.png",
        **(PictureOptions() if pictures is None else pictures).file_names(stem),
        "report": "report.json",
    }


# Characters no file name may hold on Linux, macOS or Windows (and control characters).
_UNSAFE_NAME = re.compile(r'[\x00-\x1f/\\:*?"<>|]')


def file_safe(name: str) -> str:
    """``name`` usable as a file name everywhere: characters that Windows, macOS or Linux refuse
    (``/ \\ : * ? " < > |``, control characters) become ``_``; an empty name, ``.`` or ``..``
    (a glTF node may be called anything) becomes ``mesh``."""
    safe = _UNSAFE_NAME.sub("_", str(name)).strip()
    return "mesh" if safe in ("", ".", "..") else safe


def unique_names(names: list[str]) -> list[str]:
    """``names`` with repeats renamed ``<name>_2``, ``<name>_3``... (case-insensitively, as
    file names on some systems)."""
    seen: set[str] = set()
    out = []
    for name in names:  # loop over meshes
        candidate, k = name, 1
        while candidate.lower() in seen:
            k += 1
            candidate = f"{name}_{k}"
        seen.add(candidate.lower())
        out.append(candidate)
    return out


def multi_atlas_file_names(
    stem: str,
    names: Iterable[str],
    outdir: str | os.PathLike,
    *,
    pictures=None,
    scenes: Iterable[tuple[str, Iterable[int]]] = (),
) -> dict[str, Any]:
    """The files :func:`segparam.export.save_atlases` writes into ``outdir``, by role.

    Shared by all meshes: ``mtl``, ``checker``, ``uv``, the pictures of ``pictures`` (a
    :class:`segparam.pictures.PictureOptions`, default preview and viewer) and ``report``, all
    named after ``stem``. ``meshes``: per mesh name its ``obj`` and, unless a scene holds it,
    its ``glb``. ``scenes``: per ``(scene name, mesh indices)`` of ``scenes`` one ``glb`` holding
    those meshes as nodes (a scene name met among the meshes gets ``_2``...). Names are
    shortened by :func:`fit_name` to fit the file system; two files of the same name
    (case-insensitively) are refused.
    """
    from .pictures import PictureOptions

    names = unique_names([file_safe(name) for name in names])
    scenes = [(file_safe(name), [int(i) for i in meshes]) for name, meshes in scenes]
    shared = atlas_file_names(atlas_stem(stem, outdir), pictures or PictureOptions())
    limit = name_max(outdir) - len(".obj")
    meshes = [fit_name(name, limit=limit) for name in names]
    in_scene = {i for _, members in scenes for i in members}
    scene_names = unique_names(meshes + [name for name, _ in scenes])[len(meshes) :]
    out: dict[str, Any] = {k: v for k, v in shared.items() if k not in ("obj", "glb")}
    out["meshes"] = [
        {"obj": f"{m}.obj"} if i in in_scene else {"obj": f"{m}.obj", "glb": f"{m}.glb"}
        for i, m in enumerate(meshes)
    ]
    out["scenes"] = [
        {"glb": f"{fit_name(name, limit=limit)}.glb", "meshes": members}
        for name, (_, members) in zip(scene_names, scenes, strict=True)
    ]
    files = all_file_names(out)
    if len({f.lower() for f in files}) != len(files):
        raise MeshFileError(f"{outdir}: two meshes would write files of the same name")
    return out


def all_file_names(names: dict[str, Any]) -> list[str]:
    """Every file name of :func:`multi_atlas_file_names`."""
    files = [v for k, v in names.items() if k not in ("meshes", "scenes")]
    files += [f for mesh in names["meshes"] for f in mesh.values()]
    return files + [scene["glb"] for scene in names.get("scenes", ())]


def error_reason(exc: BaseException) -> str:
    """A short reason for a failed file operation: an OSError's text (``No space left on
    device``), else the exception's type name."""
    if isinstance(exc, OSError):
        return exc.strerror or str(exc) or type(exc).__name__
    return type(exc).__name__


def check_output_folder(
    folder: str | os.PathLike,
    names: Iterable[str] = (),
    *,
    inputs: Iterable[str | os.PathLike] = (),
) -> Path:
    """Check, before any work, that files ``names`` can be written into ``folder``.

    The folder (or the nearest existing folder above it, where it will be created) must be a
    folder one can write into: a temporary folder is created there and removed at once. Every
    name, and the name of every folder still to create, must fit the file system's limit
    (:func:`name_max`); no name may be an existing folder; and none of the files may be one of
    ``inputs`` (the atlas of ``dir/scan.obj`` written into ``dir`` would replace ``scan.obj``).

    Returns
    -------
    Path
        ``folder``.

    Raises
    ------
    MeshFileError
        One line naming the path and the problem.
    """
    folder = Path(folder)
    names = list(names)
    base = _existing(folder)
    if not base.is_dir():
        if base == Path(os.path.abspath(folder)):
            raise MeshFileError(f"{folder}: is a file, not a folder")
        raise MeshFileError(f"{folder}: cannot create this folder: {base} is a file")
    limit = name_max(base)
    missing = Path(os.path.abspath(folder)).relative_to(base).parts
    for name in [*missing, *names]:
        if _nbytes(name) > limit:
            raise MeshFileError(
                f"{folder}: the name {_clip(name, 40)}... is {_nbytes(name)} bytes long; "
                f"the file system takes at most {limit}"
            )
    try:  # the one reliable test: root, ACLs and read-only mounts all answer it truly
        os.rmdir(tempfile.mkdtemp(prefix=".segparam-check-", dir=base))
    except OSError as exc:
        where = "" if base == Path(os.path.abspath(folder)) else f" (in {base})"
        raise MeshFileError(f"{folder}: cannot write there{where}: {error_reason(exc)}") from None
    sources = [Path(p) for p in inputs]
    for name in names:
        target = folder / name
        if not os.path.lexists(target):
            continue
        if os.path.isdir(target) and not os.path.islink(target):
            raise MeshFileError(f"{target}: is a folder; an output file cannot replace it")
        for source in sources:
            try:
                same = os.path.samefile(source, target)
            except OSError:
                same = False
            if same:
                raise MeshFileError(
                    f"{source}: the output {target} would overwrite this input; "
                    "write the outputs into another folder"
                )
    return folder


def check_output_files(
    paths: Iterable[str | os.PathLike], *, inputs: Iterable[str | os.PathLike] = ()
) -> list[Path]:
    """:func:`check_output_folder` for output files given by their paths (grouped by folder)."""
    paths = [Path(p) for p in paths]
    inputs = list(inputs)
    for path in paths:
        if not path.name or path.name in (".", ".."):
            raise MeshFileError(f"{path}: is a folder; give a file name")
    folders: dict[Path, list[str]] = {}
    for path in paths:
        folders.setdefault(path.parent, []).append(path.name)
    for folder, names in folders.items():
        check_output_folder(folder, names, inputs=inputs)
    return paths


@contextlib.contextmanager
def _ctrl_c_deferred() -> Iterator[None]:
    """A Ctrl-C that arrives inside the block takes effect when the block is over.

    The block must not be cut short: putting the previous files back. Only the main thread
    receives Python's ``KeyboardInterrupt`` (and only it may set a signal handler); elsewhere
    this is a no-op.
    """
    import signal
    import threading

    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is None  # a handler set from C: leave it alone
    ):
        yield
        return
    received: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if received:
            if callable(previous):
                previous(signal.SIGINT, None)  # Python's default handler raises KeyboardInterrupt
            elif previous != signal.SIG_IGN:
                raise KeyboardInterrupt


def _swap_in(stage: Path, outdir: Path, names: list[str], backup: Path) -> None:
    """Move the files ``names`` of ``stage`` into ``outdir``; each file of ``outdir`` they
    replace is first moved into ``backup`` (all in one folder tree: every move is a rename)."""
    for name in names:
        target = outdir / name
        if os.path.lexists(target):
            os.replace(target, backup / name)
        os.replace(stage / name, target)


def _swap_out(stage: Path, outdir: Path, names: list[str], backup: Path) -> list[str]:
    """Undo :func:`_swap_in`, however far it got: the new files go back to ``stage``, the
    previous ones from ``backup`` to ``outdir``. The state is read from the files, not from a
    record of the moves, so an interruption between a move and its bookkeeping cannot mislead
    it. Returns the names that could not be put back (their previous file stays in ``backup``).
    """
    failed = []
    for name in names:
        target, new, old = outdir / name, stage / name, backup / name
        try:
            if not os.path.lexists(new) and os.path.lexists(target):
                os.replace(target, new)  # the new file had been moved in: out again
            if os.path.lexists(old):
                os.replace(old, target)  # the previous file had been set aside: back
        except OSError:
            failed.append(name)
    return failed


@contextlib.contextmanager
def staged_outputs(outdir: str | os.PathLike) -> Iterator[Path]:
    """Yield a staging folder inside ``outdir``; move everything in it into ``outdir`` only if
    the block succeeds, all or nothing (also on Ctrl-C between two moves).

    The block writes its files into the staging folder. Then each file of ``outdir`` that one
    of them replaces is moved aside into the staging folder and the new file moved into its
    place (renames within one file system). If anything fails or is interrupted before the last
    move, every new file is taken out and every previous file put back, so ``outdir`` is
    exactly what it was (files of other names are never touched); the previous files are
    deleted only once every move has succeeded. The staging folder is always removed, except
    when a previous file could not be put back (a :class:`MeshFileError` then says where it is).
    """
    import shutil

    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=".segparam-", dir=outdir))
    keep = False
    try:
        yield stage
        names = sorted(path.name for path in stage.iterdir())  # every file exists
        backup = Path(tempfile.mkdtemp(prefix=".previous-", dir=stage))
        try:
            _swap_in(stage, outdir, names, backup)
        except BaseException as exc:
            with _ctrl_c_deferred():
                failed = _swap_out(stage, outdir, names, backup)
                keep = bool(failed)  # then the previous files stay where they are
            if failed:
                raise MeshFileError(
                    f"{outdir}: moving the new files in failed ({error_reason(exc)}), and so did "
                    f"putting back {', '.join(failed)}; the previous files are kept in {backup}"
                ) from exc
            raise
    finally:
        if not keep:
            with _ctrl_c_deferred():
                shutil.rmtree(stage, ignore_errors=True)
