"""Mesh files in and out: every file format segparam reads or writes lives here.

Reading: OBJ, PLY and OFF (readers of our own, numpy over the whole file: relative OBJ indices,
any whitespace, polygons triangulated inside their outline, PLY element counts checked against the
data), STL and GLB/GLTF (trimesh) and GIfTI surfaces ``.gii`` / ``.gii.gz`` (nibabel, for cortical
surfaces). Writing is atomic: each file is written under a temporary name in the destination
folder and renamed into place, so a failed run leaves no partial file. Written coordinates keep
their float64 value (OBJ text with 17 digits; a GLB far from the origin stores its offset as a
float64 node translation).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import gzip
import hashlib
import logging
import math
import os
import re
import struct
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

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
    "checker_image",
    "fit_name",
    "load_mesh",
    "mesh_stem",
    "name_max",
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
        elif suffix in _READERS:
            V, F = _READERS[suffix](data)
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


def _load_trimesh(data: bytes, suffix: str) -> tuple[np.ndarray, np.ndarray]:
    """STL, GLB and glTF through trimesh (OBJ, PLY and OFF have readers of their own below)."""
    import io as _io

    import trimesh

    if suffix == ".stl":
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


def _load_obj(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangulated faces of an OBJ file; every other kind of line is ignored.

    ``v`` lines give vertices (x y z, further values such as w or colours ignored), ``f`` lines
    faces with corners ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``. Positive indices count from 1,
    negative ones back from the last vertex read *before* that face line (streaming exporters
    interleave ``v`` and ``f -3 -2 -1``). Faces keep the file's order; polygons are triangulated
    by :func:`_triangulate`.
    """
    text = _clean_text(data, "OBJ", comments=True)
    if b"\\" in text:
        text = _OBJ_CONTINUED.sub(_join_continued, text)
    buf = np.frombuffer(text, dtype=np.uint8)
    newlines = np.flatnonzero(buf == _NEWLINE)
    starts = np.zeros(len(newlines), dtype=np.int64)
    starts[1:] = newlines[:-1] + 1
    # Keyword of each line: 'v' or 'f' followed by a space or the line end.
    first = buf[starts]
    bare = np.isin(buf[np.minimum(starts + 1, len(buf) - 1)], (_SPACE, _NEWLINE))
    kind = np.zeros(len(starts), dtype=np.uint8)
    kind[bare & (first == ord("v"))] = 1
    kind[bare & (first == ord("f"))] = 2
    work = buf.copy()
    work[starts[kind > 0]] = _SPACE  # the keyword goes, the numbers stay
    per_byte = np.repeat(kind, newlines - starts + 1)
    V = _obj_vertices(work[per_byte == 1].tobytes(), np.flatnonzero(kind == 1) + 1)
    is_v = kind == 1
    F = _obj_faces(
        work[per_byte == 2].tobytes(),
        np.flatnonzero(kind == 2) + 1,
        np.cumsum(is_v)[kind == 2],
        V,
    )
    return V, F


def _join_continued(match: re.Match) -> bytes:
    """One logical OBJ line from lines ending in a backslash, followed by the newlines it ate."""
    run = match.group()
    return _OBJ_LINE_BREAK.sub(b" ", run) + b"\n" * run.count(b"\n")


def _obj_vertices(text: bytes, lines: np.ndarray) -> np.ndarray:
    """(n, 3) coordinates of the ``v`` lines (keyword blanked) on file lines ``lines``."""
    token_line, counts = _token_table(text)
    short = np.flatnonzero(counts < 3)
    if len(short):
        i = short[0]
        raise MeshFileError(
            f"vertex on line {lines[i]} has {counts[i]} coordinates; a vertex needs x y z"
        )
    values = _numbers(text, len(token_line), np.float64)
    if values is None:
        row, token = _bad_token(text, _NOT_A_FLOAT)
        where = f" on line {lines[row]}" if row >= 0 else ""
        raise MeshFileError(f"vertex{where} has a coordinate that is not a number: {token!r}")
    if (counts == 3).all():
        return values.reshape(-1, 3)
    first = np.cumsum(counts) - counts
    return values[first[:, None] + np.arange(3)]


