"""Recovery of damaged recordings: every truncation, damaged chunks, files that are not MCAP.

A small recording with several chunks is cut at every byte offset. For each cut the messages
recovered must be exactly those of the chunks that lie wholly before the cut, in log-time order.
The expectation comes from the complete file's own chunk index (read by the ``mcap`` package's
indexed reader), independently of the recovery scan under test.
"""

from __future__ import annotations

import io
import struct

import pytest
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import breakup_chunk
from mcap.writer import Writer

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


def _read_or_refused(path, where, *, may_hold_nothing):
    """read_raw's answer, or None if it refused the file as it should have: as "not an MCAP
    file" when ``where`` (a cut or a damaged byte) lies in the magic, else as "nothing
    recoverable", and only where the caller says that is right."""
    try:
        return read_raw(path)
    except RecordError as exc:
        if where < len(MAGIC):
            assert "not an MCAP file" in str(exc), (where, exc)
        else:
            assert may_hold_nothing and "nothing recoverable" in str(exc), (where, exc)
        return None


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
        raw = _read_or_refused(cut_file, cut, may_hold_nothing=cut < first_end)
        if raw is None:
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


# -- damage outside the chunks and in their framing -----------------------------------------

def _records(data):
    """(offset, opcode) of the top-level records of an intact file, walked by their lengths."""
    out, pos = [], len(MAGIC)
    while pos < len(data) - len(MAGIC):
        opcode, length = struct.unpack_from("<BQ", data, pos)
        out.append((pos, opcode))
        pos += PREFIX + length
    assert pos == len(data) - len(MAGIC), "the walk must end at the closing magic"
    return out


def _span(data, opcode):
    """Where the first top-level record with ``opcode`` starts and ends."""
    offsets = [pos for pos, _op in _records(data)] + [len(data) - len(MAGIC)]
    i = [op for _pos, op in _records(data)].index(opcode)
    return offsets[i], offsets[i + 1]


def _flipped(data, offset, mask, tmp_path, cut=None):
    damaged = bytearray(data[:cut])
    damaged[offset] ^= mask
    target = tmp_path / "flipped.mcap"
    target.write_bytes(bytes(damaged))
    return target


@pytest.mark.parametrize("finished", [True, False])
def test_no_flipped_bit_yields_anything_the_file_did_not_hold(recording, tmp_path, finished):
    """Every byte of the file with one bit flipped (the bit cycling through all eight), finished
    or cut inside the record after its last chunk (where a killed writer leaves it): the read is
    the original, marked complete, or a part of it marked incomplete that lacks at most the
    messages of the one chunk the bit fell in; never a message, a channel definition or an error
    the file does not hold. Beyond the magic every damaged file still reads, except an
    unfinished one whose first chunk, the only definition of its channels, is damaged."""
    path, full, chunks = recording
    data = full if finished else full[:chunks[-1][1] + 20]
    target = tmp_path / "whole.mcap"
    target.write_bytes(data)
    whole = read_raw(target)
    meta_start, meta_end = _span(full, 0x0C)
    for offset in range(len(data)):
        target = _flipped(data, offset, 1 << offset % 8, tmp_path)
        raw = _read_or_refused(target, offset, may_hold_nothing=not finished
                               and chunks[0][0] <= offset < chunks[0][1])
        if raw is None:
            continue
        assert offset >= len(MAGIC), offset
        # MCAP gives the metadata record no CRC of its own; the writer adds one: a bit in it
        # loses the record (the file then is not complete), it never changes it
        assert raw.metadata in (whole.metadata, {}), offset
        assert not (raw.complete and meta_start <= offset < meta_end), offset
        if raw.complete:
            assert raw.messages == whole.messages and raw.channels == whole.channels, offset
            continue
        kept = set(raw.messages)
        assert kept <= set(whole.messages), offset
        assert [m.log_time_ns for m in raw.messages] == sorted(m.log_time_ns for m in kept)
        assert all(raw.channels[m.topic] == whole.channels[m.topic] for m in kept), offset
        lost = {m.log_time_ns for m in whole.messages} - {m.log_time_ns for m in kept}
        assert raw.damaged_chunks <= 1, offset
        assert any(lost <= set(times) for *_se, times in chunks), (offset, lost)


