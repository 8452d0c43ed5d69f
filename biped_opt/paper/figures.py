"""The data of the paper's figures: what Figs. 2-4 and the control experiment show, computed.

Nothing here draws (:mod:`biped_opt.plots.figures` and :mod:`biped_opt.plots.systems` do); this
module runs the sweeps and the nonsmooth analysis and turns them into plain arrays and records:

- :func:`reproduction_data`: the fixed-input sweeps (Figs. 2, 3) and the optimal sweeps (Fig. 4)
  of touchdown and liftoff, each with the nonsmooth report of the one engine
  (:mod:`biped_opt.analysis.switches`), and the liftoff variant's report;
- :func:`fixed_data` and :func:`optimal_data`: one sweep (live or read back from a recording) as
  :class:`FixedSweepData` / :class:`OptimalSweepData`, its nonsmooth points as
  :class:`NonsmoothMark` - on the cost panels mapped through the cost (:func:`cost_mark`);
- :func:`control_experiment_data`: the two-leg walker under the coupled and the decoupled input
  law and the rocking bar (SYSTEMS.md Secs. 2-3), with each curve's behaviour at th0 = 0 (the
  engine's jump or kink there, else the exact one-sided slopes of the variational equation).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from biped_opt.analysis.figure_data import Mark, system_marks
from biped_opt.analysis.switches import NonsmoothPoint, NonsmoothReport
from biped_opt.control.derivatives import one_sided_derivatives
from biped_opt.errors import InvalidInputError
from biped_opt.paper.biped import ContactMode
from biped_opt.paper.nonsmooth import find_nonsmooth_fixed, find_nonsmooth_optimal
from biped_opt.paper.problems import OptimalControlProblem, get_problem
from biped_opt.paper.sweeps import FixedSweep, OptimalSweep, sweep_fixed, sweep_grid, sweep_optimal
from biped_opt.piecewise import theta_grid
from biped_opt.simulation.compiled import CompiledSystem

__all__ = [
    "MANEUVERS",
    "NonsmoothMark",
    "FixedSweepData",
    "OptimalSweepData",
    "marks",
    "cost_mark",
    "fixed_data",
    "optimal_data",
    "ReproductionData",
    "reproduction_data",
    "TOUCHDOWN_INPUTS",
    "LIFTOFF_INPUTS",
    "LAWS",
    "ControlExperiment",
    "control_experiment_data",
    "at_zero",
]

Array = npt.NDArray[np.float64]

MANEUVERS = ("touchdown", "liftoff")


# --- Figs. 2-4 ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class NonsmoothMark:
    """A nonsmooth point to mark on a curve: where, what, and its one-sided numbers."""

    theta0: float
    kind: str  #: "kink", "jump" or "second-derivative"
    left: float
    right: float
    value: float  #: the curve's value at theta0 (where the marker goes)
    label: str = ""  #: what left/right are ("limit", "slope", ...)


@dataclass(frozen=True)
class FixedSweepData:
    """A fixed-input sweep of one maneuver: outcomes, costs and mode timelines per angle."""

    maneuver: str
    inputs: tuple[float, float, float]
    theta0: Array
    outcome: Array
    cost: Array
    #: per angle: event times (entry into each later mode) and the mode sequence
    event_times: Sequence[Array]
    modes: Sequence[Sequence[int]]
    t_final: Array
    marks: Sequence[NonsmoothMark] = field(default=())  #: on the outcome panels
    cost_marks: Sequence[NonsmoothMark] = field(default=())  #: on the cost panels


@dataclass(frozen=True)
class OptimalSweepData:
    """An optimal sweep of one maneuver: outcome, policy (one array per decision) and value."""

    maneuver: str
    theta0: Array
    outcome: Array
    policy: dict[str, Array]
    value: Array
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    marks: dict[str, Sequence[NonsmoothMark]] = field(default_factory=dict)


def marks(points: Sequence[NonsmoothPoint], quantity: str,
          values: Mapping[float, float] | None = None) -> list[NonsmoothMark]:
    """Figure marks for the points of one quantity (limits for jumps, slopes for kinks...).
    (``values`` is not used: a point carries its own value ``at``.)"""
    out = []
    what = {"jump": "limit", "kink": "slope", "second-derivative": "2nd deriv."}
    for p in points:
        if p.quantity != quantity:
            continue
        name = f"{p.input}: " if p.input else ""
        out.append(NonsmoothMark(theta0=p.theta0, kind=f"{name}{p.kind}", left=p.left,
                                 right=p.right, value=p.at, label=what.get(p.kind, "")))
    return out


def cost_mark(mark: NonsmoothMark, problem: OptimalControlProblem, inputs: npt.ArrayLike
              ) -> NonsmoothMark:
    """The outcome's nonsmooth point seen through the cost c = (th_f - th*)^2 + sum alpha u^2:
    limits map through c, slopes through dc/dth_f = 2 (th_f - th*) at the point's value."""
    u = np.asarray(inputs, dtype=np.float64)

    def cost(th_f: float) -> float:
        return float(problem.cost(th_f, u))

    if "jump" in mark.kind:
        left, right = cost(mark.left), cost(mark.right)
    else:
        gain = problem.outcome_slope(mark.value)
        left, right = gain * mark.left, gain * mark.right
    return NonsmoothMark(theta0=mark.theta0, kind=mark.kind, left=left, right=right,
                         value=cost(mark.value), label=mark.label)


