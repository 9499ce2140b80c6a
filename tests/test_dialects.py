"""Mesh file dialects: what exporters really write reads back as the mesh they meant.

One test per bug that read a wrong mesh silently or refused a valid file (relative OBJ indices,
polygons fanned across concave corners, PLY headers that announce more than the data holds, a
byte-order mark or tabs in an OBJ, writers that lost float64 precision), then properties: random
meshes through the writer and through random OBJ dialects read back identical; truncated or
corrupted files give the same mesh or a clean MeshFileError, never another exception.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from meshes import tri_grid

from segparam.errors import MeshFileError
from segparam.export import save_atlas, write_obj
from segparam.io import load_mesh

PROPERTY = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,  # CI sees the same examples every run
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

# ---------------------------------------------------------------------------------------------
# Helpers
# ---------------------------------------------------------------------------------------------


def _write(path: Path, data: bytes | str) -> Path:
    path.write_bytes(data.encode() if isinstance(data, str) else data)
    return path


def areas(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Unsigned triangle areas."""
    return 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)


def facing(V: np.ndarray, F: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Component of each triangle's (area-weighted) normal along ``normal``."""
    return np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]) @ normal


def star(k: int = 12, inner: float = 0.3) -> np.ndarray:
    """A concave planar k-gon (a star with k / 2 points), counter-clockwise, in the z = 0 plane."""
    t = np.arange(k) * 2 * np.pi / k
    r = np.where(np.arange(k) % 2 == 0, 1.0, inner)
    return np.stack([r * np.cos(t), r * np.sin(t), np.zeros(k)], axis=1)


