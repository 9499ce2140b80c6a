"""The atlas writers: OBJ text, PNG pictures and the binary glTF written without trimesh.

The OBJ text is byte for byte what ``np.savetxt`` with ``%.17g`` wrote before; the checker and
the uv-layout pictures have the pixels the former code drew; the GLB is valid glTF 2.0 (the JSON
checked field by field against the specification) and trimesh reads back from it the atlas's
positions, uvs, faces and texture, as it did from the file trimesh used to write.
"""

from __future__ import annotations

import io as _io
import json
import struct
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh
from meshes import tri_grid
from PIL import Image

import segparam.export as export
from segparam.export import checker_image, render_uv_layout, save_atlas, write_obj
from segparam.io import load_mesh

# ---------------------------------------------------------------------------------------------
# Helpers
# ---------------------------------------------------------------------------------------------


def two_chart_atlas(offset=(0.0, 0.0, 0.0), *, seed: int = 0) -> SimpleNamespace:
    """What save_atlas reads from an atlas: a bumpy grid cut into two charts along a seam, each
    chart's uvs (its xy projection) in one half of the unit square."""
    V, F = tri_grid(7, 5)
    V[:, 2] = np.random.default_rng(seed).normal(0, 0.1, len(V))
    centroid_x = V[F, 0].mean(axis=1)
    labels = (centroid_x > np.median(centroid_x)).astype(np.int64)
    uv_vertex, uv_F = [], np.empty_like(F)
    for k in (0, 1):  # split the seam's vertices: one uv vertex per (vertex, chart)
        faces = np.flatnonzero(labels == k)
        used, inverse = np.unique(F[faces], return_inverse=True)
        uv_F[faces] = inverse.reshape(-1, 3) + sum(len(u) for u in uv_vertex)
        uv_vertex.append(used)
    uv_vertex = np.concatenate(uv_vertex)
    uv = V[uv_vertex, :2] - V[:, :2].min(axis=0)
    uv = uv / (uv.max() * 2.2)
    uv[uv_F[labels == 1].ravel(), 0] += 0.5  # chart 1 in the right half
    return SimpleNamespace(
        V=V + np.asarray(offset),
        F=F,
        uv=uv,
        uv_F=uv_F,
        uv_vertex=uv_vertex,
        chart_of_face=labels,
        packing=SimpleNamespace(resolution=64, size=(64, 64)),
        report=lambda: {},
    )


def glb_parts(raw: bytes) -> tuple[dict, bytes]:
    """The JSON and BIN chunks of a GLB, checking the container (header, chunk order, 4-byte
    alignment) on the way."""
    magic, version, length = struct.unpack("<4sII", raw[:12])
    assert (magic, version, length) == (b"glTF", 2, len(raw))
    json_length, json_type = struct.unpack("<I4s", raw[12:20])
    assert json_type == b"JSON" and json_length % 4 == 0
    content = raw[20 : 20 + json_length]
    assert content == content.rstrip(b" ") + b" " * (len(content) - len(content.rstrip(b" ")))
    start = 20 + json_length
    bin_length, bin_type = struct.unpack("<I4s", raw[start : start + 8])
    assert bin_type == b"BIN\0" and bin_length % 4 == 0
    assert start + 8 + bin_length == len(raw)
    return json.loads(content), raw[start + 8 :]


COMPONENT_SIZE = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
COMPONENT_DTYPE = {5125: "<u4", 5126: "<f4"}


