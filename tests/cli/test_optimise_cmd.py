"""``biped-opt optimise``: JSON shape, derivatives, problem overrides and argument errors."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from biped_opt.cli.main import main


def test_json_as_a_user_runs_it():
    proc = subprocess.run(
        [sys.executable, "-m", "biped_opt.cli.main", "optimise", "--maneuver", "touchdown",
         "--theta0", "0.05", "--json"],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["value"] == pytest.approx(0.0194158739483, abs=1e-8)  # MODEL.md R5
    assert set(out["policy"]) == {"u1", "u2"}
    assert out["policy"]["u1"] == pytest.approx(1.2776719, abs=1e-6)
    assert out["modes"] == ["AIR", "LEFT", "GROUND"] and isinstance(out["outcome"], float)
    # each candidate keeps its "decision" (the acting u1's value) beside its full policy
    assert out["active"] == "u1" and out["candidates"]
    assert all(c["decision"] == c["policy"]["u1"] for c in out["candidates"])
    best = min(out["candidates"], key=lambda c: c["value"])
    assert best["decision"] == out["policy"]["u1"] and best["value"] == out["value"]
    d = out["derivatives"]
    assert set(d) >= {"outcome", "value", "policy"} and set(d["policy"]) == {"u1", "u2"}
    # smooth point: both sides agree; dV/dth0 = dc/dth0 (envelope theorem)
    assert d["value"][0] == pytest.approx(d["value"][1], rel=1e-6)
    assert d["policy"]["u1"][0] == pytest.approx(d["policy"]["u1"][1], rel=1e-6)


def test_liftoff_policy_key_and_overrides(capsys):
    code = main(["optimise", "--maneuver", "liftoff", "--theta0", "0.01", "--json",
                 "--theta-star", "0.02", "--alpha", "u12=0.02", "--bounds", "u12=-0.3,0.3",
                 "--fixed", "u2=2.5"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["policy"]) == {"u12"} and set(out["derivatives"]["policy"]) == {"u12"}
    assert out["problem"]["theta_star"] == 0.02
    assert out["problem"]["alphas"] == {"u12": 0.02}
    assert out["problem"]["bounds"] == {"u12": [-0.3, 0.3]}
    assert out["problem"]["fixed_inputs"] == {"u1": 1.5, "u2": 2.5}


def test_variant_text_output(capsys):
    assert main(["optimise", "--maneuver", "liftoff", "--variant", "--theta0", "0.05"]) == 0
    text = capsys.readouterr().out
    assert "liftoff-variant" in text and "u1 at its upper bound" in text


def test_finite_difference_fallback_without_the_derivatives_module(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "biped_opt.paper.derivatives", None)  # import fails
    assert main(["optimise", "--maneuver", "touchdown", "--theta0", "0", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)["derivatives"]
    assert d["method"] == "finite-difference"
    # MODEL.md Sec. 6: u1* ~ 18.2 th0 (right), u2* ~ 1.82 th0 (left); V'(0) = 0.1647 both sides
    assert d["policy"]["u1"][0] == 0.0 and d["policy"]["u1"][1] == pytest.approx(18.2, abs=0.05)
    assert d["policy"]["u2"][0] == pytest.approx(1.82, abs=0.01)
    assert d["value"] == pytest.approx([0.1647, 0.1647], abs=1e-4)


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["--maneuver", "touchdown", "--theta0", "nan"], "--theta0"),
        (["--maneuver", "walk", "--theta0", "0.1"], "--maneuver"),
        (["--maneuver", "touchdown", "--theta0", "0.26"], "--theta0"),
        (["--maneuver", "touchdown", "--theta0", "0.1", "--alpha", "u12=1"], "--alpha"),
        (["--maneuver", "touchdown", "--theta0", "0.1", "--alpha", "u1"], "--alpha"),
        (["--maneuver", "touchdown", "--theta0", "0.1", "--bounds", "u1=1,0"], "--bounds"),
        (["--maneuver", "touchdown", "--theta0", "0.1", "--variant"], "--variant"),
        (["--maneuver", "liftoff", "--theta0", "0.1", "--fixed", "u12=1"], "--fixed"),
        (["--maneuver", "touchdown", "--theta0", "0.1", "--theta-star", "inf"], "--theta-star"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(args, named, capsys):
    try:
        code = main(["optimise", *args])
    except SystemExit as exc:  # argparse-level errors
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and named in err
