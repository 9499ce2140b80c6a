"""Command line: parse, build a config, call the library, write files.

Every error a user can cause is a :class:`~segparam.errors.SegparamError`; it is printed as one line
on stderr and the exit code is 2, never a traceback.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from . import __version__
from .errors import SegparamError

log = logging.getLogger("segparam")


def _data(name: str) -> Path:
    """A sample mesh from the top-level ``data/`` folder (installed as ``segparam.data``)."""
    from importlib.resources import files

    return Path(str(files("segparam.data").joinpath(name)))


DEFAULT_CHART_NAME = "brain_parcel.obj"


def _cmd_chart(args: argparse.Namespace) -> int:
    from .io import load_mesh, save_uv_png, write_obj
    from .parameterize import parameterize_chart

    source = Path(args.input) if args.input else _data(DEFAULT_CHART_NAME)
    V, F = load_mesh(source)
    chart = parameterize_chart(V, F, method=args.method, tangent=args.tangent, seed=args.seed)
    out = Path(args.output) if args.output else Path(source.stem + "_uv.obj")
    uv = chart.uv - chart.uv.min(axis=0)
    uv = uv / max(float(uv.max()), 1e-300)  # into the unit square, aspect kept
    write_obj(out, V, F, uv=uv)
    png = out.with_name(out.stem + "_uv.png")
    save_uv_png(png, uv, F)
    if not args.quiet:
        q = chart.quality
        print(f"{source.name}: {len(V)} vertices, {len(F)} faces, method {chart.method}")
        print(
            f"  bijective {q.bijective}  flipped {q.n_flipped}  branch points {q.n_branch}  "
            f"boundary crossings {q.n_crossings}"
        )
        print(
            f"  angle distortion {q.angle_distortion:.4f}  area distortion "
            f"{q.area_distortion:.4f}  L2 stretch {q.l2_stretch:.4f}  "
            f"Linf stretch {q.linf_stretch:.4f}"
        )
        print(f"  wrote {out} and {png}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="segparam", description="Triangle meshes to UV atlases (Hessian eigenfunctions)."
    )
    parser.add_argument("--version", action="version", version=f"segparam {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    chart = sub.add_parser("chart", help="parameterize one disk-like mesh (a single chart)")
    chart.add_argument(
        "input", nargs="?", help=f"mesh file (default: the sample {DEFAULT_CHART_NAME})"
    )
    chart.add_argument("-o", "--output", help="output OBJ (default: <input stem>_uv.obj)")
    chart.add_argument("--method", choices=["hessian", "classic-hlle"], default="hessian")
    chart.add_argument("--tangent", choices=["normals", "pca"], default="normals")
    chart.add_argument("--seed", type=int, default=0)
    chart.add_argument("--quiet", action="store_true", help="print nothing on success")
    chart.set_defaults(func=_cmd_chart)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``segparam`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except SegparamError as exc:
        print(f"segparam: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("segparam: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
