"""Charts against stretch: segparam's stretch target swept, with xatlas's point beside it.

The knob is ``[split] max_stretch`` (:class:`segparam.split.SplitConfig`): a bijective chart
whose L2 stretch (Sander's) exceeds it is bisected along its Fiedler vector and both halves
mapped again. Lower targets give more charts and less stretch. Every other setting is the
default (``[split] refine`` and ``angle_weight`` from ``--refine`` / ``--angle-weight``). For each
mesh and target this prints and records charts, utilization, L2 stretch, angle distortion, seam
length / sqrt(area) and wall seconds (the figures of ``benchmarks/bench_atlas.py``, computed the
same way from the atlas' uvs) and the parameterize stage's seconds, then a row with the
previous defaults (``refine="arap"``, no target: ``arap``), then xatlas's row (defaults, 1024
texels, padding 2), and draws the curve per mesh: charts against L2 stretch and against angle
distortion, the previous defaults as a grey square, xatlas as a red cross.

Meshes (``--only`` picks some): ``brain-20k``, ``fsaverage5-pial``, ``icosphere``, ``torus``
(built as in ``bench_atlas.py``). Remeshing off, seed 0.

Usage::

    python benchmarks/bench_quality.py [--only NAME ...] [--targets none 1.02 1.01 ...]
        [--refine slim|arap|none] [--angle-weight W] [--out benchmarks/results/quality.json]
        [--plot benchmarks/results/quality.png]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

sys.path.insert(0, str(Path(__file__).parent))
import bench_atlas as B  # noqa: E402  (the meshes and measures, shared)

from segparam.parameterize import REFINES  # noqa: E402
from segparam.pipeline import PipelineConfig, build_atlas  # noqa: E402
from segparam.split import SplitConfig  # noqa: E402

MESHES = ("brain-20k", "fsaverage5-pial", "icosphere", "torus")
TARGETS = ("none", "1.05", "1.02", "1.01", "1.005")


def run(V: np.ndarray, F: np.ndarray, target: float | None, split: dict, tool="segparam") -> dict:
    cfg = PipelineConfig().replace(remesh={"mode": "off"}, split={"max_stretch": target, **split})
    t0 = time.perf_counter()
    a = build_atlas(V, F, cfg, seed=0)
    row = {"tool": tool, "target": target, "seconds": time.perf_counter() - t0}
    row.update(B.atlas_measures(a))
    row["stages"] = {k: round(v, 3) for k, v in a.timings.items()}
    return row


def show(r: dict) -> None:
    t = r["tool"] if r["tool"] != "segparam" else f"{r['target'] or 'none'}"
    param = r.get("stages", {}).get("parameterize")
    print(
        f"{r['mesh']:16s} {t:>7s} {r['charts']:6d} {r['utilization']:6.3f} {r['l2_stretch']:7.4f} "
        f"{r['angle_distortion']:7.4f} {r['seam']:7.2f} {r['seconds']:7.2f} "
        f"{'-' if param is None else format(param, '.2f'):>6s} "
        f"{'yes' if r['flipped'] == 0 and r['overlap_texels'] == 0 else 'no':>5s}",
        flush=True,
    )


def plot(rows: list[dict], path: Path) -> None:
    """One panel pair per mesh: charts (x, log scale) against L2 and against angle (y)."""
    meshes = list(dict.fromkeys(r["mesh"] for r in rows))
    W, H, pad = 420, 260, 48
    img = Image.new("RGB", (2 * W, H * len(meshes)), "white")
    d = ImageDraw.Draw(img)
    for i, mesh in enumerate(meshes):
        seg = sorted((r for r in rows if r["mesh"] == mesh and r["tool"] == "segparam"),
                     key=lambda r: r["charts"])  # fmt: skip
        xa = [r for r in rows if r["mesh"] == mesh and r["tool"] == "xatlas"]
        old = [r for r in rows if r["mesh"] == mesh and r["tool"] == "arap"]
        allr = seg + xa + old
        xs = np.log10([max(r["charts"], 1) for r in allr])
        x0, x1 = xs.min() - 0.1, xs.max() + 0.1
        for j, key in enumerate(("l2_stretch", "angle_distortion")):
            ox, oy = j * W, i * H
            ys = [r[key] for r in allr]
            y0, y1 = min(ys), max(ys)
            y0, y1 = y0 - 0.1 * (y1 - y0 + 1e-3), y1 + 0.1 * (y1 - y0 + 1e-3)

            def px(c, y, ox=ox, oy=oy, y0=y0, y1=y1, x0=x0, x1=x1):
                u = ox + pad + (np.log10(max(c, 1)) - x0) / (x1 - x0) * (W - 2 * pad)
                v = oy + H - pad - (y - y0) / (y1 - y0) * (H - 2 * pad)
                return float(u), float(v)

            d.rectangle([ox + pad, oy + pad, ox + W - pad, oy + H - pad], outline="black")
            d.text((ox + pad, oy + 8), f"{mesh}: {key} vs charts (log)", fill="black")
            d.text((ox + 4, oy + pad - 12), f"{y1:.3f}", fill="black")
            d.text((ox + 4, oy + H - pad), f"{y0:.3f}", fill="black")
            d.text((ox + pad, oy + H - pad + 14), f"{10**x0:.0f}", fill="black")
            d.text((ox + W - pad - 30, oy + H - pad + 14), f"{10**x1:.0f}", fill="black")
            pts = [px(r["charts"], r[key]) for r in seg]
            if len(pts) > 1:
                d.line(pts, fill=(30, 90, 200), width=2)
            labels: dict[tuple, list[str]] = {}  # targets that give the same point share a label
            for r, p in zip(seg, pts, strict=True):
                labels.setdefault((round(p[0]), round(p[1])), []).append(f"{r['target'] or 'none'}")
            for (u, v), names in labels.items():
                d.ellipse([u - 3, v - 3, u + 3, v + 3], fill=(30, 90, 200))
                d.text((u + 4, v - 12), ",".join(names), fill=(30, 90, 200))
            for r in old:
                u, v = px(r["charts"], r[key])
                d.rectangle([u - 4, v - 4, u + 4, v + 4], outline=(110, 110, 110), width=2)
                d.text((u + 6, v + 2), "arap", fill=(110, 110, 110))
            for r in xa:
                u, v = px(r["charts"], r[key])
                d.line([u - 5, v - 5, u + 5, v + 5], fill=(200, 40, 40), width=2)
                d.line([u - 5, v + 5, u + 5, v - 5], fill=(200, 40, 40), width=2)
                d.text((u + 6, v + 2), "xatlas", fill=(200, 40, 40))
    path.parent.mkdir(parents=True, exist_ok=True)
    img.save(path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", default=None, metavar="NAME", choices=MESHES)
    ap.add_argument("--targets", nargs="+", default=list(TARGETS), metavar="X")
    ap.add_argument("--refine", default=SplitConfig.refine, choices=REFINES)
    ap.add_argument("--angle-weight", type=float, default=SplitConfig.angle_weight)
    ap.add_argument("--out", default="benchmarks/results/quality.json")
    ap.add_argument("--plot", default="benchmarks/results/quality.png")
    args = ap.parse_args()
    targets = [None if t == "none" else float(t) for t in args.targets]
    split = {"refine": args.refine, "angle_weight": args.angle_weight}
    V, F = B.brain_like_surface(500)  # warm-up: numba kernels, lazy imports
    run(V, F, None, split)
    print(f"{'mesh':16s} {'target':>7s} {'charts':>6s} {'util':>6s} {'L2':>7s} {'angle':>7s} "
          f"{'seam':>7s} {'sec':>7s} {'param':>6s} {'valid':>5s}")  # fmt: skip
    rows = []
    for name in args.only or MESHES:
        try:
            V, F = B.MESHES[name][1]()
        except B.Unavailable as e:
            print(f"{name:16s} skipped: {e}")
            continue
        V, F = np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64)
        for target in targets:
            r = {"mesh": name, "faces": len(F)}
            r.update(run(V, F, target, split))
            show(r)
            rows.append(r)
        r = {"mesh": name, "faces": len(F)}
        r.update(run(V, F, None, {"refine": "arap"}, tool="arap"))
        show(r)
        rows.append(r)
        r = {"mesh": name, "faces": len(F)}
        r.update(B.run_xatlas(V, F))
        show(r)
        rows.append(r)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    result = {
        "benchmark": "quality: charts vs stretch, [split] max_stretch swept, xatlas beside",
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
        "split": split,
        "rows": rows,
    }
    out.write_text(json.dumps(B._json_ready(result), indent=2) + "\n")
    plot(rows, Path(args.plot))
    print(f"wrote {out} and {args.plot}")


if __name__ == "__main__":
    main()
