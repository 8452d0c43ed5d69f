"""``study_coordinator`` node: a parameter study fanned out over the optimiser nodes of the domain.

A work item is a few parameter points of a :class:`~biped_opt.studies.study.Study` (up to
:data:`BATCH`, fewer as the queue runs short). Every optimiser node serves them on a service of
its own, ``~/study/<worker>`` of type ``StudyPoint`` (the study as JSON and the points' indices
in; their rows as JSON out). The coordinator finds those services
through DDS discovery (:meth:`StudyCoordinator.workers`: any node, any host of the domain, also
one that starts mid-study), keeps ``in_flight`` requests at each (the next waits in the node's
queue while it computes one, so no node idles for a round trip), and writes each point's rows to
the same CSV table as a local run (:class:`biped_opt.record.study_table.StudyTable`: resumable,
every point exactly once).

An item comes back to the queue, for another node, when its node disappears from discovery (it
was stopped, or its DDS lease expired) or does not answer within ``item_timeout`` seconds; such a
node gets no more items until it answers one. A late answer to an item done meanwhile is ignored.
A refused item (``success = false``: a bad study, or a point the core cannot compute) ends the
study with the node's message: every node would refuse it.

An item a node answers with ``busy: ...`` (it is compiling the study's system,
:mod:`biped_opt.nodes.compiler`) goes back to the queue, and that node gets items again after
:data:`RETRY_S`.

The study is served as the ROS 2 action ``/biped/study`` (``Study.action``: goal the study and the
table, feedback points done/total and the last point, result the file names and a summary;
cancel ends it after the items under way), and :meth:`StudyCoordinator.run_study` runs one from
Python.

A goal is a request from anyone on the domain, so it chooses nothing outside what the operator
configured: its study names a library system or one in the parameter ``system_paths`` (and a
declared problem or one in those directories; :mod:`biped_opt.nodes.sources`), never a path, and
it is bounded by ``max_points``, ``max_num``, ``max_values`` and ``max_request_chars`` (checked
before anything is built); its ``out`` is a plain file name, the table written as
``<output_dir>/<out>`` and ``<out>.study.json`` beside it (parameter ``output_dir``, default
(also ``""``) ``$XDG_DATA_HOME/biped_opt/studies``, made when first needed). The work items name
the system and problem the same way (a file's stem), and each optimiser resolves them in its own
``system_paths``.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import json
import math
import os
import queue
import re
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from biped_opt import ros
from biped_opt.errors import BipedOptError, InvalidInputError, InvalidParameterError, quoted
from biped_opt.nodes.compiler import BUSY, run_check
from biped_opt.nodes.parameters import float_parameter, int_parameter
from biped_opt.nodes.refusals import answers, public, refusal
from biped_opt.nodes.run import announce_ready
from biped_opt.nodes.sources import (
    check_name,
    declare_request_limits,
    name_of,
    request_study,
)
from biped_opt.record.study_table import StudySummary, StudyTable, spec_path
from biped_opt.studies.study import Study, StudyRow

__all__ = ["StudyCoordinator", "StudyFailedError", "WORK_ITEM_TYPE", "encode_rows",
           "decode_rows", "coordinator_on_domain", "run_on_domain", "main"]

#: the ROS type of the work-item services the coordinator looks for
WORK_ITEM_TYPE = "biped_opt_interfaces/srv/StudyPoint"
#: defaults of the parameters item_timeout [s], in_flight, discovery_period [s]
ITEM_TIMEOUT_S, IN_FLIGHT, DISCOVERY_PERIOD_S = 300.0, 2, 0.5
#: most points in one request
BATCH = 16
#: how long a node that answered ``busy`` gets no items [s]
RETRY_S = 1.0
#: a goal's ``out``: a plain file name (no directory, not hidden)
OUT_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}")


def default_output_dir() -> Path:
    """``$XDG_DATA_HOME/biped_opt/studies`` (default ``~/.local/share/biped_opt/studies``)."""
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "biped_opt" / "studies"


def wire_spec(study: Study) -> str:
    """The study of a work item: its system and problem by name (a file by its stem), as a
    request names them; each optimiser resolves them in its own ``system_paths``."""
    spec = study.as_dict()
    spec["system"] = name_of(study.system)
    if study.problem is not None:
        spec["problem"] = name_of(study.problem)
    return json.dumps(spec)


class StudyFailedError(BipedOptError, RuntimeError):
    """A node refused a work item (its message says why); the study stops there."""


def encode_rows(rows: Iterable[StudyRow]) -> str:
    """A point's rows as JSON (NaN as the ``NaN`` token Python's json reads back)."""
    return json.dumps([dataclasses.asdict(r) for r in rows])


def decode_rows(text: str, indices: Iterable[int]) -> dict[int, list[StudyRow]]:
    """The rows :func:`encode_rows` wrote, by point, checked to hold every point of
    ``indices`` and no other."""
    wanted = list(indices)
    try:
        rows = [StudyRow(**{**d, "parameters": tuple((str(k), float(v))
                                                      for k, v in d["parameters"])})
                for d in json.loads(text)]
    except (ValueError, TypeError, KeyError) as exc:
        raise StudyFailedError(f"points {wanted}: the node's rows do not decode ({exc})") from None
    by_point: dict[int, list[StudyRow]] = {i: [] for i in wanted}
    for row in rows:
        if row.point not in by_point:
            raise StudyFailedError(f"points {wanted}: the node answered with rows of point "
                                   f"{row.point}")
        by_point[row.point].append(row)
    missing = [i for i, r in by_point.items() if not r]
    if missing:
        raise StudyFailedError(f"points {wanted}: the node's answer has no rows of {missing}")
    return by_point


@dataclasses.dataclass
class _Worker:
    """One work-item service: its client, the items sent to it (index -> time sent)."""

    name: str
    client: Any
    items: dict[int, float] = dataclasses.field(default_factory=dict)
    requests: int = 0  #: requests sent and not answered
    ready: bool = False
    stalled: bool = False  #: an item timed out: no new items until it answers one
    resting_until: float = 0.0  #: it answered busy: no new items before then (monotonic)


class StudyCoordinator(ros.Node):
    """Runs studies on the optimiser nodes of the domain (see the module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("study_coordinator", **kwargs)
        self._action: Any = None
        self.declare_parameter("item_timeout", ITEM_TIMEOUT_S)
        self.declare_parameter("in_flight", IN_FLIGHT)
        self.declare_parameter("discovery_period", DISCOVERY_PERIOD_S)
        self.declare_parameter("output_dir", str(default_output_dir()))
        self.item_timeout = float_parameter(self, "item_timeout")
        self.in_flight = int_parameter(self, "in_flight", 1)
        self.discovery_period = float_parameter(self, "discovery_period")
        self._sources, self._study_limits, self._max_request = declare_request_limits(self)
        output = str(self.get_parameter("output_dir").value).strip()
        self.output_dir = Path(output or default_output_dir()).expanduser().resolve()
        if self.output_dir.exists() and not self.output_dir.is_dir():
            raise InvalidParameterError(f"output_dir: {output} is not a directory")
        #: what replies to peers never show (biped_opt.nodes.refusals.public)
        self.private_paths = (*self._sources.system_paths, self.output_dir)
        self._group = ros.ReentrantCallbackGroup()
        self._busy = threading.Lock()  # one study at a time
        #: dispatches per point in the last study (a re-dispatched point counts twice), and the
        #: points each work-item service computed for the table
        self.dispatches: collections.Counter[int] = collections.Counter()
        self.served: dict[str, list[int]] = {}
        #: the compute time the nodes reported for the points written [s]
        self.node_seconds = 0.0
        self._action: Any = ros.ActionServer(
            self, ros.actions.Study, "/biped/study", self._execute,
            goal_callback=self._on_goal, cancel_callback=lambda _: ros.CancelResponse.ACCEPT,
            callback_group=self._group)
        announce_ready(self, serves=("/biped/study",),
                       calls=("~/study/* of the optimiser nodes",))

    def workers(self) -> list[str]:
        """The work-item services on the domain now."""
        return [name for name, kinds in self.get_service_names_and_types()
                if WORK_ITEM_TYPE in kinds]

    def run_study(self, study: Study, path: Path, *,
                  progress: Callable[[int, int, int], None] | None = None,
                  stop: Callable[[], bool] | None = None) -> StudySummary:
        """Compute every point of ``study`` not yet in the table at ``path`` on the optimiser
        nodes; ``progress(done, total, index)`` after each point written; ``stop()`` true ends
        the run (the table stays resumable). Another thread must spin this node (a
        multi-threaded executor when called from one of its callbacks)."""
        if not self._busy.acquire(blocking=False):
            raise StudyFailedError("this coordinator is running another study")
        try:
            return _Run(self, study, path, progress, stop).run()
        finally:
            self._busy.release()

    # -- the action ----------------------------------------------------------------------------
    def _on_goal(self, goal: Any) -> Any:
        if self._busy.locked():
            self.get_logger().warning("rejected a study goal: a study is running")
            return ros.GoalResponse.REJECT
        return ros.GoalResponse.ACCEPT

    def goal_study(self, text: str) -> Study:
        """The study of a goal (JSON or YAML): bounded by the node's limits, then its system
        and problem resolved by name (see the module docstring) and the study built and
        checked in a compile process (:func:`biped_opt.nodes.compiler.run_check`): describing
        a system runs its file's code, which never runs in this node."""
        spec = request_study(text, self._max_request, yaml_too=True)
        fields = Study.fields_from_spec(spec, where="study", limits=self._study_limits)
        try:  # (what needs no code run is refused here, without a process)
            self._sources.system("system", fields["system"])
            if fields["problem"]:
                check_name("problem", fields["problem"], "problem")
        except BipedOptError as exc:
            raise InvalidInputError(f"study: {exc}") from None
        try:
            wire = json.loads(json.dumps(spec))
        except (TypeError, ValueError):
            raise InvalidInputError("study: holds values JSON cannot carry") from None
        resolved = run_check({
            "spec": wire, "system_paths": [str(p) for p in self._sources.system_paths],
            "max_legs": self._sources.limits.max_legs,
            "max_coordinates": self._sources.limits.max_coordinates,
            "study_limits": dataclasses.asdict(self._study_limits)})
        fields["system"], fields["problem"] = resolved["system"], resolved["problem"]
        return Study.described_elsewhere(**fields)

    @staticmethod
    def check_out(out: str) -> str:
        """A goal's ``out``, if it is a plain file name."""
        if not isinstance(out, str) or not OUT_NAME.fullmatch(out):
            raise InvalidInputError(
                f"out: {quoted(out)} is not a plain file name (letters, digits, _ . -; at most "
                "128): the table goes into the node's output_dir")
        return out

    def goal_table(self, out: str) -> Path:
        """Where a goal's table goes: ``out`` a plain file name in ``output_dir``."""
        self.output_dir.mkdir(parents=True, exist_ok=True)
        return self.output_dir / self.check_out(out)

    def _execute(self, goal_handle: Any) -> Any:
        """A goal: the study (JSON or YAML) into the table ``out``; feedback after each point;
        a cancel ends it after the points under way (the table stays resumable)."""
        result = ros.actions.Study.Result()
        goal = goal_handle.request
        try:
            self.check_out(goal.out)  # (before the study's check, which takes a process)
            study = self.goal_study(goal.study)
            table = self.goal_table(goal.out)
            points = study.points()

            def progress(done: int, total: int, index: int) -> None:
                goal_handle.publish_feedback(ros.actions.Study.Feedback(
                    done=done, total=total, current_point=index,
                    current=point_values(points, index)))

            summary = self.run_study(study, table, progress=progress,
                                     stop=lambda: goal_handle.is_cancel_requested)
        except BaseException as exc:  # a bad goal, or a bug: one failed goal either way
            if not answers(exc):
                raise
            message = refusal(exc)
            self.get_logger().warning(f"study goal failed: {message}")
            result.success, result.message = False, public(message, self.private_paths)
            goal_handle.abort()
            return result
        result.success = not summary.stopped
        result.message = "done" if result.success else "stopped before every point was done"
        # (by name: where the node keeps its files is not the domain's business)
        result.table, result.spec = summary.path.name, spec_path(summary.path).name
        result.points, result.computed = summary.points, summary.computed
        result.resumed, result.rows, result.stopped = summary.resumed, summary.rows, \
            summary.stopped
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
        else:
            goal_handle.succeed()
        return result

    def destroy_node(self) -> None:
        if getattr(self, "_action", None) is not None:
            self._action.destroy()
            self._action = None
        super().destroy_node()


class _Run:
    """One study on the coordinator (the dispatch loop of the module docstring)."""

    def __init__(self, node: StudyCoordinator, study: Study, path: Path,
                 progress: Callable[[int, int, int], None] | None,
                 stop: Callable[[], bool] | None) -> None:
        self.node, self.study = node, study
        self.table = StudyTable(study, Path(path))
        self.spec = wire_spec(study)
        self.queue: collections.deque[int] = collections.deque(self.table.pending())
        self.events: queue.SimpleQueue[tuple[str, int, Any]] = queue.SimpleQueue()
        self.workers: dict[str, _Worker] = {}
        self.progress, self.stop = progress, stop
        node.dispatches, node.served, node.node_seconds = collections.Counter(), {}, 0.0
        self._waiting_logged = False

    def run(self) -> StudySummary:
        total = len(self.table.points)
        stopped = False
        next_discovery = 0.0
        try:
            while len(self.table.done) < total:
                if self.stop is not None and self.stop():
                    stopped = True
                    break
                now = time.monotonic()
                if now >= next_discovery:
                    self._discover()
                    next_discovery = now + self.node.discovery_period
                self._expire(now)
                self._dispatch()
                try:
                    event = self.events.get(timeout=min(0.05, self.node.discovery_period))
                except queue.Empty:
                    continue
                self._handle(*event)
                while True:  # everything else that arrived meanwhile
                    try:
                        event = self.events.get_nowait()
                    except queue.Empty:
                        break
                    self._handle(*event)
        finally:
            for worker in self.workers.values():
                self.node.destroy_client(worker.client)
        return self.table.summary(stopped)

    # -- the nodes -----------------------------------------------------------------------------
    def _discover(self) -> None:
        names = set(self.node.workers())
        for name in sorted(set(self.workers) - names):
            worker = self.workers.pop(name)
            if worker.items:
                self.node.get_logger().warning(
                    f"{name} disappeared with {len(worker.items)} item(s): sent to other nodes")
            for index in worker.items:
                self._requeue(index)
            self.node.destroy_client(worker.client)
        for name in sorted(names - set(self.workers)):
            client = self.node.create_client(ros.srvs.StudyPoint, name,
                                             callback_group=self.node._group)
            self.workers[name] = _Worker(name, client)
            self.node.get_logger().info(f"{name} joined the study")
        if not self.workers and not self._waiting_logged:
            self.node.get_logger().info("waiting for optimiser nodes (none on the domain yet)")
            self._waiting_logged = True

    def _expire(self, now: float) -> None:
        for worker in self.workers.values():
            for index, sent in list(worker.items.items()):
                if now - sent > self.node.item_timeout:
                    del worker.items[index]
                    worker.stalled = True
                    self.node.get_logger().warning(
                        f"{worker.name}: no answer for point {index} in "
                        f"{self.node.item_timeout:g} s: sent to another node")
                    self._requeue(index)

    def _requeue(self, index: int) -> None:
        if index in self.table.done or index in self.queue:
            return
        if any(index in w.items for w in self.workers.values()):
            return
        self.queue.appendleft(index)

    def _batch(self, ready: int) -> int:
        """Points per request: up to BATCH (the round trip's cost spread over them), fewer as
        the queue runs short, so that the last points still spread over every node."""
        share = len(self.queue) // max(1, 2 * self.node.in_flight * ready)
        return max(1, min(BATCH, share))

    def _dispatch(self) -> None:
        # round robin by load: the least loaded ready node gets the next request
        while self.queue:
            now = time.monotonic()
            ready = [w for w in self.workers.values()
                     if not w.stalled and w.requests < self.node.in_flight
                     and w.resting_until <= now and self._ready(w)]
            if not ready:
                return
            worker = min(ready, key=lambda w: w.requests)
            indices = []
            while self.queue and len(indices) < self._batch(len(ready)):
                index = self.queue.popleft()
                if index not in self.table.done:
                    indices.append(index)
            if not indices:
                continue
            request = ros.srvs.StudyPoint.Request(study=self.spec, indices=indices)
            now = time.monotonic()
            for index in indices:
                worker.items[index] = now
                self.node.dispatches[index] += 1
            worker.requests += 1
            future = worker.client.call_async(request)
            future.add_done_callback(
                lambda f, n=worker.name, i=tuple(indices): self.events.put((n, i, f)))

    @staticmethod
    def _ready(worker: _Worker) -> bool:
        if not worker.ready:
            worker.ready = worker.client.service_is_ready()
        return worker.ready

    # -- answers -------------------------------------------------------------------------------
    def _handle(self, name: str, indices: tuple[int, ...], future: Any) -> None:
        worker = self.workers.get(name)
        if worker is not None:
            for index in indices:
                worker.items.pop(index, None)
            worker.requests -= 1
            worker.stalled = False
        if future.cancelled() or future.exception() is not None:
            for index in indices:  # its client was destroyed (node gone) or the reply was bad
                self._requeue(index)
            return
        response = future.result()
        if all(index in self.table.done for index in indices):
            return  # a late answer to items other nodes did meanwhile
        if not response.success and response.message.startswith(BUSY):
            if worker is not None:  # compiling the study's system: ask again soon
                worker.resting_until = time.monotonic() + RETRY_S
            for index in indices:
                self.node.dispatches[index] -= 1  # (not computed: it counts when it is)
                self._requeue(index)
            return
        if not response.success:
            raise StudyFailedError(f"points {list(indices)} failed on {name}: "
                                   f"{response.message}")
        rows = decode_rows(response.rows, indices)
        self.node.node_seconds += response.seconds
        for index in indices:
            if self.table.append(rows[index]):
                self.node.served.setdefault(name, []).append(index)
                if self.progress is not None:
                    self.progress(len(self.table.done), len(self.table.points), index)


def point_values(study_points: list[dict[str, float]], index: int) -> str:
    """The parameter values of point ``index`` as JSON (the action's feedback)."""
    if not 0 <= index < len(study_points):
        return "{}"
    return json.dumps({k: (v if math.isfinite(v) else None)
                       for k, v in study_points[index].items()})


@contextlib.contextmanager
def hosted(make: Callable[[Any], Any], domain_id: int | None = None, *, threads: int = 2,
           name: str = "node") -> Iterator[Any]:
    """The node ``make(context)`` on a DDS participant and executor thread of its own (what
    another machine would run) for the ``with`` block, torn down at its end."""
    context = ros.Context()
    ros.init(args=[], context=context, domain_id=domain_id)
    try:
        node = make(context)
    except BaseException:
        ros.try_shutdown(context=context)
        raise
    executor = ros.MultiThreadedExecutor(num_threads=threads, context=context)
    executor.add_node(node)
    thread = threading.Thread(target=executor.spin, name=name, daemon=True)
    thread.start()
    try:
        yield node
    finally:
        executor.shutdown(timeout_sec=10)
        thread.join(10)
        node.destroy_node()
        ros.try_shutdown(context=context)


def coordinator_on_domain(domain_id: int | None = None,
                          parameters: dict[str, Any] | None = None
                          ) -> contextlib.AbstractContextManager[StudyCoordinator]:
    """A coordinator of its own (:func:`hosted`) with ``parameters``."""
    return hosted(lambda context: StudyCoordinator(context=context, parameter_overrides=[
        ros.Parameter(k, value=v) for k, v in (parameters or {}).items()]),
        domain_id, threads=2, name="study-coordinator")


def run_on_domain(study: Study, path: Path, *, domain_id: int | None = None,
                  parameters: dict[str, Any] | None = None,
                  progress: Callable[[int, int, int], None] | None = None,
                  stop: Callable[[], bool] | None = None) -> StudySummary:
    """Run ``study`` on the optimiser nodes of the domain from a coordinator of its own."""
    with coordinator_on_domain(domain_id, parameters) as node:
        return node.run_study(study, path, progress=progress, stop=stop)


def main(args: list[str] | None = None) -> None:
    from biped_opt.nodes.run import run_node

    run_node(StudyCoordinator, args, threads=4)


if __name__ == "__main__":
    main()
