"""Benchmark of the packing stage: raster vs. rect packer, and xatlas's own packing.

Chart sets are generated in code:

``synthetic-50``
    50 charts of a segmentation-like mix (discs, ellipses, L-shapes, stars, long strips) with
    log-uniform random sizes, random rotations and a random uv scale (the packer must undo it).
``tiny-300``
    300 small discs and squares plus 3 big charts.
``brain-<n> atlas``
    The charts segparam's own pipeline cuts from ``segparam.synthetic.brain_like_surface(n)``
    (n = 20k, 100k; default config with remeshing off, as in ``bench_atlas.py``), taken just
    before its pack stage: the real atlases the packer is made for (skip with ``--no-atlas``).
``xatlas-<mesh>``
    The charts xatlas itself cuts from a mesh built in code (an icosphere, a torus), taken with
    their xatlas uvs; xatlas's own packing of the same charts at the same resolution and padding
    is reported next to ours (utilization = uv triangle area over the square, for all rows).

Every set is packed into the whole square (``PackConfig(trim=False)``): this measures the
layout the packer finds, as in earlier sessions' tables; the pipeline's default cuts the texture
to the rows the layout uses when an eighth of the side or more would be empty.

Usage::

    python benchmarks/bench_pack.py [--out benchmarks/results/pack.json] [--resolutions 512 1024]
    python benchmarks/bench_pack.py --resolutions --no-atlas --brain-seeds 8 \
        --out benchmarks/results/pack_brains.json    # eight brain atlases, each rule alone
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from segparam import pack as pack_module
from segparam.pack import PackConfig, footprint_conflicts, pack_charts

# ----------------------------------------------------------------------------------------------
# chart generators (triangulated planar shapes)


def polar_chart(radius_fn, n_theta: int = 48, n_r: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Star-shaped chart: rings around the origin; radius_fn(theta) gives the outline."""
    theta = np.linspace(0, 2 * np.pi, n_theta, endpoint=False)
    rad = radius_fn(theta)
    t = np.arange(1, n_r + 1) / n_r
    ring = t[:, None, None] * np.stack([rad * np.cos(theta), rad * np.sin(theta)], -1)[None]
    uv = np.vstack([np.zeros((1, 2)), ring.reshape(-1, 2)])
    j = np.arange(n_theta)
    jn = (j + 1) % n_theta
    faces = [np.stack([np.zeros(n_theta, int), 1 + j, 1 + jn], 1)]
    for r in range(n_r - 1):
        a, b = 1 + r * n_theta, 1 + (r + 1) * n_theta
        faces.append(np.stack([a + j, b + j, b + jn], 1))
        faces.append(np.stack([a + j, b + jn, a + jn], 1))
    return uv, np.vstack(faces).astype(np.int64)


def grid_chart(nx: int, ny: int, keep=None) -> tuple[np.ndarray, np.ndarray]:
    """Chart made of unit grid cells (optionally a subset: keep(i, j) -> bool array)."""
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    i, j = i.ravel(), j.ravel()
    if keep is not None:
        sel = keep(i, j)
        i, j = i[sel], j[sel]
    vid = lambda a, b: a * (ny + 1) + b  # noqa: E731
    v00, v10, v11, v01 = vid(i, j), vid(i + 1, j), vid(i + 1, j + 1), vid(i, j + 1)
    F = np.vstack([np.stack([v00, v10, v11], 1), np.stack([v00, v11, v01], 1)])
    X, Y = np.meshgrid(np.arange(nx + 1.0), np.arange(ny + 1.0), indexing="ij")
    uv = np.stack([X.ravel(), Y.ravel()], 1)
    used, F = np.unique(F, return_inverse=True)
    return uv[used], F.reshape(-1, 3).astype(np.int64)


