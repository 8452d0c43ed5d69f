"""``biped-opt sweep``: fixed and optimal sweeps to a JSON file or a table."""

from __future__ import annotations

import json

import pytest

from biped_opt.cli.main import main


def test_fixed_sweep_table_holds_zero(capsys):
    code = main(["sweep", "--maneuver", "touchdown", "--theta0-min", "-0.1",
                 "--theta0-max", "0.1", "--num", "4", "--no-progress"])
    assert code == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 5  # header + 4 points, the one nearest 0 moved onto 0
    assert ["0", "0", "AIR->GROUND"] in [line.split() for line in lines]
    # MODEL.md R1 at th0 = 0.1 with the paper's figure inputs u = (2, 0.5)
    assert float(lines[-1].split()[1]) == pytest.approx(0.0703759886205, abs=1e-9)


def test_optimal_sweep_to_json_file(tmp_path, capsys):
    out = tmp_path / "opt.json"
    code = main(["sweep", "--maneuver", "liftoff", "--optimal", "--theta0-min", "-0.01",
                 "--theta0-max", "0.01", "--num", "3", "--out", str(out), "--progress"])
    assert code == 0
    captured = capsys.readouterr()
    assert "3/3" in captured.err and "wrote 3 points" in captured.out
    data = json.loads(out.read_text())
    assert data["kind"] == "optimal" and data["theta0"] == [-0.01, 0.0, 0.01]
    assert len(data["policy"]["u12"]) == 3 and all(data["success"])


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["--theta0-min", "0.1", "--theta0-max", "-0.1"], "--theta0-min"),
        (["--theta0-max", "0.4"], "--theta0-max"),
        (["--theta0-min", "nan"], "--theta0-min"),
        (["--num", "1"], "--num"),
        (["--out", "/nonexistent-dir/x.json", "--num", "2"], "--out"),
    ],
)
def test_bad_arguments(args, named, capsys):
    try:
        code = main(["sweep", "--maneuver", "liftoff", "--no-progress", *args])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and named in err
