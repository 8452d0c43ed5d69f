"""Eq. (1) of the framework: checked on the biped and on a second, non-diagonal system."""

from __future__ import annotations

import numpy as np
import pytest

from biped_opt.paper.biped import BipedParams
from biped_opt.systems.mechanics import (
    MechanicalSystem,
    accelerations,
    active_constraints,
    impact_map,
    reaction_forces,
)
from tests.paper.biped_physics import Biped, apply_impact, dynamics, packed


class Bar(MechanicalSystem):
    """A planar rigid bar (x, z, th) whose two ends must stay above the ground.

    a_j = z + s_j l sin th: the constraint Jacobian depends on q and has a velocity-product
    term, unlike the biped's, so it exercises every term of Eq. (1).
    """

    ndof = 3
    nconstraints = 2

    def __init__(self, gamma: float = 0.5) -> None:
        self.m, self.inertia, self.l, self.g, self._gamma = 2.0, 0.3, 0.7, 9.81, gamma

    @property
    def restitution(self) -> float:
        return self._gamma

    def mass_matrix(self, q):
        return np.diag([self.m, self.m, self.inertia])

    def forces(self, q, dq, u, mode):
        return np.array([u[0], -self.m * self.g, u[1]])

    def constraints(self, q):
        return np.array([q[1] - self.l * np.sin(q[2]), q[1] + self.l * np.sin(q[2])])

    def constraint_jacobian(self, q):
        c = self.l * np.cos(q[2])
        return np.array([[0.0, 1.0, -c], [0.0, 1.0, c]])

    def constraint_jacobian_rate(self, q, dq):
        s = self.l * np.sin(q[2]) * dq[2] ** 2
        return np.array([s, -s])


@pytest.mark.parametrize("mode", [0, 1, 2, 3])
def test_reactions_hold_active_constraints_still(mode):
    """a_J'' = Da_J q'' + (d/dt Da_J) q' = 0 for the active constraints (Eq. (1a))."""
    bar = Bar()
    rng = np.random.default_rng(mode)
    q, dq, u = rng.normal(size=3), rng.normal(size=3), rng.normal(size=2)
    ddq, lam = accelerations(bar, q, dq, u, mode)
    active = active_constraints(mode, 2)
    constraint_acc = bar.constraint_jacobian(q) @ ddq + bar.constraint_jacobian_rate(q, dq)
    np.testing.assert_allclose(constraint_acc[active], 0.0, atol=1e-12)
    inactive = [j for j in range(2) if j not in active]
    np.testing.assert_array_equal(lam[inactive], 0.0)


@pytest.mark.parametrize("gamma", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("mode", [1, 2, 3])
def test_impact_map_restitution_and_energy(gamma, mode):
    """Da_J q'+ = -gamma Da_J q'-; gamma = 1 conserves kinetic energy, gamma < 1 loses it."""
    bar = Bar(gamma)
    rng = np.random.default_rng(10 + mode)
    q, dq = rng.normal(size=3), rng.normal(size=3)
    delta = impact_map(bar, q, mode)
    after = delta @ dq
    active = active_constraints(mode, 2)
    da = bar.constraint_jacobian(q)[active]
    np.testing.assert_allclose(da @ after, -gamma * (da @ dq), atol=1e-12)
    mass = bar.mass_matrix(q)
    kinetic_before, kinetic_after = dq @ mass @ dq / 2, after @ mass @ after / 2
    if gamma == 1.0:
        assert kinetic_after == pytest.approx(kinetic_before, rel=1e-12)
    else:
        assert kinetic_after <= kinetic_before + 1e-12


def test_mode_must_fit_constraints():
    with pytest.raises(ValueError, match="bit mask"):
        reaction_forces(Bar(), np.zeros(3), np.zeros(3), np.zeros(2), 4)


@pytest.mark.parametrize("mode", [0, 1, 2, 3])
def test_biped_specialised_dynamics_equal_generic_eq1(mode):
    """The compiled biped vector field equals Eq. (1a) evaluated with general linear algebra."""
    # damping on and no unit masses, so every force term and every mass scaling is exercised
    params = BipedParams(c=0.3, mb=1.3, Ib=0.4, mf=0.7, g=1.1)
    biped = Biped(params)
    rng = np.random.default_rng(100 + mode)
    for _ in range(5):
        y = rng.normal(scale=0.3, size=14)
        y[1] += 1.0
        u = rng.normal(size=3)
        dy, lam = np.empty(14), np.empty(2)
        dynamics(packed(params), mode, y, u, dy, lam)
        ddq, lam_ref = accelerations(biped, y[:7], y[7:], u, mode)
        np.testing.assert_allclose(dy[:7], y[7:], rtol=0, atol=0)
        np.testing.assert_allclose(dy[7:], ddq, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(lam, lam_ref, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("mode", [1, 2, 3])
def test_biped_specialised_impact_equals_generic_eq1b(mode):
    params = BipedParams(gamma=0.7)
    rng = np.random.default_rng(200 + mode)
    y = rng.normal(size=14)
    expected = impact_map(Biped(params), y[:7], mode) @ y[7:]
    apply_impact(packed(params), mode, y)
    np.testing.assert_allclose(y[7:], expected, atol=1e-15)


def test_force_coupling_inputs_act_only_in_their_mode():
    """u1 acts only in LEFT, u2 only in RIGHT, u12 only in GROUND (paper Sec. II-B)."""
    biped = Biped()
    rng = np.random.default_rng(7)
    q, dq = rng.normal(scale=0.2, size=7), rng.normal(size=7)
    q[1] += 1.0
    for mode, active_input in ((0, None), (1, 0), (2, 1), (3, 2)):
        base = biped.forces(q, dq, np.zeros(3), mode)
        for i in range(3):
            u = np.zeros(3)
            u[i] = 1.0
            changed = not np.allclose(biped.forces(q, dq, u, mode), base, atol=0)
            assert changed == (i == active_input), (mode, i)
