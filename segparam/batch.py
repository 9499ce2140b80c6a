"""Many meshes at once, on Dask: one task per mesh, on a local cluster or an existing scheduler.

:func:`run_batch` expands the inputs (files, folders, glob patterns), skips the meshes whose output
folder already holds an atlas made with the same settings, submits one :func:`process_one` task per
remaining mesh and gathers the results as they finish. Each mesh writes ``OUTDIR/<stem>/`` exactly
as ``segparam atlas`` does (the pictures of :func:`picture_settings`, built-in bakes only);
``OUTDIR/summary.csv`` and ``OUTDIR/summary.json`` list every input.

Dask (``dask[distributed]``) is an optional dependency (``pip install 'segparam[batch]'``); it is
imported only when a batch runs. Workers need segparam installed and must see the input and output
paths (a shared filesystem), since tasks carry paths, not meshes.
"""

from __future__ import annotations

import contextlib
import csv
import glob
import hashlib
import io
import json
import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import __version__
from .errors import MeshFileError, SegparamError

log = logging.getLogger(__name__)

__all__ = [
    "DONE_MARKER",
    "SUMMARY_FIELDS",
    "BatchResult",
    "assign_folders",
    "expand_inputs",
    "fingerprint",
    "picture_settings",
    "process_one",
    "require_dask",
    "run_batch",
]

#: Written into a mesh's output folder after a successful save; a rerun skips the mesh when the
#: fingerprint stored in it matches.
DONE_MARKER = ".segparam-done.json"

#: Columns of ``summary.csv`` (and keys of each ``meshes`` row of ``summary.json``).
SUMMARY_FIELDS = (
    "input",
    "output",
    "status",
    "seconds",
    "charts",
    "utilization",
    "width",
    "height",
    "angle_distortion",
    "l2_stretch",
    "reason",
)

#: Most worker processes of a local cluster (``--workers``).
MAX_WORKERS = 4096
#: The files the batch writes into OUTDIR itself.
SUMMARY_FILES = ("summary.csv", "summary.json")

_MISSING_DASK = "segparam batch needs Dask: pip install 'segparam[batch]'"
_GLOB_CHARS = frozenset("*?[")


def require_dask() -> Any:
    """The ``distributed`` module, or a :class:`SegparamError` saying how to install it."""
    try:
        import dask.distributed as distributed
    except ImportError:
        raise SegparamError(_MISSING_DASK) from None
    return distributed


# ---------------------------------------------------------------------------------------------
# Inputs


def _is_mesh_file(path: Path) -> bool:
    """A visible file with a suffix :func:`segparam.io.load_mesh` reads (any case)."""
    from .io import SUPPORTED_SUFFIXES, split_suffix

    return (
        not path.name.startswith(".")
        and path.is_file()
        and split_suffix(path)[1] in SUPPORTED_SUFFIXES
    )


def _inside(path: Path, folder: Path | None) -> bool:
    return folder is not None and (path == folder or folder in path.parents)


