"""One-sided derivatives through events, and the policy/value B-derivatives of Theorem 1.

Independent checks: Richardson-extrapolated one-sided finite differences of the simulator's
outcome (:func:`biped_opt.piecewise.one_sided`) and of the optimal solver's policy and value,
MODEL.md's reference slopes and limits, and the biped's mirror symmetry.

Tolerances are computed (:mod:`tests.extrapolated`): SAFETY times the reference's error
estimate - its truncation (the last two extrapolants) plus each sample's error times the
extrapolation's weights - plus the sensitivity's own (the variational rtol 1e-11, relative).
Outcomes are simulated at rtol 1e-11; a solver's optimal policy is off the optimum by the
Newton step |c'(u)| / c''(u) left at it (:func:`_distance`, exact c', differenced c''), its value
by the simulation's tolerance (the value is stationary in u). MODEL.md quotes 9 digits, so its
slopes are compared to 1e-6 absolute.
"""

from __future__ import annotations

import numpy as np
import pytest

from biped_opt.control.derivatives import DEFAULT_VARIATIONAL, saltation_matrix
from biped_opt.errors import InvalidInputError, SimulationError
from biped_opt.paper.biped import ContactMode, simulate
from biped_opt.paper.derivatives import (
    PARAMETER_NAMES,
    one_sided_derivatives,
    outcome_derivative,
    outcome_sensitivity,
)
from biped_opt.paper.problems import get_problem
from biped_opt.paper.solve import optimal_policy
from biped_opt.piecewise import locate_switch
from biped_opt.simulation.options import DEFAULT_OPTIONS
from tests.extrapolated import SAFETY, extrapolated, relative_noise

TD_U = (2.0, 0.5, 0.0)
LO_U = (1.5, 3.0, 0.0)
#: the simulated outcome's error per sample (relative)
SIM_NOISE = relative_noise(DEFAULT_OPTIONS.rtol)


def _own(x: float) -> float:
    """A sensitivity's own error: the variational integration's relative tolerance."""
    return DEFAULT_VARIATIONAL.rtol * max(1.0, abs(x))


