"""Mechanical systems subject to unilateral constraints, Eq. (1) of [1]_.

A system is given by its mass matrix M(q), the generalised forces f_J(q, q', u) of each contact
mode J, the unilateral constraints a(q) >= 0 with Jacobian Da(q) and its time derivative, and the
coefficient of restitution gamma. From these alone this module computes what Eq. (1) defines:

- the reaction forces lambda_J that keep the active constraints' accelerations at zero, Eq. (1a);
- the accelerations q'' in mode J, Eq. (1a);
- the impact map Delta_J applied on entering J, Eq. (1b).

A contact mode is the bit mask of its active constraints (bit j set = constraint j active), the
convention of every trajectory (and of :class:`biped_opt.paper.biped.ContactMode`).

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import abc
from typing import cast

import numpy as np
import numpy.typing as npt

__all__ = [
    "MechanicalSystem",
    "active_constraints",
    "reaction_forces",
    "accelerations",
    "impact_map",
]

Array = npt.NDArray[np.float64]


class MechanicalSystem(abc.ABC):
    """A mechanical system subject to unilateral constraints a(q) >= 0 (paper Sec. II-A).

    Subclasses define the model; :func:`accelerations`, :func:`reaction_forces` and
    :func:`impact_map` turn it into the dynamics of Eq. (1). ``ndof`` is d (configuration
    dimension), ``nconstraints`` is n (number of unilateral constraints).
    """

    ndof: int
    nconstraints: int

    @property
    @abc.abstractmethod
    def restitution(self) -> float:
        """Coefficient of restitution gamma in [0, 1] of Delta_J (0: plastic impact)."""

    @abc.abstractmethod
    def mass_matrix(self, q: Array) -> Array:
        """M(q), shape (d, d), symmetric positive definite."""

    @abc.abstractmethod
    def forces(self, q: Array, dq: Array, u: Array, mode: int) -> Array:
        """Generalised forces f_J(q, q', u) of mode J, shape (d,)."""

    @abc.abstractmethod
    def constraints(self, q: Array) -> Array:
        """Unilateral constraint values a(q), shape (n,); contact j is possible where a_j = 0."""

    @abc.abstractmethod
    def constraint_jacobian(self, q: Array) -> Array:
        """Da(q), shape (n, d)."""

    @abc.abstractmethod
    def constraint_jacobian_rate(self, q: Array, dq: Array) -> Array:
        """(d/dt Da)(q, q') q', shape (n,): the velocity-product term of a''."""


def active_constraints(mode: int, n: int) -> list[int]:
    """Indices of the constraints active in ``mode`` (bit mask over ``n`` constraints)."""
    if mode < 0 or mode >= 1 << n:
        raise ValueError(f"mode must be a bit mask over {n} constraints, got {mode}")
    return [j for j in range(n) if mode >> j & 1]


def reaction_forces(
    system: MechanicalSystem, q: Array, dq: Array, u: Array, mode: int
) -> Array:
    """lambda_J = -(Da_J M^-1 Da_J^T)^-1 (Da_J M^-1 f_J + (d/dt Da_J) q'), Eq. (1a).

    Returns a vector of length n with zeros at the inactive constraints.
    """
    lam = np.zeros(system.nconstraints)
    active = active_constraints(mode, system.nconstraints)
    if not active:
        return lam
    mass = system.mass_matrix(q)
    da = system.constraint_jacobian(q)[active]
    minv_dat = np.linalg.solve(mass, da.T)
    minv_f = np.linalg.solve(mass, system.forces(q, dq, u, mode))
    rate = system.constraint_jacobian_rate(q, dq)[active]
    lam[active] = -np.linalg.solve(da @ minv_dat, da @ minv_f + rate)
    return lam


def accelerations(
    system: MechanicalSystem, q: Array, dq: Array, u: Array, mode: int
) -> tuple[Array, Array]:
    """q'' from M q'' = f_J + Da_J^T lambda_J, Eq. (1a); returns (q'', lambda)."""
    lam = reaction_forces(system, q, dq, u, mode)
    total = system.forces(q, dq, u, mode) + system.constraint_jacobian(q).T @ lam
    return cast(Array, np.linalg.solve(system.mass_matrix(q), total)), lam  # (float64)


def impact_map(system: MechanicalSystem, q: Array, mode: int) -> Array:
    """Delta_J = I - (1 + gamma) M^-1 Da_J^T (Da_J M^-1 Da_J^T)^-1 Da_J, Eq. (1b).

    ``mode`` is the mode being entered; q'+ = Delta_J q'-.
    """
    d = system.ndof
    active = active_constraints(mode, system.nconstraints)
    if not active:
        return np.eye(d)
    mass = system.mass_matrix(q)
    da = system.constraint_jacobian(q)[active]
    minv_dat = np.linalg.solve(mass, da.T)
    projector = minv_dat @ np.linalg.solve(da @ minv_dat, da)
    return np.eye(d) - (1.0 + system.restitution) * projector
