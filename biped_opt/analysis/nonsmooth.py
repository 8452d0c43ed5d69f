"""Where any system's outcome, optimal policy and value are not C^1 in s, and why.

The same engine as the biped's tables (:func:`biped_opt.analysis.switches.analyse_switches`):
label every grid point by its mode sequence (impacts that separated at once included, see
:func:`biped_opt.control.solve.branch_of`) - and, for optimal control, by which decisions act
and which bounds hold them -, locate every change of label by bisection to 1e-10 (a decision
reaching or leaving a bound: on the sign of the cost's exact slope at the bound, the
Karush-Kuhn-Tucker point, :func:`biped_opt.analysis.switches.bound_relocation`), measure
one-sided limits and derivatives there by extrapolation and classify **jump**, **kink** or
**second-derivative**. A change of label whose sides agree to C^1 (the decoupled walker's
simultaneous touchdown) is not a nonsmooth point and is not listed.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from biped_opt.analysis.switches import (
    CauseWords,
    Evaluator,
    NonsmoothReport,
    Sample,
    analyse_switches,
    bound_relocation,
    describe_change,
)
from biped_opt.control.problems import Problem
from biped_opt.control.solve import (
    SystemOptimalResult,
    branch_of,
    compiled_for,
    optimal_policy,
    optimal_sweep,
)
from biped_opt.control.theorem1 import cost_gradient, polish_optimum
from biped_opt.errors import InvalidInputError
from biped_opt.piecewise import theta_grid
from biped_opt.progress import bar as _bar
from biped_opt.simulation.compiled import CompiledSystem

__all__ = ["find_nonsmooth", "find_nonsmooth_optimal", "s_grid", "bound_slope", "WORDS"]

#: any system's tables name a change of contact modes a mode sequence
WORDS = CauseWords(modes="mode sequence changes", acting="acting inputs change")


def s_grid(compiled: CompiledSystem, maneuver: str, num: int,
           lo: float | None = None, hi: float | None = None) -> npt.NDArray[np.float64]:
    """``num`` evenly spaced s over the maneuver's range (or [lo, hi]), 0 included if inside."""
    s_lo, s_hi = compiled.s_range(maneuver)
    lo = s_lo if lo is None else float(lo)
    hi = s_hi if hi is None else float(hi)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise InvalidInputError(f"s range must have finite lo < hi, got [{lo}, {hi}]")
    if isinstance(num, bool) or not isinstance(num, int) or num < 2:
        raise InvalidInputError(f"num must be an integer >= 2, got {num!r}")
    return theta_grid(lo, hi, num)


def _limit(grid: npt.NDArray[np.float64]) -> float:
    return float(max(abs(grid[0]), abs(grid[-1])))


def find_nonsmooth(system: CompiledSystem | str, maneuver: str, inputs: Any = None, *,
                   s: npt.ArrayLike | None = None, num: int = 401,
                   parameters: Mapping[str, float] | None = None,
                   progress: bool = False) -> NonsmoothReport:
    """Nonsmooth points of ``maneuver``'s outcome in s at fixed ``inputs`` (by name or vector).

    ``s`` is the sweep grid (default ``num`` points over the maneuver's range, 0 included).
    """
    compiled = system if isinstance(system, CompiledSystem) else \
        CompiledSystem(system, **dict(parameters or {}))
    if parameters and isinstance(system, CompiledSystem):
        compiled.set_parameters(**dict(parameters))
    compiled.initial_mode(maneuver)  # an unknown maneuver: the system's message
    grid = s_grid(compiled, maneuver, num) if s is None else \
        np.unique(np.asarray(s, dtype=np.float64))
    if grid.size < 2 or not np.all(np.isfinite(grid)):
        raise InvalidInputError("s must hold at least two finite values")
    u = compiled.input_vector(inputs)
    first = compiled.initial_mode(maneuver)
    batch = compiled.simulate_batch(maneuver, grid, u)
    nsim = [int(grid.size)]

    def sample(x: float) -> Sample:
        tr = compiled.simulate(maneuver, x, u)
        nsim[0] += 1
        label = branch_of(compiled, first, tr.event_rows[: tr.n_events], tr.status)
        return Sample(label=label, values={"outcome": tr.outcome}, branch=label)

    ev = Evaluator(sample)
    for k, x in enumerate(grid):
        n = int(batch.n_events[k])
        label = branch_of(compiled, first, batch.event_rows[k, :n], int(batch.status[k]))
        ev.cache[float(x)] = Sample(label=label, values={"outcome": float(batch.outcome[k])},
                                    branch=label)
    bar = _bar(progress, 1, f"{compiled.name} {maneuver} locating")
    points = analyse_switches(ev, grid, ["outcome"], _limit(grid), False, bar,
                              cause=describe_change(WORDS))
    return NonsmoothReport(subject=f"{compiled.name}:{maneuver}", optimal=False,
                           theta0_range=(float(grid[0]), float(grid[-1])),
                           grid_size=int(grid.size), points=tuple(points), nsim=nsim[0],
                           parameter=compiled.s_name)


