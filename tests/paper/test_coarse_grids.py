"""Nonsmooth points located correctly from any grid, however coarse.

The grid only tells the analysis *where to look*: labels (mode order, acting input, bound) are
bisected between grid angles, so 2 angles (plus the 0 every grid holds when it straddles it) must
give the same points as a fine grid, each inside its bracket, and the bracket must hold the true
point. True points, found here without the analysis:

- contact kink/jump (fixed inputs; touchdown policy; the variant's jump): th0 = 0 exactly, where
  the feet touch down or lift off together (MODEL.md Sec. 6);
- a bound reached or left: where the *free* optimum (the bound moved out of the way) crosses the
  bound value, by secants of the optimiser's policy at +-1e-5 and +-1e-6 around it, Richardson
  extrapolated (the policy is smooth there; known to ~1e-11: optimiser's u ~1e-10 over slopes
  of 10-35);
- the liftoff branch switch: the root of the difference of the two branches' optimal values
  (smooth, slope 7e-3, noise ~1e-16: known to ~1e-13).

No point of these problems is hidden from a 2-angle grid: 0 is always a grid angle, probes just
beyond the ends see a point at an end, and no label returns to itself between two angles (each
bound is reached or left once, so a grid interval never holds a change that cancels out). So
every 2-angle report below must equal the fine one, none is skipped.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from scipy.optimize import brentq

from biped_opt.analysis.switches import LOCATE_TOL
from biped_opt.paper.biped import BipedParams, theta0_limit
from biped_opt.paper.nonsmooth import find_nonsmooth_fixed, find_nonsmooth_optimal
from biped_opt.paper.problems import liftoff_problem, liftoff_variant_problem, touchdown_problem
from biped_opt.paper.solve import optimal_policy
from biped_opt.paper.sweeps import sweep_grid
from biped_opt.piecewise import theta_grid

# --- grids ---------------------------------------------------------------------------------------
RANGES = [(-0.25, 0.25), (-0.05, 0.2), (0.01, 0.2), (-0.2, -0.01), (0.0, 0.2), (-0.2, 0.0),
          (-1e-3, 0.25), (-0.25, 1e-9), (-1e-9, 1e-9), (-0.2, 0.1999)]


@pytest.mark.parametrize("num", range(2, 13))
@pytest.mark.parametrize(("lo", "hi"), RANGES)
def test_grids_keep_both_ends_and_hold_zero(num, lo, hi):
    for grid in (theta_grid(lo, hi, num), sweep_grid("touchdown", lo, hi, num)):
        assert grid[0] == lo and grid[-1] == hi
        assert np.all(np.diff(grid) > 0)  # strictly increasing: no duplicates
        assert (0.0 in grid) == (lo <= 0.0 <= hi)
        # 0 takes an interior angle's place, or is added when only the ends are near it
        assert grid.size == num or (grid.size == num + 1 and lo < 0.0 < hi)


@pytest.mark.parametrize("maneuver", ["touchdown", "liftoff"])
@pytest.mark.parametrize("num", range(2, 7))
def test_default_grids_span_the_valid_range(maneuver, num):
    limit = theta0_limit(maneuver)
    grid = sweep_grid(maneuver, num=num)
    assert grid[0] == -limit and grid[-1] == limit and 0.0 in grid
    assert np.all(np.diff(grid) > 0)


# --- brackets ------------------------------------------------------------------------------------
#: events within 1e-9 of their guard are simultaneous (MODEL.md Sec. 3), so the contact points
#: are bracketed by that band, each edge bisected to LOCATE_TOL. Touchdown: at the first touchdown
#: the feet's heights differ by 2 w sin(th0), so the band is |th0| <= 1e-9 / (2 w) = 2e-9.
#: Liftoff: the feet's normal forces differ by ~10.2 th0 (measured band |th0| <= 9.77e-11).
BAND = {
    "touchdown": 2 * (1e-9 / (2 * BipedParams().w) + LOCATE_TOL),
    "liftoff": 2 * (9.8e-11 + LOCATE_TOL),
}


def _check_brackets(report, truths, maneuver):
    """Every point: located inside its bracket, which holds its true point and is as narrow as
    bisection (LOCATE_TOL), or the simultaneous band for a contact point (true point 0).
    Returns the set of (quantity, input, kind, true point) found."""
    found = set()
    for p in report.points:
        a, b = p.bracket
        assert a <= p.theta0 <= b, p
        near = [t for t in truths if abs(t - p.theta0) < 1e-6]
        assert len(near) == 1, f"a point where none is known: {p}"
        true = near[0]
        if true == 0.0:
            assert p.theta0 == 0.0 and b - a <= BAND[maneuver], p
        else:
            assert b - a <= LOCATE_TOL, p
            # the bracket holds the true point, known to ~1e-11 (module docstring)
            assert a - 2e-11 <= true <= b + 2e-11, (p, true)
        found.add((p.quantity, p.input, p.kind, true))
    return found


def _expected(fine, lo, hi):
    """The fine grid's points whose true location lies in [lo, hi]."""
    return {k for k in fine if lo <= k[3] <= hi}


