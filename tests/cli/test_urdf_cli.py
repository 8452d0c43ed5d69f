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


def test_nonsmooth_points_of_a_urdf_are_where_plain_simulations_change_branch(hopper, capsys):
    """``nonsmooth`` on the hopper's drop finds where its sequence of contact modes changes
    (a foot lifting off and landing again or not); each located s is checked against a bracket
    found by plain simulations alone: SciPy's bisection on the sign of "the run's mode sequence
    is the one at the bracket's left end" (to 1e-13), in a window of +-1e-4 about it (the two
    points are 1.2e-3 apart, in one cell of the grid)."""
    from scipy.optimize import bisect

    status, out, err = _run(["nonsmooth", "--system", str(HOPPER), "--maneuver", "drop",
                             "--num", "21", "--s-min", "0.02", "--s-max", "0.1", "--json"],
                            capsys)
    assert status == 0, err
    points = json.loads(out)
    assert len(points) == 2 and all(p["cause"].startswith("mode sequence changes")
                                    for p in points), points
    for p in points:
        s_tool = p["s"] if "s" in p else p["theta0"]
        lo, hi = s_tool - 1e-4, s_tool + 1e-4
        left = tuple(hopper.simulate("drop", lo).modes)

        def side(s, left=left):
            return 1.0 if tuple(hopper.simulate("drop", s).modes) == left else -1.0

        assert side(hi) == -1.0
        root = bisect(side, lo, hi, xtol=1e-13)
        # the change is a grazing contact (a foot touching the ground with zero speed), where
        # the event's time moves like sqrt(s - s*): the tool's location is good to ~1e-8
        # (measured 3e-8), not to the 1e-12 of a transversal one
        assert abs(s_tool - root) < 1e-7, (s_tool, root)


def _grid_minimum(compiled, problem, s, num):
    """The least cost of ``problem`` at s over a num x num grid of its two decisions, by
    plain batch simulation (no solver)."""
    import numpy as np

    names = list(problem.decision_names)
    (lo0, hi0), (lo1, hi1) = problem.bound(names[0]), problem.bound(names[1])
    a, b = np.meshgrid(np.linspace(lo0, hi0, num), np.linspace(lo1, hi1, num))
    rows = np.tile(problem.inputs(), (a.size, 1))
    cols = list(problem.decision_columns)
    rows[:, cols[0]], rows[:, cols[1]] = a.ravel(), b.ravel()
    batch = compiled.simulate_batch(problem.maneuver, np.full(a.size, s), rows)
    ok = batch.status == 0
    return float(np.min(problem.cost(batch.outcome[ok], batch.y_final[ok], rows[ok])))


@pytest.mark.parametrize("sampled", [False, True])
def test_the_optimum_of_a_urdf_is_no_worse_than_a_brute_force_grid(hopper, sampled,
                                                                   monkeypatch):
    """The hopper's problem ``drop`` (its two hip efforts, within the URDF's 4 N m) at s = 0.05:
    the solver's value is no more than the least of a 61 x 61 grid of plain simulations (one
    run every 0.13 N m), and its outcome meets the target. ``sampled``: the bracketing stage
    is the Sobol sample a robot's many efforts get (forced here by a smaller limit on the
    grid: 17 x 17 > 64), which must find it too."""
    from biped_opt.control import solve
    from biped_opt.control.problems import get_problem

    if sampled:
        monkeypatch.setattr(solve, "MAX_BRACKET", 64)
    problem = get_problem(str(HOPPER), "drop")
    result = solve.optimal_policy(problem, 0.05)
    assert result.success
    assert all(-4.0 <= v <= 4.0 for v in result.policy.values())
    best = _grid_minimum(hopper, problem, 0.05, 61)
    # (the cost is smooth near the optimum and simulated to ~1e-14: 1e-12 is noise only)
    assert result.value <= best + 1e-12, (result.value, best)
    assert abs(result.outcome) < 1e-3  # (the roll rate at the nadir, unforced -0.268 rad/s)


@pytest.mark.parametrize(("view", "drawn"), [("auto", "3d"), ("xz", "xz")])
def test_animate_a_urdf_in_3d_or_in_the_x_z_plane(hopper, capsys, tmp_path, view, drawn):
    """The hopper's feet stand side by side (y = +-0.1): ``auto`` draws it in 3-D; ``xz``
    asks for the plane (10 frames a second of 160 x 120 pixels: a short test)."""
    out = tmp_path / "hop.gif"
    status, text, err = _run(["animate", "--system", str(HOPPER), "--maneuver", "drop",
                              "--s", "0.05", "--view", view, "--fps", "10", "--width", "160",
                              "--height", "120", "-o", str(out)], capsys)
    assert status == 0, err
    assert f"view {drawn}" in text and out.stat().st_size > 0


def test_a_study_on_a_urdf(hopper, capsys, tmp_path):
    """``biped-opt study`` over the hopper's posture gain kp (a parameter the importer declares):
    each row's s is a point where plain simulations at that kp change their sequence of
    contact modes within +-1e-6 (the grazing landings of the nonsmooth test)."""
    import csv

    from biped_opt.simulation.compiled import compiled_with

    study = tmp_path / "hop.yaml"
    study.write_text(f"system: {HOPPER}\nmaneuver: drop\ngrid: {{kp: [5, 10]}}\n"
                     "s_range: [0.02, 0.1]\nnum: 9\n")
    table = tmp_path / "hop.csv"
    status, out, err = _run(["study", str(study), "--out", str(table), "--no-progress"], capsys)
    assert status == 0, err
    rows = list(csv.DictReader(table.open()))
    assert {r["kp"] for r in rows} == {"5.0", "10.0"} and "2 parameter points" in out
    found = [r for r in rows if r["kind"] != "none"]
    assert found
    for r in found:
        system = compiled_with(str(HOPPER), {"kp": float(r["kp"])})
        s = float(r["s"])
        assert r["cause"].startswith("mode sequence changes")
        assert system.simulate("drop", s - 1e-6).modes != system.simulate("drop", s + 1e-6).modes
