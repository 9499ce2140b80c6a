"""The packer's kernels compiled in the background on the first run after installing.

numba compiles every kernel the first time a process calls it and keeps the machine code in its
on-disk cache (``cache=True``), so only the first run after installing pays: 27-30 s of the
README's quick start, 16 s of it the packer's trial kernel (`segparam.canvas.trial`), which the
pipeline calls only at its last stage. When that kernel is not in the cache yet,
:func:`segparam.pipeline.build_atlas` starts one process that compiles it (it packs two
triangles, :func:`_compile`) while this one cleans, segments and parameterizes on the other
core; before packing it waits for that process (:func:`stop`, which meanwhile compiles the
preview renderer's kernel here) and then loads the kernel from the cache. The quick start's first
run: 34 -> about 20 s (BENCHMARKS.md, section 12). Later runs find the kernel cached and start
nothing. The process first compiles the solver's refinement and quality kernels
(:func:`_compile_refinement`), which this one needs only 10-20 s into a first run: a first
``build_atlas`` of the sample brain 34-35 -> 32-34 s (section 0.1, session 17).

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
    """In the background process: the solver's refinement and quality kernels first
    (:func:`_compile_refinement`), then pack two triangles, which compiles the trial kernel (and
    the kernels it calls) with the argument types the pipeline uses, into numba's cache. Ctrl-C
    is the caller's to handle (it ends this process)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import numpy as np

    from .pack import pack_charts

    _compile_refinement()

    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    tri = np.array([[0, 1, 2]])
    pack_charts([uv, uv], [tri, tri], [0.5, 0.5])


def _compile_refinement() -> None:
    """Refine and measure a map of a 4 x 4 bent grid as the solver's batches do (ARAP, SLIM,
    ``charts_quality``): their kernels land in numba's cache with the pipeline's argument types
    before the main process needs them. That is 10-20 s into a first run, after the
    segmentation's and the Hessian's kernels, which the main process compiles meanwhile; the
    packer's kernels are needed last. A head start only: where it fails or comes late, the main
    process compiles them itself."""
    import numpy as np

    from .parameterize import _arap_charts, charts_quality
    from .quality import inverse_frames, triangle_frames
    from .refine import slim_refine

    u, v = np.meshgrid(np.linspace(0.0, 1.0, 4), np.linspace(0.0, 1.0, 4))
    V = np.stack([u.ravel(), v.ravel(), 0.3 * (u * v).ravel()], axis=1)
    q = (np.arange(3)[:, None] * 4 + np.arange(3)[None, :]).ravel()  # lower-left corners
    F = np.concatenate([np.stack([q, q + 1, q + 5], 1), np.stack([q, q + 5, q + 4], 1)])
    vert_chart = np.zeros(len(V), dtype=np.int64)
    frames = inverse_frames(triangle_frames(V, F))
    try:
        uv, _ = _arap_charts(V, F, V[:, :2] * [1.0, 0.9], vert_chart, np.zeros(1, np.int64), 1)
        charts_quality(V, F, uv, vert_chart, 1, frames)
        slim_refine(V, F, uv, vert_chart=vert_chart, n_charts=1, inv_frames=frames)
    except Exception as exc:  # the main process compiles what is missing
        log.debug("refinement kernels not compiled ahead (%r)", exc)
