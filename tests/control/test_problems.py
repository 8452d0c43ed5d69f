"""Problems on any system: declared by a system, or written in a YAML or Python file."""

from __future__ import annotations

import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

from biped_opt.control.problems import Problem, get_problem, load_problem
from biped_opt.control.solve import compiled_for, optimal_policy
from biped_opt.errors import InvalidParameterError

#: the manual's tutorial that README's "Your own system" points to
TUTORIAL = Path(__file__).resolve().parents[2] / "docs" / "tutorials" / "own_system.md"


def _readme_blocks(section: str, lang: str) -> list[str]:
    text = TUTORIAL.read_text()
    part = text[text.index(f"## {section}"):]
    end = part.find("\n## ", 3)  # (to the next section, or the page's end)
    part = part if end < 0 else part[:end]
    return re.findall(rf"```{lang}\n(.*?)```", part, re.S)


@pytest.fixture(scope="module")
def hopper(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tutorial's hopper (compiled once for the tutorial's own test: same content, same
    cache entry), plus a declared problem (problems do not change the compiled module)."""
    folder = tmp_path_factory.mktemp("hopper")
    system_file = _readme_blocks("Your own system", "python")[0]
    (folder / "hopper.py").write_text(system_file + textwrap.dedent("""
        hop.problem("far", maneuver="bounce", decisions={"push": (0.0, 2.0)},
                    weights={"push": 0.01}, target=0.6)
    """))
    return folder


def test_the_biped_declares_the_papers_problems() -> None:
    """Eq. (14): u1, u2 in [-0.5, 1.5], th* = -0.1, alpha = (3e-4, 3e-3); Eq. (15): u12 in
    [-0.5, 0.5] with u1 = 1.5, u2 = 3 fixed, th* = 0.01, alpha = 0.01."""
    td = get_problem("biped", "touchdown")
    assert td.decisions == (("u1", (-0.5, 1.5)), ("u2", (-0.5, 1.5)))
    assert td.weights == pytest.approx((3e-4, 3e-3), rel=1e-15) and td.target == -0.1
    lo = get_problem("biped", "liftoff")
    assert lo.decisions == (("u12", (-0.5, 0.5)),) and lo.weights == (0.01,)
    assert list(lo.inputs()) == [1.5, 3.0, 0.0] and lo.target == 0.01


def test_the_readme_problem_file_runs_next_to_the_system_file(hopper: Path) -> None:
    """The tutorial's problem file, as written: the system path is relative to the file, the
    final-state term enters the cost, and the optimum is the brute-force one."""
    (problem_text,) = _readme_blocks("Problems on any system", "yaml")
    (hopper / "far.yaml").write_text(problem_text)
    problem = load_problem(hopper / "far.yaml")
    assert problem.name == "far" and problem.description.name == "hopper"
    names = [*problem.description.coordinate_names, *(str(v) for v in problem.description.dq)]
    y = np.zeros(len(names))
    y[names.index("z_dot")] = 0.1
    w, r = dict((k, (a, b)) for k, a, b in problem.final_state)["z_dot"]
    alpha = problem.weights[0]
    by_hand = problem.outcome_weight * (0.3 - problem.target) ** 2 + w * (0.1 - r) ** 2 \
        + alpha * 1.0
    assert float(problem.cost(0.3, y, [1.0])) == pytest.approx(by_hand, rel=1e-15)
    result = optimal_policy(problem, 0.3)
    assert result.success and result.active == "push"
    lo, hi = problem.bound("push")
    grid = np.linspace(lo, hi, 2001)
    compiled = compiled_for(problem)
    out = compiled.simulate_batch("bounce", np.full(grid.size, 0.3), grid[:, None])
    brute = np.min(problem.cost(out["outcome"], out["y_final"], grid[:, None]))
    # never worse than a 2001-point grid; better by at most the grid's O(h^2) gap
    assert result.value <= brute + 1e-12
    assert result.value == pytest.approx(brute, abs=1e-5)


def test_python_problem_file_and_declared_problem(hopper: Path) -> None:
    (hopper / "squat_problem.py").write_text(textwrap.dedent(f"""
        from biped_opt.control.problems import get_problem
        PROBLEM = get_problem({str(hopper / 'hopper.py')!r}, "far")
    """))
    problem = load_problem(hopper / "squat_problem.py")
    assert problem.name == "far" and problem.target == 0.6
    same = load_problem("far", system=str(hopper / "hopper.py"))
    assert same.decisions == problem.decisions


@pytest.mark.parametrize(("text", "message"), [
    ("system: rocking_bar\nmaneuver: drop\ndecisions: {u_th: [-1, 1]}\ncolour: red\n",
     "unknown key 'colour'"),
    ("system: rocking_bar\nmaneuver: fly\ndecisions: {u_th: [-1, 1]}\n", "unknown maneuver"),
    ("system: rocking_bar\nmaneuver: drop\ndecisions: {torque: [-1, 1]}\n",
     "decision 'torque' is not an input"),
    ("system: rocking_bar\nmaneuver: drop\ndecisions: {u_th: [1, -1]}\n", "lower < upper"),
    ("system: rocking_bar\nmaneuver: drop\ndecisions: {u_th: [-1]}\n", "[lower, upper]"),
    ("system: rocking_bar\nmaneuver: drop\ndecisions: {}\n", "at least one decision"),
    ("system: rocking_bar\nmaneuver: drop\ndecisions: {u_th: [-1, 1]}\nweights: {g: 1}\n",
     "'g' is not a decision"),
    ("system: rocking_bar\nmaneuver: drop\ndecisions: {u_th: [-1, 1]}\ntarget: .nan\n",
     "target must be a finite number"),
    ("system: rocking_bar\nmaneuver: drop\ndecisions: {u_th: [-1, 1]}\n"
     "final_state: {spin: [1, 0]}\n", "'spin' is not a coordinate or velocity"),
    ("system: rocking_bar\nmaneuver: drop\ndecisions: {u_th: [-1, 1]}\n"
     "parameters: {mass: 2}\n", "unknown parameter 'mass'"),
    ("maneuver: drop\ndecisions: {u_th: [-1, 1]}\n", "'system' is missing"),
    ("system: rocking_bar\nmaneuver: drop\ndecisions: [u_th]\n", "must be a mapping"),
    ("- just\n- a list\n", "must hold a mapping"),
    ("system: rocking_bar\nmaneuver: [\n", "not valid YAML"),
    ("system: nowhere.py\nmaneuver: drop\ndecisions: {u_th: [-1, 1]}\n", "no such system file"),
])
def test_bad_problem_files_get_one_clear_message(tmp_path: Path, text: str,
                                                 message: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(Exception) as info:
        load_problem(path)
    assert message in str(info.value) and "\n" not in str(info.value)
    assert isinstance(info.value, ValueError)  # a BipedOptError/ValueError, never a KeyError


def test_unknown_declared_problem_lists_the_known_ones() -> None:
    with pytest.raises(InvalidParameterError, match="problems: drop"):
        get_problem("rocking_bar", "spin")
    with pytest.raises(InvalidParameterError, match="no such problem file"):
        load_problem("missing.yaml")


def test_problem_round_trips_through_its_mapping() -> None:
    problem = get_problem("walker3_decoupled", "liftoff_variant")
    again = Problem.from_spec(problem.as_dict())
    assert again.decisions == problem.decisions and again.weights == problem.weights
    assert again.target == problem.target and again.fixed == problem.fixed
