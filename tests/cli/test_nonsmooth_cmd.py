"""``biped-opt nonsmooth``: the JSON list of findings and the text table."""

from __future__ import annotations

import json

import pytest

from biped_opt.cli.main import main


def test_fixed_liftoff_json(capsys):
    assert main(["nonsmooth", "--maneuver", "liftoff", "--num", "61", "--json"]) == 0
    points = json.loads(capsys.readouterr().out)
    assert len(points) == 1
    p = points[0]
    assert {"theta0", "quantity", "kind", "left", "right", "cause"} <= set(p)
    assert (p["theta0"], p["quantity"], p["kind"]) == (0.0, "outcome", "jump")
    assert p["left"] == pytest.approx(0.026283950, abs=1e-8)
    assert p["right"] == pytest.approx(-0.006532702, abs=1e-8)


def test_optimal_liftoff_table(capsys):
    code = main(["nonsmooth", "--maneuver", "liftoff", "--optimal", "--num", "21",
                 "--theta0-min", "-0.01", "--theta0-max", "0.01"])
    assert code == 0
    text = capsys.readouterr().out
    assert "3 nonsmooth findings" in text
    assert "policy:u12" in text and "optimal branch switches" in text


def test_bad_maneuver(capsys):
    assert main(["nonsmooth", "--maneuver", "hop"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--maneuver" in err
