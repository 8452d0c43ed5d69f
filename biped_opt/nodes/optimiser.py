"""``optimiser`` node: serves optimal-policy queries on ``/biped/optimal_policy``.

For a request (maneuver, theta0) it solves the maneuver's optimal-control problem (paper Eqs. (4),
(14), (15); the preset :mod:`biped_opt.paper.problems`' one-lane problem, by
:func:`biped_opt.control.solve.optimal_policy`) and replies with the policy (touchdown [u1, u2],
liftoff [u12]), value, outcome, final time, mode sequence, event times and the one-sided
derivatives [left, right] of the value (envelope theorem: dV/dth0 = dc/dth0 at the optimum, with the
outcome's one-sided sensitivities through the events; :func:`biped_opt.control.theorem1.
value_slopes`).

The problems' parameters are node parameters (``config/biped.yaml``): for each maneuver M,
``M.theta_star``, ``M.alphas``, ``M.bounds`` (flattened [lo, hi] per decision) and
``M.fixed_inputs`` ([u1, u2, u12]). A bad request gets ``success = false`` and a message naming
the field (an unexpected error: ``success = false`` and ``internal error: ...``); the node logs
it (one line a second at most) and keeps serving. Requests are served concurrently (reentrant
callback group, multi-threaded executor).

**Any system.** A request whose ``system`` or ``problem`` is set is solved by
:func:`biped_opt.control.solve.optimal_policy` with ``theta0`` as the maneuver's s; the reply
names the decisions (``decision_names``), gives the full input vector in the system's order
(``system_inputs``) and the contact modes as bit masks (``contact_modes``). Its
``value_derivative`` is the envelope theorem's dc/ds at the optimal inputs with the outcome's and
final state's one-sided sensitivities (the same :func:`~biped_opt.control.theorem1.value_slopes`),
NaN on a side where they are not defined. Both replies are one conversion of the one
:class:`~biped_opt.control.solve.OptimalResult` (:meth:`Answer.of`).

**What a request may name** (:mod:`biped_opt.nodes.sources`): ``system`` a library system
(``rocking_bar``, ``walker3_coupled``...) or the name of ``<dir>/<name>.py`` in a directory of
the parameter ``system_paths`` (empty by default: library systems only); ``problem`` one the
system declares or ``<dir>/<name>.yaml`` (``.yml``, ``.py``) there (``""``: the one named like
the maneuver). Never a path: a system or problem file is code the node runs, so only the
operator chooses which. Systems larger than ``max_legs`` constraints or ``max_coordinates``
coordinates are refused before anything is derived.

**Compiling never holds up a request** (:mod:`biped_opt.nodes.compiler`): the first request for
a system the node has not prepared is answered at once (``success = false``, ``busy: ... is
being compiled (k in queue); retry``) while a separate process compiles it (a first compile
takes 10-90 s; later ones load it from the on-disk cache); at most ``compile_queue`` systems
wait, ``compile_timeout`` [s] bounds one. The parameter ``systems`` prepares systems and their
declared problems at start-up: names as a request gives them, or the operator's system files,
whose directories then join ``system_paths`` (a request names such a file by its stem; a
problem file listed there only adds its directory).

Answers are cached by (maneuver, theta0, problem), least recently used first out, at most
``cache_size`` entries (parameter, default 4096). An entry holds only the reply's numbers (about
1 KB with its key), not the optimisation's trajectories, so the cache stays under ~4 MB at the
default size whatever the traffic (``bench/service_load.py`` measures the node's memory).

**Parameter studies.** The node also serves work items of a study
(:mod:`biped_opt.nodes.coordinator`) on ``~/study/<worker>`` (``StudyPoint``: the study as JSON
and a point's index; the point's rows as JSON), one at a time (further requests wait in the
service's queue). ``worker`` (parameter; default the host name and process id) makes the name
unique on the domain, so every optimiser started with the defaults on any machine serves its own.
A work item names its system and problem as a request does; its study is bounded by the
parameters ``max_points`` (parameter points), ``max_num`` (points of an s grid),
``max_values`` (values of a grid axis, samples) and ``max_request_chars`` (the study's text),
checked before anything is built.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import socket
import struct
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from biped_opt import ros
from biped_opt.control.solve import optimal_policy
from biped_opt.control.theorem1 import value_slopes
from biped_opt.errors import (
    BipedOptError,
    InvalidInputError,
    InvalidParameterError,
)
from biped_opt.nodes import convert
from biped_opt.nodes.compiler import COMPILE_TIMEOUT_S, Compiler
from biped_opt.nodes.parameters import float_parameter, int_parameter, string_list_parameter
from biped_opt.nodes.refusals import answers, refuse
from biped_opt.nodes.run import announce_ready, run_node, warm_up_kernels
from biped_opt.nodes.simulator import BIPED
from biped_opt.nodes.sources import (
    FILE_SUFFIXES,
    Names,
    check_name,
    declare_request_limits,
    name_of,
    request_study,
)
from biped_opt.paper.biped import Maneuver
from biped_opt.paper.problems import OptimalControlProblem, get_problem
from biped_opt.simulation.compiled import batch_thread_limit

if TYPE_CHECKING:
    from biped_opt.control.problems import Problem
    from biped_opt.control.solve import OptimalResult

__all__ = ["Answer", "OptimiserNode", "main"]

#: default of the ``cache_size`` parameter [entries]
CACHE_SIZE = 4096
#: default of the parameter compile_queue [systems]; the most points in one work item
COMPILE_QUEUE, MAX_INDICES = 4, 256
NAN = float("nan")


class OptimiserNode(ros.Node):
    """Serves ``/biped/optimal_policy`` (see the module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("optimiser", **kwargs)
        self.declare_parameter("warm_up", True)
        self._problems: dict[Maneuver, OptimalControlProblem] = {}
        for maneuver in Maneuver:
            default = get_problem(maneuver.value)
            name = maneuver.value
            self.declare_parameter(f"{name}.theta_star", default.theta_star)
            self.declare_parameter(f"{name}.alphas", list(default.alphas))
            self.declare_parameter(f"{name}.bounds", [b for pair in default.bounds for b in pair])
            self.declare_parameter(f"{name}.fixed_inputs", list(default.fixed_inputs))
            self._problems[maneuver] = self._problem_from_parameters(maneuver)
        self.declare_parameter("cache_size", CACHE_SIZE)
        self.declare_parameter("systems", [])
        self.declare_parameter("compile_queue", COMPILE_QUEUE)
        self.declare_parameter("compile_timeout", COMPILE_TIMEOUT_S)
        self.declare_parameter("worker", "")
        self._cache_size = int(self.get_parameter("cache_size").value)
        if self._cache_size < 0:
            raise InvalidParameterError(
                f"cache_size must be >= 0 (0: no cache), got {self._cache_size}")
        self._sources, self._study_limits, self._max_request = declare_request_limits(self)
        self._cache: OrderedDict[tuple, Answer] = OrderedDict()
        #: the same answers by the request's own fields, for the service's quick reply
        self._answers: OrderedDict[tuple, Answer] = OrderedDict()
        self._lock = threading.Lock()
        self._compiler = Compiler(self.get_logger(),
                                  queue_size=int_parameter(self, "compile_queue", 0),
                                  timeout=float_parameter(self, "compile_timeout"))
        if self.get_parameter("warm_up").value:
            warm_up_kernels(self)
        systems = string_list_parameter(self, "systems")
        files = [Path(s).expanduser().resolve() for s in systems
                 if Path(s).suffix in FILE_SUFFIXES]
        if files:  # (the operator's files: their directories join system_paths)
            folders = tuple(dict.fromkeys([*self._sources.system_paths,
                                           *(f.parent for f in files)]))
            self._sources = dataclasses.replace(self._sources, system_paths=folders)
        #: what replies to peers never show (biped_opt.nodes.refusals.public)
        self.private_paths = self._sources.system_paths
        for system in systems:  # (a .yaml problem file only adds its directory)
            if Path(system).suffix not in (".yaml", ".yml"):
                self._warm_up_system(name_of(system))
        self._group = ros.ReentrantCallbackGroup()
        self._service = self.create_service(
            ros.srvs.OptimalPolicy, "/biped/optimal_policy", self._on_request,
            callback_group=self._group,
        )
        if hasattr(self._service, "quick_reply"):  # (the built-in backend's services)
            self._service.quick_reply = self._quick_reply
        self._studies: OrderedDict[str, tuple[Any, list[dict[str, float]]]] = OrderedDict()
        worker = str(self.get_parameter("worker").value).strip() or default_worker_name()
        if not re.fullmatch(r"[A-Za-z_]\w*", worker):
            raise InvalidParameterError(
                f"worker must be letters, digits and _ (not first a digit), got {worker!r}")
        # one item at a time: a node is one core's worth of work
        self._study_service = self.create_service(
            ros.srvs.StudyPoint, f"~/study/{worker}", self._on_study_point,
            callback_group=ros.MutuallyExclusiveCallbackGroup())
        self.study_service_name = f"{self.get_fully_qualified_name()}/study/{worker}"
        announce_ready(self, serves=("/biped/optimal_policy", self.study_service_name))

    def _problem_from_parameters(self, maneuver: Maneuver) -> OptimalControlProblem:
        name = maneuver.value
        flat = [float(v) for v in self.get_parameter(f"{name}.bounds").value]
        return get_problem(
            name,
            theta_star=float(self.get_parameter(f"{name}.theta_star").value),
            alphas=tuple(float(v) for v in self.get_parameter(f"{name}.alphas").value),
            bounds=tuple(zip(flat[0::2], flat[1::2])),
            fixed_inputs=tuple(float(v) for v in self.get_parameter(f"{name}.fixed_inputs").value),
        )

    # -- other systems -----------------------------------------------------------------------
    def _job(self, kind: str, system: str, problem: str, names: Names | None = None
             ) -> dict[str, Any]:
        """What the compiler prepares (see :func:`biped_opt.nodes.compiler.prepare`): a study's
        ``system`` and ``problem``, or a policy's checked ``names``."""
        return {"kind": kind, "system": system, "problem": problem,
                "names": None if names is None else dataclasses.asdict(names),
                "system_paths": [str(p) for p in self._sources.system_paths],
                "max_legs": self._sources.limits.max_legs,
                "max_coordinates": self._sources.limits.max_coordinates}

    def _warm_up_system(self, system: str) -> None:
        """Prepare ``system`` (an entry of the parameter ``systems``) for studies and with the
        problems it declares before serving; a bad entry stops the node with one line naming
        it."""
        if system in BIPED:
            return  # (the biped's kernels: parameter warm_up)
        try:
            source = self._sources.system("systems", system)
            self.get_logger().info(f"compiling system {system!r} (a first compile takes a "
                                   "while; later starts load it)")
            described = self._sources.describe("systems", source)
            self._compiler.prepare_now(("study", system, ""), self._job("study", system, ""))
            for name, problem in described.problems.items():
                key = ("policy", system, name, problem["maneuver"])
                names = Names(source=source, problem=name, maneuver=problem["maneuver"],
                              checked=True)
                self._compiler.prepare_now(key, self._job("policy", system, name, names))
        except BipedOptError as exc:
            text = str(exc)
            raise InvalidParameterError(
                text if text.startswith("systems:") else f"systems: {system}: {text}") from None

    def kill_work(self) -> None:
        """Kill a compile under way (the node is stopping)."""
        self._compiler.close()

    # -- requests ----------------------------------------------------------------------------
    def solve(self, maneuver_text: str, theta0: float, system: str = "", problem: str = ""
              ) -> Answer:
        """Validated, cached answer to one request."""
        if system in BIPED and not problem:
            maneuver = convert.request_maneuver(maneuver_text)
            th = convert.request_theta0(maneuver, theta0)  # (in the maneuver's range)
            preset = self._problems[maneuver]
            biped = preset.problem
            return self._cached((maneuver, th, preset),
                                lambda: Answer.of(biped, optimal_policy(biped, th), paper=True))
        # names only, checked before anything is compiled (see biped_opt.nodes.sources); the
        # compiler then checks only what needs the system built (Sources.problem)
        names = self._sources.check_request(system, problem, maneuver_text)
        s = convert.request_s(theta0)
        name = problem or maneuver_text
        on = self._compiler.get(
            ("policy", system, name, maneuver_text),
            f"system {system or 'biped'} (problem {name})",
            self._job("policy", system, problem, names))
        key = ("system", id(on.description), json.dumps(on.as_dict(), sort_keys=True), s)
        return self._cached(key, lambda: Answer.of(on, optimal_policy(on, s)))

    def _cached(self, key: tuple, compute: Any) -> Answer:
        with self._lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                return self._cache[key]
        answer = compute()
        with self._lock:
            self._cache[key] = answer
            while len(self._cache) > self._cache_size:
                self._cache.popitem(last=False)
        return answer

    def _on_request(self, request: Any, response: Any) -> Any:
        try:
            answer = self.solve(request.maneuver, request.theta0, request.system,
                                request.problem)
        except BaseException as exc:  # bad request, or a bug: one refused request either way
            if not answers(exc):
                raise
            return refuse(self, "/biped/optimal_policy", response, exc)
        if self._cache_size:
            with self._lock:
                self._answers[_request_key(request)] = answer
                while len(self._answers) > self._cache_size:
                    self._answers.popitem(last=False)
        answer.fill(response)
        return response

    def _quick_reply(self, request: Any) -> Any:
        """The answer to a request asked before, from the cache, or None: the service sends it
        as the request arrives, never behind the computations of other requests (a request
        the same field for field gets the same answer: the node's problems are fixed at
        start)."""
        with self._lock:
            answer = self._answers.get(_request_key(request))
            if answer is None:
                return None
            self._answers.move_to_end(_request_key(request))
        response = ros.srvs.OptimalPolicy.Response()
        answer.fill(response)
        return response


    # -- study work items --------------------------------------------------------------------
    def _study(self, text: str) -> tuple[Any, list[dict[str, float]]]:
        """The study of a work item and its points (the last few studies kept); its size is
        checked before anything is built, its system prepared by the compiler."""
        from biped_opt.studies.study import Study

        if text in self._studies:
            self._studies.move_to_end(text)
            return self._studies[text]
        spec = request_study(text, self._max_request)
        fields = Study.fields_from_spec(spec, where="study", limits=self._study_limits)
        system, problem = fields["system"], fields["problem"] or ""
        try:  # (a study names its system: "" is not the biped here)
            check_name("system", system)
            self._sources.check_request(system, problem)
        except BipedOptError as exc:
            raise InvalidInputError(f"study: {exc}") from None
        self._compiler.get(("study", system, problem),
                           f"system {system}" + (f" (problem {problem})" if problem else ""),
                           self._job("study", system, problem))
        fields["system"], fields["problem"] = self._sources.study(system, problem)
        study = Study(**fields)
        self._studies[text] = (study, study.points())
        while len(self._studies) > 4:
            self._studies.popitem(last=False)
        return self._studies[text]

    def _on_study_point(self, request: Any, response: Any) -> Any:
        from biped_opt.nodes.coordinator import encode_rows
        from biped_opt.studies.study import evaluate_point

        start = time.perf_counter()
        try:
            if len(request.indices) > MAX_INDICES:
                raise InvalidInputError(f"indices: at most {MAX_INDICES} points in one item, "
                                        f"got {len(request.indices)}")
            indices = [int(i) for i in request.indices]
            if not indices:
                raise InvalidInputError("indices: no point asked for")
            study, points = self._study(request.study)
            for index in indices:
                if not 0 <= index < len(points):
                    raise InvalidInputError(
                        f"indices: {index} is not a point of the study ({len(points)} points)")
            # one core per node for study points (the batches' threads would take the other
            # cores from the nodes beside it): start one optimiser per core to use them
            with batch_thread_limit(1):
                rows = [r for index in indices
                        for r in evaluate_point(study, index, points[index])]
        except BaseException as exc:  # bad request, or a bug: one refused request either way
            if not answers(exc):
                raise
            return refuse(self, self.study_service_name, response, exc)
        response.success, response.rows = True, encode_rows(rows)
        response.seconds = time.perf_counter() - start
        return response

    def destroy_node(self) -> None:
        if getattr(self, "_compiler", None) is not None:  # (a bad parameter stops it sooner)
            self._compiler.close()
        super().destroy_node()


def _request_key(request: Any) -> tuple[str, bytes, str, str]:
    """A request's fields as a cache key (theta0 by its bits: -0.0 is not 0.0)."""
    return (request.maneuver, struct.pack("<d", float(request.theta0)), request.system,
            request.problem)


def default_worker_name() -> str:
    """``<host>_<pid>`` with anything but letters, digits and _ replaced: unique on a domain."""
    host = re.sub(r"\W", "_", socket.gethostname()) or "host"
    return f"{'h_' if host[0].isdigit() else ''}{host}_{os.getpid()}"


@dataclass(frozen=True)
class Answer:
    """The numbers of one OptimalPolicy reply (what the cache keeps)."""

    success: bool
    message: str
    policy: tuple[float, ...]
    value: float
    outcome: float
    t_final: float
    mode_sequence: tuple[int, ...]
    event_times: tuple[float, ...]
    value_derivative: tuple[float, float]
    inputs: tuple[float, ...]
    contact_modes: tuple[int, ...]
    decision_names: tuple[str, ...]
    system_inputs: tuple[float, ...]

    @classmethod
    def of(cls, problem: Problem, result: OptimalResult, *, paper: bool = False) -> Answer:
        """The reply to ``result``, the optimum of ``problem``: the value's one-sided slopes by
        Theorem 1 (NaN when the optimum failed). A request of the paper's (``paper``: the
        biped's problems of the node's parameters) also gets the fields the reply had before
        any system could be asked: its contact modes as ``mode_sequence`` (ContactMode values)
        and its inputs (u1, u2, u12) as ``inputs``; any other gets an empty mode_sequence and
        NaN inputs (its inputs are ``system_inputs``)."""
        dv = value_slopes(problem, result) if result.success else (NAN, NAN)
        modes = tuple(int(m) for m in result.modes)
        inputs = tuple(float(v) for v in result.inputs)
        return cls(
            success=bool(result.success), message=result.message,
            policy=tuple(float(result.policy[d]) for d in problem.decision_names),
            value=float(result.value), outcome=float(result.outcome),
            t_final=float(result.t_final), mode_sequence=modes if paper else (),
            event_times=tuple(float(t) for t in result.event_times),
            value_derivative=(float(dv[0]), float(dv[1])),
            inputs=inputs if paper else (NAN, NAN, NAN), contact_modes=modes,
            decision_names=tuple(problem.decision_names), system_inputs=inputs,
        )

    def fill(self, response: Any) -> None:
        response.success, response.message = self.success, self.message
        response.policy = list(self.policy)
        response.value, response.outcome, response.t_final = self.value, self.outcome, \
            self.t_final
        response.mode_sequence = list(self.mode_sequence)
        response.event_times = list(self.event_times)
        response.value_derivative = list(self.value_derivative)
        response.inputs = list(self.inputs)
        response.contact_modes = list(self.contact_modes)
        response.decision_names = list(self.decision_names)
        response.system_inputs = list(self.system_inputs)


def main(args: list[str] | None = None) -> None:
    run_node(OptimiserNode, args, threads=4)


if __name__ == "__main__":
    main()
