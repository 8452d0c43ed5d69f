"""The paper's full reproduction: sweeps, nonsmoothness analysis, Figs. 2-4 and their captions.

:func:`reproduce` runs the fixed-input sweeps (401 angles per maneuver), the optimal sweeps (201
angles per maneuver), finds every nonsmooth point of the outcomes, policies and values (and of the
liftoff variant's value), draws the figures with the points marked and writes ``captions.txt``
(parameters, problems, the nonsmooth table). :func:`figure_data` turns sweeps into the plain
arrays the figure functions take, so recorded sweeps are drawn by the same code.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from biped_opt.model.modes import ContactMode
from biped_opt.model.params import BipedParams
from biped_opt.optimal import get_problem
from biped_opt.optimal.nonsmooth import (
    NonsmoothPoint,
    NonsmoothReport,
    find_nonsmooth_fixed,
    find_nonsmooth_optimal,
)
from biped_opt.optimal.problems import OptimalControlProblem
from biped_opt.optimal.sweep import FixedSweep, OptimalSweep, sweep_fixed, sweep_grid, sweep_optimal
from biped_opt.plots.figures import (
    FixedSweepData,
    NonsmoothMark,
    OptimalSweepData,
    figure2,
    figure3,
    figure4,
)

__all__ = ["Reproduction", "reproduce", "fixed_data", "optimal_data", "marks", "nonsmooth_table"]

MANEUVERS = ("touchdown", "liftoff")


@dataclass(frozen=True)
class Reproduction:
    figures: tuple[Path, ...]
    captions: Path
    reports: tuple[NonsmoothReport, ...]
    seconds: float

    def table(self) -> str:
        return nonsmooth_table(self.reports)


def marks(points: Sequence[NonsmoothPoint], quantity: str, values: dict[float, float] | None = None
          ) -> list[NonsmoothMark]:
    """Figure marks for the points of one quantity (limits for jumps, slopes for kinks...)."""
    out = []
    what = {"jump": "limit", "kink": "slope", "second-derivative": "2nd deriv."}
    for p in points:
        if p.quantity != quantity:
            continue
        name = f"{p.input}: " if p.input else ""
        out.append(NonsmoothMark(theta0=p.theta0, kind=f"{name}{p.kind}", left=p.left,
                                 right=p.right, value=p.at, label=what.get(p.kind, "")))
    return out


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
        cost_marks=tuple(_cost_mark(m, problem, sweep.inputs) for m in outcome_marks),
    )


def _cost_mark(mark: NonsmoothMark, problem: OptimalControlProblem, inputs: np.ndarray
               ) -> NonsmoothMark:
    """The outcome's nonsmooth point seen through the cost c = (th_f - th*)^2 + sum alpha u^2:
    limits map through c, slopes through dc/dth_f = 2 (th_f - th*)."""
    def cost(th_f: float) -> float:
        return float(problem.cost(th_f, inputs))

    if "jump" in mark.kind:
        left, right = cost(mark.left), cost(mark.right)
    else:
        gain = problem.outcome_slope(mark.value)
        left, right = gain * mark.left, gain * mark.right
    return NonsmoothMark(theta0=mark.theta0, kind=mark.kind, left=left, right=right,
                         value=cost(mark.value), label=mark.label)


def optimal_data(sweep: OptimalSweep, points: Sequence[NonsmoothPoint] = ()) -> OptimalSweepData:
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


def nonsmooth_table(reports: Sequence[NonsmoothReport]) -> str:
    blocks = []
    for r in reports:
        kind = "optimal" if r.optimal else "fixed inputs"
        blocks.append(f"== {r.subject} ({kind}), th0 in [{r.theta0_range[0]:g}, "
                      f"{r.theta0_range[1]:g}], {r.grid_size} angles ==\n{r.table()}")
    return "\n\n".join(blocks)


def _captions(params: BipedParams, problems: Sequence[OptimalControlProblem], fixed_num: int,
              optimal_num: int, table: str) -> str:
    p = params.as_dict()
    lines = [
        "biped_opt reproduction of Banjanin & Burden, 'Nonsmooth optimal value and policy",
        "functions in mechanical systems subject to unilateral constraints' (2020).",
        "",
        "Model parameters (gravity units, g = 1): "
        + ", ".join(f"{k} = {v:g}" for k, v in p.items()),
        "",
        "fig2.png  Outcome th(t_f) (a, b) and cost c(th0, u) (c, d) over th0 at the paper's fixed",
        "          inputs: touchdown u = (2.0, 0.5), liftoff u = (1.5, 3.0), u12 = 0;",
        f"          {fixed_num} angles each, th0 = 0 included. Circles: nonsmooth points with",
        "          their one-sided limits (jump) or slopes (kink).",
        "fig3.png  Contact mode over time and th0 at the same inputs: the order of the single-",
        "          stance modes flips at th0 = 0, where both feet touch down (lift off) at once.",
        f"fig4.png  Optimal outcome (a, b), policy (c, d) and value (e, f) over th0, {optimal_num}",
        "          angles each; dashed lines are input bounds.",
        "",
        "Problems (Eqs. (14), (15)):",
    ]
    for prob in problems:
        d = prob.describe()
        lines.append(f"  {prob.name}: " + ", ".join(f"{k} = {v}" for k, v in d.items()
                                                   if k not in ("name",)))
    lines += ["", "Nonsmooth points (left | right: limits for jumps, first derivatives for kinks,",
              "second derivatives for second-derivative jumps):", "", table, ""]
    return "\n".join(lines)


def reproduce(out_dir: str | Path, *, fixed_num: int = 401, optimal_num: int = 201,
              progress: bool = False) -> Reproduction:
    """Compute everything and write fig2.png, fig3.png, fig4.png and captions.txt."""
    start = time.perf_counter()
    out = Path(out_dir)
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
    figures = (
        figure2(fixed["touchdown"], fixed["liftoff"], out / "fig2.png"),
        figure3(fixed["touchdown"], fixed["liftoff"], out / "fig3.png"),
        figure4(optimal["touchdown"], optimal["liftoff"], out / "fig4.png"),
    )
    table = nonsmooth_table(reports)
    captions = out / "captions.txt"
    captions.write_text(_captions(problems["touchdown"].params,
                                  [*problems.values(), variant], fixed_num, optimal_num, table))
    return Reproduction(figures=figures, captions=captions, reports=tuple(reports),
                        seconds=time.perf_counter() - start)
