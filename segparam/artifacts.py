"""Stage artifacts: each stage's result as ``NAME.npz`` (arrays) + ``NAME.json`` (figures).

They let any stage be rerun on its own from the previous stage's output (``segparam remesh``,
``segment``, ``parameterize``, ``pack``). Arrays are stored uncompressed with fixed dtypes, so the
same result gives the same bytes.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from .errors import MeshFileError
from .io import atomic_path, check_output_files
from .quality import chart_quality
from .split import Chart, ChartSet

__all__ = [
    "charts_from_arrays",
    "charts_to_arrays",
    "check_stage_output",
    "load_stage",
    "save_stage",
    "stage_paths",
]


def stage_paths(path: str | os.PathLike) -> tuple[Path, Path]:
    """The two files of a stage artifact: ``path`` with the suffix ``.npz``, and its ``.json``.

    Raises
    ------
    MeshFileError
        ``path`` names a folder (``-o .``, ``-o out/``, an existing folder) rather than a file.
    """
    raw = os.fspath(path)
    path = Path(raw)
    folder = raw.endswith(("/", os.sep)) or os.path.isdir(path)
    if folder or not path.name or path.name in (".", ".."):
        raise MeshFileError(f"{raw}: is a folder; give the artifact a file name (NAME.npz)")
    if path.suffix != ".npz":
        path = path.with_suffix(".npz")
    return path, path.with_suffix(".json")


def check_stage_output(
    path: str | os.PathLike, *, inputs: tuple[str | os.PathLike, ...] = ()
) -> Path:
    """Check, before any work, that a stage artifact can be written at ``path`` (its folder is
    writable, the names fit, neither file is one of ``inputs``). Returns the ``.npz`` path.

    Raises
    ------
    MeshFileError
        One line naming the path and the problem.
    """
    npz, js = stage_paths(path)
    check_output_files([npz, js], inputs=inputs)
    return npz


def save_stage(
    path: str | os.PathLike, arrays: dict[str, np.ndarray], info: dict[str, Any]
) -> Path:
    """Write ``path`` (.npz) and the JSON beside it, each atomically. Returns the npz path.

    Raises
    ------
    MeshFileError
        The location cannot take the files (:func:`check_stage_output`) or writing failed.
    """
    path = check_stage_output(path)
    try:
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)
        with atomic_path(path.with_suffix(".json")) as tmp:
            tmp.write_text(json.dumps(info, indent=1) + "\n", encoding="utf-8")
    except MeshFileError:
        raise
    except OSError as exc:
        why = exc.strerror or str(exc)
        raise MeshFileError(f"{path}: cannot write the stage artifact: {why}") from None
    return path


def load_stage(path: str | os.PathLike, *, needs: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Read a stage artifact; a missing file or array is a one-line :class:`MeshFileError`."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except FileNotFoundError:
        raise MeshFileError(f"{path}: no such stage artifact") from None
    except (OSError, ValueError) as exc:
        raise MeshFileError(f"{path}: not a segparam stage artifact ({exc})") from None
    missing = [k for k in needs if k not in arrays]
    if missing:
        raise MeshFileError(
            f"{path}: lacks {', '.join(missing)}; was it written by the previous stage?"
        )
    return arrays


def charts_to_arrays(charts: ChartSet) -> dict[str, np.ndarray]:
    """Flatten a :class:`ChartSet` into arrays with offsets."""
    cs = charts.charts
    return {
        "chart_faces": np.concatenate([c.faces for c in cs]).astype(np.int64),
        "chart_face_ptr": np.r_[0, np.cumsum([len(c.faces) for c in cs])].astype(np.int64),
        "chart_vertices": np.concatenate([c.vertices for c in cs]).astype(np.int64),
        "chart_vertex_ptr": np.r_[0, np.cumsum([len(c.vertices) for c in cs])].astype(np.int64),
        "chart_local_F": np.concatenate([c.local_F for c in cs]).astype(np.int64),
        "chart_uv": np.concatenate([c.uv for c in cs]).astype(np.float64),
        "chart_source": np.array([c.source for c in cs], dtype=np.int64),
        "chart_depth": np.array([c.depth for c in cs], dtype=np.int64),
        "chart_method": np.array([c.method for c in cs], dtype="U16"),
        "splits": charts.splits.astype(np.int64),
        "first_pass_bijective": charts.first_pass_bijective.astype(bool),
        **(
            {}
            if charts.cut_untried is None
            else {"cut_untried": np.asarray(charts.cut_untried, dtype=bool)}
        ),
    }


def charts_from_arrays(V: np.ndarray, a: dict[str, np.ndarray]) -> ChartSet:
    """Rebuild a :class:`ChartSet` (quality recomputed) from :func:`charts_to_arrays`."""
    fp, vp = a["chart_face_ptr"], a["chart_vertex_ptr"]
    charts = []
    for k in range(len(fp) - 1):  # loop over charts
        faces = a["chart_faces"][fp[k] : fp[k + 1]]
        vertices = a["chart_vertices"][vp[k] : vp[k + 1]]
        local_F = a["chart_local_F"][fp[k] : fp[k + 1]]
        uv = a["chart_uv"][vp[k] : vp[k + 1]]
        charts.append(
            Chart(
                faces=faces,
                vertices=vertices,
                local_F=local_F,
                uv=uv,
                quality=chart_quality(V[vertices], local_F, uv),
                source=int(a["chart_source"][k]),
                depth=int(a["chart_depth"][k]),
                method=str(a["chart_method"][k]),
            )
        )
    return ChartSet(
        charts=tuple(charts),
        splits=a["splits"],
        first_pass_bijective=a["first_pass_bijective"],
        cut_untried=a.get("cut_untried"),  # None in the files of earlier versions
    )
