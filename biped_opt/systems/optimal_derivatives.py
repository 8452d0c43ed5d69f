"""One-sided derivatives of any system's optimal outcome, value and policy (Theorem 1 of [1]_).

For a :class:`~biped_opt.systems.problems.Problem` and a side sigma = -1 or +1 of s, the branch
that s -> s^sigma follows is found by solving the problem at s + sigma * probe; on that branch,
at s itself, with p = (s, u) and the exact first-order sensitivities of
:func:`biped_opt.systems.derivatives.outcome_gradient` taken along sigma e_s:

- the optimum is polished by Newton's method on D_u c = 0 over the free decisions (acting and
  off their bounds), the Hessian from central differences of the exact gradient;
- value: dV/ds = D_s c (envelope theorem, Eq. (12): D_u c = 0 on the free decisions and du/ds
  = 0 on the bound ones);
- policy: du*/ds = -(D_uu c)^-1 D_us c on the free decisions (implicit function theorem,
  Eq. (13)), D_us c the one-sided difference of D_u c along sigma (Richardson-extrapolated); 0
  for decisions on a bound or acting on nothing;
- outcome: d o/ds + D_u o du*/ds.

with c = w (o - target)^2 + sum_k W_k (y_k(t_f) - r_k)^2 + sum_i alpha_i u_i^2. The result is
the biped's :class:`~biped_opt.optimal.derivatives.Derivatives` record (``theta0`` holding s).

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from biped_opt.errors import InvalidInputError, SimulationError
from biped_opt.optimal.derivatives import Derivatives
from biped_opt.systems.compiled import CompiledSystem
from biped_opt.systems.derivatives import OutcomeGradient, outcome_gradient
from biped_opt.systems.optimal import compiled_for, optimal_policy
from biped_opt.systems.problems import Problem

__all__ = ["optimal_derivatives", "cost_gradient"]

Array = npt.NDArray[np.float64]

#: central-difference step of the Hessian D_uu c, relative to each decision's bound interval
HESSIAN_STEP = 1e-4
#: one-sided step in s of the mixed derivative D_us c (halved once for Richardson)
MIXED_STEP = 1e-4
#: Newton iterations of the polish at s
NEWTON_STEPS = 3


def cost_gradient(problem: Problem, g: OutcomeGradient, inputs: Array) -> Array:
    """D c over (s, *inputs) from the branch's outcome and final-state gradients."""
    out = 2.0 * problem.outcome_weight * (g.outcome - problem.target) * g.gradient
    for col, w, r in problem.final_state_columns:
        out = out + 2.0 * w * (g.y_final[col] - r) * g.state_gradient[col]
    for col, a in zip(problem.decision_columns, problem.weights):
        out[1 + col] += 2.0 * a * inputs[col]
    return out


def optimal_derivatives(problem: Problem, s: float, *, probe: float = 1e-7) -> Derivatives:
    """(left, right) derivatives in s of the optimal outcome, value and policy of ``problem``
    (see the module docstring); ``probe`` must exceed the accuracy to which a policy jump at s is
    located and stay below the distance to the next nonsmooth point."""
    if not isinstance(problem, Problem):
        raise InvalidInputError(f"problem must be a Problem, got {problem!r}")
    if not (isinstance(probe, float) and 0.0 < probe <= 1e-3):
        raise InvalidInputError(f"probe must be a number in (0, 1e-3], got {probe!r}")
    s = float(s)
    if not math.isfinite(s):
        raise InvalidInputError(f"{problem.name}: s must be finite, got {s}")
    compiled = compiled_for(problem)
    sides = {side: _side(problem, compiled, s, side, probe) for side in (-1, 1)}
    left, right = sides[-1], sides[1]
    return Derivatives(
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


def _side(problem: Problem, compiled: CompiledSystem, s: float, side: int, probe: float
          ) -> dict[str, Any]:
    """The derivatives on the branch s -> s^side (module docstring)."""
    names = problem.description.u.names()
    start = optimal_policy(problem, s + side * probe)
    if not start.success:
        raise SimulationError(f"{problem.name} at s = {s + side * probe}: no optimum "
                              f"({start.message})")
    direction = np.zeros(1 + len(names))
    direction[0] = side
    acting = set((start.active or "").split("+")) - {""}
    held = {d for d in acting if start.policy[d] in problem.bound(d)}
    free = [d for d in problem.decision_names if d in acting and d not in held]
    cols = [names.index(d) for d in free]
    count = 0

    def branch(x: float, u: Array) -> OutcomeGradient:
        nonlocal count
        count += 1
        return outcome_gradient(compiled, problem.maneuver, x, u, direction=direction)

    def grad_u(x: float, u: Array) -> Array:
        return cost_gradient(problem, branch(x, u), u)[[1 + c for c in cols]]

    u = start.inputs.copy()
    steps = np.array([HESSIAN_STEP * (problem.bound(d)[1] - problem.bound(d)[0]) for d in free])
    hessian = np.zeros((len(free), len(free)))
    for _ in range(NEWTON_STEPS if free else 0):
        g0 = grad_u(s, u)
        for j, c in enumerate(cols):
            up, down = u.copy(), u.copy()
            up[c] += steps[j]
            down[c] -= steps[j]
            hessian[:, j] = (grad_u(s, up) - grad_u(s, down)) / (2.0 * steps[j])
        hessian = 0.5 * (hessian + hessian.T)
        step = np.linalg.solve(hessian, -g0)
        u[cols] = u[cols] + step
        if np.all(np.abs(step) <= 1e-12 * np.maximum(1.0, np.abs(u[cols]))):
            break
    g = branch(s, u)
    dc = cost_gradient(problem, g, u)
    slope = np.zeros(len(names))
    if free:
        h = MIXED_STEP
        base = dc[[1 + c for c in cols]]  # D_u c at (s, u), from the gradient just taken
        coarse = (grad_u(s + side * h, u) - base) / (side * h)
        fine = (grad_u(s + side * h / 2, u) - base) / (side * h / 2)
        slope[cols] = -np.linalg.solve(hessian, 2.0 * fine - coarse)  # Richardson: O(h^2)
    return {
        "policy": {d: float(u[names.index(d)]) for d in problem.decision_names},
        "slope": {d: float(slope[names.index(d)]) for d in problem.decision_names},
        "value": float(problem.cost(g.outcome, g.y_final, u)), "value_slope": float(dc[0]),
        "outcome": g.outcome, "outcome_slope": float(g.gradient[0] + g.gradient[1:] @ slope),
        "held": tuple(sorted(held)), "branch": start.branch, "count": count,
    }
