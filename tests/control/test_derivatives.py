"""Bouligand derivatives of generated systems' outcomes against extrapolated finite differences.

References are one-sided difference quotients of ``CompiledSystem.simulate`` at rtol 1e-13,
extrapolated to h -> 0 (:func:`~biped_opt.piecewise.one_sided`: a polynomial through five
points
h0 / 2^k on one side, i.e. Richardson), or central differences extrapolated twice. Each
comparison's tolerance is computed (:mod:`tests.extrapolated`): SAFETY times the reference's
truncation estimate (its last two extrapolants) plus the samples' integration error (rtol
max(1, |f|)) times the scheme's weights, plus the sensitivity's own error (the variational
integration's rtol 1e-11, relative)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import sympy as sp

from biped_opt.control.derivatives import (
    DEFAULT_VARIATIONAL,
    directional_derivative,
    final_state_directional_derivative,
    one_sided_derivatives,
    outcome_gradient,
)
from biped_opt.errors import InvalidInputError, SimulationError
from biped_opt.simulation.compiled import compile_system
from biped_opt.simulation.options import SimulatorOptions
from biped_opt.systems import System
from tests.extrapolated import central, extrapolated, relative_noise
from tests.paper import oracle_biped as biped_derivatives

TIGHT = SimulatorOptions(rtol=1e-13, atol=1e-14)
#: walker3 touchdown inputs (u1, u2, u3); u_body = 0
U3 = (2.0, 1.0, 0.5, 0.0)


@pytest.fixture(scope="module")
def bar():
    return compile_system("rocking_bar")


@pytest.fixture(scope="module")
def walker3():
    return compile_system("walker3_coupled")


def _along(compiled, maneuver, p, v, what="outcome"):
    """t -> the simulated ``what`` at the parameters p + t v (p, v over (s, *inputs))."""
    p, v = np.asarray(p, dtype=float), np.asarray(v, dtype=float)

    def f(t):
        q = p + t * v
        return getattr(compiled.simulate(maneuver, q[0], tuple(q[1:]), options=TIGHT), what)

    return f


def _own(x):
    """The sensitivity's own error: the variational integration's relative tolerance."""
    return DEFAULT_VARIATIONAL.rtol * np.maximum(1.0, np.abs(x))


def _one_sided(f, side):
    """The extrapolated one-sided quotient at 0 from h0 = 1e-3, samples at TIGHT's rtol."""
    return extrapolated(f, 0.0, side, h0=1e-3, noise=relative_noise(TIGHT.rtol))


@pytest.mark.parametrize("s", [0.05, 0.2])
def test_rocking_bar_gradient_away_from_zero(bar, s):
    """Away from its jumps the bar's outcome th'(t_f) is smooth: the extrapolated one-sided
    quotients in s from both sides, and extrapolated central differences (h = 1e-3, error
    O(h^6)) in s and in the air torque u_th, give the gradient."""
    g = outcome_gradient(bar, "drop", s, (0.0,))
    assert not g.simultaneous and not g.continued
    assert g.outcome == pytest.approx(bar.simulate("drop", s).outcome, abs=1e-9)
    for side in (-1, 1):
        fd = _one_sided(_along(bar, "drop", (s, 0.0), (1.0, 0.0)), side)
        assert g.d("s") == pytest.approx(fd.derivative, abs=fd.tolerance(_own(g.d("s"))))
    for k, e in enumerate(np.eye(2)):
        c = central(_along(bar, "drop", (s, 0.0), e), 0.0, 1e-3, rtol=TIGHT.rtol)
        assert g.gradient[k] == pytest.approx(c.derivative, abs=c.tolerance(_own(g.gradient[k])))
    if s == 0.2:  # SYSTEMS.md Sec. 2: left, right only
        assert g.outcome == pytest.approx(2.42070065442, abs=1e-10)
        assert g.flips == (0, 1)


