"""Nonsmooth tables of any system (biped_opt.analysis.nonsmooth) against SYSTEMS.md's numbers."""

from __future__ import annotations

import dataclasses
import json
import math
from types import SimpleNamespace

import pytest

from biped_opt.analysis.nonsmooth import WORDS, find_nonsmooth, find_nonsmooth_optimal, s_grid
from biped_opt.analysis.switches import (
    LOCATE_TOL,
    Evaluator,
    Sample,
    bound_labels,
    bound_relocation,
    describe_change,
)
from biped_opt.control.problems import Problem, get_problem
from biped_opt.control.solve import compiled_for, optimal_policy
from biped_opt.paper.nonsmooth import find_nonsmooth_fixed
from biped_opt.paper.nonsmooth import find_nonsmooth_optimal as biped_find_optimal
from biped_opt.paper.problems import get_problem as biped_problem


def test_rocking_bar_has_its_five_jumps_each_with_its_impact_orders() -> None:
    """SYSTEMS.md Sec. 2: jumps at 0 (limits -+0.1988738) and at |th0| = 0.0961485, 0.2646950
    (a third impact meets the apex). Locations to 1e-6 and limits to 1e-6: the table's numbers
    are given to 7 digits there; the table locates to 1e-10."""
    report = find_nonsmooth("rocking_bar", "drop")
    where = [p.theta0 for p in report.points]
    assert where == pytest.approx([-0.2646950, -0.0961485, 0.0, 0.0961485, 0.2646950], abs=1e-6)
    assert all(p.kind == "jump" for p in report.points)
    at_zero = report.points[2]
    assert at_zero.theta0 == 0.0
    assert at_zero.limits == pytest.approx((0.1988738, -0.1988738), abs=1e-6)
    assert at_zero.at == 0.0  # one simultaneous impact: exactly no spin
    third = report.points[3]
    assert third.limits[1] == pytest.approx(2.4098, abs=1e-4)
    assert "air->air[left]->air[right]->air[left] | air->air[left]->air[right]" in third.cause


@pytest.mark.parametrize(("system", "left", "right"), [
    ("walker3_coupled", 0.8732676633, 0.8395968313),
])
def test_coupled_walker_kinks_at_zero_with_the_measured_slopes(system: str, left: float,
                                                               right: float) -> None:
    """SYSTEMS.md Sec. 3, n = 3, u = (2, 1, 0.5): slopes 0.8732676633 | 0.8395968313. To 1e-7:
    the extrapolated one-sided slopes carry ~1e-9 (integration 1e-12 over steps >= 1e-6)."""
    report = find_nonsmooth(system, "touchdown", {"u1": 2.0, "u2": 1.0, "u3": 0.5})
    (point,) = report.points
    assert point.theta0 == 0.0 and point.kind == "kink"
    assert point.derivatives == pytest.approx((left, right), abs=1e-7)


@pytest.mark.parametrize(("system", "maneuver", "inputs"), [
    ("walker3_decoupled", "touchdown", {"u1": 2.0, "u2": 1.0, "u3": 0.5}),
    ("walker2_decoupled", "touchdown", {"u1": 2.0, "u2": 0.5}),
    ("walker2_decoupled", "liftoff", {"u1": 1.5, "u2": 3.0}),
])
def test_decoupled_walker_has_no_kink_or_jump_at_zero(system: str, maneuver: str,
                                                      inputs: dict[str, float]) -> None:
    """Pace & Burden's decoupled law: the outcome is C^1 at simultaneous contact, so the table
    holds no kink or jump at 0 (the mode order still changes there)."""
    report = find_nonsmooth(system, maneuver, inputs)
    assert not [p for p in report.points
                if abs(p.theta0) < 1e-6 and p.kind in ("kink", "jump")]


def test_biped_table_is_the_biped_engines_table() -> None:
    """The library biped through the generic path gives the hand-written path's table."""
    generic = find_nonsmooth("biped", "liftoff", {"u1": 1.5, "u2": 3.0}, num=101)
    reference = find_nonsmooth_fixed("liftoff", None, (1.5, 3.0, 0.0), num=101)
    assert [(p.kind, p.theta0) for p in generic.points] == \
        [(p.kind, p.theta0) for p in reference.points]
    for a, b in zip(generic.points, reference.points):
        assert a.limits == pytest.approx(b.limits, abs=1e-9)


def test_optimal_table_of_the_biped_touchdown_problem_matches_the_biped_engine() -> None:
    """Same problem, same grid: the same kinks and jumps of outcome, policy and value at the
    same places (to 2 LOCATE_TOL: both bisect to it, bound points on the sign of the same
    Karush-Kuhn-Tucker slope from two sensitivity integrations)."""
    grid = [-0.25 + 0.025 * k for k in range(21)]
    generic = find_nonsmooth_optimal(get_problem("biped", "touchdown"), grid)
    reference = biped_find_optimal(biped_problem("touchdown"), grid)
    key = sorted((p.quantity, p.input or "", p.kind) for p in reference.points)
    assert sorted((p.quantity, p.input or "", p.kind) for p in generic.points) == key
    for a in generic.points:
        (b,) = [p for p in reference.points if (p.quantity, p.input, p.kind) ==
                (a.quantity, a.input, a.kind) and abs(p.theta0 - a.theta0) < 1e-6]
        assert a.theta0 == pytest.approx(b.theta0, abs=2 * LOCATE_TOL)


