"""Ctrl-C while the chart worker processes start: one line, exit code 130, no file, no traceback.

Ctrl-C in a terminal sends SIGINT to the whole process group, workers included; a worker that
is still importing used to print its own traceback (about 40 lines each).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from segparam.export import write_obj
from segparam.split import PARALLEL_MIN_FACES
from segparam.synthetic import brain_like_surface


def _children(pid: int) -> list[int]:
    """Process ids whose parent is `pid` (Linux /proc)."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(entry.name))
    return out


@pytest.fixture(scope="module")
def big_mesh(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An OBJ just above the size at which charts go to worker processes, written once for the
    module (building and writing it took 2.7 s per test)."""
    V, F = brain_like_surface(int(1.05 * PARALLEL_MIN_FACES), seed=1)
    mesh = tmp_path_factory.mktemp("interrupt") / "big.obj"
    write_obj(mesh, V, F)
    return mesh


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").exists(), reason="needs /proc to see the worker processes")
@pytest.mark.parametrize("delay", [0.05, 0.4])
def test_ctrl_c_while_workers_start_is_one_line(
    tmp_path: Path, big_mesh: Path, delay: float
) -> None:
    mesh = big_mesh
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    proc = subprocess.Popen(
        [sys.executable, "-m", "segparam.cli", "atlas", str(mesh), "-o", str(out), "--quiet",
         "--no-remesh", "--config", "fast"],
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
        env=env,
        cwd=tmp_path,  # not the repository: the child imports the package the tests import
        start_new_session=True,  # its own process group, as a shell gives a command
    )  # fmt: skip
    deadline = time.monotonic() + 240
    workers: list[int] = []
    while time.monotonic() < deadline and proc.poll() is None:
        # the resource tracker is a child too: wait for the workers proper (2 or more children)
        workers = _children(proc.pid)
        if len(workers) >= 2:
            break
        time.sleep(0.02)
    assert proc.poll() is None and len(workers) >= 2, "the chart workers never started"
    time.sleep(delay)
    os.killpg(proc.pid, signal.SIGINT)  # what the terminal does
    _, err = proc.communicate(timeout=120)
    lines = err.decode().strip().splitlines()
    assert proc.returncode == 130, err.decode()
    assert lines == ["segparam: interrupted"], err.decode()
    assert not out.exists() or not any(out.iterdir())
