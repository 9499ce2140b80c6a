"""Benchmark of the split stage's solves: how much of the solver's time goes to pieces that miss
the targets, and how well the cuts before a solve (``split._caps``) tell those pieces.

Every solver call of ``build_atlas`` (remeshing off, ``[split] n_jobs = 1`` so that every call
runs in this process, seed 0) is recorded piece by piece: faces, whether the piece met the
stage's targets (bijective and ``split._within_targets``), the call's time shared among its
pieces by faces, the piece's inner curvature and the stretch of its conformal flattening of
least area distortion (``split._conformal_stretch``; disks only).

Two runs per mesh:

``with cuts``
    the defaults: the share of the solver's time spent on pieces that fail.
``without cuts``
    ``CAP_NET`` and ``CONFORMAL_STRETCH_CUT`` off (session 22's one-sign caps stay): every piece
    those two rules cut is solved, so that their precision can be read off: per threshold, the
    pieces at or above it that met the targets (they would be cut wrongly) and the share of the
    failing faces they hold.

Usage::

    python benchmarks/bench_split.py [--only NAME ...] [--out benchmarks/results/split.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_atlas import MESHES  # noqa: E402

import segparam.split as split  # noqa: E402
from segparam.mesh import inner_curvature, label_topology  # noqa: E402
from segparam.pipeline import PipelineConfig, build_atlas  # noqa: E402

DEFAULT = [
    "bone-scan", "cow", "airplane", "bunny-holes", "fsaverage5-pial", "brain-20k", "brain-2k",
    "brain-2k-s1", "brain-2k-s2", "spheres-300-jitter", "wavy-sheet",
]  # fmt: skip
THRESHOLDS = (1.04, 1.05, 1.06, 1.07, 1.08, 1.10)


class Recorder:
    """Wraps the split stage's two solver entry points; one row per piece solved."""

    def __init__(self) -> None:
        self.rows: list[tuple] = []
        self._bulk, self._alone = split.solve_charts, split._solved
        self.cfg = split.SplitConfig()

    def install(self) -> None:
        split.solve_charts, split._solved = self.bulk, self.alone

    def remove(self) -> None:
        split.solve_charts, split._solved = self._bulk, self._alone

    def _add(self, V, F, vc, n, bijective, l2, angle, seconds) -> None:
        face_chart = vc[F[:, 0]]
        nf = np.bincount(face_chart, minlength=n)
        net, _ = inner_curvature(V, F, vc, n)
        disks = label_topology(F, face_chart, n)["loops"] == 1
        estimate = split._conformal_stretch(V, F, vc, n, disks)
        estimate[~disks] = np.nan
        met = bijective & split._within_targets(angle, l2, nf, self.cfg)
        for k in range(n):  # loop over the pieces of one call
            self.rows.append(
                (int(nf[k]), bool(met[k]), float(seconds * nf[k] / len(F)), float(net[k]),
                 float(estimate[k]))
            )  # fmt: skip

    def bulk(self, V, F, vert_chart, **kw):
        t = time.perf_counter()
        maps = self._bulk(V, F, vert_chart, **kw)
        seconds = time.perf_counter() - t
        q = maps.quality
        n = int(vert_chart[-1]) + 1
        self._add(V, F, np.asarray(vert_chart), n, q["bijective"], q["l2_stretch"],
                  q["angle_distortion"], seconds)  # fmt: skip
        return maps

    def alone(self, V, F, n_faces, cfg, seed):
        t = time.perf_counter()
        result = self._alone(V, F, n_faces, cfg, seed)
        seconds = time.perf_counter() - t
        q = result.quality
        self._add(V, F, np.zeros(len(V), dtype=np.int64), 1, np.array([result.bijective]),
                  np.array([q.l2_stretch]), np.array([q.angle_distortion]), seconds)  # fmt: skip
        return result


