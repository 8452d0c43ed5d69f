"""One-sided derivatives of any system's optimal outcome, value and policy (Theorem 1 of [1]_).

For a :class:`~biped_opt.control.problems.Problem` and a side sigma = -1 or +1 of s, the branch
that s -> s^sigma follows is found by solving the problem at s + sigma * probe; on that branch,
at s itself, with p = (s, u) and the exact first-order sensitivities of
:func:`biped_opt.control.derivatives.outcome_gradient` taken along sigma e_s:

- the optimum is polished by Newton's method on D_u c = 0 over the free decisions (acting and
  off their bounds), the Hessian from central differences of the exact gradient
  (:func:`polish_optimum`; the joint optimiser's result is ~1e-9 off, its L-BFGS-B stops on
  differenced gradients, the polish ~1e-11);
- value: dV/ds = D_s c (envelope theorem, Eq. (12): D_u c = 0 on the free decisions and du/ds
  = 0 on the bound ones);
- policy: du*/ds = -(D_uu c)^-1 D_us c on the free decisions (implicit function theorem,
  Eq. (13)), D_uu c and D_us c = D_u (D_s c) from central differences in u of the exact
  gradient on the branch at the polished optimum (Richardson-extrapolated); 0 for decisions on a
  bound or acting on nothing;
- outcome: d o/ds + D_u o du*/ds.

with c = w (o - target)^2 + sum_k W_k (y_k(t_f) - r_k)^2 + sum_i alpha_i u_i^2. The result is
a :class:`Derivatives` record (``theta0`` holding s);
:func:`optimal_derivatives_with_errors` adds an error estimate of every slope
(:class:`DerivativeErrors`).

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from biped_opt.control.derivatives import (
    DEFAULT_VARIATIONAL,
    OutcomeGradient,
    VariationalOptions,
    outcome_gradient,
)
from biped_opt.control.problems import Problem
from biped_opt.control.solve import OptimalResult, compiled_for, optimal_policy
from biped_opt.errors import InvalidInputError, SimulationError
from biped_opt.simulation.compiled import CompiledSystem

__all__ = ["Derivatives", "optimal_derivatives", "optimal_derivatives_with_errors",
           "DerivativeErrors",
           "Polished", "polish_optimum", "cost_gradient", "value_slopes"]

Array = npt.NDArray[np.float64]

#: central-difference step of the Hessian D_uu c, relative to each decision's bound interval
HESSIAN_STEP = 1e-4
#: Newton iterations of the polish at most
NEWTON_STEPS = 4
#: the polish stops once its Newton step is below this relative to max(1, |u|): the exact
#: gradient's own accuracy (~1e-14 on the library's problems) over the Hessian's smallest
#: eigenvalue (~1e-3 on the walkers) is ~1e-11, so smaller steps are noise
POLISH_TOL = 1e-12


@dataclass(frozen=True, eq=False)
class Derivatives:
    """One-sided derivatives w.r.t. th0 of the optimal outcome, value and policy at ``theta0``.

    Every pair is (left, right): the derivative of the branch that th0 -> theta0^- (resp. ^+)
    follows, evaluated at ``theta0`` (Theorem 1 of [1]_: on each branch the value and policy are
    as smooth as the outcome). ``outcome`` is the total derivative of the *optimal* outcome
    th_f(th0, u*(th0)), i.e. d th_f/d th0 + D_u th_f du*/dth0. ``*_limits`` are the one-sided
    limits, which differ where the function jumps. ``branches`` are the branch mode orders
    (zero-length modes included).
    """

    problem: str
    theta0: float
    outcome: tuple[float, float]
    value: tuple[float, float]
    policy: dict[str, tuple[float, float]]
    outcome_limits: tuple[float, float]
    value_limits: tuple[float, float]
    policy_limits: dict[str, tuple[float, float]]
    branches: tuple[str, str]
    #: decisions held at a bound on each side (their policy derivative is 0 there)
    at_bound: tuple[tuple[str, ...], tuple[str, ...]]
    nsens: int  #: sensitivity (variational) solves used

    def as_dict(self) -> dict:
        """Plain-data form (JSON-ready), keys as in the ``optimise --json`` output."""
        return {
            "outcome": list(self.outcome),
            "value": list(self.value),
            "policy": {k: list(v) for k, v in self.policy.items()},
            "limits": {
                "outcome": list(self.outcome_limits),
                "value": list(self.value_limits),
                "policy": {k: list(v) for k, v in self.policy_limits.items()},
            },
            "branches": list(self.branches),
        }



def cost_gradient(problem: Problem, g: OutcomeGradient, inputs: Array) -> Array:
    """D c over ``(s, *inputs)`` from the branch's outcome and final-state gradients."""
    out = 2.0 * problem.outcome_weight * (g.outcome - problem.target) * g.gradient
    for col, w, r in problem.final_state_columns:
        out = out + 2.0 * w * (g.y_final[col] - r) * g.state_gradient[col]
    for col, a in zip(problem.decision_columns, problem.weights):
        out[1 + col] += 2.0 * a * inputs[col]
    return out



