"""Resuming a study table that was damaged since it was written (biped_opt.record.study_table).

One complete table of three parameter points is computed once. Each case damages a copy the way
a disk, an editor or another program could, then opens it as a resumed run does: every row that
fails its check is dropped with its whole point (which the run then computes again) and the run
says so in one line; a file that is not this study's table is refused with one line and left as
it was. The expectations come from the intact table, not from the code under test.
"""

from __future__ import annotations

import dataclasses
import json
import os
import random
import shutil
import signal
import time
from pathlib import Path

import pytest

from biped_opt.cli.main import main
from biped_opt.errors import InvalidInputError
from biped_opt.record import study_table
from biped_opt.record.study_table import StudyTable, read_table, run_study, spec_path
from biped_opt.studies.study import Study

BAR = {"system": "rocking_bar", "maneuver": "drop", "grid": {"gamma": [0.3, 0.5, 0.8]},
       "num": 61}
SPEC = "system: rocking_bar\nmaneuver: drop\ngrid: {gamma: [0.3, 0.5, 0.8]}\nnum: 61\n"


@pytest.fixture(scope="module")
def intact(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("resume") / "intact.csv"
    summary = run_study(Study.from_spec(BAR), path)
    assert summary.computed == 3 and summary.rows >= 3
    return path


def _lines(path: Path) -> list[bytes]:
    return path.read_bytes().split(b"\n")[:-1]  # (the table ends with a newline)


def _copy(intact: Path, tmp_path: Path, lines: list[bytes]) -> Path:
    path = tmp_path / "damaged.csv"
    path.write_bytes(b"\n".join(lines) + b"\n")
    shutil.copy(spec_path(intact), spec_path(path))
    return path


def _row_of(lines: list[bytes], point: int) -> int:
    """The index in ``lines`` of the first row of ``point``."""
    return next(k for k, line in enumerate(lines) if line.startswith(f"{point},".encode()))


def _without_point(lines: list[bytes], point: int) -> list[bytes]:
    return [line for line in lines if not line.startswith(f"{point},".encode())]


def _damage(lines: list[bytes], case: str) -> tuple[list[bytes], set[int], str]:
    """The damaged lines, the points that must survive, and what the one line must say."""
    k = _row_of(lines, 1)
    row = lines[k]
    out = list(lines)
    garbage = random.Random(21).randbytes(200).replace(b"\n", b"?")
    if case == "garbage line":
        out.insert(k, garbage)
        return out, {0, 1, 2}, "damaged row(s) dropped"
    if case == "not UTF-8":
        out[k] = row + b"\xff\xfe"
        return out, {0, 2}, "not UTF-8"
    if case == "NUL bytes":
        out[k] = row[:-4] + b"\0\0" + row[-4:]
        return out, {0, 2}, "a NUL byte"
    if case == "point 1.5":
        out[k] = b"1.5" + row[1:]
        return out, {0, 2}, "point '1.5' is not an integer"
    if case == "point -1":
        out[k] = b"-1" + row[1:]
        return out, {0, 2}, "point '-1' is not an integer"
    if case == "point 999":
        out.append(b"999" + row[1:])
        return out, {0, 1, 2}, "point 999 is not one of the study's 0..2"
    if case == "altered parameter":
        assert row.startswith(b"1,0.5,")
        out[k] = b"1,0.5000001," + row[len(b"1,0.5,"):]
        return out, {0, 2}, "the parameter values of point 1 are not the study's"
    if case == "parameter of another point":
        out[k] = b"1,0.3," + row[len(b"1,0.5,"):]
        return out, {0, 2}, "the parameter values of point 1 are not the study's"
    if case == "a column less":
        out[k] = row[: row.rindex(b",")]
        return out, {0, 2}, "11 columns, not 12"
    if case == "a column more":
        out[k] = row + b",7"
        return out, {0, 2}, "13 columns, not 12"
    if case == "number column":
        fields = row.split(b",")
        fields[6] = b"x"  # s
        out[k] = b",".join(fields)
        return out, {0, 2}, "a number column holds no number"
    if case == "rows count":
        out[k] = row[: row.rindex(b",") + 1] + b"0"
        return out, {0, 2}, "rows '0' is not a positive integer"
    if case == "row repeated":
        out.insert(k, row)
        return out, {0, 2}, "1 incomplete point(s) dropped"
    raise AssertionError(case)


CASES = ["garbage line", "not UTF-8", "NUL bytes", "point 1.5", "point -1", "point 999",
         "altered parameter", "parameter of another point", "a column less", "a column more",
         "number column", "rows count", "row repeated"]


@pytest.mark.parametrize("case", CASES)
def test_a_damaged_row_is_dropped_with_its_point(intact, tmp_path, case):
    lines = _lines(intact)
    damaged, survivors, says = _damage(lines, case)
    path = _copy(intact, tmp_path, damaged)
    table = StudyTable(Study.from_spec(BAR), path)
    assert table.done == survivors, case
    assert says in table.repaired and "\n" not in table.repaired, table.repaired
    kept = [line for line in lines[1:] if int(line.split(b",")[0]) in survivors]
    assert _lines(path) == [lines[0], *kept]  # rewritten: the intact rows of whole points


def test_a_repaired_table_ends_as_the_intact_one(intact, tmp_path):
    """The dropped point is computed again: the table equals the intact one, row for row."""
    damaged, _survivors, _says = _damage(_lines(intact), "altered parameter")
    path = _copy(intact, tmp_path, damaged)
    summary = run_study(Study.from_spec(BAR), path)
    assert (summary.resumed, summary.computed) == (2, 1) and "parameter values" in summary.repaired
    assert sorted(_lines(path)) == sorted(_lines(intact))


def test_an_intact_table_is_not_touched(intact, tmp_path):
    path = _copy(intact, tmp_path, _lines(intact))
    before = path.stat().st_mtime_ns
    table = StudyTable(Study.from_spec(BAR), path)
    assert table.done == {0, 1, 2} and table.repaired == ""
    assert path.stat().st_mtime_ns == before


@pytest.mark.parametrize(("content", "says"), [
    (random.Random(7).randbytes(200), "is not this study's table"),
    (b"", "is not this study's table"),
    (b"\xff\xfe\0" * 70, "is not this study's table"),
    (b"point,k,table\n0,1,fixed\n", "is not this study's table"),
])
def test_a_file_that_is_not_the_table_is_refused_and_kept(intact, tmp_path, content, says):
    path = tmp_path / "other.csv"
    path.write_bytes(content)
    shutil.copy(spec_path(intact), spec_path(path))
    with pytest.raises(InvalidInputError, match=says) as caught:
        StudyTable(Study.from_spec(BAR), path)
    assert "\n" not in str(caught.value) and len(str(caught.value)) < 300
    assert path.read_bytes() == content


@pytest.mark.parametrize("content", [b"\xff\xfe{", b"{\"name\": ", b"[" * 100_000, b"\0"])
def test_a_damaged_study_file_is_refused(intact, tmp_path, content):
    path = _copy(intact, tmp_path, _lines(intact))
    spec_path(path).write_bytes(content)
    with pytest.raises(InvalidInputError, match="is not valid JSON|holds a different study"):
        StudyTable(Study.from_spec(BAR), path)


def test_rows_written_are_one_line_each(tmp_path):
    """A cause or label holding a newline, a carriage return or a NUL (a reply from another
    node) is written on one line without them, so the row reads back."""
    st = Study.from_spec({**BAR, "grid": {"gamma": [0.5]}})
    path = tmp_path / "t.csv"
    table = StudyTable(st, path)
    rows = study_table.evaluate_point(st, 0, {"gamma": 0.5})
    rows = [dataclasses.replace(r, cause="a\nb\r\0c") for r in rows]
    assert table.append(rows)
    (first, *_rest) = read_table(path, st)
    assert first["cause"] == "a b  c" and len(read_table(path, st)) == len(rows)


# -- the command line -------------------------------------------------------------------------

def test_cli_says_what_it_repaired_in_one_line(intact, tmp_path, capsys):
    damaged, _survivors, _says = _damage(_lines(intact), "point 999")
    path = _copy(intact, tmp_path, damaged)
    spec = tmp_path / "bar.yaml"
    spec.write_text(SPEC)
    assert main(["study", str(spec), "--out", str(path), "--no-progress"]) == 0
    out, err = capsys.readouterr()
    assert err.count("\n") == 1 and "point 999 is not one of the study's 0..2" in err, err
    assert "0 computed now, 3 resumed" in out
    assert sorted(_lines(path)) == sorted(_lines(intact))


def test_cli_refuses_a_foreign_file_in_one_line(intact, tmp_path, capsys):
    path = tmp_path / "t.csv"
    path.write_bytes(random.Random(3).randbytes(200))
    shutil.copy(spec_path(intact), spec_path(path))
    spec = tmp_path / "bar.yaml"
    spec.write_text(SPEC)
    assert main(["study", str(spec), "--out", str(path), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is not this study's table" in err and "Traceback" not in err


def test_a_study_that_fails_leaves_nothing_behind(tmp_path, capsys):
    """A reversed s range fails at the first point: the table and study file the run made are
    removed (a later run with a corrected study must not meet them)."""
    spec = tmp_path / "rev.yaml"
    spec.write_text(SPEC + "s_range: [0.5, -0.5]\n")
    assert main(["study", str(spec), "--out", str(tmp_path / "t.csv"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rev.yaml"]


def test_an_interrupted_study_exits_130_and_resumes(tmp_path, capsys, monkeypatch):
    """SIGINT after the first point: the run stops after it, says so, exits 130 (as a shell
    gives an interrupted command) and writes no --mcap of a part of the table; the next run
    computes the rest."""
    real = study_table.evaluate_point

    def then_interrupt(*args):
        rows = real(*args)
        os.kill(os.getpid(), signal.SIGINT)
        return rows

    monkeypatch.setattr(study_table, "evaluate_point", then_interrupt)
    spec = tmp_path / "bar.yaml"
    spec.write_text(SPEC)
    out = tmp_path / "t.csv"
    argv = ["study", str(spec), "--out", str(out), "--no-progress", "--mcap",
            str(tmp_path / "t.mcap")]
    assert main(argv) == 130
    assert "1 computed now" in capsys.readouterr().out and not (tmp_path / "t.mcap").exists()
    monkeypatch.setattr(study_table, "evaluate_point", real)
    assert main(argv) == 0
    assert "2 computed now, 1 resumed" in capsys.readouterr().out


def test_a_large_table_resumes_in_one_pass(tmp_path):
    """A resume reads every row once: 5,000 points of two rows each are checked against the
    study and kept in 0.9 s here (comparing each row with every other, as resume once did,
    took 88 s)."""
    n = 5_000
    study = Study.from_spec({**BAR, "grid": {"gamma": [0.3 + k * 1e-5 for k in range(n)]}})
    header = study_table._header(study)
    rows = [",".join(header)]
    for k, point in enumerate(study.points()):
        for s in (-0.1, 0.1):  # (repr of each float, as the table writes it)
            rows.append(f"{k},{point['gamma']!r},fixed,outcome,,kink,{s!r},1.0,2.0,1.0,,2")
    path = tmp_path / "large.csv"
    path.write_text("\n".join(rows) + "\n")
    spec_path(path).write_text(json.dumps(study.as_dict(), indent=1))
    start = time.perf_counter()
    table = StudyTable(study, path)
    elapsed = time.perf_counter() - start
    print(f"resumed {n} points in {elapsed:.2f} s")  # (with -s)
    assert table.done == set(range(n)) and table.repaired == ""
    # 30x the time measured: a loaded machine passes, a scan of every row per row does not
    assert elapsed < 30, elapsed