def fixed_data(sweep: FixedSweep, problem: OptimalControlProblem,
               points: Sequence[NonsmoothPoint] = ()) -> FixedSweepData:
    """Plain arrays of a fixed-input sweep for Figs. 2 and 3 (cost per the maneuver's problem)."""
    modes = [[int(ContactMode[m]) for m in b.split("->")] if not b.startswith("FAILED") else [0]
             for b in sweep.branch]
    outcome_marks = marks(points, "outcome")
    return FixedSweepData(
        maneuver=sweep.maneuver,
        inputs=tuple(float(v) for v in sweep.inputs),  # type: ignore[arg-type]
        theta0=sweep.theta0,
        outcome=sweep.outcome,
        cost=np.asarray(problem.cost(sweep.outcome, np.tile(sweep.inputs, (sweep.theta0.size, 1)))),
        event_times=[np.asarray(t) for t in sweep.event_times],
        modes=modes,
        t_final=sweep.t_final,
        marks=tuple(outcome_marks),
        cost_marks=tuple(cost_mark(m, problem, sweep.inputs) for m in outcome_marks),
    )


def optimal_data(sweep: OptimalSweep, points: Sequence[NonsmoothPoint] = ()) -> OptimalSweepData:
    """Plain arrays of an optimal sweep for Fig. 4, marks per quantity."""
    problem = sweep.problem
    return OptimalSweepData(
        maneuver=problem.maneuver.value,
        theta0=sweep.theta0,
        outcome=sweep.outcome,
        policy=dict(sweep.policy),
        value=sweep.value,
        bounds={d: problem.bound(d) for d in problem.decisions},
        marks={q: tuple(marks(points, q)) for q in ("outcome", "policy", "value")},
    )


@dataclass(frozen=True)
class ReproductionData:
    """Everything Figs. 2-4 and their captions show."""

    fixed: dict[str, FixedSweepData]  #: maneuver -> Figs. 2, 3 data
    optimal: dict[str, OptimalSweepData]  #: maneuver -> Fig. 4 data
    #: fixed touchdown, fixed liftoff, optimal touchdown, optimal liftoff, liftoff variant
    reports: tuple[NonsmoothReport, ...]
    problems: tuple[OptimalControlProblem, ...]  #: touchdown, liftoff, liftoff-variant
    fixed_num: int
    optimal_num: int


def reproduction_data(*, fixed_num: int = 401, optimal_num: int = 201,
                      progress: bool = False) -> ReproductionData:
    """The fixed-input sweeps (``fixed_num`` angles per maneuver) and optimal sweeps
    (``optimal_num``) with every nonsmooth point of outcomes, policies and values (and of the
    liftoff variant's value)."""
    problems = {m: get_problem(m) for m in MANEUVERS}
    variant = get_problem("liftoff-variant")
    fixed, optimal, reports = {}, {}, []
    for m in MANEUVERS:
        grid = sweep_grid(m, num=fixed_num)
        report = find_nonsmooth_fixed(m, grid, progress=progress)
        reports.append(report)
        fixed[m] = fixed_data(sweep_fixed(m, grid, progress=progress), problems[m], report.points)
    for m in MANEUVERS:
        grid = sweep_grid(m, num=optimal_num)
        report = find_nonsmooth_optimal(problems[m], grid, progress=progress)
        reports.append(report)
        optimal[m] = optimal_data(sweep_optimal(problems[m], grid, progress=progress),
                                  report.points)
    reports.append(find_nonsmooth_optimal(variant, sweep_grid("liftoff", num=optimal_num),
                                          progress=progress))
    return ReproductionData(fixed=fixed, optimal=optimal, reports=tuple(reports),
                            problems=(*problems.values(), variant), fixed_num=fixed_num,
                            optimal_num=optimal_num)


