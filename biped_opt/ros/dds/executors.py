"""Executors on a Cyclone DDS WaitSet: ``SingleThreadedExecutor``, ``MultiThreadedExecutor``.

Each subscription, service and client contributes a ReadCondition to the executor's WaitSet; a
GuardCondition wakes the wait when nodes, timers or futures change; timers bound the wait time.
As in rclpy, ``spin_once`` runs at most one callback: ready work is queued and drained first.

``shutdown()`` stops a spin running in another thread and waits for it to return before it
releases anything (the thread pool, the WaitSet and its GuardCondition, deleted explicitly), so
no callback is scheduled on a pool that is gone and no DDS entity is left to the garbage
collector.
"""

from __future__ import annotations

import collections
import contextlib
import os
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from cyclonedds.core import DDSException, WaitSet

from . import context as _ctx
from .futures import Future
from .lifetime import delete_dds
from .log import Logger

__all__ = ["Executor", "SingleThreadedExecutor", "MultiThreadedExecutor",
           "spin", "spin_once", "spin_until_future_complete"]


class Executor:
    """Base executor: node set, WaitSet, ready queue."""

    def __init__(self, *, context: Any = None) -> None:
        self.context = context or _ctx.get_default_context()
        self._nodes: list[Any] = []
        self._lock = threading.RLock()
        self._ready: collections.deque[tuple[Any, Callable[[], Any]]] = collections.deque()
        self._waitset: WaitSet | None = None
        self._waitset_owner: Any = None
        self._guard: Any = None
        self._attached: dict[int, Any] = {}
        self._shutdown = False
        self._local = threading.local()
        self._spinners = 0  # threads inside spin() / spin_until_future_complete()
        self._idle = threading.Condition(self._lock)

    # node set
    def add_node(self, node: Any) -> bool:
        with self._lock:
            if node in self._nodes:
                return False
            self._nodes.append(node)
        self._wake()
        return True

    def remove_node(self, node: Any) -> None:
        with self._lock:
            if node in self._nodes:
                self._nodes.remove(node)
        self._wake()

    def get_nodes(self) -> list[Any]:
        return list(self._nodes)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        """Stop spinning: wake a spin in another thread and wait up to ``timeout_sec`` (None:
        for as long as it takes) until it has returned, then release the WaitSet. True when
        nothing spins any more (rclpy's contract)."""
        self._shutdown = True
        self._wake()
        with self._idle:
            stopped = self._idle.wait_for(
                lambda: self._spinners == 0 or self._in_callback(), timeout_sec)
        if stopped:
            self._release_waitset()
        return stopped

    def _in_callback(self) -> bool:
        """True when called from a thread that is spinning this executor (it cannot wait for
        itself to return)."""
        return getattr(self._local, "depth", 0) > 0

    def _release_waitset(self) -> None:
        with self._lock:
            waitset, guard = self._waitset, self._guard
            self._waitset = self._guard = self._waitset_owner = None
            self._attached.clear()
        if guard is not None:
            self.context.release_guard(guard)
        delete_dds(waitset, guard)

    def _wake(self) -> None:
        guard = self._guard
        if guard is not None:
            try:
                guard.set(True)
            except DDSException:
                pass  # guard of a participant that was shut down; replaced on next wait

    # waiting
    def _sync_waitset(self, entities: list[Any]) -> None:
        participant = self.context.participant
        if self._waitset is None or self._waitset_owner is not participant:
            # First use, or the context was re-initialised with a new participant.
            self._attached.clear()
            self._waitset_owner = participant
            self._waitset = WaitSet(participant)
            self._guard = self.context.new_guard()
            self._waitset.attach(self._guard)
            # a wake (shutdown, a finished future) that came before this guard existed found
            # nothing to set and was lost: the first wait returns at once, so the spin loop
            # looks at its flags again (without this, shutdown right after spin started could
            # leave the spinning thread waiting forever)
            self._guard.set(True)
        wanted = {id(e.condition): e.condition for e in entities if e.condition is not None}
        for key in list(self._attached):
            if key not in wanted:
                try:
                    self._waitset.detach(self._attached.pop(key))
                except Exception:  # condition already deleted with its reader
                    pass
        for key, cond in wanted.items():
            if key not in self._attached:
                self._waitset.attach(cond)
                self._attached[key] = cond

    def _collect(self, timeout_sec: float | None) -> None:
        """Wait until something is ready (or timeout) and queue its callbacks."""
        try:
            self._collect_unguarded(timeout_sec)
        except (DDSException, _ctx.NotInitializedError):
            # Another thread shut the context down (deleting the DDS entities) meanwhile.
            if self.context.ok():
                raise

    def _collect_unguarded(self, timeout_sec: float | None) -> None:
        if not self.context.ok():
            return
        with self._lock:
            entities = [e for node in self._nodes for e in node._waitables()]
        self._sync_waitset(entities)
        if self._shutdown:
            return
        timers = [e for e in entities if hasattr(e, "time_until_next_call")]
        wait_ns = None if timeout_sec is None or timeout_sec < 0 else int(timeout_sec * 1e9)
        for timer in timers:
            due = timer.time_until_next_call()
            if due is not None:
                wait_ns = max(due, 0) if wait_ns is None else min(wait_ns, max(due, 0))
        if threading.current_thread() is threading.main_thread():
            # Python runs signal handlers only between bytecodes: wake up now and then so that
            # Ctrl-C (KeyboardInterrupt) and SIGTERM handlers reach a main thread that spins.
            wait_ns = _SIGNAL_SLICE_NS if wait_ns is None else min(wait_ns, _SIGNAL_SLICE_NS)
        # A WaitSet timeout is an int64 of nanoseconds; "forever" is the maximum.
        self._waitset.wait(wait_ns if wait_ns is not None else (1 << 63) - 1)
        self._guard.take()
        if not self.context.ok():
            return
        for entity in entities:
            if hasattr(entity, "time_until_next_call"):
                pass  # a timer: its _take decides
            elif not entity._triggered():
                continue  # nothing new; a publisher; or destroyed while the executor waited
            for task in entity._take():
                self._ready.append((entity.callback_group, task))

    def _next_task(self, timeout_sec: float | None) -> tuple[Any, Callable[[], Any]] | None:
        if not self._ready:
            self._collect(timeout_sec)
        return self._ready.popleft() if self._ready else None

    # spinning
    def spin_once(self, timeout_sec: float | None = None) -> None:
        with self._spinning():
            task = self._next_task(timeout_sec)
            if task is not None:
                self._run(*task)

    def _run(self, group: Any, task: Callable[[], Any]) -> None:
        task()

    @contextlib.contextmanager
    def _spinning(self) -> Iterator[None]:
        with self._lock:
            self._spinners += 1
        self._local.depth = getattr(self._local, "depth", 0) + 1
        try:
            yield
        finally:
            self._local.depth -= 1
            with self._idle:
                self._spinners -= 1
                self._idle.notify_all()

    def spin(self) -> None:
        with self._spinning():
            while self.context.ok() and not self._shutdown:
                self.spin_once()

    def spin_until_future_complete(self, future: Future, timeout_sec: float | None = None
                                   ) -> None:
        future.add_done_callback(lambda _f: self._wake())
        deadline = None if timeout_sec is None else time.monotonic() + timeout_sec
        with self._spinning():
            while self.context.ok() and not future.done() and not self._shutdown:
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0:
                    return
                self.spin_once(remaining)


