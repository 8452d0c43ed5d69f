"""``biped-opt figures --system``: any system's figures from the command line. The checks read
data.json, which holds the very arrays and points the figures were drawn from (not pixels), and
compare them with SYSTEMS.md and with the solver called directly; bad invocations get one line,
status 2 and no output directory."""

from __future__ import annotations

import json

import numpy as np
import pytest

from biped_opt.control.problems import get_problem
from biped_opt.control.solve import optimal_policy
from biped_opt.simulation.compiled import CompiledSystem
from tests.cli.test_systems_cmd import _run


def _figures(argv, tmp_path, capsys):
    out = tmp_path / "figs"
    status, stdout, err = _run(["figures", *argv, "--out", str(out)], capsys)
    assert status == 0 and err == "", err
    data = json.loads((out / "data.json").read_text())
    for name in (*data["figures"], "captions.txt", "data.json"):
        assert f"wrote {out / name}" in stdout
    for name in data["figures"]:
        png = (out / name).read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 15_000  # drawn, not blank (~5 kB)
    return out, data, stdout


def test_rocking_bar_fixed_input_figures_mark_its_five_jumps(tmp_path, capsys):
    out, data, stdout = _figures(["--system", "rocking_bar", "--maneuver", "drop"], tmp_path,
                                 capsys)
    assert data["figures"] == ["outcome.png", "modes.png"]
    assert data["inputs"] == {"u_th": 0.0} and data["parameters"]["gamma"] == 0.5
    s, y = np.array(data["s"]), np.array(data["curves"]["outcome"])
    assert s.size == 401 and s[0] == -0.3 and s[-1] == 0.3 and 0.0 in s
    # the plotted curve is the system's own batch at these inputs, bit for bit
    bar = CompiledSystem("rocking_bar")
    np.testing.assert_array_equal(y, bar.simulate_batch("drop", s, (0.0,))["outcome"])
    points = data["points"]
    assert [p["kind"] for p in points] == ["jump"] * 5
    assert {p["quantity"] for p in points} == {"outcome"}
    # SYSTEMS.md Sec. 2 gives the places to 7 decimals; the table locates to 1e-10
    np.testing.assert_allclose([p["theta0"] for p in points],
                               [-0.2646950, -0.0961485, 0.0, 0.0961485, 0.2646950], atol=1e-7)
    zero = points[2]
    assert zero["theta0"] == 0.0 and zero["at"] == 0.0 == y[s == 0.0][0]
    assert zero["limits"] == pytest.approx([0.1988738, -0.1988738], abs=1e-7)
    # each mark sits on the drawn curve: the grid neighbours of a jump are its one-sided limits
    # to within the spacing 1.5e-3 times the steepest branch's slope (1.19 measured), i.e.
    # 1.8e-3; 5e-3 allows for that, and every jump is at least 0.39 high
    for p in points:
        k = int(np.searchsorted(s, p["theta0"]))
        left = k - 1
        right = k + 1 if s[k] == p["theta0"] else k
        assert abs(p["limits"][1] - p["limits"][0]) > 0.39
        assert y[left] == pytest.approx(p["limits"][0], abs=5e-3)
        assert y[right] == pytest.approx(p["limits"][1], abs=5e-3)
    captions = (out / "captions.txt").read_text()
    assert "rocking_bar drop at fixed inputs u_th = 0." in captions
    assert "outcome.png" in captions and "modes.png" in captions
    assert captions.count(" jump ") == 5 and "5 nonsmooth points over 401 values" in stdout


