"""Parameter studies (biped_opt.studies.study, record.study_table, ``biped-opt study``)."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from biped_opt.analysis.nonsmooth import find_nonsmooth
from biped_opt.cli.main import main
from biped_opt.errors import InvalidInputError, InvalidParameterError
from biped_opt.record.study_table import read_table, run_study, spec_path
from biped_opt.studies.study import Study, evaluate_point
from tests.cli.test_systems_cmd import _run

BAR = {"system": "rocking_bar", "maneuver": "drop", "grid": {"gamma": [0.3, 0.5, 0.8]},
       "num": 61}


def test_points_grid_then_seeded_sample() -> None:
    st = Study.from_spec({"system": "rocking_bar", "maneuver": "drop",
                          "grid": {"gamma": [0.3, 0.5]}, "sample": {"w": [0.4, 0.6]},
                          "samples": 3, "seed": 7})
    points = st.points()
    assert len(points) == 6 and [p["gamma"] for p in points] == [0.3] * 3 + [0.5] * 3
    assert points == Study.from_spec(st.as_dict()).points()  # the seed makes it reproducible
    assert all(0.4 <= p["w"] <= 0.6 for p in points)
    assert [p["w"] for p in points[:3]] == [p["w"] for p in points[3:]]


def test_a_point_is_the_nonsmooth_table_at_its_parameters() -> None:
    """The rows of a parameter point are find_nonsmooth's points at those parameters (the
    rocking bar's five jumps at gamma = 0.5, SYSTEMS.md Sec. 2), sizes = right - left."""
    st = Study.from_spec(BAR)
    rows = evaluate_point(st, 1, {"gamma": 0.5})
    from biped_opt.simulation.compiled import CompiledSystem

    bar = CompiledSystem("rocking_bar", gamma=0.5)
    from biped_opt.analysis.nonsmooth import s_grid

    direct = find_nonsmooth(bar, "drop", None, s=s_grid(bar, "drop", 61))
    assert [(r.kind, r.s) for r in rows] == [(p.kind, p.theta0) for p in direct.points]
    assert len(rows) == 5 and all(r.rows == 5 and r.table == "fixed" for r in rows)
    middle = rows[2]
    assert middle.s == 0.0 and middle.size == pytest.approx(-2 * 0.1988738, abs=1e-6)


def test_no_nonsmooth_point_still_gives_a_row() -> None:
    st = Study.from_spec({"system": "walker2_decoupled", "maneuver": "touchdown",
                          "inputs": {"u1": 2, "u2": 0.5}, "grid": {"k": [27.0]},
                          "s_range": [-0.01, 0.01], "num": 11})
    (row,) = evaluate_point(st, 0, {"k": 27.0})
    assert row.kind == "none" and row.rows == 1


def _sorted_rows(path: Path) -> list[tuple]:
    return sorted(tuple(r.values()) for r in read_table(path))


def test_resume_after_a_torn_write_computes_each_point_once(tmp_path: Path) -> None:
    """Cut the table in the middle of a line and drop one row of another point: the next run
    keeps the complete points, recomputes the others, and the table equals an uninterrupted
    run's (each point exactly once)."""
    st = Study.from_spec(BAR)
    full = tmp_path / "full.csv"
    assert run_study(st, full).computed == 3
    cut = tmp_path / "cut.csv"
    text = full.read_text()
    lines = text.splitlines(keepends=True)
    header, rows = lines[0], lines[1:]
    kept = [r for r in rows if r.startswith("0,")] + \
        [r for r in rows if r.startswith("1,")][:-1]  # point 1 misses its last row
    cut.write_text(header + "".join(kept) + rows[-1][:17])  # and a torn line
    spec_path(cut).write_text(spec_path(full).read_text())
    summary = run_study(st, cut)
    assert summary.resumed == 1 and summary.computed == 2
    assert _sorted_rows(cut) == _sorted_rows(full)
    points = [r["point"] for r in csv.DictReader(cut.open())]
    reference = [r["point"] for r in csv.DictReader(full.open())]
    assert sorted(points) == sorted(reference) and summary.rows == len(points)
    again = run_study(st, cut)
    assert again.computed == 0 and again.resumed == 3


def test_two_workers_give_the_same_table(tmp_path: Path) -> None:
    st = Study.from_spec(BAR)
    one, two = tmp_path / "one.csv", tmp_path / "two.csv"
    run_study(st, one)
    assert run_study(st, two, workers=2).computed == 3
    assert _sorted_rows(one) == _sorted_rows(two)


def test_stop_leaves_a_resumable_table(tmp_path: Path) -> None:
    st = Study.from_spec(BAR)
    path = tmp_path / "t.csv"
    calls = []
    summary = run_study(st, path, stop=lambda: len(calls) > 1,  # the first call: 0 done
                        progress=lambda done, total: calls.append(done))
    assert summary.stopped and summary.computed == 1
    assert run_study(st, path).computed == 2


def test_a_different_study_on_the_same_table_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    run_study(Study.from_spec({**BAR, "grid": {"gamma": [0.5]}}), path)
    with pytest.raises(InvalidInputError, match="holds a different study"):
        run_study(Study.from_spec(BAR), path)


