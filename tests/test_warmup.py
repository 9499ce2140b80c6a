"""The packer's kernels compiled in the background on a cold numba cache (segparam.warmup)."""

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest
from meshes import spherical_cap

from segparam import pipeline, warmup
from segparam.pack import pack_charts

SLEEPER = [sys.executable, "-c", "import time; time.sleep(60)"]


def test_kernels_are_cached_once_the_packer_ran():
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    pack_charts([uv], [np.array([[0, 1, 2]])], [0.5])
    assert warmup.kernels_cached()
    assert warmup.start() is None  # nothing to compile: no process


def test_stop_now_ends_the_process_at_once(monkeypatch):
    monkeypatch.setattr(warmup, "kernels_cached", lambda: False)
    monkeypatch.setattr(warmup, "_command", lambda: SLEEPER)
    process = warmup.start()
    assert process is not None and process.poll() is None
    t = time.perf_counter()
    warmup.stop(process, now=True)
    assert process.returncode is not None and time.perf_counter() - t < 10
    warmup.stop(None)  # no process: nothing to do


def test_ctrl_c_during_the_wait_ends_the_process(monkeypatch):
    monkeypatch.setattr(warmup, "kernels_cached", lambda: False)
    monkeypatch.setattr(warmup, "_command", lambda: SLEEPER)

    def interrupted():
        raise KeyboardInterrupt

    monkeypatch.setattr(warmup, "_compile_preview", interrupted)
    process = warmup.start()
    with pytest.raises(KeyboardInterrupt):
        warmup.stop(process)
    assert process.returncode is not None  # killed and reaped, not left running


def test_no_process_from_an_embedded_interpreter(monkeypatch):
    monkeypatch.setattr(warmup, "kernels_cached", lambda: False)
    monkeypatch.setattr(warmup, "_command", lambda: SLEEPER)
    monkeypatch.setattr(sys, "executable", "/opt/blender/blender")  # not a Python to run
    assert warmup.start() is None


def test_an_error_in_a_stage_ends_the_compiling_process(monkeypatch):
    started = []

    def start():
        started.append(subprocess.Popen(SLEEPER))
        return started[-1]

    def fail(*args):
        raise RuntimeError("stage failed")

    monkeypatch.setattr(warmup, "start", start)
    monkeypatch.setattr(pipeline, "_chart_stages", fail)
    V, F = spherical_cap(6, 6)
    with pytest.raises(RuntimeError, match="stage failed"):
        pipeline.build_atlas(V, F)
    assert len(started) == 1 and started[0].returncode is not None  # killed and reaped


SCRIPT = """
import json, sys
sys.path.insert(0, {tests!r})
from meshes import spherical_cap
from segparam import warmup
from segparam.canvas import trial
from segparam.pipeline import PipelineConfig, build_atlas
cold = not warmup.kernels_cached()
V, F = spherical_cap(12, 12)
atlas = build_atlas(V, F, PipelineConfig().replace(pack={{"resolution": 256}}))
print(json.dumps({{
    "cold": cold,
    "waited": "compile" in atlas.timings,
    "hits": sum(trial.stats.cache_hits.values()),
    "misses": sum(trial.stats.cache_misses.values()),
}}))
"""


@pytest.mark.slow
def test_a_cold_cache_gets_the_packer_compiled_in_the_background(tmp_path):
    """In a process with an empty numba cache, build_atlas has the packer's kernels compiled by
    the background process, waits for it and loads them from the cache: it never compiles them
    itself (a cache miss). Compiles every kernel the pipeline uses: about 20-30 s."""
    script = SCRIPT.format(tests=os.path.dirname(__file__))
    assert _run(script, tmp_path) == {"cold": True, "waited": True, "hits": 1, "misses": 0}
    # the next process finds the kernels cached and starts nothing
    assert _run(script, tmp_path) == {"cold": False, "waited": False, "hits": 1, "misses": 0}


BACKGROUND = """
import json
from segparam import pack, render, warmup
cached = {"trial": warmup.kernels_cached(), "preview": warmup._cached(render._render_kernel),
          "hulls": warmup._cached(pack._hulls)}
print(json.dumps(cached))
"""


@pytest.mark.slow
def test_the_background_compiles_the_packer_then_the_preview_renderer(tmp_path):
    """The background process (``warmup._compile``) leaves the packer's trial and hull kernels
    and the preview renderer's kernel in an empty cache. Compiles the packer's kernels: about
    15 s."""
    assert _run(BACKGROUND, tmp_path) == {"trial": False, "preview": False, "hulls": False}
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    code = "import segparam.warmup as w; w._compile()"
    subprocess.run([sys.executable, "-c", code], check=True, env=env, cwd=tmp_path)
    assert _run(BACKGROUND, tmp_path) == {"trial": True, "preview": True, "hulls": True}


PREVIEW = """
import json, subprocess, sys
from segparam import render, warmup
sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(1)"])
warmup.stop(sleeper)
print(json.dumps({"ended": sleeper.returncode, "compiled": len(render._render_kernel.signatures)}))
"""


@pytest.mark.slow
def test_the_wait_compiles_the_preview_renderer(tmp_path):
    """While the background process still runs, stop() compiles the preview's kernel in this
    process (on an empty cache), then waits for the process to end."""
    assert _run(PREVIEW, tmp_path) == {"ended": 0, "compiled": 1}


def _run(script: str, tmp_path) -> dict:
    """Run a script in a fresh process whose numba cache is ``tmp_path / "cache"`` (empty the
    first time); the JSON it prints last."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, env=env, cwd=tmp_path
    )
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout.splitlines()[-1])