def check_gltf_spec(gltf: dict, binary: bytes) -> None:
    """The glTF 2.0 required fields and the rules a validator checks for this kind of file."""
    assert gltf["asset"]["version"] == "2.0"
    (buffer,) = gltf["buffers"]  # a GLB's one buffer, its data the BIN chunk: no uri
    assert "uri" not in buffer
    assert 0 <= len(binary) - buffer["byteLength"] < 4
    for view in gltf["bufferViews"]:
        assert view["buffer"] == 0 and view["byteLength"] > 0
        offset = view.get("byteOffset", 0)
        assert offset >= 0 and offset + view["byteLength"] <= buffer["byteLength"]
        assert view.get("target", 34962) in (34962, 34963)
    for acc in gltf["accessors"]:
        assert acc["componentType"] in COMPONENT_SIZE and acc["type"] in COMPONENTS
        assert isinstance(acc["count"], int) and acc["count"] >= 1
        view = gltf["bufferViews"][acc["bufferView"]]
        size = COMPONENT_SIZE[acc["componentType"]]
        offset = acc.get("byteOffset", 0)
        assert (view.get("byteOffset", 0) + offset) % size == 0
        assert offset + acc["count"] * COMPONENTS[acc["type"]] * size <= view["byteLength"]
    for k in ("scene", "scenes", "nodes", "meshes", "materials", "textures", "images"):
        assert k in gltf
    assert 0 <= gltf["scene"] < len(gltf["scenes"])
    for scene in gltf["scenes"]:
        assert all(0 <= n < len(gltf["nodes"]) for n in scene["nodes"])
    for node in gltf["nodes"]:
        assert 0 <= node["mesh"] < len(gltf["meshes"])
        assert "matrix" not in node or "translation" not in node
    for mesh in gltf["meshes"]:
        for prim in mesh["primitives"]:
            assert prim.get("mode", 4) == 4
            attrs = prim["attributes"]
            counts = {gltf["accessors"][a]["count"] for a in attrs.values()}
            assert len(counts) == 1  # every attribute has one value per vertex
            pos = gltf["accessors"][attrs["POSITION"]]
            assert (pos["componentType"], pos["type"]) == (5126, "VEC3")
            assert len(pos["min"]) == len(pos["max"]) == 3  # required for POSITION
            uv = gltf["accessors"][attrs["TEXCOORD_0"]]
            assert (uv["componentType"], uv["type"]) == (5126, "VEC2")
            idx = gltf["accessors"][prim["indices"]]
            assert (idx["componentType"], idx["type"]) == (5125, "SCALAR")
            assert idx["count"] % 3 == 0
            assert "target" not in gltf["bufferViews"][gltf["images"][0]["bufferView"]]
            assert 0 <= prim["material"] < len(gltf["materials"])
    for texture in gltf["textures"]:
        assert 0 <= texture["source"] < len(gltf["images"])
        assert 0 <= texture.get("sampler", 0) < len(gltf.get("samplers", [{}]))
    for image in gltf["images"]:
        assert image["mimeType"] == "image/png"
        view = gltf["bufferViews"][image["bufferView"]]
        assert binary[view["byteOffset"] : view["byteOffset"] + 8] == b"\x89PNG\r\n\x1a\n"


