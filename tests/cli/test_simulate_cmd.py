"""``biped-opt simulate`` end to end, as a user runs it (a subprocess)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.conftest import REFERENCE


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "biped_opt.cli.main", *args],
        capture_output=True, text=True, timeout=120,
    )


def test_json_reproduces_r1():
    maneuver, theta0, u, expected = REFERENCE["R1"]
    proc = run_cli("simulate", "--maneuver", maneuver, "--theta0", repr(theta0),
                   "--u1", repr(u[0]), "--u2", repr(u[1]), "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert abs(out["outcome"] - expected) <= 1e-9
    assert out["status"] == "ok"
    assert [m["mode"] for m in out["modes"]] == ["AIR", "LEFT", "GROUND"]
    assert out["modes"][0]["t"] == 0.0
    assert len(out["state"]["q"]) == 7 and len(out["state"]["qdot"]) == 7
    assert out["state"]["q"][2] == out["outcome"]
    assert out["nfev"] > 0 and out["t_final"] > out["modes"][-1]["t"]


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (("--maneuver", "touchdown", "--theta0", "nan"), "--theta0"),
        (("--maneuver", "touchdown", "--theta0", "inf"), "--theta0"),
        (("--maneuver", "touchdown", "--theta0", "0.4"), "--theta0"),
        (("--maneuver", "hop", "--theta0", "0.1"), "--maneuver"),
        (("--maneuver", "liftoff", "--theta0", "0.1", "--u12", "nan"), "--u12"),
        (("--maneuver", "liftoff", "--theta0", "abc"), "--theta0"),
    ],
)
def test_bad_arguments_exit_nonzero_with_one_line_naming_the_argument(args, named):
    proc = run_cli("simulate", *args)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and named in lines[0]


FREEZE_PROBE = """\
import gc, sys
from biped_opt.cli.main import {func}
try:
    status = {func}()
except SystemExit as exc:  # (argparse's refusal)
    status = exc.code
print(f"status {{status}} frozen {{gc.get_freeze_count()}}", file=sys.stderr)
"""


@pytest.mark.parametrize("theta0", ["0.01", "nan"])
def test_the_program_freezes_what_is_alive_as_it_ends_and_main_alone_does_not(theta0):
    """The console script's entry() leaves the process's objects out of the interpreter's last
    collections (the freeze count is what gc reports after it returns), on success and on a
    refusal alike, and the output is whole; main(), which tests and scripts call and then go on,
    freezes nothing."""
    args = ["simulate", "--maneuver", "touchdown", "--theta0", theta0, "--json"]
    for func, frozen in (("entry", True), ("main", False)):
        proc = subprocess.run([sys.executable, "-c", FREEZE_PROBE.format(func=func), *args],
                              capture_output=True, text=True, timeout=120)
        status, count = proc.stderr.strip().splitlines()[-1].split()[1::2]
        assert (int(count) > 1000) == frozen, (func, proc.stderr)
        if theta0 == "nan":
            assert status == "2" and "--theta0" in proc.stderr
        else:
            assert status == "0" and json.loads(proc.stdout)["status"] == "ok"
