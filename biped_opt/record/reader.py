"""Reading biped_opt MCAP recordings back, including files a killed recorder left unfinished.

:func:`read_raw` first tries the indexed reader (a finished file whose summary passes its CRC,
every chunk's CRC checked); if the file has no usable summary - its writer was killed before
``finish()``, or the summary is damaged - or a chunk is damaged, it falls back to a scan that keeps
every complete, intact chunk, skips and counts damaged ones, and reports how much it recovered
(MCAP.md, "Crash safety"). A file that is not MCAP, or holds
nothing recoverable, is an error.
:func:`read_recording` decodes what :func:`read_raw` returns.

Metadata records lie outside the chunks: nothing but the data section's CRC covers them, and a file
whose data section fails it is read by recovery. So every metadata record is checked before it is
handed on (:func:`checked_metadata`): its own CRC where the writer sealed it
(:func:`biped_opt.record.writer.sealed`), and for the records this package reads, every key and
the type of every value used (JSON that parses to the lists and numbers expected). A record that
fails is left out and the note says so; readers then fall back on what the CRC-checked chunks hold
(the SweepPoints' maneuver and kind, the ``/biped/system_info`` message). Attachments are not
read.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import mmap
import os
import struct
import zlib
from collections import defaultdict
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, ChunkIndex, Message, Metadata, Schema

from biped_opt.input_files import InputFileError, open_regular
from biped_opt.interface_defs import load_definitions
from biped_opt.record.writer import METADATA_CRC, SYSTEM_METADATA, RecordError, metadata_crc

__all__ = [
    "RawChannel", "RawMessage", "RawRecording", "RecordedMessage", "Recording", "checked_metadata",
    "read_raw", "read_recording", "recorded_system", "system_description", "decode_messages",
    "undecodable_note", "MAX_LOG_TIME_NS",
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

    @property
    def system(self) -> dict[str, Any] | None:
        """The recorded system's description (SystemInfo's fields); None for the biped."""
        return system_description(self.metadata)

    def system_states_of(self, s: float) -> npt.NDArray[np.float64]:
        """(t, q (d), qdot (d), mode, lambda (n)) rows of the trajectory of a non-biped system
        recorded for ``s``: the columns of ``SystemTrajectory.samples``."""
        rows = [
            [m.msg.t, *m.msg.q, *m.msg.qdot, m.msg.contact_mode, *m.msg.contact_force]
            for m in self.topic("/biped/system_state") if m.msg.s == s
        ]
        return np.array(rows, dtype=float)


def system_description(metadata: dict[str, dict[str, str]]) -> dict[str, Any] | None:
    """SystemInfo's fields from a recording's ``biped_opt.system`` metadata record (lists are
    stored as JSON); None when there is none (a recording of the biped)."""
    record = metadata.get(SYSTEM_METADATA)
    if record is None:
        return None
    out: dict[str, Any] = {}
    for key, text in record.items():
        try:
            out[key] = text if key in _PLAIN else json.loads(text)
        except (ValueError, RecursionError):
            raise RecordError(f"metadata {SYSTEM_METADATA}: {key} is not JSON: {text[:40]!r}"
                              ) from None
    return out


def recorded_system(raw: RawRecording) -> dict[str, Any] | None:
    """The recorded system's description: the ``biped_opt.system`` metadata record, else (a
    record lost to damage) the ``/biped/system_info`` message, which a CRC-checked chunk holds;
    None for a recording of the biped."""
    described = system_description(raw.metadata)
    if described is not None or raw.channels.get("/biped/system_info") is None:
        return described
    infos, bad = decode_messages(raw, (m for m in raw.messages
                                       if m.topic == "/biped/system_info"))
    if not infos:
        if bad:
            raise RecordError(f"{raw.path}: the system's description is lost: its metadata "
                              "record is missing or damaged and no /biped/system_info "
                              "message decodes")
        return None
    info = infos[0][1]
    return {key: (getattr(info, key) if key in _PLAIN else
                  [float(v) if key in _NUMBER_LISTS else str(v) for v in getattr(info, key)])
            for key in (*_PLAIN, *_NAME_LISTS, *_NUMBER_LISTS)}


# -- metadata: checked before use (see the module docstring) --------------------------------------

#: biped_opt.system: the text fields, the lists of names and of numbers (SystemInfo's fields)
_PLAIN = ("system", "source")
_NAME_LISTS = ("coordinates", "constraints", "inputs", "parameter_names", "maneuvers")
_NUMBER_LISTS = ("parameter_values", "s_min", "s_max")


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)


def _loads(text: str) -> Any:
    try:
        return json.loads(text)
    except (ValueError, RecursionError):
        raise ValueError("not JSON") from None


def _names(text: str) -> None:
    value = _loads(text)
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ValueError("not a list of names")


def _numbers(text: str) -> list[Any]:
    value = _loads(text)
    if not isinstance(value, list) or not all(_finite(v) for v in value):
        raise ValueError("not a list of finite numbers")
    return value


def _number(text: str) -> None:
    if not math.isfinite(float(text)):
        raise ValueError("not finite")


def _integer(text: str) -> None:
    int(text)


def _flag(text: str) -> None:
    if text not in ("True", "False"):
        raise ValueError("not True or False")


def _inputs(text: str) -> None:
    if text and len(_numbers(text)) > 64:
        raise ValueError("more inputs than any system has")


def _pairs_of(value: Any, names: list[str], what: str, check: Any) -> None:
    if not isinstance(value, dict) or set(value) != set(names) or \
            not all(check(value[n]) for n in names):
        raise ValueError(f"{what} are not one per decision")


def _cost(text: str) -> None:
    """The biped's problem (OptimalControlProblem.describe())."""
    d = _loads(text)
    if not isinstance(d, dict) or not isinstance(d.get("decisions"), list) or \
            not all(isinstance(n, str) for n in d["decisions"]):
        raise ValueError("no list of decisions")
    names = d["decisions"]
    _pairs_of(d.get("bounds"), names, "bounds",
              lambda b: isinstance(b, list) and len(b) == 2 and all(_finite(v) for v in b))
    _pairs_of(d.get("alphas"), names, "alphas", _finite)
    if not _finite(d.get("theta_star")):
        raise ValueError("theta_star is not a finite number")
    fixed = d.get("fixed_inputs", {})
    if not isinstance(fixed, dict) or not all(_finite(v) for v in fixed.values()):
        raise ValueError("fixed_inputs are not numbers")
    for key in ("name", "maneuver"):
        if not isinstance(d.get(key, ""), str):
            raise ValueError(f"{key} is not text")