def accessor_data(gltf: dict, binary: bytes, index: int) -> np.ndarray:
    acc = gltf["accessors"][index]
    view = gltf["bufferViews"][acc["bufferView"]]
    k = COMPONENTS[acc["type"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    data = np.frombuffer(
        binary, dtype=COMPONENT_DTYPE[acc["componentType"]], count=acc["count"] * k, offset=start
    )
    return data.reshape(acc["count"], k) if k > 1 else data


def world_mesh(path: Path):
    """The mesh trimesh reads from a GLB, in world space (node transforms applied)."""
    scene = trimesh.load(path, process=False)
    (name,) = scene.graph.nodes_geometry
    transform, geometry = scene.graph[name]
    mesh = scene.geometry[geometry].copy()
    mesh.apply_transform(transform)
    return mesh


# ---------------------------------------------------------------------------------------------
# OBJ: the same text as np.savetxt wrote, faster
# ---------------------------------------------------------------------------------------------


def savetxt_obj(V, F, *, uv=None, uv_faces=None, mtl=None, material="atlas") -> bytes:
    """The OBJ text write_obj wrote with np.savetxt (the reference)."""

    def rows(tag, A, fmt, sep=None):
        A = np.asarray(A)
        if len(A) == 0:
            return ""
        if sep is None:
            row = " ".join([fmt] * A.shape[1])
        else:
            row = sep[1].join([sep[0].join([fmt, fmt])] * (A.shape[1] // 2))
        buf = _io.StringIO()
        np.savetxt(buf, A, fmt=f"{tag} {row}")
        return buf.getvalue()

    lines = ["# written by segparam"] + ([f"mtllib {mtl}"] if mtl else [])
    body = [rows("v", V, "%.17g")]
    if uv is not None:
        body.append(rows("vt", uv, "%.17g"))
        T = F if uv_faces is None else uv_faces
        corners = np.stack([F + 1, T + 1], axis=2).reshape(len(F), 6)
        faces = rows("f", corners, "%d", sep=("/", " "))
    else:
        faces = rows("f", F + 1, "%d")
    if mtl:
        body.append(f"usemtl {material}\n")
    body.append(faces)
    return ("\n".join(lines) + "\n" + "".join(body)).encode("utf-8")


def awkward_floats(rng: np.random.Generator, shape) -> np.ndarray:
    """Floats over the whole float64 range, with zeros of both signs and subnormals."""
    A = rng.normal(size=shape) * 10.0 ** rng.integers(-300, 300, size=shape)
    A[rng.random(shape) < 0.05] = 0.0
    A[rng.random(shape) < 0.05] = -0.0
    A[rng.random(shape) < 0.02] = 5e-324
    return A


@pytest.mark.parametrize("n", [1, 2, 16, 57, 300])
def test_write_obj_text_is_what_savetxt_wrote(n, tmp_path, monkeypatch):
    monkeypatch.setattr(export, "_ROW_CHUNK", 16)  # rows formatted in several blocks
    rng = np.random.default_rng(n)
    V = awkward_floats(rng, (n, 3))
    F = rng.integers(0, n, size=(2 * n + 1, 3))
    uv = rng.random((n + 3, 2))
    T = rng.integers(0, n + 3, size=F.shape)
    cases = [
        ({}, (V, F)),
        ({"uv": uv[:n]}, (V, F)),
        ({"uv": uv, "uv_faces": T, "mtl": "m é.mtl", "material": "skin"}, (V, F)),
        ({}, (np.clip(V, -1e38, 1e38).astype(np.float32), F.astype(np.int32))),
        ({"uv": uv[:n]}, (V, F.astype(np.uint32))),
        ({}, (np.round(rng.normal(size=(n, 3)) * 1e6).astype(np.int64), F)),
    ]
    for kwargs, (W, G) in cases:
        write_obj(tmp_path / "m.obj", W, G, **kwargs)
        assert (tmp_path / "m.obj").read_bytes() == savetxt_obj(W, G, **kwargs)


def test_write_obj_special_values_and_index_sizes(tmp_path):
    V = np.array([[np.nan, np.inf, -np.inf], [0.0, -0.0, 5e-324], [1e308, -1e-308, 0.1]])
    big = [0, 9, 10, 99, 100, 999_999, 10**12, 2**62, 2**63 - 2]
    F = np.array(big[:9]).reshape(3, 3)
    for W, G in [
        (V, F),
        (V, F.astype(np.uint64)),
        (V, np.array([[2**64 - 2, 0, 1]], dtype=np.uint64)),
        (V, np.array([[-5, 0, 1]])),  # negative: the %-formatting path
        (np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)),
    ]:
        write_obj(tmp_path / "m.obj", W, G)
        assert (tmp_path / "m.obj").read_bytes() == savetxt_obj(W, G)
        write_obj(tmp_path / "m.obj", W, G, uv=W[:, :2] if len(W) else None)
        expected = savetxt_obj(W, G, uv=W[:, :2] if len(W) else None)
        assert (tmp_path / "m.obj").read_bytes() == expected


def test_write_obj_with_uvs_reads_back_bit_for_bit(tmp_path):
    rng = np.random.default_rng(3)
    V, F = tri_grid(9, 7)
    V = V * 3 + 1e7 + rng.random(V.shape)
    uv = rng.random((len(V) + 5, 2))
    T = rng.integers(0, len(uv), size=F.shape)
    write_obj(tmp_path / "m.obj", V, F, uv=uv, uv_faces=T, mtl="m.mtl")
    W, G = load_mesh(tmp_path / "m.obj")
    assert W.tobytes() == V.tobytes()
    np.testing.assert_array_equal(G, F)
    text = (tmp_path / "m.obj").read_text().splitlines()
    vt = np.array([[float(x) for x in line.split()[1:]] for line in text if line[:3] == "vt "])
    assert vt.tobytes() == uv.tobytes()
    corners = [line.split()[1:] for line in text if line[:2] == "f "]
    got = np.array([[c.split("/")[1] for c in row] for row in corners], dtype=np.int64) - 1
    np.testing.assert_array_equal(got, T)


# ---------------------------------------------------------------------------------------------
# Pictures: the same pixels as before, PNG written by us
# ---------------------------------------------------------------------------------------------


def former_checker(size: int, squares: int) -> np.ndarray:
    """The checker the former code drew, pixel by pixel."""
    i, j = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
    cell = size // squares
    dark = ((i // cell + j // cell) % 2).astype(bool)
    img = np.empty((size, size, 3), dtype=np.uint8)
    img[..., 0] = (80 + 150 * j / size).astype(np.uint8)
    img[..., 1] = (80 + 150 * (1 - i / size)).astype(np.uint8)
    img[..., 2] = 200
    img[dark] = (img[dark] * 0.35).astype(np.uint8)
    return img


@pytest.mark.parametrize("size,squares", [(1024, 16), (64, 16), (100, 16), (1000, 7), (17, 4)])
def test_checker_has_the_former_pixels(size, squares):
    expected = former_checker(size, squares)
    image = checker_image(size, squares)
    assert image.mode == "RGB"
    np.testing.assert_array_equal(np.asarray(image), expected)
    png = Image.open(_io.BytesIO(export._checker_png(size, squares)))
    np.testing.assert_array_equal(np.asarray(png), expected)


def test_checker_png_is_made_once_per_size():
    assert export._checker_png(64) is export._checker_png(64)
    assert export._checker_png(64) != export._checker_png(32)


@pytest.mark.parametrize("shape", [(1, 1), (7, 5), (64, 3), (3, 200)])
def test_png_bytes_decode_to_the_pixels(shape):
    rng = np.random.default_rng(shape[0] * 1000 + shape[1])
    for pixels in (
        rng.integers(0, 256, (*shape, 3)).astype(np.uint8),
        np.zeros((*shape, 3), np.uint8),
        np.full((*shape, 3), 255, np.uint8),
    ):
        image = Image.open(_io.BytesIO(export._png_bytes(pixels)))
        image.load()
        assert image.mode == "RGB" and image.size == (shape[1], shape[0])
        np.testing.assert_array_equal(np.asarray(image), pixels)


def test_png_bytes_refuse_what_is_not_rgb8():
    with pytest.raises(ValueError):
        export._png_bytes(np.zeros((4, 4), np.uint8))
    with pytest.raises(ValueError):
        export._png_bytes(np.zeros((4, 4, 3), np.float64))


def former_fill(uv, F, labels, size) -> np.ndarray:
    """The uv layout's chart fill as the former code drew it: a full-size mask per chart."""
    from segparam.pack import rasterize_footprint

    n = int(labels.max()) + 1
    colors = export._palette(n).astype(np.uint8)
    img = np.full((size, size, 3), 255, dtype=np.uint8)
    for k in range(n):
        faces = np.flatnonzero(labels == k)
        img[rasterize_footprint(uv, F[faces], resolution=size, eps=0.0)] = colors[k]
    return img[::-1]


def test_uv_layout_fill_has_the_former_pixels():
    rng = np.random.default_rng(5)
    for trial in range(150):
        n = int(rng.integers(3, 40))
        uv = rng.random((n, 2)) * rng.choice([1.0, 1.3]) - rng.choice([0.0, 0.15])
        if trial % 3 == 0:
            uv = np.round(uv * 32) / 32  # vertices on texel corners
        F = rng.integers(0, n, size=(int(rng.integers(1, 30)), 3))
        labels = rng.integers(0, 300 if trial % 10 == 0 else 5, len(F))
        size = int(rng.choice([16, 32, 33]))
        got = render_uv_layout(uv, F, labels=labels, size=size, outline=False)
        np.testing.assert_array_equal(np.asarray(got), former_fill(uv, F, labels, size))


# ---------------------------------------------------------------------------------------------
# GLB: valid glTF 2.0, read back as the atlas
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (1e7, -2e7, 5e6)], ids=["near", "far"])
def test_glb_follows_the_gltf_spec(offset, tmp_path):
    atlas = two_chart_atlas(offset)
    save_atlas(atlas, tmp_path, size=64)
    gltf, binary = glb_parts((tmp_path / "mesh.glb").read_bytes())
    check_gltf_spec(gltf, binary)
    (prim,) = gltf["meshes"][0]["primitives"]
    positions = accessor_data(gltf, binary, prim["attributes"]["POSITION"])
    pos = gltf["accessors"][prim["attributes"]["POSITION"]]
    assert pos["min"] == positions.min(axis=0).tolist()  # the float32 values, exactly
    assert pos["max"] == positions.max(axis=0).tolist()
    (node,) = gltf["nodes"]
    V = atlas.V[atlas.uv_vertex]
    if offset == (0.0, 0.0, 0.0):
        assert "translation" not in node and "matrix" not in node
        np.testing.assert_array_equal(positions, V.astype(np.float32))
    else:  # the float64 centre in the node, float32 positions around it
        centre = (V.min(axis=0) + V.max(axis=0)) / 2
        assert node["translation"] == centre.tolist()
        np.testing.assert_array_equal(positions, (V - centre).astype(np.float32))
    texcoords = accessor_data(gltf, binary, prim["attributes"]["TEXCOORD_0"])
    np.testing.assert_array_equal(texcoords[:, 0], atlas.uv[:, 0].astype(np.float32))
    np.testing.assert_array_equal(texcoords[:, 1], (1 - atlas.uv[:, 1]).astype(np.float32))
    indices = accessor_data(gltf, binary, prim["indices"])
    np.testing.assert_array_equal(indices.reshape(-1, 3), atlas.uv_F)
    view = gltf["bufferViews"][gltf["images"][0]["bufferView"]]
    png = binary[view["byteOffset"] : view["byteOffset"] + view["byteLength"]]
    assert png == (tmp_path / "mesh_checker.png").read_bytes()


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (1e7, -2e7, 5e6)], ids=["near", "far"])
def test_trimesh_reads_the_atlas_back_from_the_glb(offset, tmp_path):
    atlas = two_chart_atlas(offset)
    save_atlas(atlas, tmp_path, size=64)
    mesh = world_mesh(tmp_path / "mesh.glb")
    V = atlas.V[atlas.uv_vertex]
    size = np.ptp(V, axis=0).max()
    assert np.abs(mesh.vertices - V).max() < 1e-6 * size
    np.testing.assert_array_equal(mesh.faces, atlas.uv_F)
    np.testing.assert_allclose(mesh.visual.uv, atlas.uv, atol=1e-7)  # float32, v flipped back
    texture = np.asarray(mesh.visual.material.baseColorTexture.convert("RGB"))
    np.testing.assert_array_equal(texture, former_checker(1024, 16))


def test_glb_shows_what_the_trimesh_export_showed(tmp_path):
    """Read back by trimesh, the GLB is the one trimesh wrote before: same geometry, uvs (the
    same v flip) and texture pixels; the material is the MTL's (white, not metallic)."""
    atlas = two_chart_atlas()
    save_atlas(atlas, tmp_path, size=64)
    V = atlas.V[atlas.uv_vertex]
    visual = trimesh.visual.TextureVisuals(uv=atlas.uv, image=checker_image(1024))
    old = trimesh.Trimesh(V, atlas.uv_F, visual=visual, process=False).export(file_type="glb")
    (tmp_path / "old.glb").write_bytes(old)
    new, before = world_mesh(tmp_path / "mesh.glb"), world_mesh(tmp_path / "old.glb")
    np.testing.assert_array_equal(new.vertices, before.vertices)
    np.testing.assert_array_equal(new.faces, before.faces)
    np.testing.assert_array_equal(new.visual.uv, before.visual.uv)
    a, b = new.visual.material, before.visual.material
    np.testing.assert_array_equal(a.baseColorFactor, [255, 255, 255, 255])
    assert a.metallicFactor == 0.0 and a.roughnessFactor == 1.0
    np.testing.assert_array_equal(
        np.asarray(a.baseColorTexture.convert("RGB")), np.asarray(b.baseColorTexture.convert("RGB"))
    )
    new_gltf, _ = glb_parts((tmp_path / "mesh.glb").read_bytes())
    assert new_gltf["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] == {"index": 0}


def test_atlas_files_are_the_same_bytes_every_time(tmp_path):
    atlas = two_chart_atlas((1e7, 0.0, 0.0))
    first = save_atlas(atlas, tmp_path / "a", stem="x", size=64)
    second = save_atlas(atlas, tmp_path / "b", stem="x", size=64)
    for p, q in zip(first, second, strict=True):
        if p.name == "report.json":  # the pictures' measured seconds differ; nothing else may
            a, b = json.loads(p.read_text()), json.loads(q.read_text())
            a.pop("timings"), b.pop("timings")
            assert a == b
        else:
            assert p.read_bytes() == q.read_bytes(), p.name


def test_uv_layout_png_is_the_rendered_picture(tmp_path):
    atlas = two_chart_atlas()
    save_atlas(atlas, tmp_path, size=64)
    written = Image.open(tmp_path / "mesh_uv.png")
    drawn = render_uv_layout(atlas.uv, atlas.uv_F, labels=atlas.chart_of_face, size=64)
    assert written.size == (64, 64)
    np.testing.assert_array_equal(np.asarray(written), np.asarray(drawn))


def test_save_atlas_does_not_import_trimesh(tmp_path):
    """trimesh is for reading STL/GLB input; importing it cost the quick start a third of a
    second just to write the GLB."""
    atlas = two_chart_atlas()
    arrays = {k: getattr(atlas, k) for k in ("V", "F", "uv", "uv_F", "uv_vertex", "chart_of_face")}
    np.savez(tmp_path / "atlas.npz", **arrays)
    code = (
        "import sys\n"
        "from types import SimpleNamespace\n"
        "import numpy as np\n"
        "from segparam.export import save_atlas\n"
        "atlas = SimpleNamespace(**np.load(sys.argv[1]), report=lambda: {},\n"
        "                        packing=SimpleNamespace(resolution=64, size=(64, 64)))\n"
        "save_atlas(atlas, sys.argv[2])\n"
        "assert 'trimesh' not in sys.modules, 'trimesh imported'\n"
    )
    out = tmp_path / "out"
    result = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path / "atlas.npz"), str(out)],
        capture_output=True,
        text=True,
        cwd=tmp_path,  # not the repository: the child imports the package the tests import
    )
    assert result.returncode == 0, result.stderr
    assert (out / "mesh.glb").exists()


