"""What any system's figures show, computed: sweeps, contact-mode bands and nonsmooth points.

The drawing functions of :mod:`biped_opt.plots.systems` take these records and draw them; nothing
here draws:

- :func:`mode_bands`: each trajectory of a sweep cut into its contact-mode intervals;
- :func:`fixed_input_sweep` and :func:`system_marks`: the outcome along a grid at fixed inputs
  and its nonsmooth points (the one engine, :func:`biped_opt.analysis.nonsmooth.find_nonsmooth`),
  the latter as :class:`Mark` records of one curve;
- :func:`fixed_input_curves` and :func:`optimal_curves`: everything ``biped-opt figures --system``
  draws for a sweep at fixed inputs or a problem's optimal sweep (:class:`SweepCurves`);
- :func:`grid_one_sided`: one-sided limit and slope at a grid point from the grid's own values,
  by :func:`biped_opt.piecewise.one_sided` (the engine's extrapolation) on a ladder of grid
  points - for a curve whose smoothness the engine found nothing to report about;
- :func:`smoothed_curve`: the Gaussian-smoothed cost J_sigma along a grid
  (:mod:`biped_opt.analysis.gradients`), for the gradient methods' figure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from biped_opt.analysis.nonsmooth import find_nonsmooth, find_nonsmooth_optimal
from biped_opt.analysis.switches import NonsmoothReport
from biped_opt.control.problems import Problem
from biped_opt.control.solve import optimal_sweep, policy_table
from biped_opt.piecewise import OneSided, one_sided
from biped_opt.progress import bar as _bar
from biped_opt.simulation.compiled import CompiledSystem

__all__ = [
    "Mark",
    "ModeBands",
    "mode_bands",
    "fixed_input_sweep",
    "system_marks",
    "SweepCurves",
    "fixed_input_curves",
    "optimal_curves",
    "grid_one_sided",
    "smoothed_curve",
]

Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Mark:
    """A nonsmooth point of one curve: where (``s``), what (``kind``: "kink", "jump"...), why
    (``cause``), ``left``/``right`` (one-sided limits for a jump, slopes for a kink), ``at``
    (the value at s) and the curve it belongs to (``series``; None: every curve)."""

    s: float
    kind: str
    cause: str = ""
    left: float = math.nan
    right: float = math.nan
    at: float = math.nan
    limits: tuple[float, float] = (math.nan, math.nan)  #: one-sided limits (any kind)
    slopes: tuple[float, float] = (math.nan, math.nan)  #: one-sided first derivatives
    series: str | None = None


# --- contact modes over time and s --------------------------------------------------------------
@dataclass(frozen=True)
class ModeBands:
    """The contact modes of one trajectory as time intervals [starts[k], ends[k]] in mode
    modes[k], and the times of all its contact events with the constraints each one switched
    (a mask; an impact that separates at once, as with restitution, leaves the mode unchanged
    but is an event)."""

    s: float
    modes: tuple[int, ...]
    starts: tuple[float, ...]
    ends: tuple[float, ...]
    events: tuple[float, ...]
    switched: tuple[int, ...]
    status: str


def mode_bands(compiled: CompiledSystem, maneuver: str, s_grid: npt.ArrayLike,
               inputs: Any = None) -> list[ModeBands]:
    """Simulate ``maneuver`` at every s and cut each trajectory into its mode intervals."""
    bands = []
    for s in np.atleast_1d(np.asarray(s_grid, dtype=np.float64)):
        tr = compiled.simulate(maneuver, float(s), inputs)
        times = (0.0, *tr.event_times, tr.t_final)
        # a contact event that does not change the mode (impact and immediate separation)
        # splits no band
        modes, starts, ends = [tr.modes[0]], [0.0], []
        for k, mode in enumerate(tr.modes[1:], start=1):
            if mode != modes[-1]:
                ends.append(times[k])
                modes.append(mode)
                starts.append(times[k])
        ends.append(tr.t_final)
        bands.append(ModeBands(s=float(s), modes=tuple(modes), starts=tuple(starts),
                               ends=tuple(ends), events=tuple(tr.event_times),
                               switched=tuple(e.mask_entered | e.mask_left
                                              for e in tr.contact_events),
                               status=tr.status.name))
    return bands


# --- nonsmooth points of a compiled system along a grid -----------------------------------------
def fixed_input_sweep(compiled: CompiledSystem, maneuver: str, grid: npt.ArrayLike,
                      inputs: Any = None, *, progress: bool = False
                      ) -> tuple[tuple[float, ...], Array, NonsmoothReport]:
    """The inputs (checked, in declared order), the outcome along ``grid`` (one batch) and its
    nonsmooth report (:func:`biped_opt.analysis.nonsmooth.find_nonsmooth`: every change of the
    mode sequence located to 1e-10 in s and classified from extrapolated one-sided limits and
    slopes)."""
    s = np.asarray(grid, dtype=np.float64)
    u = compiled.simulate(maneuver, float(s[0]), inputs).inputs
    batch = compiled.simulate_batch(maneuver, s, u)
    report = find_nonsmooth(compiled, maneuver, u, s=s, progress=progress)
    return u, batch["outcome"], report


def system_marks(compiled: CompiledSystem, maneuver: str, grid: npt.ArrayLike,
                 inputs: Any = None, *, series: str | None = None) -> tuple[Array, list[Mark]]:
    """The outcome along ``grid`` and its nonsmooth points as marks of the curve ``series``
    (:func:`fixed_input_sweep`)."""
    _, outcome, report = fixed_input_sweep(compiled, maneuver, grid, inputs)
    marks = [Mark(s=p.theta0, kind=p.kind, cause=p.cause, left=p.left, right=p.right, at=p.at,
                  limits=p.limits, slopes=p.derivatives, series=series) for p in report.points]
    return outcome, marks


@dataclass(frozen=True)
class SweepCurves:
    """One sweep as the figures show it: the curves over s ("outcome"; optimal: also "value"
    and "policy:<decision>"), the nonsmooth report whose points are marked on them, the fixed
    inputs (declared order; empty for an optimal sweep) and, at fixed inputs, the contact-mode
    bands of every s."""

    s: Array
    curves: dict[str, Array]
    report: NonsmoothReport
    inputs: tuple[float, ...] = ()
    bands: tuple[ModeBands, ...] = ()


def fixed_input_curves(compiled: CompiledSystem, maneuver: str, grid: npt.ArrayLike,
                       inputs: Any = None, *, progress: bool = False) -> SweepCurves:
    """``maneuver`` swept over ``grid`` at fixed ``inputs``: outcome, nonsmooth report, bands."""
    s = np.asarray(grid, dtype=np.float64)
    u, outcome, report = fixed_input_sweep(compiled, maneuver, s, inputs, progress=progress)
    return SweepCurves(s=s, curves={"outcome": outcome}, report=report, inputs=tuple(u),
                       bands=tuple(mode_bands(compiled, maneuver, s, u)))


def optimal_curves(problem: Problem, grid: npt.ArrayLike, *, progress: bool = False
                   ) -> SweepCurves:
    """The optimal control of ``problem`` over ``grid``: optimal outcome, value and policy and
    their nonsmooth report (:func:`biped_opt.analysis.nonsmooth.find_nonsmooth_optimal`)."""
    s = np.asarray(grid, dtype=np.float64)
    bar = _bar(progress, s.size, f"{problem.name} curves")
    table = policy_table(optimal_sweep(problem, s, callback=bar.update))
    report = find_nonsmooth_optimal(problem, s, progress=progress)
    curves = {"outcome": table["outcome"], "value": table["value"],
              **{f"policy:{d}": table[d] for d in problem.decision_names}}
    return SweepCurves(s=s, curves=curves, report=report)


def grid_one_sided(s: Array, y: Array, x: float, side: int, *, levels: int = 5) -> OneSided:
    """One-sided limit and slope at the grid point x from the grid's own values: the
    polynomial extrapolation of :func:`biped_opt.piecewise.one_sided` on the ladder of grid
    points x + side 2^k h, h the spacing, k = levels-1 .. 0 (y at x itself is never used)."""
    k = int(np.flatnonzero(s == x)[0])
    spacing = float(s[k + side] - s[k]) * side
    at = {round((float(v) - x) / spacing): float(w) for v, w in zip(s, y)}
    return one_sided(lambda v: at[round((v - x) / spacing)], x, side,
                     h0=spacing * 2 ** (levels - 1), levels=levels)


def smoothed_curve(u: Array, cost: Array, sigma: float) -> Array:
    """J_sigma on the uniform grid u by discrete Gaussian convolution (weights renormalised at
    the ends of the grid, where part of the kernel falls outside it)."""
    du = float(u[1] - u[0])
    half = int(np.ceil(4 * sigma / du))
    k = np.exp(-0.5 * (np.arange(-half, half + 1) * du / sigma) ** 2)
    finite = np.isfinite(cost)
    num = np.convolve(np.where(finite, cost, 0.0), k, mode="same")
    den = np.convolve(finite.astype(float), k, mode="same")
    return num / np.maximum(den, 1e-300)
