"""segparam vs. xatlas: time and atlas quality on the same meshes, in the same run.

Meshes, from 1k to 1M faces (all deterministic; none is downloaded): built in code, and the real
meshes bundled in the pymeshlab wheel. ``--quick`` runs the first group only, the default adds
the second, ``--large`` adds brain-300k and the range scan, ``--huge`` adds brain-1m too:

quick (up to ~36k faces)

``brain-2k``
    ``segparam.synthetic.brain_like_surface(2000)``: a small closed cortex-like surface.
``brain-2k-s1``, ``brain-2k-s2``
    The same at seeds 1 and 2: one coarse folded surface is one draw of its distortion
    (seed 0 meets issue 14's bounds, the next seeds do not; BENCHMARKS.md 0.1, session 23).
``triangles-2000``
    2,000 disjoint random triangles (many components): centres uniform in [0, 10]^3, corners
    centre + N(0, 0.2) per coordinate (``numpy.random.default_rng(0)``: centres first, then
    corners).
``sheet-3k``
    ``wavy_sheet(58, 29)``: the scan-like sheet below at 3,025 faces.
``icosphere``
    ``trimesh.creation.icosphere(5)`` (20480 faces).
``torus``
    A 160 x 64 quad torus, triangulated (20480 faces).
``fsaverage5-pial``
    A real cortical surface: FreeSurfer's fsaverage5 left pial surface (10,242 vertices, 20,480
    faces), read with ``segparam.io.load_mesh`` from the copy bundled inside the ``nilearn``
    wheel (``nilearn/datasets/data/fsaverage5/pial_left.gii.gz``; nilearn is not imported and
    nothing is fetched). Skipped with a note when nilearn is not installed.
``plate-holes``
    A CAD-like 4 x 3 plate, 0.25 thick, with six through holes: structured cells, sharp edges,
    tall wall triangles (genus 6; 19648 faces).
``brain-20k``
    ``brain_like_surface(20_000)``.
``spheres-300``
    300 closed ``trimesh.creation.icosphere(1)`` spheres of 80 faces (many small closed parts;
    24,000 faces): radii uniform in [0.3, 1.0], centres uniform in [0, 20]^3
    (``default_rng(0)``: radii first, then centres). Spheres may intersect; they share no
    vertex.
``spheres-300-jitter``
    The same spheres, every vertex moved by N(0, 0.01 radius) per coordinate
    (``default_rng(0)`` after the centres): no sphere is a copy of another, so each is cut and
    mapped on its own (``spheres-300``'s are copies, mapped once: ``segparam.instances``).
``wavy-sheet``
    A scan-like open sheet: a 200 x 100 jittered grid with a wavy height field plus noise and
    four holes (36020 faces).
``bone-scan``, ``cow``, ``airplane``, ``bunny-holes``
    Real meshes nobody here made, the rows of issue 13's and issue 14's tables: the sample
    meshes bundled in the pymeshlab wheel (``pymeshlab/tests/sample_meshes``; pymeshlab is a
    dependency, nothing is fetched), read with ``segparam.io.load_mesh``: ``bone.ply`` (a bone
    scan, 3,022 faces), ``cow.obj`` (non-manifold, 5,804), ``airplane.obj`` (10,796) and
    ``bunny10k_textured.obj`` (a bunny with holes, 9,999).

default (adds)

``brain-60k``, ``brain-100k``
    ``brain_like_surface(n)``.
``cylinder``, ``bushing``, ``pipe``
    Turned CAD parts, ``trimesh.creation`` solids subdivided twice: a capped cylinder (radius
    1, height 3, 48 sections; 3,072 faces), a bushing (``annulus``: radii 0.5 and 1, height
    0.3; 6,144 faces) and a pipe (``annulus``: radii 0.8 and 1, height 2, 64 sections; 8,192
    faces). Their walls are tubes: one opened into one chart, the bushing's too long to open.
``bunny``
    pymeshlab's ``bunny.obj`` (56,172 faces).

``--large``: ``brain-300k`` and ``range-scan`` (pymeshlab's ``rangemaps/face000.ply``: a range
scan of 166,259 faces in 22 pieces; xatlas takes about two minutes on it); ``--huge`` adds
``brain-1m`` (1,000,000 faces).

For each mesh and tool: wall seconds (the minimum over ``--repeat`` runs), charts, flipped
triangles, mirrored charts, overlap (texels shared by two charts, ``footprint_conflicts`` at 1024
with padding 0, on the tool's own texture), texture (its width x height in texels), utilization
(uv triangle area over the unit square:
the share of the tool's own texture its charts cover; segparam's texture is 1024 x 1024 unless
trimmed, ``PackConfig.trim``, and xatlas's is its atlas' ``width x height``), L2 / Linf stretch
and angle distortion (``segparam.quality.distortion`` on the uvs in texels of that texture),
seam (``segparam.quality.seam_length``: total 3-D length of
the mesh edges whose two faces have different uv rows, over sqrt of the surface area; the
mesh's own boundary is not a seam). ``ratio`` is segparam seconds / xatlas seconds. The quality
figures come from the first run (segparam is seeded and xatlas deterministic: every run gives the
same atlas). A second table gives segparam's seconds per stage (``Atlas.timings`` of its fastest
run: clean, remesh, segment, parameterize, pack; ``other`` is the rest of the wall time,
assembling the atlas); the JSON holds them per row under ``stages``. Before the table both tools
run once, untimed, on ``brain_like_surface(500)``, so that one-off costs (numba kernels, lazy
imports) do not land on the first row.

Orientation is judged per chart: a chart whose signed uv area is mostly negative is *mirrored*
(a valid texture, but mirrored); a triangle whose sign is opposite to its chart's majority, or of
zero area, is *flipped*. ``negative`` counts triangles with signed area <= 0 relative to the
input winding, as ``Atlas.report()`` does.

xatlas runs with its defaults except ``PackOptions.resolution = 1024`` and ``padding = 2`` (ours:
``PackConfig`` defaults 1024 / 2). segparam runs with remesh mode ``off``; when the ``auto``
policy would remesh a mesh, a second ``segparam-auto`` row is added.

Usage::

    python benchmarks/bench_atlas.py [--quick] [--large] [--huge] [--repeat N]
        [--only NAME ...] [--out benchmarks/results/atlas.json]

``--only`` picks meshes by name from every group (``--only brain-1m`` needs no ``--huge``).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from segparam.io import load_mesh
from segparam.mesh import face_areas
from segparam.pack import footprint_conflicts
from segparam.pipeline import PipelineConfig, build_atlas
from segparam.quality import distortion, seam_length, signed_areas
from segparam.remesh import auto_policy, mesh_quality
from segparam.synthetic import brain_like_surface

RESOLUTION = 1024
PADDING = 2
STAGES = ("clean", "remesh", "segment", "parameterize", "pack")

# ----------------------------------------------------------------------------------------------
# meshes


def icosphere(subdiv: int = 5) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdiv)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def grid_faces(nu: int, nv: int, *, wrap_u: bool, wrap_v: bool) -> np.ndarray:
    """Triangles of an nu x nv quad grid on vertices ``i * nv_pts + j``."""
    nv_pts = nv if wrap_v else nv + 1
    nu_pts = nu if wrap_u else nu + 1
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = i * nv_pts + j
    b = ((i + 1) % nu_pts) * nv_pts + j
    c = ((i + 1) % nu_pts) * nv_pts + (j + 1) % nv_pts
    d = i * nv_pts + (j + 1) % nv_pts
    return np.vstack(
        [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    )


def torus(n_major: int = 160, n_minor: int = 64, r: float = 0.35) -> tuple[np.ndarray, np.ndarray]:
    u = np.linspace(0, 2 * np.pi, n_major, endpoint=False)
    v = np.linspace(0, 2 * np.pi, n_minor, endpoint=False)
    U, W = np.meshgrid(u, v, indexing="ij")
    V = np.stack(
        [(1 + r * np.cos(W)) * np.cos(U), (1 + r * np.cos(W)) * np.sin(U), r * np.sin(W)], -1
    ).reshape(-1, 3)
    return V, grid_faces(n_major, n_minor, wrap_u=True, wrap_v=True).astype(np.int64)


def _square_boundary(m: int) -> np.ndarray:
    """4m points counter-clockwise on the boundary of [-1, 1]^2, starting at (1, 0)."""
    s = np.linspace(-1, 1, m + 1)[:-1]
    half = m // 2
    right = np.stack([np.ones(m), s], 1)
    top = np.stack([-s, np.ones(m)], 1)
    left = np.stack([-np.ones(m), -s], 1)
    bottom = np.stack([s, -np.ones(m)], 1)
    P = np.vstack([right, top, left, bottom])
    return np.roll(P, -half, axis=0)  # start at angle 0


def _cell(m: int, hole: float | None, n_r: int) -> tuple[np.ndarray, np.ndarray]:
    """One square cell [-1, 1]^2 sampled with m + 1 points a side, optionally around a hole."""
    if hole is None:
        g = np.linspace(-1, 1, m + 1)
        X, Y = np.meshgrid(g, g, indexing="ij")
        return np.stack([X.ravel(), Y.ravel()], 1), grid_faces(m, m, wrap_u=False, wrap_v=False)
    outer = _square_boundary(m)
    theta = np.arctan2(outer[:, 1], outer[:, 0])
    inner = hole * np.stack([np.cos(theta), np.sin(theta)], 1)
    t = np.linspace(0, 1, n_r + 1)[:, None, None]
    P = ((1 - t) * inner[None] + t * outer[None]).reshape(-1, 2)
    # rings are the v direction (periodic), radii the u direction
    F = grid_faces(n_r, 4 * m, wrap_u=False, wrap_v=True)
    return P, F[:, [0, 2, 1]]


def plate_with_holes(
    nx: int = 4, ny: int = 3, m: int = 16, thickness: float = 0.25
) -> tuple[np.ndarray, np.ndarray]:
    """A closed plate of nx x ny unit cells, every other cell with a through hole."""
    pts, tris, off = [], [], 0
    for ix in range(nx):
        for iy in range(ny):
            hole = (0.3 + 0.1 * (ix % 2)) if (ix + iy) % 2 == 0 else None
            P, T = _cell(m, hole, n_r=8)
            pts.append(0.5 * P + [ix + 0.5, iy + 0.5])
            tris.append(T + off)
            off += len(P)
    P = np.vstack(pts)
    T = np.vstack(tris)
    # weld the shared cell borders
    key = np.round(P * 1e6).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    P, T = P[first], inv.ravel()[T]
    n = len(P)
    # orient the top counter-clockwise
    sa = signed_areas(P, T)
    T = np.where((sa < 0)[:, None], T[:, [0, 2, 1]], T)
    # boundary half-edges of the top: those whose reverse is missing
    he = np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]])
    code = he[:, 0] * n + he[:, 1]
    rev = he[:, 1] * n + he[:, 0]
    B = he[~np.isin(rev, code)]
    a, b = B[:, 0], B[:, 1]
    walls = np.vstack([np.stack([b, a, a + n], 1), np.stack([b, a + n, b + n], 1)])
    V = np.vstack([np.c_[P, np.full(n, thickness)], np.c_[P, np.zeros(n)]])
    F = np.vstack([T, T[:, [0, 2, 1]] + n, walls])
    return V, F.astype(np.int64)


def wavy_sheet(nx: int = 200, ny: int = 100, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Scan-like open sheet: jittered grid, wavy heights with noise, four holes."""
    rng = np.random.default_rng(seed)
    h = 2.0 / nx
    x, y = np.meshgrid(np.linspace(0, 2, nx + 1), np.linspace(0, 1, ny + 1), indexing="ij")
    x = x + rng.uniform(-0.3, 0.3, x.shape) * h
    y = y + rng.uniform(-0.3, 0.3, y.shape) * h
    z = (
        0.12 * np.sin(3 * x + 1) * np.cos(4 * y)
        + 0.05 * np.sin(9 * x * y)
        + 0.003 * rng.standard_normal(x.shape)
    )
    V = np.stack([x.ravel(), y.ravel(), z.ravel()], 1)
    F = grid_faces(nx, ny, wrap_u=False, wrap_v=False).astype(np.int64)
    holes = np.array([[0.4, 0.35, 0.12], [1.0, 0.6, 0.18], [1.55, 0.3, 0.1], [1.6, 0.75, 0.08]])
    c = V[F, :2].mean(axis=1)
    inside = np.zeros(len(F), dtype=bool)
    for cx, cy, r in holes:
        inside |= np.hypot(c[:, 0] - cx, c[:, 1] - cy) < r
    F = F[~inside]
    used, inv = np.unique(F, return_inverse=True)
    return V[used], inv.reshape(-1, 3)


