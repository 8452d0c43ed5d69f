"""The command-line tools on a robot given as its URDF (SYSTEMS.md Sec. 4a): simulate, sweep and
optimise of ``tests/systems/urdf/hopper.urdf`` (a body on a floating base, two legs of one
hinge, a ball at each foot; d = 8), its options in the file-argument grammar, and the errors a
user sees. The hopper compiles once for this module (one worker) and is cached for the next
run."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from biped_opt.simulation.compiled import CompiledSystem
from tests.cli.test_systems_cmd import _run

HOPPER = Path(__file__).resolve().parents[1] / "systems" / "urdf" / "hopper.urdf"


@pytest.fixture(scope="module")
def hopper():
    """The hopper compiled once for the module (the commands below load it from the cache)."""
    return CompiledSystem(str(HOPPER))


def test_simulate_a_urdf_as_json(hopper, capsys):
    status, out, err = _run(["simulate", "--system", str(HOPPER), "--maneuver", "drop",
                             "--s", "0.05", "--json"], capsys)
    assert status == 0 and err == ""
    got = json.loads(out)
    direct = hopper.simulate("drop", 0.05)
    assert got["status"] == "ok" and got["outcome"] == direct.outcome
    assert [e["t"] for e in got["events"]] == [e.t for e in direct.contact_events]
    # the lower foot (rolled by s > 0: the right one, at -y) lands first
    assert got["events"][0]["touchdown"] == ["right_foot"]


def test_efforts_are_the_inputs_named_after_the_joints(hopper, capsys):
    status, out, _ = _run(["simulate", "--system", str(HOPPER), "--maneuver", "drop",
                           "--s", "0.05", "--input", "left_hip_effort=1.5", "--json"], capsys)
    assert status == 0
    assert json.loads(out)["outcome"] == hopper.simulate(
        "drop", 0.05, {"left_hip_effort": 1.5}).outcome != hopper.simulate("drop", 0.05).outcome


def test_sweep_a_urdf(hopper, capsys, tmp_path):
    path = tmp_path / "hop.json"
    """A sweep of tilts (not through 0: landing level on its straight legs the hopper stops
    dead, its base never reaches a lowest point and the drop ends at its horizon)."""
    status, out, err = _run(["sweep", "--system", str(HOPPER), "--maneuver", "drop",
                             "--num", "5", "--s-min", "0.02", "--s-max", "0.1",
                             "--out", str(path)], capsys)
    assert status == 0 and "wrote 5 points" in out, err
    data = json.loads(path.read_text())
    assert data["s"] == pytest.approx([0.02, 0.04, 0.06, 0.08, 0.1], abs=1e-15)
    assert data["outcome"] == [hopper.simulate("drop", s).outcome for s in data["s"]]
    assert all(b.startswith("air->right_foot->left_foot+right_foot") for b in data["branch"])
    level = hopper.simulate("drop", 0.0)
    assert level.status.name == "HORIZON" and level.contact_events[0].mask_entered == 3


def test_optimise_the_efforts_of_a_urdf(hopper, capsys):
    """The declared problem ``drop``: the hips' efforts within the URDF's effort limits (4 N m)
    that bring the roll rate at the nadir to 0."""
    status, out, err = _run(["optimise", "--system", str(HOPPER), "--problem", "drop",
                             "--s", "0.05", "--json"], capsys)
    assert status == 0, err
    got = json.loads(out)
    assert got["problem"]["decisions"] == {"left_hip_effort": [-4.0, 4.0],
                                           "right_hip_effort": [-4.0, 4.0]}
    unforced = hopper.simulate("drop", 0.05).outcome
    assert got["value"] < unforced ** 2


def test_options_in_the_file_argument(capsys):
    status, out, _ = _run(["systems", f"{HOPPER}:lock=right_hip,contacts=left_foot"], capsys)
    assert status == 0
    assert out.splitlines()[1].split()[:4] == ["hopper", "7", "1", "left_hip_effort"]
    status, _out, err = _run(["simulate", "--system", f"{HOPPER}:mass=3", "--maneuver", "drop",
                              "--s", "0"], capsys)
    assert status != 0 and "unknown option mass" in err