#: longest uninterrupted wait of a main-thread executor [ns]
_SIGNAL_SLICE_NS = 100_000_000


class SingleThreadedExecutor(Executor):
    """Runs every callback in the spinning thread."""


#: logs what a callback on a pool thread raised (else the pool's future would keep it unseen)
_LOG = Logger("executor")


def _report(exc: BaseException) -> None:
    """One line (at most one a second) for an exception that left a callback on a pool thread:
    its type, message and where it was raised."""
    frames = traceback.extract_tb(exc.__traceback__)
    where = f" at {frames[-1].filename}:{frames[-1].lineno}" if frames else ""
    _LOG.error(f"a callback raised {type(exc).__name__}: {str(exc)[:200]}{where}",
               throttle_duration_sec=1.0)


class MultiThreadedExecutor(Executor):
    """Runs callbacks on a thread pool; a MutuallyExclusiveCallbackGroup serialises its own.
    An exception that leaves a callback is logged (:func:`_report`) and the pool serves on:
    rclpy re-raises it from ``spin``, which would end every other callback's service with it."""

    def __init__(self, num_threads: int | None = None, *, context: Any = None) -> None:
        super().__init__(context=context)
        self._pool = ThreadPoolExecutor(max_workers=num_threads or os.cpu_count() or 2)

    def _run(self, group: Any, task: Callable[[], Any]) -> None:
        if self._shutdown:
            return  # shutting down: work that was ready but not started is dropped
        lock = getattr(group, "lock", None)

        def call() -> None:
            self._local.worker = True
            try:
                if lock is None:
                    task()
                else:
                    with lock:
                        task()
            except Exception as exc:  # (the pool's future would keep it where nobody looks)
                _report(exc)
            finally:
                self._wake()  # let the spinning thread see completed futures at once
        self._pool.submit(call)

    def spin_once(self, timeout_sec: float | None = None) -> None:
        # Dispatch everything that is ready, not just one callback, to keep workers busy.
        with self._spinning():
            task = self._next_task(timeout_sec)
            while task is not None:
                self._run(*task)
                task = self._ready.popleft() if self._ready else None

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        """Stop spinning (see :meth:`Executor.shutdown`), drop queued callbacks and wait for
        the running ones."""
        stopped = super().shutdown(timeout_sec)
        # a callback that shuts its own executor down cannot wait for itself to finish
        waits = not (self._in_callback() or getattr(self._local, "worker", False))
        self._pool.shutdown(wait=waits, cancel_futures=True)
        return stopped


def _executor_for(node: Any, executor: Executor | None) -> Executor:
    if executor is not None:
        return executor
    ctx = node.context
    if getattr(ctx, "_global_executor", None) is None:
        ctx._global_executor = SingleThreadedExecutor(context=ctx)
    return ctx._global_executor


def spin_once(node: Any, *, executor: Executor | None = None,
              timeout_sec: float | None = None) -> None:
    ex = _executor_for(node, executor)
    added = ex.add_node(node)
    try:
        ex.spin_once(timeout_sec=timeout_sec)
    finally:
        if added:
            ex.remove_node(node)


def spin(node: Any, executor: Executor | None = None) -> None:
    ex = _executor_for(node, executor)
    added = ex.add_node(node)
    try:
        while node.context.ok() and not ex._shutdown:
            ex.spin_once()
    finally:
        if added:
            ex.remove_node(node)


def spin_until_future_complete(node: Any, future: Future, executor: Executor | None = None,
                               timeout_sec: float | None = None) -> None:
    ex = _executor_for(node, executor)
    added = ex.add_node(node)
    try:
        ex.spin_until_future_complete(future, timeout_sec)
    finally:
        if added:
            ex.remove_node(node)