def test_optimal_table_of_a_problem_study() -> None:
    """One parameter point of a problem study: the liftoff problem's optimal tables at two
    targets; problem data (target, weights) vary without touching the system."""
    st = Study.from_spec({"system": "biped", "problem": "liftoff",
                          "grid": {"target": [0.01], "weight.u12": [0.01]},
                          "s_range": [-0.01, 0.01], "num_optimal": 5})
    rows = evaluate_point(st, 0, st.points()[0])
    assert {r.table for r in rows} == {"optimal"}
    assert any(r.quantity == "policy" and r.kind == "jump" for r in rows)


@pytest.mark.parametrize(("spec", "message"), [
    ({"system": "rocking_bar", "grid": {"gamma": [0.5]}}, "give a maneuver, a problem"),
    ({**BAR, "grid": {"mass": [1]}}, "cannot vary 'mass'"),
    ({**BAR, "grid": {"target": [0.1]}}, "'target' is problem data"),
    ({**BAR, "grid": {}}, "vary at least one parameter"),
    ({**BAR, "grid": {"gamma": []}}, "non-empty list"),
    ({**BAR, "sample": {"w": [0.6, 0.4]}, "samples": 2}, "low < high"),
    ({**BAR, "sample": {"w": [0.4, 0.6]}}, "samples >= 1"),
    ({**BAR, "colour": 1}, "unknown key 'colour'"),
    ({**BAR, "maneuver": "fly"}, "unknown maneuver 'fly'"),
    ({**BAR, "grid": {"gamma": [float("nan")]}}, "finite number"),
])
def test_bad_studies_are_one_clear_error(spec: dict, message: str) -> None:
    with pytest.raises(InvalidParameterError, match=message):
        Study.from_spec(spec)


def test_cli_runs_and_resumes(tmp_path: Path, capsys) -> None:
    spec = tmp_path / "bar.yaml"
    spec.write_text("system: rocking_bar\nmaneuver: drop\ngrid: {gamma: [0.5]}\nnum: 61\n")
    out = tmp_path / "bar.csv"
    assert main(["study", str(spec), "--out", str(out), "--no-progress"]) == 0
    assert "1 parameter points, 1 computed now, 0 resumed, 5 rows" in capsys.readouterr().out
    assert main(["study", str(spec), "--out", str(out), "--no-progress", "--figures",
                 str(tmp_path / "fig")]) == 0
    assert "0 computed now, 1 resumed" in capsys.readouterr().out
    assert (tmp_path / "fig").is_dir()  # one parameter: no heat map, no optimal table
    assert json.loads(spec_path(out).read_text())["grid"] == {"gamma": [0.5]}


@pytest.mark.parametrize(("text", "message"), [
    ("system: rocking_bar\nmaneuver: drop\n", "vary at least one parameter"),
    ("system: [\n", "not valid YAML"),
])
def test_cli_bad_study_file(tmp_path: Path, capsys, text: str, message: str) -> None:
    spec = tmp_path / "bad.yaml"
    spec.write_text(text)
    status, _, err = _run(["study", str(spec), "--out", str(tmp_path / "x.csv")], capsys)
    assert status == 2 and not (tmp_path / "x.csv").exists()
    assert message in err and len(err.strip().splitlines()) == 1


def test_table_as_mcap_read_back_by_mcap_ros2(tmp_path: Path, capsys) -> None:
    """The table's rows as /biped/study StudyRow messages, decoded by mcap-ros2-support (an
    independent reader of the .msg definition): the same numbers and strings, in point order,
    with the study in the metadata."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    spec = tmp_path / "bar.yaml"
    spec.write_text("system: rocking_bar\nmaneuver: drop\ngrid: {gamma: [0.3, 0.5]}\nnum: 61\n")
    out, mcap_path = tmp_path / "bar.csv", tmp_path / "bar.mcap"
    status, printed, _ = _run(["study", str(spec), "--out", str(out), "--mcap", str(mcap_path),
                               "--no-progress"], capsys)
    assert status == 0 and "/biped/study rows" in printed
    table = sorted(read_table(out), key=lambda r: int(r["point"]))
    with open(mcap_path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        decoded = [m for _, _, _, m in reader.iter_decoded_messages(topics=["/biped/study"])]
        (meta,) = [m for m in reader.iter_metadata() if m.name == "biped_opt.studies.study"]
    # gamma 0.5: the bar's five jumps (SYSTEMS.md Sec. 2); gamma 0.3: the chatter of the ends'
    # shrinking bounces, every one of them found since re-impacts inside a step are, makes many
    assert len(decoded) == len(table)
    assert sum(float(r["gamma"]) == 0.5 for r in table) == 5
    assert sum(float(r["gamma"]) == 0.3 for r in table) >= 3
    for msg, row in zip(decoded, table):
        assert msg.point == int(row["point"]) and msg.kind == row["kind"]
        assert list(msg.parameter_names) == ["gamma"]
        assert msg.parameter_values[0] == float(row["gamma"])
        # (a failure boundary has no size: empty in the table, NaN in the message)
        size = math.nan if row["size"] == "" else float(row["size"])
        assert msg.s == float(row["s"])
        assert msg.size == size or (math.isnan(size) and math.isnan(msg.size))
        assert msg.cause == row["cause"] and msg.rows == int(row["rows"])
    assert json.loads(meta.metadata["study"])["grid"] == {"gamma": [0.3, 0.5]}
