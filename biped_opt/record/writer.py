"""MCAP files of biped_opt sweeps in the ROS 2 profile (MCAP.md).

Every file opens in ``ros2 bag info/play``, Foxglove and the ``mcap``/``rosbags`` readers:

- header profile ``ros2``; messages ``cdr``, serialized from the ``msg_defs/`` definitions;
- schemas ``ros2msg``: the ``.msg`` text followed by each dependency after a line of 80 ``=`` and
  ``MSG: pkg/Type`` (rosbags' ``generate_msgdef``);
- channel metadata ``offered_qos_profiles`` (rosbag2's YAML with integer enums, which Humble
  requires) and ``topic_type_hash`` (RIHS01);
- zstd chunks with message indexes, statistics and summary offsets (the ``mcap`` writer's
  defaults, which ``ros2 bag`` needs to list topics);
- a ``biped_opt.sweep`` metadata record with the sweep's parameters.

MCAP gives a metadata record no CRC of its own (only the data section's, which covers every
record at once), so each record written here carries one: the key ``crc32`` holds the CRC-32 of
the record's name and other pairs (:func:`sealed`), and a reader can tell a damaged record from
an intact one even in a file it has to recover.

A recording of another system than the biped (``system=`` the SystemInfo fields) holds
``/biped/system_state`` (SystemState) instead of ``/biped/state`` and ``/biped/contact_mode``, its
SystemInfo once on ``/biped/system_info`` (first, at log time 0) and the same description in a
``biped_opt.system`` metadata record (lists as JSON), so a reader needs no ROS graph to name the
entries of q, the bits of a contact mode or the inputs.

Log times are integer nanoseconds: a sample's simulation time offset by the start of its sweep
point, so a sweep replays in order. :class:`SweepWriter` is a context manager; it finishes the file
on normal exit and on exceptions, and :meth:`SweepWriter.finish_on_signals` makes SIGINT/SIGTERM
finish it too: a signal that arrives while a write is under way is held until the write is done, so
the file never ends in the middle of a batch.
"""

from __future__ import annotations

import contextlib
import json
import signal
import threading
import zlib
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from types import FrameType
from typing import IO, Any

import numpy as np
import numpy.typing as npt
from mcap.writer import CompressionType, Writer

from biped_opt.errors import BipedOptError
from biped_opt.interface_defs import load_definitions
from biped_opt.record.cdr import FixedLayout, compile_layout, numpy_dtype
from biped_opt.record.scene import SCENE_TOPICS, SceneMessages
from biped_opt.version import __version__

__all__ = [
    "RecordError",
    "TOPICS",
    "BIPED_TOPICS",
    "SYSTEM_TOPICS",
    "STUDY_TOPICS",
    "SYSTEM_METADATA",
    "METADATA_CRC",
    "SweepWriter",
    "metadata_crc",
    "sealed",
    "qos_yaml",
    "NS",
]

NS = 1_000_000_000

#: the recorded topics: name -> (ROS type, offered QoS as rosbag2 integer enums)
#: history 1 = KEEP_LAST, reliability 1 = RELIABLE / 2 = BEST_EFFORT, durability 1 =
#: TRANSIENT_LOCAL / 2 = VOLATILE, liveliness 1 = AUTOMATIC
TOPICS: dict[str, tuple[str, dict[str, int]]] = {
    "/biped/state": (
        "biped_opt_interfaces/msg/BipedState",
        {"history": 1, "depth": 5, "reliability": 2, "durability": 2},
    ),
    "/biped/contact_mode": (
        "biped_opt_interfaces/msg/ContactMode",
        {"history": 1, "depth": 10, "reliability": 1, "durability": 1},
    ),
    "/biped/sweep": (
        "biped_opt_interfaces/msg/SweepPoint",
        {"history": 1, "depth": 10, "reliability": 1, "durability": 2},
    ),
    "/biped/system_state": (
        "biped_opt_interfaces/msg/SystemState",
        {"history": 1, "depth": 5, "reliability": 2, "durability": 2},
    ),
    "/biped/system_info": (
        "biped_opt_interfaces/msg/SystemInfo",
        {"history": 1, "depth": 1, "reliability": 1, "durability": 1},
    ),
    "/biped/study": (
        "biped_opt_interfaces/msg/StudyRow",
        {"history": 1, "depth": 10, "reliability": 1, "durability": 2},
    ),
}
TOPICS.update(SCENE_TOPICS)  # /clock, /tf, the markers and /robot_description (ROS.md Sec. 6)
#: the topics of a recording of the biped, and of any other system
BIPED_TOPICS = ("/biped/state", "/biped/contact_mode", "/biped/sweep")
SYSTEM_TOPICS = ("/biped/system_info", "/biped/system_state", "/biped/sweep")
#: the topic of a parameter study's table (:mod:`biped_opt.record.study_table`)
STUDY_TOPICS = ("/biped/study",)
#: name of the metadata record describing a non-biped system (SystemInfo's fields)
SYSTEM_METADATA = "biped_opt.system"
#: the key of a metadata record that holds the CRC of the rest of it (:func:`sealed`)
METADATA_CRC = "crc32"