def expand_inputs(
    inputs: Iterable[str | os.PathLike],
    *,
    recursive: bool = False,
    exclude: str | os.PathLike | None = None,
) -> list[Path]:
    """The mesh files named by ``inputs``: absolute, deduplicated and sorted.

    Parameters
    ----------
    inputs : iterable of str or PathLike
        Files (taken as given, whatever their suffix: an unsupported one fails as that mesh's
        result), folders (the supported mesh files inside, hidden files left out) or glob patterns
        (``**`` spans folders with ``recursive``); folders matched by a pattern are expanded too.
    recursive : bool
        Look into sub-folders of the folders.
    exclude : str or PathLike, optional
        A folder whose files are never inputs (the output folder, so that a rerun does not take
        the atlases it wrote for new meshes).

    Returns
    -------
    list of Path

    Raises
    ------
    MeshFileError
        A path that does not exist and is not a pattern, or nothing matched at all.
    """
    skip = Path(exclude).resolve() if exclude is not None else None
    found: set[Path] = set()

    def add_folder(folder: Path) -> None:
        entries = folder.rglob("*") if recursive else folder.iterdir()
        found.update(p.resolve() for p in entries if _is_mesh_file(p))

    given = [str(item) for item in inputs]
    for item in given:
        path = Path(item).expanduser()
        if path.is_dir():
            add_folder(path)
        elif path.is_file():
            found.add(path.resolve())
        elif _GLOB_CHARS & set(item):
            matches = sorted(glob.glob(str(path), recursive=recursive))
            if not matches:
                log.warning("%s: matched no files", item)
            for match in map(Path, matches):
                if match.is_dir():
                    add_folder(match)
                elif _is_mesh_file(match):
                    found.add(match.resolve())
        else:
            raise MeshFileError(f"{item}: no such file or folder")
    paths = sorted(p for p in found if not _inside(p, skip))
    if not paths:
        raise MeshFileError(f"no mesh files matched {' '.join(given) or '(no inputs)'}")
    return paths


def assign_folders(paths: Iterable[Path], *, limit: int | None = None) -> list[str]:
    """One output folder name per input: its stem, then ``<stem>-2``, ``<stem>-3``... on clashes.

    Names are compared case-insensitively (macOS and Windows filesystems) and given in input
    order, so sorted inputs always get the same names. A name longer than ``limit`` bytes
    (default: 255, the usual file-system limit) keeps the beginning of its stem and gets a hash
    of the whole stem (:func:`segparam.io.fit_name`).
    """
    from .io import DEFAULT_NAME_MAX, fit_name, mesh_stem

    limit = DEFAULT_NAME_MAX if limit is None else limit
    used: set[str] = set()
    names = []
    for path in paths:
        stem = mesh_stem(path)
        name, k = fit_name(stem, limit=limit), 1
        while name.casefold() in used:
            k += 1
            name = fit_name(stem, f"-{k}", limit=limit)
        used.add(name.casefold())
        names.append(name)
    return names


# ---------------------------------------------------------------------------------------------
# One mesh (runs on a worker)


def _file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def fingerprint(
    input_sha256: str,
    config_dict: dict[str, Any],
    seed: int,
    pictures: dict[str, Any] | None = None,
) -> str:
    """sha256 of everything that determines an atlas folder: input bytes, settings, seed,
    version, and the pictures asked for (:func:`picture_settings`)."""
    key = {
        "input_sha256": input_sha256,
        "settings": config_dict,
        "seed": int(seed),
        "segparam": __version__,
        "pictures": picture_settings(**(pictures or {})),
    }
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()


