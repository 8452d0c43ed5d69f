"""The paper's sweeps over th0 (re-exported from :mod:`biped_opt.paper.sweeps`)."""

from __future__ import annotations

from biped_opt.paper.sweeps import (
    FixedSweep,
    OptimalSweep,
    Progress,
    sweep_fixed,
    sweep_grid,
    sweep_optimal,
)

__all__ = ["Progress", "sweep_grid", "FixedSweep", "OptimalSweep", "sweep_fixed", "sweep_optimal"]
