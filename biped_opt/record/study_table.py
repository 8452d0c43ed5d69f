"""A study's tidy table on disk: CSV, resumable, computed by one or many local processes.

The table is CSV (what pandas' ``read_csv`` and polars' ``read_csv`` take with no extra
dependency; Parquet would add pyarrow, ~100 MB, for tables of a few thousand rows): one row per
parameter point and nonsmooth point, columns ``point``, the varied parameters, then
:data:`~biped_opt.studies.study.COLUMNS`.
Next to it, ``<table>.study.json`` holds the study, so that an
interrupted run continues where it stopped: the rows of a parameter point are appended in one
write and flushed; on resume the points whose rows are all there are kept, anything torn (a half
line, a point with missing rows) is dropped and recomputed, and no point appears twice.

On resume every row is checked before it is trusted (:func:`_check_row`): valid UTF-8 without NUL
bytes, the header's number of columns, a point index that is an integer of the study, the
parameter values of that point exactly (they are written as Python's shortest repr, so they read
back equal), numbers where numbers belong. A row that fails is dropped with its whole point, which
is computed again, and the run says so in one line (:attr:`StudySummary.repaired`); a file whose
header or study is not this study's is refused, never rewritten.
"""

from __future__ import annotations

import csv
import io
import json
import math
import multiprocessing
import os
import signal
import time
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

from biped_opt.errors import InvalidInputError
from biped_opt.input_files import InputFileError, read_text
from biped_opt.studies.study import COLUMNS, Study, StudyRow, evaluate_point

__all__ = ["run_study", "read_table", "StudySummary", "StudyTable", "spec_path",
           "write_study_mcap"]


@dataclass(frozen=True)
class StudySummary:
    path: Path
    points: int  #: parameter points of the study
    computed: int  #: computed in this run
    resumed: int  #: already in the table when the run started
    rows: int  #: rows in the table now
    stopped: bool  #: interrupted before every point was done
    #: what resuming dropped from a damaged table (one line), "" when nothing
    repaired: str = ""


def spec_path(path: Path) -> Path:
    return path.with_name(path.name + ".study.json")


def _header(study: Study) -> list[str]:
    return ["point", *study.parameter_names, *COLUMNS]


#: characters a table row never holds: a row is one line, and NUL is no text
_NOT_IN_ROWS = str.maketrans({"\n": " ", "\r": " ", "\0": " "})
#: the result columns that hold numbers ("" for NaN); ``rows``, a positive count, is checked
#: on its own
_NUMBERS = ("s", "left", "right", "size")


def _field(value: object) -> object:
    if isinstance(value, float) and math.isnan(value):
        return ""
    return value.translate(_NOT_IN_ROWS) if isinstance(value, str) else value


