"""Optimal policies and values of the maneuvers and their nonsmoothness ([1]_ Secs. III-IV), in
the paper's words over the one lane (:mod:`biped_opt.control`, :mod:`biped_opt.paper`):

- :mod:`~biped_opt.optimal.problems`: the problems of Eqs. (4), (14), (15) as frozen values;
- :mod:`~biped_opt.optimal.solve`: pi(th0), nu(th0) by the one solver;
- :mod:`~biped_opt.optimal.derivatives`: one-sided derivatives (the one lane's Theorem 1);
- :mod:`~biped_opt.optimal.sweep`: fixed-input and optimal sweeps over th0 grids;
- :mod:`~biped_opt.optimal.nonsmooth`: where outcome, policy and value fail to be C^1, and why.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from biped_opt.optimal.problems import (
    PROBLEMS,
    OptimalControlProblem,
    get_problem,
    liftoff_problem,
    liftoff_variant_problem,
    touchdown_problem,
)
from biped_opt.optimal.solve import Candidate, OptimalResult, optimal_policy, optimal_sweep

__all__ = [
    "PROBLEMS",
    "Candidate",
    "OptimalControlProblem",
    "OptimalResult",
    "get_problem",
    "liftoff_problem",
    "liftoff_variant_problem",
    "optimal_policy",
    "optimal_sweep",
    "touchdown_problem",
]
