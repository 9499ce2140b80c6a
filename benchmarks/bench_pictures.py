"""The cost of the pictures: preview, bakes, flatmap, viewer, flat GIfTI, on atlases of brains.

For each mesh the atlas is built once (``pipelines/default.toml``, seed 0; its wall seconds are
printed for scale, with xatlas's on the same mesh side by side when xatlas is installed), then
each picture is made ``--repeat`` times and the minimum wall time kept:

``preview``
    ``render_preview`` with its defaults (4 views of 256 px, checker texture, seams). It runs on
    every ``segparam atlas``; its budget is 0.15 s at 20k faces.
``curvature``
    ``bake_named(atlas, "curvature")`` at the atlas resolution (mean curvature, bake, colours).
``flatmap``
    ``render_flatmap`` of the curvature (no data layer) at the atlas resolution.
``viewer``
    ``viewer_html`` with the checker and the curvature texture as PNG bytes (as the atlas
    writer passes them: encoded once for their own files).
``flat.gii``
    ``write_flat_gifti`` with the curvature as a data array.

Before the table every picture is made once on ``brain_like_surface(500)`` so that the numba
kernels' loading (compiled on the first run after installing, then cached) lands on no row.

Meshes: ``brain-2k``, ``brain-20k`` (``segparam.synthetic.brain_like_surface``); ``--quick``
runs brain-20k only. Output: a table on stdout and ``benchmarks/results/bench_pictures.json``.

    PYTHONPATH=$PWD python benchmarks/bench_pictures.py [--quick] [--repeat 5]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from segparam.bake import bake_named
from segparam.export import _checker_pixels, _png_bytes
from segparam.flatmap import render_flatmap, write_flat_gifti
from segparam.pipeline import build_atlas, load_config
from segparam.render import render_preview
from segparam.synthetic import brain_like_surface
from segparam.viewer import viewer_html

ROOT = Path(__file__).resolve().parent.parent


def _best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def _xatlas_seconds(V, F) -> float | None:
    try:
        import xatlas
    except ImportError:
        return None
    t = time.perf_counter()
    atlas = xatlas.Atlas()
    atlas.add_mesh(V.astype(np.float32), F.astype(np.uint32))
    po = xatlas.PackOptions()
    po.resolution, po.padding = 1024, 2
    atlas.generate(pack_options=po)
    return time.perf_counter() - t


def _pictures(atlas, repeat: int, folder: Path) -> dict[str, float]:
    checker = _png_bytes(_checker_pixels(1024, 16))
    curv = bake_named(atlas, "curvature")
    curv_png = _png_bytes(curv.rgb)
    uv_values = curv.values[atlas.uv_vertex]
    return {
        "preview": _best(lambda: render_preview(atlas.V, atlas.F, atlas.uv, atlas.uv_F), repeat),
        "curvature": _best(lambda: bake_named(atlas, "curvature"), repeat),
        "flatmap": _best(
            lambda: render_flatmap(
                atlas.V, atlas.F, atlas.uv, atlas.uv_F, resolution=atlas.packing.size
            ),
            repeat,
        ),
        "viewer": _best(
            lambda: viewer_html(
                atlas.V,
                atlas.F,
                atlas.uv,
                atlas.uv_F,
                {"checker": checker, "curvature": curv_png},
            ),
            repeat,
        ),
        "flat.gii": _best(
            lambda: write_flat_gifti(
                folder / "x_flat.gii", atlas.uv, atlas.uv_F, {"curvature": uv_values}
            ),
            repeat,
        ),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="brain-20k only")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    config = load_config(ROOT / "pipelines" / "default.toml")
    meshes = {"brain-20k": 20_000} if args.quick else {"brain-2k": 2_000, "brain-20k": 20_000}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        warm = build_atlas(*brain_like_surface(500), config, seed=0)
        _pictures(warm, 1, Path(tmp))
        for name, n in meshes.items():
            V, F = brain_like_surface(n)
            t = time.perf_counter()
            atlas = build_atlas(V, F, config, seed=0)
            seconds = time.perf_counter() - t
            row = {
                "mesh": name,
                "faces": len(atlas.F),
                "resolution": atlas.packing.resolution,
                "atlas": seconds,
                "xatlas": _xatlas_seconds(V, F),
                **_pictures(atlas, args.repeat, Path(tmp)),
            }
            rows.append(row)
    cols = ["mesh", "faces", "resolution", "atlas", "xatlas", "preview", "curvature", "flatmap"]
    cols += ["viewer", "flat.gii"]
    print(" | ".join(cols))
    for r in rows:
        cells = [f"{r[c]:.3f}" if isinstance(r[c], float) else str(r[c]) for c in cols]
        print(" | ".join(cells))
    out = ROOT / "benchmarks" / "results" / "bench_pictures.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"repeat": args.repeat, "rows": rows}, indent=1) + "\n")
    print(f"wrote {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
