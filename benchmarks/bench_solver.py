"""Benchmark of the chart solver: scaling with mesh size, and map quality on cortex-like parcels.

Part 1, scaling
    A disk-like chart of near-equilateral triangles (offset rows over a square) bent into the height
    field ``z = 0.1 sin(3x) cos(2y)`` on ``[-1, 1]^2``, for each vertex count in ``--sizes``.
    Each size runs in a fresh subprocess (``--one-size N``) so that its peak resident memory
    (``ru_maxrss``) is its own: reported as the absolute peak and as the peak minus the baseline
    taken after imports and mesh construction (``delta``), also per vertex. Times are the solver's
    own ``timings`` (assemble, eigen, post = isometric fit + quality, refine = ARAP) of
    ``HessianSolver(V, F).solve(refine="arap")`` and the wall time of both calls. Every size runs
    ``--repeats`` times (interleaved) and the run with the best wall time is reported: the
    machine may be shared, so the best run is the least disturbed one.

Part 2, quality on cortex-like parcels (the paper's comparison)
    ``--parcel-set``: ``cortex`` (default; ``brain_like_parcels(n, mean_faces=460,
    min_faces=380, max_faces=560, seed=0)`` of the realistic default surface, as cut),
    ``cortex-ico`` (the same with icosahedral connectivity), ``fsaverage5`` (real parcels: the
    fsaverage5 pial hemispheres cut by ``synthetic.atlas_parcels``), ``gentle`` (the earlier set:
    ``style="gentle", folding=2.0``, 250-1000 faces, each remeshed with ``RemeshConfig(mode="on")``
    as in the paper; parcels where remeshing fails are used as they are, and counted). Each variant
    (method, tangent, refinement) maps every parcel; reported: bijective maps, median angle
    distortion (all maps, bijective maps), median L2 stretch, failures (exceptions) and seconds.
    Baselines: plain ARAP from the planar projection (:func:`segparam.split.project_chart`, so
    without the Hessian start), and libigl's LSCM with two far-apart boundary vertices pinned
    when ``igl`` is importable. BLAS is limited to ``--quality-threads`` threads (default 1,
    through ``threadpoolctl`` when installed) in this part: the charts are small (a few hundred
    vertices), a pipeline runs them in parallel, and multithreaded dense ``eigh`` on such sizes
    only adds overhead, up to 5-8x on a machine whose cores are busy.

Part 3, factorization (``--part factor``, not in ``all``)
    The factorization behind the eigen-solver, alone, on the ``K - sigma I`` of the scaling
    surfaces and of one folded brain-like parcel of about the same size
    (``brain_like_parcels(1, ..., folding=2.0)``): CHOLMOD's supernodal Cholesky through cvxopt
    (what :func:`segparam.linalg.spd_solver` uses) against its SuperLU fallback (minimum degree on
    ``A + A^T``, symmetric mode); best of ``--repeats``, and SuperLU's fill (non-zeros in L + U).

Usage::

    python benchmarks/bench_solver.py [--sizes 1000,10000,100000,300000] [--parcels 89]
                                      [--parcel-set cortex|cortex-ico|fsaverage5|gentle]
                                      [--quick] [--out benchmarks/results/solver.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from contextlib import nullcontext
from pathlib import Path

import numpy as np

DEFAULT_SIZES = "1000,10000,100000,300000"
QUICK_SIZES = "1000,10000"
VARIANTS = (
    ("hessian", "normals", "none"),
    ("hessian", "pca", "none"),
    ("classic-hlle", "pca", "none"),
    ("hessian", "normals", "arap"),
    ("classic-hlle", "pca", "arap"),
    ("hessian", "normals", "slim"),  # the pipeline's default ([split] refine)
)

# ---------------------------------------------------------------------------------------------
# Part 1: scaling
# ---------------------------------------------------------------------------------------------


def wavy_sheet(n: int, surface: str = "sheet") -> tuple[np.ndarray, np.ndarray]:
    """About ``n`` vertices of near-equilateral triangles on a height field over ``[-1, 1]^2``.

    ``surface="sheet"``: ``z = 0.1 sin(3x) cos(2y)``, nearly developable (the Hessian map is
    already near-isometric and the ARAP refinement stops at once). ``surface="bump"``:
    ``z = 0.5 exp(-2 (x^2 + y^2))``, doubly curved, so the refinement runs.

    Rows of ``nx`` points spaced ``h``, ``ny`` rows spaced ``h sqrt(3) / 2``, odd rows shifted by
    ``h / 2``, over ``[-1, 1]^2`` (up to half a cell); faces wound counter-clockwise.
    """
    nx = max(int(round(np.sqrt(n * np.sqrt(3) / 2))), 2)
    ny = max(int(round(n / nx)), 2)
    h = 2.0 / (nx - 0.5)
    j, i = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    x = -1.0 + h * (i + 0.5 * (j % 2))
    y = -1.0 + (2.0 / (ny - 1)) * j  # row spacing ~ h sqrt(3) / 2 by the choice of nx, ny
    x, y = x.ravel(), y.ravel()
    if surface == "sheet":
        z = 0.1 * np.sin(3 * x) * np.cos(2 * y)
    elif surface == "bump":
        z = 0.5 * np.exp(-2 * (x**2 + y**2))
    else:
        raise ValueError(f"unknown surface {surface!r}")
    V = np.stack([x, y, z], 1)

    jj, ii = np.meshgrid(np.arange(ny - 1), np.arange(nx - 1), indexing="ij")
    jj, ii = jj.ravel(), ii.ravel()
    a = jj * nx + ii  # lower row, column i
    b, c, d = a + 1, a + nx, a + nx + 1  # lower i + 1, upper i, upper i + 1
    even = (jj % 2) == 0
    # even rows: the upper row is shifted right; odd rows: the lower row is.
    t1 = np.where(even[:, None], np.stack([a, b, c], 1), np.stack([a, b, d], 1))
    t2 = np.where(even[:, None], np.stack([b, d, c], 1), np.stack([a, d, c], 1))
    F = np.vstack([t1, t2]).astype(np.int64)
    return V, F


def _maxrss_kb() -> int:
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)  # KB on Linux


def one_size(n: int, surface: str = "sheet", seed: int = 0) -> dict:
    """Child process: build the surface, time the solver, report peak memory (JSON on stdout)."""
    from segparam.parameterize import HessianSolver

    V, F = wavy_sheet(n, surface)
    base = _maxrss_kb()
    t0 = time.perf_counter()
    solver = HessianSolver(V, F)
    chart = solver.solve(seed=seed, refine="arap")
    wall = time.perf_counter() - t0
    peak = _maxrss_kb()
    return {
        "n_target": n,
        "surface": surface,
        "n_vertices": len(V),
        "n_faces": len(F),
        "nnz_K": int(solver.K.nnz),
        **{f"{k}_s": float(v) for k, v in chart.timings.items()},
        "wall_s": wall,
        "baseline_rss_kb": base,
        "peak_rss_kb": peak,
        "delta_rss_kb": peak - base,
        "bytes_per_vertex": (peak - base) * 1024 / len(V),
        "bijective": bool(chart.bijective),
        "refined": bool(chart.refined),
        "angle_distortion": float(chart.angle_distortion),
        "l2_stretch": float(chart.l2_stretch),
    }


def _rss_of(pid: int) -> int:
    """Current resident set of a process, KB (0 if it is gone)."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def run_size(n: int, surface: str, *, timeout: float, mem_limit_gb: float) -> dict:
    """Run :func:`one_size` in a fresh interpreter; stop it past the time or memory limit."""
    cmd = [sys.executable, os.path.abspath(__file__), "--one-size", str(n), "--surface", surface]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    start, limit_kb, failure = time.perf_counter(), mem_limit_gb * 1024**2, None
    while True:
        try:
            out, err = proc.communicate(timeout=0.5)
            break
        except subprocess.TimeoutExpired:
            if time.perf_counter() - start > timeout:
                failure = f"stopped after {timeout:.0f} s"
            elif _rss_of(proc.pid) > limit_kb:
                failure = f"stopped above {mem_limit_gb:g} GB resident"
            if failure:
                proc.kill()
                proc.communicate()
                return {"n_target": n, "error": failure}
    if proc.returncode != 0:
        tail = err.strip().splitlines()[-1] if err.strip() else f"exit code {proc.returncode}"
        return {"n_target": n, "error": tail}
    return json.loads(out.strip().splitlines()[-1])


