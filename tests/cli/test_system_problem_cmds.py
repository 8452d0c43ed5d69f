"""``optimise``, ``sweep`` and ``nonsmooth`` with ``--system``/``--problem``: any system's
optimal control and nonsmooth tables from the command line, and one line for each mistake."""

from __future__ import annotations

import json

import pytest

from biped_opt.control.problems import get_problem
from biped_opt.control.solve import optimal_policy
from tests.cli.test_systems_cmd import _run


def test_optimise_a_declared_problem_as_json(capsys):
    status, out, err = _run(["optimise", "--system", "rocking_bar", "--problem", "drop",
                             "--s", "0.05", "--json"], capsys)
    assert status == 0 and err == ""
    got = json.loads(out)
    direct = optimal_policy(get_problem("rocking_bar", "drop"), 0.05)
    assert got["value"] == direct.value and got["policy"] == direct.policy  # same solver
    assert got["problem"]["decisions"] == {"u_th": [-0.5, 0.5]}


def test_maneuver_names_the_declared_problem_and_param_overrides(capsys):
    status, out, _ = _run(["optimise", "--system", "rocking_bar", "--maneuver", "drop",
                           "--s", "0.05", "--param", "gamma=0.3", "--json"], capsys)
    assert status == 0
    got = json.loads(out)
    assert got["problem"]["parameters"] == {"gamma": 0.3}
    assert got["value"] != optimal_policy(get_problem("rocking_bar", "drop"), 0.05).value


def test_problem_file_alone_selects_its_system(tmp_path, capsys):
    (tmp_path / "bar.yaml").write_text(
        "system: rocking_bar\nmaneuver: drop\ndecisions: {u_th: [-0.2, 0.2]}\n"
        "weights: {u_th: 0.1}\ntarget: 0.02\n")
    status, out, _ = _run(["optimise", "--problem", str(tmp_path / "bar.yaml"), "--s", "0.1"],
                          capsys)
    assert status == 0
    assert "problem    bar  (rocking_bar, maneuver drop)" in out


def test_fixed_sweep_to_json_file(tmp_path, capsys):
    path = tmp_path / "bar.json"
    status, out, _ = _run(["sweep", "--system", "rocking_bar", "--maneuver", "drop", "--num", "5",
                           "--out", str(path)], capsys)
    assert status == 0 and "wrote 5 points" in out
    data = json.loads(path.read_text())
    assert data["s"] == pytest.approx([-0.3, -0.15, 0.0, 0.15, 0.3], abs=1e-15)
    assert data["s"][2] == 0.0
    assert data["outcome"][2] == 0.0 and data["branch"][2] == "air->air[left+right]"


def test_optimal_sweep_of_a_problem(capsys):
    status, out, _ = _run(["sweep", "--system", "walker3_coupled", "--problem", "touchdown",
                           "--num", "3", "--s-min", "-0.1", "--s-max", "0.1"], capsys)
    assert status == 0
    lines = out.strip().splitlines()
    assert len(lines) == 4 and "u3=" in lines[1]


def test_nonsmooth_of_any_system(capsys):
    status, out, _ = _run(["nonsmooth", "--system", "walker3_coupled", "--maneuver", "touchdown",
                           "--input", "u1=2", "--input", "u2=1", "--input", "u3=0.5", "--json"],
                          capsys)
    assert status == 0
    (point,) = json.loads(out)
    assert point["theta0"] == 0.0 and point["kind"] == "kink"
    assert point["derivatives"] == pytest.approx([0.8732676633, 0.8395968313], abs=1e-7)


@pytest.mark.parametrize(("argv", "message"), [
    (["optimise", "--system", "rocking_bar", "--problem", "drop", "--theta0", "0.1"],
     "--theta0: the biped's option"),
    (["optimise", "--system", "rocking_bar", "--problem", "drop"], "--s is required"),
    (["optimise", "--system", "rocking_bar", "--problem", "spin", "--s", "0"],
     "unknown problem 'spin'"),
    (["optimise", "--system", "rocking_bar", "--maneuver", "fly", "--s", "0"],
     "declares no problem named like --maneuver"),
    (["optimise", "--system", "nowhere.py", "--problem", "drop", "--s", "0"],
     "no such system file"),
    (["optimise", "--maneuver", "touchdown", "--s", "0.1"], "--s: only with --system"),
    (["optimise", "--maneuver", "touchdown"], "--theta0 is required"),
    (["sweep", "--system", "rocking_bar", "--maneuver", "drop", "--s-min", "0.2", "--s-max",
      "0"], "lo < hi"),
    (["sweep", "--system", "rocking_bar", "--maneuver", "drop", "--s-min", "1", "--s-max",
      "0"], "--s-min: s = 1 is outside the valid range [-0.3, 0.3] of the drop maneuver"),
    (["sweep", "--system", "rocking_bar", "--maneuver", "drop", "--input", "torque=1"],
     "unknown input 'torque'"),
    (["nonsmooth", "--system", "rocking_bar", "--maneuver", "fly"], "unknown maneuver 'fly'"),
    (["sweep", "--system", "rocking_bar", "--u1", "2", "--maneuver", "drop"],
     "--u1: the biped's option"),
    (["nonsmooth", "--system", "rocking_bar", "--variant", "--maneuver", "drop"],
     "--variant: the biped's option"),
    (["sweep", "--system", "rocking_bar"], "--maneuver is required"),
])
def test_mistakes_get_one_line_and_status_2(argv, message, capsys):
    status, out, err = _run(argv, capsys)
    assert status == 2 and out == ""
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
