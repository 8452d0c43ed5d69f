"""Reading biped_opt MCAP recordings back, including files a killed recorder left unfinished.

:func:`read_raw` first tries the indexed reader (a finished file, every chunk's CRC checked); if
the file has no valid summary - its writer was killed before ``finish()`` - or a chunk is damaged,
it falls back to a scan that keeps every complete, intact chunk, skips and counts damaged ones,
and reports how much it recovered (MCAP.md: crash safety). A file that is not MCAP, or holds
nothing recoverable, is an error.
:func:`read_recording` decodes what :func:`read_raw` returns.
"""

from __future__ import annotations

import io
import struct
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Footer, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk

from biped_opt.record.writer import RecordError
from biped_opt.ros.interfaces import load_interfaces

__all__ = [
    "RawChannel", "RawMessage", "RawRecording", "RecordedMessage", "Recording", "read_raw",
    "read_recording",
]


@dataclass(frozen=True)
class RecordedMessage:
    topic: str
    log_time_ns: int
    msg: Any  #: the decoded message (a rosbags dataclass)


@dataclass(frozen=True)
class Recording:
    """Everything in one recording, decoded."""

    path: Path
    messages: tuple[RecordedMessage, ...]
    metadata: dict[str, dict[str, str]]
    #: False when the file was not finished (a killed writer) and was read by recovery
    complete: bool
    #: how the file was read, for humans ("indexed" or "recovered N messages from M chunks")
    note: str
    counts: dict[str, int] = field(default_factory=dict)

    def topic(self, name: str) -> list[RecordedMessage]:
        return [m for m in self.messages if m.topic == name]

    def sweep_points(self) -> list[Any]:
        return [m.msg for m in self.topic("/biped/sweep")]

    def states_of(self, theta0: float) -> npt.NDArray[np.float64]:
        """(t, q (7), qdot (7), mode) rows of the trajectory recorded for ``theta0``."""
        rows = [
            [m.msg.t, *m.msg.q, *m.msg.qdot, m.msg.contact_mode]
            for m in self.topic("/biped/state") if m.msg.theta0 == theta0
        ]
        return np.array(rows, dtype=float).reshape(-1, 16)


def read_recording(path: str | Path) -> Recording:
    """Decode a recording; recover what can be recovered from an unfinished file."""
    raw = read_raw(path)
    typestore = load_interfaces().typestore
    messages = [
        RecordedMessage(m.topic, m.log_time_ns,
                        typestore.deserialize_cdr(m.data, raw.channels[m.topic].type))
        for m in raw.messages
    ]
    return _recording(raw.path, messages, raw.metadata, complete=raw.complete, note=raw.note)


def _recording(path: Path, messages: list[RecordedMessage], metadata: dict[str, dict[str, str]],
               *, complete: bool, note: str) -> Recording:
    counts: dict[str, int] = defaultdict(int)
    for m in messages:
        counts[m.topic] += 1
    return Recording(path=path, messages=tuple(messages), metadata=metadata, complete=complete,
                     note=note, counts=dict(counts))


# -- raw access (replay, info, rosbag2 export) ---------------------------------------------------

@dataclass(frozen=True)
class RawChannel:
    """One recorded topic: its ROS type, encodings and channel metadata (QoS, type hash)."""

    topic: str
    type: str  #: the schema name, ``pkg/msg/Name``
    message_encoding: str
    schema_encoding: str
    schema_data: bytes
    metadata: dict[str, str]


class RawMessage(NamedTuple):
    topic: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes  #: the serialized message (CDR with its encapsulation header)


@dataclass(frozen=True)
class RawRecording:
    """A recording's channels and still-serialized messages in log-time order.

    ``complete`` is False for a file read by recovery: unfinished (its writer was killed) or
    with damaged chunks; ``bytes_read`` is then how far into the file the last complete record
    reached.
    """

    path: Path
    channels: dict[str, RawChannel]
    messages: tuple[RawMessage, ...]
    metadata: dict[str, dict[str, str]]
    complete: bool
    note: str
    file_size: int
    bytes_read: int
    #: chunks skipped because their CRC or decompression failed (recovery only)
    damaged_chunks: int = 0

    @property
    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {topic: 0 for topic in self.channels}
        for m in self.messages:
            out[m.topic] += 1
        return out

    @property
    def time_range_ns(self) -> tuple[int, int] | None:
        if not self.messages:
            return None
        return self.messages[0].log_time_ns, self.messages[-1].log_time_ns


def _raw_channel(schema: Schema | None, channel: Channel) -> RawChannel:
    return RawChannel(
        topic=channel.topic,
        type=schema.name if schema is not None else "",
        message_encoding=channel.message_encoding,
        schema_encoding=schema.encoding if schema is not None else "",
        schema_data=bytes(schema.data) if schema is not None else b"",
        metadata=dict(channel.metadata),
    )


def read_raw(path: str | Path, topics: Iterable[str] | None = None) -> RawRecording:
    """Channels and serialized messages of a recording (only ``topics`` when given), sorted by
    log time. A finished file is read through its index with every chunk's CRC checked; an
    unfinished or damaged one is recovered record by record (:func:`_recover`). A file that is
    not MCAP, or holds nothing recoverable, is a :class:`RecordError`."""
    path = Path(path)
    if path.is_dir():
        raise RecordError(f"{path}: is a directory, not a recording")
    if not path.is_file():
        raise RecordError(f"no such recording: {path}")
    wanted = None if topics is None else set(topics)
    try:
        with open(path, "rb") as stream:
            head = stream.read(len(MAGIC))
    except OSError as exc:
        raise RecordError(f"{path}: cannot read: {exc.strerror}") from None
    if head != MAGIC:
        raise RecordError(f"{path}: not an MCAP file (it does not start with the MCAP magic)")
    try:
        return _read_raw_indexed(path, wanted)
    except (*_DAMAGED, OSError):  # (a file shorter than a footer: seeking before its start)
        return _recover(path, wanted)