def _obj_faces(text: bytes, lines: np.ndarray, before: np.ndarray, V: np.ndarray) -> np.ndarray:
    """Triangles of the ``f`` lines (keyword blanked) on file lines ``lines``.

    ``before`` holds, per face line, the number of ``v`` lines above it: the base of negative
    indices.
    """
    if b"/" in text:  # keep the vertex index of every corner, drop /vt and /vn
        lone = re.search(rb"(?<![^ \n])/", text)
        if lone:
            line = lines[text.count(b"\n", 0, lone.start())]
            raise MeshFileError(f"face on line {line} has a corner without a vertex index")
        text = re.sub(rb"/[^ \n]*", b"", text)
    token_line, counts = _token_table(text)
    few = np.flatnonzero(counts < 3)
    if len(few):
        i = few[0]
        raise MeshFileError(
            f"face on line {lines[i]} has {counts[i]} corners; a face needs at least 3"
        )
    raw = _numbers(text, len(token_line), np.int64)
    if raw is None:
        row, token = _bad_token(text, _NOT_AN_INT)
        where = f" on line {lines[row]}" if row >= 0 else ""
        raise MeshFileError(f"face{where} has a vertex index that is not a whole number: {token!r}")
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
    return _triangulate(V, idx, counts)


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
    token_line, counts = _token_table(body)
    rows = np.flatnonzero(counts)  # non-blank lines
    if len(rows) != nv + nf:
        raise MeshFileError(
            f"header announces {_announced([('vertex', nv), ('face', nf)])} "
            f"({nv + nf} lines of data), data holds {len(rows)} lines"
        )
    values = _numbers(body, len(token_line), np.float64)
    if values is None:
        row, token = _bad_token(body, _NOT_A_FLOAT)
        where = f"line {line0 + row + 1} holds" if row >= 0 else "data holds"
        raise MeshFileError(f"{where} a value that is not a number: {token!r}")
    row_counts = counts[rows]
    row_first = np.cumsum(row_counts) - row_counts
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
    token_line, counts = _token_table(text)
    rows = np.flatnonzero(counts)  # non-blank lines
    expected = sum(e.size for e in elements)
    if len(rows) != expected:
        raise MeshFileError(
            f"header announces {_announced([(e.name, e.size) for e in elements])} "
            f"({expected} lines of data), data holds {len(rows)} lines"
        )
    values = _numbers(text, len(token_line), np.float64)
    if values is None:
        row, token = _bad_token(text, _NOT_A_FLOAT)
        where = f"line {line0 + row + 1} holds" if row >= 0 else "data holds"
        raise MeshFileError(f"PLY {where} a value that is not a number: {token!r}")
    row_counts = counts[rows]
    row_first = np.cumsum(row_counts) - row_counts
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
    name = Path(path).name
    stem = name[: -len(".gii.gz")] if name.lower().endswith(".gii.gz") else Path(name).stem
    return stem or "mesh"


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
    """The files :func:`save_atlas` writes into its folder, by role; ``pictures`` (a
    :class:`segparam.pictures.PictureOptions`, default: preview and viewer) adds its files."""
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


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc) or type(exc).__name__


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
        raise MeshFileError(f"{folder}: cannot write there{where}: {_reason(exc)}") from None
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

    Coordinates are written with 17 significant digits: :func:`load_mesh` reads back the same
    float64 values bit for bit.

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
    from .raster import rasterize_footprint

    labels = np.zeros(len(F), dtype=np.int64) if labels is None else np.asarray(labels)
    n = int(labels.max()) + 1
    # colour of each chart's number + 1; 0 (no chart) is white
    lut = np.vstack([[255, 255, 255], _palette(n)]).astype(np.uint8)
    chart = np.zeros((size, size), dtype=np.uint8 if n < 255 else np.int64)
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(n + 1))
    groups = [order[bounds[k] : bounds[k + 1]] for k in range(n)]
    P = np.asarray(uv, dtype=np.float64) * size
    for k, faces in enumerate(groups):  # loop over charts
        if len(faces) == 0:
            continue
        mask = rasterize_footprint(uv, F[faces], resolution=size, eps=0.0)
        box = _texel_box(P[F[faces].ravel()], size)  # the chart's texels all lie in this box
        np.copyto(chart[box], k + 1, where=mask[box])
    image = Image.fromarray(lut.take(chart[::-1], axis=0))  # row 0 is v = 0: flip, v grows up
    if outline:
        draw = ImageDraw.Draw(image)
        P = uv * size
        P[:, 1] = size - P[:, 1]
        for faces in groups:  # loop over charts, then over their few boundary loops
            for loop in boundary_loops(F[faces]):
                pts = P[np.r_[loop, loop[:1]]]
                draw.line(list(map(tuple, pts.tolist())), fill=(40, 40, 40), width=1)
    return image