@dataclass(frozen=True)
class DerivativeErrors:
    """Error estimates of a :class:`Derivatives` record's slopes,
    (left, right) as there; each is a size, not a bound (tests multiply it by a safety factor).

    - policy: |H^-1| (|e_mixed| + e_H |du*/ds|), e_mixed the change the Richardson
      extrapolation made to D_us c, and e_H that of the Hessian H (both central differences of
      the exact gradient in u at steps h and h/2, Richardson-extrapolated): the largest change
      the extrapolation made or asymmetry left (an exact Hessian is
      symmetric);
    - value: |D_us c| . |u - u*| (D_s c taken off the optimum by the polish's distance) plus the
      variational integration's relative tolerance;
    - outcome: |D_u o| . (policy error) plus the same tolerance;
    - polish: the distance |H^-1 D_u c| of the polished optimum at s from the zero of D_u c.
    """

    outcome: tuple[float, float]
    value: tuple[float, float]
    policy: dict[str, tuple[float, float]]
    polish: tuple[float, float]


@dataclass(frozen=True, eq=False)
class Polished:
    """An optimum polished by Newton's method on D_u c = 0 over its free decisions."""

    inputs: Array = field(repr=False)  #: the full input vector
    decisions: tuple[str, ...]  #: the problem's decisions
    free: tuple[str, ...]  #: the decisions polished (acting and off their bounds)
    held: tuple[str, ...]  #: acting decisions on a bound (not moved)
    hessian: Array = field(repr=False)  #: D_uu c over ``free`` (central differences)
    #: max |H^-1 D_u c| at ``inputs``: the estimated distance to the zero of D_u c
    error: float
    gradient: OutcomeGradient = field(repr=False)  #: the branch's sensitivities at ``inputs``
    value: float  #: the cost at ``inputs`` (the branch's limit)
    count: int  #: sensitivity solves used

    @property
    def policy(self) -> dict[str, float]:
        names = self.gradient.names[1:]
        return {d: float(self.inputs[names.index(d)]) for d in self.decisions}


class _Costs:
    """D c on one branch (direction sigma e_s), counting the sensitivity solves."""

    def __init__(self, problem: Problem, compiled: CompiledSystem, side: int,
                 cols: list[int], variational: VariationalOptions = DEFAULT_VARIATIONAL) -> None:
        self.problem, self.compiled, self.cols = problem, compiled, cols
        self.variational = variational
        self.direction = np.zeros(1 + len(problem.facts.inputs))
        self.direction[0] = side
        self.count = 0

    def branch(self, x: float, u: Array) -> OutcomeGradient:
        self.count += 1
        return outcome_gradient(self.compiled, self.problem.maneuver, x, u,
                                direction=self.direction, options=self.problem.options,
                                variational=self.variational)

    def grad_u(self, x: float, u: Array) -> Array:
        return cost_gradient(self.problem, self.branch(x, u), u)[[1 + c for c in self.cols]]

    def second_derivatives(self, x: float, u: Array, extrapolate: bool = True
                           ) -> tuple[Array, float, Array, Array]:
        """D_uu c over the columns and D_us c = D_u (D_s c), by central differences in u of
        the exact D_(s, u) c on the branch, with steps h and h/2, Richardson-extrapolated (or
        step h alone), and their error estimates: for D_uu c the largest entry of the change
        made by the extrapolation or of the asymmetry (an exact Hessian is symmetric), for
        D_us c the change per entry. (One set of gradients gives both: D_us c as a difference in
        s would need more, and amplify the gradient's noise over a one-sided step.)"""
        n = len(self.cols)
        rows = [0, *(1 + c for c in self.cols)]
        levels = []
        for scale in ((1.0, 0.5) if extrapolate else (1.0,)):
            out = np.zeros((n + 1, n))
            for j, c in enumerate(self.cols):
                lo, hi = self.problem.bound(self.problem.facts.inputs[c])
                step = scale * HESSIAN_STEP * (hi - lo)
                up, down = u.copy(), u.copy()
                up[c] += step
                down[c] -= step
                g_up = cost_gradient(self.problem, self.branch(x, up), up)[rows]
                g_down = cost_gradient(self.problem, self.branch(x, down), down)[rows]
                out[:, j] = (g_up - g_down) / (2.0 * step)
            levels.append(out)
        extrapolated = (4.0 * levels[1] - levels[0]) / 3.0 if extrapolate else levels[0]
        change = np.abs(extrapolated - levels[-1])
        hessian, mixed = extrapolated[1:], extrapolated[0]
        error = float(max(np.max(change[1:]), np.max(np.abs(hessian - hessian.T)))) if n else 0.0
        return 0.5 * (hessian + hessian.T), error, mixed, change[0]

    def hessian(self, x: float, u: Array, extrapolate: bool = True) -> tuple[Array, float]:
        """D_uu c and its error estimate (:meth:`second_derivatives`)."""
        hessian, error, _, _ = self.second_derivatives(x, u, extrapolate)
        return hessian, error


