"""Benchmark of the remesh stage: does the "auto" policy help the chart solver?

For sliver-heavy charts (Delaunay triangulations of random points, anisotropically stretched grids)
and regular ones (near-equilateral grids on curved / folded surfaces, synthetic brain parcels),
parameterize every chart with the Hessian solver (single pass, no split) with remeshing off, on
at 0.7x and 1.0x the mean edge length, and "auto", and report how many maps are bijective and
their median angle distortion. Also times remeshing of a ~100k-face mesh.

Usage::

    python benchmarks/bench_remesh.py [--out benchmarks/results/remesh.json] [--quick]
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path

import numpy as np
from scipy.spatial import Delaunay

from segparam.errors import SegparamError
from segparam.parameterize import parameterize_chart
from segparam.remesh import RemeshConfig, mesh_quality, remesh

# ---------------------------------------------------------------------------------------------
# Charts: a parameter domain in [0, 1]^2, triangulated, then mapped onto a surface
# ---------------------------------------------------------------------------------------------


def surface(name: str, P: np.ndarray) -> np.ndarray:
    """Map parameter points (k, 2) in [0, 1]^2 onto a named surface of size ~1."""
    u, v = P[:, 0], P[:, 1]
    if name == "cylinder":
        th = np.pi * u
        return np.stack([0.35 * np.cos(th), 0.35 * np.sin(th), v], axis=1)
    if name == "saddle":
        x, y = 2 * u - 1, 2 * v - 1
        return np.stack([x, y, 0.5 * (x**2 - y**2)], axis=1)
    if name == "cap":
        x, y = 1.4 * (u - 0.5), 1.4 * (v - 0.5)
        Q = np.stack([x, y, np.ones_like(x)], axis=1)
        return Q / np.linalg.norm(Q, axis=1, keepdims=True)
    if name == "folds":  # accordion: deep folds whose walls come close
        return np.stack([u, v, 0.12 * np.sin(2 * np.pi * 2.5 * u)], axis=1)
    if name == "bumps":
        return np.stack([u, v, 0.15 * np.sin(3 * np.pi * u) * np.cos(2 * np.pi * v)], axis=1)
    raise ValueError(name)


SURFACES = ("cylinder", "saddle", "cap", "folds", "bumps")


def _orient_up(P: np.ndarray, F: np.ndarray) -> np.ndarray:
    a, b, c = P[F[:, 0]], P[F[:, 1]], P[F[:, 2]]
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    F = F.copy()
    F[cross < 0] = F[cross < 0][:, ::-1]
    return F.astype(np.int64)


def delaunay_patch(n: int, seed: int, *, disk: bool) -> tuple[np.ndarray, np.ndarray]:
    """Delaunay triangulation of ``n`` uniform random points (square or disk) plus boundary."""
    rng = np.random.default_rng(seed)
    nb = int(4 * np.sqrt(n))
    if disk:
        r = np.sqrt(rng.random(n)) * 0.5
        t = rng.random(n) * 2 * np.pi
        P = np.c_[0.5 + r * np.cos(t), 0.5 + r * np.sin(t)]
        s = np.linspace(0, 2 * np.pi, nb, endpoint=False)
        Bp = np.c_[0.5 + 0.5 * np.cos(s), 0.5 + 0.5 * np.sin(s)]
        P = P[np.linalg.norm(P - 0.5, axis=1) < 0.5 - 0.2 / np.sqrt(n)]
    else:
        P = rng.random((n, 2))
        s = np.linspace(0, 1, nb // 4, endpoint=False)
        z, o = np.zeros_like(s), np.ones_like(s)
        Bp = np.r_[np.c_[s, z], np.c_[o, s], np.c_[1 - s, o], np.c_[z, 1 - s]]
    P = np.r_[Bp, P]
    F = Delaunay(P).simplices
    return P, _orient_up(P, F)


def tri_grid(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
    """Near-equilateral grid triangulation of [0, 1] x [0, h] (h = sqrt(3)/2 (ny-1)/(nx-1))."""
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    x = (i + 0.5 * (j % 2)) / (nx - 0.5)
    y = j * np.sqrt(3) / 2 / (nx - 0.5)
    P = np.stack([x.ravel(), y.ravel()], axis=1)
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    even = (np.arange(ny - 1) % 2 == 0)[None, :].repeat(nx - 1, axis=0)[..., None]
    t1 = np.where(even, np.stack([a, b, d], -1), np.stack([a, b, c], -1))
    t2 = np.where(even, np.stack([b, c, d], -1), np.stack([a, c, d], -1))
    F = np.concatenate([t1.reshape(-1, 3), t2.reshape(-1, 3)])
    return P, _orient_up(P, F)


def stretched_grid(nx: int, ny: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A grid ``nx`` x ``ny`` over [0, 1]^2 (anisotropic cells), jittered, random diagonals."""
    rng = np.random.default_rng(seed)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    x, y = i / (nx - 1), j / (ny - 1)
    inner = (i > 0) & (i < nx - 1) & (j > 0) & (j < ny - 1)
    x = x + inner * rng.uniform(-0.3, 0.3, x.shape) / (nx - 1)
    P = np.stack([x.ravel(), y.ravel()], axis=1)
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    flip = rng.random(a.shape)[..., None] < 0.5
    t1 = np.where(flip, np.stack([a, b, d], -1), np.stack([a, b, c], -1))
    t2 = np.where(flip, np.stack([b, c, d], -1), np.stack([a, c, d], -1))
    F = np.concatenate([t1.reshape(-1, 3), t2.reshape(-1, 3)])
    return P, _orient_up(P, F)