def test_a_damaged_summary_is_not_trusted(recording, tmp_path):
    """A bit in a channel's topic inside the summary: the summary fails its CRC, so the file is
    not read through it; every message comes back under the topic its chunk defined."""
    path, data, _chunks = recording
    whole = read_raw(path)
    summary_channel = [pos for pos, op in _records(data) if op == 0x04][0]
    raw = read_raw(_flipped(data, summary_channel + PREFIX + 2 + 2 + 4 + 3, 0x01, tmp_path))
    assert not raw.complete and "summary is damaged" in raw.note
    assert raw.messages == whole.messages and raw.channels == whole.channels


def test_a_channel_turned_message_in_the_summary_adds_no_message(recording, tmp_path):
    """Opcode 0x04 (channel) with its low bit flipped reads as 0x05 (message), and a channel
    record's first field (its id) is a valid channel id: it must not become a message."""
    path, data, _chunks = recording
    summary_channel = [pos for pos, op in _records(data) if op == 0x04][0]
    raw = read_raw(_flipped(data, summary_channel, 0x01, tmp_path))
    assert raw.messages == read_raw(path).messages and not raw.complete


def test_a_message_index_turned_message_between_chunks_adds_no_message(recording, tmp_path):
    """The same in an unfinished file (no summary to check against): a message index's opcode
    0x07 with bit 1 flipped reads as 0x05; a file written in chunks has no messages outside
    them, so the record is ignored and counted."""
    _path, data, chunks = recording
    cut = chunks[-1][1]  # the writer was killed after its last chunk
    index = [pos for pos, op in _records(data) if op == 0x07][0]
    raw = read_raw(_flipped(data, index, 0x02, tmp_path, cut=cut))
    assert [m.log_time_ns for m in raw.messages] == _expected(chunks, cut)
    assert "1 message, schema or channel records between chunks ignored" in raw.note


def test_a_damaged_chunk_length_loses_that_chunk_only(recording, tmp_path):
    """The top byte of a chunk's record length in an unfinished file: where the next record
    starts is unknown. The scan resumes at the next record framed exactly as a chunk; only the
    damaged chunk is lost, and counted."""
    _path, data, chunks = recording
    start, _end, times = chunks[2]
    raw = read_raw(_flipped(data, start + PREFIX - 1, 0x40, tmp_path, cut=chunks[-1][1]))
    assert raw.damaged_chunks == 1 and not raw.complete
    assert [m.log_time_ns for m in raw.messages] == sorted(
        t for s, _e, ts in chunks if s != start for t in ts)
    assert len(raw.messages) == sum(len(ts) for *_se, ts in chunks) - len(times)


