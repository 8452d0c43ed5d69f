"""One-sided limits and derivatives of piecewise-smooth scalar functions, and switch location.

The outcome of a maneuver is piecewise smooth in th0: smooth while the sequence of contact modes
is fixed, and possibly kinked (continuous, one-sided derivatives differ) or discontinuous where the
sequence changes (paper Sec. III). This module supplies the numerical tools:

- :func:`one_sided` fits f(x0 + s h) on a geometric ladder of h on one side and extrapolates the
  one-sided limit and derivative (polynomial extrapolation to h -> 0, i.e. Richardson);
- :func:`locate_switch` bisects on a discrete label (the mode sequence) to find where it changes.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["OneSided", "one_sided", "locate_switch", "theta_grid"]


@dataclass(frozen=True)
class OneSided:
    """Limit and derivative of f at x0 from one side (side = -1 left, +1 right)."""

    side: int
    limit: float
    derivative: float
    #: change of the extrapolated derivative when the ladder's coarsest point is dropped
    derivative_error: float
    #: second derivative of the same fit (meaningful when f is C^2 on that side)
    second_derivative: float = float("nan")


def one_sided(
    f: Callable[[float], float],
    x0: float,
    side: int,
    *,
    h0: float = 1e-2,
    levels: int = 5,
    ratio: float = 2.0,
) -> OneSided:
    """Extrapolated one-sided limit and derivative of ``f`` at ``x0``.

    Evaluates f at x0 + side * h0 / ratio**k, k = 0..levels-1, fits the interpolating polynomial
    in the signed offset and reads its value and slope at 0. f must be smooth on the open side
    interval (x0, x0 + side * h0]; f(x0) itself is never evaluated, so a jump at x0 is fine.
    """
    if side not in (-1, 1):
        raise ValueError("side must be -1 or +1")
    offsets = side * h0 / ratio ** np.arange(levels)
    values = np.array([f(x0 + s) for s in offsets])
    if np.all(values == values[0]):
        # a constant side (a saturated input, a flat outcome): the fit would return the constant
        # only up to the least-squares rounding of the machine's BLAS, ~1e-15 off and CPU-dependent
        value = float(values[0])
        second = 0.0 if levels > 2 else float("nan")
        return OneSided(side=side, limit=value, derivative=0.0, derivative_error=0.0,
                        second_derivative=second)
    coeffs = np.polynomial.polynomial.polyfit(offsets, values, levels - 1)
    coarse = np.polynomial.polynomial.polyfit(offsets[1:], values[1:], levels - 2)
    return OneSided(
        side=side,
        limit=float(coeffs[0]),
        derivative=float(coeffs[1]),
        derivative_error=float(abs(coeffs[1] - coarse[1])),
        second_derivative=float(2.0 * coeffs[2]) if levels > 2 else float("nan"),
    )


def locate_switch(
    label: Callable[[float], Hashable], a: float, b: float, *, tol: float = 1e-10
) -> tuple[float, float]:
    """Bracket [lo, hi] of width <= tol where ``label`` changes, by bisection.

    label(a) != label(b) is required. On return label(lo) == label(a) != label(hi); a third label
    met on the way (the simultaneous-event sequence exactly at the switch) counts as "different".
    """
    la, lb = label(a), label(b)
    if la == lb:
        raise ValueError("label(a) and label(b) must differ to bracket a switch")
    lo, hi = a, b  # a > b is allowed: the bracket then shrinks from the right
    while abs(hi - lo) > tol:
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        if label(mid) == la:
            lo = mid
        else:
            hi = mid
    return lo, hi


def theta_grid(lo: float, hi: float, num: int) -> npt.NDArray[np.float64]:
    """``num`` evenly spaced angles in [lo, hi], both ends kept, with 0 exactly if it lies
    inside: the interior angle nearest to 0 moves onto it, or, when the nearest is an end (a
    grid of 2 or a range whose end lies close to 0), 0 is added (num + 1 angles)."""
    grid = np.linspace(lo, hi, num)
    if lo < 0.0 < hi and 0.0 not in grid:
        nearest = int(np.argmin(np.abs(grid)))
        if 0 < nearest < num - 1:
            grid[nearest] = 0.0
        else:
            grid = np.insert(grid, nearest + (grid[nearest] < 0.0), 0.0)
    return grid
