"""``optimiser`` node: serves optimal-policy queries on ``/biped/optimal_policy``.

For a request (maneuver, theta0) it solves the maneuver's optimal-control problem (paper Eqs. (4),
(14), (15); :func:`biped_opt.optimal.optimal_policy`) and replies with the policy (touchdown
[u1, u2], liftoff [u12]), value, outcome, final time, mode sequence, event times and the one-sided
derivatives [left, right] of the value (envelope theorem: dV/dth0 = dc/dth0 at the optimum, with the
outcome's one-sided sensitivities through the events).

The problems' parameters are node parameters (``config/biped.yaml``): for each maneuver M,
``M.theta_star``, ``M.alphas``, ``M.bounds`` (flattened [lo, hi] per decision) and
``M.fixed_inputs`` ([u1, u2, u12]). A bad request gets ``success = false`` and a message naming
the field (an unexpected error: ``success = false`` and ``internal error: ...``); the node logs
it (one line a second at most) and keeps serving. Requests are served concurrently (reentrant
callback group, multi-threaded executor).

Answers are cached by (maneuver, theta0, problem), least recently used first out, at most
``cache_size`` entries (parameter, default 4096). An entry holds only the reply's numbers (about
1 KB with its key), not the optimisation's trajectories, so the cache stays under ~4 MB at the
default size whatever the traffic (``bench/service_load.py`` measures the node's memory).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np

from biped_opt import ros
from biped_opt.errors import InvalidParameterError
from biped_opt.maneuvers import Maneuver
from biped_opt.nodes import convert
from biped_opt.nodes.run import announce_ready, refuse, run_node, warm_up_kernels
from biped_opt.optimal import OptimalControlProblem, OptimalResult, get_problem, optimal_policy
from biped_opt.optimal.derivatives import outcome_sensitivity

__all__ = ["Answer", "OptimiserNode", "main", "value_derivative"]

#: default of the ``cache_size`` parameter [entries]
CACHE_SIZE = 4096


def value_derivative(problem: OptimalControlProblem, result: OptimalResult) -> tuple[float, float]:
    """[left, right] dV/dth0 by the envelope theorem (Theorem 1, Eq. (13)): the partial of the
    cost c = (th_f - th*)^2 + sum alpha u^2 in th0 at the optimal inputs, with the outcome's
    one-sided sensitivity through the events on each side."""
    out = []
    for side in (-1, +1):
        s = outcome_sensitivity(
            problem.maneuver.value, result.theta0, result.inputs,
            direction=(side, 0.0, 0.0, 0.0), params=problem.params,
        )
        out.append(problem.outcome_slope(s.outcome) * s.gradient[0])
    return out[0], out[1]


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
        self._cache_size = int(self.get_parameter("cache_size").value)
        if self._cache_size < 0:
            raise InvalidParameterError(
                f"cache_size must be >= 0 (0: no cache), got {self._cache_size}")
        self._cache: OrderedDict[tuple, Answer] = OrderedDict()
        self._lock = threading.Lock()
        if self.get_parameter("warm_up").value:
            warm_up_kernels(self)
        self._group = ros.ReentrantCallbackGroup()
        self._service = self.create_service(
            ros.srvs.OptimalPolicy, "/biped/optimal_policy", self._on_request,
            callback_group=self._group,
        )
        announce_ready(self, serves=("/biped/optimal_policy",))

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

    def solve(self, maneuver_text: str, theta0: float) -> Answer:
        """Validated, cached answer to one request."""
        maneuver = convert.request_maneuver(maneuver_text)
        th = convert.request_theta0(maneuver, theta0)
        problem = self._problems[maneuver]
        key = (maneuver, th, problem)
        with self._lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                return self._cache[key]
        answer = Answer.of(problem, optimal_policy(problem, th))
        with self._lock:
            self._cache[key] = answer
            while len(self._cache) > self._cache_size:
                self._cache.popitem(last=False)
        return answer

    def _on_request(self, request: Any, response: Any) -> Any:
        try:
            answer = self.solve(request.maneuver, request.theta0)
        except Exception as exc:  # bad request, or a bug: one refused request either way
            return refuse(self, "/biped/optimal_policy", response, exc)
        answer.fill(response)
        return response


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

    @classmethod
    def of(cls, problem: OptimalControlProblem, result: OptimalResult) -> Answer:
        dv = value_derivative(problem, result)
        return cls(
            success=bool(result.success), message=result.message,
            policy=tuple(float(v) for v in result.x), value=float(result.value),
            outcome=float(result.outcome),
            t_final=float(result.trajectory.t_final) if result.trajectory else float("nan"),
            mode_sequence=tuple(int(m) for m in result.modes),
            event_times=tuple(float(t) for t in np.asarray(result.event_times)),
            value_derivative=(float(dv[0]), float(dv[1])),
            inputs=tuple(float(v) for v in result.inputs),
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


def main(args: list[str] | None = None) -> None:
    run_node(OptimiserNode, args, threads=4)


if __name__ == "__main__":
    main()
