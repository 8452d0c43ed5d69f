"""``biped-opt info``: topics, counts, time range, sweep parameters, complete or recovered."""

from __future__ import annotations

import json

from biped_opt.cli.info_cmd import describe
from biped_opt.cli.main import main
from tests.record.test_report import write_fixed_sweep


def test_info_summarises_a_recording(tmp_path, capsys):
    path = write_fixed_sweep(tmp_path / "s.mcap", num=5)
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "complete (finished, indexed)" in out
    assert "sweep points: 5" in out
    assert "biped_opt_interfaces/msg/BipedState" in out and "best_effort" in out
    assert "maneuver: liftoff" in out and "fixed_inputs: [1.5, 3.0]" in out
    info = describe(path)
    counts = {t["topic"]: t["count"] for t in info["topics"]}
    assert counts["/biped/sweep"] == 5 and counts["/biped/state"] > 100
    assert info["messages"] == sum(counts.values())
    assert info["start_ns"] == 0 and info["duration_s"] > 2.0  # 5 points, 0.5 s apart at least
    assert main(["info", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["sweep"]["num"] == "5"


def test_info_of_a_recovered_file(tmp_path, capsys):
    path = write_fixed_sweep(tmp_path / "k.mcap", num=5, chunk_size=3000)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "RECOVERED: recovered" in out and "unfinished" in out
    info = describe(path)
    assert not info["complete"] and 0 < info["messages"]