def _texel_box(Q: np.ndarray, size: int) -> tuple[slice, slice]:
    """Rows and columns of a ``size`` grid that hold every texel a conservative rasterization of
    points ``Q`` (texel units) can touch: their bounding box and one texel around it."""
    lo, hi = Q.min(axis=0), Q.max(axis=0)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        return slice(0, size), slice(0, size)
    c0, r0 = np.clip(np.floor(lo) - 1, 0, size).astype(np.int64)
    c1, r1 = np.clip(np.floor(hi) + 2, 0, size).astype(np.int64)
    return slice(int(r0), int(r1)), slice(int(c0), int(c1))


def checker_image(size: int = 1024, squares: int = 16):
    """A checkerboard texture with a colour ramp (so flips and rotations show), PIL image."""
    from PIL import Image

    return Image.fromarray(_checker_pixels(size, squares))


def _checker_pixels(size: int, squares: int) -> np.ndarray:
    """The pixels of :func:`checker_image`, (size, size, 3) uint8.

    Red ramps along the columns, green down the rows, blue is constant, and dark squares take
    35% of each: every channel is a lookup by row or by column, broadcast over the image.
    """
    a = np.arange(size)
    cell = size // squares
    parity = (a // cell) % 2 == 1
    dark = parity[:, None] != parity[None, :]  # (i // cell + j // cell) is odd
    red = (80 + 150 * a / size).astype(np.uint8)  # by column
    green = (80 + 150 * (1 - a / size)).astype(np.uint8)  # by row
    blue = np.full(1, 200, dtype=np.uint8)
    img = np.empty((size, size, 3), dtype=np.uint8)
    img[..., 0] = np.where(dark, (red * 0.35).astype(np.uint8), red)
    img[..., 1] = np.where(dark, (green * 0.35).astype(np.uint8)[:, None], green[:, None])
    img[..., 2] = np.where(dark, (blue * 0.35).astype(np.uint8), blue)
    return img


@functools.lru_cache(maxsize=4)
def _checker_png(size: int = 1024, squares: int = 16) -> bytes:
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


def save_atlas(
    atlas, outdir: str | os.PathLike, *, stem: str = "mesh", size: int | None = None, pictures=None
):
    """Write an atlas into ``outdir``: ``<stem>.obj/.mtl/_checker.png``, ``<stem>.glb``,
    ``<stem>_uv.png``, the pictures of ``pictures`` (:class:`segparam.pictures.PictureOptions`;
    default ``<stem>_preview.png`` and ``<stem>.html``) and ``report.json``.

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
    import json

    outdir = Path(outdir)
    stem = str(stem)
    if not stem or stem in (".", "..") or "/" in stem or os.sep in stem:
        raise MeshFileError(f"stem {stem!r} is not a file name")
    stem = atlas_stem(stem, outdir)
    from .pictures import PictureOptions, make_pictures

    pictures = PictureOptions() if pictures is None else pictures
    names = atlas_file_names(stem, pictures)
    check_output_folder(outdir, names.values())
    size = size or atlas.packing.resolution
    try:
        # the pictures are made before anything is written: a failure leaves no file
        layout = render_uv_layout(atlas.uv, atlas.uv_F, labels=atlas.chart_of_face, size=size)
        uv_png = _png_bytes(np.asarray(layout))
        extra, pictures_info = make_pictures(
            atlas, stem, pictures, checker_png=_checker_png(1024), uv_png=uv_png
        )
        report = atlas.report()
        seconds = pictures_info.pop("seconds")
        timings = {**report.get("timings", {}), **{f"picture {k}": v for k, v in seconds.items()}}
        report["timings"] = timings
        report["pictures"] = pictures_info
        with staged_outputs(outdir) as stage:
            checker = _checker_png(1024)
            (stage / names["checker"]).write_bytes(checker)
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
            (stage / names["glb"]).write_bytes(
                _glb_bytes(atlas.V[atlas.uv_vertex], atlas.uv_F, atlas.uv, checker)
            )
            (stage / names["uv"]).write_bytes(uv_png)
            for name, data in extra.items():
                (stage / name).write_bytes(data)
            (stage / names["report"]).write_text(
                json.dumps(report, indent=1, sort_keys=False) + "\n", encoding="utf-8"
            )
    except MeshFileError:
        raise
    except OSError as exc:
        raise MeshFileError(f"{outdir}: cannot write the atlas files: {_reason(exc)}") from None
    return [outdir / name for name in names.values()]


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
    """A binary glTF 2.0 of a textured triangle mesh that keeps float64 placement.

    One scene, one node, one mesh with one triangle primitive: ``POSITION`` (float32),
    ``TEXCOORD_0`` (float32, ``v`` flipped: glTF's uv origin is the top-left corner) and uint32
    indices, and a material whose base colour is the PNG ``png``, embedded. An object far from
    the origin (1e7 away, say) would lose up to half a unit to float32 positions: its positions
    are written relative to its bounding-box centre and the node carries the centre as its
    ``translation``, which glTF keeps as a JSON (double) number. The same input gives the same
    bytes.

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
    import json

    from . import __version__

    V = np.asarray(V, dtype=np.float64)
    uv = np.asarray(uv, dtype=np.float64)
    if len(uv) != len(V):
        raise ValueError(f"{len(V)} positions but {len(uv)} texture coordinates")
    node: dict = {"mesh": 0}
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
    blobs = [indices.tobytes(), positions.tobytes(), texcoords.tobytes(), png]
    targets = [_GL_ELEMENT_ARRAY_BUFFER, _GL_ARRAY_BUFFER, _GL_ARRAY_BUFFER, None]
    views, offset = [], 0
    for blob, target in zip(blobs, targets, strict=True):
        view = {"buffer": 0, "byteOffset": offset, "byteLength": len(blob)}
        views.append(view if target is None else {**view, "target": target})
        offset += len(blob)  # a multiple of 4 up to the image: 4-byte indices, 12-, 8-byte vertices
    binary = _pad(b"".join(blobs), b"\0")
    gltf = {
        "asset": {"version": "2.0", "generator": f"segparam {__version__}"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [node],
        "meshes": [
            {
                "primitives": [
                    {
                        "attributes": {"POSITION": 1, "TEXCOORD_0": 2},
                        "indices": 0,
                        "material": 0,
                        "mode": _GL_TRIANGLES,
                    }
                ]
            }
        ],
        "accessors": [
            _accessor(0, _GL_UNSIGNED_INT, indices.size, "SCALAR"),
            _accessor(
                1,
                _GL_FLOAT,
                len(positions),
                "VEC3",
                min=positions.min(axis=0).tolist(),  # required for POSITION
                max=positions.max(axis=0).tolist(),
            ),
            _accessor(2, _GL_FLOAT, len(texcoords), "VEC2"),
        ],
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
        "images": [{"bufferView": 3, "mimeType": "image/png"}],
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
                    f"{outdir}: moving the new files in failed ({_reason_of(exc)}), and so did "
                    f"putting back {', '.join(failed)}; the previous files are kept in {backup}"
                ) from exc
            raise
    finally:
        if not keep:
            with _ctrl_c_deferred():
                shutil.rmtree(stage, ignore_errors=True)


def _reason_of(exc: BaseException) -> str:
    if isinstance(exc, OSError):
        return _reason(exc)
    return type(exc).__name__