# --- fixed inputs: one point at 0, a kink (touchdown) or a jump (liftoff) ------------------------
#: MODEL.md Sec. 6: one-sided slopes (10 digits) and limits (9 digits) at 0. The slopes are
#: extrapolated from ladders of outcomes accurate to ~1e-11 (measured within 4e-10 of MODEL.md;
#: 1e-8 is 1e-7 of the kink's size); the limits are outcomes, correct to 1e-9 (MODEL.md Sec. 7).
FIXED = {
    "touchdown": ("kink", 0.7962438835, 0.7143664519, 1e-8),
    "liftoff": ("jump", 0.026283950, -0.006532702, 1e-9),
}
FIXED_CASES = [(None, None, n) for n in (2, 3, 4, 5)] + [
    (-0.05, 0.2, 2), (0.0, 0.2, 2), (-0.2, 0.0, 3), (-1e-3, 0.25, 2), (-0.25, 1e-9, 2),
    (-1e-9, 1e-9, 2),  # inside the touchdown band: one label throughout, the probes see it
    (0.01, 0.2, 2), (-0.2, -1e-3, 3), (1e-9, 0.2, 2),  # 0 outside the range: no point
]


@cache
def _fine_fixed(maneuver):
    report = find_nonsmooth_fixed(maneuver, sweep_grid(maneuver, num=401))
    return _check_brackets(report, [0.0], maneuver)


@pytest.mark.parametrize("maneuver", sorted(FIXED))
@pytest.mark.parametrize(("lo", "hi", "num"), FIXED_CASES)
def test_fixed_input_points_equal_the_fine_grids(maneuver, lo, hi, num):
    kind, left, right, tol = FIXED[maneuver]
    assert _fine_fixed(maneuver) == {("outcome", None, kind, 0.0)}
    grid = sweep_grid(maneuver, lo, hi, num)
    report = find_nonsmooth_fixed(maneuver, grid)
    assert _check_brackets(report, [0.0], maneuver) == _expected(
        _fine_fixed(maneuver), grid[0], grid[-1])
    for p in report.points:
        assert p.left == pytest.approx(left, abs=tol)
        assert p.right == pytest.approx(right, abs=tol)


# --- optimal problems ----------------------------------------------------------------------------
def _bound_crossing(problem, decision, which, near):
    """th0 where the free optimum of ``decision`` meets its ``which`` bound (see docstring)."""
    lo, hi = problem.bound(decision)
    width = hi - lo
    end = hi if which == "upper" else lo
    free = problem.with_bounds(decision, *((lo, hi + width) if which == "upper"
                                          else (lo - width, hi)))

    def secant(centre, d):
        ua, ub = (optimal_policy(free, centre + s * d).policy[decision] for s in (-1, 1))
        return centre - d + (end - ua) * 2 * d / (ub - ua)

    # a secant centred delta off the crossing errs by ~(u''/u') (delta^2 - d^2) / 2: centre it
    # first, then extrapolate the d^2 term away
    centre = secant(near, 1e-5)
    fine, coarse = secant(centre, 1e-6), secant(centre, 1e-5)
    return fine + (fine - coarse) / 99.0


