"""Systems compiled beside a node's service, never on the threads that answer requests.

A first request for a system the node has not prepared is answered at once (``success =
false``, ``busy: system X is being compiled (k in queue); retry``) and queued. One background
thread takes the queue in order: a separate process (``python -m biped_opt.nodes.compiler``,
killed when the node stops) describes the system, checks its size, derives, generates and
compiles it into the on-disk cache and runs the calls a request will make (so their machine code
is cached too); then the thread loads the result into the node's process (from the cache: about
a second) and later requests are served. The queue holds at most ``compile_queue`` systems
(parameter); a system whose preparation failed is refused with the reason from then on.
"""

from __future__ import annotations

import collections
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Hashable
from pathlib import Path
from typing import Any

from biped_opt import children
from biped_opt.errors import BipedOptError, InvalidInputError
from biped_opt.nodes.refusals import failure_message
from biped_opt.nodes.sources import Names, Sources, SystemLimits

__all__ = ["BUSY", "Busy", "Compiler", "prepare", "check_study", "run_check", "main"]

#: the start of a refusal that a retry may cure (a client or coordinator waits and asks again)
BUSY = "busy: "
#: longest a compile process may run [s] (default of the parameter compile_timeout)
COMPILE_TIMEOUT_S = 900.0


class Busy(BipedOptError, RuntimeError):
    """The system of a request is being prepared; its message starts with :data:`BUSY`."""


def _sources(job: dict[str, Any]) -> Sources:
    return Sources(tuple(Path(p) for p in job["system_paths"]),
                   SystemLimits(max_legs=job["max_legs"],
                                max_coordinates=job["max_coordinates"]))


def prepare(job: dict[str, Any]) -> Any:
    """Build and exercise what a job names (in the compile process, then in the node):
    ``kind`` "policy" (an OptimalPolicy request's names, as :meth:`Sources.check_request`
    resolved them: returns its Problem), "study" (a study's system and problem: returns
    None) or "urdf" (a robot's URDF text, ``urdf``: returns its CompiledSystem)."""
    sources = _sources(job)
    if job["kind"] == "urdf":  # a robot spawned from its URDF text: its CompiledSystem
        from biped_opt.systems.urdf import parse_urdf, system_from_urdf

        system = system_from_urdf(parse_urdf(job["urdf"], source="resource_string"))
        sources.limits.check("resource_string", system)
        from biped_opt.simulation.compiled import CompiledSystem

        compiled = CompiledSystem(system)
        for maneuver in compiled.maneuvers:
            compiled.simulate(maneuver, 0.0)
        return compiled
    if job["kind"] == "policy":
        problem = sources.problem(Names(**job["names"]))
    else:  # a study: the fixed-input kernels, and its problem's if it has one
        from biped_opt.control.problems import load_problem

        source, problem_source = sources.study(job["system"], job["problem"])
        problem = None if problem_source is None else load_problem(problem_source,
                                                                   system=source)
        if problem is not None:
            sources.limits.check("problem", problem.description)
    # (only now the compiler's modules: a description that fails has failed already)
    import numpy as np

    from biped_opt.analysis.nonsmooth import find_nonsmooth
    from biped_opt.control.solve import compiled_for, optimal_policy
    from biped_opt.control.theorem1 import value_slopes
    from biped_opt.simulation.compiled import compiled_with

    if job["kind"] == "study":
        compiled = compiled_with(source)
        for maneuver in compiled.maneuvers:
            compiled.simulate(maneuver, 0.0)
        if compiled.maneuvers:
            find_nonsmooth(compiled, compiled.maneuvers[0], s=np.linspace(-0.1, 0.1, 5))
    if problem is not None:  # the optimiser's calls
        compiled_for(problem).simulate(problem.maneuver, 0.0)
        try:
            result = optimal_policy(problem, 0.05)
            if result.success:
                value_slopes(problem, result)
        except BipedOptError:
            pass  # (s = 0.05 is only an exercise: a point it cannot solve proves nothing)
    return problem if job["kind"] == "policy" else None


