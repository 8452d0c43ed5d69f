"""A second process starts a cached system from the index without deriving or rendering it, and
a changed system file misses the index instead of serving what it described before."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from biped_opt.simulation.compiled import CompiledSystem

ROOT = Path(__file__).resolve().parents[2]

# Run in a fresh interpreter: count the calls of derive, simulate once, then read .derived (which
# must derive now, lazily), and report what was imported before that.
_PROBE = """
import json, sys
import biped_opt.systems.derive
D = sys.modules["biped_opt.systems.derive"]  # (the package's attribute is the function)
calls = []
real = D.derive
D.derive = lambda system: calls.append(system.name) or real(system)
from biped_opt.simulation.compiled import CompiledSystem
c = CompiledSystem(sys.argv[1])
tr = c.simulate(c.maneuvers[0], 0.1, sample_dt=0.05)
report = {"derive_calls": len(calls), "codegen": "biped_opt.codegen.render" in sys.modules,
          "outcome": tr.outcome, "status": tr.status.name, "parameters": c.parameters,
          "maneuvers": list(c.maneuvers), "inputs": list(c.inputs), "name": c.name}
report["constraints"] = list(c.derived.constraint_names)
report["derive_calls_after"] = len(calls)
print(json.dumps(report))
"""


def _probe(spec: str) -> dict:
    path = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    env = dict(os.environ, PYTHONPATH=path)
    done = subprocess.run([sys.executable, "-c", _PROBE, spec], env=env, capture_output=True,
                          text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def _check_hit(report: dict, here: CompiledSystem) -> None:
    assert report["derive_calls"] == 0 and not report["codegen"]
    # the same compiled module on the same inputs: the same floating-point operations, so the
    # outcome agrees to rounding (1e-12 relative leaves room for nothing else)
    ref = here.simulate(here.maneuvers[0], 0.1, sample_dt=0.05)
    assert report["status"] == ref.status.name == "OK"
    assert report["outcome"] == pytest.approx(ref.outcome, rel=1e-12, abs=1e-14)
    assert report["parameters"] == here.parameters
    assert (report["name"], report["maneuvers"], report["inputs"]) == \
        (here.name, list(here.maneuvers), list(here.inputs))
    # .derived is still there when asked for, derived then
    assert report["constraints"] == list(here.derived.constraint_names)
    assert report["derive_calls_after"] == 1


def test_library_system_starts_from_the_index():
    here = CompiledSystem("rocking_bar")  # (writes the index entry if this checkout lacks it)
    _check_hit(_probe("rocking_bar"), here)


def test_system_file_starts_from_the_index_and_a_changed_file_misses(tmp_path):
    path = tmp_path / "bar.py"
    # the library's bar from a file: the same generated module, so nothing compiles afresh
    path.write_text("from biped_opt.systems.library import rocking_bar\n"
                    "SYSTEM = rocking_bar()\n")
    here = CompiledSystem(str(path))
    _check_hit(_probe(str(path)), here)
    # a new default changes no generated code, only the description: it must still miss
    path.write_text("from biped_opt.systems.library import rocking_bar\n"
                    "SYSTEM = rocking_bar()\n"
                    "SYSTEM.defaults['g'] = 2.0\n")
    changed = _probe(str(path))
    assert changed["derive_calls"] == 1 and changed["codegen"]
    assert changed["parameters"]["g"] == 2.0
    again = _probe(str(path))  # and the entry the miss wrote serves the next start
    assert again["derive_calls"] == 0 and again["parameters"]["g"] == 2.0
    assert again["outcome"] == pytest.approx(changed["outcome"], rel=1e-12, abs=1e-14)


# The command line's cached start: the whole `biped-opt simulate` in a fresh interpreter, then
# what it imported. A user's file that prints when run tells whether it ran.
_CLI_PROBE = """
import contextlib, io, json, sys
from biped_opt.cli.main import main
out = io.StringIO()
with contextlib.redirect_stdout(out):
    rc = main(sys.argv[1:])
print(json.dumps({"rc": rc, "stdout": out.getvalue(), "sympy": "sympy" in sys.modules,
                  "scipy.optimize": "scipy.optimize" in sys.modules,
                  "derive": "biped_opt.systems.derive" in sys.modules}))
"""


def _cli(*args: str) -> dict:
    path = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    done = subprocess.run([sys.executable, "-c", _CLI_PROBE, *args], capture_output=True,
                          text=True, timeout=300, check=False,
                          env=dict(os.environ, PYTHONPATH=path))
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("json_out", [False, True])
def test_cli_simulate_of_a_cached_file_runs_neither_sympy_nor_the_file(tmp_path, json_out):
    path = tmp_path / "bar.py"
    path.write_text("print('the file ran')\n"
                    "from biped_opt.systems.library import rocking_bar\n"
                    "SYSTEM = rocking_bar()\n")
    args = ["simulate", "--system", str(path), "--maneuver", "drop", "--s", "0.1"]
    first = _cli(*args, *(["--json"] if json_out else []))  # (compiles, or reads the index)
    again = _cli(*args, *(["--json"] if json_out else []))
    assert first["rc"] == again["rc"] == 0
    assert again["stdout"] == first["stdout"].replace("the file ran\n", "")
    assert "the file ran" not in again["stdout"]
    assert not again["sympy"] and not again["scipy.optimize"] and not again["derive"]
    if json_out:  # the coordinates by name, from the index
        state = json.loads(again["stdout"])["state"]
        assert list(state["q"]) == list(CompiledSystem(str(path)).coordinates)


def test_cli_simulate_of_the_biped_imports_no_sympy():
    _cli("simulate", "--maneuver", "touchdown", "--theta0", "0.1")  # (the index entry)
    again = _cli("simulate", "--maneuver", "touchdown", "--theta0", "0.1", "--u1", "2")
    assert again["rc"] == 0 and "outcome" in again["stdout"]
    assert not again["sympy"] and not again["scipy.optimize"]