def _text(study: Study, rows: Iterable[StudyRow]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    for row in rows:
        d = row.as_dict()
        writer.writerow([_field(d[c]) for c in _header(study)])
    return buf.getvalue()


def _check_row(line: bytes, header: list[str], study: Study | None,
               points: list[dict[str, float]] | None) -> dict[str, str] | str:
    """The row on ``line`` (one line of the table, without its newline) as a dict, or why it
    cannot be trusted (see the module docstring); without a study only its form is checked."""
    if b"\0" in line:
        return "a NUL byte"
    try:
        text = line.decode("utf-8")
    except UnicodeDecodeError:
        return "not UTF-8"
    try:
        (fields,) = list(csv.reader([text]))
    except (csv.Error, ValueError):
        return "not one CSV row"
    if len(fields) != len(header):
        return f"{len(fields)} columns, not {len(header)}"
    row = dict(zip(header, fields))
    if not (row["point"].isascii() and row["point"].isdigit()):
        return f"point {row['point'][:20]!r} is not an integer"
    if not (row["rows"].isascii() and row["rows"].isdigit()) or int(row["rows"]) < 1:
        return f"rows {row['rows'][:20]!r} is not a positive integer"
    try:
        for name in _NUMBERS:
            if row[name]:
                float(row[name])
        values = {n: float(row[n]) for n in header[1:len(header) - len(COLUMNS)]}
    except ValueError:
        return "a number column holds no number"
    if study is None or points is None:
        return row
    index = int(row["point"])
    if index >= len(points):
        return f"point {index} is not one of the study's 0..{len(points) - 1}"
    if values != {n: points[index][n] for n in study.parameter_names}:
        return f"the parameter values of point {index} are not the study's"
    return row


@dataclass
class _Read:
    """A table read back: its complete, checked rows and what was dropped."""

    header: list[str]
    rows: list[dict[str, str]]
    damaged: list[tuple[int, str]]  #: (line number, why) of each row that failed its check
    incomplete: int  #: points whose rows were not all there (or too many)


def _read(path: Path, study: Study | None = None) -> _Read:
    """Every line of the table checked (:func:`_check_row`), complete points only."""
    data = Path(path).read_bytes()
    lines = data.split(b"\n")
    if lines[-1]:
        lines[-1] = b""  # a line cut by an interruption
    first = lines[0].decode("utf-8", "replace")
    header = next(csv.reader([first]), []) if "\0" not in first else []
    if (header[:1] != ["point"] or tuple(header[len(header) - len(COLUMNS):]) != COLUMNS
            or (study is not None and header != _header(study))):
        return _Read(header, [], [], 0)  # not a table (of this study): no row is read
    points = study.points() if study is not None else None
    rows, damaged = [], []
    for number, line in enumerate(lines[1:-1], start=2):
        checked = _check_row(line, header, study, points)
        if isinstance(checked, str):
            damaged.append((number, checked))
        else:
            rows.append(checked)
    groups: dict[str, list[dict[str, str]]] = {}
    for r in rows:
        groups.setdefault(r["point"], []).append(r)
    # a point is complete when each of its rows gives their number (one pass: a table of a
    # million points resumes in seconds)
    whole = {p for p, group in groups.items() if {r["rows"] for r in group} == {str(len(group))}}
    complete = [r for r in rows if r["point"] in whole]
    return _Read(header, complete, damaged, len(groups) - len(whole))


def read_table(path: Path, study: Study | None = None) -> list[dict[str, str]]:
    """The complete rows of a study table (torn lines, rows that fail their check and
    incomplete points left out; with ``study``, rows of other points or parameter values
    too)."""
    return _read(path, study).rows


def _repairs(read: _Read) -> str:
    """One line saying what a resume dropped ("" when nothing)."""
    if not read.damaged and not read.incomplete:
        return ""
    parts = []
    if read.damaged:
        line, why = read.damaged[0]
        more = f" and {len(read.damaged) - 1} more" if len(read.damaged) > 1 else ""
        parts.append(f"{len(read.damaged)} damaged row(s) dropped (line {line}: {why}{more})")
    if read.incomplete:
        parts.append(f"{read.incomplete} incomplete point(s) dropped")
    return "; ".join(parts) + "; their points are computed again"


def _resume(study: Study, path: Path) -> tuple[set[int], str]:
    """Points already complete in ``path`` (rewritten without torn or damaged rows) and what
    was dropped (:func:`_repairs`), or a new table."""
    spec = spec_path(path)
    if not path.exists():
        path.write_text(",".join(_header(study)) + "\n")
        spec.write_text(json.dumps(study.as_dict(), indent=1))
        return set(), ""
    if not spec.exists():
        raise InvalidInputError(f"--out: {path} exists and is not a study table (no {spec.name})")
    try:
        saved = json.loads(read_text(spec, what="study file"))
    except InputFileError as exc:  # (not UTF-8, a device, too large)
        raise InvalidInputError(f"--out: {spec} is not valid JSON "
                                f"({str(exc).split(': ', 1)[-1]})") from None
    except (ValueError, RecursionError):  # (also an integer of more digits than Python reads)
        raise InvalidInputError(f"--out: {spec} is not valid JSON") from None
    if saved != json.loads(json.dumps(study.as_dict())):
        raise InvalidInputError(f"--out: {path} holds a different study; choose another file "
                                "or remove it to start again")
    read = _read(path, study)
    if read.header != _header(study):
        raise InvalidInputError(f"--out: {path} is not this study's table (its first line is "
                                "not the header); choose another file or remove it")
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=_header(study), lineterminator="\n")
    writer.writeheader()
    writer.writerows(read.rows)
    if buf.getvalue().encode() != path.read_bytes():  # drop the rest once, atomically
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(buf.getvalue())
        os.replace(tmp, path)
    return {int(r["point"]) for r in read.rows}, _repairs(read)


def _worker_init() -> None:
    # a terminal's Ctrl-C reaches the whole process group: the parent decides when to stop,
    # the workers finish the point they hold
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def _evaluate(args: tuple[Study, int, dict[str, float]]) -> list[StudyRow]:
    study, index, values = args
    return evaluate_point(study, index, values)


#: longest time a written point stays out of an fsync [s]
SYNC_INTERVAL_S = 1.0


