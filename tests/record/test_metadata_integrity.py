"""Damaged metadata records: ``info`` and ``report`` give the recording's own answer or a clean
one-line error, never a traceback and never an answer from altered metadata.

A metadata record lies outside the CRC-checked chunks. The writer seals each one with a CRC of
its own (key ``crc32``); a file written without it (an older recording) is checked by a
validated parse of every key used. Every byte of the metadata records of small recordings (a
fixed-input sweep of the biped, sealed and not, a sweep of another system) is damaged in turn,
and both commands run in-process on the result. (The writer writes no attachments, and the
readers read none.)
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import biped_opt.plots.figures
import biped_opt.record.report
from biped_opt import simulate
from biped_opt.cli.info_cmd import describe
from biped_opt.cli.main import main
from biped_opt.nodes import convert
from biped_opt.paper.problems import get_problem
from biped_opt.piecewise import theta_grid
from biped_opt.record import SweepWriter, writer
from biped_opt.record.reader import read_raw
from biped_opt.simulation.compiled import CompiledSystem

NS = 1_000_000_000
PREFIX = 9  # opcode and length in front of every record
METADATA = 0x0C


def _sweep_points(w: SweepWriter, points: list[dict]) -> None:
    offset = 0
    for p in points:
        w.write("/biped/sweep", p, offset)
        offset += NS


def biped_sweep(path, *, seal: bool = True):
    """A fixed-input liftoff sweep of 9 angles, SweepPoints only (all a report reads), with the
    metadata the recorder writes."""
    problem = get_problem("liftoff")
    u = np.array([1.5, 3.0, 0.0])
    meta = {"maneuver": "liftoff", "theta0_min": -0.04, "theta0_max": 0.04, "num": 9,
            "optimal": False, "fixed_inputs": json.dumps([1.5, 3.0]),
            "cost": json.dumps(problem.describe())}
    points = []
    for th in theta_grid(-0.04, 0.04, 9):
        tr = simulate("liftoff", th, u)
        points.append({"maneuver": "liftoff", "theta0": th, "policy": list(u),
                       "value": float(problem.cost(tr.outcome, u)), "outcome": tr.outcome,
                       "t_final": tr.t_final, "event_times": list(tr.event_times),
                       "mode_sequence": [int(m) for m in tr.mode_sequence]})
    _write(path, {k: str(v) for k, v in meta.items()}, points, seal=seal)
    return path


def system_sweep(path):
    """A fixed-input sweep of the rocking bar's drop: its SystemInfo on /biped/system_info and
    in the biped_opt.system record, and 7 SweepPoints."""
    bar = CompiledSystem("rocking_bar")
    info = convert.system_info_fields(bar, "rocking_bar")
    u = [0.0] * len(bar.inputs)
    meta = {"system": "rocking_bar", "maneuver": "drop", "theta0_min": -0.3,
            "theta0_max": 0.3, "num": 7, "optimal": False, "fixed_inputs": json.dumps(u)}
    points = []
    for s in theta_grid(-0.3, 0.3, 7):
        tr = bar.simulate("drop", s, u)
        points.append({"maneuver": "drop", "theta0": s, "policy": u, "value": math.nan,
                       "outcome": tr.outcome, "t_final": tr.t_final,
                       "mode_sequence": list(tr.modes), "event_times": list(tr.event_times)})
    _write(path, {k: str(v) for k, v in meta.items()}, points, system=info)
    return path


def _write(path, meta, points, *, seal=True, system=None):
    sealed = writer.sealed
    if not seal:  # as the writer did before records carried their CRC
        writer.sealed = lambda _name, pairs: dict(pairs)
    try:
        with SweepWriter(path, metadata=meta, system=system) as w:
            _sweep_points(w, points)
    finally:
        writer.sealed = sealed


def _metadata_spans(data: bytes) -> list[tuple[int, int]]:
    """(start, end) of every metadata record of the data section."""
    spans, pos = [], 8
    while pos + PREFIX <= len(data):
        opcode = data[pos]
        length = int.from_bytes(data[pos + 1:pos + PREFIX], "little")
        if opcode == METADATA:
            spans.append((pos, pos + PREFIX + length))
        if opcode == 0x0F:  # data end: the summary follows
            break
        pos += PREFIX + length
    return spans


@pytest.fixture(autouse=True)
def no_drawing(monkeypatch):
    """The figures only draw the arrays the report computed from the file: drawing each of
    hundreds of variants would take minutes and test matplotlib (one report draws for real)."""
    def placeholder(*args):
        path = args[-1]  # a figure's file is its last argument: the report embeds it in its page
        path.write_bytes(b"not drawn")
        return path

    for name in ("figure2", "figure3", "figure4"):
        monkeypatch.setattr(biped_opt.plots.figures, name, placeholder)
    monkeypatch.setattr(biped_opt.record.report, "_system_figure", placeholder)


def _run(argv, capsys) -> tuple[int, str, str]:
    status = main(argv)  # no exception may come out of it
    out, err = capsys.readouterr()
    return status, out, err


def _check_every_byte(path, tmp_path, capsys, *, may_alter: bool):
    """Damage each byte of each metadata record (one of its low seven bits, which keeps text
    text, or every bit, cycling with the offset); info and report must answer with the file's
    own metadata, without it (a recovered result), or a clean one-line error. Returns the
    outcomes seen (for the caller's expectations).

    Both commands read the file through :func:`read_raw` alone, so what they answer follows
    from what it makes of the file: the reader runs on every damaged copy, and the commands
    once per distinct reading (all of it, the note and every message included). Most damage
    reads the same (a record that fails its CRC), so this checks every byte with a tenth of
    the command runs."""
    data = path.read_bytes()
    whole = read_raw(path)
    original = describe(path)
    points = len({m.data for m in whole.messages if m.topic == "/biped/sweep"})
    spans = _metadata_spans(data)
    assert spans, "the recording must hold a metadata record"
    target = tmp_path / "flipped.mcap"
    outcomes: dict[str, int] = {}
    answered: dict[str, str] = {}  # a reading (its repr) -> the commands' outcome
    for start, end in spans:
        for offset in range(start, end):
            damaged = bytearray(data)
            damaged[offset] ^= 0xFF if offset % 8 == 7 else 1 << offset % 8
            target.write_bytes(bytes(damaged))
            reading = repr(read_raw(target))  # (never an error: the chunks are intact)
            if reading not in answered:
                answered[reading] = _commands(target, tmp_path, capsys, offset, original,
                                              points, may_alter=may_alter)
            kind = answered[reading]
            outcomes[kind] = outcomes.get(kind, 0) + 1
    print(f"{path.name}: {sum(outcomes.values())} bytes damaged, {len(answered)} distinct "
          f"readings: {outcomes}")  # (with -s)
    return outcomes


def _commands(target, tmp_path, capsys, offset, original, points, *, may_alter: bool) -> str:
    """info and report on one damaged file (``offset``: the byte damaged, for the messages);
    what became of its metadata."""
    status, out, err = _run(["info", str(target), "--json"], capsys)
    assert status == 0, (offset, err)  # the chunks are intact: always readable
    info = json.loads(out)
    if info["sweep"] == original["sweep"]:
        kind = "kept"
    elif info["sweep"] == {}:
        kind = "dropped"
        assert not info["complete"], offset  # (the note says why)
    else:
        assert may_alter, (offset, info["sweep"])  # only without a CRC
        kind = "altered"
    assert info["system"] == original["system"], offset
    status, out, err = _run(["report", str(target), "--out", str(tmp_path / "r")], capsys)
    assert "Traceback" not in err, (offset, err)
    if status == 2:
        assert err.count("\n") == 1 and err.startswith("biped-opt report: error: "), err
        kind += ", report refused"
    else:
        assert status == 0 and err == "", (offset, err)
        assert f" sweep, {points} points, " in out, (offset, out)
    return kind


def test_every_byte_of_a_sealed_record(tmp_path, capsys):
    """With the record's CRC nothing altered is ever used: the report is the file's own, or
    the one from its SweepPoints when the record is left out."""
    path = biped_sweep(tmp_path / "sealed.mcap")
    outcomes = _check_every_byte(path, tmp_path, capsys, may_alter=False)
    assert "altered" not in outcomes and outcomes.get("dropped", 0) > 100, outcomes


def test_every_byte_of_an_unsealed_record(tmp_path, capsys):
    """An older file without the CRC: what the validated parse lets through (a changed digit,
    a changed letter in a name) reaches the report, which answers or refuses in one line."""
    path = biped_sweep(tmp_path / "unsealed.mcap", seal=False)
    assert writer.METADATA_CRC not in read_raw(path).metadata["biped_opt.sweep"]
    outcomes = _check_every_byte(path, tmp_path, capsys, may_alter=True)
    assert outcomes.get("dropped", 0) > 0, outcomes


def test_every_byte_of_a_system_record(tmp_path, capsys):
    """A recording of another system loses its biped_opt.system record to damage: the system
    is still known, from its /biped/system_info message, so the report names it."""
    path = system_sweep(tmp_path / "bar.mcap")
    outcomes = _check_every_byte(path, tmp_path, capsys, may_alter=False)
    assert "altered" not in outcomes, outcomes


def test_a_dropped_record_is_said_and_the_report_still_drawn(tmp_path, capsys, monkeypatch):
    """One changed letter in the cost: the record fails its CRC, the note says so, and the full
    report (figures drawn for real) is the one of the maneuver's default problem."""
    monkeypatch.undo()  # (draw for real)
    path = biped_sweep(tmp_path / "one.mcap")
    data = bytearray(path.read_bytes())
    at = data.index(b"theta_star")
    data[at] ^= 0x01  # ("uheta_star": still UTF-8, still JSON)
    path.write_bytes(bytes(data))
    raw = read_raw(path)
    assert raw.metadata == {} and not raw.complete
    assert "metadata record 'biped_opt.sweep' ignored: it fails its CRC" in raw.note
    status, out, err = _run(["report", str(path), "--out", str(tmp_path / "rep")], capsys)
    assert status == 0 and err == "", err
    assert "RECOVERED" in out and (tmp_path / "rep" / "fig2.png").stat().st_size > 10_000


@pytest.mark.parametrize(("name", "pairs", "why"), [
    ("biped_opt.sweep", {"cost": "{"}, "cost: not JSON"),
    ("biped_opt.sweep", {"cost": json.dumps({"decisions": ["u1"], "bounds": {}})},
     "cost: bounds are not one per decision"),
    ("biped_opt.sweep", {"fixed_inputs": "[1, NaN]"}, "not a list of finite numbers"),
    ("biped_opt.sweep", {"fixed_inputs": json.dumps([0] * 100)}, "more inputs"),
    ("biped_opt.sweep", {"num": "1e3"}, "num: invalid literal"),
    ("biped_opt.sweep", {"optimal": "Tru"}, "not True or False"),
    ("biped_opt.sweep", {"theta0_min": "1e999"}, "not finite"),
    ("biped_opt.sweep", {"problem": "[]"}, "no decisions"),
    ("biped_opt.sweep", {"manuever": "x"}, "unknown key 'manuever'"),
    ("biped_opt.system", {"system": "bar"}, "is missing"),
    ("biped_opt.studies.study", {"study": "[" * 100_000}, "not JSON"),
])
def test_a_record_that_fails_its_parse_is_left_out(tmp_path, name, pairs, why):
    path = tmp_path / "r.mcap"
    with SweepWriter(path, metadata=pairs, metadata_name=name) as w:
        _sweep_points(w, [{"maneuver": "touchdown", "theta0": 0.0}])
    raw = read_raw(path)
    assert name not in raw.metadata and not raw.complete
    assert f"metadata record {name!r} ignored: " in raw.note and why in raw.note, raw.note
