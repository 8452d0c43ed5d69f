"""Nonsmooth points estimated from a sweep's samples alone, at the samples' resolution.

The engine (:mod:`biped_opt.analysis.switches`) evaluates the sweep wherever it needs to:
bisection to 1e-10 and one-sided ladders down to 1e-6. A recorded sweep can be read but not
evaluated again (``biped-opt report`` runs no simulation unless asked to refine), so this module
estimates what the samples themselves hold:

Along a sweep, outcome, policy and value are smooth while the mode order (and, for optima, which
bound holds the policy) stays fixed ([1]_ Sec. III), so every change of that label between
neighbouring samples brackets a candidate point; for optimal sweeps a policy step much larger
than its neighbours' (the optimum moving to another local minimum with the same mode order) is one
too. A label held by a single sample between two others (s = 0, where both feet touch down or
lift off at once) is one point at that sample. On each side a cubic through the 4 nearest samples
of that side is extrapolated to the point to give one-sided limits and slopes; the difference to
the quadratic through the 3 nearest is the error estimate. Limits further apart than 3x their
errors are a **jump**, else slopes further apart than 3x theirs a **kink**. The bracket width
(the sample spacing) bounds the location error.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from biped_opt.analysis.switches import NonsmoothPoint

__all__ = ["Samples", "GridPoint", "labels", "candidates", "grid_nonsmooth", "FIT_POINTS",
           "SIGNIFICANCE", "BOUND_TOL", "STEP_RATIO"]

Array = npt.NDArray[np.float64]

#: one-sided fits use this many samples per side (a cubic); the error estimate drops one
FIT_POINTS = 4
#: a difference counts when it exceeds this many times the summed extrapolation error estimates
SIGNIFICANCE = 3.0
#: a policy within this of a bound is held by it (the optimiser stops ~1e-8 from a bound)
BOUND_TOL = 1e-7
#: a policy step this many times larger than both neighbouring steps is a jump candidate
STEP_RATIO = 10.0


@dataclass(frozen=True, eq=False)
class Samples:
    """A sweep's samples, sorted by s: the mode-sequence name at each, the quantities to analyse
    ("outcome", "policy:<decision>", "value") and, for an optimal sweep, its decisions with their
    bounds (in the problem's order; their policies among the quantities)."""

    s: Array
    branch: tuple[str, ...]
    quantities: Mapping[str, Array]
    optimal: bool = False
    bounds: tuple[tuple[str, tuple[float, float]], ...] = field(default=())


@dataclass(frozen=True)
class GridPoint:
    """A nonsmooth point estimated from the samples (see the module docstring).

    ``point`` carries the estimate in the engine's form (limits and slopes at ``point.theta0``;
    second derivatives are not estimated: NaN); ``*_error`` are the extrapolation error estimates
    (left, right); ``point.bracket`` is the sampled interval that holds the point.
    """

    point: NonsmoothPoint
    limit_error: tuple[float, float]
    slope_error: tuple[float, float]

    @property
    def width(self) -> float:
        return self.point.bracket[1] - self.point.bracket[0]


def labels(samples: Samples) -> list[tuple[Any, ...]]:
    """Per sample: (mode sequence,), for an optimal sweep (mode sequence, the bound holding each
    decision: "lower", "upper" or None)."""
    if not samples.optimal:
        return [(b,) for b in samples.branch]
    out = []
    for k, b in enumerate(samples.branch):
        held = []
        for d, (lo, hi) in samples.bounds:
            v = samples.quantities[f"policy:{d}"][k]
            held.append("lower" if abs(v - lo) <= BOUND_TOL else
                        "upper" if abs(v - hi) <= BOUND_TOL else None)
        out.append((b, tuple(held)))
    return out


def _fit(x: Array, y: Array, xref: float) -> tuple[Array, Array | None]:
    """Polynomials in (x - xref) through the FIT_POINTS nearest points (nearest first) and
    through one point fewer (for an error estimate); None where too few points."""
    n = min(FIT_POINTS, x.size)
    c = np.polyfit(x[:n] - xref, y[:n], max(n - 1, 0))
    c2 = np.polyfit(x[: n - 1] - xref, y[: n - 1], n - 2) if n > 2 else None
    return c, c2


def _at(fit: tuple[Array, Array | None], dx: float) -> tuple[float, float, float, float]:
    """(value, slope, value error, slope error) of a fit at offset dx."""
    c, c2 = fit
    value = float(np.polyval(c, dx))
    slope = float(np.polyval(np.polyder(c), dx)) if c.size > 1 else math.nan
    if c2 is None:
        return value, slope, math.inf, math.inf
    return (value, slope, abs(value - float(np.polyval(c2, dx))),
            abs(slope - float(np.polyval(np.polyder(c2), dx))) if c2.size > 1 else math.inf)


def _crossing(left: tuple[Array, Array | None], right: tuple[Array, Array | None],
              lo: float, hi: float) -> float | None | bool:
    """Where the two one-sided fits meet inside the bracket [lo, hi] (offsets from the fits'
    reference): the continuous quantity's kink. None if they do not meet there (a jump); True if
    they coincide (no break at all)."""
    diff = np.polysub(left[0], right[0])
    scale = max(1.0, float(np.max(np.abs(left[0]))), float(np.max(np.abs(right[0]))))
    if np.all(np.abs(diff) <= 1e-12 * scale):
        return True
    diff = np.trim_zeros(diff, "f")
    if diff.size <= 1:
        return None
    roots = [r.real for r in np.roots(diff) if abs(r.imag) <= 1e-12 and lo <= r.real <= hi]
    return min(roots, key=lambda r: abs(r - 0.5 * (lo + hi))) if roots else None


def candidates(samples: Samples) -> list[tuple[int, int, int | None, str]]:
    """(last index left, first index right, isolated index or None, cause) per candidate."""
    labs = labels(samples)
    n = len(labs)
    runs: list[tuple[int, int]] = []
    start = 0
    for k in range(1, n + 1):
        if k == n or labs[k] != labs[start]:
            runs.append((start, k - 1))
            start = k
    events: list[tuple[int, int, int | None, str]] = []
    r = 0
    while r < len(runs) - 1:
        a, b = runs[r], runs[r + 1]
        if b[0] == b[1] and r + 2 < len(runs):
            c = runs[r + 2]
            events.append((a[1], c[0], b[0], _cause(samples, labs, a[1], c[0], b[0])))
            r += 2
        else:
            events.append((a[1], b[0], None, _cause(samples, labs, a[1], b[0], None)))
            r += 1
    if samples.optimal:
        # the optimum may jump to another local minimum with the same mode order
        known = {(lo, hi) for lo, hi, _, _ in events}
        for d, _ in samples.bounds:
            step = np.abs(np.diff(samples.quantities[f"policy:{d}"]))
            for k in range(1, step.size - 1):
                big = step[k] > STEP_RATIO * max(step[k - 1], step[k + 1]) and step[k] > 1e-6
                if big and labs[k] == labs[k + 1] and (k, k + 1) not in known:
                    events.append((k, k + 1, None,
                                   f"policy {d} steps with the mode order unchanged "
                                   "(the optimum moves to another local minimum)"))
                    known.add((k, k + 1))
    return sorted(events)


def _cause(samples: Samples, labs: Sequence[Any], i: int, j: int, mid: int | None) -> str:
    left, right = samples.branch[i], samples.branch[j]
    parts = []
    if left != right:
        via = (f" (th0 = {samples.s[mid]:g}: {samples.branch[mid]})" if mid is not None
               else "")
        parts.append(f"mode order changes: {left} | {right}{via}")
    if samples.optimal:
        for (d, _), hl, hr in zip(samples.bounds, labs[i][1], labs[j][1]):
            if hl != hr:
                what = (f"reaches its {hr} bound" if hl is None else
                        f"leaves its {hl} bound" if hr is None else f"moves to its {hr} bound")
                parts.append(f"input {d} {what}")
    return "; ".join(parts) or "label change"


def grid_nonsmooth(samples: Samples) -> list[GridPoint]:
    """Nonsmooth points estimated from the samples (see the module docstring).

    Each quantity gets a cubic through the 4 nearest samples on each side of a bracket. Where the
    two meet inside the bracket the quantity is continuous there and the meeting point locates
    its kink; where they do not, it jumps. The bracket's location is the isolated sample between
    the sides if there is one (s = 0 with its simultaneous events), else the kink of the
    continuous quantity whose slopes differ most, else the bracket's centre (0 when the bracket
    straddles it); all quantities are evaluated there.
    """
    out = []
    th = samples.s
    quantities = samples.quantities
    for i, j, mid, cause in candidates(samples):
        lo, hi = float(th[i]), float(th[j])
        xref = float(th[mid]) if mid is not None else (0.0 if lo < 0.0 < hi else 0.5 * (lo + hi))
        left_idx = np.arange(i, -1, -1)  # nearest first
        right_idx = np.arange(j, th.size)
        fits = {name: (_fit(th[left_idx], y[left_idx], xref), _fit(th[right_idx], y[right_idx],
                                                                   xref))
                for name, y in quantities.items()}
        meets = {name: _crossing(L, R, lo - xref, hi - xref) for name, (L, R) in fits.items()}
        x0 = xref
        if mid is None:
            best = 0.0
            for name, where in meets.items():
                if isinstance(where, float):
                    L, R = fits[name]
                    jump_in_slope = abs(_at(L, where)[1] - _at(R, where)[1])
                    if jump_in_slope > best:
                        best, x0 = jump_in_slope, xref + where
        for name, (L, R) in fits.items():
            ll, sl, el, esl = _at(L, x0 - xref)
            lr, sr, er, esr = _at(R, x0 - xref)
            scale = max(1.0, abs(ll), abs(lr))
            continuous = meets[name] is not None or mid is not None
            if meets[name] is None and abs(lr - ll) > SIGNIFICANCE * (el + er) + 1e-12 * scale:
                kind, a, b = "jump", ll, lr
            elif mid is not None and abs(lr - ll) > SIGNIFICANCE * (el + er) + 1e-12 * scale:
                kind, a, b = "jump", ll, lr
            elif continuous and abs(sr - sl) > SIGNIFICANCE * (esl + esr) + 1e-9 * max(
                    1.0, abs(sl), abs(sr)):
                kind, a, b = "kink", sl, sr
            else:
                continue
            y = quantities[name]
            at = float(y[mid]) if mid is not None else 0.5 * (ll + lr)
            family, _, comp = name.partition(":")
            point = NonsmoothPoint(
                theta0=x0, quantity=family, input=comp or None, kind=kind, left=a, right=b,
                cause=cause, limits=(ll, lr), derivatives=(sl, sr),
                second_derivatives=(math.nan, math.nan), at=at, bracket=(lo, hi),
                labels=(samples.branch[i], samples.branch[j]))
            out.append(GridPoint(point, (el, er), (esl, esr)))
    return out
