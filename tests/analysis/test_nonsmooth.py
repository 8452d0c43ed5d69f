"""Nonsmooth tables of any system (biped_opt.analysis.nonsmooth) against SYSTEMS.md's numbers."""

from __future__ import annotations

import json
import math

import pytest

from biped_opt.analysis.nonsmooth import find_nonsmooth, find_nonsmooth_optimal
from biped_opt.analysis.switches import LOCATE_TOL
from biped_opt.control.problems import get_problem
from biped_opt.optimal.nonsmooth import find_nonsmooth_fixed
from biped_opt.optimal.nonsmooth import find_nonsmooth_optimal as biped_find_optimal
from biped_opt.optimal.problems import get_problem as biped_problem


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
    same places (to 1e-8: both locate to 1e-10, bound points to the optimiser's ~1e-9)."""
    grid = [-0.25 + 0.025 * k for k in range(21)]
    generic = find_nonsmooth_optimal(get_problem("biped", "touchdown"), grid)
    reference = biped_find_optimal(biped_problem("touchdown"), grid)
    key = sorted((p.quantity, p.input or "", p.kind) for p in reference.points)
    assert sorted((p.quantity, p.input or "", p.kind) for p in generic.points) == key
    for a in generic.points:
        (b,) = [p for p in reference.points if (p.quantity, p.input, p.kind) ==
                (a.quantity, a.input, a.kind) and abs(p.theta0 - a.theta0) < 1e-6]
        assert a.theta0 == pytest.approx(b.theta0, abs=1e-8)


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
