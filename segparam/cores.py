"""The machine's other cores for the split stage's solver batches: helper processes forked from
this one.

The split stage (:mod:`segparam.split`) maps most charts in batches: one
:func:`segparam.parameterize.solve_charts` call maps many charts at once, and each chart's map
does not depend on the other charts of its batch. A batch is numpy and scipy work in one thread
(brain-20k's largest: 0.44 s), and the interpreter lock keeps threads from sharing it (two
threads took 1.01-1.30x the time of one; BENCHMARKS.md section 0.1). :class:`Helpers` runs parts
of such work in processes forked from this one when the work starts: a fork shares the mesh,
the imported modules and the loaded compiled kernels, so a helper costs a few milliseconds to
start instead of the ~2 s of CPU a spawned worker spends importing (the split stage's worker
processes for meshes of 100k+ faces, :func:`segparam.split.start_workers`, are spawned).

Forking is used on Linux only (macOS's system libraries are not safe to use after a fork, and
Windows has none), from the main thread, and not in a daemonic process (:func:`fork_available`).
Elsewhere, or with one job, the parts run one after the other in this process, with the same
result. Each helper limits its BLAS to its share of the cores and ignores Ctrl-C
(the Ctrl-C of a terminal goes to the whole process group; this process stops the helpers).
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import sys
import threading
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from .linalg import blas_threads

log = logging.getLogger(__name__)

#: The BLAS thread limit of a helper or worker process (kept for the process's life).
_PROCESS_BLAS_LIMIT: list = []
#: How long stopping a pool waits for its manager thread to end (it takes milliseconds once the
#: processes are terminated; the bound only keeps a stuck one from hanging).
STOP_JOIN_SECONDS = 10.0
#: At most this many helpers, whatever the machine: each fork costs ~15 ms here and the parts
#: of a batch of the meshes helped (under 100k faces) get small past four (measured on 2 cores
#: only, i.e. one helper).
MAX_HELPERS = 3


def may_start_processes() -> bool:
    """Whether this process may have children: not a daemonic one (a ``multiprocessing`` pool's
    worker, where starting a process fails with "daemonic processes are not allowed to have
    children")."""
    return not multiprocessing.current_process().daemon


def fork_available() -> bool:
    """Whether helpers can be forked here: Linux with the ``fork`` start method, called from the
    main thread (another thread may hold a lock the fork would copy locked: a caller running
    several atlases in threads), in a process that may have children (a ``multiprocessing``
    pool's worker may not)."""
    return (
        sys.platform.startswith("linux")
        and "fork" in multiprocessing.get_all_start_methods()
        and threading.current_thread() is threading.main_thread()
        and may_start_processes()
    )


def _helper_start(blas_threads: int) -> None:
    """A helper's start: Ctrl-C ignored, its BLAS limited to ``blas_threads`` threads.

    Without the limit a helper's BLAS would start a thread per core next to this process's
    own (the spawned workers' finding: on 2 cores, 4 busy threads took the 1M-face brain's
    parameterize stage 24.6-26.0 s against 18.0-18.3 s; BENCHMARKS.md section 0.1, session 9).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    limit_blas(blas_threads)


def limit_blas(n: int) -> None:
    """Limit this process's BLAS to ``n`` threads for the rest of its life (a helper's or a
    spawned worker's start: each gets its share of the cores)."""
    from threadpoolctl import threadpool_limits

    _PROCESS_BLAS_LIMIT.append(threadpool_limits(n, user_api="blas"))


def stop_pool(pool: ProcessPoolExecutor) -> None:
    """Cancel what has not started and end the pool's processes now (they ignore Ctrl-C), then
    wait for them and for the pool's manager thread."""
    # taken before shutdown, which forgets them
    processes = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(timeout=STOP_JOIN_SECONDS)
    # The pool's manager thread closes its wake-up pipe as it ends; Python 3.11's exit hook
    # writes to that pipe unlocked, and printed a traceback (EBADF) when the two raced: a
    # Ctrl-C while the workers were still starting. Let it end first.
    if manager is not None:
        manager.join(timeout=STOP_JOIN_SECONDS)


class Helpers:
    """Up to ``jobs - 1`` helper processes, forked on the first :meth:`map` that has work for
    them and ended when the ``with`` block ends (at once on an error or Ctrl-C).

    Parameters
    ----------
    jobs : int
        Processes to share the work, this one included (1: no helper; at most
        ``MAX_HELPERS + 1``).
    prepare : callable, optional
        Called in this process just before the helpers are forked: what every process will
        need, done once here (a compiled kernel loaded, or compiled on a first run, is then
        the helpers' too instead of compiled again in each).
    """

    def __init__(self, jobs: int, *, prepare: Callable[[], None] | None = None) -> None:
        self.jobs = min(max(1, int(jobs)), MAX_HELPERS + 1) if fork_available() else 1
        self._prepare = prepare
        self._pool: ProcessPoolExecutor | None = None

    def __enter__(self) -> Helpers:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(now=exc_type is not None)

    @property
    def started(self) -> bool:
        """Whether the helpers run (forked by :meth:`start` or a :meth:`map`)."""
        return self._pool is not None

    def start(self) -> Helpers:
        """Fork the helpers now (a no-op with one job): their start then overlaps what this
        process does until their first part arrives."""
        if self._pool is None and self.jobs > 1:
            if self._prepare is not None:
                self._prepare()
            blas_threads = max(1, (os.cpu_count() or 1) // self.jobs)
            self._pool = ProcessPoolExecutor(
                max_workers=self.jobs - 1,
                mp_context=multiprocessing.get_context("fork"),
                initializer=_helper_start,
                initargs=(blas_threads,),
            )
            with warnings.catch_warnings():
                # Python 3.12+ warns on a fork from a process with threads (here BLAS's idle
                # ones, which their library stops and restarts around a fork).
                warnings.filterwarnings("ignore", message=".*fork.*", category=DeprecationWarning)
                self._pool.submit(int)  # forks every helper (the fork context starts them all)
        return self

    def map(self, fn: Callable[..., Any], parts: Sequence[tuple]) -> list:
        """``[fn(*args) for args in parts]``: the first part in this process, the others in the
        helpers, at the same time. An exception of any part is raised here once every part has
        ended (the first part's first)."""
        if len(parts) <= 1 or self.jobs <= 1:
            return [fn(*args) for args in parts]
        pool = self.start()._pool
        futures = [pool.submit(fn, *args) for args in parts[1:]]
        try:
            with blas_threads(max(1, (os.cpu_count() or 1) // self.jobs)):
                first = fn(*parts[0])
        except Exception:
            wait(futures)
            raise
        out = [first]
        for args, future in zip(parts[1:], futures, strict=True):
            try:
                out.append(future.result())
            except BrokenProcessPool:  # a helper died (killed): its part, and the rest, here
                log.warning("a helper process ended unexpectedly; going on in this one")
                self.close(now=True)
                self.jobs = 1
                out.append(fn(*args))
            except Exception:
                wait(futures)
                raise
        return out

    def close(self, *, now: bool = False) -> None:
        """End the helpers: once they are idle, without waiting for them to exit, or ``now``
        (terminated, and waited for)."""
        pool, self._pool = self._pool, None
        if pool is None:
            return
        if now:
            stop_pool(pool)
        else:
            pool.shutdown(wait=False)