def test_optimal_table_of_the_decoupled_walker_is_smooth_at_zero() -> None:
    """The control experiment on optimal control: coupled touchdown value and policy are not
    C^1 at 0, decoupled (inputs act whenever their foot is down) are."""
    grid = [-0.2 + 0.02 * k for k in range(21)]
    coupled = find_nonsmooth_optimal(get_problem("biped", "touchdown"), grid)  # = walker2
    decoupled = find_nonsmooth_optimal(get_problem("walker2_decoupled", "touchdown"), grid)
    assert [p for p in coupled.points if p.theta0 == 0.0 and p.kind in ("kink", "jump")]
    assert not [p for p in decoupled.points
                if abs(p.theta0) < 1e-6 and p.kind in ("kink", "jump")]


def test_the_edge_of_a_failed_region_is_a_failure_boundary_not_a_kink() -> None:
    """Three-leg walker pushing off with u = 2 on every leg: beyond |s| = 0.2617480590 the body
    reaches its apex with a foot still down (status APEX_IN_CONTACT). That edge is reported as a
    failure boundary naming the status, with NaN (JSON null) on the failing side, never as a
    kink or jump; the jump at 0 is still found. Located to the engine's 1e-10 bracket."""
    report = find_nonsmooth("walker3_coupled", "liftoff",
                            {"u1": 2.0, "u2": 2.0, "u3": 2.0, "u_body": 0.0}, num=41)
    kinds = [(p.kind, round(p.theta0, 6)) for p in report.points]
    assert kinds == [("failure", -0.261748), ("jump", 0.0), ("failure", 0.261748)]
    for p, failing in ((report.points[0], 0), (report.points[2], 1)):
        assert "APEX_IN_CONTACT" in p.cause and "failure boundary" in p.cause
        assert p.labels[failing] == "FAILED:APEX_IN_CONTACT"
        assert math.isnan(p.limits[failing]) and math.isfinite(p.limits[1 - failing])
        assert p.location_error <= LOCATE_TOL
        assert p.bracket[0] <= p.theta0 <= p.bracket[1]
    # mirror images of each other: the same edge at -s and s, to the brackets' widths
    assert report.points[0].theta0 == pytest.approx(-report.points[2].theta0, abs=2 * LOCATE_TOL)
    # ... and the limits there, up to the slope times that distance plus the limits' own
    # extrapolation error (~1e-10: samples at rtol 1e-11, weights of order 10), SAFETY 10
    slope = abs(report.points[0].derivatives[1])
    assert report.points[0].limits[1] == pytest.approx(
        -report.points[2].limits[0], abs=10 * (slope * 2 * LOCATE_TOL + 1e-10))
    assert json.loads(report.to_json())["points"][0]["limits"][0] is None


# --- the engine's bound relocation and causes, on stand-in samples (no simulation) -------------
def _optimum(branch: str, active: str | None, bound: str | None) -> Sample:
    """A sample as an optimum labels it; its problem holds every decision in [0, 3]."""
    problem = SimpleNamespace(bound=lambda d: (0.0, 3.0))
    result = SimpleNamespace(problem=problem, candidates=(), policy={})
    return Sample(label=(branch, active, bound), values={}, branch=branch, active=active,
                  bound=bound, result=result)


@pytest.mark.parametrize(("left", "right", "expected"), [
    # the variant's jump at 0: u2 acts on the left (on its lower bound), u1 on the right; u2's
    # bound does not shape the value where u2 acts on nothing, so it is not a bound change
    (("a", "u2", "lower"), ("b", "u1", None),
     "mode sequence changes: a | b; acting inputs change: u2 | u1"),
    (("a", "u1", None), ("a", "u1", "upper"), "input u1 reaches its upper bound 3"),
    (("a", "u1", "lower"), ("a", "u1", "upper"), "input u1 moves to its upper bound 3"),
    # several acting decisions: each one acting on both sides is compared
    (("a", "u1+u2", "u1=upper"), ("a", "u1+u2", None), "input u1 leaves its upper bound 3"),
    (("a", "u1+u2", "u2=lower"), ("a", "u1", "upper"),
     "acting inputs change: u1+u2 | u1; input u1 reaches its upper bound 3"),
    (("a", "u1", "upper"), ("a", "u1", "upper"), "change of label without a mode change"),
])
def test_a_bound_is_a_cause_only_for_a_decision_acting_on_both_sides(
        left: tuple, right: tuple, expected: str) -> None:
    cause = describe_change(WORDS)
    assert cause(_optimum(*left), _optimum(*right), True, False) == expected


