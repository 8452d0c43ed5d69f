"""Fixed-input sweeps of a maneuver's outcome over th0 and the nonsmooth points they reveal.

MODEL.md Sec. 6 (paper Figs. 2 and 3): at fixed inputs the touchdown outcome is kinked at
th0 = 0 and the liftoff outcome jumps there. :func:`fixed_sweep` evaluates a grid (always holding
th0 = 0 exactly) in parallel; :func:`outcome_breaks` finds every change of the mode sequence along
the grid, locates it to 1e-10 by bisection and measures the one-sided limits and slopes there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from biped_opt.hybrid import BatchResult, SimulatorOptions, simulate, simulate_batch
from biped_opt.hybrid.simulate import DEFAULT_OPTIONS
from biped_opt.maneuvers import spec
from biped_opt.model.params import BipedParams
from biped_opt.nonsmooth import locate_switch, one_sided

__all__ = ["FIXED_INPUTS", "theta_grid", "fixed_sweep", "Break", "outcome_breaks"]

#: inputs of the paper's fixed-input figures (MODEL.md Sec. 5): (u1, u2, u12)
FIXED_INPUTS = {
    "touchdown": (2.0, 0.5, 0.0),
    "liftoff": (1.5, 3.0, 0.0),
}

#: one-sided limits differing by more than this are a jump (simulation error is ~1e-11)
JUMP_TOL = 1e-7
#: one-sided slopes differing by more than this are a kink
KINK_TOL = 1e-5


def theta_grid(lo: float, hi: float, num: int) -> npt.NDArray[np.float64]:
    """``num`` evenly spaced angles in [lo, hi], with 0 inserted exactly if it lies inside."""
    grid = np.linspace(lo, hi, num)
    if lo < 0.0 < hi:
        grid[np.argmin(np.abs(grid))] = 0.0
        grid = np.unique(grid)
    return grid


def fixed_sweep(
    maneuver: str,
    theta0: npt.ArrayLike,
    inputs: npt.ArrayLike | None = None,
    *,
    params: BipedParams | None = None,
    options: SimulatorOptions = DEFAULT_OPTIONS,
) -> BatchResult:
    """Outcomes over the grid ``theta0`` at fixed inputs (default: the paper's, per maneuver)."""
    name = spec(maneuver).maneuver.value
    u = FIXED_INPUTS[name] if inputs is None else inputs
    return simulate_batch(name, theta0, u, params=params, options=options)


@dataclass(frozen=True)
class Break:
    """A point where the outcome's mode sequence changes, with one-sided behaviour there."""

    theta0: float
    kind: str  #: "jump", "kink" or "smooth"
    left_limit: float
    right_limit: float
    left_slope: float
    right_slope: float
    sequence_left: tuple[str, ...]
    sequence_right: tuple[str, ...]


def outcome_breaks(
    maneuver: str,
    sweep: BatchResult,
    *,
    params: BipedParams | None = None,
    options: SimulatorOptions = DEFAULT_OPTIONS,
    h0: float = 1e-2,
) -> list[Break]:
    """Locate and classify every change of mode sequence along a fixed-input sweep."""
    u = sweep.inputs[0]

    def sequence(th: float) -> tuple[str, ...]:
        tr = simulate(maneuver, th, u, params=params, options=options)
        return tuple(m.name for m in tr.mode_sequence)

    def outcome(th: float) -> float:
        return simulate(maneuver, th, u, params=params, options=options).outcome

    limit = spec(maneuver).theta0_limit
    seqs = [tuple(m.name for m in sweep.mode_sequence(k)) for k in range(sweep.theta0.size)]
    breaks = []
    k = 0
    while k + 1 < len(seqs):
        if seqs[k] == seqs[k + 1]:
            k += 1
            continue
        # the grid may hold the switch itself (th0 = 0 with its simultaneous sequence): skip it
        j = k + 1
        while j + 1 < len(seqs) and seqs[j] not in (seqs[k],) and seqs[j] != seqs[j + 1]:
            j += 1
        a, b = float(sweep.theta0[k]), float(sweep.theta0[j])
        lo, hi = locate_switch(sequence, a, b)
        band_lo, band_hi = hi, hi
        if sequence(hi) != seqs[j]:
            # a band of simultaneous-event sequences (guards within 1e-9 of each other) separates
            # the two branches: the switch is its centre, or 0 exactly when 0 lies in it
            band_hi = locate_switch(sequence, b, hi)[1]
        x = 0.0 if band_lo <= 0.0 <= band_hi else 0.5 * (band_lo + band_hi)
        h = min(h0, 0.5 * (x - a), 0.5 * (b - x), limit - abs(x)) if j > k + 1 else min(
            h0, limit - abs(x)
        )
        h = max(h, 4 * (hi - lo))
        left = one_sided(outcome, x, -1, h0=h)
        right = one_sided(outcome, x, +1, h0=h)
        if abs(right.limit - left.limit) > JUMP_TOL:
            kind = "jump"
        elif abs(right.derivative - left.derivative) > KINK_TOL:
            kind = "kink"
        else:
            kind = "smooth"
        breaks.append(
            Break(
                theta0=x,
                kind=kind,
                left_limit=left.limit,
                right_limit=right.limit,
                left_slope=left.derivative,
                right_slope=right.derivative,
                sequence_left=seqs[k],
                sequence_right=seqs[j],
            )
        )
        k = j
    return breaks
