"""The data of the paper's figures (biped_opt.paper.figures), computed without drawing: marks
through the cost, a fixed-input sweep's arrays, and the control experiment's behaviour at 0
against MODEL.md Sec. 6 and SYSTEMS.md Sec. 3."""

from __future__ import annotations

import numpy as np
import pytest

from biped_opt.analysis.figure_data import Mark
from biped_opt.paper.biped import ContactMode
from biped_opt.paper.figures import (
    NonsmoothMark,
    at_zero,
    control_experiment_data,
    cost_mark,
    fixed_data,
)
from biped_opt.paper.problems import get_problem
from biped_opt.paper.sweeps import sweep_fixed, sweep_grid


def test_cost_mark_maps_limits_through_the_cost_and_slopes_through_its_gradient():
    problem = get_problem("liftoff")
    u = np.array([1.5, 3.0, 0.0])
    jump = NonsmoothMark(theta0=0.0, kind="jump", left=0.0262, right=-0.0065, value=0.0)
    mapped = cost_mark(jump, problem, u)
    assert mapped.left == problem.cost(0.0262, u) and mapped.right == problem.cost(-0.0065, u)
    assert mapped.value == problem.cost(0.0, u)
    kink = NonsmoothMark(theta0=0.0, kind="kink", left=0.796, right=0.714, value=-0.02)
    mapped = cost_mark(kink, problem, u)
    # dc/dth0 = dc/dth_f * dth_f/dth0, dc/dth_f = 2 (th_f - th*) at the point's outcome
    gain = 2.0 * (-0.02 - problem.theta_star)
    assert (mapped.left, mapped.right) == pytest.approx((gain * 0.796, gain * 0.714), rel=1e-15)


def test_fixed_data_holds_the_sweep_its_costs_and_modes():
    problem = get_problem("touchdown")
    grid = sweep_grid("touchdown", num=9)
    sweep = sweep_fixed("touchdown", grid)
    data = fixed_data(sweep, problem)
    np.testing.assert_array_equal(data.outcome, sweep.outcome)
    for k, th_f in enumerate(sweep.outcome):  # the cost of each angle at the sweep's inputs
        assert data.cost[k] == pytest.approx(float(problem.cost(th_f, sweep.inputs)), rel=1e-15)
    k = int(np.flatnonzero(grid == 0.0)[0])
    assert data.modes[k] == [int(ContactMode.AIR), int(ContactMode.GROUND)]  # both feet at once
    assert data.marks == () and data.cost_marks == ()


def test_at_zero_reads_the_engines_point_of_that_curve_only():
    kink = Mark(s=0.0, kind="kink", slopes=(0.79, 0.71), series="a")
    jump = Mark(s=0.0, kind="jump", limits=(0.02, -0.006), series="b")
    elsewhere = Mark(s=0.01, kind="jump", limits=(1.0, 2.0), series="c")
    assert at_zero([kink, jump, elsewhere], "a") == ("kink", (0.79, 0.71))
    assert at_zero([kink, jump, elsewhere], "b") == ("jump", (0.02, -0.006))
    assert at_zero([kink, jump, elsewhere], "c") is None  # not at 0


@pytest.fixture(scope="module")
def experiment():
    return control_experiment_data(num=41, bar_num=61)


def test_control_experiment_behaviour_at_zero(experiment):
    zero = experiment.zero
    kind, slopes = zero[("touchdown", "coupled")]
    # MODEL.md Sec. 6, the engine's one-sided slopes (located to 1e-10, good to ~1e-8)
    assert kind == "kink" and slopes == pytest.approx((0.7962438835, 0.7143664519), abs=1e-6)
    kind, limits = zero[("liftoff", "coupled")]
    assert kind == "jump" and limits == pytest.approx((0.026283950, -0.006532702), abs=1e-7)
    # decoupled: C^1, slopes of the variational equation (exact up to the integrator's
    # tolerance); SYSTEMS.md gives 10 decimals whose two sides differ by 2e-10: 1e-8
    kind, slopes = zero[("touchdown", "decoupled")]
    assert kind == "C1" and slopes == pytest.approx((0.8304310463, 0.8304310461), abs=1e-8)
    kind, slopes = zero[("liftoff", "decoupled")]
    assert kind == "C1" and slopes == pytest.approx((0.4926096190, 0.4926096191), abs=1e-8)