def _problem(text: str) -> None:
    """Another system's problem (Problem.as_dict()): what a report reads of it."""
    d = _loads(text)
    decisions = d.get("decisions") if isinstance(d, dict) else None
    if not isinstance(decisions, dict) or not all(
            isinstance(b, list) and len(b) == 2 and all(_finite(v) for v in b)
            for b in decisions.values()):
        raise ValueError("no decisions with [low, high] bounds")


def _study(text: str) -> None:
    if not isinstance(_loads(text), dict):
        raise ValueError("not a JSON object")


def _text(_text: str) -> None:
    """Any text."""


#: the records this package reads: each key it knows with the check of its value, and the keys
#: that must be there; a record with another key is not this package's record as written
_RECORDS: dict[str, tuple[dict[str, Any], tuple[str, ...]]] = {
    "biped_opt.sweep": ({
        "maneuver": _text, "system": _text, "theta0_min": _number, "theta0_max": _number,
        "num": _integer, "optimal": _flag, "fixed_inputs": _inputs, "cost": _cost,
        "problem": _problem}, ()),
    SYSTEM_METADATA: ({
        **{k: _text for k in _PLAIN}, **{k: _names for k in _NAME_LISTS},
        **{k: _numbers for k in _NUMBER_LISTS}}, (*_PLAIN, *_NAME_LISTS, "parameter_values")),
    "biped_opt.studies.study": ({"study": _study}, ("study",)),
}


