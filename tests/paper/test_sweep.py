"""Fixed-input and optimal sweeps: grids with th0 = 0, MODEL.md R1-R2, JSON round trips."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from biped_opt.errors import InvalidInputError
from biped_opt.paper.problems import liftoff_problem
from biped_opt.paper.solve import optimal_policy
from biped_opt.paper.sweeps import sweep_fixed, sweep_grid, sweep_optimal
from biped_opt.progress import Progress
from tests.conftest import REFERENCE


def test_grid_always_holds_zero():
    grid = sweep_grid("touchdown", num=4)  # linspace(-0.25, 0.25, 4) has no 0
    assert 0.0 in grid and grid[0] == -0.25 and grid[-1] == 0.25
    assert np.all(np.diff(grid) > 0)
    with pytest.raises(InvalidInputError, match="min < max"):
        sweep_grid("liftoff", 0.1, -0.1)
    with pytest.raises(InvalidInputError, match="theta0"):
        sweep_grid("liftoff", -0.5, 0.1)


def test_fixed_sweep_reproduces_r1_r2_and_round_trips(tmp_path):
    _, th1, u, r1 = REFERENCE["R1"]
    _, th2, _, r2 = REFERENCE["R2"]
    sweep = sweep_fixed("touchdown", [th1, th2], u)
    assert sweep.theta0.tolist() == [th2, 0.0, th1]  # sorted, 0 inserted
    assert sweep.outcome[0] == pytest.approx(r2, abs=1e-9)
    assert sweep.outcome[2] == pytest.approx(r1, abs=1e-9)
    assert sweep.branch == ("AIR->RIGHT->GROUND", "AIR->GROUND", "AIR->LEFT->GROUND")
    assert sweep.success.all() and len(sweep.event_times[1]) == 1
    path = tmp_path / "sweep.json"
    path.write_text(sweep.to_json())
    data = json.loads(path.read_text())
    assert data["kind"] == "fixed" and data["outcome"] == sweep.outcome.tolist()
    assert data["inputs"] == {"u1": 2.0, "u2": 0.5, "u12": 0.0}


def test_optimal_sweep_arrays_json_and_progress_bar():
    stream = io.StringIO()
    bar = Progress(3, "test", stream=stream, min_interval=0.0)
    sweep = sweep_optimal(liftoff_problem(), [-0.01, 0.01], progress=bar)
    assert sweep.theta0.tolist() == [-0.01, 0.0, 0.01]
    lines = stream.getvalue().split("\r")[1:]
    assert [line.split("] ")[1].split()[0] for line in lines] == ["1/3", "2/3", "3/3"]
    assert lines[-1].startswith("test [" + "#" * 30 + "]") and lines[-1].endswith("\n")
    single = optimal_policy(liftoff_problem(), 0.01)
    assert sweep.value[2] == pytest.approx(single.value, abs=1e-14)
    assert sweep.policy["u12"][2] == pytest.approx(single.policy["u12"], abs=1e-9)
    data = json.loads(sweep.to_json())
    assert data["kind"] == "optimal" and data["problem"]["name"] == "liftoff"
    assert data["branch"] == list(sweep.branch) and data["policy"]["u12"][0] < 0


def test_disabled_progress_bar_is_silent():
    stream = io.StringIO()
    Progress(2, stream=stream, enabled=False).update(2)
    assert stream.getvalue() == ""
