"""The paper's one-sided (Bouligand) derivatives in its words, computed by the one lane.

- :func:`outcome_sensitivity`, :func:`outcome_derivative`: the gradient of th_f over
  (th0, u1, u2, u12) on the branch a direction selects, by
  :func:`biped_opt.control.derivatives.outcome_gradient` on the library biped (variational
  equation and saltation matrices, simultaneous events flipped in the order of their time
  shifts);
- :func:`one_sided_derivatives`: Theorem 1 of [1]_, Eqs. (12)-(13), for a paper problem, by
  :func:`biped_opt.control.theorem1.optimal_derivatives` on its one-lane problem, branches in
  the paper's mode names.

The variational options, the saltation matrix and the sensitivities' type are the one lane's
(:mod:`biped_opt.control.derivatives`).

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt

from biped_opt.control.derivatives import (
    DEFAULT_VARIATIONAL,
    OutcomeGradient,
    VariationalOptions,
    outcome_gradient,
)
from biped_opt.control.theorem1 import Derivatives, optimal_derivatives
from biped_opt.errors import InvalidInputError
from biped_opt.paper.biped import (
    INPUT_NAMES,
    BipedParams,
    check_theta0,
    compiled_biped,
    parse_maneuver,
)
from biped_opt.paper.problems import OptimalControlProblem, paper_branch
from biped_opt.simulation.options import DEFAULT_OPTIONS, SimulatorOptions

__all__ = ["PARAMETER_NAMES", "outcome_sensitivity", "outcome_derivative",
           "one_sided_derivatives"]

#: the parameters the outcome is differentiated with respect to, in gradient order (the
#: gradient is the one lane's :class:`~biped_opt.control.derivatives.OutcomeGradient`, whose
#: ``theta0``, ``d_theta0``, ``d_input`` and ``mode_sequence`` are the biped's names on it)
PARAMETER_NAMES = ("theta0", *INPUT_NAMES)


def _direction(direction: npt.ArrayLike | None) -> npt.NDArray[np.float64]:
    """A direction over PARAMETER_NAMES (default +d th0; missing trailing entries 0)."""
    if direction is None:
        direction = (1.0,)
    try:
        v = np.asarray(direction, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise InvalidInputError(f"direction must be numbers, got {direction!r}") from None
    if v.size > len(PARAMETER_NAMES) or not np.all(np.isfinite(v)):
        raise InvalidInputError(
            f"direction must be at most {len(PARAMETER_NAMES)} finite numbers over "
            f"{PARAMETER_NAMES}, got {direction!r}")
    out = np.zeros(len(PARAMETER_NAMES))
    out[: v.size] = v
    return out


def outcome_sensitivity(
    maneuver: str,
    theta0: float,
    inputs: npt.ArrayLike | None = None,
    *,
    direction: npt.ArrayLike | None = None,
    params: BipedParams | None = None,
    options: SimulatorOptions = DEFAULT_OPTIONS,
    variational: VariationalOptions = DEFAULT_VARIATIONAL,
) -> OutcomeGradient:
    """Gradient of th_f w.r.t. (th0, u1, u2, u12) on the branch selected by ``direction``.

    ``direction`` is a perturbation over PARAMETER_NAMES (default +d th0); it matters only at a
    simultaneous event. Raises SimulationError if the maneuver does not reach its terminal
    event.
    """
    name = parse_maneuver(maneuver).value
    th0 = check_theta0(name, theta0)
    v = _direction(direction)
    compiled = compiled_biped(params)
    return outcome_gradient(compiled, name, th0, inputs, direction=v, options=options,
                            variational=variational)


def outcome_derivative(
    maneuver: str,
    theta0: float,
    inputs: npt.ArrayLike | None = None,
    side: int = 1,
    *,
    params: BipedParams | None = None,
    options: SimulatorOptions = DEFAULT_OPTIONS,
    variational: VariationalOptions = DEFAULT_VARIATIONAL,
) -> float:
    """One-sided derivative of th_f w.r.t. th0: side = +1 from the right, -1 from the left
    (at a simultaneous event the slope of the branch the side selects)."""
    if side not in (-1, 1):
        raise InvalidInputError(f"side must be -1 or +1, got {side!r}")
    return outcome_sensitivity(maneuver, theta0, inputs, direction=(float(side),), params=params,
                               options=options, variational=variational).d_theta0


def one_sided_derivatives(
    problem: OptimalControlProblem,
    theta0: float,
    *,
    params: BipedParams | None = None,
    variational: VariationalOptions = DEFAULT_VARIATIONAL,
    probe: float = 1e-7,
) -> Derivatives:
    """One-sided derivatives of the optimal outcome, value and policy (Theorem 1, (12)-(13)) of
    a paper problem at ``theta0`` (``params`` overrides its biped parameters); see
    :func:`biped_opt.control.theorem1.optimal_derivatives`. Branches in the paper's mode names.
    """
    if not isinstance(problem, OptimalControlProblem):
        raise InvalidInputError(f"problem must be an OptimalControlProblem, got {problem!r}")
    if not (isinstance(probe, (int, float)) and math.isfinite(probe) and 0 < probe <= 1e-3):
        raise InvalidInputError(f"probe must be a small positive number, got {probe!r}")
    if params is not None:
        problem = dataclasses.replace(problem, params=params)
    th0 = check_theta0(problem.maneuver, theta0)
    d = optimal_derivatives(problem.problem, th0, probe=float(probe), variational=variational)
    left, right = d.branches
    return dataclasses.replace(d, branches=(paper_branch(left), paper_branch(right)))