def _fault(name: str, pairs: dict[str, str]) -> str:
    """Why a metadata record cannot be used ("" when it can)."""
    crc = pairs.get(METADATA_CRC)
    if crc is not None and crc != metadata_crc(name, pairs):
        return "it fails its CRC"
    if name not in _RECORDS:
        return ""
    checks, required = _RECORDS[name]
    for key, text in pairs.items():
        if key == METADATA_CRC:
            continue
        if key not in checks:
            return f"unknown key {key[:40]!r}"
        try:
            checks[key](text)
        except (ValueError, TypeError, OverflowError) as exc:
            return f"{key}: {exc}"
    missing = [k for k in required if k not in pairs]
    return f"{missing[0]} is missing" if missing else ""


def checked_metadata(records: Iterable[tuple[str, dict[str, str]]]
                     ) -> tuple[dict[str, dict[str, str]], list[str]]:
    """The metadata records that pass their checks (see the module docstring), their CRC key
    removed, and one note per record left out. A later record of a name replaces an earlier."""
    out: dict[str, dict[str, str]] = {}
    notes = []
    for name, pairs in records:
        why = _fault(name, pairs)
        if why:
            notes.append(f"metadata record {name[:40]!r} ignored: {why}")
            continue
        out[name] = {k: v for k, v in pairs.items() if k != METADATA_CRC}
    return out, notes


def read_recording(path: str | Path) -> Recording:
    """Decode a recording; recover what can be recovered from an unfinished file. A message
    that does not decode (its CRCs can be intact: a writer may have written anything) is left
    out and counted in the note."""
    raw = read_raw(path)
    messages, bad = decode_messages(raw, raw.messages)
    note = raw.note + undecodable_note(bad)
    return _recording(raw.path, [RecordedMessage(m.topic, m.log_time_ns, msg)
                                 for m, msg in messages], raw.metadata,
                      complete=raw.complete and not bad, note=note)


def decode_messages(raw: RawRecording, messages: Iterable[RawMessage]
                    ) -> tuple[list[tuple[RawMessage, Any]], dict[str, int]]:
    """(message, decoded) for each of ``messages`` of ``raw`` that decodes with its channel's
    type, and how many did not, by topic."""
    typestore = load_definitions().typestore
    out: list[tuple[RawMessage, Any]] = []
    bad: dict[str, int] = defaultdict(int)
    for m in messages:
        try:
            out.append((m, typestore.deserialize_cdr(m.data, raw.channels[m.topic].type)))
        except Exception:  # (any decoding failure: a short, cut or hostile message)
            bad[m.topic] += 1
    return out, dict(bad)


def undecodable_note(bad: dict[str, int]) -> str:
    """"; N messages that do not decode left out (topic n, ...)", or ""."""
    if not bad:
        return ""
    where = ", ".join(f"{topic} {count}" for topic, count in sorted(bad.items()))
    return f"; {sum(bad.values())} messages that do not decode left out ({where})"


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

    ``complete`` is False for a file read by recovery: unfinished (its writer was killed), or
    with a damaged chunk or summary; ``bytes_read`` is then how far into the file the last
    complete record reached.
    """

    path: Path
    channels: dict[str, RawChannel]
    messages: tuple[RawMessage, ...]
    metadata: dict[str, dict[str, str]]
    complete: bool
    note: str
    file_size: int
    bytes_read: int
    #: chunks skipped because their framing, size, CRC or decompression failed (recovery only)
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
    log time. A finished file whose summary passes its CRC, and whose data section does, is
    read through its records with every chunk's size and CRC checked ("indexed"); any other
    file is recovered record by record (:func:`_recover`). Only a regular file is read, mapped
    into memory rather than read into it, and no chunk decompresses beyond its declared size
    or the reader's budget (:class:`_Budget`). A file that is not MCAP, or holds nothing
    recoverable, is a :class:`RecordError`."""
    path = Path(path)
    with _mapped(path) as data:
        if data[:len(MAGIC)] != MAGIC:
            raise RecordError(
                f"{path}: not an MCAP file (it does not start with the MCAP magic)")
        wanted = None if topics is None else set(topics)
        summary, why = _read_summary(data)
        found = _scan(data, summary, _Budget(len(data)))
        if summary is not None and not why and not (found.corrupt or found.skipped
                                                    or found.over_budget):
            return _recording_of(path, data, found, wanted, complete=True, why="")
        if summary is not None and not why:
            why = "a finished file whose index could not read every chunk"
        return _recording_of(path, data, found, wanted, complete=False, why=why)