def shape_chart(kind: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    if kind == "disc":
        return polar_chart(lambda t: np.ones_like(t))
    if kind == "ellipse":
        e = rng.uniform(0.3, 0.8)
        return polar_chart(lambda t: 1 / np.sqrt(np.cos(t) ** 2 + (np.sin(t) / e) ** 2))
    if kind == "star":
        k, d = int(rng.integers(4, 8)), rng.uniform(0.15, 0.4)
        return polar_chart(lambda t: 1 + d * np.cos(k * t), n_theta=96)
    if kind == "blob":
        c = rng.normal(0, 0.12, 4)
        return polar_chart(lambda t: 1 + sum(c[m] * np.cos((m + 2) * t + m) for m in range(4)))
    if kind == "L":
        n = int(rng.integers(6, 12))
        return grid_chart(n, n, lambda i, j: (i < n // 2) | (j < n // 2))
    if kind == "strip":
        return grid_chart(int(rng.integers(12, 30)), 2)
    raise ValueError(kind)


def synthetic_set(n: int, seed: int) -> tuple[list, list, np.ndarray]:
    """n charts: a segmentation-like mix with random sizes, rotations and uv scales."""
    rng = np.random.default_rng(seed)
    kinds = ["disc", "ellipse", "star", "blob", "L", "strip"]
    probs = [0.15, 0.25, 0.1, 0.25, 0.15, 0.1]
    uvs, faces, areas = [], [], []
    for _ in range(n):
        uv, F = shape_chart(kinds[rng.choice(len(kinds), p=probs)], rng)
        a = rng.uniform(0, 2 * np.pi)
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        uv = uv @ R.T * rng.uniform(0.1, 10) + rng.normal(0, 5, 2)
        target = np.exp(rng.uniform(np.log(0.05), np.log(1.0)))
        uvs.append(uv)
        faces.append(F)
        areas.append(target)
    return uvs, faces, np.array(areas)


def tiny_set(n: int, seed: int) -> tuple[list, list, np.ndarray]:
    rng = np.random.default_rng(seed)
    uvs, faces, areas = [], [], []
    for i in range(n):
        uv, F = polar_chart(lambda t: np.ones_like(t), 12, 2) if i % 2 else grid_chart(2, 2)
        uvs.append(uv * rng.uniform(0.5, 2))
        faces.append(F)
        areas.append(rng.uniform(0.5, 1.5))
    for _ in range(3):
        uv, F = polar_chart(lambda t: np.ones_like(t))
        uvs.append(uv)
        faces.append(F)
        areas.append(40.0)
    return uvs, faces, np.array(areas)


def _area(uv: np.ndarray, F: np.ndarray) -> float:
    a, b, c = uv[F[:, 0]], uv[F[:, 1]], uv[F[:, 2]]
    d1, d2 = b - a, c - a
    return float(np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]).sum() / 2)


# ----------------------------------------------------------------------------------------------
# segparam's own charts


def atlas_set(n_faces: int, seed: int = 0) -> tuple[list, list, np.ndarray]:
    """The charts of the default pipeline (remeshing off) on a brain-like surface, unpacked."""
    from segparam.clean import clean
    from segparam.mesh import face_areas
    from segparam.pipeline import PipelineConfig
    from segparam.remesh import remesh
    from segparam.segment import segment
    from segparam.split import parameterize_charts
    from segparam.synthetic import brain_like_surface

    cfg = PipelineConfig().replace(remesh={"mode": "off"})
    cleaned = clean(*brain_like_surface(n_faces, seed=seed))
    mesh = remesh(cleaned.V, cleaned.F, config=cfg.remesh)
    seg = segment(mesh.V, mesh.F, config=cfg.segment, seed=0)
    charts = parameterize_charts(mesh.V, mesh.F, seg.labels, config=cfg.split, seed=0).charts
    area = face_areas(mesh.V, mesh.F)
    return (
        [c.uv for c in charts],
        [c.local_F for c in charts],
        np.array([float(area[c.faces].sum()) for c in charts]),
    )


# ----------------------------------------------------------------------------------------------
# xatlas charts


def icosphere(subdiv: int = 3) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdiv)
    return np.asarray(m.vertices), np.asarray(m.faces)


