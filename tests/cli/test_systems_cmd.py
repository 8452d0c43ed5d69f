"""``biped-opt simulate --system`` and ``biped-opt systems``: any system from the command line,
and one clear line for every mistake in a system file or an option."""

from __future__ import annotations

import json

import pytest

from biped_opt.cli.main import main


def _run(argv, capsys):
    try:
        status = main(argv)
    except SystemExit as exc:
        status = exc.code
    out, err = capsys.readouterr()
    return status, out, err


def test_simulate_a_library_system_as_json(capsys):
    status, out, err = _run(["simulate", "--system", "rocking_bar", "--maneuver", "drop",
                             "--s", "-1e-6", "--json"], capsys)
    assert status == 0 and err == ""
    tr = json.loads(out)
    assert tr["outcome"] == pytest.approx(0.1988749738, abs=1e-9)  # SYSTEMS.md, mirrored
    assert [e["touchdown"] for e in tr["events"]] == [["right"], ["left"], ["right"]]
    assert tr["parameters"]["gamma"] == 0.5 and set(tr["state"]["q"]) == {"x", "z", "th"}


def test_parameters_and_inputs_by_name(capsys):
    base = ["simulate", "--system", "rocking_bar", "--maneuver", "drop", "--s", "0.1", "--json"]
    _, plain, _ = _run(base, capsys)
    status, pushed, _ = _run([*base, "--input", "u_th=0.5", "--param", "gamma=0.2"], capsys)
    assert status == 0
    a, b = json.loads(plain), json.loads(pushed)
    assert b["inputs"] == {"u_th": 0.5} and b["parameters"]["gamma"] == 0.2
    assert a["outcome"] != b["outcome"]


def test_systems_lists_the_library(capsys):
    status, out, _ = _run(["systems", "--json"], capsys)
    rows = {r["name"]: r for r in json.loads(out)}
    assert status == 0 and {"biped", "walker", "rocking_bar"} <= set(rows)
    assert (rows["biped"]["d"], rows["biped"]["n"]) == (7, 2)
    assert (rows["walker"]["d"], rows["walker"]["n"]) == (9, 3)
    assert rows["rocking_bar"]["inputs"] == ["u_th"]
    status, out, _ = _run(["systems", "walker4_decoupled", "--json"], capsys)
    assert json.loads(out)[0]["d"] == 11


BROKEN = {
    "syntax.py": ("def f(:\n", "syntax.py:"),
    "shape.py": ("import sympy as sp\nfrom biped_opt.systems import System\n"
                 "s = System('b', ['x', 'z'])\ns.mass_matrix = sp.eye(3)\n"
                 "s.forces = lambda J: [0, -1]\ns.constraint('floor', s.q[1])\nSYSTEM = s\n",
                 "shape.py: b: mass_matrix: must be 2x2, got 3x3"),
    "unknown.py": ("import sympy as sp\nfrom biped_opt.systems import System\n"
                   "s = System('b', ['x', 'z'])\ns.mass_matrix = sp.eye(2)\n"
                   "s.forces = lambda J: [0, -sp.Symbol('gravity')]\n"
                   "s.constraint('floor', s.q[1])\nSYSTEM = s\n",
                   "unknown.py: b: forces in mode {}: uses gravity"),
}


@pytest.mark.parametrize("name", sorted(BROKEN))
def test_a_broken_system_file_is_one_line(tmp_path, capsys, name):
    text, fragment = BROKEN[name]
    path = tmp_path / name
    path.write_text(text)
    for argv in (["simulate", "--system", str(path), "--maneuver", "m", "--s", "0"],
                 ["systems", str(path)]):
        status, out, err = _run(argv, capsys)
        assert status == 2 and err.count("\n") == 1 and "Traceback" not in err, err
        assert fragment in err


@pytest.mark.parametrize(("argv", "fragment"), [
    (["--system", "rocking_bar", "--maneuver", "drop"], "--s is required with --system"),
    (["--system", "rocking_bar", "--maneuver", "drop", "--s", "0", "--theta0", "0"],
     "--theta0/--u1/--u2/--u12: the biped's options"),
    (["--system", "rocking_bar", "--maneuver", "hop", "--s", "0"], "unknown maneuver 'hop'"),
    (["--system", "rocking_bar", "--maneuver", "drop", "--s", "nan"], "--s must be finite"),
    (["--system", "rocking_bar", "--maneuver", "drop", "--s", "0", "--input", "u_th"],
     "--input must look like NAME=VALUE"),
    (["--system", "rocking_bar", "--maneuver", "drop", "--s", "0", "--param", "k=2"],
     "unknown parameter 'k'"),
    (["--system", "hexapod", "--maneuver", "trot", "--s", "0"], "unknown system 'hexapod'"),
    (["--maneuver", "touchdown", "--s", "0"], "--s: only with --system"),
    (["--maneuver", "touchdown"], "--theta0 is required"),
])
def test_bad_system_options_are_one_line(capsys, argv, fragment):
    status, _out, err = _run(["simulate", *argv], capsys)
    assert status == 2 and err.count("\n") == 1 and fragment in err, err
