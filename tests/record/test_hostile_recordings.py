"""Files that are not what they claim, through the commands that read recordings: decompression
bombs, special files, and records whose CRCs are right but whose content is hostile (the cases
of ``bench/recording_fuzz.py``, which runs them all with time and memory measured). Each is
refused in one line or read with what cannot be used left out and counted; never a traceback,
never memory the file does not justify."""

from __future__ import annotations

import os
import random
import sys
from pathlib import Path

import pytest

from bench.recording_fuzz import bomb, cases, hostile_rewrites, passed, rewrite, run_command
from biped_opt.cli.main import main
from biped_opt.input_files import InputFileError, read_text
from biped_opt.record.reader import BUDGET_BASE, BUDGET_RATIO, read_raw, read_recording
from biped_opt.record.replay import MAX_GAP_NS, play_offsets
from biped_opt.record.report import load_sweep
from biped_opt.record.writer import RecordError

from .test_report import write_fixed_sweep

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("hostile")


@pytest.fixture(scope="module")
def source(folder):
    """A small fixed-input liftoff sweep written as the recorder writes it."""
    return write_fixed_sweep(folder / "source.mcap", num=9)


@pytest.fixture(scope="module")
def every_case(folder, source):
    return dict(cases(folder, source, seed=7))


def test_a_49_kb_bomb_is_refused_without_inflating_it(folder):
    """One zstd chunk of 1.5 GB of zeros in a 45 KB file, no footer: it declares more than the
    reader's budget (16 MiB + 32 x the file), so nothing is decompressed. In a process of its
    own the refusal must stay below 100 MB of resident memory (the interpreter and the reader's
    modules take about 50) for each command; before the budget, ``info`` took 1.5 GB and two
    minutes."""
    path = bomb(folder / "bomb49.mcap")
    assert path.stat().st_size < 50_000
    for args in (["info", str(path)], ["report", str(path), "--out", str(folder / "r")],
                 ["replay", str(path), "--delay", "0"]):
        result = run_command(args, timeout=120, memory_cap=1 << 30)
        assert result["status"] == 2 and not result["traceback"], result
        assert "reader's budget" in result["first"] and result["lines"] == 1, result
        assert result["peak_mib"] < 100, result


def test_a_chunk_that_inflates_beyond_what_it_declares_is_refused_at_its_declared_size(folder):
    """The same zeros declaring 1 MB: decompression stops at 1 MB + 1 byte, the chunk is
    damaged; the reader never holds more than the declared size of it."""
    path = bomb(folder / "declares_1mb.mcap", inflated=64 << 20, declared=1 << 20)
    with pytest.raises(RecordError, match="nothing recoverable.* 1 damaged chunks"):
        read_raw(path)


def test_chunks_within_the_budget_are_read_until_it_is_spent(folder):
    """Many chunks that each declare their true size: the budget (a function of the file's
    size) runs out and the rest are skipped without being decompressed."""
    path = bomb(folder / "many.mcap", inflated=4 << 20, chunks=100)
    budget = BUDGET_BASE + BUDGET_RATIO * path.stat().st_size
    with pytest.raises(RecordError) as error:
        read_raw(path)
    text = str(error.value)
    assert f"budget of {budget} bytes" in text
    skipped = int(text.split("; ")[-1].split()[0])
    # (the chunks that fit in the budget were decompressed: zeros, no record in them)
    assert skipped == 100 - budget // (4 << 20)


@pytest.mark.parametrize("name", ["/dev/zero", "a FIFO nobody writes", "a directory",
                                  "an empty file", "a symlink to /dev/zero"])
def test_special_files_are_refused_in_one_line(every_case, capsys, name):
    path = every_case[name]
    for args in (["info", str(path)], ["report", str(path), "--out", str(path) + ".out"]):
        assert main(args) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "Traceback" not in err
        assert ("not a regular file" in err or "not a recording" in err
                or "not an MCAP file" in err), err


