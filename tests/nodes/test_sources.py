"""What a request may name (biped_opt.nodes.sources), checked without a node: names only, the
library's systems and problems refused at once when they cannot be served, a study's problem
file naming a library system or a file beside it, sizes checked by a walker's name."""

from __future__ import annotations

import pytest

from biped_opt.errors import InvalidInputError
from biped_opt.nodes.sources import Sources, SystemLimits

BAR_PROBLEM = "maneuver: drop\ndecisions: {u_th: [-0.5, 0.5]}\n"


@pytest.mark.parametrize(("names", "message"), [
    (("rocking_bar", "nothing", "drop"), "problem: rocking_bar declares no problem 'nothing' "
                                         "(problems: drop) and this node has no system_paths"),
    (("rocking_bar", "", "hop"), "maneuver: rocking_bar has no maneuver 'hop'"),
    (("rocking_bar", "../p.yaml", "drop"), "problem: '../p.yaml' is not a problem name"),
    (("rocking_bar", "", "a b"), "maneuver: 'a b' is not a maneuver name"),
    (("bar.py", "", "drop"), "system: 'bar.py' is not a system name"),
    (("walker9", "", "touchdown"), "system: walker9 has 9 constraints and 21 coordinates; "
                                   "this node serves at most 6 and 16"),
    (("chain11", "", "drop"), "system: chain11 has 2 constraints and 11 coordinates; this "
                              "node serves at most 6 and 8"),
    (("quadruped", "", "drop"), "system: quadruped has 4 constraints and 20 coordinates; this "
                                "node serves at most 6 and 16"),
])
def test_a_request_naming_what_no_compile_can_serve_is_refused(names, message, monkeypatch):
    # sizes come from the name alone: building the quadruped's description takes seconds, so
    # none is built (a factory that raises proves it)
    from biped_opt.systems import library

    def never(*_args, **_kwargs):
        raise AssertionError("a description was built")

    monkeypatch.setitem(library.BY_NAME, "quadruped", never)
    limits = SystemLimits(max_coordinates=8) if names[0] == "chain11" else SystemLimits()
    with pytest.raises(InvalidInputError) as err:
        Sources(limits=limits).check_request(*names)
    assert str(err.value).startswith(message), err.value


def test_a_library_system_built_only_when_named_waits_for_the_compiler(monkeypatch):
    """Within the limits, the quadruped's name passes the service's check unbuilt, as a file's
    does: its description (seconds of SymPy) is the compiler process's work."""
    from biped_opt.systems import library

    def never(*_args, **_kwargs):
        raise AssertionError("a description was built")

    monkeypatch.setitem(library.BY_NAME, "quadruped", never)
    names = Sources(limits=SystemLimits(max_coordinates=20)).check_request(
        "quadruped", "", "drop")
    assert (names.source, names.checked) == ("quadruped", False)


def test_a_work_item_names_no_maneuver_and_a_served_request_passes():
    Sources().check_request("rocking_bar", "")  # (a study's maneuver is checked by Study)
    Sources().check_request("rocking_bar", "drop", "drop")
    Sources().check_request("", "", "touchdown")  # "": the biped


def test_a_study_problem_file_names_a_library_system_or_a_file_beside_it(tmp_path):
    sources = Sources((tmp_path,), SystemLimits(max_legs=3))
    (tmp_path / "near.yaml").write_text("system: bar.py\n" + BAR_PROBLEM)
    (tmp_path / "library.yaml").write_text("system: rocking_bar\n" + BAR_PROBLEM)
    (tmp_path / "far.yaml").write_text("system: ../bar.py\n" + BAR_PROBLEM)
    (tmp_path / "large.yaml").write_text("system: walker5\n" + BAR_PROBLEM)
    assert sources.study("rocking_bar", "near") == ("rocking_bar", str(tmp_path / "near.yaml"))
    assert sources.study("rocking_bar", "library")[1] == str(tmp_path / "library.yaml")
    assert sources.study("rocking_bar", "drop") == ("rocking_bar", "drop")  # declared
    with pytest.raises(InvalidInputError, match=r"^problem: far.yaml: system: a study's "
                                                r"problem file names a library system"):
        sources.study("rocking_bar", "far")
    with pytest.raises(InvalidInputError, match=r"^problem: large.yaml: system: walker5 has 5 "
                                                r"constraints"):
        sources.study("rocking_bar", "large")
    with pytest.raises(InvalidInputError, match=r"declares no problem 'none' \(problems: drop\) "
                                                r"and system_paths has no such file$"):
        sources.study("rocking_bar", "none")