def test_rocking_bar_one_sided_at_the_jump(bar):
    """At th0 = 0 the outcome jumps (0 at the point, -0.1988738 from the right, its mirror
    image from the left). Each side's derivative is the slope of that branch's limit: the
    impacts left, right, left (right, left, right) in one instant, then the continued flight."""
    left, right = one_sided_derivatives(bar, "drop", 0.0)
    for side, slope in ((-1, left), (1, right)):
        fd = _one_sided(_along(bar, "drop", (0.0, 0.0), (1.0, 0.0)), side)
        assert slope == pytest.approx(fd.derivative, abs=fd.tolerance(_own(slope)))
        g = outcome_gradient(bar, "drop", 0.0, direction=(side, 0.0))
        assert g.simultaneous and g.continued
        assert g.outcome == pytest.approx(fd.limit, abs=1e-9)
        assert g.outcome == pytest.approx(-side * 0.1988738, abs=1e-7)
        # every impact separates at once (gamma = 0.5): the mode stays the air mode
        assert g.flips == ((0, 1, 0) if side > 0 else (1, 0, 1))
        assert g.modes == (0, 0, 0, 0)
    assert right == pytest.approx(left, abs=1e-9)  # th'(t_f) is odd in th0: slopes agree


@pytest.mark.parametrize(("name", "left", "right"), [
    ("walker3_coupled", 0.8732676633, 0.8395968313),
    ("walker3_decoupled", 0.8874799113, 0.8874799113),
])
def test_walker3_touchdown_slopes_at_the_triple_touchdown(name, left, right):
    """SYSTEMS.md Sec. 3 (u = (u1, u2, u3) = (2, 1, 0.5), u_body = 0): three feet touch down
    together at th0 = 0. SYSTEMS.md gives 10 digits from an independent implementation; ours
    are good to ~1e-10, so 1e-8 leaves room for the reference only. Also the extrapolated
    one-sided quotients."""
    w = compile_system(name)
    lo, hi = one_sided_derivatives(w, "touchdown", 0.0, U3)
    assert lo == pytest.approx(left, abs=1e-8)
    assert hi == pytest.approx(right, abs=1e-8)
    f = _along(w, "touchdown", (0.0, *U3), (1.0, 0.0, 0.0, 0.0, 0.0))
    for slope, side in ((lo, -1), (hi, 1)):
        fd = _one_sided(f, side)
        assert slope == pytest.approx(fd.derivative, abs=fd.tolerance(_own(slope)))


@pytest.mark.parametrize(("maneuver", "u", "jump"), [
    ("touchdown", (2.0, 0.5, 0.0), False),
    ("liftoff", (1.5, 3.0, 0.0), True),
    ("liftoff", (1.5, -3.0, 0.0), True),  # th0 < 0: the right foot's reaction drops below 0
    ("liftoff", (0.0, 0.0, 0.0), False),
])
def test_walker2_is_the_biped(maneuver, u, jump):
    """walker2_coupled is the biped: its branches' gradients (s and inputs) and limits at the
    simultaneous events of th0 = 0 (the touchdown kink, the liftoff jump, and the liftoff where
    u2 < 0 makes the second foot lift at once from one side) and at th0 = 0.1 agree with the
    biped's own hand-written derivatives. Same method, same formulas, two variational
    integrations at rtol 1e-11: 1e-9."""
    w = compile_system("walker2_coupled")
    for s in (0.0, 0.1):
        mine = one_sided_derivatives(w, maneuver, s, u)
        ref = tuple(biped_derivatives.outcome_derivative(maneuver, s, u, side)
                    for side in (-1, 1))
        assert mine == pytest.approx(ref, abs=1e-9)
    for side in (-1, 1):
        v = (float(side), 0.0, 0.0, 0.0)
        g = outcome_gradient(w, maneuver, 0.0, u, direction=v)
        r = biped_derivatives.outcome_sensitivity(maneuver, 0.0, u, direction=v)
        np.testing.assert_allclose(g.gradient, r.gradient, rtol=0, atol=1e-9)
        assert g.outcome == pytest.approx(r.outcome, abs=1e-10)
        assert g.continued == r.continued
        if side > 0:
            assert g.continued == jump