def _fd_gradient(maneuver: str, theta0: float, inputs: tuple[float, ...]
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Central (two one-sided extrapolations, averaged) differences of th_f per parameter, and
    their error estimates (the two sides must agree within them: th_f is C^1 here)."""
    out, err = np.empty(len(PARAMETER_NAMES)), np.empty(len(PARAMETER_NAMES))
    for k in range(len(PARAMETER_NAMES)):
        def f(x: float, k: int = k) -> float:
            if k == 0:
                return simulate(maneuver, x, inputs).outcome
            u = np.array(inputs, dtype=float)
            u[k - 1] = x
            return simulate(maneuver, theta0, u).outcome

        x0 = theta0 if k == 0 else inputs[k - 1]
        h0 = 1e-2 if k == 0 else 5e-2
        right = extrapolated(f, x0, 1, h0=h0, levels=5, noise=SIM_NOISE)
        left = extrapolated(f, x0, -1, h0=h0, levels=5, noise=SIM_NOISE)
        assert right.derivative == pytest.approx(left.derivative, abs=right.tolerance(left.error))
        out[k] = 0.5 * (right.derivative + left.derivative)
        err[k] = 0.5 * (right.error + left.error)
    return out, err


@pytest.mark.parametrize(
    ("maneuver", "theta0", "inputs"),
    [
        ("touchdown", 0.1, TD_U),
        ("touchdown", -0.137, (0.3, 1.2, 0.4)),
        ("liftoff", 0.05, (1.5, 3.0, 0.1)),
        ("liftoff", -0.12, (1.0, 2.0, -0.2)),
    ],
)
def test_gradient_matches_extrapolated_differences(maneuver, theta0, inputs):
    sens = outcome_sensitivity(maneuver, theta0, inputs)
    assert not sens.simultaneous and not sens.continued
    assert sens.outcome == pytest.approx(simulate(maneuver, theta0, inputs).outcome, abs=1e-13)
    fd, err = _fd_gradient(maneuver, theta0, inputs)
    own = np.array([_own(g) for g in sens.gradient])
    gap = np.abs(sens.gradient - fd)
    assert np.all(gap <= SAFETY * (err + own)), (gap, err)
    # away from simultaneous events the two sides agree (th_f is C^1 there)
    left = outcome_derivative(maneuver, theta0, inputs, side=-1)
    assert left == pytest.approx(sens.d_theta0, rel=1e-12)


def test_touchdown_kink_slopes_at_zero():
    right = outcome_sensitivity("touchdown", 0.0, TD_U, direction=(1, 0, 0, 0))
    left = outcome_sensitivity("touchdown", 0.0, TD_U, direction=(-1, 0, 0, 0))
    assert right.d_theta0 == pytest.approx(0.714366448, abs=1e-6)  # MODEL.md Sec. 6
    assert left.d_theta0 == pytest.approx(0.796243869, abs=1e-6)
    assert right.simultaneous and not right.continued  # zero-length single stance
    assert right.mode_sequence == (ContactMode.AIR, ContactMode.LEFT, ContactMode.GROUND)
    assert left.mode_sequence == (ContactMode.AIR, ContactMode.RIGHT, ContactMode.GROUND)

    def f(x: float) -> float:
        return simulate("touchdown", x, TD_U).outcome

    for sens, side in ((right, 1), (left, -1)):
        fd = extrapolated(f, 0.0, side, h0=1e-2, levels=6, noise=SIM_NOISE)
        assert sens.d_theta0 == pytest.approx(fd.derivative,
                                              abs=fd.tolerance(_own(sens.d_theta0)))
        assert fd.limit == pytest.approx(0.0, abs=1e-10)
    # the single-stance inputs act for a zero time on either branch at th0 = 0
    assert right.d_input("u1") == 0.0 and right.d_input("u2") == 0.0


def test_touchdown_smooth_without_inputs():
    right = outcome_derivative("touchdown", 0.0, (0.0, 0.0), side=1)
    left = outcome_derivative("touchdown", 0.0, (0.0, 0.0), side=-1)
    # MODEL.md gives 0.823536373; the extrapolated differences agree with 0.82353636076 to 1e-11
    assert right == pytest.approx(0.823536373, abs=1e-6)
    assert right == pytest.approx(left, rel=1e-12)


def test_mirror_symmetry_swaps_sides():
    # outcome(-th0; u1, u2) = -outcome(th0; u2, u1): the left slope equals the mirrored right one
    left = outcome_derivative("touchdown", 0.0, (2.0, 0.5), side=-1)
    right_mirror = outcome_derivative("touchdown", 0.0, (0.5, 2.0), side=1)
    assert left == pytest.approx(right_mirror, rel=1e-9)


def test_liftoff_jump_branches_at_zero():
    right = outcome_sensitivity("liftoff", 0.0, LO_U, direction=(1, 0, 0, 0))
    left = outcome_sensitivity("liftoff", 0.0, LO_U, direction=(-1, 0, 0, 0))
    # the branches' one-sided limits are MODEL.md's jump (the point itself has th_f = 0)
    assert right.continued and left.continued
    assert right.outcome == pytest.approx(-0.006532702, abs=1e-9)
    assert left.outcome == pytest.approx(0.026283950, abs=1e-9)
    assert simulate("liftoff", 0.0, LO_U).outcome == pytest.approx(0.0, abs=1e-12)
    assert right.mode_sequence == (ContactMode.GROUND, ContactMode.LEFT, ContactMode.AIR)
    assert left.mode_sequence == (ContactMode.GROUND, ContactMode.RIGHT, ContactMode.AIR)

    def f(x: float) -> float:
        return simulate("liftoff", x, LO_U).outcome

    for sens, side in ((right, 1), (left, -1)):
        fd = extrapolated(f, 0.0, side, h0=1e-2, levels=6, noise=SIM_NOISE)
        assert sens.d_theta0 == pytest.approx(fd.derivative,
                                              abs=fd.tolerance(_own(sens.d_theta0)))
        assert sens.outcome == pytest.approx(fd.limit, abs=1e-10)
    assert left.d_theta0 == pytest.approx(0.27253, abs=1e-5)
    assert right.d_theta0 == pytest.approx(0.37681, abs=1e-5)


def test_liftoff_without_inputs_is_continuous_at_zero():
    right = outcome_sensitivity("liftoff", 0.0, (0.0, 0.0, 0.0), direction=(1, 0, 0, 0))
    left = outcome_sensitivity("liftoff", 0.0, (0.0, 0.0, 0.0), direction=(-1, 0, 0, 0))
    assert not right.continued and not left.continued  # zero-length single stance
    assert right.outcome == pytest.approx(0.0, abs=1e-12)

    def f(x: float) -> float:
        return simulate("liftoff", x, (0.0, 0.0, 0.0)).outcome

    for sens, side in ((right, 1), (left, -1)):
        fd = extrapolated(f, 0.0, side, h0=1e-2, levels=6, noise=SIM_NOISE)
        assert sens.d_theta0 == pytest.approx(fd.derivative,
                                              abs=fd.tolerance(_own(sens.d_theta0)))


def test_saltation_matrix_of_a_bouncing_ball():
    # y = (height, velocity), guard height, reset v -> -e v: the textbook saltation matrix
    e, v = 0.5, -2.0
    f_minus = np.array([v, -1.0])
    f_plus = np.array([-e * v, -1.0])
    dr = np.diag([1.0, -e])
    xi = saltation_matrix(dr, f_minus, f_plus, np.array([1.0, 0.0]))
    expected = np.array([[-e, 0.0], [(1.0 + e) * (-1.0) / v, -e]])
    np.testing.assert_allclose(xi, expected, rtol=1e-15)
    with pytest.raises(SimulationError, match="grazing"):
        saltation_matrix(dr, np.array([0.0, -1.0]), f_plus, np.array([1.0, 0.0]))


def test_argument_errors():
    with pytest.raises(InvalidInputError, match="side"):
        outcome_derivative("touchdown", 0.1, TD_U, side=0)
    with pytest.raises(InvalidInputError, match="direction"):
        outcome_sensitivity("touchdown", 0.1, TD_U, direction=(1, 0, 0, 0, 0))
    with pytest.raises(InvalidInputError, match="theta0"):
        outcome_sensitivity("touchdown", 0.3, TD_U)
    with pytest.raises(InvalidInputError, match="input"):
        outcome_sensitivity("touchdown", 0.1, TD_U).d_input("u3")


# --- policy and value: Theorem 1, Eqs. (12)-(13) ------------------------------------------------
def _distance(problem, theta0: float, r) -> float:
    """The solver's distance from the optimum of its acting decision: the Newton step
    |c'(u)| / c''(u) left at it (c' exact, c'' by central differences of c'); 0 on a bound."""
    d = r.active
    if d is None or r.bound is not None:
        return 0.0

    def slope(u: float) -> float:
        s = outcome_sensitivity(problem.maneuver, theta0, problem.inputs({**r.policy, d: u}),
                                params=problem.params, options=problem.options)
        return problem.outcome_slope(s.outcome) * s.d_input(d) + 2.0 * problem.alpha(d) * u

    u, h = r.policy[d], 1e-4
    return abs(slope(u)) / abs((slope(u + h) - slope(u - h)) / (2.0 * h))


def _fd_optimal(problem, theta0: float, side: int, h0: float):
    """One-sided extrapolated derivatives of the solver's value and (active) policy, with
    their errors (the policy's samples off by :func:`_distance`, the value's by rtol)."""
    cache: dict[float, object] = {}

    def res(t: float):
        if t not in cache:
            cache[t] = optimal_policy(problem, t)
        return cache[t]

    value = extrapolated(lambda t: res(t).value, theta0, side, h0=h0, levels=4, noise=SIM_NOISE)
    policy = {
        d: extrapolated(lambda t, d=d: res(t).policy[d], theta0, side, h0=h0, levels=4,
                        noise=lambda t, _: _distance(problem, t, res(t)))
        for d in problem.decisions
    }
    return value, policy


def test_touchdown_policy_and_value_smooth_point():
    problem = get_problem("touchdown")
    d = one_sided_derivatives(problem, 0.03)
    assert d.branches == ("AIR->LEFT->GROUND", "AIR->LEFT->GROUND")
    value, policy = _fd_optimal(problem, 0.03, 1, 4e-3)
    for k in (0, 1):
        assert d.value[k] == pytest.approx(value.derivative, abs=value.tolerance(_own(d.value[k])))
        assert d.policy["u1"][k] == pytest.approx(policy["u1"].derivative,
                                                  abs=policy["u1"].tolerance())
        assert d.policy["u2"][k] == pytest.approx(0.0, abs=1e-9)  # u2 does not act
    # Newton's polish on the branch lands on the solver's optimum (its value is flat in u*)
    at = optimal_policy(problem, 0.03)
    assert d.value_limits[1] == pytest.approx(at.value, abs=1e-13)
    assert d.policy_limits["u1"][1] == pytest.approx(at.policy["u1"], abs=1e-6)
    # the envelope theorem: dV/dth0 = D_th0 c = 2 (th_f - th*) d th_f/d th0 at fixed u*
    sens = outcome_sensitivity("touchdown", 0.03, problem.inputs(
        {"u1": d.policy_limits["u1"][1]}))
    assert d.value[1] == pytest.approx(2 * (sens.outcome + 0.1) * sens.d_theta0, rel=1e-9)


def test_touchdown_policy_kink_value_c1_at_zero():
    problem = get_problem("touchdown")
    d = one_sided_derivatives(problem, 0.0)
    assert d.branches == ("AIR->RIGHT->GROUND", "AIR->LEFT->GROUND")
    # MODEL.md Sec. 6: u1* ~ 18.2 th0 for th0 > 0, u2* ~ 1.82 th0 for th0 < 0, V'(0) = 0.1647
    assert d.policy["u1"] == pytest.approx((0.0, 18.2), abs=0.05)
    assert d.policy["u2"] == pytest.approx((1.82, 0.0), abs=0.005)
    assert d.value[0] == pytest.approx(d.value[1], rel=1e-9)  # C^1: no first-order kink
    assert d.value[1] == pytest.approx(0.1647, abs=1e-4)
    value, policy = _fd_optimal(problem, 0.0, 1, 1e-3)
    assert d.value[1] == pytest.approx(value.derivative, abs=value.tolerance(_own(d.value[1])))
    assert d.policy["u1"][1] == pytest.approx(policy["u1"].derivative,
                                              abs=policy["u1"].tolerance())


def test_liftoff_policy_jump_value_kink():
    problem = get_problem("liftoff")

    def branch(t: float) -> str:
        return optimal_policy(problem, t).branch

    lo, hi = locate_switch(branch, 5e-4, 1e-3, tol=1e-9)
    ts = 0.5 * (lo + hi)
    d = one_sided_derivatives(problem, ts)
    assert d.branches == ("GROUND->RIGHT->AIR", "GROUND->LEFT->AIR")
    # the policy jumps (about -0.077 to +0.077), the value is continuous with a kink
    left_u, right_u = d.policy_limits["u12"]
    assert left_u == pytest.approx(-0.077, abs=2e-3) and right_u == pytest.approx(0.077, abs=2e-3)
    assert d.value_limits[0] == pytest.approx(d.value_limits[1], abs=1e-10)
    assert abs(d.value[0] - d.value[1]) > 1e-4
    for side, k in ((-1, 0), (1, 1)):
        value, _ = _fd_optimal(problem, ts + side * 2e-9, side, 1e-4)
        assert d.value[k] == pytest.approx(value.derivative,
                                           abs=value.tolerance(_own(d.value[k])))


def test_variant_value_jump_limits():
    d = one_sided_derivatives(get_problem("liftoff-variant"), 0.0)
    # MODEL.md Sec. 6: value 4.000e-4 from the left, ~6.63e-5 from the right
    assert d.value_limits[0] == pytest.approx(4.0e-4, abs=1e-9)
    assert d.value_limits[1] == pytest.approx(6.63e-5, abs=1e-7)
    # left of 0 (right stance) u2 sits on its lower bound 0 and u1 does not act: both slopes
    # vanish (u1's is ~1e-9, the noise of differencing an inactive decision)
    assert "u2" in d.at_bound[0] and d.policy["u2"][0] == 0.0
    assert abs(d.policy["u1"][0]) < 1e-6


@pytest.mark.parametrize("direction", [(0, 0, 0, 1), (0, 0, 0, -1), (1, 0, 0, -50), (1, 0, 0, -5)])
def test_bouligand_derivative_in_a_general_direction(direction):
    # at the simultaneous liftoff the torque u12 also picks the branch: the B-derivative along
    # v is the branch gradient . v, checked by a one-sided difference along v itself
    v = np.array(direction, dtype=float)
    sens = outcome_sensitivity("liftoff", 0.0, LO_U, direction=v)

    def f(s: float) -> float:
        return simulate("liftoff", s * v[0], np.array(LO_U) + s * v[1:]).outcome

    fd = extrapolated(f, 0.0, 1, h0=1e-3 / np.max(np.abs(v)), levels=6, noise=SIM_NOISE)
    assert sens.outcome == pytest.approx(fd.limit, abs=1e-10)
    b = float(sens.gradient @ v)
    assert b == pytest.approx(fd.derivative, abs=fd.tolerance(_own(b)))
    trajectory = simulate("liftoff", 1e-7 * v[0], np.array(LO_U) + 1e-7 * v[1:])
    assert sens.mode_sequence == trajectory.mode_sequence


def test_policy_derivative_argument_errors():
    problem = get_problem("touchdown")
    with pytest.raises(InvalidInputError, match="problem"):
        one_sided_derivatives("touchdown", 0.0)
    with pytest.raises(InvalidInputError, match="probe"):
        one_sided_derivatives(problem, 0.0, probe=0.0)
    with pytest.raises(InvalidInputError, match="theta0"):
        one_sided_derivatives(problem, 0.26)