def _read_marker(folder: Path) -> dict[str, Any] | None:
    try:
        data = json.loads((folder / DONE_MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _done_row(
    path: Path, folder: Path, config_dict: dict, seed: int, pictures: dict | None = None
) -> dict[str, Any] | None:
    """The ``skipped`` row of a mesh whose folder holds an atlas of these settings, else None."""
    marker = _read_marker(folder)
    if marker is None:
        return None
    try:
        fp = fingerprint(_file_sha256(path), config_dict, seed, pictures)
    except OSError:
        return None  # unreadable input: let the task report why
    if marker.get("fingerprint") != fp:
        return None
    return {**_row(path, folder), **marker.get("result", {}), "status": "skipped"}


def _row(path: Path, folder: Path, **values: Any) -> dict[str, Any]:
    row = dict.fromkeys(SUMMARY_FIELDS)
    row.update(input=str(path), output=folder.name, **values)
    return row


def _one_line(exc: BaseException) -> str:
    text = str(exc) if isinstance(exc, SegparamError) else f"{type(exc).__name__}: {exc}"
    return " ".join(text.split()) or type(exc).__name__


def picture_settings(
    preview: bool = True, viewer: bool = True, bakes: Iterable[str] = ()
) -> dict[str, Any]:
    """The pictures of every mesh's folder, checked: ``{"preview", "viewer", "bakes"}``.

    Bakes are the built-in names only (:data:`segparam.bake.BAKE_NAMES`: ``curvature``,
    ``normals``, ...): a per-vertex data file belongs to one input, and its length could only
    be checked against one mesh. The flat map follows the input, as in ``segparam atlas``
    (on for GIfTI surfaces).

    Raises
    ------
    BakeError
        A data file, or two bakes of the same file name; one line, before any work.
    """
    from .bake import BAKE_NAMES, BakeError, bake_label

    bakes = [str(b) for b in bakes]
    labels: dict[str, str] = {}
    for name in bakes:
        if name not in BAKE_NAMES:
            raise BakeError(
                f"--bake {name}: a data file belongs to one input; segparam batch bakes "
                f"{', '.join(BAKE_NAMES)}"
            )
        label = bake_label(name)
        if label in labels:
            raise BakeError(
                f"--bake {name} and --bake {labels[label]} would both write _{label}.png"
            )
        labels[label] = name
    return {"preview": bool(preview), "viewer": bool(viewer), "bakes": bakes}


def process_one(
    path: str | os.PathLike,
    outdir: str | os.PathLike,
    config_dict: dict[str, Any],
    seed: int,
    pictures: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Make the atlas of one mesh file into ``outdir`` (the Dask task; never raises on a bad mesh).

    Skips the mesh when ``outdir`` already holds an atlas with the same fingerprint (see
    :func:`fingerprint`); otherwise runs :func:`~segparam.pipeline.build_atlas`, saves the atlas
    as ``segparam atlas`` does and then writes :data:`DONE_MARKER`.

    Parameters
    ----------
    path : str or PathLike
        The mesh file (an absolute path the worker can read).
    outdir : str or PathLike
        The mesh's output folder, ``OUTDIR/<stem>``.
    config_dict : dict
        :meth:`PipelineConfig.as_dict` of the settings.
    seed : int
    pictures : dict, optional
        The keywords of :func:`picture_settings` (default: preview and viewer, no bakes).

    Returns
    -------
    dict
        One summary row (:data:`SUMMARY_FIELDS`): status ``done``, ``skipped`` or ``failed``
        (with the one-line reason: the :class:`SegparamError` message, else ``Type: message``).
    """
    from .io import (
        atlas_file_names,
        atlas_stem,
        atomic_path,
        check_output_folder,
        load_mesh,
        mesh_stem,
    )
    from .pictures import PictureOptions, check_bakes, flat_default
    from .pipeline import build_atlas, config_from_dict

    path, folder = Path(path), Path(outdir)
    t0 = time.perf_counter()
    try:
        settings = picture_settings(**(pictures or {}))
        skipped = _done_row(path, folder, config_dict, seed, settings)
        if skipped is not None:
            return skipped
        options = PictureOptions(
            preview=settings["preview"],
            viewer=settings["viewer"],
            bakes=tuple(settings["bakes"]),
            flat=flat_default(path),
            input_path=str(path),
        )
        stem = atlas_stem(mesh_stem(path), folder)
        names = [*atlas_file_names(stem, options).values(), DONE_MARKER]
        check_output_folder(folder, names, inputs=[path])  # before any work
        # One task per mesh already keeps every worker busy: no process pool inside a task.
        config = config_from_dict(config_dict).replace(split={"n_jobs": 1})
        try:
            input_sha = _file_sha256(path)
        except OSError:
            input_sha = None  # load_mesh below says what is wrong with the file
        V, F = load_mesh(path)
        check_bakes(options.bakes, path, V)  # vertex-colors: this input has them, before work
        atlas = build_atlas(V, F, config, seed=seed)
        (folder / DONE_MARKER).unlink(missing_ok=True)  # an older atlas is being replaced
        atlas.save(folder, stem=stem, pictures=options)
        report = json.loads((folder / "report.json").read_text(encoding="utf-8"))["atlas"]
        result = {
            "seconds": round(time.perf_counter() - t0, 3),
            "charts": report["charts"],
            "utilization": report["utilization"],
            "width": report["width"],
            "height": report["height"],
            "angle_distortion": report["angle_distortion"],
            "l2_stretch": report["l2_stretch"],
        }
        marker = {
            "fingerprint": fingerprint(input_sha, config_dict, seed, settings),
            "input": str(path),
            "input_sha256": input_sha,
            "seed": int(seed),
            "segparam": __version__,
            "settings": config_dict,
            "pictures": settings,
            "result": result,
        }
        with atomic_path(folder / DONE_MARKER) as tmp:
            tmp.write_text(json.dumps(marker, indent=1) + "\n", encoding="utf-8")
        return _row(path, folder, status="done", **result)
    except Exception as exc:  # one bad mesh must not stop the others
        log.info("%s failed", path, exc_info=True)
        seconds = round(time.perf_counter() - t0, 3)
        return _row(path, folder, status="failed", seconds=seconds, reason=_one_line(exc))


# ---------------------------------------------------------------------------------------------
# The batch


@dataclass(frozen=True)
class BatchResult:
    """What a batch did: one row per input (sorted as the inputs), and where it wrote them.

    Attributes
    ----------
    rows : list of dict
        :data:`SUMMARY_FIELDS` per input; ``status`` is ``done``, ``skipped``, ``failed``, or
        ``pending`` for meshes left unfinished by an interruption.
    outdir : Path
    seconds : float
        Wall time of the batch.
    """

    rows: list[dict[str, Any]]
    outdir: Path
    seconds: float

    def count(self, status: str) -> int:
        return sum(row["status"] == status for row in self.rows)

    @property
    def n_failed(self) -> int:
        return self.count("failed")


def _write_summary(outdir: Path, rows: list[dict], meta: dict[str, Any]) -> None:
    """``summary.csv`` and ``summary.json``, each replaced atomically."""
    from .io import atomic_path, json_safe

    rows = json_safe(rows)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=SUMMARY_FIELDS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    with atomic_path(outdir / "summary.csv") as tmp:
        tmp.write_text(buffer.getvalue(), encoding="utf-8")
    counts = {s: sum(r["status"] == s for r in rows) for s in ("done", "skipped", "failed")}
    counts["pending"] = len(rows) - sum(counts.values())
    doc = {**meta, "counts": counts, "meshes": rows}
    with atomic_path(outdir / "summary.json") as tmp:
        tmp.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")


@contextlib.contextmanager
def _sigint_ignored() -> Iterator[None]:
    """Ignore SIGINT while the local workers start, so that they inherit ``SIG_IGN``.

    Ctrl-C in a terminal interrupts the whole process group; the workers should not die with a
    traceback each but be closed by this process, which saves the summary first.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def run_batch(
    inputs: Iterable[str | os.PathLike],
    outdir: str | os.PathLike,
    config=None,
    *,
    seed: int = 0,
    recursive: bool = False,
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    progress: Callable[[dict[str, Any]], None] | None = None,
    summary_interval: float = 2.0,
    pictures: dict[str, Any] | None = None,
) -> BatchResult:
    """Make the atlas of every mesh in ``inputs`` on Dask, one task per mesh.

    Parameters
    ----------
    inputs : iterable of str or PathLike
        Files, folders or glob patterns (see :func:`expand_inputs`).
    outdir : str or PathLike
        Gets one folder per mesh (see :func:`assign_folders`) and ``summary.csv/.json``.
    config : PipelineConfig, optional
        The settings (default ``PipelineConfig()``); the command line builds it from its options.
    seed : int
    recursive : bool
    workers : int, optional
        Worker processes of the local cluster (default: one per CPU).
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``) instead of a local cluster.
    client : distributed.Client, optional
        An existing client to use (and leave open) instead of either.
    progress : callable, optional
        ``progress(row)`` once per input as it is skipped or finishes.
    summary_interval : float
        Least seconds between rewrites of the summaries while meshes finish.
    pictures : dict, optional
        The keywords of :func:`picture_settings`: ``preview``, ``viewer`` (default True) and
        ``bakes`` (built-in names; default none).

    Returns
    -------
    BatchResult

    Raises
    ------
    SegparamError
        Dask is missing, no input matched (:class:`MeshFileError`), or a bake is a data file
        (:class:`~segparam.bake.BakeError`).
    KeyboardInterrupt
        After cancelling the tasks, closing the cluster and writing the summaries.
    """
    from .io import check_output_folder, name_max
    from .pipeline import PipelineConfig, check_seed

    seed = check_seed(seed)
    pictures = picture_settings(**(pictures or {}))
    outdir = Path(outdir).expanduser().resolve()
    check_output_folder(outdir, SUMMARY_FILES)  # writable, not a file: before any work
    distributed = require_dask()
    t_start = time.perf_counter()
    config = config or PipelineConfig()
    paths = expand_inputs(inputs, recursive=recursive, exclude=outdir)
    folders = [outdir / name for name in assign_folders(paths, limit=name_max(outdir))]
    config_dict = config.as_dict()
    report = progress or (lambda row: None)
    meta = {
        "segparam": __version__,
        "seed": int(seed),
        "settings": config_dict,
        "pictures": pictures,
    }

    rows = [_row(p, f, status="pending") for p, f in zip(paths, folders, strict=True)]
    todo = []
    for k, (path, folder) in enumerate(zip(paths, folders, strict=True)):
        done = _done_row(path, folder, config_dict, seed, pictures)
        if done is None:
            todo.append(k)
        else:
            rows[k] = done
            report(done)
    outdir.mkdir(parents=True, exist_ok=True)
    _write_summary(outdir, rows, meta)
    log.info(
        "%d meshes, %d already done, %d to make", len(paths), len(paths) - len(todo), len(todo)
    )

    if todo:
        own_cluster = own_client = None
        futures: dict[Any, int] = {}
        try:
            if client is None:
                if scheduler is None:
                    with _sigint_ignored():  # inherited by the worker processes
                        own_cluster = distributed.LocalCluster(
                            n_workers=workers or os.cpu_count() or 1,
                            threads_per_worker=1,
                            processes=True,
                            dashboard_address=":0",  # a free port: 8787 may be another's
                            silence_logs=logging.ERROR,
                        )
                own_client = client = distributed.Client(own_cluster or scheduler)
                log.info("dask dashboard: %s", client.dashboard_link)
            for k in todo:
                future = client.submit(
                    process_one,
                    str(paths[k]),
                    str(folders[k]),
                    config_dict,
                    seed,
                    pictures,
                    pure=False,
                )
                futures[future] = k
            last_write = time.monotonic()
            for future in distributed.as_completed(futures):
                k = futures.pop(future)
                try:
                    rows[k] = future.result()
                except Exception as exc:  # the worker died (KilledWorker), or similar
                    rows[k] = _row(paths[k], folders[k], status="failed", reason=_one_line(exc))
                report(rows[k])
                if time.monotonic() - last_write >= summary_interval:
                    _write_summary(outdir, rows, meta)
                    last_write = time.monotonic()
        except BaseException:
            if futures and client is not None:
                try:
                    client.cancel(list(futures))
                except Exception:  # pragma: no cover - closing anyway
                    pass
            raise
        finally:
            _write_summary(outdir, rows, meta)
            if own_client is not None:
                own_client.close()
            if own_cluster is not None:
                own_cluster.close()
    return BatchResult(rows=rows, outdir=outdir, seconds=time.perf_counter() - t_start)