def scaling(
    sizes: list[int], surface: str, *, repeats: int, timeout: float, mem_limit_gb: float
) -> list:
    best: dict[int, dict] = {}
    for r in range(repeats):
        for n in sizes:
            if n in best and "error" in best[n]:
                continue  # a size that hit a limit is not run again
            print(f"  scaling: n={n} run {r + 1}/{repeats} ...", file=sys.stderr, flush=True)
            row = run_size(n, surface, timeout=timeout, mem_limit_gb=mem_limit_gb)
            row["runs"] = r + 1
            if n not in best or "error" in row or row["wall_s"] < best[n]["wall_s"]:
                best[n] = row
            best[n]["runs"] = r + 1
    return [best[n] for n in sizes]


def print_scaling(rows: list) -> None:
    head = (
        "vertices faces assemble_s eigen_s post_s refine_s wall_s peak_MB delta_MB "
        "B/vertex bijective refined angle_dist"
    ).split()
    table = []
    for r in rows:
        if "error" in r:
            table.append([f"{r['n_target']}", r["error"]])
            continue
        table.append(
            [
                f"{r['n_vertices']}",
                f"{r['n_faces']}",
                f"{r['assemble_s']:.3f}",
                f"{r['eigen_s']:.3f}",
                f"{r['post_s']:.3f}",
                f"{r['refine_s']:.3f}",
                f"{r['wall_s']:.3f}",
                f"{r['peak_rss_kb'] / 1024:.0f}",
                f"{r['delta_rss_kb'] / 1024:.0f}",
                f"{r['bytes_per_vertex']:.0f}",
                "yes" if r["bijective"] else "no",
                "yes" if r["refined"] else "no",
                f"{r['angle_distortion']:.4f}",
            ]
        )
    print_table(head, table)
    sys.stdout.flush()


