"""Where any system's outcome, optimal policy and value are not C^1 in s, and why.

The same engine as the biped's tables (:func:`biped_opt.optimal.nonsmooth.analyse_switches`):
label every grid point by its mode sequence (impacts that separated at once included, see
:func:`biped_opt.control.solve.branch_of`) - and, for optimal control, by which decisions act
and which bounds hold them -, locate every change of label by bisection to 1e-10, measure
one-sided limits and derivatives there by extrapolation and classify **jump**, **kink** or
**second-derivative**. A change of label whose sides agree to C^1 (the decoupled walker's
simultaneous touchdown) is not a nonsmooth point and is not listed.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from biped_opt.analysis.switches import Evaluator, NonsmoothReport, Sample, analyse_switches
from biped_opt.control.problems import Problem
from biped_opt.control.solve import SystemOptimalResult, branch_of, optimal_policy, optimal_sweep
from biped_opt.errors import InvalidInputError
from biped_opt.piecewise import theta_grid
from biped_opt.progress import bar as _bar
from biped_opt.simulation.compiled import CompiledSystem

__all__ = ["find_nonsmooth", "find_nonsmooth_optimal", "s_grid"]


def s_grid(compiled: CompiledSystem, maneuver: str, num: int,
           lo: float | None = None, hi: float | None = None) -> npt.NDArray[np.float64]:
    """``num`` evenly spaced s over the maneuver's range (or [lo, hi]), 0 included if inside."""
    s_lo, s_hi = compiled.derived.maneuvers[maneuver].description.s_range
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
    u = compiled._inputs(inputs)
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
                              cause=_system_cause)
    return NonsmoothReport(subject=f"{compiled.name}:{maneuver}", optimal=False,
                           theta0_range=(float(grid[0]), float(grid[-1])),
                           grid_size=int(grid.size), points=tuple(points), nsim=nsim[0],
                           parameter=str(compiled.system.s))


def _sample_of(r: SystemOptimalResult) -> Sample:
    values = {"outcome": r.outcome, "value": r.value}
    values.update({f"policy:{d}": v for d, v in r.policy.items()})
    return Sample(label=(r.branch, r.active, r.bound), values=values, branch=r.branch,
                  active=r.active, bound=r.bound, result=r)  # type: ignore[arg-type]


def find_nonsmooth_optimal(problem: Problem, s: npt.ArrayLike | None = None, *,
                           num: int = 201, progress: bool = False) -> NonsmoothReport:
    """Nonsmooth points of the optimal outcome, policy and value of ``problem`` in s."""
    if not isinstance(problem, Problem):
        raise InvalidInputError(f"problem must be a Problem, got {problem!r}")
    from biped_opt.control.solve import compiled_for

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
    points = analyse_switches(ev, grid, quantities, _limit(grid), True, locate,
                              cause=_system_cause)
    return NonsmoothReport(subject=problem.name, optimal=True,
                           theta0_range=(float(grid[0]), float(grid[-1])),
                           grid_size=int(grid.size), points=tuple(points), nsim=nsim[0],
                           parameter=str(compiled.system.s))


def _bounds(text: str | None, active: str | None) -> dict[str, str]:
    """{decision: "lower"/"upper"} from a result's ``bound`` label."""
    if not text:
        return {}
    if "=" not in text:
        return {active: text} if active else {}
    return dict(part.split("=", 1) for part in text.split(","))


def _system_cause(sl: Sample, sr: Sample, optimal: bool, policy_jumps: bool) -> str:
    """Why the label changes between the two sides, in the problem's own names."""
    causes = []
    if sl.branch != sr.branch:
        both = (sl.result is not None and sr.result is not None
                and sr.branch in {c.branch for c in sl.result.candidates}
                and sl.branch in {c.branch for c in sr.result.candidates})
        if optimal and policy_jumps and both:
            causes.append(f"optimal branch switches: {sl.branch} | {sr.branch} "
                          "(the global minimum moves to another local minimum)")
        else:
            causes.append(f"mode sequence changes: {sl.branch} | {sr.branch}")
    if optimal and sl.active != sr.active:
        causes.append(f"acting inputs change: {sl.active or 'none'} | {sr.active or 'none'}")
    if optimal and sl.result is not None:
        problem = sl.result.problem
        left, right = _bounds(sl.bound, sl.active), _bounds(sr.bound, sr.active)
        for d in problem.decision_names:
            a, b = left.get(d), right.get(d)
            if a == b:
                continue
            lo, hi = problem.bound(d)
            if b is not None:
                verb = "reaches" if a is None else "moves to"
                causes.append(f"input {d} {verb} its {b} bound {lo if b == 'lower' else hi:g}")
            else:
                causes.append(f"input {d} leaves its {a} bound {lo if a == 'lower' else hi:g}")
    return "; ".join(causes) if causes else "change of label without a mode change"
