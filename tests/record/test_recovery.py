"""Recovery of damaged recordings: every truncation, damaged chunks, files that are not MCAP.

A small recording with several chunks is cut at every byte offset. For each cut the messages
recovered must be exactly those of the chunks that lie wholly before the cut, in log-time order.
The expectation comes from the complete file's own chunk index (read by the ``mcap`` package's
indexed reader), independently of the recovery scan under test.
"""

from __future__ import annotations

import io

import pytest
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import breakup_chunk

from biped_opt.record import SweepWriter
from biped_opt.record.reader import MAGIC, read_raw, read_recording
from biped_opt.record.writer import RecordError

HEADER = {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "biped"}
PREFIX = 9  # opcode + length in front of every record


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """~5 KB, 24 messages on two topics in several zstd chunks (chunk size 300 bytes)."""
    path = tmp_path_factory.mktemp("recovery") / "small.mcap"
    with SweepWriter(path, metadata={"maneuver": "touchdown"}, chunk_size=300) as w:
        for k in range(24):
            ns = 1_000_000 * (k + 1)
            w.write("/biped/contact_mode", {"header": HEADER, "mode": k % 4}, ns)
            if k % 6 == 5:
                w.write("/biped/contact_mode", {"header": HEADER, "mode": 9}, ns + 1)
    data = path.read_bytes()
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    chunks = []  # (end offset, log times of its messages)
    for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        start = index.chunk_start_offset
        body = data[start + PREFIX:start + index.chunk_length]
        records = breakup_chunk(Chunk.read(ReadDataStream(io.BytesIO(body))))
        times = [r.log_time for r in records if isinstance(r, Message)]
        chunks.append((start, start + index.chunk_length, times))
    assert len(chunks) >= 4, "the recording must span several chunks for the test to mean much"
    return path, data, chunks


def _expected(chunks, cut):
    return sorted(t for _start, end, times in chunks if end <= cut for t in times)


def test_the_complete_file_reads_through_its_index(recording):
    path, _data, chunks = recording
    raw = read_raw(path)
    assert raw.complete and raw.note == "indexed" and raw.damaged_chunks == 0
    assert [m.log_time_ns for m in raw.messages] == _expected(chunks, len(_data))


def test_every_truncation_recovers_exactly_its_complete_chunks(recording, tmp_path):
    path, data, chunks = recording
    first_end = chunks[0][1]
    cut_file = tmp_path / "cut.mcap"
    for cut in range(len(data)):
        cut_file.write_bytes(data[:cut])
        try:
            raw = read_raw(cut_file)
        except RecordError as exc:
            # before the magic: not MCAP; before the first complete chunk: nothing to recover
            if cut < len(MAGIC):
                assert "not an MCAP file" in str(exc), (cut, exc)
            else:
                assert cut < first_end and "nothing recoverable" in str(exc), (cut, exc)
            continue
        assert cut >= first_end, cut
        got = [m.log_time_ns for m in raw.messages]
        assert got == _expected(chunks, cut), cut
        assert not raw.complete and raw.damaged_chunks == 0, cut
        assert raw.bytes_read <= cut


@pytest.mark.parametrize("which", [1, 2, -1])
def test_a_damaged_chunk_is_skipped_and_counted_the_rest_kept(recording, tmp_path, which):
    """One byte flipped in the middle of a chunk's compressed records: its CRC (or the
    decompression) fails; the finished file is then read by recovery, which drops that chunk
    only."""
    path, data, chunks = recording
    start, end, times = chunks[which]
    middle = (start + end + 40) // 2  # past the chunk's 40-odd bytes of fixed fields
    damaged = bytearray(data)
    damaged[middle] ^= 0x10
    target = tmp_path / "damaged.mcap"
    target.write_bytes(bytes(damaged))
    raw = read_raw(target)
    assert not raw.complete and raw.damaged_chunks == 1
    assert "1 damaged chunks" in raw.note and "finished file" in raw.note
    kept = sorted(t for s, _e, ts in chunks if s != start for t in ts)
    assert [m.log_time_ns for m in raw.messages] == kept
    assert len(kept) == sum(len(ts) for *_se, ts in chunks) - len(times)


def test_a_damaged_first_chunk_loses_only_its_own_messages_in_a_finished_file(recording,
                                                                              tmp_path):
    """The summary of a finished file repeats the channel definitions, so the messages of the
    later chunks stay readable when the chunk that first defined the channels is damaged."""
    _path, data, chunks = recording
    start, end, times = chunks[0]
    damaged = bytearray(data)
    damaged[(start + end + 40) // 2] ^= 0x10
    target = tmp_path / "damaged.mcap"
    target.write_bytes(bytes(damaged))
    raw = read_raw(target)
    assert raw.damaged_chunks == 1
    assert [m.log_time_ns for m in raw.messages] == sorted(
        t for *_se, ts in chunks[1:] for t in ts)


def test_messages_whose_channel_was_lost_are_counted(recording, tmp_path):
    """Cut before the summary and damage the chunk that defined the channels: the later
    messages cannot be decoded; the error says how many were dropped and why."""
    _path, data, chunks = recording
    start, end, _times = chunks[0]
    damaged = bytearray(data[:chunks[-1][1]])
    damaged[(start + end + 40) // 2] ^= 0x10
    target = tmp_path / "damaged.mcap"
    target.write_bytes(bytes(damaged))
    later = sum(len(ts) for *_se, ts in chunks[1:])
    with pytest.raises(RecordError, match=f"nothing recoverable: .*1 damaged chunks .*; "
                                          f"{later} messages of channels defined in a damaged"):
        read_raw(target)


@pytest.mark.parametrize(("content", "message"), [
    (b"", "not an MCAP file"),
    (b"these are notes\n", "not an MCAP file"),
    (b"\x89MCAP", "not an MCAP file"),
    (MAGIC, "nothing recoverable"),
    (MAGIC + b"\x01\xff\xff\xff\xff\xff\xff\xff\x7f", "nothing recoverable"),
])
def test_files_that_hold_no_recording_are_errors(tmp_path, content, message):
    target = tmp_path / "bad.mcap"
    target.write_bytes(content)
    with pytest.raises(RecordError, match=message):
        read_raw(target)
    with pytest.raises(RecordError, match=message):
        read_recording(target)


def test_a_directory_or_a_missing_file_is_named(tmp_path):
    with pytest.raises(RecordError, match="is a directory"):
        read_raw(tmp_path)
    with pytest.raises(RecordError, match="no such recording"):
        read_raw(tmp_path / "none.mcap")