# ---------------------------------------------------------------------------------------------
# a trimmed (non-square) texture: every picture and metric at its width x height


def test_a_long_sheet_gets_a_trimmed_texture_and_every_file_follows(tmp_path):
    from segparam.pictures import PictureOptions
    from segparam.pipeline import PipelineConfig, build_atlas
    from segparam.quality import distortion

    V, F = tri_grid(24, 6, width=4.0, height=1.0)  # flat, 4 x 1: one chart, no distortion
    config = PipelineConfig().replace(pack={"resolution": 256}, remesh={"mode": "off"})
    atlas = build_atlas(V, F, config)
    W, H = atlas.packing.size
    assert atlas.n_charts == 1 and W == 256 and H < 128 and H % 4 == 0
    report = atlas.report()["atlas"]
    assert (report["width"], report["height"], report["resolution"]) == (W, H, 256)
    assert report["utilization"] > 0.7  # of the trimmed texture; under 0.3 of the square
    # distortion on the texture's texels: the flat sheet is mapped without any
    assert report["l2_stretch"] == pytest.approx(1.0, abs=1e-9)
    assert report["angle_distortion"] == pytest.approx(1.0, abs=1e-9)
    d = distortion(atlas.V[atlas.uv_vertex], atlas.uv_F, atlas.texel_uv)
    assert d["angle_distortion"] == pytest.approx(report["angle_distortion"], abs=1e-12)
    assert distortion(atlas.V[atlas.uv_vertex], atlas.uv_F, atlas.uv)["angle_distortion"] > 1.5
    options = PictureOptions(bakes=("curvature",), flat=True)
    atlas.save(tmp_path, stem="sheet", pictures=options)
    for name in ("sheet_uv.png", "sheet_curvature.png", "sheet_flatmap.png"):
        with Image.open(tmp_path / name) as img:
            assert img.size == (W, H), name
    with Image.open(tmp_path / "sheet_checker.png") as img:  # its squares square on the model
        cw, ch = img.size
        assert cw == export.CHECKER_SIZE and ch == round(export.CHECKER_SIZE * H / W)
        pixels = np.asarray(img.convert("RGB"))
    cell = export.CHECKER_SIZE // export.CHECKER_SQUARES
    dark = pixels[:, :, 2] < 100  # blue: 200, or 70 in a dark square
    assert dark[0, 0] == dark[cell - 1, cell - 1] != dark[cell, 0] == dark[0, cell]
    glb = trimesh.load(tmp_path / "sheet.glb", force="mesh", process=False)
    assert glb.visual.material.baseColorTexture.size == (cw, ch)
    import nibabel as nib  # the flat surface keeps the texture's proportions

    points = nib.load(tmp_path / "sheet_flat.gii").darrays[0].data
    np.testing.assert_allclose(points[:, :2], atlas.uv * [1, H / W], atol=1e-6)


def test_square_keeps_the_whole_texture(tmp_path, capsys):
    from segparam.cli import main

    V, F = tri_grid(24, 6, width=4.0, height=1.0)
    write_obj(tmp_path / "sheet.obj", V, F)
    common = ["atlas", str(tmp_path / "sheet.obj"), "--resolution", "256", "--no-remesh"]
    assert main([*common, "-o", str(tmp_path / "trim"), "--quiet"]) == 0
    assert main([*common, "-o", str(tmp_path / "square"), "--square", "--quiet"]) == 0
    trimmed = json.loads((tmp_path / "trim" / "report.json").read_text())["atlas"]
    square = json.loads((tmp_path / "square" / "report.json").read_text())["atlas"]
    assert (square["width"], square["height"]) == (256, 256) and trimmed["height"] < 128
    assert trimmed["texels_per_unit"] == pytest.approx(square["texels_per_unit"], rel=1e-12)
    with Image.open(tmp_path / "square" / "sheet_uv.png") as img:
        assert img.size == (256, 256)
