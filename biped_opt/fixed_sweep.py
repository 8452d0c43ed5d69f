"""Sweep grids and the paper's fixed inputs (MODEL.md Secs. 5-6).

Every grid holds th0 = 0 exactly when it straddles it: that is where the events are simultaneous
and the outcome, policy and value break (paper Figs. 2-4).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["FIXED_INPUTS", "theta_grid"]

#: inputs of the paper's fixed-input figures (MODEL.md Sec. 5): (u1, u2, u12)
FIXED_INPUTS = {
    "touchdown": (2.0, 0.5, 0.0),
    "liftoff": (1.5, 3.0, 0.0),
}


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
