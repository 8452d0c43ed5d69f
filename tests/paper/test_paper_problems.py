"""Problems as values: MODEL.md Sec. 5 defaults, the cost of Eqs. (14)-(15), validation."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from biped_opt.errors import BipedOptError, InvalidInputError, InvalidParameterError
from biped_opt.paper.biped import Maneuver
from biped_opt.paper.problems import (
    OptimalControlProblem,
    get_problem,
    liftoff_problem,
    liftoff_variant_problem,
    touchdown_problem,
)


def test_defaults_are_model_md_section_5():
    td = touchdown_problem()
    assert td.maneuver is Maneuver.TOUCHDOWN
    assert td.decisions == ("u1", "u2")
    assert td.bounds == ((-0.5, 1.5), (-0.5, 1.5))
    assert (td.theta_star, td.alphas) == (-0.1, (3e-4, 3e-3))
    lo = liftoff_problem()
    assert lo.maneuver is Maneuver.LIFTOFF and lo.decisions == ("u12",)
    assert lo.fixed_inputs == (1.5, 3.0, 0.0)
    assert (lo.bounds, lo.theta_star, lo.alphas) == (((-0.5, 0.5),), 0.01, (0.01,))
    va = liftoff_variant_problem()
    assert va.decisions == ("u1", "u2") and va.fixed_inputs[2] == 0.0
    assert (va.bounds, va.theta_star, va.alphas) == (((0.0, 3.0), (0.0, 3.0)), -0.02,
                                                     (1e-5, 2e-5))


def test_cost_is_eq_14_and_15_over_decisions_only():
    td = touchdown_problem()
    assert td.cost(0.05, (1.0, 0.5, 0.2)) == pytest.approx(
        (0.05 + 0.1) ** 2 + 3e-4 * 1.0 + 3e-3 * 0.25, rel=1e-15
    )
    lo = liftoff_problem()
    # the fixed u1 = 1.5, u2 = 3 carry no weight (Eq. (15))
    assert lo.cost(0.03, lo.inputs({"u12": 0.2})) == pytest.approx(
        (0.03 - 0.01) ** 2 + 0.01 * 0.04, rel=1e-15
    )
    batch = td.cost(np.array([0.0, 0.1]), np.zeros((2, 3)))
    assert batch.shape == (2,) and batch[1] == pytest.approx(0.04)


def test_inputs_fill_fixed_and_default_decisions():
    lo = liftoff_problem()
    assert lo.inputs().tolist() == [1.5, 3.0, 0.0]
    assert lo.inputs({"u12": -0.1}).tolist() == [1.5, 3.0, -0.1]
    # a decision that cannot act sits at the bound point nearest 0
    shifted = touchdown_problem().with_bounds("u2", 0.2, 1.0)
    assert shifted.default_decision("u2") == 0.2
    with pytest.raises(InvalidInputError, match="u12"):
        touchdown_problem().inputs({"u12": 1.0})


def test_overrides_by_replace_and_helpers():
    td = dataclasses.replace(touchdown_problem(), theta_star=-0.2)
    assert td.theta_star == -0.2
    assert td.with_alpha("u2", 1e-2).alphas == (3e-4, 1e-2)
    assert td.with_bounds("u1", -1.0, 2.0).bound("u1") == (-1.0, 2.0)
    assert get_problem("Liftoff-Variant", theta_star=0.0).theta_star == 0.0


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"theta_star": math.nan}, "theta_star"),
        ({"bounds": ((1.5, -0.5), (-0.5, 1.5))}, r"bounds\[u1\]"),
        ({"bounds": ((-0.5, 1.5),)}, "bounds"),
        ({"alphas": (3e-4, -1.0)}, r"alphas\[u2\]"),
        ({"decisions": ("u1", "u3")}, "decisions"),
        ({"maneuver": "walk"}, "maneuver"),
        ({"fixed_inputs": (0.0, math.inf, 0.0)}, r"fixed_inputs\[u2\]"),
    ],
)
def test_validation_names_the_field(change, field):
    with pytest.raises(InvalidParameterError, match=field) as info:
        dataclasses.replace(touchdown_problem(), **change)
    assert isinstance(info.value, (BipedOptError, ValueError))


def test_unknown_names():
    with pytest.raises(InvalidInputError, match="problem must be one of"):
        get_problem("hop")
    with pytest.raises(InvalidInputError, match="not a decision"):
        liftoff_problem().alpha("u1")
    assert isinstance(OptimalControlProblem(), OptimalControlProblem)
