"""A study's values are checked, and its size counted, before anything is built or written:
one clear error per bad value (the CLI's exit 2), limits named in the message."""

from __future__ import annotations

import pytest
import yaml

from biped_opt.errors import InvalidParameterError
from biped_opt.studies.study import LIMITS, Study, StudyLimits

BASE = "system: rocking_bar\nmaneuver: drop\ngrid: {gamma: [0.5]}\n"


@pytest.mark.parametrize(("extra", "message"), [
    ("num: abc", "study: num must be an integer, got 'abc'"),
    ("num: 1e12", "study: num must be an integer, got '1e12'"),  # (YAML 1.1: a string)
    ("num: 1.0e+12", "study: num must be in [3, 100001] (max_num), got 1000000000000"),
    ("num: 2", "study: num must be in [3, 100001] (max_num), got 2"),
    ("num_optimal: 2.5", "study: num_optimal must be an integer, got 2.5"),
    ("seed: 1.5e400", "study: seed must be an integer, got '1.5e400'"),
    ("seed: 1.5e+400", "study: seed must be an integer, got inf"),
    ("seed: -1", "study: seed must be in [0, 9223372036854775807], got -1"),
    ("seed: true", "study: seed must be an integer, got True"),
    ("s_range: [0.1, -0.1]", "study: s_range must have low < high, got [0.1, -0.1]"),
    ("s_range: [0.1, 0.1]", "study: s_range must have low < high"),
    ("samples: -3", "study: samples must be in [0, 100000] (max_values), got -3"),
    ("name: [1]", "study: name must be a string, got [1]"),
    ("maneuver: {a: 1}", "study: maneuver must be a string"),
])
def test_a_bad_value_is_one_error_naming_the_key(extra, message):
    spec = yaml.safe_load(BASE + extra)
    with pytest.raises(InvalidParameterError) as err:
        Study.from_spec(spec)
    assert str(err.value).startswith(message), err.value


def test_a_huge_grid_is_counted_not_built(monkeypatch):
    """400^4 points: refused by the product of the axis lengths; the points are never made
    (Study.points fails the test if called)."""
    monkeypatch.setattr(Study, "points", lambda self: pytest.fail("points built"))
    spec = {"system": "rocking_bar", "maneuver": "drop",
            "grid": {k: [float(i) for i in range(400)] for k in ("gamma", "k", "mb", "l0")}}
    with pytest.raises(InvalidParameterError,
                       match=r"^study: 25600000000 parameter points \(grid x samples\); at most "
                             r"1000000 \(limit max_points\)$"):
        Study.from_spec(spec)
    tight = StudyLimits(max_points=10, max_num=50, max_values=20, max_text=30)
    with pytest.raises(InvalidParameterError, match=r"16 parameter points.*at most 10 \("):
        Study.from_spec({**spec, "grid": {"gamma": [0.1] * 4, "k": [1.0] * 4}}, limits=tight)
    with pytest.raises(InvalidParameterError, match=r"grid: gamma: at most 20 values"):
        Study.from_spec({**spec, "grid": {"gamma": [0.1] * 21}}, limits=tight)
    with pytest.raises(InvalidParameterError, match=r"num must be in \[3, 50\] \(max_num\)"):
        Study.from_spec({**spec, "grid": {"gamma": [0.1]}, "num": 51}, limits=tight)
    with pytest.raises(InvalidParameterError, match=r"system must be at most 30 characters"):
        Study.from_spec({**spec, "grid": {"gamma": [0.1]}, "system": "w" * 31}, limits=tight)
    # samples count too: 3 grid points x 5 samples
    sampled = {**spec, "grid": {"gamma": [0.1, 0.2, 0.3]}, "sample": {"k": [20, 30]},
               "samples": 5}
    with pytest.raises(InvalidParameterError, match=r"15 parameter points.*at most 10 \("):
        Study.from_spec(sampled, limits=tight)


def test_a_study_within_the_limits_is_unchanged():
    study = Study.from_spec(yaml.safe_load(BASE + "num: 5.0\nseed: 7\ns_range: [-0.1, 0.1]\n"))
    assert (study.num, study.seed, study.s_range, study.size) == (5, 7, (-0.1, 0.1), 1)
    assert study.points() == [{"gamma": 0.5}]
    assert Study.from_spec(study.as_dict()) == study  # the round trip a table's spec makes


def test_a_directly_built_study_is_bounded_too():
    with pytest.raises(InvalidParameterError, match=r"limit max_points"):
        Study(system="rocking_bar", maneuver="drop",
              grid=tuple((k, tuple(float(i) for i in range(1000))) for k in ("gamma", "k", "mb")))
    # the limits of a study file that README states (10^6 points, s grids of 100,001)
    assert (LIMITS.max_points, LIMITS.max_num) == (1_000_000, 100_001)


@pytest.mark.parametrize("extra", ["num: abc", "seed: 1.5e400", "seed: -1", "num: 1e12",
                                   "s_range: [0.2, -0.2]"])
def test_the_cli_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys, extra):
    from tests.cli.test_systems_cmd import _run

    spec = tmp_path / "s.yaml"
    spec.write_text(BASE + extra + "\n")
    status, out, err = _run(["study", str(spec), "--out", str(tmp_path / "t.csv")], capsys)
    assert status == 2 and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and str(spec) in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.yaml"]


#: one YAML value of nested aliases, 9 lists of 9 per level: 9^7 (4.8 million) leaves from 7
#: short lines, and each line more is 9 times more (a goal's text is YAML)
BOMB = "[&b0 [1, 1, 1, 1, 1, 1, 1, 1, 1], " + ", ".join(
    f"&b{i} [{', '.join([f'*b{i - 1}'] * 9)}]" for i in range(1, 7)) + "]"


@pytest.mark.parametrize("extra", [f"num: {BOMB}", f"name: {BOMB}", f"inputs: {{u_th: {BOMB}}}",
                                   f"sample: {BOMB}", f"s_range: [{BOMB}, 1]"])
def test_a_value_of_nested_aliases_is_refused_without_being_expanded(extra):
    """The message shows a bounded part of the value: its full repr here would be 17.5 MB (a
    line more of aliases, ~160 MB), so a peak under 1 MB proves it was never built."""
    import tracemalloc

    spec = yaml.safe_load(BASE + extra)
    tracemalloc.start()
    try:
        with pytest.raises(InvalidParameterError) as err:
            Study.from_spec(spec)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000 and len(str(err.value)) < 200, (peak, str(err.value)[:200])