def test_gradient_of_outcome_final_state_and_time(walker3):
    """Away from simultaneous events (th0 = 0.1: feet 1, 2, 3 one after another, u_body
    active at the end): d outcome, d y_final and d t_final w.r.t. (s, u1, u2, u3, u_body)
    against extrapolated central differences (h = 1e-2)."""
    p = np.array([0.1, 2.0, 1.0, 0.5, 0.3])
    g = outcome_gradient(walker3, "touchdown", p[0], tuple(p[1:]))
    assert not g.simultaneous and g.modes == walker3.simulate(
        "touchdown", p[0], tuple(p[1:])).modes
    for k in range(p.size):
        e = np.eye(p.size)[k]
        for what, value in (("outcome", g.gradient[k]), ("t_final", g.time_gradient[k]),
                            ("y_final", g.state_gradient[:, k])):
            c = central(_along(walker3, "touchdown", p, e, what), 0.0, 1e-2, rtol=TIGHT.rtol)
            gap = np.abs(value - c.derivative)
            assert np.all(gap <= c.tolerance(_own(value))), (what, k, gap, c.error)
    # u2 and u3 act only while their leg is alone on the ground, which never happens here
    assert abs(g.d("u2")) < 1e-10 and abs(g.d("u3")) < 1e-10
    assert abs(g.d("u_body")) > 1e-3 and abs(g.d("u1")) > 1e-3


DIRECTIONS = [
    (1.0, 0.0, 0.0, 0.0, 0.0),
    (1.0, 0.3, -0.2, 0.5, 1.0),
    (-1.0, 0.3, -0.2, 0.5, 1.0),
    (-0.4, 1.0, 2.0, -1.0, -0.5),
    (0.2, 0.0, 0.0, 0.0, -2.0),
    (0.0, 1.0, 0.0, 0.0, 1.0),
]


@pytest.mark.parametrize("v", DIRECTIONS)
def test_walker3_bouligand_derivative_along_directions(walker3, v):
    """At th0 = 0 (three simultaneous touchdowns) the derivative along v in (s, u) is the
    extrapolated one-sided quotient along v, for directions on both sides of the kink."""
    b = directional_derivative(walker3, "touchdown", 0.0, U3, v)
    fd = _one_sided(_along(walker3, "touchdown", (0.0, *U3), v), 1)
    assert b == pytest.approx(fd.derivative, abs=fd.tolerance(_own(b)))


def test_walker3_bouligand_derivative_is_piecewise_linear(walker3):
    """Positively homogeneous in v; linear on each side of the kink (th0 perturbed up or down
    orders the touchdowns 1, 2, 3 or 3, 2, 1); not linear across it."""
    def b(v):
        return directional_derivative(walker3, "touchdown", 0.0, U3, v)

    v = np.array(DIRECTIONS[1])
    assert b(3.0 * v) == pytest.approx(3.0 * b(v), rel=1e-12)
    assert b(0.25 * v) == pytest.approx(0.25 * b(v), rel=1e-12)
    up, down = np.array(DIRECTIONS[1]), np.array(DIRECTIONS[3])
    w = np.array([0.5, -1.0, 0.0, 2.0, 0.7])
    assert b(up + w) == pytest.approx(b(up) + b(w), abs=1e-9)  # both on the th0 > 0 side
    assert b(down - w) == pytest.approx(b(down) + b(-w), abs=1e-9)  # both on th0 < 0
    left, right = one_sided_derivatives(walker3, "touchdown", 0.0, U3)
    assert b(up + down) != pytest.approx(b(up) + b(down), abs=1e-3)
    assert right - left == pytest.approx(0.8395968313 - 0.8732676633, abs=1e-8)
    dy = final_state_directional_derivative(walker3, "touchdown", 0.0, U3, v)
    g = outcome_gradient(walker3, "touchdown", 0.0, U3, direction=v)
    assert dy[2] == pytest.approx(b(v), abs=1e-12)  # the outcome is th(t_f)
    assert g.modes == (0, 1, 3, 7)  # th0 up: foot 1 (hip at -w) first, zero-length modes


