"""What any system's figures show (biped_opt.analysis.figure_data), computed without drawing:
the grid's one-sided extrapolation on a known curve, and the figure records of a sweep against
the simulator, the solver and the engine they come from."""

from __future__ import annotations

import numpy as np
import pytest

from biped_opt.analysis.figure_data import (
    fixed_input_curves,
    grid_one_sided,
    optimal_curves,
    smoothed_curve,
    system_marks,
)
from biped_opt.analysis.nonsmooth import find_nonsmooth
from biped_opt.control.problems import get_problem
from biped_opt.control.solve import optimal_policy
from biped_opt.piecewise import theta_grid
from biped_opt.simulation.compiled import CompiledSystem


@pytest.fixture(scope="module")
def bar():
    return CompiledSystem("rocking_bar")


def test_grid_one_sided_reads_each_side_of_a_kink_and_never_the_point_itself():
    s = theta_grid(-0.05, 0.05, 101)  # spacing 1e-3, 0 included
    y = np.where(s < 0, np.sin(s) + 1.0, 1.0 + 2.0 * s + np.exp(s) - 1.0)
    y[s == 0.0] = np.nan  # never read: a NaN there would spoil every fit
    left, right = grid_one_sided(s, y, 0.0, -1), grid_one_sided(s, y, 0.0, 1)
    # a quartic through 5 points up to 16 spacings away: error ~ (1.6e-2)^5 f^(5) / 5! ~ 1e-11
    assert left.limit == pytest.approx(1.0, abs=1e-10)
    assert right.limit == pytest.approx(1.0, abs=1e-10)
    assert left.derivative == pytest.approx(1.0, abs=1e-8)  # cos(0)
    assert right.derivative == pytest.approx(3.0, abs=1e-8)  # 2 + exp(0)


def test_fixed_input_curves_are_the_simulators_and_the_engines(bar):
    s = theta_grid(-0.3, 0.3, 61)
    data = fixed_input_curves(bar, "drop", s)
    assert data.inputs == (0.0,) and set(data.curves) == {"outcome"}
    np.testing.assert_array_equal(data.curves["outcome"],
                                  bar.simulate_batch("drop", s, data.inputs)["outcome"])
    engine = find_nonsmooth(bar, "drop", data.inputs, s=s)
    assert [p.as_dict() for p in data.report.points] == [p.as_dict() for p in engine.points]
    # the bands are the trajectories' own events, one band per s (restitution: no mode change)
    assert [b.s for b in data.bands] == list(s)
    k = 40  # s = 0.1: left, right impacts (SYSTEMS.md Sec. 2)
    tr = bar.simulate("drop", float(s[k]), data.inputs)
    assert data.bands[k].events == tuple(tr.event_times) and data.bands[k].modes == (0,)


def test_system_marks_carry_the_engines_limits_and_slopes(bar):
    s = theta_grid(-0.3, 0.3, 61)
    y, marks = system_marks(bar, "drop", s, series="bar")
    report = find_nonsmooth(bar, "drop", s=s)
    assert len(marks) == len(report.points) >= 3  # 0 and +-0.0961 at least (SYSTEMS.md Sec. 2)
    for m, p in zip(marks, report.points):
        assert (m.s, m.kind, m.limits, m.slopes, m.series) == (
            p.theta0, p.kind, p.limits, p.derivatives, "bar")
    (zero,) = [m for m in marks if m.s == 0.0]
    # SYSTEMS.md Sec. 2 gives the limits at 0 to 7 decimals
    assert zero.limits == pytest.approx((0.1988738, -0.1988738), abs=1e-7)


def test_optimal_curves_are_the_solvers_optima():
    problem = get_problem("walker3_coupled", "touchdown")
    s = np.array([-0.1, 0.0, 0.1])
    data = optimal_curves(problem, s)
    assert set(data.curves) == {"outcome", "value", "policy:u1", "policy:u2", "policy:u3"}
    direct = optimal_policy(problem, 0.1)
    # the same deterministic solver at the same s: bit for bit
    assert data.curves["value"][2] == direct.value
    assert data.curves["policy:u1"][2] == direct.policy["u1"]
    assert data.report.optimal and data.report.grid_size == 3
    assert data.inputs == () and data.bands == ()


def test_smoothed_curve_is_the_gaussian_average():
    u = np.linspace(-1.0, 1.0, 2001)  # spacing 1e-3
    sigma = 0.05
    # a line is its own Gaussian average away from the ends (the kernel is symmetric)
    line = smoothed_curve(u, 2.0 * u + 1.0, sigma)
    inner = np.abs(u) < 1.0 - 4 * sigma
    np.testing.assert_allclose(line[inner], (2.0 * u + 1.0)[inner], rtol=0, atol=1e-12)
    # |u| at its kink: E|sigma w| = sigma sqrt(2 / pi); the kernel sampled at 1e-3 (sigma / 50)
    # and cut at 4 sigma is good to ~1e-4 relative (the cut tail holds 6e-5 of the mass)
    kink = smoothed_curve(u, np.abs(u), sigma)
    assert kink[1000] == pytest.approx(sigma * np.sqrt(2.0 / np.pi), rel=1e-3)
    # at an end the weights are renormalised over the half kernel inside the grid: the line's
    # average over a half-normal offset, 2 sigma sqrt(2 / pi) above the end value; the discrete
    # half kernel's own centre weight shifts it by ~1/(2 x 50 x 1.25) ~ 0.8 %, hence 2 %
    assert line[0] + 1.0 == pytest.approx(2.0 * sigma * np.sqrt(2.0 / np.pi), rel=2e-2)