def value_slopes(problem: Problem, result: OptimalResult) -> tuple[float, float]:
    """[left, right] dV/ds of a problem on any system by the envelope theorem: the partial in s
    of c = w (outcome - target)^2 + sum_k W_k (y_k(t_f) - r_k)^2 + sum alpha u^2 at the optimal
    inputs (the input terms do not depend on s), each side with the outcome's and final state's
    limits and sensitivities on the branch s -> s^- or s^+. NaN on a side the sensitivities
    cannot be had (a grazing terminal event, a failed simulation)."""
    compiled = compiled_for(problem)
    e_s = np.zeros(1 + len(compiled.inputs))
    e_s[0] = 1.0
    out = []
    for side in (-1.0, 1.0):
        try:
            g = outcome_gradient(compiled, problem.maneuver, result.s, result.inputs,
                                 direction=side * e_s, options=problem.options)
        except SimulationError:
            out.append(math.nan)
            continue
        out.append(float(cost_gradient(problem, g, result.inputs)[0]))
    return out[0], out[1]


def polish_optimum(problem: Problem, s: float, start: OptimalResult, *, side: int,
                   hessian: Array | None = None,
                   variational: VariationalOptions = DEFAULT_VARIATIONAL) -> Polished:
    """``start`` (an optimum of ``problem`` at s) polished by Newton's method on D_u c = 0 over
    its free decisions on the branch s -> s^side, with exact first derivatives.

    The Hessian is differenced once, at ``start``, or taken from ``hessian``; Newton's
    iteration with it contracts by |I - hessian^-1 H| (fast for a Hessian of a nearby point)
    towards the zero of the exact D_u c, which the Hessian's error does not move. Iterates
    until the Newton step is below POLISH_TOL (relative) or NEWTON_STEPS
    steps; ``error`` is the Newton step left at the returned point, not applied.
    """
    if side not in (-1, 1):
        raise InvalidInputError(f"side must be -1 or +1, got {side!r}")
    names = problem.facts.inputs
    acting = set((start.active or "").split("+")) - {""}
    held = tuple(d for d in problem.decision_names if d in acting and
                 start.policy[d] in problem.bound(d))
    free = tuple(d for d in problem.decision_names if d in acting and d not in held)
    cols = [names.index(d) for d in free]
    costs = _Costs(problem, compiled_for(problem), side, cols, variational)
    u = start.inputs.copy()
    if hessian is None:
        hessian, _ = costs.hessian(s, u, extrapolate=False)  # Newton needs no more
    elif hessian.shape != (len(cols), len(cols)):
        raise InvalidInputError(f"hessian must be {len(cols)} x {len(cols)} (free decisions "
                                f"{', '.join(free) or 'none'}), got {hessian.shape}")
    g = costs.branch(s, u)
    error = 0.0
    for k in range(NEWTON_STEPS + 1 if free else 0):
        step = np.linalg.solve(hessian, -cost_gradient(problem, g, u)[[1 + c for c in cols]])
        error = float(np.max(np.abs(step)))
        if error <= POLISH_TOL * max(1.0, float(np.max(np.abs(u[cols])))) or k == NEWTON_STEPS:
            break
        u[cols] = u[cols] + step
        g = costs.branch(s, u)
    return Polished(inputs=u, decisions=problem.decision_names, free=free, held=held,
                    hessian=hessian, error=error, gradient=g,
                    value=float(problem.cost(g.outcome, g.y_final, u)), count=costs.count)


def optimal_derivatives(problem: Problem, s: float, *, probe: float = 1e-7,
                        variational: VariationalOptions = DEFAULT_VARIATIONAL) -> Derivatives:
    """(left, right) derivatives in s of the optimal outcome, value and policy of ``problem``
    (see the module docstring); ``probe`` must exceed the accuracy to which a policy jump at s is
    located and stay below the distance to the next nonsmooth point; ``variational`` sets the
    sensitivities' integration."""
    return optimal_derivatives_with_errors(problem, s, probe=probe, variational=variational)[0]


