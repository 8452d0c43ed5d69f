"""The samples-only nonsmooth estimate (biped_opt.analysis.sampled) on curves with known answers.

Each curve is a polynomial of degree <= 3 on each side, so the cubic through the 4 nearest
samples of a side is the side itself: limits, slopes and the meeting point of two continuous
sides come out exact up to rounding (1e-12 below: the fits' conditioning on offsets ~1e-2 costs a
few digits of 1e-16).
"""

from __future__ import annotations

import numpy as np
import pytest

from biped_opt.analysis.sampled import Samples, candidates, grid_nonsmooth, labels
from biped_opt.piecewise import theta_grid

EXACT = 1e-12


def test_a_jump_at_an_isolated_sample_has_the_sides_limits_and_slopes():
    s = theta_grid(-0.05, 0.05, 11)  # spacing 0.01, 0 included
    y = np.where(s < 0, s**3 + s, 0.5 + 2.0 * s - s**2)
    y[s == 0.0] = 0.25  # the simultaneous event's own value: used for `at` only
    branch = tuple("A" if v < 0 else "B" if v == 0 else "C" for v in s)
    (g,) = grid_nonsmooth(Samples(s=s, branch=branch, quantities={"outcome": y}))
    p = g.point
    assert p.kind == "jump" and p.theta0 == 0.0 and p.at == 0.25
    assert p.bracket == pytest.approx((-0.01, 0.01), abs=1e-15) and g.width == pytest.approx(0.02)
    assert p.left == pytest.approx(0.0, abs=EXACT) and p.right == pytest.approx(0.5, abs=EXACT)
    assert p.derivatives == pytest.approx((1.0, 2.0), abs=1e-9)  # slopes: one order less exact
    assert p.labels == ("A", "C") and "mode order changes: A | C (th0 = 0: B)" in p.cause


def test_a_kink_between_samples_is_located_where_the_sides_meet():
    s = np.linspace(-0.1, 0.1, 21)
    kink = 0.0137  # between the samples 0.01 and 0.02
    y = np.where(s < kink, -(s - kink), 3.0 * (s - kink)) + 1.0
    branch = tuple("L" if v < kink else "R" for v in s)
    (g,) = grid_nonsmooth(Samples(s=s, branch=branch, quantities={"outcome": y}))
    p = g.point
    assert p.kind == "kink" and p.bracket == pytest.approx((0.01, 0.02), abs=1e-15)
    assert p.theta0 == pytest.approx(kink, abs=EXACT)  # exact lines meet at the kink itself
    assert (p.left, p.right) == pytest.approx((-1.0, 3.0), abs=1e-9)


def test_a_label_change_with_matching_sides_is_no_point():
    s = np.linspace(-0.1, 0.1, 21)
    y = 0.3 * s + s**2  # one smooth curve, though the label changes at 0.035
    branch = tuple("L" if v < 0.035 else "R" for v in s)
    samples = Samples(s=s, branch=branch, quantities={"outcome": y})
    assert len(candidates(samples)) == 1  # the change is a candidate ...
    assert grid_nonsmooth(samples) == []  # ... whose sides agree: not reported


def test_an_input_reaching_its_bound_is_labelled_and_kinks_the_policy():
    s = np.linspace(-0.2, 0.2, 41)
    policy = np.minimum(0.5 + 2.0 * s, 0.63)  # reaches its upper bound 0.63 at s = 0.065
    value = (s - 0.1) ** 2 + policy**2
    samples = Samples(s=s, branch=("A",) * s.size,
                      quantities={"outcome": s.copy(), "policy:u": policy, "value": value},
                      optimal=True, bounds=(("u", (-1.0, 0.63)),))
    held = [lab[1] for lab in labels(samples)]
    assert held[0] == (None,) and held[-1] == ("upper",)
    points = {(g.point.quantity, g.point.input, g.point.kind): g.point
              for g in grid_nonsmooth(samples)}
    assert set(points) == {("policy", "u", "kink"), ("value", None, "kink")}
    p = points[("policy", "u", "kink")]
    assert p.bracket == pytest.approx((0.06, 0.07), abs=1e-15)
    assert p.theta0 == pytest.approx(0.065, abs=EXACT)  # where the two exact pieces meet
    assert (p.left, p.right) == pytest.approx((2.0, 0.0), abs=1e-9)
    assert p.cause == "input u reaches its upper bound"
    # the value's slopes at 0.065: 2 (s - 0.1) + 2 u u' = -0.07 + 2.52 left, -0.07 right
    v = points[("value", None, "kink")]
    assert (v.left, v.right) == pytest.approx((2.45, -0.07), abs=1e-9)


def test_an_isolated_policy_step_is_a_candidate_without_a_label_change():
    s = np.linspace(-0.1, 0.1, 21)
    policy = np.where(s < 0.015, 0.2 + 0.1 * s, -0.3 + 0.1 * s)  # another local minimum
    samples = Samples(s=s, branch=("A",) * s.size,
                      quantities={"outcome": s.copy(), "policy:u": policy}, optimal=True,
                      bounds=(("u", (-1.0, 1.0)),))
    (event,) = candidates(samples)
    assert event[:3] == (11, 12, None) and "another local minimum" in event[3]
    (g,) = grid_nonsmooth(samples)
    assert g.point.kind == "jump" and g.point.input == "u"
    assert (g.point.left, g.point.right) == pytest.approx((0.2015, -0.2985), abs=EXACT)