def _three_drops() -> System:
    """Three unit masses dropped from heights 1, 1 + s, 1 - s onto the ground (plastic), each
    pushed up by its input while in the air; a recorder x is accelerated by a constant that
    depends on the contact mode non-additively, so the order of the touchdowns shows in x(2)."""
    s = System("three_drops", ["z1", "z2", "z3", "x", "c"], parameters={"g": 1.0},
               inputs=["u1", "u2", "u3"], s="s")
    z = s.q[:3]
    s.mass_matrix = sp.eye(5)
    feet = ["f1", "f2", "f3"]
    for name, zj in zip(feet, z):
        s.constraint(name, zj)

    def forces(J):
        down = [name in J for name in feet]
        mask = sum(1 << j for j, b in enumerate(down) if b)
        return [*(-s.p.g + (0 if b else u) for b, u in zip(down, s.u)),
                sp.Rational((mask * mask) % 7 + mask, 5), 0]

    s.forces = forces
    s.maneuver("drop", initial={z[0]: 1, z[1]: 1 + s.s, z[2]: 1 - s.s, s.dq[4]: 1},
               terminal=2 - s.q[4], outcome=s.q[3])
    return s


def test_three_simultaneous_touchdowns_have_six_linear_pieces():
    """At s = 0, u = 0 the three masses land together; a direction in u orders them in any
    of the 3! ways (the most negative input lands first). Each order is its own linear piece,
    and each direction's derivative is the extrapolated one-sided quotient along it."""
    c = compile_system(_three_drops())
    assert c.simulate("drop", 0.0, (0.0, 0.0, 0.0)).modes == (0, 7)
    pieces = []
    for order in itertools.permutations(range(3)):
        v = np.zeros(4)
        for rank, j in enumerate(order):
            v[1 + j] = -(3.0 - rank)
        g = outcome_gradient(c, "drop", 0.0, (0.0, 0.0, 0.0), direction=v)
        assert g.flips == order and g.simultaneous and not g.continued
        fd = _one_sided(_along(c, "drop", (0.0, 0.0, 0.0, 0.0), v), 1)
        b = g.gradient @ v
        assert b == pytest.approx(fd.derivative, abs=fd.tolerance(_own(b)))
        pieces.append(g.gradient)
    gaps = [np.max(np.abs(a - b)) for a, b in itertools.combinations(pieces, 2)]
    assert min(gaps) > 1e-2


def test_near_a_simultaneous_event_the_gradient_is_the_local_one(walker3):
    """At th0 = 1e-9 the feet land 1e-9 apart: no direction is needed, the gradient is the one
    of th0 > 0 (to O(1e-9)), from either direction."""
    near = outcome_gradient(walker3, "touchdown", 1e-9, U3)
    left = outcome_gradient(walker3, "touchdown", 1e-9, U3, direction=(-1.0, 0, 0, 0, 0))
    right = outcome_gradient(walker3, "touchdown", 0.0, U3, direction=(1.0, 0, 0, 0, 0))
    np.testing.assert_allclose(near.gradient, right.gradient, rtol=0, atol=1e-7)
    np.testing.assert_allclose(left.gradient, right.gradient, rtol=0, atol=1e-7)
    assert near.flips == left.flips == right.flips == (0, 1, 2)


def test_errors(walker3):
    with pytest.raises(SimulationError, match="simultaneous"):
        outcome_gradient(walker3, "touchdown", 0.0, U3)
    with pytest.raises(InvalidInputError, match="direction"):
        directional_derivative(walker3, "touchdown", 0.0, U3, (1.0, 0.0))
    with pytest.raises(InvalidInputError, match="maneuver"):
        outcome_gradient(walker3, "jump", 0.0, U3)