# --- the control experiment ---------------------------------------------------------------------
#: SYSTEMS.md Sec. 3: the paper's fixed inputs (u1, u2, u_body) of the two-leg walker
TOUCHDOWN_INPUTS = (2.0, 0.5, 0.0)
LIFTOFF_INPUTS = (1.5, 3.0, 0.0)
LAWS = ("coupled", "decoupled")


@dataclass(frozen=True)
class ControlExperiment:
    """Walker outcomes under both input laws on one grid (0 included), and the rocking bar's."""

    s: Array
    touchdown: dict[str, Array]  #: law -> outcome th(t_f)
    liftoff: dict[str, Array]
    touchdown_marks: tuple[Mark, ...]  #: each with ``series`` = its law
    liftoff_marks: tuple[Mark, ...]
    bar_s: Array
    bar: Array  #: the rocking bar's drop outcome th'(t_f)
    bar_marks: tuple[Mark, ...]
    #: (maneuver, law) -> what the curve does at th0 = 0: ("jump", limits) or ("kink", slopes)
    #: from the engine's point there (:func:`at_zero`), else ("C1", the one-sided slopes of the
    #: variational equation, :func:`biped_opt.control.derivatives.one_sided_derivatives`)
    zero: dict[tuple[str, str], tuple[str, tuple[float, float]]] = field(default_factory=dict)


def at_zero(marks: Sequence[Mark], law: str) -> tuple[str, tuple[float, float]] | None:
    """What the engine found at s = 0 on the curve of ``law``: ("jump", its one-sided limits)
    or ("kink", its one-sided slopes); None where it found neither."""
    mine = {m.kind: m for m in marks if m.series == law and m.s == 0.0}
    if "jump" in mine:
        return "jump", mine["jump"].limits
    if "kink" in mine:
        return "kink", mine["kink"].slopes
    return None


def control_experiment_data(*, half_width: float = 0.02, num: int = 801,
                            bar_num: int = 1201) -> ControlExperiment:
    """Outcomes of the two-leg walker, coupled and decoupled, at touchdown (u = (2, 0.5, 0))
    and liftoff (u = (1.5, 3, 0)) for th0 in [-half_width, half_width] (``num`` angles), and
    of the rocking bar's drop over its whole range (``bar_num`` angles), with their nonsmooth
    points."""
    if not 0.0 < half_width <= 0.3:
        raise InvalidInputError(f"half_width must lie in (0, 0.3], got {half_width!r}")
    for name, n in (("num", num), ("bar_num", bar_num)):
        if isinstance(n, bool) or not isinstance(n, int) or n < 5:
            raise InvalidInputError(f"{name} must be an integer >= 5, got {n!r}")
    s = theta_grid(-half_width, half_width, num)
    outcomes: dict[str, dict[str, Array]] = {"touchdown": {}, "liftoff": {}}
    found: dict[str, list[Mark]] = {"touchdown": [], "liftoff": []}
    zero: dict[tuple[str, str], tuple[str, tuple[float, float]]] = {}
    for law in LAWS:
        walker = CompiledSystem(f"walker2_{law}")
        for maneuver, u in (("touchdown", TOUCHDOWN_INPUTS), ("liftoff", LIFTOFF_INPUTS)):
            y, mine = system_marks(walker, maneuver, s, u, series=law)
            outcomes[maneuver][law] = y
            found[maneuver] += mine
            zero[(maneuver, law)] = at_zero(mine, law) or (
                "C1", one_sided_derivatives(walker, maneuver, 0.0, list(u)))
    bar = CompiledSystem("rocking_bar")
    lo, hi = bar.s_range("drop")
    bar_s = theta_grid(lo, hi, bar_num)
    bar_y, bar_marks = system_marks(bar, "drop", bar_s)
    return ControlExperiment(s=s, touchdown=outcomes["touchdown"], liftoff=outcomes["liftoff"],
                             touchdown_marks=tuple(found["touchdown"]),
                             liftoff_marks=tuple(found["liftoff"]), bar_s=bar_s, bar=bar_y,
                             bar_marks=tuple(bar_marks), zero=zero)
