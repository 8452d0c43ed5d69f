"""A system's names and declared problems read from the compiled systems' index
(biped_opt/simulation/facts.py, compiled.system_facts) are the description's, and a problem is
checked the same against either."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from biped_opt.control.problems import Problem, get_problem
from biped_opt.errors import InvalidParameterError
from biped_opt.simulation.compiled import CompiledSystem, cached_facts, system_facts
from biped_opt.simulation.facts import SystemFacts, describe

from ..control.test_problems import _readme_blocks


@pytest.mark.parametrize("name", ["biped", "rocking_bar", "walker3_decoupled"])
def test_the_index_holds_the_descriptions_facts(name):
    CompiledSystem(name)  # (writes the index entry when it is not there)
    cached = cached_facts(name)
    assert cached is not None and cached.problems
    assert cached.as_json() == SystemFacts.of(describe(name)).as_json()
    assert system_facts(name) == cached


#: (problem fields, the message) on the rocking bar: every check that reads the facts
BAD = [({"maneuver": "fly"}, "unknown maneuver 'fly' (maneuvers: drop)"),
       ({"decisions": (("torque", (-1.0, 1.0)),)},
        "decision 'torque' is not an input of the system (inputs: u_th)"),
       ({"fixed": (("g", 1.0),)}, "fixed input 'g' is not an input"),
       ({"final_state": (("spin", 1.0, 0.0),)},
        "'spin' is not a coordinate or velocity (x, z, th, x_dot"),
       ({"parameters": (("mass", 2.0),)}, "unknown parameter 'mass' (parameters: ")]


@pytest.mark.parametrize(("fields", "message"), BAD, ids=[m[:20] for _, m in BAD])
def test_a_problem_is_checked_the_same_from_the_index_and_the_description(fields, message):
    CompiledSystem("rocking_bar")
    spec = {"maneuver": "drop", "decisions": (("u_th", (-1.0, 1.0)),), **fields}
    errors = []
    for system in ("rocking_bar", describe("rocking_bar")):  # (index, description)
        with pytest.raises(InvalidParameterError) as info:
            Problem(system=system, **spec)
        errors.append(str(info.value))
    assert message in errors[0] and errors[0] == errors[1]


def test_problems_json_cannot_carry_are_read_from_the_description(tmp_path: Path):
    """A declared problem with a float32 target: the index keeps no problems for the system,
    and its problems come from the description (the same numbers)."""
    system_file = _readme_blocks("Your own system", "python")[0]
    path = tmp_path / "hopper.py"
    path.write_text("import numpy as np\n" + system_file + textwrap.dedent("""
        hop.problem("far", maneuver="bounce", decisions={"push": (0.0, 2.0)},
                    target=np.float32(0.5))
    """))
    CompiledSystem(str(path))
    assert cached_facts(str(path)) is None
    assert system_facts(str(path)).problems["far"]["target"] == 0.5
    assert get_problem(str(path), "far").target == 0.5


def test_a_problems_description_is_the_system_also_for_a_path_like_name():
    """The facts serve the checks; ``description`` is the System (built by describe, the one
    every problem on it shares), also for a system given as a path-like name."""
    problem = Problem(system=Path("rocking_bar"), maneuver="drop",
                      decisions=(("u_th", (-1.0, 1.0)),))
    assert problem.facts.name == "rocking_bar"
    assert problem.description is describe("rocking_bar")
    assert problem.description.name == "rocking_bar"