class StudyTable:
    """An open study table: the points already complete in it (``done``, after dropping torn
    rows, see the module docstring) and :meth:`append`, which writes a point's rows in one
    flushed write, and only the first time that point comes (every point exactly once)."""

    def __init__(self, study: Study, path: Path) -> None:
        path = Path(path)
        if not path.parent.is_dir():
            raise InvalidInputError(f"--out: directory {str(path.parent)!r} does not exist")
        self.study, self.path = study, path
        self.points = study.points()
        self.created = not path.exists()
        self.done, self.repaired = _resume(study, path)
        self.resumed = len(self.done)
        self.computed = 0
        self._synced = time.monotonic()

    def pending(self) -> list[int]:
        """The points not yet in the table, in order."""
        return [i for i in range(len(self.points)) if i not in self.done]

    def append(self, rows: list[StudyRow]) -> bool:
        """Write the rows of one point (all of the same ``point``); False, writing nothing,
        when that point is in the table already."""
        index = rows[0].point
        if any(r.point != index for r in rows):
            raise ValueError("append: the rows of one parameter point at a time")
        if index in self.done:
            return False
        with open(self.path, "a", encoding="utf-8") as fh:
            fh.write(_text(self.study, rows))
            fh.flush()  # in the OS's hands: a killed process loses nothing
            now = time.monotonic()
            if now - self._synced >= SYNC_INTERVAL_S:
                # on disk at most this long after: an fsync per point (~10-15 ms on a virtual
                # disk) held the coordinator longer than a point takes; what a power cut loses
                # the next run recomputes
                os.fsync(fh.fileno())
                self._synced = now
        self.done.add(index)
        self.computed += 1
        return True

    def summary(self, stopped: bool) -> StudySummary:
        with open(self.path, "a", encoding="utf-8") as fh:
            os.fsync(fh.fileno())
        return StudySummary(path=self.path, points=len(self.points), computed=self.computed,
                            resumed=self.resumed, rows=len(read_table(self.path)),
                            stopped=stopped or len(self.done) < len(self.points),
                            repaired=self.repaired)

    def discard_if_new(self) -> None:
        """Remove the table and its study file if this run made them and wrote no point: a run
        that fails before its first point (a study that cannot be computed) leaves nothing."""
        if self.created and not self.done:
            for path in (self.path, spec_path(self.path)):
                path.unlink(missing_ok=True)


def run_study(study: Study, path: Path, *, workers: int = 1,
              progress: Callable[[int, int], None] | None = None,
              stop: Callable[[], bool] | None = None) -> StudySummary:
    """Compute every point of ``study`` not yet in the table at ``path`` (see the module
    docstring) with ``workers`` local processes; ``progress(done, total)`` after each point;
    ``stop()`` true ends the run after the points under way (the table stays resumable)."""
    table = StudyTable(study, path)
    try:
        return _run(table, workers, progress, stop)
    except BaseException:
        table.discard_if_new()
        raise


def _run(table: StudyTable, workers: int, progress: Callable[[int, int], None] | None,
         stop: Callable[[], bool] | None) -> StudySummary:
    study, points = table.study, table.points
    pending = table.pending()
    stopped = False

    def append(rows: list[StudyRow]) -> None:
        table.append(rows)
        if progress is not None:
            progress(len(table.done), len(points))

    if progress is not None:
        progress(len(table.done), len(points))
    if workers <= 1:
        for i in pending:
            if stop is not None and stop():
                stopped = True
                break
            append(evaluate_point(study, i, points[i]))
    else:
        # spawn, not fork: the parent may hold Numba's and DDS's threads
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=context,
                                 initializer=_worker_init) as pool:
            queue = list(pending)
            running = set()
            while queue or running:
                while queue and len(running) < 2 * workers and not stopped:
                    i = queue.pop(0)
                    running.add(pool.submit(_evaluate, (study, i, points[i])))
                finished, running = wait(running, return_when=FIRST_COMPLETED)
                for future in finished:
                    append(future.result())
                if stop is not None and stop() and not stopped:
                    stopped = True
                    queue.clear()
    return table.summary(stopped)


def write_study_mcap(study: Study, table: Path, output: Path) -> int:
    """The complete rows of the table at ``table`` as ``/biped/study`` StudyRow messages in an
    MCAP file (ROS 2 profile, like the sweeps; log time = row number in point order), the study
    in a ``biped_opt.studies.study`` metadata record. Returns the number of rows written."""
    from biped_opt.record.writer import STUDY_TOPICS, SweepWriter

    rows = sorted(read_table(table, study), key=lambda r: int(r["point"]))
    names = list(study.parameter_names)

    def number(text: str) -> float:
        return math.nan if text == "" else float(text)

    with SweepWriter(output, metadata={"study": json.dumps(study.as_dict())},
                     topics=STUDY_TOPICS, metadata_name="biped_opt.studies.study") as writer:
        for k, r in enumerate(rows):
            writer.write("/biped/study", {
                "point": int(r["point"]), "parameter_names": names,
                "parameter_values": [float(r[n]) for n in names], "table": r["table"],
                "quantity": r["quantity"], "input": r["input"], "kind": r["kind"],
                "s": number(r["s"]), "left": number(r["left"]), "right": number(r["right"]),
                "size": number(r["size"]), "cause": r["cause"], "rows": int(r["rows"]),
            }, k)
    return len(rows)
