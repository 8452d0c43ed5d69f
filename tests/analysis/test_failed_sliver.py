"""A failed region narrower than the one-sided estimates' steps (solo12's drop near s = 0.0345:
a foot lands and the complementarity rule finds no contact mode, INCONSISTENT, on an interval
of s about 2e-5 wide) is reported as failure boundaries, never as a jump or kink whose limits
are extrapolated from failed runs' numbers. Checked against plain simulations: every reported
side that has a value is a working run, and the failure is really there."""

from __future__ import annotations

import json

import pytest

from biped_opt.simulation.compiled import compiled_with
from tests.cli.test_systems_cmd import _run


@pytest.fixture(scope="module")
def solo():
    return compiled_with("solo12")


def test_a_sliver_of_failed_runs_is_failure_not_a_jump(solo, capsys):
    status, out, err = _run(["nonsmooth", "--system", "solo12", "--large", "--maneuver",
                             "drop", "--s-min", "0.03", "--s-max", "0.04", "--num", "11",
                             "--json"], capsys)
    assert status == 0, err
    points = json.loads(out)
    # plain simulations: inside the sliver the drop fails, on its two sides it works
    assert solo.simulate("drop", 0.03451).status.name == "INCONSISTENT"
    assert solo.simulate("drop", 0.0345).status.name == "OK"
    assert solo.simulate("drop", 0.03453).status.name == "OK"
    near = [p for p in points if 0.0345 <= p["theta0"] <= 0.03453]
    assert near and all(p["kind"] == "failure" for p in near), near
    for p in points:
        for value, side in ((p["left"], -1), (p["right"], 1)):
            if value is None:
                continue
            # a side with a value: the run just there works and has that outcome (to the
            # one-sided extrapolation's accuracy: the slope is ~2.3, the step 1e-9)
            run = solo.simulate("drop", p["theta0"] + side * 1e-9)
            assert run.status.name == "OK", p
            assert abs(run.outcome - value) < 1e-6, (p, run.outcome)