def torus(n_major: int = 64, n_minor: int = 24) -> tuple[np.ndarray, np.ndarray]:
    u = np.linspace(0, 2 * np.pi, n_major, endpoint=False)
    v = np.linspace(0, 2 * np.pi, n_minor, endpoint=False)
    U, W = np.meshgrid(u, v, indexing="ij")
    V = np.stack(
        [(1 + 0.35 * np.cos(W)) * np.cos(U), (1 + 0.35 * np.cos(W)) * np.sin(U), 0.35 * np.sin(W)],
        -1,
    ).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    a = i * n_minor + j
    b = ((i + 1) % n_major) * n_minor + j
    c = ((i + 1) % n_major) * n_minor + (j + 1) % n_minor
    d = i * n_minor + (j + 1) % n_minor
    F = np.vstack([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return V, F


def xatlas_charts(V: np.ndarray, F: np.ndarray, resolution: int, padding: int):
    """Charts cut and packed by xatlas at (resolution, padding).

    Returns the per-chart uvs, faces and 3-D areas, xatlas's utilization (uv triangle area over
    the square of the atlas' longer side) and its time.
    """
    import xatlas

    atlas = xatlas.Atlas()
    atlas.add_mesh(V.astype(np.float32), F.astype(np.uint32))
    po = xatlas.PackOptions()
    po.resolution = resolution
    po.padding = padding
    t0 = time.perf_counter()
    atlas.generate(pack_options=po)
    dt = time.perf_counter() - t0
    vmap, idx, uv = atlas.get_mesh(0)
    uv = uv.astype(np.float64)
    idx = idx.astype(np.int64)
    uvs, faces, areas = [], [], []
    for c in range(atlas.get_mesh_chart_count(0)):
        fids = np.asarray(atlas.get_mesh_chart(0, c).faces, dtype=np.int64)
        tri = idx[fids]
        used, local = np.unique(tri, return_inverse=True)
        uvs.append(uv[used])
        faces.append(local.reshape(-1, 3))
        P = V[vmap[tri]]
        areas.append(
            float(np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1).sum() / 2)
        )
    w, h = atlas.width, atlas.height
    side = max(w, h)
    util = sum(_area(u * [w / side, h / side], f) for u, f in zip(uvs, faces, strict=True))
    return uvs, faces, np.array(areas), util, dt, (w, h), float(atlas.utilization)


# ----------------------------------------------------------------------------------------------


def run_one(name, uvs, faces, areas, method, resolution, padding, verify):
    """Pack one set. `method` "raster-rest" / "raster-holes" is the raster packer with that one
    placement rule only (the packer before the "rest" rule was "raster-holes")."""
    cfg = PackConfig(
        resolution=resolution, padding=padding, method=method.split("-")[0], trim=False
    )
    rules = pack_module._RULE_ORDER
    if "-" in method:
        pack_module._RULE_ORDER = (method.split("-")[1],)
    try:
        t0 = time.perf_counter()
        res = pack_charts(uvs, faces, areas, config=cfg)
        dt = time.perf_counter() - t0
    finally:
        pack_module._RULE_ORDER = rules
    row = {
        "set": name,
        "method": method,
        "charts": len(uvs),
        "resolution": resolution,
        "padding": padding,
        "utilization": round(res.utilization, 4),
        "seconds": round(dt, 3),
    }
    if verify:
        row["conflicts"] = footprint_conflicts(
            res.uvs, faces, resolution=resolution, padding=padding
        )
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="benchmarks/results/pack.json")
    ap.add_argument("--resolutions", type=int, nargs="*", default=[512, 1024, 2048])
    ap.add_argument("--padding", type=int, default=2)
    ap.add_argument("--no-verify", action="store_true", help="skip the footprint check")
    ap.add_argument("--no-atlas", action="store_true", help="skip the pipeline's brain charts")
    ap.add_argument(
        "--brain-seeds",
        type=int,
        default=0,
        help="also pack the atlases of N brain-like 100k surfaces (seeds 0..N-1) at 1024, with "
        "both placement rules and with each rule alone",
    )
    args = ap.parse_args()

    sets = {
        "synthetic-50 seed0": synthetic_set(50, 0),
        "synthetic-50 seed1": synthetic_set(50, 1),
        "tiny-300": tiny_set(300, 2),
    }
    if not args.no_atlas:
        sets["brain-20k atlas"] = atlas_set(20_000)
        sets["brain-100k atlas"] = atlas_set(100_000)
    meshes = {"xatlas-icosphere": icosphere(3), "xatlas-torus": torus()}
    rows = []
    # one untimed packing first: the packer's compiled kernels load (or, after installing,
    # compile) on first use, which is not what the rows measure
    warm = sets["synthetic-50 seed0"]
    pack_charts(warm[0][:4], warm[1][:4], warm[2][:4])
    header = (
        f"{'set':22s} {'method':8s} {'res':>5s} {'charts':>6s} {'util':>7s} {'sec':>7s} "
        f"{'conf':>5s}"
    )
    print(header)
    print("-" * len(header))

    def show(r):
        print(
            f"{r['set']:22s} {r['method']:8s} {r['resolution']:5d} {r['charts']:6d} "
            f"{r['utilization']:7.4f} {r['seconds']:7.3f} {str(r.get('conflicts', '')):>5s}"
        )

    for res in args.resolutions:
        for name, (uvs, faces, areas) in sets.items():
            for method in ("raster", "rect"):
                r = run_one(name, uvs, faces, areas, method, res, args.padding, not args.no_verify)
                rows.append(r)
                show(r)
        for name, (V, F) in meshes.items():
            uvs, faces, areas, xu, xdt, wh, xtex = xatlas_charts(V, F, res, args.padding)
            r = {
                "set": name,
                "method": "xatlas",
                "charts": len(uvs),
                "resolution": res,
                "padding": args.padding,
                "utilization": round(xu, 4),
                "seconds": round(xdt, 3),
                "xatlas_size": list(wh),
                "xatlas_texel_utilization": round(xtex, 4),
            }
            rows.append(r)
            show(r)
            for method in ("raster", "rect"):
                r = run_one(name, uvs, faces, areas, method, res, args.padding, not args.no_verify)
                rows.append(r)
                show(r)
    by_method: dict[str, list[float]] = {}
    for seed in range(args.brain_seeds):
        uvs, faces, areas = atlas_set(100_000, seed)
        for method in ("raster", "raster-rest", "raster-holes"):
            r = run_one(f"brain-100k s{seed}", uvs, faces, areas, method, 1024, args.padding, False)
            rows.append(r)
            show(r)
            by_method.setdefault(method, []).append(r["utilization"])
    for method, u in by_method.items():
        print(
            f"brain-100k seeds 0-{args.brain_seeds - 1}, {method}: mean {np.mean(u):.4f}, "
            f"min {np.min(u):.4f}, max {np.max(u):.4f}"
        )
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"python": platform.python_version(), "machine": platform.machine()}
    out.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