# ---------------------------------------------------------------------------------------------
# Part 2: quality on cortex-like parcels
# ---------------------------------------------------------------------------------------------


PARCEL_SETS = ("cortex", "cortex-ico", "fsaverage5", "gentle")


def make_parcels(n: int, parcel_set: str = "cortex") -> tuple[list, int, str]:
    """The parcels of one set, how many could not be remeshed, and a description.

    ``cortex`` / ``cortex-ico``: ``brain_like_parcels(n, mean_faces=460, min_faces=380,
    max_faces=560, seed=0)`` of the default (realistic) surface with uniform / icosahedral
    connectivity, as cut. ``fsaverage5``: fsaverage5's left and right pial surfaces (nilearn's
    bundled copies) cut by :func:`segparam.synthetic.atlas_parcels` into ``ceil(n/2)`` and
    ``floor(n/2)`` parcels (453-480 faces for n = 89), as cut. ``gentle``: the earlier set,
    ``style="gentle", folding=2.0``, 250-1000 faces, each remeshed as in the paper (parcels
    where remeshing fails are kept as generated, and counted).
    """
    from segparam.parameterize import check_chart
    from segparam.remesh import RemeshConfig, remesh
    from segparam.synthetic import atlas_parcels, brain_like_parcels

    if parcel_set in ("cortex", "cortex-ico"):
        connectivity = "icosahedral" if parcel_set == "cortex-ico" else "uniform"
        raw = brain_like_parcels(
            n, mean_faces=460, min_faces=380, max_faces=560, connectivity=connectivity, seed=0
        )
        return [check_chart(V, F) for V, F in raw], 0, f"{parcel_set} parcels, as cut"
    if parcel_set == "fsaverage5":
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from bench_brains import fsaverage5

        out = []
        for hemi, k in (("left", (n + 1) // 2), ("right", n // 2)):
            mesh = fsaverage5("pial", hemi)
            if mesh is None:
                raise SystemExit(
                    "fsaverage5 needs nilearn's bundled surfaces (pip install nilearn)"
                )
            out += [check_chart(V, F) for V, F in atlas_parcels(*mesh, k)]
        return out, 0, "fsaverage5 pial parcels (left + right), as cut"
    raw = brain_like_parcels(
        n, mean_faces=500, min_faces=250, max_faces=1000, folding=2.0, style="gentle", seed=0
    )
    out, kept = [], 0
    for V, F in raw:
        try:
            res = remesh(V, F, config=RemeshConfig(mode="on"))
            if not res.remeshed:
                raise ValueError(res.reason)
            out.append(check_chart(res.V, res.F))
        except Exception:  # noqa: BLE001 - any failure: keep the generated parcel, counted
            out.append((V, F))
            kept += 1
    return out, kept, "gentle parcels (folding 2.0), remeshed"


def _hessian_variant(method: str, tangent: str, refine: str):
    from segparam.parameterize import HessianSolver

    def run(V, F):
        chart = HessianSolver(V, F, method=method, tangent=tangent).solve(seed=0, refine=refine)
        return chart.quality

    return run


def _plain_arap(V, F):
    from segparam.parameterize import arap_refine
    from segparam.quality import chart_quality
    from segparam.split import project_chart

    uv = arap_refine(V, F, project_chart(V, F), iterations=10)
    return chart_quality(V, F, uv)


def _lscm(V, F):
    """libigl's LSCM with the two boundary vertices farthest apart (two sweeps) pinned."""
    import igl

    from segparam.parameterize import orient
    from segparam.quality import chart_quality

    loop = igl.boundary_loop(F)
    i = loop[np.argmax(np.linalg.norm(V[loop] - V[loop[0]], axis=1))]
    j = loop[np.argmax(np.linalg.norm(V[loop] - V[i], axis=1))]
    d = float(np.linalg.norm(V[i] - V[j]))
    b = np.array([i, j], dtype=np.int64)
    bc = np.array([[0.0, 0.0], [d, 0.0]])
    uv, _ = igl.lscm(V, F, b, bc)
    return chart_quality(V, F, orient(np.asarray(uv, dtype=float), F))


def _igl_available() -> bool:
    try:
        import igl

        return hasattr(igl, "lscm") and hasattr(igl, "boundary_loop")
    except ImportError:
        return False


def quality(parcels: list) -> list:
    variants = [(f"{m} / {t} / {r}", _hessian_variant(m, t, r)) for m, t, r in VARIANTS]
    variants.append(("plain ARAP (projection start)", _plain_arap))
    if _igl_available():
        variants.append(("LSCM (libigl, 2 pins)", _lscm))
    rows = []
    for name, run in variants:
        print(f"  quality: {name} ...", file=sys.stderr, flush=True)
        bij, angle, stretch, errors = [], [], [], []
        try:  # warm-up (lazy imports, first-call set-up), not timed
            run(*parcels[0])
        except Exception:  # noqa: BLE001 - counted below
            pass
        t0 = time.perf_counter()
        for k, (V, F) in enumerate(parcels):
            try:
                q = run(V, F)
            except Exception as exc:  # noqa: BLE001 - a failed solve is a result here
                errors.append(f"parcel {k}: {type(exc).__name__}: {exc}")
                continue
            bij.append(bool(q.bijective))
            angle.append(q.angle_distortion if np.isfinite(q.angle_distortion) else np.inf)
            stretch.append(q.l2_stretch if np.isfinite(q.l2_stretch) else np.inf)
        seconds = time.perf_counter() - t0
        bij_a, angle_a = np.array(bij, dtype=bool), np.array(angle)
        rows.append(
            {
                "variant": name,
                "charts": len(parcels),
                "bijective": int(bij_a.sum()),
                "bijective_pct": 100.0 * bij_a.sum() / len(parcels),
                "median_angle_all": float(np.median(angle_a)) if len(angle_a) else None,
                "median_angle_bijective": (
                    float(np.median(angle_a[bij_a])) if bij_a.any() else None
                ),
                "median_l2_stretch": float(np.median(stretch)) if stretch else None,
                "failures": len(errors),
                "errors": errors,
                "seconds": seconds,
            }
        )
    return rows


def print_quality(rows: list) -> None:
    def num(x):
        return "-" if x is None else ("inf" if not np.isfinite(x) else f"{x:.4f}")

    head = [
        "variant",
        "bijective",
        "%",
        "angle(all)",
        "angle(bij)",
        "L2 stretch",
        "failures",
        "seconds",
    ]
    table = [
        [
            r["variant"],
            f"{r['bijective']}/{r['charts']}",
            f"{r['bijective_pct']:.1f}",
            num(r["median_angle_all"]),
            num(r["median_angle_bijective"]),
            num(r["median_l2_stretch"]),
            f"{r['failures']}",
            f"{r['seconds']:.2f}",
        ]
        for r in rows
    ]
    print_table(head, table, left=1)


# ---------------------------------------------------------------------------------------------
# Output
# ---------------------------------------------------------------------------------------------


def print_table(head: list[str], rows: list[list[str]], *, left: int = 0) -> None:
    """Aligned columns: the first ``left`` columns left-aligned, the others right-aligned."""
    width = [len(h) for h in head]
    for row in rows:
        for k, cell in enumerate(row[: len(head)]):
            width[k] = max(width[k], len(cell))

    def line(cells):
        parts = [
            c.ljust(width[k]) if k < left else c.rjust(width[k])
            for k, c in enumerate(cells[: len(head)])
        ]
        return "  ".join(parts + list(cells[len(head) :]))

    print(line(head))
    print("  ".join("-" * w for w in width))
    for row in rows:
        if len(row) == 2 and len(head) > 2:  # an error row: size then message
            print(f"{row[0].rjust(width[0])}  {row[1]}")
        else:
            print(line(row))


def blas_limit(threads: int):
    """A context limiting BLAS threads (if ``threadpoolctl`` is there) and what was applied."""
    if threads <= 0:
        return nullcontext(), "library default"
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return nullcontext(), "library default (threadpoolctl not installed)"
    return threadpool_limits(limits=threads, user_api="blas"), threads


def machine_info() -> dict:
    import scipy

    import segparam

    return {
        "platform": platform.platform(),
        "processor": platform.processor(),
        "python": platform.python_version(),
        "cpu_count": os.cpu_count(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "segparam": segparam.__version__,
    }


# ---------------------------------------------------------------------------------------------
# Part 3: the factorization alone


def _shifted_hessian(surface: str, n: int):
    import scipy.sparse as sp

    from segparam.parameterize import hessian_matrix

    if surface == "brain":
        from segparam.synthetic import brain_like_parcels

        V, F = brain_like_parcels(
            1,
            mean_faces=2 * n,
            min_faces=int(1.8 * n),
            max_faces=int(2.2 * n),
            folding=2.0,
            style="gentle",
        )[0]
    else:
        V, F = wavy_sheet(n, surface)
    K = hessian_matrix(V, F).tocsc()
    sigma = -1e-3 * float(np.abs(K.diagonal()).mean()) / K.shape[0] ** 2  # as in linalg
    return (K - sigma * sp.identity(K.shape[0], format="csc")).tocsc()


def factor_table(sizes: list[int], surfaces: list[str], repeats: int) -> list[dict]:
    import scipy.sparse.linalg as spla

    from segparam import linalg

    rows = []
    for surface in surfaces:
        for n in sizes:
            A = _shifted_hessian(surface, n)
            times = {"cholmod": [], "superlu": []}
            for _ in range(repeats):
                t0 = time.perf_counter()
                linalg._cholmod_solver(A)
                times["cholmod"].append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                lu = spla.splu(
                    A,
                    permc_spec="MMD_AT_PLUS_A",
                    diag_pivot_thresh=0.0,
                    options={"SymmetricMode": True},
                )
                times["superlu"].append(time.perf_counter() - t0)
            row = {
                "surface": surface,
                "rows": A.shape[0],
                "nnz": int(A.nnz),
                "cholmod_s": min(times["cholmod"]),
                "superlu_s": min(times["superlu"]),
                "superlu_fill": int(lu.L.nnz + lu.U.nnz),
            }
            print(
                f"  {surface:6s} {row['rows']:>8,d} rows  CHOLMOD {row['cholmod_s']:6.2f} s  "
                f"SuperLU {row['superlu_s']:6.2f} s  ({row['superlu_fill']:,d} in L+U)",
                flush=True,
            )
            rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", default=None, help=f"vertex counts (default {DEFAULT_SIZES})")
    p.add_argument("--parcels", type=int, default=None, help="number of parcels (default 89)")
    p.add_argument("--quick", action="store_true", help=f"sizes {QUICK_SIZES} and 20 parcels")
    p.add_argument("--repeats", type=int, default=2, help="runs per size; the best is kept")
    p.add_argument("--timeout", type=float, default=900.0, help="seconds allowed per size run")
    p.add_argument("--mem-limit-gb", type=float, default=12.0, help="resident memory per run")
    p.add_argument(
        "--quality-threads", type=int, default=1, help="BLAS threads in part 2 (0: no limit)"
    )
    p.add_argument("--part", choices=("all", "scaling", "quality", "factor"), default="all")
    p.add_argument("--parcel-set", choices=PARCEL_SETS, default="cortex", help="parcels of part 2")
    p.add_argument(
        "--surfaces", default="sheet,bump", help="scaling surfaces: sheet (developable), bump"
    )
    p.add_argument("--surface", default="sheet", help=argparse.SUPPRESS)
    p.add_argument("--out", default="benchmarks/results/solver.json")
    p.add_argument("--one-size", type=int, default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)

    if args.one_size is not None:
        print(json.dumps(one_size(args.one_size, args.surface)))
        return 0

    sizes_arg = args.sizes or (QUICK_SIZES if args.quick else DEFAULT_SIZES)
    sizes = [int(s) for s in sizes_arg.split(",") if s.strip()]
    n_parcels = args.parcels or (20 if args.quick else 89)
    result = {
        "machine": machine_info(),
        "args": {**vars(args), "sizes": sizes, "parcels": n_parcels},
    }
    result["args"].pop("one_size")
    result["args"].pop("surface")

    if args.part in ("all", "scaling"):
        result["scaling"] = []
        for surface in args.surfaces.split(","):
            print(f"\nScaling: {surface} (near-equilateral), best of {args.repeats} runs per size")
            rows = scaling(
                sizes,
                surface,
                repeats=args.repeats,
                timeout=args.timeout,
                mem_limit_gb=args.mem_limit_gb,
            )
            print_scaling(rows)
            result["scaling"] += rows

    if args.part == "factor":
        print(f"\nFactorization of K - sigma I, best of {args.repeats}")
        surfaces = args.surfaces.split(",") + ["brain"]
        result["factor"] = factor_table(sizes, surfaces, args.repeats)

    if args.part in ("all", "quality"):
        t0 = time.perf_counter()
        parcels, kept, what = make_parcels(n_parcels, args.parcel_set)
        prep = time.perf_counter() - t0
        nv = np.array([len(V) for V, _ in parcels])
        nf = np.array([len(F) for _, F in parcels])
        print(
            f"\nQuality: {len(parcels)} {what} ({kept} not remeshed), {nf.min()}-{nf.max()} "
            f"faces, {nv.min()}-{nv.max()} vertices (median {int(np.median(nv))}); "
            f"preparation {prep:.1f} s"
        )
        limit, threads = blas_limit(args.quality_threads)
        print(f"BLAS threads: {threads}", flush=True)
        with limit:
            rows = quality(parcels)
        print_quality(rows)
        for r in rows:
            for e in r["errors"][:3]:
                print(f"  {r['variant']}: {e}")
        result["quality"] = {
            "parcel_set": args.parcel_set,
            "parcels": len(parcels),
            "faces_min": int(nf.min()),
            "faces_max": int(nf.max()),
            "kept_unremeshed": kept,
            "vertices_min": int(nv.min()),
            "vertices_median": float(np.median(nv)),
            "vertices_max": int(nv.max()),
            "prepare_seconds": prep,
            "blas_threads": threads,
            "rows": rows,
        }

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"\nwrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
