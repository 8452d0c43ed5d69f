"""The paper's full reproduction drawn: Figs. 2-4 and their captions.

:func:`reproduce` takes the sweeps and nonsmooth reports of
:func:`biped_opt.paper.figures.reproduction_data` (fixed-input sweeps of 401 angles and optimal
sweeps of 201 angles per maneuver, every nonsmooth point of outcomes, policies and values, and of
the liftoff variant's value), draws the figures with the points marked and writes
``captions.txt`` (parameters, problems, the nonsmooth table). The data helpers
(:func:`~biped_opt.paper.figures.fixed_data`, :func:`~biped_opt.paper.figures.optimal_data`,
:func:`~biped_opt.paper.figures.marks`) live in :mod:`biped_opt.paper.figures` and are
importable from here too, so recorded sweeps are drawn by the same code.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from biped_opt.analysis.switches import NonsmoothReport
from biped_opt.paper.biped import BipedParams
from biped_opt.paper.figures import (
    MANEUVERS,
    ReproductionData,
    fixed_data,
    marks,
    optimal_data,
    reproduction_data,
)
from biped_opt.paper.problems import OptimalControlProblem
from biped_opt.plots.figures import figure2, figure3, figure4

__all__ = ["Reproduction", "reproduce", "draw_reproduction", "fixed_data", "optimal_data",
           "marks", "nonsmooth_table", "MANEUVERS"]


@dataclass(frozen=True)
class Reproduction:
    figures: tuple[Path, ...]
    captions: Path
    reports: tuple[NonsmoothReport, ...]
    seconds: float

    def table(self) -> str:
        return nonsmooth_table(self.reports)


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


def draw_reproduction(out_dir: str | Path, data: ReproductionData
                      ) -> tuple[tuple[Path, ...], Path]:
    """fig2.png, fig3.png, fig4.png and captions.txt of ``data`` into ``out_dir``."""
    out = Path(out_dir)
    figures = (
        figure2(data.fixed["touchdown"], data.fixed["liftoff"], out / "fig2.png"),
        figure3(data.fixed["touchdown"], data.fixed["liftoff"], out / "fig3.png"),
        figure4(data.optimal["touchdown"], data.optimal["liftoff"], out / "fig4.png"),
    )
    captions = out / "captions.txt"
    captions.write_text(_captions(data.problems[0].params, data.problems, data.fixed_num,
                                  data.optimal_num, nonsmooth_table(data.reports)))
    return figures, captions


def reproduce(out_dir: str | Path, *, fixed_num: int = 401, optimal_num: int = 201,
              progress: bool = False) -> Reproduction:
    """Compute everything (:func:`biped_opt.paper.figures.reproduction_data`) and write
    fig2.png, fig3.png, fig4.png and captions.txt."""
    start = time.perf_counter()
    data = reproduction_data(fixed_num=fixed_num, optimal_num=optimal_num, progress=progress)
    figures, captions = draw_reproduction(out_dir, data)
    return Reproduction(figures=figures, captions=captions, reports=data.reports,
                        seconds=time.perf_counter() - start)