@contextlib.contextmanager
def _mapped(path: Path) -> Iterator[Any]:
    """The regular file ``path`` mapped read-only (an empty file: ``b""``)."""
    try:
        fd, size = open_regular(path)
    except InputFileError as exc:
        text = str(exc)
        if text.endswith("no such file"):
            raise RecordError(f"no such recording: {path}") from None
        raise RecordError(text.replace("not a regular file", "not a recording")
                          if "is a directory" in text else text) from None
    try:
        if size == 0:
            yield b""
            return
        with mmap.mmap(fd, size, prot=mmap.PROT_READ) as data:
            yield data
    except (OSError, ValueError) as exc:
        if isinstance(exc, RecordError):
            raise
        raise RecordError(f"{path}: cannot read: {exc}") from None
    finally:
        os.close(fd)


#: the reader's budget: what it may decompress and hold, 16 MiB plus 32 times the file's size
#: (this package's recordings decompress to 5-7 times their size); each record kept also
#: counts :data:`RECORD_COST` bytes, what Python holds for it beyond its data
BUDGET_BASE, BUDGET_RATIO, RECORD_COST = 16 << 20, 32, 256


class _OverBudget(ValueError):
    """A chunk that would decompress beyond the reader's budget."""


class _Budget:
    """What a reading may still decompress and keep [bytes] (see :data:`BUDGET_BASE`)."""

    def __init__(self, file_size: int) -> None:
        self.limit = self.left = BUDGET_BASE + BUDGET_RATIO * file_size

    def take(self, size: int) -> None:
        if size > self.left:
            raise _OverBudget(f"{size} bytes beyond the {self.left} the reader has left of "
                              f"its {self.limit}")
        self.left -= size


def _recording_of(path: Path, data: Any, found: _Scan, wanted: set[str] | None, *,
                  complete: bool, why: str) -> RawRecording:
    """The recording of what the scan found: "indexed" (``complete``: a finished, intact
    file) or recovered (:func:`_recover`)."""
    if not complete:
        return _recover(path, data, found, wanted, why)
    schemas, by_id = _definitions(found.chunked, None)
    raw = [m for m in found.chunked if isinstance(m, Message)]
    out, late = _messages(raw, by_id, wanted)
    channels = {ch.topic: _raw_channel(schemas.get(ch.schema_id), ch)
                for ch in by_id.values() if wanted is None or ch.topic in wanted}
    metadata, notes = checked_metadata(found.metadata)
    notes += [late] if late else []
    return RawRecording(path=path, channels=channels, messages=tuple(out), metadata=metadata,
                        complete=not notes, note="; ".join(["indexed", *notes]),
                        file_size=len(data), bytes_read=len(data))


#: the latest log time a recording may give [ns]: ROS 2 times are signed 64-bit nanoseconds
MAX_LOG_TIME_NS = (1 << 63) - 1


def _messages(raw: list[Message], by_id: dict[int, Channel], wanted: set[str] | None
              ) -> tuple[list[RawMessage], str]:
    """The messages of known channels (of ``wanted`` topics) sorted by log time, and a note
    on those left out for a log or publish time beyond :data:`MAX_LOG_TIME_NS` ("" if
    none)."""
    out = [RawMessage(by_id[m.channel_id].topic, m.log_time, m.publish_time, m.data)
           for m in raw if m.channel_id in by_id
           and (wanted is None or by_id[m.channel_id].topic in wanted)]
    kept = [m for m in out if m.log_time_ns <= MAX_LOG_TIME_NS
            and m.publish_time_ns <= MAX_LOG_TIME_NS]
    kept.sort(key=lambda m: m.log_time_ns)
    late = len(out) - len(kept)
    return kept, (f"{late} messages with a time beyond 2^63 - 1 ns (what ROS 2 represents) "
                  "left out" if late else "")