def test_a_sweep_point_cut_to_7_bytes_is_left_out_and_counted(every_case, source, capsys):
    """CRCs right, one /biped/sweep message of 7 bytes: info and report read the rest, and say
    what they left out (before: SerdeError traceback in report, struct.error in replay)."""
    path = every_case["CRC-valid: sweep point cut to 7 bytes"]
    recording = read_recording(path)
    assert not recording.complete
    assert "1 messages that do not decode left out (/biped/sweep 1)" in recording.note
    sweep = load_sweep(path)
    assert sweep.theta0.size == load_sweep(source).theta0.size - 1 and not sweep.complete
    assert main(["report", str(path), "--out", str(path) + ".out"]) == 0
    out = capsys.readouterr().out
    assert "RECOVERED" in out and "do not decode" in out


@pytest.mark.parametrize("name", [n for n in hostile_rewrites(random.Random(0))])
def test_crc_valid_hostile_records_cost_no_traceback(every_case, capsys, name):
    path = every_case[f"CRC-valid: {name}"]
    for args in (["info", str(path)], ["report", str(path), "--out", str(path) + ".out"]):
        status = main(args)
        captured = capsys.readouterr()
        assert status in (0, 2), (args, captured.err)
        assert "Traceback" not in captured.err and captured.err.count("\n") <= 1


def test_absurd_sweep_points_are_left_out(every_case):
    """A NaN angle, a contact mode of 200 for the biped, a policy of 7 values among 3s: the
    report uses the other points and says how many it left out."""
    sweep = load_sweep(every_case["CRC-valid: absurd sweep points"])
    assert "3 sweep points left out" in sweep.note and not sweep.complete
    assert sweep.theta0.size == 9 - 3


def test_times_beyond_what_ros_represents_are_left_out_and_long_gaps_cut(every_case):
    raw = read_raw(every_case["CRC-valid: log times near 2^64"])
    assert "3 messages with a time beyond 2^63 - 1 ns" in raw.note and not raw.complete
    assert raw.messages[-1].log_time_ns == (1 << 63) - 5
    offsets = play_offsets([m.log_time_ns for m in raw.messages])
    assert max(b - a for a, b in zip(offsets, offsets[1:])) == MAX_GAP_NS


@pytest.mark.skipif(sys.platform != "linux", reason="/proc, FIFOs")
def test_replay_of_hostile_records_publishes_the_rest(every_case, domain_id):
    """Replay (its own process, real DDS) of the cut sweep point and of centuries-long gaps:
    status 0, a note of what it left out or cut, no traceback."""
    for name, note in (("CRC-valid: sweep point cut to 7 bytes", "do not decode"),
                       ("CRC-valid: log times near 2^64", "played as an hour")):
        result = run_command(["replay", str(every_case[name]), "--rate", "1000", "--delay",
                              "0", "--domain-id", str(domain_id)], timeout=120,
                             memory_cap=2 << 30)
        assert passed(result) and result["status"] == 0, result
        assert note in result["first"], result


def test_text_files_are_read_only_if_regular_and_small(tmp_path):
    big = tmp_path / "big.yaml"
    big.write_bytes(b"a: 1\n" * 1000)
    with pytest.raises(InputFileError, match="5000 bytes; a study may have at most 100"):
        read_text(big, limit=100, what="study")
    latin = tmp_path / "latin.yaml"
    latin.write_bytes("a: caf\xe9\n".encode("latin-1"))
    with pytest.raises(InputFileError, match=r"not UTF-8 text \(byte 6"):
        read_text(latin)
    with pytest.raises(InputFileError, match="is a character device, not a regular file"):
        read_text("/dev/zero")
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(InputFileError, match="is a FIFO"):
        read_text(fifo)
    with pytest.raises(InputFileError, match="is a directory"):
        read_text(tmp_path)
    with pytest.raises(InputFileError, match="no such file"):
        read_text(tmp_path / "absent")


def test_the_rewriter_keeps_a_recording_as_it_was(folder, source):
    """Guard of the fuzz's own tool: an unchanged rewrite reads as the source does."""
    same = rewrite(source, folder / "same.mcap", lambda messages: None)
    a, b = read_raw(source), read_raw(same)
    assert b.complete and a.messages == b.messages and a.metadata == b.metadata
