"""A study's tidy table on disk: CSV, resumable, computed by one or many local processes.

The table is CSV (what pandas' ``read_csv`` and polars' ``read_csv`` take with no extra
dependency; Parquet would add pyarrow, ~100 MB, for tables of a few thousand rows): one row per
parameter point and nonsmooth point, columns ``point``, the varied parameters, then
:data:`biped_opt.study.COLUMNS`. Next to it, ``<table>.study.json`` holds the study, so that an
interrupted run continues where it stopped: the rows of a parameter point are appended in one
write and flushed; on resume the points whose rows are all there are kept, anything torn (a half
line, a point with missing rows) is dropped and recomputed, and no point appears twice.
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
from biped_opt.study import COLUMNS, Study, StudyRow, evaluate_point

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


def spec_path(path: Path) -> Path:
    return path.with_name(path.name + ".study.json")


def _header(study: Study) -> list[str]:
    return ["point", *study.parameter_names, *COLUMNS]


def _text(study: Study, rows: Iterable[StudyRow]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    for row in rows:
        d = row.as_dict()
        writer.writerow([("" if isinstance(v, float) and math.isnan(v) else v)
                         for v in (d[c] for c in _header(study))])
    return buf.getvalue()


def read_table(path: Path) -> list[dict[str, str]]:
    """The complete rows of a study table (torn lines and incomplete points left out)."""
    text = Path(path).read_text()
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]  # a line cut by an interruption
    rows = list(csv.DictReader(io.StringIO(text)))
    count: dict[str, int] = {}
    for r in rows:
        count[r["point"]] = count.get(r["point"], 0) + 1
    return [r for r in rows if r.get("rows") and str(count[r["point"]]) == r["rows"]]


def _resume(study: Study, path: Path) -> set[int]:
    """Points already complete in ``path`` (rewritten without torn rows), or a new table."""
    spec = spec_path(path)
    if not path.exists():
        path.write_text(",".join(_header(study)) + "\n")
        spec.write_text(json.dumps(study.as_dict(), indent=1))
        return set()
    if not spec.exists():
        raise InvalidInputError(f"--out: {path} exists and is not a study table (no {spec.name})")
    try:
        saved = json.loads(spec.read_text())
    except json.JSONDecodeError:
        raise InvalidInputError(f"--out: {spec} is not valid JSON") from None
    if saved != json.loads(json.dumps(study.as_dict())):
        raise InvalidInputError(f"--out: {path} holds a different study; choose another file "
                                "or remove it to start again")
    with open(path, encoding="utf-8") as fh:
        first = fh.readline().rstrip("\n")
    if first != ",".join(_header(study)):
        raise InvalidInputError(f"--out: {path}: unexpected header {first!r}")
    keep = read_table(path)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=_header(study), lineterminator="\n")
    writer.writeheader()
    writer.writerows(keep)
    if buf.getvalue() != path.read_text():  # drop torn rows once, atomically
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(buf.getvalue())
        os.replace(tmp, path)
    return {int(r["point"]) for r in keep}


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
        self.done = _resume(study, path)
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
                            stopped=stopped or len(self.done) < len(self.points))


def run_study(study: Study, path: Path, *, workers: int = 1,
              progress: Callable[[int, int], None] | None = None,
              stop: Callable[[], bool] | None = None) -> StudySummary:
    """Compute every point of ``study`` not yet in the table at ``path`` (see the module
    docstring) with ``workers`` local processes; ``progress(done, total)`` after each point;
    ``stop()`` true ends the run after the points under way (the table stays resumable)."""
    table = StudyTable(study, path)
    points = table.points
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
    in a ``biped_opt.study`` metadata record. Returns the number of rows written."""
    from biped_opt.record.writer import STUDY_TOPICS, SweepWriter

    rows = sorted(read_table(table), key=lambda r: int(r["point"]))
    names = list(study.parameter_names)

    def number(text: str) -> float:
        return math.nan if text == "" else float(text)

    with SweepWriter(output, metadata={"study": json.dumps(study.as_dict())},
                     topics=STUDY_TOPICS, metadata_name="biped_opt.study") as writer:
        for k, r in enumerate(rows):
            writer.write("/biped/study", {
                "point": int(r["point"]), "parameter_names": names,
                "parameter_values": [float(r[n]) for n in names], "table": r["table"],
                "quantity": r["quantity"], "input": r["input"], "kind": r["kind"],
                "s": number(r["s"]), "left": number(r["left"]), "right": number(r["right"]),
                "size": number(r["size"]), "cause": r["cause"], "rows": int(r["rows"]),
            }, k)
    return len(rows)
