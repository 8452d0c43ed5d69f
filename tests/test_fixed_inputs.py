"""The fixed-input nonsmoothness of MODEL.md Sec. 6: touchdown kink and liftoff jump at th0 = 0,
measured with the extrapolated one-sided limits and slopes of biped_opt.piecewise."""

from __future__ import annotations

import numpy as np
import pytest

from biped_opt.paper.biped import simulate
from biped_opt.piecewise import one_sided, theta_grid


def _outcome(maneuver, u):
    return lambda th: simulate(maneuver, th, u).outcome


def test_grid_holds_zero_exactly():
    grid = theta_grid(-0.25, 0.25, 400)  # an even count would straddle 0
    assert 0.0 in grid and np.all(np.diff(grid) > 0)


def test_touchdown_kink_slopes_and_continuity():
    """One-sided slopes at 0 within 1e-6 of MODEL.md (its reference is itself ~1e-9 accurate;
    our extrapolated slopes agree with each other to ~1e-8), limits equal to outcome(0) = 0."""
    f = _outcome("touchdown", (2.0, 0.5))
    left, right = one_sided(f, 0.0, -1), one_sided(f, 0.0, +1)
    assert abs(right.derivative - 0.714366448) < 1e-6
    assert abs(left.derivative - 0.796243869) < 1e-6
    assert abs(left.limit) < 1e-9 and abs(right.limit) < 1e-9 and f(0.0) == 0.0


def test_touchdown_without_inputs_is_smooth_at_zero():
    f = _outcome("touchdown", (0.0, 0.0))
    left, right = one_sided(f, 0.0, -1), one_sided(f, 0.0, +1)
    assert abs(left.derivative - 0.823536373) < 1e-6
    assert abs(right.derivative - 0.823536373) < 1e-6


def test_liftoff_jump_limits():
    """One-sided limits within 1e-7 of MODEL.md; the value at 0 itself is 0 (symmetric push)."""
    f = _outcome("liftoff", (1.5, 3.0, 0.0))
    left, right = one_sided(f, 0.0, -1), one_sided(f, 0.0, +1)
    assert abs(left.limit - 0.026283950) < 1e-7
    assert abs(right.limit - (-0.006532702)) < 1e-7
    assert f(0.0) == 0.0


def test_liftoff_without_inputs_is_continuous():
    f = _outcome("liftoff", (0.0, 0.0, 0.0))
    left, right = one_sided(f, 0.0, -1), one_sided(f, 0.0, +1)
    assert abs(left.limit - right.limit) < 1e-9


def test_one_sided_of_a_constant_side_is_exact():
    """A saturated input is constant on one side: its limit must be the bound itself, bit for bit
    (a least-squares fit returns it only to ~1e-15, differently on different CPUs)."""
    side = one_sided(lambda x: 1.5 if x > 0 else 0.1 * x, 0.0, +1)
    assert side.limit == 1.5 and side.derivative == 0.0 and side.second_derivative == 0.0
    other = one_sided(lambda x: 1.5 if x > 0 else 0.1 * x, 0.0, -1)
    assert other.derivative == pytest.approx(0.1, abs=1e-12)  # a line: exact up to rounding
