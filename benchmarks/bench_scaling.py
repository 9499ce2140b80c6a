"""Scaling of the full pipeline on synthetic brain-like surfaces (10k to 1M faces).

Each size runs in a fresh subprocess (so that peak RSS is that size's own) with a timeout; the
worker prints a line per finished stage on stderr, so a run that times out still tells how far
it got. Reported per size: seconds per stage (``Atlas.timings``) and in total, the time to build
the mesh, peak RSS (``ru_maxrss``, KB), charts and utilization.

Usage::

    python benchmarks/bench_scaling.py [--sizes 10000 100000 1000000] [--timeout 1200]
        [--no-remesh] [--out benchmarks/results/scaling.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

STAGES = ("clean", "remesh", "segment", "parameterize", "pack")


def worker(n_faces: int, seed: int, no_remesh: bool) -> None:
    """Build one atlas; stage lines go to stderr, the result as one JSON line to stdout."""
    import resource

    from segparam.pipeline import PipelineConfig, build_atlas
    from segparam.synthetic import brain_like_surface

    t_start = time.perf_counter()

    def note(stage: str, done: int, total: int) -> None:
        if stage != "parameterize" or done == total or done % 50 == 0:
            print(
                f"STAGE {stage} {done} {total} {time.perf_counter() - t_start:.2f}",
                file=sys.stderr,
                flush=True,
            )

    t = time.perf_counter()
    V, F = brain_like_surface(n_faces, seed=seed)
    t_mesh = time.perf_counter() - t
    note("mesh", 1, 1)
    cfg = PipelineConfig()
    if no_remesh:
        cfg = cfg.replace(remesh={"mode": "off"})
    t = time.perf_counter()
    atlas = build_atlas(V, F, cfg, seed=seed, progress=note)
    total = time.perf_counter() - t
    row = {
        "faces": int(len(F)),
        "vertices": int(len(V)),
        "mesh_seconds": round(t_mesh, 3),
        "stages": {k: round(v, 3) for k, v in atlas.timings.items()},
        "total_seconds": round(total, 3),
        "peak_rss_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
        "remeshed": bool(atlas.remeshing.remeshed),
        "charts": atlas.n_charts,
        "utilization": round(float(atlas.packing.utilization), 4),
        "status": "ok",
    }
    print(json.dumps(row), flush=True)


def _vm_hwm_kb(pid: int) -> int | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1])
    except OSError:
        pass
    return None


def run_size(n_faces: int, seed: int, no_remesh: bool, timeout: float, logdir: Path) -> dict:
    cmd = [sys.executable, __file__, "--worker", str(n_faces), "--seed", str(seed)]
    if no_remesh:
        cmd.append("--no-remesh")
    log_path = logdir / f"scaling_{n_faces}.log"
    t0 = time.perf_counter()
    with open(log_path, "w") as err:
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err, text=True)
        hwm = None
        out = ""
        while True:
            try:
                out, _ = proc.communicate(timeout=5)
                break
            except subprocess.TimeoutExpired:
                hwm = _vm_hwm_kb(proc.pid) or hwm
                if time.perf_counter() - t0 > timeout:
                    proc.kill()
                    proc.communicate()
                    break
    wall = time.perf_counter() - t0
    lines = [ln.split() for ln in log_path.read_text().splitlines() if ln.startswith("STAGE ")]
    if proc.returncode == 0 and out.strip():
        row = json.loads(out.strip().splitlines()[-1])
        row["wall_seconds"] = round(wall, 2)
        return row
    # timeout or crash: reconstruct what finished from the stage lines
    done, stamps, last = {}, {"mesh": 0.0}, 0.0
    for _, stage, k, total, t in lines:
        if k == total:
            stamps[stage] = float(t)
            if stage in STAGES:
                done[stage] = round(float(t) - last, 2)
            last = float(t)
    running = next((s for s in STAGES if s not in done), None)
    progress = [ln for ln in lines if ln[1] == running]
    return {
        "faces": n_faces,
        "status": "timeout" if wall > timeout else f"failed (exit {proc.returncode})",
        "wall_seconds": round(wall, 2),
        "stages_done": done,
        "running_stage": running,
        "running_stage_progress": f"{progress[-1][2]}/{progress[-1][3]}" if progress else None,
        "running_stage_seconds": round(wall - last, 1),
        "peak_rss_kb": hwm,
        "log_tail": [" ".join(ln) for ln in lines[-5:]],
    }


def show_header() -> None:
    print(
        f"{'faces':>8s} {'mesh':>6s} "
        + " ".join(f"{s[:7]:>7s}" for s in STAGES)
        + f" {'total':>7s} {'RSS MB':>7s} {'charts':>6s} {'util':>6s}  status"
    )


def show_row(r: dict) -> None:
    if r["status"] == "ok":
        st = r["stages"]
        print(
            f"{r['faces']:8d} {r['mesh_seconds']:6.1f} "
            + " ".join(f"{st.get(s, float('nan')):7.1f}" for s in STAGES)
            + f" {r['total_seconds']:7.1f} {r['peak_rss_kb'] / 1024:7.0f} {r['charts']:6d}"
            f" {r['utilization']:6.3f}  ok"
        )
    else:
        st = r["stages_done"]
        rss = r["peak_rss_kb"] / 1024 if r["peak_rss_kb"] else float("nan")
        print(
            f"{r['faces']:8d} {'':>6s} "
            + " ".join(f"{st[s]:7.1f}" if s in st else f"{'-':>7s}" for s in STAGES)
            + f" {r['wall_seconds']:7.1f} {rss:7.0f} {'-':>6s} {'-':>6s}  {r['status']} in "
            f"{r['running_stage']} ({r['running_stage_progress'] or ''}, "
            f"{r['running_stage_seconds']} s)"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    ap.add_argument("--timeout", type=float, default=1200.0, help="seconds per size")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-remesh", action="store_true", help="remesh mode 'off' (default: auto)")
    ap.add_argument("--out", default="benchmarks/results/scaling.json")
    ap.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker is not None:
        worker(args.worker, args.seed, args.no_remesh)
        return

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    logdir = Path(tempfile.mkdtemp(prefix="segparam-scaling-"))
    rows = []
    show_header()
    for n in args.sizes:
        rows.append(run_size(n, args.seed, args.no_remesh, args.timeout, logdir))
        show_row(rows[-1])
    result = {
        "benchmark": "scaling",
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
        "python": platform.python_version(),
        "seed": args.seed,
        "remesh": "off" if args.no_remesh else "auto",
        "timeout": args.timeout,
        "rows": rows,
    }
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