def test_bound_labels_read_one_or_several_decisions() -> None:
    assert bound_labels("upper", "u1") == {"u1": "upper"}
    assert bound_labels("u1=upper,u3=lower", "u1+u2+u3") == {"u1": "upper", "u3": "lower"}
    assert bound_labels(None, "u1") == {} and bound_labels("lower", None) == {}


def test_bound_relocation_bisects_the_slope_at_the_bound() -> None:
    """A decision reaching its upper bound 3 where the slope d c / d u there, s - 0.3, turns
    negative (outward): the optimiser's bracket 3e-9 off is moved to one of LOCATE_TOL around
    0.3 (the slope is exact here, so 0.3 lies in it); any other change keeps its bracket."""
    ev = Evaluator(lambda s: _optimum("a", "u1", "upper" if s > 0.3 + 3e-9 else None))
    relocate = bound_relocation(ev, 1.0, lambda held, d, s: 0.3 - s)
    lo, hi = 0.3 + 3e-9, 0.3 + 3e-9 + 5e-11
    a, b = relocate(lo, hi, ("a", "u1", None), ("a", "u1", "upper"))
    assert a <= 0.3 <= b and b - a <= LOCATE_TOL
    for la, lb in ((("a", "u1", None), ("b", "u1", "upper")),  # the branch changes too
                   (("a", "u1", "lower"), ("a", "u1", "upper")),  # bound to bound
                   (("a", "u2", None), ("a", "u1", "upper"))):  # the acting input changes
        assert relocate(lo, hi, la, lb) == (lo, hi)
    # a slope that keeps its sign over the search (MERGE_TOL around the bracket): kept too
    kept = bound_relocation(ev, 1.0, lambda held, d, s: -1.0)
    assert kept(lo, hi, ("a", "u1", None), ("a", "u1", "upper")) == (lo, hi)


# --- any system's bound points from coarse grids ------------------------------------------------
def _bound_crossing(problem: Problem, decision: str, which: str, near: float) -> float:
    """s where the free optimum of ``decision`` (that bound moved a width away) meets the bound,
    by secants of the optimiser's policy at +-1e-5 and +-1e-6 around it, centred first, then
    Richardson-extrapolated: the policy is smooth there, so this is known to ~1e-11 (the
    optimiser's u, ~1e-10, over slopes of 10-35), without the tables' engine."""
    lo, hi = problem.bound(decision)
    end = hi if which == "upper" else lo
    wide = (lo, 2 * hi - lo) if which == "upper" else (2 * lo - hi, hi)
    free = dataclasses.replace(problem, decisions=tuple(
        (d, wide if d == decision else b) for d, b in problem.decisions))

    def secant(centre: float, d: float) -> float:
        ua, ub = (optimal_policy(free, centre + k * d).policy[decision] for k in (-1, 1))
        return centre - d + (end - ua) * 2 * d / (ub - ua)

    centre = secant(near, 1e-5)
    fine, coarse = secant(centre, 1e-6), secant(centre, 1e-5)
    return fine + (fine - coarse) / 99.0


#: the biped's problems' bound points (decision, bound, near), MODEL.md Sec. 6
BOUND_POINTS = {
    "touchdown": [("u1", "upper", 0.0567)],
    "liftoff_variant": [("u2", "upper", -0.1787), ("u2", "lower", -0.04556),
                        ("u1", "upper", 0.02867)],
}


@pytest.mark.parametrize(("name", "lo", "hi", "num"), [
    ("touchdown", None, None, 2), ("touchdown", 0.05, 0.06, 2),
    ("liftoff_variant", None, None, 2), ("liftoff_variant", -0.1, 0.2, 3),
])
def test_bound_points_from_a_coarse_grid_are_the_kkt_points(name: str, lo: float | None,
                                                             hi: float | None, num: int) -> None:
    """The grid only says where to look: from 2 or 3 angles every bound point inside the range
    is found, with a bracket of LOCATE_TOL that holds the true point (to the 2e-11 it is known
    to), and with the kinks MODEL.md Sec. 6 lists there (outcome and policy kink, the value
    C^1 with a jump of curvature). No other point of these problems is a bound point."""
    problem = get_problem("biped", name)
    compiled = compiled_for(problem)
    grid = s_grid(compiled, problem.maneuver, num, lo, hi)
    report = find_nonsmooth_optimal(problem, grid)
    truths = {(d, which): _bound_crossing(problem, d, which, near)
              for d, which, near in BOUND_POINTS[name] if grid[0] <= near <= grid[-1]}
    bound = [p for p in report.points if "bound" in p.cause]
    assert {round(p.theta0, 6) for p in bound} == {round(x, 6) for x in truths.values()}
    for (decision, which), true in truths.items():
        here = [p for p in bound if abs(p.theta0 - true) < 1e-6]
        assert {(p.quantity, p.input, p.kind) for p in here} == {
            ("outcome", None, "kink"), ("policy", decision, "kink"),
            ("value", None, "second-derivative")}
        for p in here:
            a, b = p.bracket
            assert b - a <= LOCATE_TOL and a - 2e-11 <= true <= b + 2e-11, (p, true)
            assert f"input {decision}" in p.cause and f"its {which} bound" in p.cause
