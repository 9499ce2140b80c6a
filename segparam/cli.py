"""Command line: parse, build a config, call the library, write files.

Every error a user can cause is a :class:`~segparam.errors.SegparamError`; it is printed as one line
on stderr and the exit code is 2, never a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import sys
from collections.abc import Iterator
from pathlib import Path

from . import __version__
from .errors import SegparamError

log = logging.getLogger("segparam")


class _UsageError(Exception):
    """A bad command line (unknown option, a value out of range): one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line like every other error (no usage block)."""

    def error(self, message: str):  # type: ignore[override]
        raise _UsageError(message)


def _integer(low: int, high: int):
    """An argparse ``type``: an integer in ``[low, high]``."""

    def parse(text: str) -> int:
        try:
            value = int(text, 10)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected an integer from {low} to {high}, got {text!r}"
            ) from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be from {low} to {high}, got {value}")
        return value

    parse.__name__ = "integer"
    return parse


def _number(low: float, *, above: bool = False):
    """An argparse ``type``: a finite number ``>= low`` (``> low`` with ``above``)."""
    relation = ">" if above else ">="

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected a number {relation} {low:g}, got {text!r}"
            ) from None
        if not (math.isfinite(value) and (value > low if above else value >= low)):
            raise argparse.ArgumentTypeError(
                f"must be a finite number {relation} {low:g}, got {text}"
            )
        return value

    parse.__name__ = "number"
    return parse


# segparam.pipeline.MAX_RESOLUTION and MAX_SEED (not imported: --help stays fast); the tests check
# that they agree.
_MAX_RESOLUTION, _MAX_SEED = 16384, 2**32 - 1
#: ``--seed``: numpy's RandomState (the clustering's start vector) takes 32-bit seeds.
SEED = _integer(0, _MAX_SEED)
#: ``--resolution``: texels per side.
RESOLUTION = _integer(1, _MAX_RESOLUTION)
#: ``--padding``: texels; below half the resolution (checked with the resolution).
PADDING = _integer(0, _MAX_RESOLUTION // 2)
#: ``--max-charts``.
MAX_CHARTS = _integer(1, 1_000_000)
#: ``--max-distortion``: an angle distortion s1/s2, 1 at best.
MAX_DISTORTION = _number(1.0)
#: ``--texels-per-unit``: texels per unit of 3-D length.
TEXELS_PER_UNIT = _number(0.0, above=True)
#: ``--max-chart-size``: texels, 0 for no limit.
MAX_CHART_SIZE = _integer(0, _MAX_RESOLUTION)


@contextlib.contextmanager
def _naming(path: Path) -> Iterator[None]:
    """Errors raised inside the block name ``path`` (the input file) if they do not already."""
    try:
        yield
    except SegparamError as exc:
        text = str(exc)
        if str(path) in text or path.name in text:
            raise
        raise type(exc)(f"{path}: {text}") from None


def _bundled(folder: str, name: str) -> Path:
    """A file of the top-level ``data/`` or ``pipelines/`` folder.

    Installed, they are the packages ``segparam.data`` and ``segparam.pipelines``; when segparam
    is imported from a source checkout (e.g. ``python -m pytest`` in the repository), they are
    the folders beside the package.
    """
    from importlib.resources import files

    try:
        return Path(str(files(f"segparam.{folder}").joinpath(name)))
    except ModuleNotFoundError:
        return Path(__file__).resolve().parent.parent / folder / name


def _data(name: str) -> Path:
    """A sample mesh from the top-level ``data/`` folder."""
    return _bundled("data", name)


DEFAULT_CHART_NAME = "brain_parcel.obj"


def _cmd_chart(args: argparse.Namespace) -> int:
    from .export import render_uv_layout, write_obj
    from .io import (
        check_output_files,
        fit_name,
        load_mesh,
        mesh_stem,
        name_max,
        staged_outputs,
    )
    from .parameterize import parameterize_chart

    source = Path(args.input) if args.input else _data(DEFAULT_CHART_NAME)
    if args.output:
        out = Path(args.output)
    else:  # <stem>_uv.obj and <stem>_uv_uv.png, the stem shortened if they would be too long
        limit = name_max(Path.cwd()) - len("_uv_uv.png")
        out = Path(fit_name(mesh_stem(source), limit=limit) + "_uv.obj")
    png = out.with_name(out.stem + "_uv.png")
    check_output_files([out, png], inputs=[source])
    V, F = load_mesh(source)
    with _naming(source):
        chart = parameterize_chart(V, F, method=args.method, tangent=args.tangent, seed=args.seed)
    uv = chart.uv - chart.uv.min(axis=0)
    uv = uv / max(float(uv.max()), 1e-300)  # into the unit square, aspect kept
    with staged_outputs(out.parent) as stage:  # both files or neither
        write_obj(stage / out.name, V, F, uv=uv)
        render_uv_layout(uv, F).save(stage / png.name, format="PNG")
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


DEFAULT_MESH_NAME = "brain.obj"


def _resolve_config(value: str | None):
    """``--config``: a TOML path, or the name of a bundled pipeline (``default``, ``brain``...)."""
    from .errors import ConfigError
    from .pipeline import PipelineConfig, load_config

    if value is None:
        return PipelineConfig()
    path = Path(value)
    if path.suffix != ".toml" and not path.exists():
        bundled = _bundled("pipelines", f"{value}.toml")
        if not bundled.exists():
            names = sorted(p.stem for p in bundled.parent.glob("*.toml"))
            raise ConfigError(f"no pipeline named {value!r}; bundled: {', '.join(names)}")
        path = bundled
    return load_config(path)


def _config_from_args(args: argparse.Namespace):
    """The pipeline config: ``--config`` (file or bundled name), then command-line overrides."""
    config = _resolve_config(getattr(args, "config", None))
    overrides: dict[str, dict] = {"pack": {}, "remesh": {}, "segment": {}, "split": {}}
    if getattr(args, "resolution", None) is not None:
        overrides["pack"]["resolution"] = args.resolution
    if getattr(args, "padding", None) is not None:
        overrides["pack"]["padding"] = args.padding
    if getattr(args, "square", False):
        overrides["pack"]["trim"] = False
    if getattr(args, "texels_per_unit", None) is not None:
        overrides["pack"]["texels_per_unit"] = args.texels_per_unit
        if getattr(args, "resolution", None) is None:  # the resolution follows the density
            overrides["pack"]["resolution"] = 0
    if getattr(args, "max_chart_size", None) is not None:
        overrides["pack"]["max_chart_size"] = args.max_chart_size
    if getattr(args, "no_remesh", False):
        overrides["remesh"]["mode"] = "off"
    elif getattr(args, "remesh", None) is not None:
        overrides["remesh"]["mode"] = args.remesh
    if getattr(args, "max_charts", None) is not None:
        overrides["segment"]["max_charts"] = args.max_charts
    if getattr(args, "max_distortion", None) is not None:
        overrides["split"]["max_distortion"] = args.max_distortion
    return config.replace(**{k: v for k, v in overrides.items() if v})


def _cmd_remesh(args: argparse.Namespace) -> int:
    from .artifacts import check_stage_output, save_stage
    from .clean import clean
    from .io import load_mesh
    from .remesh import remesh

    config = _config_from_args(args)
    out = check_stage_output(args.output, inputs=[args.input])
    V, F = load_mesh(args.input)
    with _naming(Path(args.input)):
        cleaned = clean(V, F)
        result = remesh(cleaned.V, cleaned.F, config=config.remesh)
    info = {
        "stage": "remesh",
        "input": str(args.input),
        "cleaning": cleaned.summary(),
        "remeshing": {"remeshed": result.remeshed, "reason": result.reason},
    }
    out = save_stage(out, {"V": result.V, "F": result.F}, info)
    if not args.quiet:
        print(f"{len(result.F)} faces ({result.reason}); wrote {out}")
    return 0


def _cmd_segment(args: argparse.Namespace) -> int:
    from .artifacts import check_stage_output, load_stage, save_stage
    from .segment import segment

    config = _config_from_args(args)
    out = check_stage_output(args.output, inputs=[args.input])
    a = load_stage(args.input, needs=("V", "F"))
    with _naming(Path(args.input)):
        seg = segment(a["V"], a["F"], config=config.segment, seed=args.seed)
    info = {"stage": "segment", "charts": seg.n_charts, "curvature": seg.curvature}
    out = save_stage(out, {"V": a["V"], "F": a["F"], "labels": seg.labels}, info)
    if not args.quiet:
        print(f"{seg.n_charts} charts; wrote {out}")
    return 0


def _cmd_parameterize(args: argparse.Namespace) -> int:
    from .artifacts import charts_to_arrays, check_stage_output, load_stage, save_stage
    from .split import parameterize_charts

    config = _config_from_args(args)
    out = check_stage_output(args.output, inputs=[args.input])
    a = load_stage(args.input, needs=("V", "F", "labels"))
    with _naming(Path(args.input)):
        cs = parameterize_charts(a["V"], a["F"], a["labels"], config=config.split, seed=args.seed)
    info = {
        "stage": "parameterize",
        "charts": len(cs.charts),
        "first_pass_bijective": int(cs.first_pass_bijective.sum()),
        "cut_untried": int(cs.cut_untried.sum()),
        "splits": int(cs.splits.sum()),
    }
    arrays = {"V": a["V"], "F": a["F"], **charts_to_arrays(cs)}
    out = save_stage(out, arrays, info)
    if not args.quiet:
        print(f"{len(cs.charts)} bijective charts ({info['splits']} splits); wrote {out}")
    return 0


def _cmd_pack(args: argparse.Namespace) -> int:
    from .artifacts import charts_from_arrays, load_stage
    from .io import atlas_file_names, atlas_stem, check_output_folder, mesh_stem
    from .pipeline import pack_atlas

    config = _config_from_args(args)
    source, outdir = Path(args.input), Path(args.output)
    stem = atlas_stem(mesh_stem(source), outdir)
    check_output_folder(outdir, atlas_file_names(stem).values(), inputs=[source])
    a = load_stage(source, needs=("V", "F", "chart_faces", "chart_uv"))
    with _naming(source):
        charts = charts_from_arrays(a["V"], a)
        atlas = pack_atlas(a["V"], a["F"], charts, config=config, seed=args.seed)
    written = atlas.save(outdir, stem=stem)
    if not args.quiet:
        print(f"{atlas.n_charts} charts, utilization {atlas.packing.utilization:.3f}; ", end="")
        print(f"wrote {len(written)} files to {args.output}/")
    return 0


def _cmd_atlas(args: argparse.Namespace) -> int:
    import time

    from .io import (
        SCENE_SUFFIXES,
        atlas_file_names,
        atlas_stem,
        check_output_folder,
        fit_name,
        load_mesh,
        load_scene,
        mesh_stem,
        name_max,
        split_suffix,
    )
    from .pictures import check_bakes
    from .pipeline import build_atlas

    if len(args.input) > 1:
        return _atlas_of_several([Path(p) for p in args.input], args)
    source = Path(args.input[0]) if args.input else _data(DEFAULT_MESH_NAME)
    stem = mesh_stem(source)
    if args.output:
        outdir = Path(args.output)
    else:
        outdir = Path(fit_name(stem, "_atlas", limit=name_max(Path.cwd())))
    config = _config_from_args(args)
    pictures = _picture_options(args, source)
    # Everything about the output location, before any work: a run never fails at its end for it.
    stem = atlas_stem(stem, outdir)
    check_output_folder(outdir, atlas_file_names(stem, pictures).values(), inputs=[source])
    t0 = time.perf_counter()
    if args.uvs:
        return _repack_file(source, outdir, stem, config, args)
    read = None
    if split_suffix(source)[1] in SCENE_SUFFIXES:
        meshes = load_scene(source)
        if len(meshes) > 1:  # a scene of several meshes: one texture, the scene back as one GLB
            return _atlas_of_several([source], args, loaded=[meshes])
        read = meshes[0]  # one mesh: as load_mesh reads it
    V, F = load_mesh(source) if read is None else (read.V, read.F)
    check_bakes(pictures.bakes, source, V)  # data files of the right length, before the work
    bar = _progress_bar(args.quiet)
    try:
        with _naming(source):
            atlas = build_atlas(V, F, config, seed=args.seed, progress=bar.update if bar else None)
    finally:
        if bar:
            bar.close()
    written = atlas.save(outdir, stem=stem, pictures=pictures)
    if not args.quiet:
        r = atlas.report()
        a = r["atlas"]
        c = r["cleaning"]
        print(f"{source.name}: {r['input']['faces']} faces in, {a['faces']} charted", end="")
        print(f" ({'remeshed' if r['remeshing']['remeshed'] else 'not remeshed'}:", end="")
        print(f" {r['remeshing']['reason']})")
        removed = c.get("removed_faces", 0)
        if removed:
            print(f"  cleaning removed {removed} faces (listed in report.json)")
        seg = r["segmentation"]
        untried = seg.get("cut_untried") or 0
        print(
            f"  charts {a['charts']} (segmentation {seg['charts']}, "
            f"{seg['first_pass_bijective']} bijective on the first pass"
            + (f", {untried} cut before a solve)" if untried else ")")
        )
        print(
            f"  bijective charts {a['bijective_charts']}/{a['charts']}  flipped triangles "
            f"{a['flipped_triangles']}  utilization {a['utilization']:.3f} of a "
            f"{a['width']}x{a['height']} texture"
        )
        print(
            f"  angle distortion {a['angle_distortion']:.3f}  L2 stretch {a['l2_stretch']:.3f}  "
            f"area distortion {a['area_distortion']:.3f}"
        )
        times = "  ".join(f"{k} {v:.1f}s" for k, v in atlas.timings.items())
        print(f"  time {time.perf_counter() - t0:.1f}s: {times}")
        print(f"  wrote {len(written)} files to {outdir}/")
    return 0


def _atlas_of_several(
    sources: list[Path], args: argparse.Namespace, *, loaded: list | None = None
) -> int:
    """``segparam atlas a.obj b.ply scene.glb ... -o OUT``, or one GLB/glTF scene of several
    meshes: one texture, one texel density (:func:`segparam.pipeline.build_atlases`); an OBJ
    per mesh, a GLB per input (a scene's holds its meshes as nodes); the preview, viewer and
    shared bakes of the whole set; one report. ``loaded``: the inputs' meshes, if read."""
    from .errors import ConfigError
    from .io import (
        all_file_names,
        check_output_folder,
        fit_name,
        load_scene,
        mesh_stem,
        multi_atlas_file_names,
        name_max,
        unique_names,
    )
    from .pictures import PictureOptions, check_several
    from .pipeline import build_atlases

    pictures = PictureOptions(
        preview=not args.no_preview,
        viewer=not args.no_viewer,
        bakes=tuple(args.bake or ()),
        flat=bool(args.flat),  # refused with several meshes; never on by default for them
    )
    if len(sources) > 1:  # all before any file is read
        if args.uvs:
            raise ConfigError(f"--uvs repacks one input mesh, got {len(sources)}")
        if not args.output:
            raise ConfigError(
                f"{len(sources)} input meshes make one atlas: name its folder with -o"
            )
        check_several(pictures, len(sources))
    if loaded is None:
        # the folder checked before any file is read (with the names of one mesh per input;
        # a scene's own names are checked once it is read), then every file read before work
        plain = multi_atlas_file_names(
            "atlas", [mesh_stem(p) for p in sources], Path(args.output), pictures=pictures
        )
        check_output_folder(args.output, all_file_names(plain), inputs=sources)
        loaded = [load_scene(p) for p in sources]
    meshes = [m for group in loaded for m in group]
    check_several(pictures, len(meshes))
    names = unique_names([m.name for m in meshes])
    scenes, start = [], 0
    for source, group in zip(sources, loaded, strict=True):  # loop over inputs
        if len(group) > 1:
            scenes.append((mesh_stem(source), list(range(start, start + len(group)))))
        start += len(group)
    if len(sources) == 1:  # one scene: its files are named after it, as one input's atlas
        stem = mesh_stem(sources[0])
        default = fit_name(stem, "_atlas", limit=name_max(Path.cwd()))
        outdir = Path(args.output or default)
    else:
        stem, outdir = "atlas", Path(args.output)
    config = _config_from_args(args)
    files = multi_atlas_file_names(stem, names, outdir, pictures=pictures, scenes=scenes)
    check_output_folder(outdir, all_file_names(files), inputs=sources)
    bar = _progress_bar(args.quiet)
    try:
        multi = build_atlases(
            [(m.V, m.F) for m in meshes],
            config,
            seed=args.seed,
            names=names,
            progress=bar.update if bar else None,
        )
    finally:
        if bar:
            bar.close()
    written = multi.save(outdir, stem=stem, pictures=pictures, scenes=scenes)
    if not args.quiet:
        r = multi.report()["texture"]
        print(
            f"{r['meshes']} meshes, {r['charts']} charts in one {r['width']}x"
            f"{r['height']} texture at {r['texels_per_unit']:.4g} texels per unit, "
            f"utilization {r['utilization']:.3f}"
        )
        inputs = [str(s) for s, group in zip(sources, loaded, strict=True) for _ in group]
        for name, atlas, source in zip(names, multi.atlases, inputs, strict=True):
            print(f"  {name} ({source}): {len(atlas.F)} faces, {atlas.n_charts} charts")
        print(f"  wrote {len(written)} files to {outdir}/")
    return 0


def _repack_file(source: Path, outdir: Path, stem: str, config, args: argparse.Namespace) -> int:
    """``segparam atlas INPUT --uvs keep|repair``: the input's own uv islands as the charts."""
    from .errors import MeshFileError
    from .io import load_mesh
    from .repack import RepackConfig, repack

    mesh = load_mesh(source, uvs=True)
    if mesh.uv is None:
        raise MeshFileError(
            f"{source}: has no uv on every face (OBJ vt with f v/vt corners, glTF TEXCOORD_0); "
            f"--uvs {args.uvs} needs them"
        )
    cfg = RepackConfig(mode=args.uvs, pack=config.pack, split=config.split, seed=args.seed)
    with _naming(source):
        result = repack(mesh.V, mesh.F, mesh.uv, mesh.uv_F, config=cfg)
    written = result.save(outdir, stem=stem)
    if not args.quiet:
        r = result.report()
        print(
            f"{source.name}: {len(r['islands'])} uv islands, {r['kept_islands']} kept, "
            f"{r['recharted_islands']} re-charted; {r['charts']} charts, "
            f"utilization {r['utilization']:.3f}"
        )
        for island in r["islands"]:
            if not island["kept"]:
                print(f"  island {island['island']} re-charted: {', '.join(island['reasons'])}")
        print(f"  wrote {len(written)} files to {outdir}/")
    return 0


class _StageBar:
    """A tqdm bar per stage (and per chart while parameterizing), on stderr."""

    def __init__(self) -> None:
        from tqdm import tqdm

        self._tqdm = tqdm
        self._bar = None
        self._stage = None

    def update(self, stage: str, done: int, total: int) -> None:
        if stage != self._stage:
            self.close()
            self._stage = stage
            self._bar = self._tqdm(
                total=total,
                desc=f"{stage:>12}",
                unit="chart" if total > 1 else "stage",
                leave=False,
                file=sys.stderr,
            )
        self._bar.n = done
        self._bar.refresh()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None


def _progress_bar(quiet: bool) -> _StageBar | None:
    """The progress bar on a terminal (None with ``--quiet`` or when stderr is not one), after a
    line saying that the first run after installing compiles the kernels (20-30 s, once)."""
    if quiet or not sys.stderr.isatty():
        return None
    from .warmup import kernels_cached

    if not kernels_cached():
        print("segparam: first run after installing: compiling (once, 20-30 s)", file=sys.stderr)
    return _StageBar()


def _picture_options(args: argparse.Namespace, source: Path):
    """The pictures ``segparam atlas`` writes (:class:`segparam.pictures.PictureOptions`)."""
    from .pictures import PictureOptions, flat_default

    return PictureOptions(
        preview=not args.no_preview,
        viewer=not args.no_viewer,
        bakes=tuple(args.bake or ()),
        flat=bool(args.flat or flat_default(source)),
        input_path=str(source),
    )


def add_picture_options(p: argparse.ArgumentParser, *, batch: bool = False) -> None:
    """The options of the atlas folder's pictures (``atlas``; ``batch``: no ``--flat``, and
    ``--bake`` takes the built-in names only, data files being per input)."""
    p.add_argument("--no-preview", action="store_true", help="no <stem>_preview.png")
    p.add_argument("--no-viewer", action="store_true", help="no <stem>.html")
    if batch:
        bake_help = (
            "write <stem>_<NAME>.png in every mesh's folder: curvature, gaussian-curvature, "
            "normals, vertex-colors (no data files: they are per input); repeatable"
        )
    else:
        bake_help = (
            "write <stem>_<NAME>.png: curvature, gaussian-curvature, normals, vertex-colors, "
            "or a per-vertex data file (.func.gii/.shape.gii, lh.thickness, .npy, .csv, .txt); "
            "repeatable; with several meshes curvature, gaussian-curvature, normals only"
        )
    p.add_argument("--bake", action="append", metavar="NAME", help=bake_help)
    if not batch:
        p.add_argument(
            "--flat",
            action="store_true",
            help="<stem>_flat.gii and _flatmap.png (on for GIfTI input; one mesh only)",
        )


def add_pipeline_options(p: argparse.ArgumentParser) -> None:
    """The options shared by ``atlas`` and ``batch`` (read back by :func:`_config_from_args`)."""
    p.add_argument("--config", help="pipeline TOML file, or a bundled name: default, brain, fast")
    p.add_argument(
        "--resolution",
        type=RESOLUTION,
        help="texture size in texels, 1 to 16384 (default 1024); the texture is cut to the "
        "rows or columns the charts use when 1/8 or more of its side would be empty",
    )
    p.add_argument("--square", action="store_true", help="always a square texture (no trimming)")
    p.add_argument("--padding", type=PADDING, help="texels between charts and at the border (2)")
    p.add_argument(
        "--texels-per-unit",
        type=TEXELS_PER_UNIT,
        metavar="X",
        help="texel density: texels per unit of 3-D length; the resolution follows, or is "
        "checked against --resolution (default: the largest density that fits)",
    )
    p.add_argument(
        "--max-chart-size",
        type=MAX_CHART_SIZE,
        metavar="N",
        help="most texels a chart may span; larger charts are scaled down (0: no limit)",
    )
    p.add_argument("--remesh", choices=["auto", "on", "off"], help="remeshing policy (auto)")
    p.add_argument("--no-remesh", action="store_true", help="keep the input's vertices")
    p.add_argument("--max-charts", type=MAX_CHARTS, help="most charts from the segmentation")
    p.add_argument("--max-distortion", type=MAX_DISTORTION, help="split charts above this s1/s2")
    p.add_argument("--seed", type=SEED, default=0, help="0 to 4294967295 (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress bar, no summary")


def _add_batch_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """The ``batch`` subcommand (:func:`_cmd_batch`): many meshes, on Dask."""
    p = subparsers.add_parser(
        "batch",
        help="many mesh files -> one atlas folder each, on Dask (local cluster or a scheduler)",
        description=(
            "Make the atlas of every mesh in INPUTS into OUTDIR/<stem>/ (as 'segparam atlas'), "
            "one Dask task per mesh, and list them in OUTDIR/summary.csv and summary.json. "
            "A rerun skips the meshes already done with the same settings."
        ),
    )
    p.add_argument("inputs", nargs="+", help="mesh files, folders or glob patterns")
    p.add_argument("-o", "--output", required=True, help="output folder (OUTDIR)")
    p.add_argument("--recursive", action="store_true", help="look into sub-folders of folders")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=int,
        help="worker processes of the local cluster, 1 to 4096 (default: CPUs)",
    )
    where.add_argument(
        "--scheduler", metavar="ADDRESS", help="a running Dask scheduler, e.g. tcp://host:8786"
    )
    add_pipeline_options(p)
    add_picture_options(p, batch=True)
    p.set_defaults(func=_cmd_batch)
    return p