def test_checked_names_are_resolved_once_and_the_compile_checks_only_what_needs_the_system(
        tmp_path):
    """A request's names are checked at the edge and come back resolved; building the problem
    from them (the compile) checks only what the edge could not see: a file's description
    and maneuvers, and the problem found against the system and maneuver asked."""
    (tmp_path / "bar_copy.py").write_text(
        "from biped_opt.systems.library import rocking_bar\nSYSTEM = rocking_bar()\n")
    sources = Sources((tmp_path,))
    library = sources.check_request("rocking_bar", "", "drop")
    assert (library.source, library.checked) == ("rocking_bar", True)
    problem = sources.problem(library)
    assert (problem.name, problem.maneuver, problem.description.name) == \
        ("drop", "drop", "rocking_bar")
    # a file's description runs its code: its maneuver is checked by the compile, with the
    # message the edge gives for a library system
    names = sources.check_request("bar_copy", "", "hop")
    assert (names.source, names.checked) == (str(tmp_path / "bar_copy.py"), False)
    with pytest.raises(InvalidInputError, match=r"^maneuver: rocking_bar has no maneuver 'hop'"):
        sources.problem(names)
    # a declared problem on another maneuver than the one asked
    names = sources.check_request("rocking_bar", "drop", "hop")
    with pytest.raises(InvalidInputError, match=r"^maneuver: problem drop is on maneuver 'drop', "
                                                r"not 'hop'"):
        sources.problem(names)


@pytest.mark.parametrize("name", ["biped", "walker", "rocking_bar", "chain", "walker2", "chain7"])
def test_sizes_by_name_are_the_descriptions(name):
    """The sizes a node checks before building anything are the built descriptions' (the
    quadruped's: tests/systems/test_quadruped.py)."""
    from biped_opt.systems import load_system
    from biped_opt.systems.files import library_size

    system = load_system(name)
    assert library_size(name) == (len(system.constraints), len(system.q))


def test_a_urdf_of_system_paths_is_named_by_its_stem(tmp_path):
    """``<dir>/<name>.urdf`` is found like ``<dir>/<name>.py`` (a .py file first in the same
    directory; the first directory that has either), and like a file waits for the compiler:
    its import is not done on the serving thread."""
    first, second = tmp_path / "a", tmp_path / "b"
    first.mkdir()
    second.mkdir()
    (second / "robot.urdf").write_text("<robot name='r'/>")
    sources = Sources((first, second))
    assert sources.system("system", "robot") == str(second / "robot.urdf")
    names = sources.check_request("robot", "", "drop")
    assert (names.source, names.checked) == (str(second / "robot.urdf"), False)
    (first / "robot.urdf").write_text("<robot name='r'/>")
    assert sources.system("system", "robot") == str(first / "robot.urdf")
    (first / "robot.py").write_text("")
    assert sources.system("system", "robot") == str(first / "robot.py")
    with pytest.raises(InvalidInputError, match=r"nor other.py or other.urdf in the node's "):
        sources.system("system", "other")
    with pytest.raises(InvalidInputError, match=r"'robot.urdf' is not a system name"):
        sources.system("system", "robot.urdf")
    outside = tmp_path / "elsewhere.urdf"
    outside.write_text("<robot name='r'/>")
    (second / "linked.urdf").symlink_to(outside)
    with pytest.raises(InvalidInputError, match=r"a link to a file outside its directory"):
        sources.system("system", "linked")
