"""Reading biped_opt MCAP recordings back, including files a killed recorder left unfinished.

:func:`read_recording` first tries the indexed reader (a finished file); if the file has no valid
summary - its writer was killed before ``finish()`` - it falls back to a stream reader that decodes
every complete chunk and reports how much it recovered (MCAP.md: crash safety).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from biped_opt.record.writer import RecordError
from biped_opt.ros.interfaces import load_interfaces

__all__ = ["RecordedMessage", "Recording", "read_recording"]


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
    path = Path(path)
    if not path.is_file():
        raise RecordError(f"no such recording: {path}")
    typestore = load_interfaces().typestore
    try:
        return _read_indexed(path, typestore)
    except (McapError, ValueError, EOFError, AssertionError, KeyError):
        return _read_stream(path, typestore)


def _decode(typestore: Any, schema_name: str, data: bytes) -> Any:
    return typestore.deserialize_cdr(data, schema_name)


def _read_indexed(path: Path, typestore: Any) -> Recording:
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        if summary is None:
            raise McapError("no summary")
        out = []
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            out.append(RecordedMessage(channel.topic, message.log_time,
                                       _decode(typestore, schema.name, message.data)))
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return _recording(path, out, metadata, complete=True, note="indexed")


def _read_stream(path: Path, typestore: Any) -> Recording:
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    out: list[RecordedMessage] = []
    metadata: dict[str, dict[str, str]] = {}
    with open(path, "rb") as stream:
        reader = StreamReader(stream, skip_magic=False, emit_chunks=False)
        try:
            for record in reader.records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    channel = channels[record.channel_id]
                    schema = schemas[channel.schema_id]
                    out.append(RecordedMessage(channel.topic, record.log_time,
                                               _decode(typestore, schema.name, record.data)))
                elif isinstance(record, Metadata):
                    metadata[record.name] = dict(record.metadata)
        except (McapError, EOFError, ValueError, KeyError, AssertionError):
            pass  # the truncated tail: everything before it is complete
    out.sort(key=lambda m: m.log_time_ns)
    note = f"recovered {len(out)} messages from an unfinished file (its writer was killed)"
    return _recording(path, out, metadata, complete=False, note=note)


def _recording(path: Path, messages: list[RecordedMessage], metadata: dict[str, dict[str, str]],
               *, complete: bool, note: str) -> Recording:
    counts: dict[str, int] = defaultdict(int)
    for m in messages:
        counts[m.topic] += 1
    return Recording(path=path, messages=tuple(messages), metadata=metadata, complete=complete,
                     note=note, counts=dict(counts))
