import os
import signal

import numpy as np
import pytest
import trimesh

import segparam.cores as cores
import segparam.split as split
from segparam.cores import Helpers
from segparam.segment import segment
from segparam.split import SplitConfig, parameterize_charts

needs_fork = pytest.mark.skipif(not cores.fork_available(), reason="helpers are forked (Linux)")


def _pid_of(x):
    return x, os.getpid()


def _fails_on(x):
    if x == 1:
        raise ValueError(f"part {x} failed")
    return x


def _helper_state():
    from threadpoolctl import threadpool_info

    blas = [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]
    return blas, signal.getsignal(signal.SIGINT)


@needs_fork
def test_the_first_part_runs_here_the_others_in_helpers_in_order():
    with Helpers(3) as helpers:
        out = helpers.map(_pid_of, [(0,), (1,), (2,)])
    assert [x for x, _ in out] == [0, 1, 2]
    assert out[0][1] == os.getpid()
    assert all(pid != os.getpid() for _, pid in out[1:])


@needs_fork
def test_an_error_in_a_helper_is_raised_here_and_the_helper_stays_usable():
    with Helpers(2) as helpers:
        with pytest.raises(ValueError, match="part 1 failed"):
            helpers.map(_fails_on, [(0,), (1,)])
        assert helpers.map(_fails_on, [(2,), (3,)]) == [2, 3]


