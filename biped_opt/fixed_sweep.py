"""Sweep grids and the paper's fixed inputs (MODEL.md Secs. 5-6).

Every grid holds th0 = 0 exactly when it straddles it: that is where the events are simultaneous
and the outcome, policy and value break (paper Figs. 2-4).
"""

from __future__ import annotations

from biped_opt.piecewise import theta_grid

__all__ = ["FIXED_INPUTS", "theta_grid"]

#: inputs of the paper's fixed-input figures (MODEL.md Sec. 5): (u1, u2, u12)
FIXED_INPUTS = {
    "touchdown": (2.0, 0.5, 0.0),
    "liftoff": (1.5, 3.0, 0.0),
}