def _definitions(records: list[Any], summary: _Summary | None
                 ) -> tuple[dict[int, Schema], dict[int, Channel]]:
    """Schemas and channels by id: the first definition of an id stands (later ones must
    repeat it); an intact summary supplies those a lost chunk held."""
    schemas: dict[int, Schema] = {}
    by_id: dict[int, Channel] = {}
    for item in records:
        if isinstance(item, Schema):
            schemas.setdefault(item.id, item)
        elif isinstance(item, Channel):
            by_id.setdefault(item.id, item)
    if summary is not None:
        for schema_id, schema in summary.schemas.items():
            schemas.setdefault(schema_id, schema)
        for channel_id, channel in summary.channels.items():
            by_id.setdefault(channel_id, channel)
    return schemas, by_id


# -- the record structure --------------------------------------------------------------------

MAGIC = b"\x89MCAP0\r\n"
#: opcode (1 byte) and content length (8 bytes) in front of every record
_PREFIX = struct.Struct("<BQ")
#: a footer's content: summary_start, summary_offset_start, summary_crc
_FOOTER = struct.Struct("<QQI")
#: a chunk's fixed fields: message start/end time, uncompressed size and CRC, compression length
_CHUNK_HEAD = struct.Struct("<QQQII")
_U64 = struct.Struct("<Q")
_CHUNK_OPCODE = bytes([Opcode.CHUNK])
#: a data end record's content: the CRC of the data section before it (0: not computed)
_DATA_CRC = struct.Struct("<I")
#: what reading a damaged record can raise: all of it means "this record is unusable" (lz4
#: reports a bad frame as RuntimeError; mcap's own decompression of a chunk whose size field
#: is damaged overflows)
_DAMAGED = (McapError, EOFError, ValueError, KeyError, AssertionError, struct.error,
            UnicodeDecodeError, zstandard.ZstdError, RuntimeError, OverflowError)


class _Framing(ValueError):
    """A chunk's own lengths disagree with its record length: either may be the damaged one, so
    where the next record starts is unknown."""


def _record_at(data: Any, pos: int, stop: int) -> tuple[int, int, int] | None:
    """(opcode, body start, end) of the record at ``pos`` if it lies wholly before ``stop``."""
    if pos + _PREFIX.size > stop:
        return None
    opcode, length = _PREFIX.unpack_from(data, pos)
    body = pos + _PREFIX.size
    return (opcode, body, body + length) if length <= stop - body else None


def _stream(data: Any, start: int, end: int) -> ReadDataStream:
    return ReadDataStream(io.BytesIO(data[start:end]))


@dataclass(frozen=True)
class _Summary:
    """What the CRC-checked summary of a finished file says about its data section."""

    start: int  #: where the summary section begins: the data section ends before it
    schemas: dict[int, Schema]
    channels: dict[int, Channel]
    chunk_starts: tuple[int, ...]  #: offsets of the chunk records, ascending


def _crc(data: Any, start: int, end: int) -> int:
    """CRC-32 of ``data[start:end]`` without copying it (a mapped file)."""
    with memoryview(data) as whole, whole[start:end] as part:
        return zlib.crc32(part)