def _read_raw_indexed(path: Path, wanted: set[str] | None) -> RawRecording:
    size = path.stat().st_size
    with open(path, "rb") as stream:
        reader = make_reader(stream, validate_crcs=True)
        summary = reader.get_summary()
        if summary is None:
            raise McapError("no summary")
        channels = {
            ch.topic: _raw_channel(summary.schemas.get(ch.schema_id), ch)
            for ch in summary.channels.values() if wanted is None or ch.topic in wanted
        }
        out = [
            RawMessage(channel.topic, message.log_time, message.publish_time, message.data)
            for _schema, channel, message in reader.iter_messages(
                topics=None if wanted is None else sorted(wanted), log_time_order=True)
        ]
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return RawRecording(path=path, channels=channels, messages=tuple(out), metadata=metadata,
                        complete=True, note="indexed", file_size=size, bytes_read=size)


# -- recovery --------------------------------------------------------------------------------

MAGIC = b"\x89MCAP0\r\n"
#: opcode (1 byte) and content length (8 bytes) in front of every record
_PREFIX = struct.Struct("<BQ")
#: what parsing a damaged record can raise: all of it means "this record is unusable"
#: (lz4 reports a bad frame as RuntimeError)
_DAMAGED = (McapError, EOFError, ValueError, KeyError, AssertionError, struct.error,
            UnicodeDecodeError, zstandard.ZstdError, RuntimeError)


def _recover(path: Path, wanted: set[str] | None) -> RawRecording:
    """Every complete record of a file whose summary cannot be used: the writer was killed
    (the file ends inside a record), or a chunk is damaged.

    The scan walks the top-level records by their length prefixes and stops at the first one
    that does not fit in the file; each complete chunk is decompressed and checked against its
    CRC, and a chunk that fails is skipped and counted, the scan going on after it. Messages of a
    channel whose definition was lost with a damaged chunk cannot be decoded and are counted
    too."""
    data = path.read_bytes()
    schemas: dict[int, Schema] = {}
    by_id: dict[int, Channel] = {}
    raw: list[Message] = []
    metadata: dict[str, dict[str, str]] = {}
    corrupt = 0
    finished = False
    pos = good = len(MAGIC)
    while pos + _PREFIX.size <= len(data):
        opcode, length = _PREFIX.unpack_from(data, pos)
        end = pos + _PREFIX.size + length
        if end > len(data):
            break  # the record the writer was writing when it stopped
        body = ReadDataStream(io.BytesIO(data[pos + _PREFIX.size:end]))
        try:
            if opcode == Opcode.CHUNK:
                records = breakup_chunk(Chunk.read(body), validate_crc=True)
            elif opcode in _TOP_LEVEL:
                records = [_TOP_LEVEL[opcode](body, length)]
            else:  # indexes, statistics, attachments: not needed to recover the messages
                records = []
        except _DAMAGED:
            if opcode != Opcode.CHUNK:
                break  # a damaged record outside a chunk: its length may be wrong too
            corrupt += 1
            records = []
        for record in records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                by_id[record.id] = record
            elif isinstance(record, Message):
                raw.append(record)
            elif isinstance(record, Metadata):
                metadata[record.name] = dict(record.metadata)
        pos = good = end
        if opcode == Opcode.FOOTER:
            finished = True
            break
    decodable = [m for m in raw if m.channel_id in by_id]
    orphans = len(raw) - len(decodable)
    losses = "".join([f"; {corrupt} damaged chunks (CRC or decompression failed) skipped"
                      if corrupt else "",
                      f"; {orphans} messages of channels defined in a damaged chunk dropped"
                      if orphans else ""])
    if not decodable:
        raise RecordError(f"{path}: nothing recoverable: no complete message in its "
                          f"{len(data)} bytes{losses}")
    out = [RawMessage(by_id[m.channel_id].topic, m.log_time, m.publish_time, m.data)
           for m in decodable if wanted is None or by_id[m.channel_id].topic in wanted]
    out.sort(key=lambda m: m.log_time_ns)
    channels = {
        ch.topic: _raw_channel(schemas.get(ch.schema_id), ch)
        for ch in by_id.values() if wanted is None or ch.topic in wanted
    }
    how = ("a finished file with damaged chunks" if finished
           else "an unfinished file (its writer was killed)")
    note = (f"recovered {len(out)} messages from the complete chunks of {how}: {good} of "
            f"{len(data)} bytes ({good / max(len(data), 1):.1%}) were readable{losses}")
    return RawRecording(path=path, channels=channels, messages=tuple(out), metadata=metadata,
                        complete=False, note=note, file_size=len(data), bytes_read=good,
                        damaged_chunks=corrupt)


#: readers of the records that may stand outside chunks
_TOP_LEVEL = {
    Opcode.SCHEMA: lambda stream, _length: Schema.read(stream),
    Opcode.CHANNEL: lambda stream, _length: Channel.read(stream),
    Opcode.MESSAGE: Message.read,
    Opcode.METADATA: lambda stream, _length: Metadata.read(stream),
    Opcode.FOOTER: lambda stream, _length: Footer.read(stream),
}
