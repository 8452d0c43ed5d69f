"""Figures reproducing the paper's plots, and the same figures for any system (matplotlib, Agg).
Never imported by the core."""

from biped_opt.plots.figures import (
    FixedSweepData,
    NonsmoothMark,
    OptimalSweepData,
    figure2,
    figure3,
    figure4,
)
from biped_opt.plots.systems import (
    ControlExperiment,
    Mark,
    ModeBands,
    SystemFigures,
    control_experiment_data,
    control_experiment_figure,
    fixed_input_figures,
    mode_bands,
    modes_figure,
    optimal_figures,
    outcome_figure,
    policy_value_figure,
)

__all__ = [
    "ControlExperiment",
    "Mark",
    "ModeBands",
    "SystemFigures",
    "control_experiment_data",
    "control_experiment_figure",
    "fixed_input_figures",
    "mode_bands",
    "modes_figure",
    "optimal_figures",
    "outcome_figure",
    "policy_value_figure",
    "FixedSweepData",
    "NonsmoothMark",
    "OptimalSweepData",
    "figure2",
    "figure3",
    "figure4",
]