def run(name: str, cuts: bool) -> dict:
    V, F = MESHES[name][1]()
    cfg = PipelineConfig().replace(remesh={"mode": "off"}, split={"n_jobs": 1})
    saved = split.CAP_NET, split.CONFORMAL_STRETCH_CUT
    if not cuts:
        split.CAP_NET = split.CONFORMAL_STRETCH_CUT = np.inf
    rec = Recorder()
    rec.install()
    try:
        t = time.perf_counter()
        atlas = build_atlas(V, F, cfg, seed=0)
        build = time.perf_counter() - t
    finally:
        rec.remove()
        split.CAP_NET, split.CONFORMAL_STRETCH_CUT = saved
    R = np.array(rec.rows, dtype=float).reshape(-1, 5)
    faces, met, seconds = R[:, 0], R[:, 1].astype(bool), R[:, 2]
    return {
        "mesh": name,
        "cuts": cuts,
        "faces": len(F),
        "build_s": build,
        "charts": atlas.n_charts,
        "pieces": len(R),
        "faces_solved": int(faces.sum()),
        "failing_pieces": int((~met).sum()),
        "solver_s": float(seconds.sum()),
        "failing_share": float(seconds[~met].sum() / max(seconds.sum(), 1e-12)),
        "pieces_detail": R.tolist(),  # faces, met, seconds, inner curvature, estimate
    }


def estimate_table(rows: list[dict]) -> list[dict]:
    """Across the runs without cuts: the estimate's precision per threshold."""
    R = np.concatenate([np.array(r["pieces_detail"], dtype=float).reshape(-1, 5) for r in rows])
    faces, met, est, net = R[:, 0], R[:, 1].astype(bool), R[:, 4], R[:, 3]
    fail_faces = faces[~met].sum()
    out = []
    for thr in THRESHOLDS:
        at = np.nan_to_num(est, nan=0.0) >= thr
        out.append({
            "rule": f"estimate >= {thr}", "pieces": int(at.sum()), "met": int((at & met).sum()),
            "failing_faces_share": float(faces[at & ~met].sum() / max(fail_faces, 1)),
        })  # fmt: skip
    at = net >= split.CAP_NET
    out.append({
        "rule": f"inner curvature >= {split.CAP_NET}", "pieces": int(at.sum()),
        "met": int((at & met).sum()),
        "failing_faces_share": float(faces[at & ~met].sum() / max(fail_faces, 1)),
    })  # fmt: skip
    passing = np.nan_to_num(est[met], nan=0.0)
    out.append({"rule": "highest estimate of a piece that met the targets",
                "value": float(passing.max()) if len(passing) else None})  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", default=None, metavar="NAME",
                    help=f"meshes (default: {', '.join(DEFAULT)})")  # fmt: skip
    ap.add_argument("--out", default="benchmarks/results/split.json")
    args = ap.parse_args()
    names = args.only or DEFAULT
    if unknown := sorted(set(names) - set(MESHES)):
        ap.error(f"unknown mesh {', '.join(unknown)}; known: {', '.join(MESHES)}")
    run(names[0], True)  # warm-up: kernels loaded, not reported
    rows = []
    print(f"{'mesh':20s} {'cuts':>5s} {'faces':>7s} {'solved':>7s} {'pieces':>6s} {'failing':>7s} "
          f"{'solver s':>8s} {'share':>6s} {'build s':>7s} {'charts':>6s}")  # fmt: skip
    for name in names:
        for cuts in (True, False):
            r = run(name, cuts)
            rows.append(r)
            print(f"{name:20s} {'yes' if cuts else 'no':>5s} {r['faces']:7d} "
                  f"{r['faces_solved']:7d} {r['pieces']:6d} {r['failing_pieces']:7d} "
                  f"{r['solver_s']:8.3f} {r['failing_share']:6.2f} {r['build_s']:7.2f} "
                  f"{r['charts']:6d}", flush=True)  # fmt: skip
    table = estimate_table([r for r in rows if not r["cuts"]])
    print("\nwithout cuts, across the meshes: pieces a rule would cut, of them meeting the targets")
    for t in table:
        if "value" in t:
            print(f"  {t['rule']}: {t['value']:.4f}")
        else:
            print(f"  {t['rule']:32s} {t['pieces']:5d} pieces, {t['met']:3d} met the targets, "
                  f"{t['failing_faces_share']:.2f} of the failing faces")  # fmt: skip
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    for r in rows:
        r.pop("pieces_detail")
    out.write_text(json.dumps({"machine": platform.platform(), "runs": rows, "rules": table},
                              indent=1))  # fmt: skip
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