def test_walker3_touchdown_problem_figures(tmp_path, capsys):
    out, data, _ = _figures(["--system", "walker3_coupled", "--problem", "touchdown", "--num",
                             "5", "--s-min", "-0.1", "--s-max", "0.1"], tmp_path, capsys)
    assert data["figures"] == ["outcome.png", "policy_value.png"]
    assert data["problem"]["name"] == "touchdown" and data["system"] == "walker3_coupled"
    s = np.array(data["s"])
    np.testing.assert_allclose(s, [-0.1, -0.05, 0.0, 0.05, 0.1], rtol=0, atol=1e-16)
    c = {k: np.array(v) for k, v in data["curves"].items()}
    assert set(c) == {"outcome", "value", "policy:u1", "policy:u2", "policy:u3"}
    # the drawn optimum is the solver's at that s, bit for bit (same deterministic solver)
    direct = optimal_policy(get_problem("walker3_coupled", "touchdown"), float(s[3]))
    assert c["value"][3] == direct.value and c["outcome"][3] == direct.outcome
    assert c["policy:u1"][3] == direct.policy["u1"]
    # coupled law: u_i acts only while leg i alone is down. Tilted left (s < 0) foot3 lands
    # first, tilted right foot1, foot2 never alone: the idle inputs sit exactly at 0
    assert np.all(c["policy:u1"][s <= 0] == 0.0) and np.all(c["policy:u3"][s >= 0] == 0.0)
    assert np.all(c["policy:u2"] == 0.0) and np.all(c["policy:u3"][s < 0] != 0.0)
    assert c["policy:u1"][-1] == 1.5  # at its upper bound at s = 0.1
    found = {(p["quantity"], p["input"], p["kind"]) for p in data["points"]
             if p["theta0"] == 0.0}
    # the acting input switches from u3 to u1 at 0: both policy components kink there
    assert {("policy", "u1", "kink"), ("policy", "u3", "kink")} <= found
    (bound,) = [p for p in data["points"] if p["quantity"] == "outcome" and p["kind"] == "kink"]
    # u1 reaches its bound: measured 0.0974787639 on 5- and 9-point grids alike; 1e-8 is the
    # optimiser's ~1e-9 over the 1e-10 location
    assert bound["theta0"] == pytest.approx(0.0974787639, abs=1e-8)
    assert "input u1 reaches its upper bound 1.5" in bound["cause"]
    captions = (out / "captions.txt").read_text()
    assert "Cost: 1 (outcome + 0.1)^2" in captions and "(other inputs: u_body = 0)" in captions


def test_a_problem_file_alone_selects_its_system(tmp_path, capsys):
    (tmp_path / "bar.yaml").write_text(
        "system: rocking_bar\nmaneuver: drop\ndecisions: {u_th: [-0.2, 0.2]}\n"
        "weights: {u_th: 0.1}\ntarget: 0.02\n")
    # a window without a branch switch keeps it quick (the switch near -0.167 costs seconds)
    _, data, stdout = _figures(["--problem", str(tmp_path / "bar.yaml"), "--num", "5",
                                "--s-min", "0.02", "--s-max", "0.06"], tmp_path, capsys)
    assert data["problem"]["name"] == "bar" and data["system"] == "rocking_bar"
    assert data["s"] == pytest.approx([0.02, 0.03, 0.04, 0.05, 0.06], abs=1e-16)
    assert len(data["curves"]["policy:u_th"]) == 5 and data["points"] == []
    assert "problem bar on rocking_bar: 0 nonsmooth points over 5 values of th0" in stdout


BAR = ["--system", "rocking_bar", "--maneuver", "drop"]


@pytest.mark.parametrize(("argv", "message"), [
    (["--system", "rocking_bar"], "--maneuver (fixed inputs) or --problem (optimal) is required"),
    (["--maneuver", "drop"], "--maneuver: only with --system"),
    (["--num", "9"], "--num: only with --system"),
    (["--input", "u_th=1"], "--input: only with --system"),
    (["--s-min", "0"], "--s-min: only with --system"),
    ([*BAR[:2], "--maneuver", "fly"], "unknown maneuver 'fly'"),
    ([*BAR, "--input", "torque=1"], "unknown input 'torque'"),
    ([*BAR, "--input", "u_th"], "--input must look like NAME=VALUE"),
    ([*BAR, "--param", "zeta=1"], "unknown parameter 'zeta'"),
    ([*BAR, "--fixed-num", "9"], "--fixed-num: the biped's option"),
    ([*BAR, "--optimal-num", "9"], "--optimal-num: the biped's option"),
    ([*BAR, "--num", "3"], "--num must be between 5 and 1000000"),
    ([*BAR, "--s-min", "0.2", "--s-max", "0"], "lo < hi"),
    ([*BAR, "--s-min", "1", "--s-max", "0"], "--s-min: s = 1 is outside the valid range"),
    ([*BAR, "--s", "0"], "ambiguous option: --s could match"),
    (["--system", "nowhere.py", "--maneuver", "drop"], "no such system file"),
    (["--system", "rocking_bar", "--problem", "drop", "--input", "u_th=1"],
     "--input: fixed-input figures only"),
    (["--system", "rocking_bar", "--problem", "spin"], "unknown problem 'spin'"),
    (["--system", "rocking_bar", "--problem", "drop", "--maneuver", "fly"],
     "the problem drop is on maneuver 'drop'"),
])
def test_mistakes_get_one_line_status_2_and_no_directory(argv, message, tmp_path, capsys):
    out = tmp_path / "never"
    status, stdout, err = _run(["figures", *argv, "--out", str(out)], capsys)
    assert status == 2 and stdout == ""
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not out.exists()


def test_an_output_path_that_is_a_file_is_refused(tmp_path, capsys):
    (tmp_path / "f").write_text("")
    status, _, err = _run(["figures", *BAR, "--out", str(tmp_path / "f")], capsys)
    assert status == 2 and "--out:" in err and "exists and is not a directory" in err