def _read_summary(data: Any) -> tuple[_Summary | None, str]:
    """The summary of a finished file if it passes its CRC (else None), and why the file cannot
    be read through it ("" when it can: the data section also passes its CRC, if it has one).
    Outside chunks these CRCs are the only way to detect a damaged byte, so a summary that fails
    is not used at all."""
    footer = len(data) - len(MAGIC) - _PREFIX.size - _FOOTER.size
    if (footer < len(MAGIC) or data[len(data) - len(MAGIC):] != MAGIC
            or _record_at(data, footer, len(data) - len(MAGIC))
            != (Opcode.FOOTER, footer + _PREFIX.size, footer + _PREFIX.size + _FOOTER.size)):
        return None, "an unfinished file (its writer was killed)"
    start, _offsets, crc = _FOOTER.unpack_from(data, footer + _PREFIX.size)
    damaged = None, "a finished file whose summary is damaged"
    if start == 0:
        return None, "a finished file without a summary"
    if not len(MAGIC) <= start <= footer or (
            crc and _crc(data, start, footer + _PREFIX.size + 2 * _U64.size) != crc):
        return damaged
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    starts: list[int] = []
    pos = start
    while pos < footer:
        record = _record_at(data, pos, footer)
        if record is None:
            return damaged
        opcode, body, pos = record
        try:
            if opcode == Opcode.SCHEMA:
                schema = Schema.read(_stream(data, body, pos))
                schemas[schema.id] = schema
            elif opcode == Opcode.CHANNEL:
                channel = Channel.read(_stream(data, body, pos))
                channels[channel.id] = channel
            elif opcode == Opcode.CHUNK_INDEX:
                starts.append(ChunkIndex.read(_stream(data, body, pos)).chunk_start_offset)
        except _DAMAGED:
            return damaged
    summary = _Summary(start, schemas, channels, tuple(sorted(starts)))
    data_end = start - _PREFIX.size - _DATA_CRC.size
    if _record_at(data, data_end, start) != (Opcode.DATA_END, data_end + _PREFIX.size, start):
        return summary, "a finished file whose data section does not end where its summary says"
    (data_crc,) = _DATA_CRC.unpack_from(data, data_end + _PREFIX.size)
    if data_crc and _crc(data, 0, data_end) != data_crc:
        return summary, "a finished file whose data section fails its CRC"
    return summary, ""


def _decompress(compression: str, data: bytes, size: int, budget: _Budget) -> bytes:
    """A chunk's records, decompressed to at most its declared ``size`` (taken from the
    ``budget`` first): a chunk that declares more than the reader has left, or whose data
    inflates beyond what it declares, is refused before anything beyond that is allocated."""
    budget.take(size)
    if compression == "zstd":
        reader = zstandard.ZstdDecompressor().stream_reader(data)
        parts, got = [], 0
        while got <= size:
            piece = reader.read(size + 1 - got)
            if not piece:
                break
            parts.append(piece)
            got += len(piece)
        out = b"".join(parts)
    elif compression == "lz4":
        import lz4.frame  # (optional: only files written with lz4 need it)

        out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=size + 1)
    elif compression == "":
        out = data
    else:
        raise McapError(f"unsupported chunk compression {compression!r}")
    if len(out) != size:
        raise ValueError(f"chunk decompressed to {'more than ' if len(out) > size else ''}"
                         f"{len(out)} bytes, its header says {size}")
    return out


def _chunk(data: Any, body: int, end: int) -> Chunk:
    """The chunk record whose body is data[body:end], its records still compressed.
    :class:`_Framing` if its own lengths do not add up to the record's."""
    try:
        start, stop, size, crc, name_length = _CHUNK_HEAD.unpack_from(data, body)
        records_at = body + _CHUNK_HEAD.size + name_length + _U64.size
        (records_length,) = _U64.unpack_from(data, records_at - _U64.size)
    except struct.error:
        raise _Framing("chunk fields run past the record") from None
    if records_at + records_length != end:
        raise _Framing("chunk fields disagree with the record length")
    # (a damaged name is no framing error: it fails later as an unsupported compression)
    name = str(data[body + _CHUNK_HEAD.size:records_at - _U64.size], "utf-8", "replace")
    return Chunk(compression=name, data=data[records_at:end], message_start_time=start,
                 message_end_time=stop, uncompressed_crc=crc, uncompressed_size=size)


#: the records a chunk may hold, and how each is read from its body
_IN_CHUNK = {
    Opcode.SCHEMA: lambda stream, _length: Schema.read(stream),
    Opcode.CHANNEL: lambda stream, _length: Channel.read(stream),
    Opcode.MESSAGE: Message.read,
}


