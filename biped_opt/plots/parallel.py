"""Drawing several figures at once, each share in a forked copy of this process.

matplotlib draws one figure at a time and holds the interpreter while it does: a report's
Fig. 2 and Fig. 3 take 0.4 s and 0.25 s one after the other, mostly layout. :func:`draw_all`
runs the first share of the jobs here and every other share in a child made by ``fork``: the
child is this process as it stands (the figures' data, matplotlib and its fonts loaded), so a
job needs no pickling and the child no start-up. Each child sends back its share's results, or
the exception its share raised, pickled through a pipe, and ends with ``os._exit`` (this
process's exit handlers and buffered output are not its own). A child that ends without a whole
answer (killed, out of memory) has its share drawn again here, so the results are the same
whichever way they were made; an exception is raised here as the job raised it.

``fork`` copies only the calling thread, and any lock another thread held stays held in the
copy. :func:`draw_all` forks only when the caller asks for more than one process and Python
runs no thread but this one; the command line asks, a library caller that may run native
threads beside Python's (a ROS node's middleware) keeps the default of one process.
"""

from __future__ import annotations

import os
import pickle
import threading
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

__all__ = ["draw_all", "usable_processes"]

T = TypeVar("T")


def usable_processes() -> int:
    """The CPUs this process may run on (its affinity where the system has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # (no affinity on this system)
        return max(1, os.cpu_count() or 1)


def draw_all(jobs: Sequence[Callable[[], T]], processes: int = 1) -> list[T]:
    """Every job's result, in order: jobs k, k + n, k + 2n... in process k of
    n = min(processes, len(jobs)), process 0 being this one (module docstring)."""
    jobs = list(jobs)
    n = min(int(processes), len(jobs))
    if n <= 1 or not hasattr(os, "fork") or threading.active_count() > 1:
        return [job() for job in jobs]
    shares = [range(k, len(jobs), n) for k in range(n)]
    results: dict[int, Any] = {}
    children: list[tuple[range, int, int]] = []
    try:
        for share in shares[1:]:
            children.append((share, *_fork(jobs, share)))
        results.update((i, jobs[i]()) for i in shares[0])
        while children:
            share, pid, fd = children.pop(0)
            results.update(zip(share, _answer(jobs, share, pid, fd)))
    finally:
        for _share, pid, fd in children:  # (this process failed: its children end on their
            _read_all(fd)                 # own, their files whole, before the error goes on)
            os.waitpid(pid, 0)
    return [results[i] for i in range(len(jobs))]


def _fork(jobs: list[Callable[[], Any]], share: range) -> tuple[int, int]:
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: its share, its answer, and out without this process's exit
        try:
            os.close(read)
            try:
                payload = pickle.dumps(("done", [jobs[i]() for i in share]))
            except BaseException as exc:  # (sent back whole, KeyboardInterrupt too)
                try:
                    payload = pickle.dumps(("raised", exc))
                except Exception:  # (an exception that does not pickle: its text)
                    payload = pickle.dumps(("raised", RuntimeError(
                        f"{type(exc).__name__}: {exc}")))
            with os.fdopen(write, "wb") as pipe:
                pipe.write(payload)
        finally:
            os._exit(0)
    os.close(write)
    return pid, read


def _read_all(fd: int) -> bytes:
    with os.fdopen(fd, "rb") as pipe:
        return pipe.read()


def _answer(jobs: list[Callable[[], Any]], share: range, pid: int, fd: int) -> list[Any]:
    try:
        data = _read_all(fd)
    finally:
        os.waitpid(pid, 0)
    try:
        kind, value = pickle.loads(data)
    except Exception:  # (the child died before its whole answer was written)
        return [jobs[i]() for i in share]
    if kind == "raised":
        raise value
    return list(value)
