"""Reading biped_opt MCAP recordings back, including files a killed recorder left unfinished.

:func:`read_raw` first tries the indexed reader (a finished file); if the file has no valid
summary - its writer was killed before ``finish()`` - it falls back to a stream reader that keeps
every complete chunk and reports how much it recovered (MCAP.md: crash safety).
:func:`read_recording` decodes what :func:`read_raw` returns.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

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

    ``complete`` is False for an unfinished file (its writer was killed) read by recovery;
    ``bytes_read`` is then how far into the file the last complete record reached.
    """

    path: Path
    channels: dict[str, RawChannel]
    messages: tuple[RawMessage, ...]
    metadata: dict[str, dict[str, str]]
    complete: bool
    note: str
    file_size: int
    bytes_read: int

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
    log time; an unfinished file is recovered like :func:`read_recording` does."""
    path = Path(path)
    if not path.is_file():
        raise RecordError(f"no such recording: {path}")
    wanted = None if topics is None else set(topics)
    try:
        return _read_raw_indexed(path, wanted)
    except (McapError, ValueError, EOFError, AssertionError, KeyError):
        return _read_raw_stream(path, wanted)


def _read_raw_indexed(path: Path, wanted: set[str] | None) -> RawRecording:
    size = path.stat().st_size
    with open(path, "rb") as stream:
        reader = make_reader(stream)
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


def _read_raw_stream(path: Path, wanted: set[str] | None) -> RawRecording:
    size = path.stat().st_size
    schemas: dict[int, Schema] = {}
    by_id: dict[int, Channel] = {}
    out: list[RawMessage] = []
    metadata: dict[str, dict[str, str]] = {}
    good = 0
    with open(path, "rb") as stream:
        reader = StreamReader(stream, skip_magic=False, emit_chunks=False)
        try:
            for record in reader.records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    by_id[record.id] = record
                elif isinstance(record, Message):
                    topic = by_id[record.channel_id].topic
                    if wanted is None or topic in wanted:
                        out.append(RawMessage(topic, record.log_time, record.publish_time,
                                              record.data))
                elif isinstance(record, Metadata):
                    metadata[record.name] = dict(record.metadata)
                # a chunk is read whole before its records are yielded, so the position after
                # a record is the end of a complete record
                good = stream.tell()
        except (McapError, EOFError, ValueError, KeyError, AssertionError):
            pass  # the truncated tail: everything before it is complete
    out.sort(key=lambda m: m.log_time_ns)
    channels = {
        ch.topic: _raw_channel(schemas.get(ch.schema_id), ch)
        for ch in by_id.values() if wanted is None or ch.topic in wanted
    }
    note = (f"recovered {len(out)} messages from the complete chunks of an unfinished file "
            f"(its writer was killed): {good} of {size} bytes ({good / max(size, 1):.1%}) "
            "were readable")
    return RawRecording(path=path, channels=channels, messages=tuple(out), metadata=metadata,
                        complete=False, note=note, file_size=size, bytes_read=good)
