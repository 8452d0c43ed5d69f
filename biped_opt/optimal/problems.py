"""The paper's optimal-control problems (re-exported from :mod:`biped_opt.paper.problems`).

An :class:`OptimalControlProblem` is one of the paper's problems in its words (th*, alpha,
bounds, fixed inputs (u1, u2, u12), BipedParams, simulator options); its ``problem`` is the same
problem as a one-lane :class:`~biped_opt.control.problems.Problem` of the library biped, which
every computation runs on.
"""

from __future__ import annotations

from biped_opt.model.modes import ContactMode
from biped_opt.paper.problems import (
    INPUT_NAMES,
    PROBLEMS,
    OptimalControlProblem,
    get_problem,
    liftoff_problem,
    liftoff_variant_problem,
    touchdown_problem,
)

__all__ = [
    "INPUT_NAMES",
    "INPUT_MODES",
    "OptimalControlProblem",
    "touchdown_problem",
    "liftoff_problem",
    "liftoff_variant_problem",
    "PROBLEMS",
    "get_problem",
]

#: the contact mode in which each input acts (MODEL.md Sec. 2, force coupling)
INPUT_MODES = {"u1": ContactMode.LEFT, "u2": ContactMode.RIGHT, "u12": ContactMode.GROUND}