def shoelace(P: np.ndarray) -> float:
    """Area of a planar polygon in the z = 0 plane."""
    x, y = P[:, 0], P[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


TILT = trimesh.transformations.rotation_matrix(0.7, [1.0, 2.0, 0.5])[:3, :3]
# A dart: corner 1 is reflex, so the 0-2 diagonal (the fan from corner 0) runs outside the quad.
DART = np.array([[0.0, 0.0, 0.0], [1.0, 0.6, 0.0], [2.0, 0.0, 0.0], [1.0, 2.0, 0.0]])


def polygon_mesh() -> tuple[np.ndarray, list[list[int]], np.ndarray]:
    """A triangle, the dart quad and the 12-gon star, tilted out of the plane.

    Returns V, the faces as lists of corners, and the polygon normal (the same for all).
    """
    P = np.vstack([[[3.0, 0, 0], [4, 0, 0], [3, 1, 0]], DART, star() + [0, 4, 0]])
    faces = [[0, 1, 2], [3, 4, 5, 6], list(range(7, 19))]
    return P @ TILT.T, faces, TILT @ [0.0, 0.0, 1.0]


def polygon_area() -> float:
    """True area of :func:`polygon_mesh`'s three polygons."""
    return 0.5 + shoelace(DART) + shoelace(star())


def ply_bytes(
    V: np.ndarray,
    faces: list[list[int]],
    *,
    binary: bool,
    counts: tuple[int, int] | None = None,
    order: str = "<",
) -> bytes:
    """A PLY of polygons (float32 x y z, uchar-int lists); ``counts`` overrides the header's,
    ``order`` is the byte order of a binary one."""
    nv, nf = counts or (len(V), len(faces))
    fmt = f"binary_{'little' if order == '<' else 'big'}_endian" if binary else "ascii"
    header = (
        f"ply\nformat {fmt} 1.0\ncomment made by test_dialects\nelement vertex {nv}\n"
        "property float x\nproperty float y\nproperty float z\n"
        f"element face {nf}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    if binary:
        body = V.astype(f"{order}f4").tobytes() + b"".join(
            struct.pack(f"{order}B{len(f)}i", len(f), *f) for f in faces
        )
    else:
        rows = [" ".join(repr(float(x)) for x in v) for v in V.astype(np.float32)]
        rows += [" ".join(map(str, [len(f), *f])) for f in faces]
        body = ("\n".join(rows) + "\n").encode()
    return header + body


def off_text(V: np.ndarray, faces: list[list[int]]) -> str:
    """An OFF file of polygons, with a comment line."""
    rows = [f"{len(V)} {len(faces)} 0"] + [" ".join(map(repr, v.tolist())) for v in V]
    rows += [" ".join(map(str, [len(f), *f])) for f in faces]
    return "OFF\n# an OFF file\n" + "\n".join(rows) + "\n"


def obj_text(V: np.ndarray, faces: list[list[int]]) -> str:
    """A plain OBJ of polygons (shortest exact float spelling)."""
    rows = [f"v {x!r} {y!r} {z!r}" for x, y, z in V.tolist()]
    rows += ["f " + " ".join(str(i + 1) for i in f) for f in faces]
    return "\n".join(rows) + "\n"


def small_mesh(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A 4 x 3 grid (12 triangles) with random heights."""
    V, F = tri_grid(4, 3)
    V[:, 2] = np.random.default_rng(seed).normal(0, 0.1, len(V))
    return V, F


# ---------------------------------------------------------------------------------------------
# 1. OBJ relative (negative) indices resolve against the vertices read so far
# ---------------------------------------------------------------------------------------------


def test_relative_indices_interleaved_with_vertices(tmp_path):
    """A streaming exporter writes each face's vertices and then ``f -3 -2 -1``."""
    V, F = small_mesh()
    corners = ["{}", "{}/{}", "{}//{}", "{}/{}/{}"]
    rows = []
    for k, face in enumerate(F):
        rows += [f"v {x!r} {y!r} {z!r}" for x, y, z in V[face].tolist()]
        rows += ["vt 0.5 0.5", "vn 0 0 1"]
        fmt = corners[k % 4]
        rows.append("f " + " ".join(fmt.format(i, -1, -1) for i in (-3, -2, -1)))
    loaded_V, loaded_F = load_mesh(_write(tmp_path / "stream.obj", "\n".join(rows) + "\n"))
    np.testing.assert_array_equal(loaded_V, V[F.ravel()])
    np.testing.assert_array_equal(loaded_F, np.arange(3 * len(F)).reshape(-1, 3))


def test_mixed_positive_and_negative_indices(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 -2 -1\nv 1 1 0\nf -3/1 2/-1 -1//4\nf 4 -1 3\n"
    _, F = load_mesh(_write(tmp_path / "mixed.obj", text))
    assert F.tolist() == [[0, 1, 2], [1, 1, 3], [3, 3, 2]]


def test_relative_index_before_its_vertex_is_refused_naming_the_line(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n"
    with pytest.raises(MeshFileError, match=r"line 3 uses vertex index -3, out of range"):
        load_mesh(_write(tmp_path / "early.obj", text))


# ---------------------------------------------------------------------------------------------
# 2. Polygons: concave quads and n-gons triangulated inside, in the file's order and winding
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", ["obj", "off", "ply ascii", "ply binary"])
def test_concave_polygons_keep_their_area_and_winding(fmt, tmp_path):
    V, faces, normal = polygon_mesh()
    if fmt == "obj":
        path = _write(tmp_path / "poly.obj", obj_text(V, faces))
    elif fmt == "off":
        path = _write(tmp_path / "poly.off", off_text(V, faces))
    else:
        path = _write(tmp_path / "poly.ply", ply_bytes(V, faces, binary=fmt == "ply binary"))
    W, F = load_mesh(path)
    assert len(F) == 1 + 2 + 10  # k - 2 triangles per k-gon, nothing dropped
    # file order: the triangle, the quad's two, the star's ten
    assert F[0].tolist() == [0, 1, 2] and set(F[1:3].ravel()) == {3, 4, 5, 6}
    assert set(F[3:].ravel()) == set(range(7, 19))
    tol = 1e-6 if fmt.startswith("ply") else 1e-12  # float32 positions in the PLY
    assert areas(W, F).sum() == pytest.approx(polygon_area(), rel=tol)
    assert (facing(W, F, normal) > 0).all()  # none flipped against the polygon


def test_concave_quad_is_split_at_its_reflex_corner(tmp_path):
    """The fan from corner 0 of the dart covers area outside it and flips one triangle."""
    V = DART @ TILT.T
    for start in range(4):  # the reflex corner at every position of the face
        face = np.roll(np.arange(4), -start) + 1
        path = _write(tmp_path / "dart.obj", obj_text(V, []) + "f " + " ".join(map(str, face)))
        W, F = load_mesh(path)
        assert areas(W, F).sum() == pytest.approx(shoelace(DART), rel=1e-12)
        assert (facing(W, F, TILT[:, 2]) > 0).all()


def test_convex_quads_keep_the_0_2_diagonal(tmp_path):
    V = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    _, F = load_mesh(_write(tmp_path / "square.obj", obj_text(V, [[0, 1, 2, 3]])))
    first = np.argmin(F, axis=1)  # each triangle from its smallest corner, winding kept
    F = np.take_along_axis(F, (first[:, None] + np.arange(3)) % 3, axis=1)
    assert sorted(F.tolist()) == [[0, 1, 2], [0, 2, 3]]


def test_binary_ply_with_mixed_polygon_sizes_reads_like_the_obj(tmp_path):
    """Triangles, quads and hexagons in random order: every row's start depends on the last."""
    rng = np.random.default_rng(5)
    t = np.arange(6) * np.pi / 3
    hexagon = np.stack([np.cos(t), np.sin(t), np.zeros(6)], axis=1)
    V = (hexagon[None] + np.arange(200)[:, None, None] * [3.0, 0, 0]).reshape(-1, 3)
    sizes = rng.choice([3, 4, 6], size=200)
    faces = [list(6 * i + np.arange(k)) for i, k in enumerate(sizes)]
    expected = load_mesh(_write(tmp_path / "mixed.obj", obj_text(V.astype(np.float32), faces)))
    W, F = load_mesh(_write(tmp_path / "mixed.ply", ply_bytes(V, faces, binary=True)))
    np.testing.assert_array_equal(W, expected[0])
    np.testing.assert_array_equal(F, expected[1])
    assert len(F) == (sizes - 2).sum()


def test_polygon_with_a_repeated_corner_still_gives_k_minus_2_triangles(tmp_path):
    V = np.array([[0.0, 0, 0], [2, 0, 0], [2, 0, 0], [2, 1, 0], [1, 0.5, 0], [0, 1, 0]])
    _, F = load_mesh(_write(tmp_path / "repeat.obj", obj_text(V, [list(range(6))])))
    assert len(F) == 4


# ---------------------------------------------------------------------------------------------
# 3. PLY: the header's element counts must match the data
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
@pytest.mark.parametrize("counts", [(1, 0), (0, 1), (0, -1), (2, -1)], ids=str)
def test_ply_header_counts_that_disagree_with_the_data_are_an_error(binary, counts, tmp_path):
    V, F = small_mesh()
    faces = F.tolist()
    announced = (len(V) + counts[0], len(faces) + counts[1])
    path = _write(tmp_path / "lie.ply", ply_bytes(V, faces, binary=binary, counts=announced))
    with pytest.raises(MeshFileError, match="announces") as info:
        load_mesh(path)
    assert "lie.ply" in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize("binary,order", [(False, "<"), (True, "<"), (True, ">")])
def test_ply_with_the_right_counts_reads_back(binary, order, tmp_path):
    V, F = small_mesh()
    faces = F.tolist() + [[0, 1, 5, 4]]  # a quad too: list lengths differ
    path = _write(tmp_path / "ok.ply", ply_bytes(V, faces, binary=binary, order=order))
    W, G = load_mesh(path)
    np.testing.assert_array_equal(W, V.astype(np.float32))
    np.testing.assert_array_equal(G[: len(F)], F)
    assert len(G) == len(F) + 2


def test_ply_from_trimesh_reads_back(tmp_path):
    V, F = small_mesh()
    for encoding in ("binary", "ascii"):
        data = trimesh.Trimesh(V, F, process=False).export(file_type="ply", encoding=encoding)
        W, G = load_mesh(_write(tmp_path / "tm.ply", data))
        np.testing.assert_allclose(W, V, rtol=0, atol=1e-6)
        np.testing.assert_array_equal(G, F)


# ---------------------------------------------------------------------------------------------
# 4. OBJ whitespace: byte-order mark, tabs, runs of spaces, CRLF, trailing blanks, comments
# ---------------------------------------------------------------------------------------------


def test_byte_order_mark_keeps_the_first_vertex(tmp_path):
    V, F = small_mesh()
    W, G = load_mesh(_write(tmp_path / "bom.obj", b"\xef\xbb\xbf" + obj_text(V, F).encode()))
    np.testing.assert_array_equal(W, V)
    np.testing.assert_array_equal(G, F)


@pytest.mark.parametrize(
    "sep,end",
    [("\t", "\n"), ("  ", "\n"), (" \t ", "\n"), (" ", "\r\n"), (" ", "  \n"), (" ", " # c\n")],
    ids=["tab", "spaces", "mixed", "crlf", "trailing", "comment"],
)
def test_any_whitespace_between_tokens(sep, end, tmp_path):
    V, F = small_mesh()
    rows = [sep.join(["v", *map(repr, v)]) for v in V.tolist()]
    rows += [sep.join(["f", *map(str, f + 1)]) for f in F]
    W, G = load_mesh(_write(tmp_path / "ws.obj", end.join(rows) + end))
    np.testing.assert_array_equal(W, V)
    np.testing.assert_array_equal(G, F)


# ---------------------------------------------------------------------------------------------
# 5. Writers keep float64 precision
# ---------------------------------------------------------------------------------------------


def test_write_obj_round_trips_bit_for_bit_far_from_the_origin(tmp_path):
    V, F = small_mesh()
    V = V * 3 + 1e7 + np.random.default_rng(1).random(V.shape)
    write_obj(tmp_path / "far.obj", V, F)
    W, G = load_mesh(tmp_path / "far.obj")
    assert W.tobytes() == V.tobytes()
    np.testing.assert_array_equal(G, F)


def _fake_atlas(V: np.ndarray, F: np.ndarray) -> SimpleNamespace:
    """What save_atlas reads from an atlas: one chart, uv = the xy projection."""
    uv = V[:, :2] - V[:, :2].min(axis=0)
    return SimpleNamespace(
        V=V,
        F=F,
        uv=uv / uv.max(),
        uv_F=F,
        uv_vertex=np.arange(len(V)),
        chart_of_face=np.zeros(len(F), dtype=np.int64),
        packing=SimpleNamespace(resolution=64, size=(64, 64)),
        report=lambda: {},
    )


def _glb_positions(path: Path) -> np.ndarray:
    """Vertex positions of a GLB in world space (node transforms applied) and its nodes."""
    scene = trimesh.load(path)
    mesh = scene.to_geometry() if hasattr(scene, "to_geometry") else scene.dump(concatenate=True)
    return np.asarray(mesh.vertices)


def _glb_nodes(path: Path) -> list[dict]:
    raw = path.read_bytes()
    (length,) = struct.unpack("<I", raw[12:16])
    return json.loads(raw[20 : 20 + length])["nodes"]


def test_glb_far_from_the_origin_keeps_its_shape(tmp_path):
    V, F = small_mesh()
    V = V * 3 + [1e7, -2e7, 5e6]
    save_atlas(_fake_atlas(V, F), tmp_path, size=64)
    size = np.ptp(V, axis=0).max()
    assert np.abs(_glb_positions(tmp_path / "mesh.glb") - V).max() < 1e-6 * size
    (node,) = _glb_nodes(tmp_path / "mesh.glb")
    assert "translation" in node and "matrix" not in node


def test_glb_near_the_origin_has_no_node_translation(tmp_path):
    """Near the origin the positions are stored as they are (no offset on the node), and read
    back as the mesh (tests/test_export.py compares the whole file with trimesh's export)."""
    V, F = small_mesh()
    atlas = _fake_atlas(V, F)
    save_atlas(atlas, tmp_path, size=64)
    assert all(
        "translation" not in n and "matrix" not in n for n in _glb_nodes(tmp_path / "mesh.glb")
    )
    mesh = trimesh.load(tmp_path / "mesh.glb", force="mesh", process=False)
    assert np.abs(np.asarray(mesh.vertices) - V).max() < 1e-6


# ---------------------------------------------------------------------------------------------
# Properties
# ---------------------------------------------------------------------------------------------

_coords = hnp.arrays(
    np.float64,
    st.tuples(st.integers(3, 12), st.just(3)),
    elements=st.floats(allow_nan=False, allow_infinity=False, width=64),
)


@PROPERTY
@given(V=_coords, seed=st.integers(0, 2**16))
def test_property_write_obj_reads_back_bit_for_bit(V, seed, tmp_path_factory):
    rng = np.random.default_rng(seed)
    F = rng.integers(0, len(V), size=(rng.integers(1, 10), 3))
    path = tmp_path_factory.mktemp("rt") / "mesh.obj"
    write_obj(path, V, F)
    W, G = load_mesh(path)
    assert W.tobytes() == V.tobytes()
    np.testing.assert_array_equal(G, F)


SEPARATORS = [" ", "\t", "  ", " \t", "\t\t "]
CORNERS = ["{v}", "{v}/{t}", "{v}//{n}", "{v}/{t}/{n}"]
FILLER = ["o part", "g group", "usemtl skin", "s off", "vt 0.25 0.75", "vn 0 0 1", "l 1 2", "# x"]


def dialect_obj(V: np.ndarray, F: np.ndarray, rng: np.random.Generator, flags: dict) -> bytes:
    """OBJ text of (V, F) in a random dialect; faces follow as soon as their vertices are read.

    ``flags``: bom, crlf, indent, trailing, comments, final_newline; per line the separators,
    number spelling, corner format, index sign and filler lines are random.
    """

    def sep():
        return SEPARATORS[rng.integers(len(SEPARATORS))] if flags["odd_space"] else " "

    def line(*tokens):
        text = ("  " if flags["indent"] and rng.random() < 0.5 else "") + tokens[0]
        for t in tokens[1:]:
            text += sep() + t
        if flags["trailing"] and rng.random() < 0.5:
            text += sep()
        if flags["comments"] and rng.random() < 0.3:
            text += " # note v 1 2 3"
        return text

    def number(x: float) -> str:
        return repr(x) if rng.random() < 0.5 else f"{x:.17e}"

    ready = np.maximum.accumulate(F.max(axis=1))  # faces keep their order
    rows, f = [], 0
    for i, v in enumerate(V.tolist()):
        rows.append(line("v", *map(number, v)))
        if rng.random() < 0.3:
            rows.append(FILLER[rng.integers(len(FILLER))])
        while f < len(F) and ready[f] <= i:
            fmt = CORNERS[rng.integers(len(CORNERS))]
            negative = rng.random(3) < 0.5
            idx = np.where(negative, F[f] - (i + 1), F[f] + 1)
            rows.append(line("f", *(fmt.format(v=j, t=1, n=1) for j in idx)))
            f += 1
    end = "\r\n" if flags["crlf"] else "\n"
    text = end.join(rows) + (end if flags["final_newline"] else "")
    return (b"\xef\xbb\xbf" if flags["bom"] else b"") + text.encode()


_flags = st.fixed_dictionaries(
    {
        k: st.booleans()
        for k in ("bom", "crlf", "indent", "trailing", "comments", "final_newline", "odd_space")
    }
)


@PROPERTY
@given(V=_coords, seed=st.integers(0, 2**16), flags=_flags)
def test_property_obj_dialects_read_back_the_same_mesh(V, seed, flags, tmp_path_factory):
    rng = np.random.default_rng(seed)
    F = rng.integers(0, len(V), size=(rng.integers(1, 10), 3))
    path = tmp_path_factory.mktemp("dialect") / "mesh.obj"
    path.write_bytes(dialect_obj(V, F, rng, flags))
    W, G = load_mesh(path)
    assert W.tobytes() == V.tobytes()
    np.testing.assert_array_equal(G, F)


def _corrupt(data, raw: bytes, *, flips: bool) -> bytes:
    raw = bytearray(raw)
    if data.draw(st.booleans(), label="truncate"):
        raw = raw[: data.draw(st.integers(0, len(raw) - 1), label="keep")]
    if flips and raw:
        for i, x in data.draw(
            st.lists(st.tuples(st.integers(0, len(raw) - 1), st.integers(1, 255)), max_size=4),
            label="flips",
        ):
            raw[i] ^= x
    return bytes(raw)


@PROPERTY
@given(data=st.data())
def test_property_corrupted_obj_is_a_mesh_or_a_clean_error(data, tmp_path_factory):
    V, F = small_mesh()
    path = tmp_path_factory.mktemp("obj") / "mesh.obj"
    write_obj(path, V, F)
    flips = data.draw(st.booleans(), label="flip bytes")
    raw = _corrupt(data, path.read_bytes(), flips=flips)
    path.write_bytes(raw)
    try:
        W, G = load_mesh(path)
    except MeshFileError as exc:
        assert path.name in str(exc) and "\n" not in str(exc)
        return
    assert W.shape[1] == 3 and G.shape[1] == 3 and G.min() >= 0 and G.max() < len(W)
    if not flips:  # a prefix of the file: all but the last (possibly cut) row are the original
        np.testing.assert_array_equal(W[:-1], V[: len(W) - 1])
        np.testing.assert_array_equal(G[:-1], F[: len(G) - 1])


@PROPERTY
@given(data=st.data(), binary=st.booleans())
def test_property_corrupted_ply_is_a_mesh_or_a_clean_error(data, binary, tmp_path_factory):
    V, F = small_mesh()
    raw = ply_bytes(V, F.tolist(), binary=binary)
    flips = data.draw(st.booleans(), label="flip bytes")
    path = tmp_path_factory.mktemp("ply") / "mesh.ply"
    path.write_bytes(_corrupt(data, raw, flips=flips))
    try:
        W, G = load_mesh(path)
    except MeshFileError as exc:
        assert path.name in str(exc) and "\n" not in str(exc)
        return
    assert G.min() >= 0 and G.max() < len(W)
    if not flips:  # only a cut inside the last face line of an ASCII file can still parse
        assert len(path.read_bytes()) == len(raw) or not binary
        np.testing.assert_array_equal(W, V.astype(np.float32))
        np.testing.assert_array_equal(G[:-1], F[:-1])


@PROPERTY
@given(
    delta=st.tuples(st.integers(-3, 3), st.integers(-3, 3)).filter(lambda d: d != (0, 0)),
    binary=st.booleans(),
    seed=st.integers(0, 2**16),
)
def test_property_ply_header_counts_that_lie_are_always_an_error(
    delta, binary, seed, tmp_path_factory
):
    V, F = small_mesh(seed)
    counts = (len(V) + delta[0], len(F) + delta[1])
    path = tmp_path_factory.mktemp("lie") / "mesh.ply"
    path.write_bytes(ply_bytes(V, F.tolist(), binary=binary, counts=counts))
    with pytest.raises(MeshFileError):
        load_mesh(path)