def metadata_crc(name: str, pairs: Mapping[str, str]) -> str:
    """The CRC-32 (as 8 hex digits) of a metadata record's name and pairs other than
    :data:`METADATA_CRC`, over their JSON text in key order (what any reader can recompute)."""
    items = sorted((k, v) for k, v in pairs.items() if k != METADATA_CRC)
    text = json.dumps([name, items], ensure_ascii=False)
    return f"{zlib.crc32(text.encode('utf-8', 'surrogatepass')):08x}"


def sealed(name: str, pairs: Mapping[str, str]) -> dict[str, str]:
    """``pairs`` with :data:`METADATA_CRC` added: the record as it is written. The CRC comes
    first, so a damaged length that cuts the map short cuts the other pairs, not the CRC."""
    out = {k: v for k, v in pairs.items() if k != METADATA_CRC}
    return {METADATA_CRC: metadata_crc(name, out), **out}


class RecordError(BipedOptError, OSError):
    """A recording cannot be written or read."""


def qos_yaml(profile: Mapping[str, int]) -> str:
    """rosbag2's ``offered_qos_profiles`` YAML for one publisher, enums as integers."""
    lines = [
        f"- history: {profile['history']}",
        f"  depth: {profile['depth']}",
        f"  reliability: {profile['reliability']}",
        f"  durability: {profile['durability']}",
    ]
    for name in ("deadline", "lifespan", "liveliness_lease_duration"):
        lines += [f"  {name}:", "    sec: 2147483647", "    nsec: 4294967295"]
    lines += ["  liveliness: 1", "  avoid_ros_namespace_conventions: false"]
    return "\n".join(lines)