def disjoint_triangles(n: int = 2000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n disjoint triangles: centres uniform in [0, 10]^3, corners centre + N(0, 0.2)."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0.0, 10.0, (n, 3))
    corners = centres[:, None, :] + rng.normal(0.0, 0.2, (n, 3, 3))
    return corners.reshape(-1, 3), np.arange(3 * n, dtype=np.int64).reshape(-1, 3)


def many_spheres(n: int = 300, seed: int = 0, jitter: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """n closed icospheres (subdivision 1, 80 faces): radii in [0.3, 1], centres in [0, 20]^3;
    with ``jitter``, every vertex moved by N(0, jitter * radius) per coordinate (then drawn)."""
    import trimesh

    ico = trimesh.creation.icosphere(subdivisions=1)
    P = np.asarray(ico.vertices, dtype=np.float64)
    T = np.asarray(ico.faces, dtype=np.int64)
    rng = np.random.default_rng(seed)
    radii = rng.uniform(0.3, 1.0, n)
    centres = rng.uniform(0.0, 20.0, (n, 3))
    V = centres[:, None, :] + radii[:, None, None] * P[None]
    if jitter:
        V = V + rng.normal(0.0, jitter, V.shape) * radii[:, None, None]
    F = T[None] + len(P) * np.arange(n, dtype=np.int64)[:, None, None]
    return V.reshape(-1, 3), F.reshape(-1, 3)


class Unavailable(Exception):
    """A mesh that cannot be built on this machine (the row is skipped with a note)."""


def fsaverage5_pial() -> tuple[np.ndarray, np.ndarray]:
    """fsaverage5's left pial surface from the copy bundled in the nilearn wheel."""
    spec = importlib.util.find_spec("nilearn")  # locates the package without importing it
    if spec is None or spec.origin is None:
        raise Unavailable("nilearn is not installed (pip install -e '.[bench]')")
    folder = Path(spec.origin).parent / "datasets" / "data" / "fsaverage5"
    for name in ("pial_left.gii.gz", "pial.left.gii.gz"):
        if (folder / name).is_file():
            return load_mesh(folder / name)
    raise Unavailable(f"no bundled fsaverage5 pial surface in {folder}")


#: The real scans and models of issue 13's and issue 14's tables, as bundled in the pymeshlab
#: wheel (a dependency of segparam: ``pymeshlab/tests/sample_meshes``); nothing is downloaded.
SAMPLE_MESHES = {
    "bone-scan": "bone.ply",
    "cow": "cow.obj",
    "airplane": "airplane.obj",
    "bunny-holes": "bunny10k_textured.obj",
    "bunny": "bunny.obj",
    "range-scan": "rangemaps/face000.ply",
}


def pymeshlab_sample(name: str) -> tuple[np.ndarray, np.ndarray]:
    """A real mesh from pymeshlab's bundled samples (``SAMPLE_MESHES``), read with
    ``segparam.io.load_mesh``."""
    spec = importlib.util.find_spec("pymeshlab")  # locates the package without importing it
    if spec is None or spec.origin is None:
        raise Unavailable("pymeshlab is not installed")
    path = Path(spec.origin).parent / "tests" / "sample_meshes" / SAMPLE_MESHES[name]
    if not path.is_file():
        raise Unavailable(f"this pymeshlab wheel has no {path.name} in its samples")
    return load_mesh(path)


def turned_part(kind: str) -> tuple[np.ndarray, np.ndarray]:
    """The CAD parts of the default group (see the module docstring), subdivided twice."""
    import trimesh

    m = {
        "cylinder": lambda: trimesh.creation.cylinder(radius=1.0, height=3.0, sections=48),
        "bushing": lambda: trimesh.creation.annulus(r_min=0.5, r_max=1.0, height=0.3, sections=48),
        "pipe": lambda: trimesh.creation.annulus(r_min=0.8, r_max=1.0, height=2.0, sections=64),
    }[kind]()
    m = m.subdivide().subdivide()
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


# name -> (group, builder); groups: quick, default, large, huge (each adds to the one before)
MESHES: dict[str, tuple[str, Callable[[], tuple[np.ndarray, np.ndarray]]]] = {
    "brain-2k": ("quick", lambda: brain_like_surface(2_000)),
    "brain-2k-s1": ("quick", lambda: brain_like_surface(2_000, seed=1)),
    "brain-2k-s2": ("quick", lambda: brain_like_surface(2_000, seed=2)),
    "triangles-2000": ("quick", lambda: disjoint_triangles(2_000)),
    "sheet-3k": ("quick", lambda: wavy_sheet(58, 29)),
    "icosphere": ("quick", lambda: icosphere(5)),
    "torus": ("quick", torus),
    "fsaverage5-pial": ("quick", fsaverage5_pial),
    "plate-holes": ("quick", plate_with_holes),
    "brain-20k": ("quick", lambda: brain_like_surface(20_000)),
    "spheres-300": ("quick", lambda: many_spheres(300)),
    "spheres-300-jitter": ("quick", lambda: many_spheres(300, jitter=0.01)),
    "wavy-sheet": ("quick", wavy_sheet),
    "bone-scan": ("quick", lambda: pymeshlab_sample("bone-scan")),
    "cow": ("quick", lambda: pymeshlab_sample("cow")),
    "airplane": ("quick", lambda: pymeshlab_sample("airplane")),
    "bunny-holes": ("quick", lambda: pymeshlab_sample("bunny-holes")),
    "brain-60k": ("default", lambda: brain_like_surface(60_000)),
    "brain-100k": ("default", lambda: brain_like_surface(100_000)),
    "cylinder": ("default", lambda: turned_part("cylinder")),
    "bushing": ("default", lambda: turned_part("bushing")),
    "pipe": ("default", lambda: turned_part("pipe")),
    "bunny": ("default", lambda: pymeshlab_sample("bunny")),
    "brain-300k": ("large", lambda: brain_like_surface(300_000)),
    "range-scan": ("large", lambda: pymeshlab_sample("range-scan")),
    "brain-1m": ("huge", lambda: brain_like_surface(1_000_000)),
}


def selected(quick: bool, large: bool, huge: bool, only: list[str] | None) -> list[str]:
    """Mesh names to run, in table order: ``only`` if given, else the groups the flags ask for."""
    if only:
        return [name for name in MESHES if name in only]
    groups = {"quick"}
    if not quick:
        groups.add("default")
        if large or huge:
            groups.add("large")
        if huge:
            groups.add("huge")
    return [name for name, (group, _) in MESHES.items() if group in groups]


# ----------------------------------------------------------------------------------------------
# measures


def orientation(uv: np.ndarray, uv_F: np.ndarray, chart: np.ndarray) -> dict[str, int]:
    """Mirrored charts and flipped triangles, judged against each chart's majority sign."""
    sa = signed_areas(uv, uv_F)
    n_charts = int(chart.max()) + 1
    net = np.bincount(chart, weights=sa, minlength=n_charts)
    sign = np.where(net < 0, -1.0, 1.0)
    return {
        "flipped": int((sa * sign[chart] <= 0).sum()),
        "mirrored_charts": int((net < 0).sum()),
        "negative": int((sa <= 0).sum()),
    }


def per_chart(uv: np.ndarray, uv_F: np.ndarray, chart: np.ndarray):
    """Per-chart (uv, local faces), loop over charts."""
    order = np.argsort(chart, kind="stable")
    bounds = np.searchsorted(chart[order], np.arange(int(chart.max()) + 2))
    uvs, faces = [], []
    for k in range(len(bounds) - 1):
        tri = uv_F[order[bounds[k] : bounds[k + 1]]]
        if len(tri) == 0:
            continue
        used, local = np.unique(tri, return_inverse=True)
        uvs.append(uv[used])
        faces.append(local.reshape(-1, 3))
    return uvs, faces


def uv_components(uv_F: np.ndarray, n_uv: int) -> np.ndarray:
    """Connected components of the uv mesh (faces sharing a uv row), per face."""
    m = len(uv_F)
    rows = np.repeat(np.arange(m), 3)
    A = sp.csr_matrix((np.ones(3 * m), (rows, uv_F.ravel())), shape=(m, n_uv))
    _, lab = connected_components(A @ A.T, directed=False)
    return lab.astype(np.int64)


def measures(
    V: np.ndarray,
    F: np.ndarray,
    uv: np.ndarray,
    uv_F: np.ndarray,
    uv_vertex: np.ndarray,
    chart: np.ndarray,
    texture: tuple[int, int],
) -> dict:
    """All figures of an atlas of the mesh ``(V, F)``: ``uv`` (in [0, 1]^2, u over the texture's
    width and v over its height, ``texture = (width, height)`` texels) row ``k`` belongs to mesh
    vertex ``uv_vertex[k]``, ``uv_F`` are the faces of ``F`` in uv rows."""
    P = V[uv_vertex]
    uvs, faces = per_chart(uv, uv_F, chart)
    row = {"charts": len(uvs), "texture": [int(texture[0]), int(texture[1])]}
    row.update(orientation(uv, uv_F, chart))
    row["overlap_texels"] = footprint_conflicts(uvs, faces, resolution=texture, padding=0)
    row["utilization"] = float(np.abs(signed_areas(uv, uv_F)).sum())
    d = distortion(P, uv_F, uv * np.asarray(texture, dtype=np.float64))  # in texels
    row.update({k: d[k] for k in ("l2_stretch", "linf_stretch", "angle_distortion")})
    row["seam"] = seam_length(V, F, uv_F, uv_vertex) / np.sqrt(face_areas(V, F).sum())
    return row


def atlas_measures(atlas) -> dict:
    """:func:`measures` of a segparam ``Atlas`` on its own texture (``packing.size``)."""
    return measures(
        atlas.V,
        atlas.F,
        atlas.uv,
        atlas.uv_F,
        atlas.uv_vertex,
        atlas.chart_of_face,
        atlas.packing.size,
    )


# ----------------------------------------------------------------------------------------------
# tools


def run_segparam(V: np.ndarray, F: np.ndarray, mode: str, repeat: int = 1) -> dict:
    cfg = PipelineConfig().replace(remesh={"mode": mode})
    atlas, seconds, stages = None, [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        a = build_atlas(V, F, cfg, seed=0)
        seconds.append(time.perf_counter() - t0)
        stages.append(a.timings)
        if atlas is None:  # the figures come from the first run
            atlas = a
    best = int(np.argmin(seconds))
    row = {"tool": "segparam" if mode == "off" else f"segparam-{mode}", "seconds": seconds[best]}
    row.update(atlas_measures(atlas))
    row["faces_out"] = int(len(atlas.uv_F))
    row["stages"] = {k: round(v, 3) for k, v in stages[best].items()}
    row["remeshed"] = bool(atlas.remeshing.remeshed)
    if repeat > 1:
        row["seconds_all"] = [round(t, 3) for t in seconds]
    return row


def _xatlas_generate(V: np.ndarray, F: np.ndarray):
    """One timed xatlas run: (atlas, (vmap, idx, uv), seconds)."""
    import xatlas

    t0 = time.perf_counter()
    atlas = xatlas.Atlas()
    atlas.add_mesh(V.astype(np.float32), F.astype(np.uint32))
    po = xatlas.PackOptions()
    po.resolution = RESOLUTION
    po.padding = PADDING
    atlas.generate(pack_options=po)
    mesh = atlas.get_mesh(0)
    return atlas, mesh, time.perf_counter() - t0


def run_xatlas(V: np.ndarray, F: np.ndarray, repeat: int = 1) -> dict:
    atlas, (vmap, idx, uv), dt = _xatlas_generate(V, F)  # the figures come from the first run
    seconds = [dt] + [_xatlas_generate(V, F)[2] for _ in range(repeat - 1)]
    vmap = vmap.astype(np.int64)
    idx = idx.astype(np.int64)
    uv = uv.astype(np.float64)
    w, h = int(atlas.width), int(atlas.height)  # xatlas's uvs are per axis in [0, 1]
    chart = np.full(len(idx), -1, dtype=np.int64)
    n_xcharts = atlas.get_mesh_chart_count(0)
    for c in range(n_xcharts):  # loop over charts
        chart[np.asarray(atlas.get_mesh_chart(0, c).faces, dtype=np.int64)] = c
    source = "xatlas charts"
    if (chart < 0).any():  # faces xatlas left out of every chart: take uv components instead
        chart = uv_components(idx, len(uv))
        source = "uv components"
    row = {"tool": "xatlas", "seconds": min(seconds)}
    row.update(measures(V, F, uv, idx, vmap, chart, (w, h)))
    row.update(
        {
            "faces_out": int(len(idx)),
            "chart_source": source,
            "atlas_size": [w, h],
            "atlas_count": int(atlas.atlas_count),
            "xatlas_texel_utilization": float(atlas.utilization),
        }
    )
    if repeat > 1:
        row["seconds_all"] = [round(t, 3) for t in seconds]
    return row


# ----------------------------------------------------------------------------------------------


COLS = (
    ("seconds", "sec", "8.2f"),
    ("ratio", "ratio", "6.2f"),
    ("charts", "charts", "6d"),
    ("flipped", "flip", "5d"),
    ("mirrored_charts", "mirr", "5d"),
    ("overlap_texels", "overlap", "7d"),
    ("texture_text", "texture", "9s"),
    ("utilization", "util", "6.3f"),
    ("l2_stretch", "L2", "6.3f"),
    ("linf_stretch", "Linf", "8.2f"),
    ("angle_distortion", "angle", "6.3f"),
    ("seam", "seam", "6.2f"),
)


NAME_W = 18


def show_header() -> None:
    print(
        f"{'mesh':{NAME_W}s} {'faces':>7s} {'tool':14s} "
        + " ".join(f"{h:>{f[:-1].split('.')[0]}s}" for _, h, f in COLS)
    )


def show_row(r: dict) -> None:
    cells = []
    for key, _, fmt in COLS:
        v = r.get(key)
        if key == "texture_text" and r.get("texture"):  # the tool's own texture, width x height
            v = "{:>9s}".format("{}x{}".format(*r["texture"]))
        width = fmt[:-1].split(".")[0]
        cells.append(f"{'-':>{width}s}" if v is None else format(v, fmt))
    print(f"{r['mesh']:{NAME_W}s} {r['faces']:7d} {r['tool']:14s} " + " ".join(cells), flush=True)


def show_stages(rows: list[dict]) -> None:
    """segparam's seconds per stage (its fastest run), one line per segparam row."""
    seg = [r for r in rows if "stages" in r]
    if not seg:
        return
    names = list(STAGES) + sorted({k for r in seg for k in r["stages"]} - set(STAGES))
    short = {"parameterize": "param"}
    print("\nsegparam seconds per stage (fastest run; other = wall time outside the stages)")
    print(
        f"{'mesh':{NAME_W}s} {'faces':>7s} {'tool':14s} "
        + " ".join(f"{short.get(k, k):>8s}" for k in names)
        + f" {'other':>8s} {'total':>8s}"
    )
    for r in seg:
        st = r["stages"]
        other = max(r["seconds"] - sum(st.values()), 0.0)  # stages are rounded to 1 ms
        print(
            f"{r['mesh']:{NAME_W}s} {r['faces']:7d} {r['tool']:14s} "
            + " ".join(f"{'-':>8s}" if k not in st else f"{st[k]:8.2f}" for k in names)
            + f" {other:8.2f} {r['seconds']:8.2f}"
        )


#: The issues' goals against xatlas on the same mesh (issue 13: time; issue 14: valid, no more
#: charts, L2 stretch no more, angle distortion within 0.02, utilization 0.70 or more).
ANGLE_SLACK = 0.02
MIN_UTILIZATION = 0.70


def goals(seg: dict, xat: dict) -> dict[str, bool]:
    """Which goals segparam's row ``seg`` meets against xatlas's row ``xat`` of the same run."""
    return {
        "time": seg["seconds"] <= xat["seconds"],
        "valid": seg["flipped"] == 0 and seg["mirrored_charts"] == 0 and seg["overlap_texels"] == 0,
        "charts": seg["charts"] <= xat["charts"],
        "l2": seg["l2_stretch"] <= xat["l2_stretch"],
        "angle": seg["angle_distortion"] <= xat["angle_distortion"] + ANGLE_SLACK,
        "utilization": seg["utilization"] >= MIN_UTILIZATION,
    }


def show_goals(rows: list[dict]) -> None:
    """One line per segparam row (default settings, remeshing off): each goal met or not."""
    seg = [r for r in rows if "goals" in r]
    if not seg:
        return
    names = list(seg[0]["goals"])
    print(
        "\ngoals against xatlas (time <=; valid; charts <=; L2 <=; angle <= xatlas + "
        f"{ANGLE_SLACK}; utilization >= {MIN_UTILIZATION})"
    )
    print(f"{'mesh':{NAME_W}s} " + " ".join(f"{k:>11s}" for k in names) + "   missed")
    for r in seg:
        g = r["goals"]
        missed = [k for k in names if not g[k]]
        print(
            f"{r['mesh']:{NAME_W}s} "
            + " ".join(f"{'yes' if g[k] else 'NO':>11s}" for k in names)
            + f"   {len(missed)}"
        )
    every = {k: sum(r["goals"][k] for r in seg) for k in names}
    print(f"{'met on':{NAME_W}s} " + " ".join(f"{f'{v}/{len(seg)}':>11s}" for v in every.values()))


def _json_ready(value):
    if isinstance(value, dict):
        return {k: _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float):
        return round(value, 5) if np.isfinite(value) else None
    return value


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="only the small meshes (up to ~36k)")
    ap.add_argument("--large", action="store_true", help="add brain-300k")
    ap.add_argument("--huge", action="store_true", help="add brain-300k and brain-1m")
    ap.add_argument(
        "--only", nargs="+", default=None, metavar="NAME", help=f"meshes: {', '.join(MESHES)}"
    )
    ap.add_argument(
        "--repeat", type=int, default=1, metavar="N", help="runs per tool; the minimum is reported"
    )
    ap.add_argument("--out", default="benchmarks/results/atlas.json")
    args = ap.parse_args()
    if args.only and (unknown := sorted(set(args.only) - set(MESHES))):
        ap.error(f"unknown mesh {', '.join(unknown)}; known: {', '.join(MESHES)}")
    if args.repeat < 1:
        ap.error("--repeat must be at least 1")

    # one-off costs (numba kernels loaded from cache, lazy imports) would land on the first row
    t0 = time.perf_counter()
    V, F = brain_like_surface(500)
    run_segparam(V, F, "off")
    run_xatlas(V, F)
    print(f"warm-up (brain-500, both tools, not reported): {time.perf_counter() - t0:.1f} s")

    rows, skipped = [], []
    show_header()
    for name in selected(args.quick, args.large, args.huge, args.only):
        try:
            V, F = MESHES[name][1]()
        except Unavailable as e:
            print(f"{name:{NAME_W}s} skipped: {e}", flush=True)
            skipped.append({"mesh": name, "reason": str(e)})
            continue
        V = np.asarray(V, dtype=np.float64)
        F = np.asarray(F, dtype=np.int64)
        auto, reason = auto_policy(V, F, mesh_quality(V, F))
        runs = [(run_segparam, ("off",)), (run_xatlas, ())]
        if auto:
            runs.insert(1, (run_segparam, ("auto",)))
        mesh_rows = []
        for run, extra in runs:
            r = {"mesh": name, "faces": int(len(F)), "vertices": int(len(V))}
            r.update(run(V, F, *extra, repeat=args.repeat))
            mesh_rows.append(r)
        x_sec = mesh_rows[-1]["seconds"]
        for r in mesh_rows:
            if r["tool"].startswith("segparam"):
                r["ratio"] = r["seconds"] / x_sec
            if r["tool"] == "segparam":
                r["auto_would_remesh"] = bool(auto)
                r["auto_reason"] = reason
                r["goals"] = goals(r, mesh_rows[-1])
            show_row(r)
        rows.extend(mesh_rows)
    show_stages(rows)
    show_goals(rows)

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    result = {
        "benchmark": "atlas: segparam vs xatlas",
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
        "python": platform.python_version(),
        "resolution": RESOLUTION,
        "padding": PADDING,
        "repeat": args.repeat,
        "notes": (
            "ratio = segparam seconds / xatlas seconds on the same mesh in the same run; "
            "seconds = minimum over `repeat` runs (all in seconds_all), quality figures from "
            "the first run; stages = segparam's Atlas.timings of its fastest run"
        ),
        "rows": rows,
        "skipped": skipped,
    }
    out.write_text(json.dumps(_json_ready(result), indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