def _chunk_records(data: Any, body: int, end: int, budget: _Budget) -> list[Any]:
    """The schemas, channels and messages of a chunk record, after checking its framing
    (:class:`_Framing`), its size and its CRC (a ``_DAMAGED`` error). Every record must fit in
    the chunk, be one a chunk holds and be read to its end; each costs the budget
    :data:`RECORD_COST` bytes."""
    chunk = _chunk(data, body, end)
    records = _decompress(chunk.compression, chunk.data, chunk.uncompressed_size, budget)
    if chunk.uncompressed_crc and zlib.crc32(records) != chunk.uncompressed_crc:
        raise ValueError("chunk fails its CRC")
    out: list[Any] = []
    pos = 0
    while pos < len(records):
        record = _record_at(records, pos, len(records))
        if record is None:
            raise ValueError("a record runs past the end of its chunk")
        opcode, start, pos = record
        read = _IN_CHUNK.get(opcode)
        if read is None:
            raise ValueError(f"a record of opcode {opcode:#x} in a chunk")
        stream = _stream(records, start, pos)
        out.append(read(stream, pos - start))
        if stream.count != pos - start:
            raise ValueError("a record shorter than its length")
        budget.take(RECORD_COST)
    return out


def _resync(data: Any, after: int, stop: int, anchors: tuple[int, ...]) -> int:
    """The first chunk record past ``after``: from an intact summary's index, else the first
    offset holding a record framed exactly as a chunk (chance can hardly do that; its CRC is
    still checked); ``stop`` if there is none."""
    if anchors:
        return next((a for a in anchors if a > after), stop)
    at = after
    while (at := data.find(_CHUNK_OPCODE, at + 1, stop)) != -1:
        record = _record_at(data, at, stop)
        if record is not None:
            try:
                _chunk(data, record[1], record[2])
            except _Framing:
                continue
            return at
    return stop


#: readers of the records that a file written without chunks holds in its data section
_TOP_LEVEL = _IN_CHUNK


# -- recovery --------------------------------------------------------------------------------

@dataclass
class _Scan:
    """What a record-by-record scan of a data section found."""

    chunked: list[Any] = field(default_factory=list)  #: records from intact chunks, in order
    #: schemas, channels and messages standing outside chunks: such records are only trusted in
    #: a file without chunks (a writer that chunks puts them all in chunks, so between chunks
    #: they can only be records whose opcode was damaged)
    loose: list[Any] = field(default_factory=list)
    metadata: list[tuple[str, dict[str, str]]] = field(default_factory=list)
    chunks: int = 0  #: chunk records seen, intact or not
    corrupt: int = 0  #: chunks skipped: framing, size, CRC or decompression failed
    skipped: int = 0  #: records outside chunks that did not parse
    #: chunks skipped because they would have decompressed beyond the reader's budget
    over_budget: int = 0
    budget: int = 0  #: that budget [bytes]
    good: int = len(MAGIC)  #: the end of the last record read
    summary: _Summary | None = None  #: the file's summary, if it passed its CRC


