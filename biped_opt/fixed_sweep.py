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
    """``num`` evenly spaced angles in [lo, hi], with 0 inserted exactly if it lies inside."""
    grid = np.linspace(lo, hi, num)
    if lo < 0.0 < hi:
        grid[np.argmin(np.abs(grid))] = 0.0
        grid = np.unique(grid)
    return grid