def _cmd_batch(args: argparse.Namespace) -> int:
    """``segparam batch``: 0 if every mesh is done or skipped, 1 if some failed, 130 on Ctrl-C.

    Usage errors (no input matched, a bad config, Dask missing) raise :class:`SegparamError`,
    which :func:`main` prints as one line with exit code 2.
    """
    from .batch import (
        MAX_WORKERS,
        SUMMARY_FILES,
        expand_inputs,
        picture_settings,
        require_dask,
        run_batch,
    )
    from .io import check_output_folder

    if args.workers is not None and not 1 <= args.workers <= MAX_WORKERS:
        raise SegparamError(
            f"argument --workers: must be from 1 to {MAX_WORKERS}, got {args.workers}"
        )
    config = _config_from_args(args)
    pictures = picture_settings(
        preview=not args.no_preview, viewer=not args.no_viewer, bakes=args.bake or ()
    )
    check_output_folder(args.output, SUMMARY_FILES)  # before Dask starts or any mesh is read
    require_dask()
    # Dask's own INFO chatter (scheduler start, workers retired) is noise on a terminal.
    logging.getLogger("distributed").setLevel(logging.WARNING)
    outdir = Path(args.output)
    paths = expand_inputs(args.inputs, recursive=args.recursive, exclude=outdir)
    bar = None
    if not args.quiet:
        from tqdm import tqdm

        bar = tqdm(total=len(paths), unit="mesh", desc="batch", file=sys.stderr)

    def progress(row: dict) -> None:
        if bar is None:
            return
        if row["status"] == "failed":
            reason = row["reason"]  # most reasons start with the file name already
            where = "" if reason.startswith(row["input"]) else f"{row['input']}: "
            bar.write(f"failed: {where}{reason}", file=sys.stderr)
        bar.update(1)

    try:
        result = run_batch(
            paths,
            outdir,
            config,
            seed=args.seed,
            recursive=args.recursive,
            workers=args.workers,
            scheduler=args.scheduler,
            progress=progress,
            pictures=pictures,
        )
    except KeyboardInterrupt:
        if bar is not None:
            bar.close()  # before the message, so that it does not end up on the bar's line
        print(
            f"segparam: interrupted; finished meshes stay done (see {outdir / 'summary.csv'})",
            file=sys.stderr,
        )
        return 130
    finally:
        if bar is not None:
            bar.close()
    total = len(result.rows)
    summary = result.outdir / "summary.csv"
    if not args.quiet:
        print(
            f"{total} meshes: {result.count('done')} done, {result.count('skipped')} skipped, "
            f"{result.n_failed} failed in {result.seconds:.1f}s; wrote {summary}"
        )
    if result.n_failed:
        print(f"{result.n_failed} of {total} failed; see {summary}", file=sys.stderr)
        return 1
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
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
    chart.add_argument("--seed", type=SEED, default=0, help="0 to 4294967295 (default 0)")
    chart.add_argument("--quiet", action="store_true", help="print nothing on success")
    chart.set_defaults(func=_cmd_chart)

    atlas = sub.add_parser(
        "atlas",
        help="mesh file(s) -> packed UV atlas (OBJ, GLB, PNGs, report)",
        description="One mesh: its atlas files. Several meshes, or a GLB/glTF scene of "
        "several: one texture at one texel density, an OBJ per mesh, a GLB per input (a "
        "scene's with its nodes), one preview, viewer and report (use 'segparam batch' for "
        "an atlas per mesh).",
    )
    atlas.add_argument(
        "input",
        nargs="*",
        help=f"mesh file(s) (default: the sample {DEFAULT_MESH_NAME})",
    )
    atlas.add_argument(
        "-o",
        "--output",
        help="output folder (default for one input: ./<input stem>_atlas; needed for several)",
    )
    atlas.add_argument(
        "--uvs",
        choices=["keep", "repair"],
        help="repack the input's own uv islands (OBJ vt, glTF TEXCOORD_0) instead of charting: "
        "keep them all, or repair (re-chart the islands that overlap, flip or leave the square)",
    )
    add_pipeline_options(atlas)
    add_picture_options(atlas)
    atlas.set_defaults(func=_cmd_atlas)

    _add_batch_parser(sub)

    def stage(name: str, help_: str, inp: str, out: str, func, options=()) -> None:
        p = sub.add_parser(name, help=help_)
        p.add_argument("input", help=inp)
        p.add_argument("-o", "--output", required=True, help=out)
        p.add_argument("--config", help="pipeline TOML file, or a bundled name")
        p.add_argument("--seed", type=SEED, default=0, help="0 to 4294967295 (default 0)")
        p.add_argument("--quiet", action="store_true")
        for flag, kwargs in options:
            p.add_argument(flag, **kwargs)
        p.set_defaults(func=func)

    stage(
        "remesh",
        "load, clean and remesh a mesh file -> OUT.npz + OUT.json",
        "mesh file",
        "artifact (.npz)",
        _cmd_remesh,
        [("--remesh", {"choices": ["auto", "on", "off"]})],
    )
    stage("segment", "charts of a remesh artifact", "remesh .npz", "artifact", _cmd_segment)
    stage(
        "parameterize",
        "map every chart bijectively (split + retry)",
        "segment .npz",
        "artifact (.npz)",
        _cmd_parameterize,
        [("--max-distortion", {"type": MAX_DISTORTION})],
    )
    stage(
        "pack",
        "pack the charts and write the atlas files",
        "parameterize .npz",
        "output folder",
        _cmd_pack,
        [
            ("--resolution", {"type": RESOLUTION}),
            ("--square", {"action": "store_true", "help": "always a square texture"}),
            ("--padding", {"type": PADDING}),
            ("--texels-per-unit", {"type": TEXELS_PER_UNIT, "metavar": "X"}),
            ("--max-chart-size", {"type": MAX_CHART_SIZE, "metavar": "N"}),
        ],
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``segparam`` console script."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except _UsageError as exc:  # argparse's message, e.g. "argument --seed: must be from 0 to..."
        print(f"segparam: error: {exc}", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except SegparamError as exc:
        print(f"segparam: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # writing failed where no check could tell (disk full...): one line
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"segparam: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("segparam: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
