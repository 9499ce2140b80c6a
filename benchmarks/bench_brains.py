"""How folded are the synthetic brains next to a real cortex (issue 16)?

Prints, for fsaverage5's left pial and white surfaces (the copies bundled in the nilearn wheel,
read with ``segparam.io.load_mesh``; skipped with a note without nilearn) and for synthetic
surfaces from :func:`segparam.synthetic.brain_like_surface`, the figures of
:func:`segparam.synthetic.surface_statistics`: surface area / convex hull area, integrated
absolute Gaussian curvature / 4 pi, 1st / 5th percentiles of the smallest triangle angle, vertex
valence standard deviation, and the seconds the generator took. Writes the rows as JSON.

With ``--pipeline SIZES`` it runs instead the whole pipeline (``build_atlas``, seed 0) on the
default hemispheres of those face counts, with ``pipelines/default.toml`` and
``pipelines/brain.toml``, and xatlas side by side (``bench_atlas.run_xatlas``: its defaults,
1024 texels, padding 2); per row: seconds, charts, bijective charts, faces in and out, flipped
triangles, utilization, distortion, and whether a second run gave the same bytes (smallest size).

Usage::

    python benchmarks/bench_brains.py [--sizes 5000,20000,80000,320000] [--seed 0]
                                      [--pipeline 20000,160000,300000]
                                      [--out benchmarks/results/brains.json]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import time
from pathlib import Path

import numpy as np

from segparam.io import load_mesh
from segparam.synthetic import brain_like_surface, surface_statistics

COLUMNS = (
    ("area_over_hull", "area/hull", "{:.2f}"),
    ("abs_curvature", "|K|/4pi", "{:.1f}"),
    ("min_angle_p1", "minang p1", "{:.1f}"),
    ("min_angle_p5", "minang p5", "{:.1f}"),
    ("valence_std", "val std", "{:.2f}"),
    ("seconds", "seconds", "{:.2f}"),
)


def fsaverage5(surface: str, hemi: str = "left") -> tuple[np.ndarray, np.ndarray] | None:
    """fsaverage5's ``pial`` or ``white`` surface of ``hemi`` from the nilearn wheel, or None."""
    spec = importlib.util.find_spec("nilearn")  # locates the package without importing it
    if spec is None or spec.origin is None:
        return None
    folder = Path(spec.origin).parent / "datasets" / "data" / "fsaverage5"
    for name in (f"{surface}_{hemi}.gii.gz", f"{surface}.{hemi}.gii.gz"):
        if (folder / name).is_file():
            return load_mesh(folder / name)
    return None


def synthetic_rows(sizes: list[int], seed: int) -> list[tuple[str, dict]]:
    """(name, keyword arguments of brain_like_surface) for every synthetic row."""
    rows = []
    for n in sizes:
        rows.append((f"cortex pial, {n}", {"n_faces": n}))
        rows.append((f"cortex white, {n}", {"n_faces": n, "surface": "white"}))
        rows.append(
            (f"cortex icosahedral pial, {n}", {"n_faces": n, "connectivity": "icosahedral"})
        )
        rows.append((f"gentle folding 1, {n}", {"n_faces": n, "style": "gentle"}))
        rows.append((f"gentle folding 3, {n}", {"n_faces": n, "style": "gentle", "folding": 3.0}))
    return [(name, {**kw, "seed": seed}) for name, kw in rows]


def pipeline_rows(sizes: list[int], seed: int) -> list[dict]:
    """The whole pipeline (default and brain configs) and xatlas on default hemispheres."""
    import sys

    from segparam.pipeline import build_atlas, load_config

    here = Path(__file__).resolve().parent
    sys.path.insert(0, str(here))
    from bench_atlas import atlas_measures, run_xatlas

    rows = []
    for n in sizes:
        V, F = brain_like_surface(n, seed=seed)
        for name in ("default", "brain"):
            cfg = load_config(str(here.parent / "pipelines" / f"{name}.toml"))
            t = time.perf_counter()
            atlas = build_atlas(V, F, cfg, seed=0)
            seconds = time.perf_counter() - t
            report = atlas.report()["atlas"]
            row = {"faces": len(F), "tool": f"segparam ({name})", "seconds": seconds}
            row.update(atlas_measures(atlas))
            row["bijective_charts"] = int(report["bijective_charts"])
            row["faces_out"] = int(len(atlas.uv_F))
            row["stages"] = {k: round(v, 3) for k, v in atlas.timings.items()}
            if n == min(sizes):
                again = build_atlas(V, F, cfg, seed=0)
                row["deterministic"] = bool(
                    again.uv.tobytes() == atlas.uv.tobytes()
                    and again.uv_F.tobytes() == atlas.uv_F.tobytes()
                )
            rows.append(row)
            print(_pipeline_line(row), flush=True)
        row = {"faces": len(F), **run_xatlas(V, F)}
        rows.append(row)
        print(_pipeline_line(row), flush=True)
    return rows


def _pipeline_line(r: dict) -> str:
    cells = [
        f"{r['faces']:>8}",
        f"{r['tool']:<19}",
        f"{r['seconds']:8.2f} s",
        f"charts {r['charts']:>4}",
        f"bijective {r.get('bijective_charts', '-')!s:>4}",
        f"faces out {r.get('faces_out', '-')!s:>7}",
        f"flipped {r.get('flipped', '-')!s:>3}",
        f"util {r['utilization']:.3f}",
        f"L2 {r['l2_stretch']:.3f}",
        f"s1/s2 {r['angle_distortion']:.3f}",
    ]
    if "deterministic" in r:
        cells.append(f"deterministic {r['deterministic']}")
    if "stages" in r:
        cells.append(" ".join(f"{k} {v:.2f}" for k, v in r["stages"].items()))
    return "  ".join(cells)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", default="5000,20000,80000,320000")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--pipeline", default=None, help="face counts: run the pipeline instead")
    p.add_argument("--out", default="benchmarks/results/brains.json")
    args = p.parse_args(argv)
    if args.pipeline:
        rows = pipeline_rows([int(s) for s in args.pipeline.split(",") if s], args.seed)
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        command = f"python benchmarks/bench_brains.py --pipeline {args.pipeline}"
        out.write_text(json.dumps({"command": command, "rows": rows}, indent=1, default=str))
        print(f"wrote {out}")
        return 0
    sizes = [int(s) for s in args.sizes.split(",") if s]
    results = []
    for surface in ("pial", "white"):
        mesh = fsaverage5(surface)
        if mesh is None:
            print(f"fsaverage5 {surface}: skipped (nilearn or its bundled surface missing)")
            continue
        results.append({"name": f"fsaverage5 {surface}", **surface_statistics(*mesh)})
    for name, kwargs in synthetic_rows(sizes, args.seed):
        t = time.perf_counter()
        V, F = brain_like_surface(**kwargs)
        seconds = time.perf_counter() - t
        results.append(
            {"name": name, "kwargs": kwargs, **surface_statistics(V, F), "seconds": seconds}
        )
    width = max(len(r["name"]) for r in results)
    print(f"{'surface':<{width}} {'faces':>8} " + " ".join(f"{h:>10}" for _, h, _ in COLUMNS))
    for r in results:
        cells = [fmt.format(r[k]) if k in r else "-" for k, _, fmt in COLUMNS]
        print(f"{r['name']:<{width}} {r['faces']:>8} " + " ".join(f"{c:>10}" for c in cells))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        json.dumps({"command": "python benchmarks/bench_brains.py", "rows": results}, indent=1)
    )
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