def _branch_switch(problem, near):
    """th0 where two branches' optimal values cross (the global minimum changes branch)."""
    def gap(th):
        values = {c.branch: c.value for c in optimal_policy(problem, th).candidates}
        return values["GROUND->RIGHT->AIR"] - values["GROUND->LEFT->AIR"]

    return brentq(gap, near - 1e-6, near + 1e-6, xtol=1e-15)


PROBLEMS = {
    "touchdown": (touchdown_problem, lambda p: [0.0, _bound_crossing(p, "u1", "upper", 0.0567)]),
    "liftoff": (liftoff_problem, lambda p: [_branch_switch(p, 7.555e-4)]),
    "liftoff-variant": (liftoff_variant_problem, lambda p: [
        _bound_crossing(p, "u2", "upper", -0.1787), _bound_crossing(p, "u2", "lower", -0.04556),
        0.0, _bound_crossing(p, "u1", "upper", 0.02867)]),
}
OPTIMAL_CASES = [("touchdown", None, None, n) for n in (2, 3, 4, 5)] + [
    ("touchdown", -0.05, 0.2, 2), ("touchdown", 0.01, 0.2, 2), ("touchdown", -0.2, 0.0, 3),
    ("touchdown", -1e-9, 1e-9, 2), ("touchdown", 0.05, 0.06, 2),
] + [("liftoff", None, None, n) for n in (2, 3, 4, 5)] + [
    ("liftoff", -0.05, 0.2, 2), ("liftoff", 0.01, 0.3, 2), ("liftoff", 7.5e-4, 7.6e-4, 2),
    ("liftoff", -1e-3, 7.5e-4, 2),  # ends just short of the switch: no point
    ("liftoff-variant", None, None, 2), ("liftoff-variant", -0.1, 0.2, 3),
]


@cache
def _optimal(name):
    """The problem, its true points and the set of points from 41 angles."""
    make, truths = PROBLEMS[name]
    problem = make()
    true = truths(problem)
    fine = find_nonsmooth_optimal(problem, sweep_grid(problem.maneuver, num=41))
    return problem, true, _check_brackets(fine, true, problem.maneuver.value)


def _at(points, true):
    return {k[:3] for k in points if k[3] == true}


def test_fine_optimal_reports_hold_model_points():
    """The reference the coarse grids are held to: MODEL.md Sec. 6's points, each located (a
    bound reached kinks outcome and policy; the value, C^1 there, jumps in curvature)."""
    at_bound = {("outcome", None, "kink"), ("value", None, "second-derivative")}
    _, (zero, saturation), fine = _optimal("touchdown")
    assert _at(fine, zero) == {("outcome", None, "second-derivative"),
                               ("value", None, "second-derivative"),
                               ("policy", "u1", "kink"), ("policy", "u2", "kink")}
    assert _at(fine, saturation) == at_bound | {("policy", "u1", "kink")}
    _, (switch,), fine = _optimal("liftoff")
    assert _at(fine, switch) == {("outcome", None, "jump"), ("policy", "u12", "jump"),
                                 ("value", None, "kink")}
    _, (u2_upper, u2_lower, zero, u1_upper), fine = _optimal("liftoff-variant")
    for true, decision in ((u2_upper, "u2"), (u2_lower, "u2"), (u1_upper, "u1")):
        assert _at(fine, true) == at_bound | {("policy", decision, "kink")}
    assert ("value", None, "jump") in _at(fine, zero)


@pytest.mark.parametrize(("name", "lo", "hi", "num"), OPTIMAL_CASES)
def test_optimal_points_from_a_coarse_grid_equal_the_fine_grids(name, lo, hi, num):
    problem, true, fine = _optimal(name)
    grid = sweep_grid(problem.maneuver, lo, hi, num)
    report = find_nonsmooth_optimal(problem, grid)
    found = _check_brackets(report, true, problem.maneuver.value)
    assert found == _expected(fine, grid[0], grid[-1]), report.table()
