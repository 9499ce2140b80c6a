"""The packer's kernels compiled in the background on the first run after installing.

numba compiles every kernel the first time a process calls it and keeps the machine code in its
on-disk cache (``cache=True``), so only the first run after installing pays: about 25 s of the
README's quick start, 11-16 s of it the packer's trial kernel (`segparam.canvas.trial`), which
the pipeline calls only at its last stage. When that kernel is not in the cache yet,
:func:`segparam.pipeline.build_atlas` starts one process that compiles it (it packs a few
small charts, :func:`_compile`), then the preview renderer's kernel, while this one cleans,
segments and parameterizes on the other core, compiling the solver's kernels as it needs them;
before packing it waits for that process (:func:`stop`, which meanwhile compiles the preview
renderer's kernel here if the process has not got to it) and then loads the kernels from the
cache. Later runs find the trial kernel cached and start nothing. The split of the work between
the two processes is measured (BENCHMARKS.md, section 12, session 18): this process now has
the longer share, and giving the background more of it did not pay.

If the process fails (or the cache cannot be written), the pack stage compiles the kernel
itself, as it would without this module.
"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
from pathlib import Path

__all__ = ["kernels_cached", "start", "stop"]

log = logging.getLogger(__name__)

# The package's parent directory: the background process imports this very copy of segparam
# (a source tree on sys.path, an editable or a regular install), whose cache it must fill.
_ROOT = str(Path(__file__).resolve().parent.parent)


def kernels_cached() -> bool:
    """Whether numba's on-disk cache holds the packer's trial kernel (its index file exists).

    True as well where numba caches nothing (``NUMBA_DISABLE_JIT``, no cache locator): there is
    nothing a background process could prepare.
    """
    from .canvas import trial

    return _cached(trial)


def _cached(kernel) -> bool:
    """Whether numba's on-disk cache has an index for this compiled function (True where numba
    caches nothing)."""
    cache_file = getattr(getattr(kernel, "_cache", None), "_cache_file", None)  # numba's
    index = getattr(cache_file, "_index_path", None)
    return index is None or os.path.exists(index)


def _command() -> list[str]:
    """The background process: this interpreter, this copy of segparam, :func:`_compile`."""
    code = f"import sys; sys.path.insert(0, {_ROOT!r}); import segparam.warmup as w; w._compile()"
    return [sys.executable, "-c", code]


def start() -> subprocess.Popen | None:
    """Start compiling the packer's kernels in a background process, or None when they are
    already cached, or when this interpreter is embedded in another program (``sys.executable``
    is then that program, e.g. an old Blender's, not a Python to run). The caller ends it with
    :func:`stop`."""
    if kernels_cached() or not Path(sys.executable).name.lower().startswith("python"):
        return None
    return subprocess.Popen(
        _command(), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )


def stop(process: subprocess.Popen | None, *, now: bool = False) -> None:
    """Wait for the process of :func:`start` to finish (None: nothing to do), or, with ``now``
    (an error or Ctrl-C in the caller), end it at once. Either way no process is left behind.

    While it is still compiling, this process compiles the preview renderer's kernel
    (`segparam.render`, 1.2 s, the next one an atlas with pictures needs), if it is not cached:
    the wait would otherwise be idle.
    """
    if process is None:
        return
    try:
        if now:
            process.kill()
        elif process.poll() is None:
            _compile_preview()
        process.wait()
    except BaseException:  # Ctrl-C during the wait: the process goes too
        process.kill()
        process.wait()
        raise


def _compile_preview() -> None:
    """Render one triangle from one viewpoint (:func:`segparam.render.render_preview`, the
    argument types the pictures use), unless the renderer's kernel is cached."""
    from . import render

    if _cached(render._render_kernel):
        return
    import numpy as np

    V = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    uv = V[:, :2].copy()
    tri = np.array([[0, 1, 2]])
    try:  # a head start only: the pictures compile the kernel themselves (and report failures)
        render.render_preview(V, tri, uv, tri, views=[(30.0, 20.0)], size=8)
    except Exception as exc:
        log.debug("preview kernel not compiled ahead (%r)", exc)


def _compile() -> None:
    """In the background process: pack two triangles and a 16-triangle fan, which compiles the
    trial kernel (and the kernels it calls) and the hull of a chart over 12 uv points
    (`pack._hulls`, else the main process's last compile, ~0.5-0.7 s at the pack stage) with the
    argument types the pipeline uses, into numba's cache; then the preview renderer's kernel
    (:func:`_compile_preview`), the next one an atlas with pictures needs. Ctrl-C is the
    caller's to handle (it ends this process)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import numpy as np

    from .pack import pack_charts

    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    tri = np.array([[0, 1, 2]])
    # and a fan of 16 triangles: over 12 uv points a chart's hull is compiled (pack._hulls)
    t = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    fan = np.vstack([[0.0, 0.0], np.column_stack([np.cos(t), np.sin(t)])])
    fan_F = np.column_stack(
        [np.zeros(16, np.int64), 1 + np.arange(16), 1 + (np.arange(16) + 1) % 16]
    )
    pack_charts([uv, uv, fan], [tri, tri, fan_F], [0.5, 0.5, 3.0])
    _compile_preview()
