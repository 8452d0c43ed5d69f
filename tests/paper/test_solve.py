"""Optimal policy and value (Eqs. (4)-(6)): MODEL.md R5, global bracketing, bounds, counters.

Independent checks: MODEL.md R5 (an independent solve_ivp reference), brute-force grids of
simulations (never the solver's own grid), direct simulations around the optimum, and SciPy's
plain bounded Brent, which the discontinuous liftoff cost defeats.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from biped_opt.errors import InvalidInputError
from biped_opt.paper.biped import ContactMode, simulate, simulate_batch
from biped_opt.paper.problems import liftoff_problem, liftoff_variant_problem, touchdown_problem
from biped_opt.paper.solve import optimal_policy, optimal_sweep

TD = touchdown_problem()
LO = liftoff_problem()


def _cost(problem, theta0, u):
    return problem.cost(simulate(problem.maneuver, theta0, u).outcome, u)


def test_r5_touchdown_optimum():
    r = optimal_policy(TD, 0.05)
    # MODEL.md R5; values to 1e-8 and inputs to 1e-6 as the acceptance asks
    assert r.value == pytest.approx(0.0194158739483, abs=1e-8)
    assert r.policy["u1"] == pytest.approx(1.2776719, abs=1e-6)
    assert r.policy["u2"] == 0.0 and r.active == "u1" and r.bound is None
    assert r.modes == (ContactMode.AIR, ContactMode.LEFT, ContactMode.GROUND)
    assert r.branch == "AIR->LEFT->GROUND" and len(r.event_times) == 2
    assert r.success and r.status == 0 and r.nsim > 65 and r.nfev > r.nsim and r.nit > 0
    assert r.fun == r.value and r.x.tolist() == [r.policy["u1"], 0.0]


def test_only_the_single_stance_input_acts():
    # th0 > 0: left stance, u2 cannot move th_f; th0 < 0: right stance, u1 cannot
    assert simulate("touchdown", 0.05, (1.0, 0.0)).outcome == simulate(
        "touchdown", 0.05, (1.0, 1.5)).outcome
    assert simulate("touchdown", -0.05, (0.0, 1.0)).outcome == simulate(
        "touchdown", -0.05, (-0.5, 1.0)).outcome
    assert optimal_policy(TD, -0.05).active == "u2"


def test_touchdown_at_zero_has_no_single_stance_and_policy_zero():
    outcomes = {simulate("touchdown", 0.0, u).outcome for u in
                [(0, 0), (1.5, 0), (0, 1.5), (-0.5, -0.5), (1.5, 1.5)]}
    assert outcomes == {0.0}  # AIR -> GROUND: no input acts, th_f = 0 exactly
    r = optimal_policy(TD, 0.0)
    assert r.policy == {"u1": 0.0, "u2": 0.0} and r.active is None
    assert r.value == pytest.approx(0.01, rel=1e-12)  # (0 - th*)^2
    assert r.modes == (ContactMode.AIR, ContactMode.GROUND) and r.success


def test_interior_optimum_is_a_local_minimum():
    r = optimal_policy(TD, 0.05)
    for du in (-1e-4, 1e-4):
        # c'' ~ 6e-4: the cost rises ~3e-12 there, far above the ~1e-14 simulation noise
        assert _cost(TD, 0.05, (r.policy["u1"] + du, 0.0)) > r.value + 1e-12


@pytest.mark.parametrize("theta0", [0.0, 7e-4, 2e-3])
def test_global_bracketing_beats_plain_brent_on_liftoff(theta0):
    r = optimal_policy(LO, theta0)
    u12 = np.linspace(-0.5, 0.5, 1001)
    u = np.column_stack([np.full_like(u12, 1.5), np.full_like(u12, 3.0), u12])
    brute = simulate_batch("liftoff", np.full(u12.size, theta0), u)
    # a 1e-3 grid misses the minimum by at most ~c'' (5e-4)^2 ~ 1e-8
    assert r.value <= LO.cost(brute.outcome, u).min() + 1e-12
    plain = minimize_scalar(lambda x: _cost(LO, theta0, (1.5, 3.0, x)), bounds=(-0.5, 0.5),
                            method="bounded", options={"xatol": 1e-10})
    assert r.value < plain.fun - 1e-7  # plain Brent stops on the worse branch here


def test_liftoff_optimum_changes_branch_near_7_55e_4():
    before, after = optimal_policy(LO, 7.4e-4), optimal_policy(LO, 7.7e-4)
    assert before.branch == "GROUND->RIGHT->AIR" and after.branch == "GROUND->LEFT->AIR"
    assert before.policy["u12"] == pytest.approx(-0.077, abs=2e-3)
    assert after.policy["u12"] == pytest.approx(0.077, abs=2e-3)
    assert {c.branch for c in before.candidates} >= {before.branch, after.branch}
    # continuous value: over 3e-5 in th0 at slopes below 5e-3 it moves less than 1.5e-7
    assert abs(before.value - after.value) < 1.5e-7


def test_saturated_input_sits_exactly_on_its_bound():
    r = optimal_policy(TD, 0.07)
    assert r.policy["u1"] == 1.5 and r.bound == "upper"
    # the cost falls towards the bound: 1.5 is the constrained minimum (KKT)
    assert _cost(TD, 0.07, (1.499, 0.0)) > r.value
    inner = optimal_policy(TD, 0.05)
    assert inner.bound is None and inner.policy["u1"] < 1.5


def test_variant_value_at_and_around_zero():
    va = liftoff_variant_problem()
    at0 = optimal_policy(va, 0.0)
    assert at0.policy == {"u1": 0.0, "u2": 0.0} and at0.value == pytest.approx(4e-4, rel=1e-12)
    left = optimal_policy(va, -1e-7)
    assert left.active == "u2" and left.bound == "lower" and left.policy["u2"] == 0.0
    right = optimal_policy(va, 1e-7)
    assert right.active == "u1" and right.bound is None
    # brute force over u1 (a 5e-5 grid misses the minimum by < 1e-12): nothing is better
    u1 = np.linspace(2.4, 2.6, 4001)
    u = np.column_stack([u1, np.zeros_like(u1), np.zeros_like(u1)])
    brute = simulate_batch("liftoff", np.full(u1.size, 1e-7), u)
    assert right.value <= va.cost(brute.outcome, u).min() + 1e-15
    # MODEL.md Sec. 6 quotes 6.634e-5 from the right; we (and the brute force) get 6.6330e-5,
    # so its last digit is checked to 2e-8 only (the limit is within 1e-10 of this value)
    assert right.value == pytest.approx(6.634e-5, abs=2e-8)
    assert right.value == pytest.approx(6.63297e-5, abs=1e-9)


def test_params_override_changes_the_model():
    from biped_opt.paper.biped import BipedParams

    stiff = optimal_policy(TD, 0.05, params=BipedParams(k=40.0))
    assert stiff.problem.params.k == 40.0 and TD.params.k == 27.0
    assert abs(stiff.value - optimal_policy(TD, 0.05).value) > 1e-6


def test_sweep_matches_single_solves_and_reports_progress():
    calls = []
    grid = [-0.05, 0.0, 0.05]
    results = optimal_sweep(TD, grid, callback=lambda done, total: calls.append((done, total)))
    assert calls[-1] == (3, 3) and len(calls) == 3
    for th, r in zip(grid, results):
        single = optimal_policy(TD, th)
        assert r.theta0 == th and r.branch == single.branch
        assert r.value == pytest.approx(single.value, abs=1e-14)
        for name in ("u1", "u2"):
            assert r.policy[name] == pytest.approx(single.policy[name], abs=1e-9)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: optimal_policy(TD, math.nan), "theta0"),
        (lambda: optimal_policy(TD, 0.3), "theta0"),
        (lambda: optimal_policy("touchdown", 0.1), "problem"),
        (lambda: optimal_policy(TD, 0.1, grid_points=2), "grid_points"),
        (lambda: optimal_policy(TD, 0.1, xatol=-1.0), "xatol"),
        (lambda: optimal_sweep(TD, [[0.1]]), "theta0"),
        (lambda: optimal_policy(TD, 0.1, params={"k": 1.0}), "params"),
    ],
)
def test_bad_arguments(call, match):
    with pytest.raises(InvalidInputError, match=match):
        call()