def test_a_finished_file_resumes_on_its_index(recording, tmp_path):
    """A finished file with a damaged chunk length: the index reader would not notice (it reads
    chunks by the index), but the data section's CRC does and sends the file to recovery, which
    resumes after that chunk at the next chunk of the (intact) index; damage a second chunk's
    records too. Those chunks are lost, nothing else."""
    path, data, chunks = recording
    once = read_raw(_flipped(data, chunks[2][0] + PREFIX - 1, 0x40, tmp_path))
    assert not once.complete and once.damaged_chunks == 1
    assert [m.log_time_ns for m in once.messages] == sorted(
        t for i, (*_se, ts) in enumerate(chunks) if i != 2 for t in ts)
    damaged = bytearray(data)
    damaged[chunks[2][0] + PREFIX - 1] ^= 0x40
    damaged[(chunks[4][0] + chunks[4][1] + 40) // 2] ^= 0x10
    target = tmp_path / "twice.mcap"
    target.write_bytes(bytes(damaged))
    raw = read_raw(target)
    assert raw.damaged_chunks == 2 and not raw.complete
    assert [m.log_time_ns for m in raw.messages] == sorted(
        t for i, (*_se, ts) in enumerate(chunks) if i not in (2, 4) for t in ts)
    assert raw.metadata == read_raw(path).metadata


def test_a_damaged_header_in_an_unfinished_file_loses_no_chunk(recording, tmp_path):
    """The header record's length, before any chunk: the scan cannot step over it, resyncs on
    the first chunk, and keeps every complete chunk."""
    _path, data, chunks = recording
    cut = chunks[-1][1]
    raw = read_raw(_flipped(data, len(MAGIC) + 1, 0x80, tmp_path, cut=cut))
    assert [m.log_time_ns for m in raw.messages] == _expected(chunks, cut)
    assert "1 damaged records outside chunks skipped" in raw.note


def test_a_chunk_found_by_resync_may_be_damaged_too(recording, tmp_path):
    """A damaged length in the message index after the first chunk sends the scan looking for
    the next chunk; the chunk it finds has a damaged compression name (not UTF-8): it frames as
    a chunk, so it is one, skipped and counted, and the scan goes on after it."""
    _path, data, chunks = recording
    cut = chunks[-1][1]
    damaged = bytearray(data[:cut])
    damaged[chunks[0][1] + PREFIX - 1] ^= 0x80  # the top byte of the index's length
    damaged[chunks[1][0] + PREFIX + 8 + 8 + 8 + 4 + 4] ^= 0x80  # the "z" of "zstd"
    target = tmp_path / "twice.mcap"
    target.write_bytes(bytes(damaged))
    raw = read_raw(target)
    assert raw.damaged_chunks == 1 and "1 damaged records outside chunks" in raw.note
    assert [m.log_time_ns for m in raw.messages] == sorted(
        t for i, (*_se, ts) in enumerate(chunks) if i != 1 for t in ts)


def test_a_zstd_header_that_declares_exabytes_is_a_damaged_chunk(recording, tmp_path):
    """Bit 7 of a chunk's zstd frame header descriptor widens its content size field to 8 bytes
    of compressed data: a decompressor that believes it asks for exabytes."""
    _path, data, chunks = recording
    start, _end, times = chunks[1]
    frame = start + PREFIX + 8 + 8 + 8 + 4 + 4 + len("zstd") + 8
    assert data[frame:frame + 4] == b"\x28\xb5\x2f\xfd", "the zstd frame magic"
    raw = read_raw(_flipped(data, frame + 4, 0x80, tmp_path))
    assert raw.damaged_chunks == 1
    assert len(raw.messages) == sum(len(ts) for *_se, ts in chunks) - len(times)


def test_a_data_section_crc_is_checked_when_the_writer_computed_one(tmp_path):
    """A record outside the chunks (the metadata) has no CRC of its own: with the data section's
    CRC the damage is seen, and the file is not called complete."""
    path = tmp_path / "crc.mcap"
    with open(path, "wb") as stream:
        writer = Writer(stream, chunk_size=200, enable_data_crcs=True)
        writer.start("test", "test")
        writer.add_metadata("run", {"maneuver": "touchdown"})
        schema = writer.register_schema("s", "jsonschema", b"{}")
        channel = writer.register_channel("/t", "json", schema)
        for k in range(20):
            writer.add_message(channel, k + 1, b"{}", k + 1)
        writer.finish()
    assert read_raw(path).complete
    data = path.read_bytes()
    metadata = [pos for pos, op in _records(data) if op == 0x0C][0]
    raw = read_raw(_flipped(data, metadata + PREFIX + 4 + 2, 0x01, tmp_path))
    assert not raw.complete and "data section fails its CRC" in raw.note
    assert [m.log_time_ns for m in raw.messages] == list(range(1, 21))