def _sample_of(r: SystemOptimalResult) -> Sample:
    values = {"outcome": r.outcome, "value": r.value}
    values.update({f"policy:{d}": v for d, v in r.policy.items()})
    return Sample(label=(r.branch, r.active, r.bound), values=values, branch=r.branch,
                  active=r.active, bound=r.bound, result=r)


def find_nonsmooth_optimal(problem: Problem, s: npt.ArrayLike | None = None, *,
                           num: int = 201, progress: bool = False) -> NonsmoothReport:
    """Nonsmooth points of the optimal outcome, policy and value of ``problem`` in s."""
    if not isinstance(problem, Problem):
        raise InvalidInputError(f"problem must be a Problem, got {problem!r}")
    compiled = compiled_for(problem)
    grid = s_grid(compiled, problem.maneuver, num) if s is None else \
        np.unique(np.asarray(s, dtype=np.float64))
    if grid.size < 2 or not np.all(np.isfinite(grid)):
        raise InvalidInputError("s must hold at least two finite values")
    bar = _bar(progress, grid.size, f"{problem.name} sweep")
    results = optimal_sweep(problem, grid, callback=bar.update)
    nsim = [sum(r.nsim for r in results)]

    def sample(x: float) -> Sample:
        r = optimal_policy(problem, x)
        nsim[0] += r.nsim
        return _sample_of(r)

    ev = Evaluator(sample)
    for r in results:
        ev.cache[float(r.s)] = _sample_of(r)
    quantities = ["outcome", *(f"policy:{d}" for d in problem.decision_names), "value"]
    locate = _bar(progress, 1, f"{problem.name} locating")
    limit = _limit(grid)
    points = analyse_switches(ev, grid, quantities, limit, True, locate,
                              bound_relocation(ev, limit, bound_slope),
                              cause=describe_change(WORDS))
    return NonsmoothReport(subject=problem.name, optimal=True,
                           theta0_range=(float(grid[0]), float(grid[-1])),
                           grid_size=int(grid.size), points=tuple(points), nsim=nsim[0],
                           parameter=compiled.s_name)


def bound_slope(held: Sample, decision: str, s: float) -> float:
    """d c / d ``decision`` at s with the decision on the bound it has in the optimum ``held``
    (a :class:`~biped_opt.analysis.switches.BoundSlope`): the exact sensitivities of
    :func:`biped_opt.control.derivatives.outcome_gradient` through the whole cost
    (:func:`biped_opt.control.theorem1.cost_gradient`: outcome, final-state and input terms).
    The other acting decisions off their bounds are first polished to their optimum at s
    (Newton on D_u c = 0 with the decision held, :func:`polish_optimum`): the slope at the bound
    is that of the constrained optimum, which meets the free one where the slope is 0."""
    result: SystemOptimalResult = held.result
    problem = result.problem
    polished = polish_optimum(problem, s, result, side=1)
    column = 1 + problem.facts.inputs.index(decision)
    return float(cost_gradient(problem, polished.gradient, polished.inputs)[column])
