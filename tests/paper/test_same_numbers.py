"""The any-system lane gives the numbers the biped-only lane gave for docs/MODEL.md's biped.

``biped_lane.json`` holds what the biped-only lane computed (recorded by a script that ran it
once, in commit afd61cd, before that lane was retired; lane and script are gone since):
trajectories, outcome branch gradients, optimal values and policies, Theorem 1's one-sided
derivatives and the nonsmooth tables. Each test here computes the
same quantity with the any-system lane alone -- the library's ``biped`` (the 2-leg walker,
constraints ``left`` and ``right``, inputs u1, u2, u12) and its declared problems -- and compares,
to a tolerance stated with its reason. Where the lanes differed in method, the one lane keeps
the better of the two and a test says which and why (the held decisions of Theorem 1 at the
variant's th0 = 0.1; the bound points, placed by the sign of the exact Karush-Kuhn-Tucker slope).

Nothing here imports the biped-only lane; the few conventions it had are written out below.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from biped_opt.analysis.nonsmooth import find_nonsmooth, find_nonsmooth_optimal
from biped_opt.control.derivatives import outcome_gradient
from biped_opt.control.problems import Problem, get_problem
from biped_opt.control.solve import compiled_for, optimal_policy
from biped_opt.control.theorem1 import optimal_derivatives_with_errors
from biped_opt.simulation.compiled import compiled_with, simulate
from tests.extrapolated import SAFETY

RECORD = json.loads(Path(__file__).with_name("biped_lane.json").read_text())

#: the paper's fixed inputs (u1, u2, u12) of Figs. 2, 3 (MODEL.md Sec. 5), as the old lane had them
FIXED_INPUTS = {"touchdown": (2.0, 0.5, 0.0), "liftoff": (1.5, 3.0, 0.0)}
#: the old lane's problem names -> the names the library's biped declares them by
PROBLEMS = {"touchdown": "touchdown", "liftoff": "liftoff", "liftoff-variant": "liftoff_variant"}
#: contact modes: bit masks (bit 0 the left foot, bit 1 the right) and the old lane's names
MODE_NAMES = {0: "AIR", 1: "LEFT", 2: "RIGHT", 3: "GROUND"}
#: the old lane's mode names in branch labels -> the any-system lane's (constraints joined by +)
MODE_LABELS = {"AIR": "air", "LEFT": "left", "RIGHT": "right", "GROUND": "left+right"}
#: the old lane's wording of a cause -> the any-system lane's
CAUSE_WORDS = {"mode order changes": "mode sequence changes",
               "acting input changes": "acting inputs change"}

#: the nonsmooth engine's bracket width (both lanes bisect a change of label to it)
LOCATE_TOL = 1e-10
#: the sensitivities' relative integration tolerance and the any-system lane's one-sided step in
#: s of D_u c: a zero slope computed from them is zero to about their ratio
VARIATIONAL_RTOL = 1e-11
MIXED_STEP = 1e-4


def problem(name: str) -> Problem:
    return get_problem("biped", PROBLEMS[name])


def label(branch: str) -> str:
    """An old-lane branch label (``AIR->LEFT->GROUND``) in the any-system lane's words."""
    if branch.startswith("FAILED:"):
        return branch
    return "->".join(MODE_LABELS[m] for m in branch.split("->"))


def cause(text: str) -> str:
    """An old-lane cause in the any-system lane's words (its mode labels too)."""
    for old, new in CAUSE_WORDS.items():
        text = text.replace(old, new)
    return re.sub(r"\b(?:AIR|LEFT|RIGHT|GROUND)(?:->(?:AIR|LEFT|RIGHT|GROUND))+\b",
                  lambda m: label(m.group(0)), text)


def test_the_record_is_of_the_papers_setting() -> None:
    """The recorded fixed-input tables are at the paper's inputs written out above, and the
    record is small (it lives in the repository)."""
    tables = RECORD["nonsmooth"]["fixed"]
    assert {(t["maneuver"], tuple(t["inputs"])) for t in tables} >= set(FIXED_INPUTS.items())
    assert set(RECORD["nonsmooth"]["optimal"]) == set(PROBLEMS)
    assert Path(__file__).with_name("biped_lane.json").stat().st_size < 300_000


# --- trajectories ---------------------------------------------------------------------------
def _trajectory_id(r: dict[str, Any]) -> str:
    return f"{r['maneuver']}@{r['theta0']:g}-u={','.join(f'{v:g}' for v in r['inputs'])}"