def datasets(quick: bool) -> dict[str, list[tuple[str, np.ndarray, np.ndarray]]]:
    reps = 1 if quick else 3
    sets: dict[str, list] = {"delaunay": [], "stretched": [], "grid": [], "aniso": [], "brain": []}
    for k, name in enumerate(SURFACES):
        for r in range(reps):
            seed = 100 * k + r
            P, F = delaunay_patch(250 + 60 * r, seed, disk=bool(r % 2))
            sets["delaunay"].append((f"{name}-delaunay-{r}", surface(name, P), F))
            P, F = stretched_grid(12 + 6 * r, 40 + 4 * r, seed)
            sets["stretched"].append((f"{name}-stretched-{r}", surface(name, P), F))
            P, F = tri_grid(16 + 4 * r, 18 + 4 * r)
            P[:, 1] /= P[:, 1].max()  # fill [0, 1]^2 (triangles slightly anisotropic)
            P[:, 1] *= 0.9 + 0.1 * r
            sets["grid"].append((f"{name}-grid-{r}", surface(name, P), F))
            # Regular connectivity, thin triangles: a grid squeezed 2.5:1 to 6:1.
            aspect = (2.5, 4.0, 6.0, 4.0)[r]
            P, F = tri_grid(14 + 6 * (r % 2), int((14 + 6 * (r % 2)) * aspect))
            P[:, 1] /= P[:, 1].max()
            sets["aniso"].append((f"{name}-aniso{aspect:g}-{r}", surface(name, P), F))
    try:
        from segparam.synthetic import brain_like_parcels

        parcels = brain_like_parcels(
            8 if quick else 20,
            mean_faces=460,
            min_faces=150,
            max_faces=1500,
            folding=1.0,
            frequency=1.0,
            seed=0,
        )
        sets["brain"] = [(f"parcel-{i}", V, F) for i, (V, F) in enumerate(parcels)]
    except (ImportError, TypeError, SegparamError) as err:  # being rewritten by someone else
        logging.warning("brain_like_parcels unavailable (%s); brain set skipped", err)
        del sets["brain"]
    return sets


# ---------------------------------------------------------------------------------------------
# Runs
# ---------------------------------------------------------------------------------------------

VARIANTS = {
    "off": lambda q: RemeshConfig(mode="off"),
    "on-0.7": lambda q: RemeshConfig(mode="on", target_edge=0.7 * q.mean_edge),
    "on-1.0": lambda q: RemeshConfig(mode="on", target_edge=1.0 * q.mean_edge),
    "on": lambda q: RemeshConfig(mode="on"),
    "auto": lambda q: RemeshConfig(mode="auto"),
}


#: Solver settings: the paper's single pass ("hessian", no refinement) and the library default
#: (Hessian eigenmap, then ARAP refinement kept when not worse).
SOLVERS = {"hessian": {"refine": "none"}, "default": {}}


def solve(V: np.ndarray, F: np.ndarray, **kwargs) -> tuple[bool, float]:
    try:
        cm = parameterize_chart(V, F, **kwargs)
    except SegparamError:
        return False, float("nan")
    return bool(cm.bijective), float(cm.quality.angle_distortion)