@needs_fork
def test_helpers_ignore_ctrl_c_and_take_their_share_of_the_blas_threads():
    # this process handles Ctrl-C (a test run in the background may have it ignored)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with Helpers(2) as helpers:
            (_, here), (blas, sigint) = helpers.map(_helper_state, [(), ()])
    finally:
        signal.signal(signal.SIGINT, previous)
    assert here == signal.default_int_handler and sigint == signal.SIG_IGN
    assert blas and all(t == max(1, (os.cpu_count() or 1) // 2) for t in blas)


@needs_fork
def test_an_error_here_ends_the_helpers_at_once():
    helpers = Helpers(2).start()
    processes = list(helpers._pool._processes.values())
    with pytest.raises(KeyboardInterrupt), helpers:
        raise KeyboardInterrupt
    assert not helpers.started
    assert processes and not any(p.is_alive() for p in processes)


def test_without_fork_or_with_one_job_every_part_runs_here(monkeypatch):
    assert Helpers(1).map(_pid_of, [(0,), (1,)]) == [(0, os.getpid()), (1, os.getpid())]
    monkeypatch.setattr(cores, "fork_available", lambda: False)
    helpers = Helpers(4)
    assert helpers.jobs == 1
    assert helpers.map(_pid_of, [(0,), (1,)]) == [(0, os.getpid()), (1, os.getpid())]
    assert not helpers.started


@needs_fork
@pytest.mark.parametrize("alone", [False, True], ids=["batches", "pieces alone"])
def test_charts_solved_in_parts_are_the_one_process_charts_bit_for_bit(monkeypatch, alone):
    # Small parts, so that a small mesh's work is shared; the spy shows it was. With `alone`,
    # no piece fits a batch: the pieces the solver takes one by one are dealt out instead.
    monkeypatch.setattr(split, "PART_MIN_FACES", 100)
    monkeypatch.setattr(split, "FORK_MIN_FACES", 0)
    monkeypatch.setattr(split, "HELPERS_MIN_FACES", 0)
    if alone:
        monkeypatch.setattr(split, "BATCH_MAX_VERTICES", 10)
    shared_by = []
    real_map = Helpers.map

    def spy(self, fn, args):
        shared_by.append((fn.func.__name__, len(args)))
        return real_map(self, fn, args)

    monkeypatch.setattr(Helpers, "map", spy)
    prepared = []
    monkeypatch.setattr(split, "_before_the_helpers", lambda: prepared.append(True))
    # an icosphere: two hemispheres, then their four halves
    sphere = trimesh.creation.icosphere(3)
    V, F = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    seg = segment(V, F, seed=0)
    serial = parameterize_charts(V, F, seg.labels, config=SplitConfig(n_jobs=1))
    assert shared_by == []
    shared = parameterize_charts(V, F, seg.labels, config=SplitConfig(n_jobs=2))
    assert ("_try_all" if alone else "_solve_part", 2) in shared_by
    assert prepared == [True]  # the kernels loaded once, before the fork
    assert np.array_equal(serial.splits, shared.splits)
    assert np.array_equal(serial.first_pass_bijective, shared.first_pass_bijective)
    assert len(serial.charts) == len(shared.charts)
    for a, b in zip(serial.charts, shared.charts, strict=True):
        assert np.array_equal(a.faces, b.faces) and np.array_equal(a.uv, b.uv)
        assert a.quality == b.quality and a.method == b.method


@needs_fork
def test_a_mesh_under_the_helpers_size_is_mapped_in_this_process_alone(monkeypatch):
    # Below HELPERS_MIN_FACES no helper is forked, however large its batches are: a fork costs
    # more than sharing a small mesh's work saves.
    monkeypatch.setattr(split, "PART_MIN_FACES", 100)
    monkeypatch.setattr(split, "FORK_MIN_FACES", 0)
    shared_by = []
    real_map = Helpers.map
    monkeypatch.setattr(
        Helpers,
        "map",
        lambda self, fn, args: shared_by.append(len(args)) or real_map(self, fn, args),
    )
    sphere = trimesh.creation.icosphere(3)
    V, F = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    labels = segment(V, F, seed=0).labels
    monkeypatch.setattr(split, "HELPERS_MIN_FACES", len(F) + 1)
    parameterize_charts(V, F, labels, config=SplitConfig(n_jobs=2))
    assert shared_by == []
    monkeypatch.setattr(split, "HELPERS_MIN_FACES", len(F))
    parameterize_charts(V, F, labels, config=SplitConfig(n_jobs=2))
    assert 2 in shared_by


def _dies_in_a_helper(x):
    if os.getpid() != x:
        os.kill(os.getpid(), signal.SIGKILL)
    return x


@needs_fork
def test_a_helper_that_dies_is_replaced_by_this_process(caplog):
    with Helpers(2) as helpers:
        here = os.getpid()
        assert helpers.map(_dies_in_a_helper, [(here,), (here,)]) == [here, here]
        assert helpers.jobs == 1 and not helpers.started
    assert "ended unexpectedly" in caplog.text


@needs_fork
def test_a_big_machine_gets_a_few_helpers_not_one_per_core():
    assert Helpers(64).jobs == cores.MAX_HELPERS + 1
    assert Helpers(2).jobs == 2


_PREPARED = []


def _prepared():
    return list(_PREPARED)


@needs_fork
def test_prepare_runs_here_once_before_the_helpers_are_forked():
    with Helpers(2, prepare=lambda: _PREPARED.append(os.getpid())) as helpers:
        seen = helpers.map(_prepared, [(), ()])
        helpers.map(_prepared, [(), ()])
    assert _PREPARED == [os.getpid()]
    assert seen == [[os.getpid()], [os.getpid()]]  # the helper was forked after it
    _PREPARED.clear()


def test_the_split_stage_loads_the_solvers_kernels_before_forking():
    import subprocess
    import sys

    code = (
        "import segparam.split as s, segparam.parameterize as p\n"
        "assert not p.kernels_loaded()\n"
        "s._before_the_helpers()\n"
        "assert p.kernels_loaded()\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=300)


def test_no_helpers_from_another_thread():
    import threading

    seen = []
    thread = threading.Thread(target=lambda: seen.append(Helpers(4).jobs))
    thread.start()
    thread.join()
    assert seen == [1]


def _split_in_a_pool_worker():
    sphere = trimesh.creation.icosphere(3)
    V, F = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    labels = segment(V, F, seed=0).labels
    charts = parameterize_charts(V, F, labels, config=SplitConfig(n_jobs=2)).charts
    return [c.uv for c in charts], Helpers(2).jobs, split._jobs(SplitConfig(n_jobs=2))


@needs_fork
def test_a_multiprocessing_pool_worker_maps_its_charts_alone(monkeypatch):
    """A pool's worker is daemonic and may not start processes: no helper, no worker, the same
    charts (it used to fail with "daemonic processes are not allowed to have children")."""
    import multiprocessing

    monkeypatch.setattr(split, "PART_MIN_FACES", 100)  # the forked worker sees these too
    monkeypatch.setattr(split, "FORK_MIN_FACES", 0)
    monkeypatch.setattr(split, "HELPERS_MIN_FACES", 0)
    monkeypatch.setattr(split, "PARALLEL_MIN_FACES", 500)  # and the spawned workers' path
    with multiprocessing.get_context("fork").Pool(1) as pool:
        uvs, helper_jobs, worker_jobs = pool.apply(_split_in_a_pool_worker)
    assert helper_jobs == 1 and worker_jobs == 1
    sphere = trimesh.creation.icosphere(3)
    V, F = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    labels = segment(V, F, seed=0).labels
    alone = parameterize_charts(V, F, labels, config=SplitConfig(n_jobs=1)).charts
    assert len(uvs) == len(alone)
    assert all(np.array_equal(a, c.uv) for a, c in zip(uvs, alone, strict=True))
