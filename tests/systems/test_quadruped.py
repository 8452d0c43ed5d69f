"""The library's quadruped (SYSTEMS.md Sec. 3) against an independent reference.

``tests/simulation/user/reference_quadruped.py`` computes M(q), the forces and the feet's
kinematics numerically by a recursive Newton-Euler pass over the kinematic tree and imports
nothing from biped_opt; the library's description declares its ten bodies (SYSTEMS.md Sec. 1a)
and ``derive`` sums M and the forces from their Jacobians. The derived system is checked point
by point against it without compiling anything, the generated code run as Python against
Eq. (1) of the derived system, and the compiled simulator against the reference's solve_ivp
(a cold compile of the quadruped takes about 35 s on two cores, SYSTEMS.md Sec. 3b; the
compiled tests share one compile on one worker).
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest
import sympy as sp

from biped_opt.systems.files import library_size
from biped_opt.systems.library.quadruped import PARAMETERS, quadruped
from tests.simulation.user import reference_quadruped as reference

D = 20
RNG_SEED = 25


@cache
def description():
    return quadruped()


@cache
def derived():
    from biped_opt.systems.derive import derive

    return derive(description())


@cache
def numeric():
    return derived().numeric()


@cache
def energy():
    s = description()
    values = {sym: s.defaults[str(sym)] for sym in s.p}
    return sp.lambdify([list(s.q), list(s.dq)], s.energy.xreplace(values), "numpy", cse=True)


def evaluate(q, dq):
    """(M, forces with no foot in contact, feet, Da, energy) of the derived system at (q, q')
    and the default parameters, as float arrays."""
    n = numeric()
    return (n.mass_matrix(q), n.forces(q, dq, np.zeros(0), 0), n.constraints(q),
            n.constraint_jacobian(q), float(energy()(list(q), list(dq))))


def states(count):
    """Random states around the standing posture, angles within about a radian."""
    rng = np.random.default_rng(RNG_SEED)
    rest = reference.Quadruped().initial(0.0)
    for _ in range(count):
        y = rest + np.concatenate([rng.uniform(-0.8, 0.8, D), rng.uniform(-2, 2, D)])
        yield y[:D], y[D:]


def test_the_description_is_the_issue_s_size():
    s = description()
    assert len(s.q) == 20 and len(s.constraints) == 4
    # (the size a node checks by name, before building anything)
    assert library_size("quadruped") == (len(s.constraints), len(s.q))
    assert s.defaults == {**PARAMETERS}
    assert list(s.maneuvers) == ["drop"]


def test_mass_matrix_is_symmetric_positive_definite_and_the_reference_s():
    """M is symmetric (a sum of symmetric products); at random q it is positive
    definite and equals the reference's sum of m Jv^T Jv + Jw^T I Jw to rounding (1e-12 of its
    largest entry: both evaluate the same numbers in different orders)."""
    ref = reference.Quadruped()
    for q, _dq in states(4):
        M = evaluate(q, np.zeros(D))[0]
        assert np.array_equal(M, M.T)
        expected = ref.mass(q)
        assert np.linalg.eigvalsh(M).min() > 1e-4  # the lightest rod's inertia is ~1e-3
        np.testing.assert_allclose(M, expected, rtol=0, atol=1e-12 * np.abs(expected).max())


def test_forces_are_the_reference_s():
    """The bodies' weight and velocity products plus the hinges' springs equal the reference's
    gravity, springs and Newton-Euler velocity products at random states (velocity products
    are O(|q'|^2) ~ 10, the tolerance 1e-10 of the largest force)."""
    ref = reference.Quadruped()
    for q, dq in states(4):
        f = evaluate(q, dq)[1]
        expected = ref.dynamics(np.concatenate([q, dq]))[1]
        np.testing.assert_allclose(f, expected, rtol=0, atol=1e-10 * np.abs(expected).max())


def test_feet_and_their_jacobian_are_the_reference_s():
    ref = reference.Quadruped()
    for q, dq in states(3):
        _M, _F, heights, Da, _rate = ref.dynamics(np.concatenate([q, dq]))
        _m, _f, feet, jacobian, _e = evaluate(q, dq)
        np.testing.assert_allclose(feet, heights, rtol=0, atol=1e-14)
        np.testing.assert_allclose(jacobian, Da, rtol=0, atol=1e-14)


def test_energy_is_kinetic_from_m_plus_the_reference_s_potential():
    """The declared energy is q'^T M q' / 2 plus a potential of q alone (so it is consistent
    with M), and equals the reference's energy."""
    ref = reference.Quadruped()
    for q, dq in states(3):
        M, _f, _feet, _da, E = evaluate(q, dq)
        at_rest = evaluate(q, np.zeros(D))[4]
        assert E == pytest.approx(at_rest + dq @ M @ dq / 2, rel=1e-13, abs=1e-13)
        assert E == pytest.approx(ref.energy(np.concatenate([q, dq])), rel=1e-12)


def test_the_reference_conserves_energy_and_falls_rigidly():
    """The reference itself: in flight from a random velocity the energy holds to 1e-10 of its
    scale (the velocity products are right, DOP853 at rtol 1e-12); from rest in the posture the
    springs are slack and the robot falls as one body, so at th0 = 0 all four feet land at once
    at t = sqrt(2 drop / g), the fall's closed form."""
    from scipy.integrate import solve_ivp

    ref = reference.Quadruped()
    y = ref.initial(0.1)
    y[D:] = np.random.default_rng(RNG_SEED).uniform(-2, 2, D)
    sol = solve_ivp(ref.field(frozenset()), (0, 0.05), y, method="DOP853",
                    rtol=reference.RTOL, atol=reference.ATOL)
    assert abs(ref.energy(sol.y[:, -1]) - ref.energy(y)) < 1e-10 * ref.energy(y)
    level = reference.simulate(ref, 0.0, max_events=1)
    t, down, _up, _after = level.events[0]
    assert sorted(down) == [0, 1, 2, 3]
    assert t == pytest.approx(math.sqrt(2 * PARAMETERS["drop"] / PARAMETERS["g"]), abs=1e-12)


# -- the compiled simulator against the reference ------------------------------------------------

#: event times and outcomes: the reference (rtol 1e-12) and the simulator (rtol 1e-11) follow
#: the same trajectory through several impacts and liftoffs; 1e-8 leaves room for the
#: integrators' global errors over ~0.2 s and none for a wrong event (a wrong impact changes
#: the roll rate by O(1))
TOL = 1e-8


@pytest.fixture(scope="module")
def quad():
    """The compiled quadruped, once per module (and so on one worker: tests/conftest.py)."""
    from biped_opt.simulation.compiled import CompiledSystem

    return CompiledSystem("quadruped")


#: a foot this slow (m/s) at an event is at rest on the ground to rounding
GRAZING = 1e-9


def assert_agrees(tr, ref, where):
    """Same status, the same touchdowns and liftoffs in the same order with the same modes after
    them, event times and the outcome within TOL.

    A foot that lifted off a little above the ground (the feet of a merged impact land within
    the 1e-9 band, not at 0) hovers there at rest to rounding; when the next event comes, the
    sign of its rounding-level rate decides whether it joins the event as a touchdown, is
    released at once and changes nothing. Such grazing touchdowns (rate below GRAZING, the foot
    not in the mode after) are left out on both sides."""
    assert tr.status.name == ref.status, f"{where}: {tr.status.name} vs {ref.status}"
    robot = reference.Quadruped()

    def feet(mask):
        return frozenset(j for j in range(4) if mask >> j & 1)

    def landed(down, after, state):
        rates = robot.dynamics(state)[3] @ state[D:]
        return frozenset(j for j in down if j in after or abs(rates[j]) > GRAZING)

    ours = [(landed(feet(e.mask_entered), feet(e.mask_after), e.state_before),
             feet(e.mask_left), feet(e.mask_after)) for e in tr.contact_events]
    theirs = [(landed(down, after, e.state_before), up, after)
              for (_t, down, up, after), e in zip(ref.events, tr.contact_events)]
    assert len(ref.events) == len(tr.contact_events), f"{where}: {len(tr.contact_events)} " \
        f"events, reference {len(ref.events)}"
    assert ours == theirs, f"{where}: events {ours}, reference {theirs}"
    np.testing.assert_allclose([e.t for e in tr.contact_events], ref.times, rtol=0, atol=TOL,
                               err_msg=where)
    assert tr.outcome == pytest.approx(ref.outcome, rel=0, abs=TOL), where
    assert tr.t_final == pytest.approx(ref.t_final, rel=0, abs=TOL), where


@pytest.mark.parametrize("th0", [0.05, -0.12])
def test_drop_against_the_reference(th0, quad):
    ref = reference.simulate(reference.Quadruped(), th0)
    tr = quad.simulate("drop", th0)
    assert_agrees(tr, ref, f"th0 = {th0}")
    before, after = ref.first_impact
    first = tr.contact_events[0]
    np.testing.assert_allclose(first.state_before, before, rtol=0, atol=1e-9)
    np.testing.assert_allclose(first.state_after, after, rtol=0, atol=1e-9)


def test_a_released_foot_s_short_hop(quad):
    """th0 = 0.11: the front left foot lands at t = 0.1060647, is released at once (it would
    pull in contact), hops and lands again 0.116 ms later; the reference follows it with short
    steps while the foot sits at zero. The hop starts at rest (rate -5e-16, rounding) and is
    3e-10 high: the kernel finds its apex by halving toward the start (SYSTEMS.md Sec. 5;
    it once ended this run INCONSISTENT)."""
    ref = reference.simulate(reference.Quadruped(), 0.11)
    assert [sorted(down) for _t, down, *_rest in ref.events][2:4] == [[0], [0]]
    assert_agrees(quad.simulate("drop", 0.11), ref, "th0 = 0.11")


def test_energy_holds_in_flight(quad):
    """Nothing dissipates before the first touchdown: the reference's energy of the
    simulator's samples stays within 1e-9 of its scale (~31 J)."""
    ref = reference.Quadruped()
    tr = quad.simulate("drop", 0.1, sample_dt=0.002)
    flight = tr.samples[tr.samples[:, 0] < tr.contact_events[0].t]
    assert len(flight) > 20
    energy = np.array([ref.energy(row[1:1 + 2 * D]) for row in flight])
    assert np.ptp(energy) < 1e-9 * abs(energy[0])


def test_four_feet_land_together_at_th0_zero(quad):
    """At th0 = 0 the fall is level: one impact of all four feet; within 1e-9 of it the feet
    are within the simultaneity band and still land in one impact, and 1e-6 away they land
    one by one, in orders that differ on the two sides."""
    ref = reference.Quadruped()
    for th0 in (0.0, -1e-9, 1e-9):
        level = reference.simulate(ref, th0)
        assert sorted(level.events[0][1]) == [0, 1, 2, 3]
        assert_agrees(quad.simulate("drop", th0), level, f"th0 = {th0}")
    orders = []
    for th0 in (-1e-6, 1e-6):
        split = reference.simulate(ref, th0)
        assert_agrees(quad.simulate("drop", th0), split, f"th0 = {th0}")
        orders.append([sorted(down) for _t, down, *_rest in split.events if down])
    assert orders[0][0] != orders[1][0]


def test_the_scene_is_the_reference_s_pose(quad):
    """The looks in 3-D: at a random pose the frames' positions and rotations (the rear half's
    rpy recovered from its rotation by atan2 and asin) and the contact points are the
    reference's to rounding."""
    system = quad
    ref = reference.Quadruped()
    q = ref.initial(0.0)[:D] + np.random.default_rng(RNG_SEED).uniform(-0.8, 0.8, D)
    state = system.scene.evaluate(q[None], np.array(list(PARAMETERS.values())))
    bodies, feet = ref.tree(q, np.zeros(D))
    poses = {"base_link": bodies[0].centre, "rear_link": bodies[1].centre,
             **{f"{leg}_foot": foot for leg, foot in zip(reference.LEGS, feet)}}
    assert set(system.scene.frames) == set(poses)
    for k, name in enumerate(system.scene.frames):
        x, y, z, w = state.quaternions[0, k]
        rotation = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                             [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                             [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        np.testing.assert_allclose(state.positions[0, k], poses[name].o, rtol=0, atol=1e-14)
        if not name.endswith("_foot"):  # (feet are balls: no orientation declared)
            np.testing.assert_allclose(rotation, poses[name].R, rtol=0, atol=1e-14)
    np.testing.assert_allclose(state.contacts[0], [f.o for f in feet], rtol=0, atol=1e-14)


# -- the generated code, run as Python (no compile): the bodies' sums of SYSTEMS.md Sec. 1a -----

@cache
def generated():
    """The quadruped's generated module, imported without compiling anything: its functions'
    ``py_func`` run the generated code itself in Python."""
    import importlib.util
    import tempfile
    from pathlib import Path

    from biped_opt.codegen.render import render

    folder = Path(tempfile.mkdtemp(prefix="biped_opt_quadruped_"))
    path = folder / "quadruped_generated.py"
    path.write_text(render(derived()))
    spec = importlib.util.spec_from_file_location("quadruped_generated", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_generated_field_and_impact_are_eq_1_of_the_derived_system():
    """The vector field in every mode (accelerations and reactions) and the impact map of every
    mode, as generated (sums of the bodies' products, unrolled Cholesky), against Eq. (1) from
    NumericSystem (NumPy sums of the same bodies, LAPACK solves) at random states: 1e-12 of
    each quantity's scale (two evaluations of the same sums in different orders, and the
    reactions' small Schur complements amplify rounding by ~1e2)."""
    from biped_opt.systems import mechanics

    m = generated()
    n = numeric()
    s = description()
    p = m.prepare_parameters(np.array([s.defaults[k] for k in s.p.names()]))
    for q, dq in states(2):
        y = np.concatenate([q, dq])
        for mode in range(16):
            out, lam = np.zeros(2 * D), np.zeros(4)
            m._field_at.py_func(p, mode, y.copy(), 0, np.zeros(0), out, 0, lam, 0)
            acc, reactions = mechanics.accelerations(n, q, dq, np.zeros(0), mode)
            assert np.array_equal(out[:D], dq)
            np.testing.assert_allclose(out[D:], acc, rtol=0, atol=1e-12 * np.abs(acc).max())
            np.testing.assert_allclose(lam, reactions, rtol=0,
                                       atol=1e-12 * max(1.0, np.abs(reactions).max()))
            if mode:
                after = y.copy()
                m.apply_impact.py_func(p, mode, after)
                expected = mechanics.impact_map(n, q, mode) @ dq
                np.testing.assert_allclose(after[D:], expected, rtol=0,
                                           atol=1e-12 * np.abs(dq).max())