class Compiler:
    """The queue and the background thread of a node (see the module docstring)."""

    def __init__(self, logger: Any, *, queue_size: int, timeout: float = COMPILE_TIMEOUT_S
                 ) -> None:
        self._logger = logger
        self.queue_size, self.timeout = queue_size, timeout
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._ready: dict[Hashable, Any] = {}
        self._failed: dict[Hashable, str] = {}
        self._queue: collections.deque[tuple[Hashable, str, dict[str, Any]]] = \
            collections.deque()
        self._current: Hashable | None = None
        self._process: subprocess.Popen | None = None
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="system-compiler", daemon=True)
        self._thread.start()

    def get(self, key: Hashable, what: str, job: dict[str, Any]) -> Any:
        """What ``job`` prepared for ``key``; else queue it and raise :class:`Busy` (or the
        reason it failed)."""
        with self._lock:
            if key in self._ready:
                return self._ready[key]
            if key in self._failed:
                raise InvalidInputError(self._failed[key])
            waiting = [k for k, _, _ in self._queue]
            if key == self._current:
                raise Busy(f"{BUSY}{what} is being compiled ({len(waiting)} in queue behind "
                           "it); retry")
            if key in waiting:
                raise Busy(f"{BUSY}{what} is waiting to be compiled ({waiting.index(key) + 1} "
                           f"of {len(waiting)} in queue); retry")
            if self.queue_size < 1 or len(self._queue) >= self.queue_size:
                raise Busy(f"{BUSY}{what} needs a compile and the compile queue is full "
                           f"({len(self._queue)} of compile_queue = {self.queue_size}); retry "
                           "later")
            self._queue.append((key, what, job))
            self._wake.notify()
            position = len(self._queue) + (self._current is not None)
        self._logger.info(f"queued a compile of {what} ({position} in queue)")
        raise Busy(f"{BUSY}{what} is being compiled ({position} in queue); retry")

    def prepare_now(self, key: Hashable, job: dict[str, Any]) -> Any:
        """Prepare ``job`` in this thread (start-up: the parameter ``systems``)."""
        value = prepare(job)
        with self._lock:
            self._ready[key] = value
        return value

    def close(self) -> None:
        """Stop the thread and kill a compile under way."""
        with self._lock:
            self._closed = True
            self._queue.clear()
            self._wake.notify()
            process = self._process
        if process is not None and process.poll() is None:
            _kill(process)

    # -- the background thread ---------------------------------------------------------------
    def _run(self) -> None:
        try:  # (SymPy and the systems' modules: a first request need not wait for them)
            import biped_opt.control.problems  # noqa: F401
        except Exception:  # pragma: no cover (the same error reaches the first request)
            pass
        while True:
            with self._lock:
                while not self._queue and not self._closed:
                    self._wake.wait()
                if self._closed:
                    return
                key, what, job = self._queue.popleft()
                self._current = key
            start = time.monotonic()
            try:
                self._compile(what, job)
                value = prepare(job)  # from the cache the process filled
            except BaseException as exc:  # (a system file's SystemExit too): the reason
                message = failure_message(exc, what)
                with self._lock:
                    self._failed[key], self._current = message, None
                self._logger.warning(f"cannot compile {what}: {message}")
                continue
            with self._lock:
                self._ready[key], self._current = value, None
            self._logger.info(f"compiled {what} in {time.monotonic() - start:.1f} s")

    def _compile(self, what: str, job: dict[str, Any]) -> None:
        with self._lock:
            if self._closed:
                raise InvalidInputError(f"{what}: the node is stopping")
            # (-P and a working directory of the node's own: biped_opt.children)
            self._process = process = children.popen(
                "biped_opt.nodes.compiler", json.dumps(job), stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                start_new_session=True)
        try:
            _, err = process.communicate(timeout=self.timeout)
        except subprocess.TimeoutExpired:
            _kill(process)
            process.communicate()
            raise InvalidInputError(
                f"{what}: the compile took more than {self.timeout:g} s (compile_timeout)"
            ) from None
        finally:
            with self._lock:
                self._process = None
        if process.returncode != 0:
            lines = [line for line in (err or "").splitlines() if line.strip()]
            reason = lines[-1] if lines and process.returncode == 2 else \
                f"the compile process ended with status {process.returncode}"
            raise InvalidInputError(reason)


def _kill(process: subprocess.Popen) -> None:
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except OSError:
        pass


def _watch_parent() -> None:
    """End this process when the node that started it is gone (killed without a word)."""
    parent = os.getppid()
    while True:
        time.sleep(1.0)
        if os.getppid() != parent:
            os._exit(3)


#: how long the check of a study goal may take in its process [s] (describing the largest
#: library system takes seconds; a system file may take what its code takes)
CHECK_TIMEOUT_S = 120.0


def check_study(job: dict[str, Any]) -> dict[str, Any]:
    """A study goal's system and problem resolved by name and the study built and checked
    (in the compile process: a system file's code runs there, not in the node that asks).
    ``job``: ``spec`` (the goal's study), the node's ``system_paths``, its system and study
    limits. Returns the resolved ``system`` and ``problem``."""
    from biped_opt.studies.study import Study, StudyLimits

    limits = StudyLimits(**job["study_limits"])
    fields = Study.fields_from_spec(job["spec"], where="study", limits=limits)
    try:
        fields["system"], fields["problem"] = _sources(job).study(fields["system"],
                                                                  fields["problem"])
    except BipedOptError as exc:
        raise InvalidInputError(f"study: {exc}") from None
    Study(**fields)
    return {"system": fields["system"], "problem": fields["problem"]}


def run_check(job: dict[str, Any], timeout: float = CHECK_TIMEOUT_S) -> dict[str, Any]:
    """:func:`check_study` in a compile process of its own, waited for here (at most
    ``timeout``); its failure is an :class:`InvalidInputError` with the process's reason."""
    process = children.popen("biped_opt.nodes.compiler", "--check-study", json.dumps(job),
                             stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        _kill(process)
        process.communicate()
        raise InvalidInputError(f"study: checking its system took more than {timeout:g} s"
                                ) from None
    except BaseException:  # (the node stopping: no process left behind)
        _kill(process)
        raise
    if process.returncode != 0:
        lines = [line for line in (err or "").splitlines() if line.strip()]
        raise InvalidInputError(lines[-1] if lines and process.returncode == 2 else
                                f"study: the check ended with status {process.returncode}")
    result: dict[str, Any] = json.loads(out.strip().splitlines()[-1])
    return result


def main(argv: list[str] | None = None) -> int:
    """The compile process: ``python -m biped_opt.nodes.compiler JOB_JSON`` (or
    ``--check-study JOB_JSON``: :func:`check_study`, its result as JSON on stdout); status 2
    and one line on stderr when the job fails."""
    threading.Thread(target=_watch_parent, daemon=True).start()
    args = sys.argv[1:] if argv is None else argv
    if args[0] == "--check-study":
        try:
            print(json.dumps(check_study(json.loads(args[1]))), flush=True)
        except BaseException as exc:  # (a system file's SystemExit too): one line, status 2
            print(failure_message(exc, "study"), file=sys.stderr, flush=True)
            return 2
        return 0
    job = json.loads(args[0])
    try:
        prepare(job)
    except BaseException as exc:  # (a system file's SystemExit too): one line, status 2
        print(failure_message(exc, f"system {job.get('system') or 'biped'}"), file=sys.stderr,
              flush=True)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
