"""The paper's problems are the library biped's declared problems, in the paper's words."""

from __future__ import annotations

import dataclasses

import pytest

from biped_opt.control.problems import get_problem as declared
from biped_opt.control.solve import compiled_for
from biped_opt.errors import InvalidParameterError
from biped_opt.paper.biped import BipedParams, compiled_biped
from biped_opt.paper.problems import LIBRARY_NAMES, get_problem, paper_branch, paper_problem
from biped_opt.simulation.options import SimulatorOptions


@pytest.mark.parametrize("name", list(LIBRARY_NAMES))
def test_each_paper_problem_is_the_declared_one(name: str) -> None:
    """Same maneuver, decisions with bounds, weights, target, and the same input vector (the
    fixed inputs); no parameters beyond the system's defaults."""
    mine, theirs = paper_problem(name), declared("biped", LIBRARY_NAMES[name])
    assert mine.name == name and mine.maneuver == theirs.maneuver
    assert mine.decisions == theirs.decisions and mine.weights == theirs.weights
    assert (mine.target, mine.outcome_weight) == (theirs.target, theirs.outcome_weight)
    assert mine.inputs().tolist() == theirs.inputs().tolist()
    assert mine.parameters == () and mine.options == theirs.options


def test_overrides_reach_the_one_problem() -> None:
    p = get_problem("liftoff", theta_star=0.02, alphas=(0.5,), bounds=((-0.3, 0.3),),
                    fixed_inputs=(1.0, 2.5, 0.0), params=BipedParams(k=30.0, c=0.1),
                    options=SimulatorOptions(rtol=1e-10))
    one = p.problem
    assert (one.target, one.weights, one.decisions) == (0.02, (0.5,), (("u12", (-0.3, 0.3)),))
    assert one.inputs({"u12": 0.1}).tolist() == [1.0, 2.5, 0.1]
    assert dict(one.parameters) == {"k": 30.0, "c": 0.1}
    assert one.options.rtol == 1e-10
    # the compiled system carries the parameters (one per parameter set)
    assert compiled_for(one).parameters["k"] == 30.0
    assert compiled_biped(BipedParams(k=30.0, c=0.1)) is compiled_for(one)
    # the cost is the one Problem's: (th_f - th*)^2 + alpha u12^2 over the decision only
    assert p.cost(0.05, (1.0, 2.5, 0.2)) == pytest.approx(0.03**2 + 0.5 * 0.04, rel=1e-15)
    with pytest.raises(InvalidParameterError, match="options"):
        dataclasses.replace(p, options={"rtol": 1e-9})


@pytest.mark.parametrize(("label", "words"), [
    ("air->left->left+right", "AIR->LEFT->GROUND"),
    ("left+right->right->air", "GROUND->RIGHT->AIR"),
    ("air->air[left]", "AIR->AIR[LEFT]"),
    ("FAILED:MAX_EVENTS", "FAILED:MAX_EVENTS"),
])
def test_branch_labels_in_the_papers_words(label: str, words: str) -> None:
    assert paper_branch(label) == words