def run_chart(name: str, V: np.ndarray, F: np.ndarray) -> dict:
    q = mesh_quality(V, F)
    row: dict = {"chart": name, "faces": len(F), "quality": q.__dict__}
    for key, make in VARIANTS.items():
        t = time.perf_counter()
        res = remesh(V, F, config=make(q))
        t_remesh = time.perf_counter() - t
        row[key] = {
            "remeshed": res.remeshed,
            "faces": len(res.F),
            "min_angle_p1": res.after.min_angle_p1,
            "frac_irregular": res.after.frac_irregular,
            "remesh_seconds": t_remesh,
            "reason": res.reason,
        }
        for solver, kwargs in SOLVERS.items():
            ok, dist = solve(res.V, res.F, **kwargs)
            row[key][solver] = {"bijective": ok, "angle_distortion": dist}
    return row


def summarize(rows: list[dict]) -> dict:
    out: dict = {"charts": len(rows)}
    names = ("min_angle_p1", "frac_small_angles", "valence_std", "edge_cv")
    q = np.array([[r["quality"][k] for k in names] for r in rows])
    out["input_median"] = dict(zip(names, np.median(q, axis=0).round(3).tolist(), strict=True))
    for key in VARIANTS:
        out[key] = {
            "remeshed": int(sum(r[key]["remeshed"] for r in rows)),
            "median_faces_ratio": float(np.median([r[key]["faces"] / r["faces"] for r in rows])),
        }
        for solver in SOLVERS:
            ok = [r[key][solver]["bijective"] for r in rows]
            dist = [r[key][solver]["angle_distortion"] for r in rows if r[key][solver]["bijective"]]
            out[key][solver] = {
                "bijective": int(sum(ok)),
                "median_angle_distortion": float(np.median(dist)) if dist else float("nan"),
            }
    return out


def time_large() -> dict:
    """Remesh a ~100k-face sliver mesh (Delaunay on a bumpy patch) at its mean edge length."""
    P, F = delaunay_patch(50_000, 7, disk=False)
    V = surface("bumps", P)
    q = mesh_quality(V, F)
    t = time.perf_counter()
    res = remesh(V, F, config=RemeshConfig(mode="on"))
    seconds = time.perf_counter() - t
    return {
        "faces_in": len(F),
        "faces_out": len(res.F),
        "seconds": seconds,
        "remeshed": res.remeshed,
        "min_angle_p1": [q.min_angle_p1, res.after.min_angle_p1],
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="benchmarks/results/remesh.json")
    ap.add_argument("--quick", action="store_true", help="fewer charts")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)

    t0 = time.perf_counter()
    results: dict = {"sets": {}, "rows": {}}
    for set_name, charts in datasets(args.quick).items():
        rows = [run_chart(*c) for c in charts]
        results["rows"][set_name] = rows
        results["sets"][set_name] = summarize(rows)
    results["large"] = time_large()
    results["seconds"] = time.perf_counter() - t0

    head = f"{'set':<10} {'solver':<8} {'n':>3}  {'p1 / small / vstd / ecv':<25}" + "".join(
        f"{k:>13}  " for k in VARIANTS
    )
    print(head)
    print("-" * len(head))
    for set_name, s in results["sets"].items():
        qi = s["input_median"]
        qs = (
            f"{qi['min_angle_p1']:.1f} / {qi['frac_small_angles']:.2f} / "
            f"{qi['valence_std']:.2f} / {qi['edge_cv']:.2f}"
        )
        for solver in SOLVERS:
            cells = ""
            for k in VARIANTS:
                c = s[k][solver]
                cells += f"{c['bijective']:>3} {c['median_angle_distortion']:5.2f} "
                cells += f"{s[k]['remeshed']:>2}r  "
            print(f"{set_name:<10} {solver:<8} {s['charts']:>3}  {qs:<25}{cells}")
    print("cells: bijective charts, their median angle distortion, number remeshed. inputs:")
    print("median 1st-pct min angle / fraction of faces with an angle < 20 / valence std / edge cv")
    print("on-0.7, on-1.0: target 0.7x, 1.0x the mean edge; on, auto: the default target")
    print("solver hessian: the paper's single pass (refine='none'); default: + ARAP refinement")
    lg = results["large"]
    print(
        f"large: {lg['faces_in']} -> {lg['faces_out']} faces in {lg['seconds']:.2f} s; "
        f"min-angle p1 {lg['min_angle_p1'][0]:.1f} -> {lg['min_angle_p1'][1]:.1f} deg"
    )
    print(f"total {results['seconds']:.0f} s")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=1, default=float))


if __name__ == "__main__":
    main()
