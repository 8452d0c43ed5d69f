"""Figures reproducing the paper's plots (matplotlib, Agg). Never imported by the core."""

from biped_opt.plots.figures import (
    FixedSweepData,
    NonsmoothMark,
    OptimalSweepData,
    figure2,
    figure3,
    figure4,
)

__all__ = [
    "FixedSweepData",
    "NonsmoothMark",
    "OptimalSweepData",
    "figure2",
    "figure3",
    "figure4",
]