def _scan(data: Any, summary: _Summary | None, budget: _Budget) -> _Scan:
    """Walk the data section by the records' length prefixes (see :func:`_recover`); what it
    decompresses and keeps is taken from ``budget``."""
    stop = summary.start if summary is not None else len(data)
    anchors = summary.chunk_starts if summary is not None else ()
    found = _Scan(summary=summary, budget=budget.limit)
    pos = len(MAGIC)
    trusted = len(MAGIC) - 1  #: the last byte of the last chunk whose framing checked
    resumed = -1  #: where the last resync went: each goes further, so the scan ends
    while pos < stop:
        record = _record_at(data, pos, stop)
        in_chunk = pos in anchors or data[pos] == Opcode.CHUNK
        found.chunks += in_chunk
        try:
            if record is None:
                raise _Framing("the record does not fit in the data section")
            opcode, body, end = record
            if opcode == Opcode.DATA_END:
                found.good = end
                break
            if opcode == Opcode.CHUNK:
                found.chunked += _chunk_records(data, body, end, budget)
                trusted = end - 1
            elif in_chunk:  # the index says a chunk starts here: its opcode is damaged
                raise _Framing("not a chunk where the index has one")
            elif opcode == Opcode.METADATA:
                stream = _stream(data, body, end)
                item = Metadata.read(stream)
                if stream.count != end - body:  # (the map's own length is damaged)
                    raise ValueError("a metadata map shorter than its record")
                budget.take(RECORD_COST + end - body)
                found.metadata.append((item.name, dict(item.metadata)))
            elif opcode in _TOP_LEVEL:
                budget.take(RECORD_COST)
                found.loose.append(_TOP_LEVEL[opcode](_stream(data, body, end), end - body))
        except _OverBudget:
            found.over_budget += 1
            if record is None:  # (cannot be: a record that does not fit takes nothing)
                break
            pos = record[2]
            continue
        except _DAMAGED as exc:
            if in_chunk and not isinstance(exc, _Framing):
                found.corrupt += 1
                pos = end  # only the chunk's content is damaged: the next record follows it
                trusted = end - 1
                continue
            # the damaged length may be this record's own or that of any record read since the
            # last chunk (nothing checks those): resume at the first chunk after that
            resume = _resync(data, max(trusted, resumed, pos if in_chunk else -1), stop, anchors)
            if record is not None or resume < stop:  # (else: where an unfinished file ends)
                found.corrupt += in_chunk
                found.skipped += not in_chunk
            pos = resumed = resume
            continue
        pos = end
        found.good = max(found.good, end)
    return found


def _recover(path: Path, data: Any, found: _Scan, wanted: set[str] | None, why: str
             ) -> RawRecording:
    """Every intact record of the data section of a file that cannot be read through its index:
    its writer was killed (the file ends inside a record), its summary is damaged, or a chunk is.

    The scan (:func:`_scan`) walks the data section's records by their length prefixes. A
    complete chunk is kept if its framing, size and CRC check, else skipped and counted; so is
    one that would decompress beyond the reader's budget. A record that does not fit (the
    one the writer was writing when it stopped), a chunk whose lengths disagree, or a record
    outside a chunk that does not parse leave the next record's start unknown: the scan resumes
    at the next chunk (:func:`_resync`), or ends if there is none.
    An intact summary also supplies the definitions of channels whose chunk was lost; messages of
    a channel whose definition was lost all the same cannot be decoded and are counted."""
    records = found.chunked
    ignored = len(found.loose) if found.chunks else 0
    if not found.chunks:
        records = found.loose
    schemas, by_id = _definitions(records, found.summary)
    raw = [m for m in records if isinstance(m, Message)]
    decodable = [m for m in raw if m.channel_id in by_id]
    orphans = len(raw) - len(decodable)
    losses = "".join([
        f"; {found.corrupt} damaged chunks (framing, size, CRC or decompression failed) skipped"
        if found.corrupt else "",
        f"; {found.skipped} damaged records outside chunks skipped" if found.skipped else "",
        f"; {ignored} message, schema or channel records between chunks ignored as damaged"
        if ignored else "",
        f"; {orphans} messages of channels defined in a damaged chunk dropped" if orphans else "",
        f"; {found.over_budget} records skipped that would have decompressed or held more than "
        f"the reader's budget of {found.budget} bytes (16 MiB + 32 x the file's size)"
        if found.over_budget else "",
    ])
    if not decodable:
        raise RecordError(f"{path}: nothing recoverable: no complete message in its "
                          f"{len(data)} bytes{losses}")
    out, late = _messages(decodable, by_id, wanted)
    losses += f"; {late}" if late else ""
    channels = {
        ch.topic: _raw_channel(schemas.get(ch.schema_id), ch)
        for ch in by_id.values() if wanted is None or ch.topic in wanted
    }
    metadata, notes = checked_metadata(found.metadata)
    note = (f"recovered {len(out)} messages from the complete chunks of {why}: {found.good} of "
            f"{len(data)} bytes ({found.good / max(len(data), 1):.1%}) were readable{losses}"
            + "".join(f"; {n}" for n in notes))
    return RawRecording(path=path, channels=channels, messages=tuple(out),
                        metadata=metadata, complete=False, note=note,
                        file_size=len(data), bytes_read=found.good,
                        damaged_chunks=found.corrupt)
