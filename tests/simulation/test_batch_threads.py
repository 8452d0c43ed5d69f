"""How a batch shares its cases out between threads (docs/SYSTEMS.md Sec. 1: a batch is single
calls, run in parallel): the thread count from the work and the cores, every case run exactly
once, and a threaded batch equal to single calls to the last bit."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from biped_opt.simulation import compiled
from biped_opt.simulation.compiled import (
    MIN_CASES_PER_THREAD,
    batch_threads,
    compile_system,
    run_batch,
)


@pytest.mark.parametrize(("n", "cores", "threads"), [
    (0, 2, 1), (1, 2, 1), (2 * MIN_CASES_PER_THREAD - 1, 2, 1), (2 * MIN_CASES_PER_THREAD, 2, 2),
    (10_000, 2, 2), (10_000, 1, 1), (10_000, 8, 8), (3 * MIN_CASES_PER_THREAD, 8, 3)])
def test_threads_follow_the_work_and_the_cores(n, cores, threads):
    """One thread per MIN_CASES_PER_THREAD cases (a thread's start costs about a trajectory),
    never more than the cores the process may use."""
    assert batch_threads(n, cores) == threads


def test_the_default_is_the_process_affinity(monkeypatch):
    monkeypatch.setattr(compiled.os, "sched_getaffinity", lambda pid: {0, 3, 5}, raising=False)
    assert compiled.available_cores() == 3
    assert batch_threads(10_000) == 3


@pytest.mark.parametrize("n", [0, 1, 7, 64, 1000])
@pytest.mark.parametrize("threads", [1, 2, 3, 5])
def test_every_case_runs_once(n, threads):
    """The pieces cover 0..n-1 without gap or overlap, whichever thread takes which."""
    seen = np.zeros(n, dtype=int)
    names = set()
    lock = threading.Lock()

    def kernel(out, start, stop):
        with lock:
            out[start:stop] += 1
            names.add(threading.current_thread().name)

    run_batch(kernel, n, (seen,), threads=threads)
    assert (seen == 1).all()
    assert len(names) <= threads


def test_an_error_in_a_thread_reaches_the_caller():
    def kernel(start, stop):
        if start > 0:
            raise ValueError("piece failed")

    with pytest.raises(ValueError, match="piece failed"):
        run_batch(kernel, 100, (), threads=2)


def test_a_threaded_batch_is_single_calls_to_the_last_bit():
    """64 cases, so two threads on two cores (and the pieces interleave): each row equals the
    single call with the same s and inputs, bit for bit (the threads write disjoint rows)."""
    bar = compile_system("rocking_bar")
    s = np.linspace(-0.3, 0.3, 64)
    batch = bar.simulate_batch("drop", s)
    assert batch_threads(s.size, 2) == 2
    for k in range(s.size):
        one = bar.simulate("drop", s[k])
        assert batch.outcome[k] == one.outcome and batch.t_final[k] == one.t_final
        assert batch.statuses()[k] is one.status and batch.nfev[k] == one.nfev
        np.testing.assert_array_equal(batch.event_times(k), one.event_times)


def test_a_thread_limit_holds_for_its_thread_only():
    """batch_thread_limit (what an optimiser node computing study points uses: one core per
    node) caps this thread's batches and no other thread's."""
    from biped_opt.simulation.compiled import batch_thread_limit

    seen = {}
    with batch_thread_limit(1):
        seen["inside"] = batch_threads(10_000, 8)
        other = threading.Thread(target=lambda: seen.update(other=batch_threads(10_000, 8)))
        other.start()
        other.join()
    seen["after"] = batch_threads(10_000, 8)
    assert seen == {"inside": 1, "other": 8, "after": 8}
