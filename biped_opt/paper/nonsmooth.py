"""The biped's nonsmooth tables (MODEL.md Sec. 6) on the engine of
:mod:`biped_opt.analysis.switches`: the paper's [1]_ problems and fixed inputs, branches in its
mode names (``AIR->LEFT->GROUND``).

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from biped_opt.analysis.switches import (
    BoundSlope,
    Evaluator,
    NonsmoothReport,
    Sample,
    analyse_switches,
    bound_relocation,
)
from biped_opt.control.solve import OptimalResult
from biped_opt.errors import InvalidInputError
from biped_opt.paper.biped import (
    FIXED_INPUTS,
    BipedParams,
    ContactMode,
    check_inputs,
    parse_maneuver,
    simulate,
    theta0_limit,
)
from biped_opt.paper.derivatives import outcome_sensitivity
from biped_opt.paper.problems import OptimalControlProblem
from biped_opt.paper.solve import optimal_policy
from biped_opt.paper.sweeps import sweep_fixed, sweep_grid, sweep_optimal
from biped_opt.progress import bar as _bar
from biped_opt.simulation.options import DEFAULT_OPTIONS, SimulatorOptions

__all__ = ["find_nonsmooth_fixed", "find_nonsmooth_optimal"]


def _optimal_sample(r: OptimalResult) -> Sample:
    values = {"outcome": r.outcome, "value": r.value}
    values.update({f"policy:{d}": v for d, v in r.policy.items()})
    return Sample(label=(r.branch, r.active, r.bound), values=values, branch=r.branch,
                   active=r.active, bound=r.bound, result=r)


def _bound_slope(problem: OptimalControlProblem) -> BoundSlope:
    """d c / d u at the bound from the exact sensitivity d th_f / d u (a single decision acts
    at a time in the biped's problems: the others stay at their defaults)."""

    def slope(held: Sample, decision: str, th: float) -> float:
        end = held.result.policy[decision]
        s = outcome_sensitivity(problem.maneuver, th, problem.inputs({decision: end}),
                                params=problem.params, options=problem.options)
        return (problem.outcome_slope(s.outcome) * s.d_input(decision)
                + 2.0 * problem.alpha(decision) * end)

    return slope


# --- public API -------------------------------------------------------------------------------
def find_nonsmooth_fixed(
    maneuver: str,
    theta0: npt.ArrayLike | None = None,
    inputs: npt.ArrayLike | None = None,
    *,
    params: BipedParams | None = None,
    options: SimulatorOptions = DEFAULT_OPTIONS,
    num: int = 401,
    progress: bool = False,
) -> NonsmoothReport:
    """Nonsmooth points of the outcome th_f(th0) at fixed inputs (default: the paper's).

    ``theta0`` is the sweep grid (default: ``num`` points over the valid range, 0 included).
    """
    name = parse_maneuver(maneuver).value
    u = check_inputs(FIXED_INPUTS[name] if inputs is None else inputs)
    grid = sweep_grid(name, num=num) if theta0 is None else np.asarray(theta0, dtype=float)
    sweep = sweep_fixed(name, grid, u, params=params, options=options, progress=progress)
    nsim = [0]

    def sample(th: float) -> Sample:
        tr = simulate(name, th, u, params=params, options=options)
        nsim[0] += 1
        label = ("->".join(ContactMode(m).name for m in tr.mode_sequence) if tr.success
                 else f"FAILED:{tr.status.name}")
        return Sample(label=label, values={"outcome": tr.outcome}, branch=label)

    ev = Evaluator(sample)
    for k, th in enumerate(sweep.theta0):
        ev.cache[float(th)] = Sample(
            label=sweep.branch[k], values={"outcome": float(sweep.outcome[k])},
            branch=sweep.branch[k],
        )
    bar = _bar(progress, 1, f"{name} locating")
    points = analyse_switches(ev, sweep.theta0, ["outcome"], theta0_limit(name), False,
                              bar)
    return NonsmoothReport(
        subject=name,
        optimal=False,
        theta0_range=(float(sweep.theta0[0]), float(sweep.theta0[-1])),
        grid_size=int(sweep.theta0.size),
        points=tuple(points),
        nsim=nsim[0] + int(sweep.theta0.size),
    )


def find_nonsmooth_optimal(
    problem: OptimalControlProblem,
    theta0: npt.ArrayLike | None = None,
    *,
    num: int = 201,
    progress: bool = False,
) -> NonsmoothReport:
    """Nonsmooth points of the optimal outcome, policy and value (Eqs. (5), (6) of [1]_).

    ``theta0`` is the sweep grid (default: ``num`` points over the valid range, 0 included).
    """
    if not isinstance(problem, OptimalControlProblem):
        raise InvalidInputError(f"problem must be an OptimalControlProblem, got {problem!r}")
    grid = (sweep_grid(problem.maneuver, num=num) if theta0 is None
            else np.asarray(theta0, dtype=float))
    sweep = sweep_optimal(problem, grid, progress=progress)
    nsim = [0]

    def sample(th: float) -> Sample:
        r = optimal_policy(problem, th)
        nsim[0] += r.nsim
        return _optimal_sample(r)

    ev = Evaluator(sample)
    for r in sweep.results:
        ev.cache[float(r.theta0)] = _optimal_sample(r)
    quantities = ["outcome", *(f"policy:{d}" for d in problem.decisions), "value"]
    bar = _bar(progress, 1, f"{problem.name} locating")
    limit = theta0_limit(problem.maneuver)
    points = analyse_switches(ev, sweep.theta0, quantities, limit, True, bar,
                              bound_relocation(ev, limit, _bound_slope(problem)))
    return NonsmoothReport(
        subject=problem.name,
        optimal=True,
        theta0_range=(float(sweep.theta0[0]), float(sweep.theta0[-1])),
        grid_size=int(sweep.theta0.size),
        points=tuple(points),
        nsim=nsim[0] + int(sweep.nsim.sum()),
    )
