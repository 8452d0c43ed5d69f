"""Nonsmooth points located correctly from any grid, however coarse.

The location is bisection on labels (mode order, acting input, bound) between grid points, so
the grid must only tell the analysis *where to look*: two points (plus the 0 every grid holds)
must give the same points, each inside its bracket, as a fine grid. The true location of the
contact kink and jump is th0 = 0 exactly (the feet touch or leave together there, MODEL.md
Sec. 6); their brackets are the band of simultaneous events around it, ~4e-9 wide (the event
location tolerance), so 1e-8 is the width allowed.
"""

from __future__ import annotations

import numpy as np
import pytest

from biped_opt.fixed_sweep import theta_grid
from biped_opt.optimal import liftoff_problem, touchdown_problem
from biped_opt.optimal.nonsmooth import find_nonsmooth_fixed, find_nonsmooth_optimal
from biped_opt.optimal.sweep import sweep_grid

RANGES = [(-0.25, 0.25), (-0.05, 0.2), (0.01, 0.2), (-0.2, -0.01), (0.0, 0.2), (-0.2, 0.0),
          (-1e-3, 0.25), (-0.25, 1e-9)]
#: width of the simultaneous-event band the contact points are bracketed by (see above)
BAND = 1e-8


@pytest.mark.parametrize("num", range(2, 13))
@pytest.mark.parametrize(("lo", "hi"), RANGES)
def test_grids_keep_both_ends_and_hold_zero(num, lo, hi):
    for grid in (theta_grid(lo, hi, num), sweep_grid("touchdown", lo, hi, num)):
        assert grid[0] == lo and grid[-1] == hi
        assert np.all(np.diff(grid) > 0)
        assert (0.0 in grid) == (lo <= 0.0 <= hi)
        # 0 takes an interior angle's place, or is added when only the ends are near it
        assert grid.size == num or (grid.size == num + 1 and lo < 0.0 < hi)


# (maneuver, which one-sided quantity, MODEL.md's left and right values, their tolerance)
FIXED = {
    "touchdown": ("kink", 0.796243869, 0.714366448, 1e-6),
    "liftoff": ("jump", 0.026283950, -0.006532702, 1e-7),
}
COARSE = [(None, None, n) for n in (2, 3, 4, 5)] + [
    (-0.05, 0.2, 2), (0.0, 0.2, 2), (-0.2, 0.0, 3), (-1e-3, 0.25, 2), (-0.25, 1e-9, 2)]


@pytest.mark.parametrize("maneuver", sorted(FIXED))
@pytest.mark.parametrize(("lo", "hi", "num"), COARSE)
def test_fixed_input_point_is_at_zero_inside_its_bracket(maneuver, lo, hi, num):
    kind, left, right, tol = FIXED[maneuver]
    report = find_nonsmooth_fixed(maneuver, sweep_grid(maneuver, lo, hi, num))
    (point,) = report.points
    a, b = point.bracket
    assert point.theta0 == 0.0 and a <= 0.0 <= b and b - a <= BAND, point.bracket
    assert point.kind == kind
    assert point.left == pytest.approx(left, abs=tol)
    assert point.right == pytest.approx(right, abs=tol)


@pytest.mark.parametrize("maneuver", sorted(FIXED))
def test_a_range_without_the_simultaneous_point_has_no_point(maneuver):
    assert find_nonsmooth_fixed(maneuver, sweep_grid(maneuver, 0.01, 0.2, 2)).points == ()
    assert find_nonsmooth_fixed(maneuver, sweep_grid(maneuver, -0.2, -1e-3, 3)).points == ()


def _key(p):
    return (p.quantity, p.input or "", p.kind)


@pytest.fixture(scope="module", params=["touchdown", "liftoff"])
def fine(request):
    problem = {"touchdown": touchdown_problem, "liftoff": liftoff_problem}[request.param]()
    return problem, find_nonsmooth_optimal(problem, sweep_grid(problem.maneuver, num=41))


@pytest.mark.parametrize("num", [2, 3, 5])
def test_optimal_points_from_a_coarse_grid_equal_the_fine_grids(fine, num):
    """Same points as from 41 angles: the touchdown kinks at 0 and the bound reached by u1 at
    0.0567 (found although the interval (0, 0.25] of the 2-angle grid holds both the band's
    edge and the bound), the liftoff jump at 7.55e-4. The contact points' brackets hold 0. A
    bound reached or a branch switch is a change of the optimiser's answer, which flickers over
    a zone as wide as the optimiser resolves it: "u1 on its bound" is decided from a cost slope
    that vanishes there (measured: 2- and 41-angle grids bracket it 9e-9 apart, each bracket
    1e-10 wide), so there the coarse and fine locations must agree to 2e-8."""
    problem, reference = fine
    report = find_nonsmooth_optimal(problem, sweep_grid(problem.maneuver, num=num))
    assert sorted(map(_key, report.points)) == sorted(map(_key, reference.points))
    for p in report.points:
        a, b = p.bracket
        assert a <= p.theta0 <= b and b - a <= BAND
        (ref,) = [r for r in reference.points if _key(r) == _key(p)
                  and abs(r.theta0 - p.theta0) <= BAND]
        if ref.theta0 == 0.0:
            assert p.theta0 == 0.0 and a <= 0.0 <= b
        else:
            assert abs(p.theta0 - ref.theta0) <= 2e-8