def optimal_derivatives_with_errors(problem: Problem, s: float, *, probe: float = 1e-7,
                                    variational: VariationalOptions = DEFAULT_VARIATIONAL
                                    ) -> tuple[Derivatives, DerivativeErrors]:
    """:func:`optimal_derivatives` with an error estimate of every slope
    (:class:`DerivativeErrors`)."""
    if not isinstance(problem, Problem):
        raise InvalidInputError(f"problem must be a Problem, got {problem!r}")
    if not (isinstance(probe, float) and 0.0 < probe <= 1e-3):
        raise InvalidInputError(f"probe must be a number in (0, 1e-3], got {probe!r}")
    s = float(s)
    if not math.isfinite(s):
        raise InvalidInputError(f"{problem.name}: s must be finite, got {s}")
    compiled = compiled_for(problem)
    if not isinstance(variational, VariationalOptions):
        raise InvalidInputError(f"variational must be VariationalOptions, got {variational!r}")
    sides = {side: _side(problem, compiled, s, side, probe, variational) for side in (-1, 1)}
    left, right = sides[-1], sides[1]
    derivatives = Derivatives(
        problem=problem.name, theta0=s,
        outcome=(left["outcome_slope"], right["outcome_slope"]),
        value=(left["value_slope"], right["value_slope"]),
        policy={d: (left["slope"][d], right["slope"][d]) for d in problem.decision_names},
        outcome_limits=(left["outcome"], right["outcome"]),
        value_limits=(left["value"], right["value"]),
        policy_limits={d: (left["policy"][d], right["policy"][d])
                       for d in problem.decision_names},
        branches=(left["branch"], right["branch"]),
        at_bound=(left["held"], right["held"]), nsens=left["count"] + right["count"])
    errors = DerivativeErrors(
        outcome=(left["outcome_error"], right["outcome_error"]),
        value=(left["value_error"], right["value_error"]),
        policy={d: (left["slope_error"][d], right["slope_error"][d])
                for d in problem.decision_names},
        polish=(left["polish_error"], right["polish_error"]))
    return derivatives, errors


def _side(problem: Problem, compiled: CompiledSystem, s: float, side: int, probe: float,
          variational: VariationalOptions) -> dict[str, Any]:
    """The derivatives on the branch s -> s^side (module docstring), with error estimates."""
    names = problem.facts.inputs
    start = optimal_policy(problem, s + side * probe)
    if not start.success:
        raise SimulationError(f"{problem.name} at s = {s + side * probe}: no optimum "
                              f"({start.message})")
    polished = polish_optimum(problem, s, start, side=side, variational=variational)
    u, g = polished.inputs, polished.gradient
    cols = [names.index(d) for d in polished.free]
    costs = _Costs(problem, compiled, side, cols, variational)
    # the Hessian again at the polished optimum: the polish's is at the optimum of s + side *
    # probe, |du*/ds| probe away (2e-6 on the walkers), enough to move the slope by ~1e-6
    dc = cost_gradient(problem, g, u)
    slope = np.zeros(len(names))
    slope_error = np.zeros(len(names))
    value_error = 0.0
    floor = variational.rtol  # the sensitivities' relative integration tolerance
    if cols:
        hessian, asym, mixed, mixed_error = costs.second_derivatives(s, u)
        slope[cols] = -np.linalg.solve(hessian, mixed)
        inverse = np.abs(np.linalg.inv(hessian))
        slope_error[cols] = inverse @ (mixed_error + asym * np.abs(slope[cols]))
        value_error = float(np.abs(mixed).sum() * polished.error)
    value_error += floor * max(1.0, abs(float(dc[0])))
    outcome_slope = float(g.gradient[0] + g.gradient[1:] @ slope)
    outcome_error = (float(np.abs(g.gradient[1:]) @ slope_error)
                     + floor * max(1.0, abs(outcome_slope)))
    return {
        "policy": {d: float(u[names.index(d)]) for d in problem.decision_names},
        "slope": {d: float(slope[names.index(d)]) for d in problem.decision_names},
        "slope_error": {d: float(slope_error[names.index(d)]) for d in problem.decision_names},
        "value": polished.value, "value_slope": float(dc[0]), "value_error": value_error,
        "outcome": g.outcome, "outcome_slope": outcome_slope, "outcome_error": outcome_error,
        "held": polished.held, "branch": start.branch, "polish_error": polished.error,
        "count": polished.count + costs.count,
    }
