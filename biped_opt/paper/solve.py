"""The paper's optimal policy pi(th0) and value nu(th0) (Eqs. (4)-(6) of [1]_) on the one lane.

:func:`optimal_policy` and :func:`optimal_sweep` validate th0 against the paper's maneuver
ranges, solve the problem's one-lane :class:`~biped_opt.control.problems.Problem` with
:func:`biped_opt.control.solve.optimal_policy` (global bracketing on a grid of 65, bounded Brent,
Newton polish, the bound test) and return its :class:`~biped_opt.control.solve.OptimalResult`
in the paper's words (:func:`in_paper_words`): ``problem`` the paper's problem, ``modes`` as
:class:`~biped_opt.paper.biped.ContactMode` and branches as ``AIR->LEFT->GROUND``.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from biped_opt.control import solve as one_lane
from biped_opt.control.solve import XATOL, OptimalResult
from biped_opt.errors import InvalidInputError
from biped_opt.paper.biped import BipedParams, ContactMode, check_theta0
from biped_opt.paper.problems import OptimalControlProblem, paper_branch

__all__ = ["in_paper_words", "optimal_policy", "optimal_sweep"]


def in_paper_words(problem: OptimalControlProblem, result: OptimalResult) -> OptimalResult:
    """A one-lane result of ``problem.problem`` with the paper's problem, mode and branch names."""
    return dataclasses.replace(
        result, problem=problem, modes=tuple(ContactMode(m) for m in result.modes),
        branch=paper_branch(result.branch),
        candidates=tuple(dataclasses.replace(c, branch=paper_branch(c.branch))
                         for c in result.candidates))


def _with_params(
    problem: OptimalControlProblem, params: BipedParams | None
) -> OptimalControlProblem:
    if not isinstance(problem, OptimalControlProblem):
        raise InvalidInputError(f"problem must be an OptimalControlProblem, got {problem!r}")
    if params is None:
        return problem
    if not isinstance(params, BipedParams):
        raise InvalidInputError(f"params must be BipedParams, got {params!r}")
    return dataclasses.replace(problem, params=params)


def optimal_policy(
    problem: OptimalControlProblem,
    theta0: float,
    *,
    params: BipedParams | None = None,
    grid_points: int | None = None,
    xatol: float = XATOL,
) -> OptimalResult:
    """Optimal policy and value at ``theta0`` (Eqs. (4)-(6) of [1]_), globally bracketed.

    ``params`` overrides the problem's biped parameters; ``grid_points`` is the size of the
    bracketing grid over the acting decision's bounds (default 65), ``xatol`` the tolerance of
    the bounded Brent refinement. Raises only for invalid arguments; a failure to find any
    feasible point is reported by ``success``/``status``.
    """
    problem = _with_params(problem, params)
    th0 = check_theta0(problem.maneuver, theta0)
    result = one_lane.optimal_policy(problem.problem, th0, grid_points=grid_points, xatol=xatol)
    return in_paper_words(problem, result)


def optimal_sweep(
    problem: OptimalControlProblem,
    theta0: npt.ArrayLike,
    *,
    params: BipedParams | None = None,
    grid_points: int | None = None,
    xatol: float = XATOL,
    callback: Callable[[int, int], None] | None = None,
) -> tuple[OptimalResult, ...]:
    """:func:`optimal_policy` at every angle of ``theta0``; ``callback(done, total)`` is called
    after each th0 (for progress bars)."""
    problem = _with_params(problem, params)
    th = np.atleast_1d(np.asarray(theta0, dtype=np.float64))
    if th.ndim != 1 or th.size == 0:
        raise InvalidInputError(f"theta0 must be a non-empty 1-D array, got shape {th.shape}")
    for value in th:
        check_theta0(problem.maneuver, value)
    results = one_lane.optimal_sweep(problem.problem, th, grid_points=grid_points, xatol=xatol,
                                     callback=callback)
    return tuple(in_paper_words(problem, r) for r in results)
