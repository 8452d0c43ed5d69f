"""Offline report from a small recorded sweep: figures, grid-resolution table, recovered files."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from biped_opt import simulate
from biped_opt.cli.main import main
from biped_opt.paper.problems import get_problem
from biped_opt.piecewise import theta_grid
from biped_opt.record import SweepWriter
from biped_opt.record.report import ReportError, grid_nonsmooth, load_sweep, report

NS = 1_000_000_000
#: MODEL.md Sec. 7, R3/R4: liftoff outcomes just left and right of th0 = 0 at u = (1.5, 3)
R3, R4 = 0.0262836775109, -0.00653232497802


def write_fixed_sweep(path, maneuver="liftoff", inputs=(1.5, 3.0), num=15, chunk_size=1 << 20):
    """A fixed-input sweep written as the recorder writes it, straight from simulate()."""
    problem = get_problem(maneuver)
    meta = {"maneuver": maneuver, "theta0_min": -0.07, "theta0_max": 0.07, "num": num,
            "optimal": False, "fixed_inputs": json.dumps(list(inputs)),
            "cost": json.dumps(problem.describe())}
    offset = 0
    u = np.zeros(3)
    u[: len(inputs)] = inputs
    with SweepWriter(path, metadata={k: str(v) for k, v in meta.items()},
                     chunk_size=chunk_size) as w:
        for th in theta_grid(-0.07, 0.07, num):
            tr = simulate(maneuver, th, u, sample_dt=0.005)
            w.write_states(maneuver=maneuver, theta0=th, samples=tr.samples,
                           stamp_offset_ns=offset)
            w.write("/biped/sweep", {
                "maneuver": maneuver, "theta0": th, "policy": list(u),
                "value": float(problem.cost(tr.outcome, u)), "outcome": tr.outcome,
                "t_final": tr.t_final, "mode_sequence": [int(m) for m in tr.mode_sequence],
                "event_times": list(tr.event_times)}, offset + int(tr.t_final * NS))
            offset += int((tr.t_final + 0.5) * NS)
    return path


@pytest.fixture(scope="module")
def liftoff_file(tmp_path_factory):
    return write_fixed_sweep(tmp_path_factory.mktemp("rec") / "liftoff.mcap")


def test_load_sweep_reads_the_points_and_metadata(liftoff_file):
    s = load_sweep(liftoff_file)
    assert s.maneuver == "liftoff" and not s.optimal and s.complete
    assert s.theta0.size == 15 and 0.0 in s.theta0
    np.testing.assert_array_equal(s.inputs, [1.5, 3.0, 0.0])
    assert s.branch[list(s.theta0).index(0.0)] == "GROUND->AIR"  # simultaneous liftoff


def test_liftoff_jump_at_zero_is_found_at_grid_resolution(liftoff_file):
    points = grid_nonsmooth(load_sweep(liftoff_file))
    outcome = [g for g in points if g.point.quantity == "outcome"]
    assert len(outcome) == 1
    g = outcome[0]
    assert g.point.kind == "jump" and g.point.theta0 == 0.0
    assert g.point.bracket == pytest.approx((-0.01, 0.01)) and g.width == pytest.approx(0.02)
    # cubic extrapolation over 0.01 spacing: its own error estimate bounds the true error (x3)
    assert abs(g.point.left - R3) < max(3 * g.limit_error[0], 1e-9)
    assert abs(g.point.right - R4) < max(3 * g.limit_error[1], 1e-9)


def test_report_writes_figures_and_a_labelled_table(liftoff_file, tmp_path, capsys):
    assert main(["report", str(liftoff_file), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    for name in ("fig2.png", "fig3.png", "nonsmooth_recorded.txt"):
        path = tmp_path / "out" / name
        assert path.is_file() and path.stat().st_size > 500
    assert not (tmp_path / "out" / "fig4.png").exists()  # no optimal sweep recorded
    table = (tmp_path / "out" / "nonsmooth_recorded.txt").read_text()
    assert "GRID-RESOLUTION ESTIMATES" in table and "bracket" in table
    line = next(x for x in table.splitlines() if " outcome " in x)
    assert line.split()[0] == "0" and "jump" in line and "0.02" in line  # bracket width
    assert "liftoff sweep, 15 points, complete" in out


def test_figures_drawn_in_two_processes_are_the_ones_drawn_in_one(liftoff_file, tmp_path):
    """The command as a user runs it (a process of one thread, so --jobs 2 forks): the same
    figures, byte for byte, and the same table; --jobs 0 is refused before anything is read."""
    outs = {}
    for jobs in ("1", "2"):
        outs[jobs] = tmp_path / f"jobs{jobs}"
        proc = subprocess.run([sys.executable, "-m", "biped_opt.cli.main", "report",
                               str(liftoff_file), "--out", str(outs[jobs]), "--jobs", jobs],
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr
    for name in ("fig2.png", "fig3.png", "nonsmooth_recorded.txt"):
        assert (outs["1"] / name).read_bytes() == (outs["2"] / name).read_bytes(), name
    proc = subprocess.run([sys.executable, "-m", "biped_opt.cli.main", "report",
                           str(liftoff_file), "--out", str(tmp_path / "none"), "--jobs", "0"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "--jobs" in proc.stderr
    assert not (tmp_path / "none").exists()


def test_report_of_a_recovered_file_says_how_much(tmp_path):
    path = write_fixed_sweep(tmp_path / "killed.mcap", chunk_size=4000)
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * 0.8)])
    r = report([path], tmp_path / "out")
    s = r.sweeps[0]
    assert not s.complete and 0 < s.theta0.size < 15
    assert "RECOVERED" in r.table and "recovered" in r.table and "bytes" in r.table


def test_report_errors(tmp_path):
    empty = tmp_path / "empty.mcap"
    with SweepWriter(empty):
        pass
    with pytest.raises(ReportError, match="no /biped/sweep messages"):
        load_sweep(empty)
    assert main(["report", str(tmp_path / "missing.mcap"), "--out", str(tmp_path)]) == 2