@pytest.mark.parametrize("rec", RECORD["trajectories"], ids=_trajectory_id)
def test_trajectory(rec: dict[str, Any]) -> None:
    """Status, mode sequence, outcome, final time and state, event times. Both lanes run the
    biped's one generated kernel with the same settings (DOP853 at rtol 1e-11, the same event
    budget and horizon), so they agree to the last bits (measured: exactly); 1e-12 is far below
    what two different integrations at rtol 1e-11 would agree to (~1e-11), so it still says
    "the same computation"."""
    tr = simulate("biped", rec["maneuver"], rec["theta0"], tuple(rec["inputs"]))
    assert tr.status.name == rec["status"]
    assert [MODE_NAMES[m] for m in tr.modes] == rec["modes"]
    assert tr.outcome == pytest.approx(rec["outcome"], abs=1e-12)
    assert tr.t_final == pytest.approx(rec["t_final"], abs=1e-12)
    np.testing.assert_allclose(tr.y_final, rec["state_final"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(tr.event_times, rec["event_times"], rtol=0, atol=1e-12)


# --- outcome derivatives at fixed inputs ------------------------------------------------------
@pytest.mark.parametrize("rec", RECORD["outcome_derivatives"], ids=_trajectory_id)
def test_outcome_branch_gradients(rec: dict[str, Any]) -> None:
    """The gradient of th_f over (th0, u1, u2, u12) on each side's branch (the kink and the jump
    at 0 included): the same saltation method on two variational integrations at rtol 1e-11
    (hand-written physics with differenced Jacobians against generated code), so 1e-9 (measured
    5e-12); the branch limits come from the same simulation, or the same continuation, to
    1e-10."""
    compiled = compiled_with("biped")
    for side, key in ((-1.0, "left"), (1.0, "right")):
        g = outcome_gradient(compiled, rec["maneuver"], rec["theta0"], tuple(rec["inputs"]),
                             direction=(side, 0.0, 0.0, 0.0))
        ref = rec[key]
        np.testing.assert_allclose(g.gradient, ref["gradient"], rtol=0, atol=1e-9)
        assert g.outcome == pytest.approx(ref["outcome"], abs=1e-10)
        assert [MODE_NAMES[m] for m in g.modes] == ref["modes"]
        assert g.continued == ref["continued"]


# --- optimal policies and values --------------------------------------------------------------
def _optimum_id(r: dict[str, Any]) -> str:
    return f"{r['problem']}@{r['theta0']:.10g}"


@pytest.mark.parametrize("rec", RECORD["optimal"], ids=_optimum_id)
def test_optimum(rec: dict[str, Any]) -> None:
    """Value, policy, outcome, branch, acting decision and bound, near the tables' points too.

    Both lanes bracket the acting decision on a grid of 65 and refine each grid minimum by
    bounded Brent (xatol 1e-10) and a Newton polish, which locates the minimiser to ~1e-10 where
    the cost is curved; where it is flattest Brent alone stops ~1e-8 off: policies to 1e-8. The
    cost is flat at an interior optimum (such an error costs ~1e-16) and exact on a bound: values
    to 1e-12. Outcomes move with the policy by |d th_f / d u| (below 1 here): 1e-9. (Measured:
    the lanes agree exactly.)"""
    r = optimal_policy(problem(rec["problem"]), rec["theta0"])
    assert r.success == rec["success"]
    assert r.branch == label(rec["branch"])
    assert (r.active, r.bound) == (rec["active"], rec["bound"])
    assert r.value == pytest.approx(rec["value"], abs=1e-12)
    for d, v in rec["policy"].items():
        assert r.policy[d] == pytest.approx(v, abs=1e-8), d
    assert r.outcome == pytest.approx(rec["outcome"], abs=1e-9)
    np.testing.assert_allclose(r.event_times, rec["event_times"], rtol=0, atol=1e-9)


# --- Theorem 1: one-sided derivatives of the optimum -------------------------------------------
_DERIVATIVES: dict[tuple[str, float], Any] = {}


def _derivatives(rec: dict[str, Any]) -> Any:
    key = (rec["problem"], rec["theta0"])
    if key not in _DERIVATIVES:
        _DERIVATIVES[key] = optimal_derivatives_with_errors(problem(rec["problem"]),
                                                            rec["theta0"])
    return _DERIVATIVES[key]


@pytest.mark.parametrize("rec", RECORD["derivatives"], ids=_optimum_id)
def test_optimal_derivatives(rec: dict[str, Any]) -> None:
    """(left, right) slopes of the optimal value, outcome and policy, and their limits.

    Slopes: the same Theorem 1 in two implementations, each off by about the any-system lane's
    own error estimate (differences of exact gradients, Richardson-extrapolated), so they agree
    to SAFETY times twice it. A policy slope that is zero by construction on one side (a
    decision held on a bound or acting on nothing) is the other lane's rounding of a zero
    gradient: zero to SAFETY times the sensitivities' rtol over the mixed difference's step.
    Limits: value limits are one simulation each (1e-10 relative); policy limits are the zeros of
    D_u c, which the lanes take from two variational integrations (D_u c differs by ~3e-13 at
    touchdown th0 = 0.05, where the curvature is 6e-4): 1e-9 relative."""
    ours, err = _derivatives(rec)
    for k in (0, 1):
        assert ours.value[k] == pytest.approx(rec["value"][k], abs=2 * SAFETY * err.value[k])
        assert ours.outcome[k] == pytest.approx(rec["outcome"][k],
                                                abs=2 * SAFETY * err.outcome[k])
        for d, pair in rec["policy"].items():
            if d in ours.at_bound[k] or ours.policy[d][k] == 0.0:
                tol = SAFETY * VARIATIONAL_RTOL / MIXED_STEP
            else:
                tol = 2 * SAFETY * err.policy[d][k]
            assert ours.policy[d][k] == pytest.approx(pair[k], abs=tol), (d, k)
            assert ours.policy_limits[d][k] == pytest.approx(
                rec["policy_limits"][d][k], rel=1e-9, abs=1e-9), (d, k)
    assert ours.value_limits == pytest.approx(rec["value_limits"], rel=1e-10, abs=1e-12)
    assert ours.outcome_limits == pytest.approx(rec["outcome_limits"], abs=1e-10)


#: (problem, th0) -> the decisions held on a bound (left, right) where the one lane keeps its own
#: verdict: at the variant's th0 = 0.1 the biped lane held u1 and u2 on the left and u1 on the
#: right, the one lane holds u1 on both. u2 acts on nothing there (GROUND->LEFT->AIR: only u1
#: pushes) and sits at its cheapest value, its lower bound 0; the biped lane counted it held on
#: the side where the rounding of its zero slope (+2.3e-10, its reported right slope) pointed out
#: of the box. A decision that acts on nothing is not held by a bound (its derivative is 0
#: because nothing moves it), so only acting decisions are held.
HELD = {("liftoff-variant", 0.1): (("u1",), ("u1",))}


@pytest.mark.parametrize("rec", RECORD["derivatives"], ids=_optimum_id)
def test_optimal_derivative_labels(rec: dict[str, Any]) -> None:
    """The branch each side follows and the decisions held on a bound there (the record's, or
    :data:`HELD`'s where the one lane decides otherwise)."""
    ours, _ = _derivatives(rec)
    assert list(ours.branches) == [label(b) for b in rec["branches"]]
    held = HELD.get((rec["problem"], rec["theta0"]), rec["at_bound"])
    assert [sorted(h) for h in ours.at_bound] == [sorted(h) for h in held]


# --- nonsmooth tables -------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tables() -> Any:
    """The any-system lane's table of a recorded one, computed once per module (default
    grids, as recorded: 401 angles at fixed inputs, 201 for a problem)."""
    found: dict[tuple[str, ...], Any] = {}

    def table(key: tuple[str, ...]) -> Any:
        if key not in found:
            if key[0] == "fixed":
                _, maneuver, inputs = key
                u = tuple(float(v) for v in inputs.split(","))
                found[key] = find_nonsmooth("biped", maneuver, u)
            else:
                found[key] = find_nonsmooth_optimal(problem(key[1]))
        return found[key]

    return table


def _recorded_tables() -> list[tuple[tuple[str, ...], dict[str, Any]]]:
    out: list[tuple[tuple[str, ...], dict[str, Any]]] = [
        (("fixed", t["maneuver"], ",".join(repr(float(v)) for v in t["inputs"])), t)
        for t in RECORD["nonsmooth"]["fixed"]]
    out += [(("optimal", name), t) for name, t in RECORD["nonsmooth"]["optimal"].items()]
    return out


def _table_id(key: tuple[str, ...]) -> str:
    return ":".join(key)


def _kinds(points: Any) -> list[tuple[str, str, str]]:
    return sorted((p["quantity"], p["input"] or "", p["kind"]) if isinstance(p, dict) else
                  (p.quantity, p.input or "", p.kind) for p in points)


@pytest.mark.parametrize(("key", "rec"), _recorded_tables(),
                         ids=[_table_id(k) for k, _ in _recorded_tables()])
def test_table_lists_the_same_points(tables: Any, key: tuple[str, ...],
                                     rec: dict[str, Any]) -> None:
    """The same grid, the same set of (quantity, component, kind) points, none more, none
    less, at the same angles to 1e-6 (the points' own accuracy is tested point by point)."""
    report = tables(key)
    assert report.grid_size == rec["grid_size"]
    assert _kinds(report.points) == _kinds(rec["points"])
    mine = sorted(p.theta0 for p in report.points)
    theirs = sorted(p["theta0"] for p in rec["points"])
    assert np.abs(np.subtract(mine, theirs)).max(initial=0.0) < 1e-6


def _point_id(key: tuple[str, ...], p: dict[str, Any]) -> str:
    what = p["quantity"] + (f":{p['input']}" if p["input"] else "")
    return f"{_table_id(key)}@{p['theta0']:.6g}:{what}:{p['kind']}"


def _point_params() -> list[Any]:
    """Every recorded point."""
    return [pytest.param(key, p, id=_point_id(key, p))
            for key, rec in _recorded_tables() for p in rec["points"]]


def _match(report: Any, p: dict[str, Any]) -> Any:
    """The point of ``report`` that is recorded point ``p``: same quantity, component and kind,
    within 1e-6 (test_table_lists_the_same_points checks there is one)."""
    found = [q for q in report.points
             if (q.quantity, q.input, q.kind) == (p["quantity"], p["input"], p["kind"])
             and abs(q.theta0 - p["theta0"]) < 1e-6]
    assert len(found) == 1, f"{len(found)} points match {p['quantity']} {p['kind']}"
    return found[0]


@pytest.mark.parametrize(("key", "p"), _point_params())
def test_point_is_located_at_the_same_angle(tables: Any, key: tuple[str, ...],
                                            p: dict[str, Any]) -> None:
    """Both lanes claim a bracket of LOCATE_TOL around each point (a band of simultaneous events
    widened over it, then the point is 0): the same point to 2 LOCATE_TOL, exactly 0 at 0."""
    q = _match(tables(key), p)
    if p["theta0"] == 0.0:
        assert q.theta0 == 0.0
    assert q.theta0 == pytest.approx(p["theta0"], abs=2 * LOCATE_TOL)


@pytest.mark.parametrize(("key", "p"), _point_params())
def test_point_has_the_same_cause(tables: Any, key: tuple[str, ...], p: dict[str, Any]) -> None:
    """The same cause (in the any-system lane's words) and mode sequences on both sides."""
    q = _match(tables(key), p)
    assert list(q.labels) == [label(b) for b in p["labels"]]
    assert q.cause == cause(p["cause"])


@pytest.mark.parametrize(("key", "p"), _point_params())
def test_point_has_the_same_numbers(tables: Any, key: tuple[str, ...],
                                    p: dict[str, Any]) -> None:
    """One-sided limits and slopes, and for a second-derivative point its second derivatives.

    Both lanes bracket every point identically (the same label changes bisected between the same
    angles, a bound point on the sign of the same Karush-Kuhn-Tucker slope), so the samples are
    the same simulations and optima (test_trajectory and test_optimum: exactly) in the same
    extrapolation ladders, and the numbers agree to rounding (1e-12 relative)."""
    q = _match(tables(key), p)
    assert list(q.bracket) == p["bracket"]
    for name in ("limits", "derivatives", "second_derivatives"):
        mine = [math.nan if v is None else v for v in p[name]]
        np.testing.assert_allclose(getattr(q, name), mine, rtol=1e-12, atol=1e-15,
                                   err_msg=name)


#: the nonsmooth engine accepts an extrapolated one-sided slope once two successive ladders (steps
#: shrinking by 8) agree to this, relative to max(1, |slope|): the accuracy it works to on ladders
#: of optima, whose optimiser noise (~1e-10 in u) its finer ladders amplify
LADDER_AGREEMENT = 1e-3


def _optimal_point_params() -> list[Any]:
    return [pytest.param(key, p, id=_point_id(key, p))
            for key, rec in _recorded_tables() if key[0] == "optimal" for p in rec["points"]]


@pytest.mark.parametrize(("key", "p"), _optimal_point_params())
def test_optimal_table_slopes_are_theorem_1s(tables: Any, key: tuple[str, ...],
                                             p: dict[str, Any]) -> None:
    """The table's one-sided slopes, extrapolated from ladders of optima, against Theorem 1's at
    the same point (exact sensitivities; its own error estimate, times SAFETY, is added).

    The ladders are accurate to the engine's LADDER_AGREEMENT, not better: next to a bound point
    the free side's policy slope is off by up to 6.7e-4 of 32 (2.1e-5 relative, the variant at
    -0.0456) and the outcome's by up to 1.8e-5 (the variant at -0.1787: 0.000641763 against
    Theorem 1's 0.000659595, both lanes alike), measured; this says the tables' slopes are
    Theorem 1's to what the engine claims, and that a kink smaller than ~2e-5 in the outcome is
    below what an extrapolated table resolves there."""
    q = _match(tables(key), p)
    ours, err = _derivatives({"problem": key[1], "theta0": q.theta0})
    if q.quantity == "policy":
        reference, error = ours.policy[q.input], err.policy[q.input]
    else:
        reference, error = getattr(ours, q.quantity), getattr(err, q.quantity)
    for k in (0, 1):
        tol = LADDER_AGREEMENT * max(1.0, abs(reference[k])) + SAFETY * error[k]
        assert q.derivatives[k] == pytest.approx(reference[k], abs=tol), k


# --- where a bound is reached or left: the Karush-Kuhn-Tucker point ----------------------------
_BOUND = re.compile(r"input (\w+) (?:reaches|leaves|moves to) its (lower|upper) bound")


def _bound_points() -> list[Any]:
    """One case per recorded point where a decision reaches or leaves a bound: (problem,
    decision, which bound, recorded th0, the any-system lane's table key)."""
    seen = set()
    out = []
    for name, t in RECORD["nonsmooth"]["optimal"].items():
        for p in t["points"]:
            m = _BOUND.search(p["cause"])
            if m and (name, p["theta0"]) not in seen:
                seen.add((name, p["theta0"]))
                out.append((name, m.group(1), m.group(2), p["theta0"]))
    return out


def _kkt_slope(prob: Problem, decision: str, which: str, th0: float) -> float:
    """The cost's slope d c / d u at the bound, pointing out of the box (exact sensitivities):
    <= 0 where the bound holds the optimum, and it crosses 0 where the free optimum meets the
    bound."""
    lo, hi = prob.bound(decision)
    end, outward = (hi, 1.0) if which == "upper" else (lo, -1.0)
    u = prob.inputs({decision: end})
    g = outcome_gradient(compiled_for(prob), prob.maneuver, th0, u)
    col = prob.description.u.names().index(decision)
    slope = 2.0 * prob.outcome_weight * (g.outcome - prob.target) * g.gradient[1 + col]
    return outward * (slope + 2.0 * prob.alpha(decision) * end)


@pytest.mark.parametrize(("name", "decision", "which", "th0"), _bound_points(),
                         ids=[f"{n}@{x:.6g}:{d}" for n, d, _, x in _bound_points()])
def test_recorded_bound_points_are_where_the_kkt_slope_changes_sign(
        name: str, decision: str, which: str, th0: float) -> None:
    """Which lane places a bound point right: the recorded one lies within LOCATE_TOL of the
    sign change of the KKT slope at the bound, as the any-system lane's own sensitivities
    compute it (smooth in th0; its sign flips within ~1e-11 of the point)."""
    prob = problem(name)
    before = _kkt_slope(prob, decision, which, th0 - LOCATE_TOL)
    after = _kkt_slope(prob, decision, which, th0 + LOCATE_TOL)
    assert before * after < 0.0, (before, after)


@pytest.mark.parametrize(("name", "decision", "which", "th0"), _bound_points(),
                         ids=[f"{n}@{x:.6g}:{d}" for n, d, _, x in _bound_points()])
def test_located_bound_points_are_where_the_kkt_slope_changes_sign(
        tables: Any, name: str, decision: str, which: str, th0: float) -> None:
    """The any-system lane's own bound points pass the same test."""
    report = tables(("optimal", name))
    (x,) = {p.theta0 for p in report.points if abs(p.theta0 - th0) < 1e-6}
    prob = problem(name)
    before = _kkt_slope(prob, decision, which, x - LOCATE_TOL)
    after = _kkt_slope(prob, decision, which, x + LOCATE_TOL)
    assert before * after < 0.0, (before, after)