class SweepWriter:
    """Write a sweep (SweepPoints, states, contact modes) to one MCAP file.

    ``output`` is a path or a binary stream (tests use ``BytesIO``). Use as a context manager, or
    call :meth:`finish` yourself; writing after finishing raises :class:`RecordError`.
    ``system`` (SystemInfo's fields as plain values) makes it a recording of that system
    (see the module docstring).
    """

    def __init__(
        self,
        output: str | Path | IO[bytes],
        *,
        metadata: Mapping[str, str] | None = None,
        chunk_size: int = 1 << 20,
        compression: str = "zstd",
        system: Mapping[str, Any] | None = None,
        topics: tuple[str, ...] | None = None,
        metadata_name: str = "biped_opt.sweep",
    ) -> None:
        try:
            kind = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                    "none": CompressionType.NONE}[compression]
        except KeyError:
            raise RecordError(
                f"compression must be zstd, lz4 or none, got {compression!r}"
            ) from None
        self.path = Path(output) if isinstance(output, (str, Path)) else None
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._stream: IO[bytes] = open(self.path, "wb")  # noqa: SIM115 - closed in finish()
        else:
            self._stream = output  # type: ignore[assignment]
        self._lock = threading.RLock()
        self._busy = 0
        self._pending_signal: int | None = None
        # the data section's CRC is what lets a reader detect a damaged byte outside the chunks
        # (the metadata record has no CRC of its own); zlib's CRC costs ~1 ms per MB
        self._writer = Writer(self._stream, chunk_size=chunk_size, compression=kind,
                              enable_data_crcs=True)
        self._writer.start(profile="ros2", library=f"biped_opt {__version__}")
        self.typestore = load_definitions().typestore
        self._channels: dict[str, int] = {}
        self._layouts: dict[tuple[Any, ...], FixedLayout] = {}
        self.system = dict(system) if system is not None else None
        if topics is None:
            topics = BIPED_TOPICS if system is None else SYSTEM_TOPICS
        self.counts: dict[str, int] = {topic: 0 for topic in topics}
        self._sequence = 0
        self.finished = False
        for topic in topics:
            typename, qos = TOPICS[topic]
            text, _ = self.typestore.generate_msgdef(typename, ros_version=2)
            schema = self._writer.register_schema(
                name=typename, encoding="ros2msg", data=text.encode()
            )
            self._channels[topic] = self._writer.register_channel(
                topic=topic,
                message_encoding="cdr",
                schema_id=schema,
                metadata={
                    "offered_qos_profiles": qos_yaml(qos),
                    "topic_type_hash": self.typestore.hash_rihs01(typename),
                },
            )
        if metadata:
            self._writer.add_metadata(metadata_name, sealed(
                metadata_name, {k: str(v) for k, v in metadata.items()}))
        if self.system is not None:
            self._writer.add_metadata(SYSTEM_METADATA, sealed(SYSTEM_METADATA, {
                k: v if isinstance(v, str) else json.dumps(v) for k, v in self.system.items()}))
            self.write("/biped/system_info", self.system, 0)

    # -- lifecycle -------------------------------------------------------------------------
    def __enter__(self) -> SweepWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.finish()

    def finish(self) -> None:
        """Write the summary (indexes, statistics) and close; safe to call twice."""
        with self._lock:
            if self.finished:
                return
            self.finished = True
            self._writer.finish()
            if self.path is not None:
                self._stream.close()

    def _check_open(self) -> None:
        if self.finished:
            raise RecordError("the recording is already finished")

    @contextlib.contextmanager
    def _critical(self) -> Iterator[None]:
        """Hold signals handled by :meth:`finish_on_signals` until the write is complete."""
        self._busy += 1
        try:
            yield
        finally:
            self._busy -= 1
        if not self._busy and self._pending_signal is not None:
            self._on_signal(self._pending_signal, None)

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        if self._busy:
            self._pending_signal = signum
            return
        self.finish()
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        raise SystemExit(128 + signum)

    def finish_on_signals(
        self, signals: Iterable[int] = (signal.SIGINT, signal.SIGTERM)
    ) -> Callable[[], None]:
        """Finish the file on ``signals``, then raise KeyboardInterrupt (SIGINT) or SystemExit
        (128 + signal number). Call from the main thread; returns a function that restores the
        previous handlers."""
        previous = {sig: signal.getsignal(sig) for sig in signals}
        for sig in signals:
            signal.signal(sig, self._on_signal)

        def restore() -> None:
            for sig, old in previous.items():
                signal.signal(sig, old)

        return restore

    # -- messages --------------------------------------------------------------------------
    def write_raw(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """One pre-serialized CDR message (encapsulation header included)."""
        with self._lock, self._critical():
            self._check_open()
            self._writer.add_message(
                self._channels[topic], log_time=int(log_time_ns), data=data,
                publish_time=int(log_time_ns), sequence=self._sequence,
            )
            self._sequence += 1
            self.counts[topic] += 1

    def write(self, topic: str, fields: Mapping[str, Any], log_time_ns: int) -> None:
        """One message built from nested field values (dicts for nested messages)."""
        typename = TOPICS[topic][0]
        msg = _build(self.typestore, typename, fields)
        self.write_raw(topic, bytes(self.typestore.serialize_cdr(msg, typename)), log_time_ns)

    def write_states(
        self,
        *,
        maneuver: str,
        theta0: float,
        samples: npt.NDArray[np.float64],
        stamp_offset_ns: int,
        frame_id: str = "biped",
    ) -> int:
        """All samples of one trajectory on ``/biped/state`` in one vectorised pass.

        ``samples`` has the columns of :attr:`biped_opt.simulation.trajectory.Trajectory.samples`
        (t, y (14), mode, lambda_1, lambda_2). Header stamps and log times are
        ``stamp_offset_ns`` + t. Returns the number written.
        """
        key = (maneuver, frame_id)
        layout = self._layouts.get(key)
        if layout is None:
            layout = compile_layout(
                self.typestore, TOPICS["/biped/state"][0],
                {"header.frame_id": frame_id, "maneuver": maneuver},
            )
            self._layouts[key] = layout
        n = samples.shape[0]
        stamps = stamp_offset_ns + np.round(samples[:, 0] * NS).astype(np.int64)
        msgs = layout.empty(n)
        msgs["header.stamp.sec"] = stamps // NS
        msgs["header.stamp.nanosec"] = stamps % NS
        msgs["theta0"] = theta0
        msgs["t"] = samples[:, 0]
        msgs["q"] = samples[:, 1:8]
        msgs["qdot"] = samples[:, 8:15]
        msgs["contact_mode"] = samples[:, 15].astype(np.uint8)
        msgs["contact_force"] = samples[:, 16:18]
        return self._add_batch("/biped/state", layout.serialize(msgs), stamps)


    def write_system_states(
        self,
        *,
        maneuver: str,
        s: float,
        samples: npt.NDArray[np.float64],
        ndof: int,
        stamp_offset_ns: int,
    ) -> int:
        """All samples of one trajectory of the recording's system on ``/biped/system_state``
        in one vectorised pass.

        ``samples`` has the columns of
        :attr:`biped_opt.simulation.compiled.SystemTrajectory.samples`
        (t, q (d), qdot (d), mode, lambda (n)); ``ndof`` is d. Header stamps and log times are
        ``stamp_offset_ns`` + t; the frame id is the system's name. Returns the number written.
        """
        if self.system is None:
            raise RecordError("write_system_states: this is a recording of the biped "
                              "(give system= to record another system)")
        d = int(ndof)
        n = samples.shape[1] - 2 - 2 * d
        name = str(self.system["system"])
        key = ("system", maneuver, d, n)
        layout = self._layouts.get(key)
        if layout is None:
            layout = compile_layout(
                self.typestore, TOPICS["/biped/system_state"][0],
                {"header.frame_id": name, "system": name, "maneuver": maneuver},
                {"q": d, "qdot": d, "contact_force": n},
            )
            self._layouts[key] = layout
        stamps = stamp_offset_ns + np.round(samples[:, 0] * NS).astype(np.int64)
        msgs = layout.empty(samples.shape[0])
        msgs["header.stamp.sec"] = stamps // NS
        msgs["header.stamp.nanosec"] = stamps % NS
        msgs["s"] = s
        msgs["t"] = samples[:, 0]
        if d:
            msgs["q"] = samples[:, 1 : 1 + d]
            msgs["qdot"] = samples[:, 1 + d : 1 + 2 * d]
        msgs["contact_mode"] = samples[:, 1 + 2 * d].astype(np.uint32)
        if n:
            msgs["contact_force"] = samples[:, 2 + 2 * d :]
        return self._add_batch("/biped/system_state", layout.serialize(msgs), stamps)

    def write_scene(self, scene: SceneMessages, *, samples: npt.NDArray[np.float64],
                    stamp_offset_ns: int) -> int:
        """``/clock``, ``/tf`` and the markers of one trajectory's samples (the columns of
        :meth:`write_system_states`), stamped ``stamp_offset_ns`` + t; the number of samples
        shown (:meth:`SceneMessages.messages`, at the scene's rate). The topics must be among
        the recording's."""
        stamps, out = scene.messages(samples, stamp_offset_ns)
        for topic, data in out.items():
            self._add_batch(topic, data, stamps)
        return len(stamps)

    def write_robot_description(self, scene: SceneMessages, log_time_ns: int = 0) -> None:
        """The system's URDF on ``/robot_description`` (once per recording)."""
        self.write_raw("/robot_description", scene.robot_description(), log_time_ns)

    def _add_batch(self, topic: str, data: list[bytes], stamps: npt.NDArray[np.int64]) -> int:
        """Pre-serialized messages of one topic, under one lock and signal hold."""
        channel = self._channels[topic]
        with self._lock, self._critical():
            self._check_open()
            add = self._writer.add_message
            seq = self._sequence
            for item, stamp in zip(data, stamps.tolist()):
                add(channel, log_time=stamp, data=item, publish_time=stamp, sequence=seq)
                seq += 1
            self._sequence = seq
            self.counts[topic] += len(data)
        return len(data)


def _build(typestore: Any, typename: str, fields: Mapping[str, Any]) -> Any:
    """A rosbags message object of ``typename`` from (nested) field values."""
    cls = typestore.types[typename]
    _consts, defs = typestore.fielddefs[typename]
    kwargs: dict[str, Any] = {}
    for name, (kind, spec) in defs:
        kind = getattr(kind, "name", kind)
        value = fields.get(name)
        if kind == "NAME":
            kwargs[name] = _build(typestore, spec, value or {})
        elif kind in ("ARRAY", "SEQUENCE"):
            (_, (base, _)), _count = spec
            items = value if value is not None else []
            kwargs[name] = [str(v) for v in items] if base == "string" else np.asarray(
                items, dtype=numpy_dtype(base))
        else:
            base = spec[0]
            default: Any = "" if base == "string" else (False if base == "bool" else 0)
            kwargs[name] = value if value is not None else default
            if base.startswith("float"):
                kwargs[name] = float(kwargs[name])
    return cls(**kwargs)
