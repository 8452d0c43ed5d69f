"""Republishing a recording with its recorded timing, like ``ros2 bag play``.

:class:`Player` creates one publisher per recorded topic on the ROS backend of
:mod:`biped_opt.ros` (real rclpy or the built-in Cyclone DDS backend), with the QoS the recording's
publishers offered (channel metadata ``offered_qos_profiles``, rosbag2's YAML), and publishes every
message when ``(log time - first log time) / rate`` has elapsed since the start. On rclpy the
recorded CDR bytes are published as they are (rclpy's ``publish`` takes serialized messages);
the built-in backend has no raw-publish API, so each message is decoded into its ``ros.msgs``
class (Cyclone's own deserializer, ~50 us per BipedState) just before its deadline.

Messages are scheduled against one monotonic start time, so timing errors do not accumulate:
each message leaves within a sleep's wake-up latency (typically < 1 ms) of its target.
An unfinished recording (killed writer) is replayed from its complete chunks; :attr:`Player.note`
says how much was recovered.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from biped_opt.errors import BipedOptError
from biped_opt.record.reader import RawRecording, read_raw

__all__ = ["ReplayError", "ReplayStats", "Player", "qos_from_metadata", "MAX_GAP_NS",
           "play_offsets"]


class ReplayError(BipedOptError, ValueError):
    """A replay cannot be set up (bad rate, unknown topic, nothing to play)."""


@dataclass(frozen=True)
class QoSSettings:
    """The integer enums of one offered QoS profile (rosbag2 / rmw numbering)."""

    history: int = 1  #: 1 KEEP_LAST, 2 KEEP_ALL
    depth: int = 10
    reliability: int = 1  #: 1 RELIABLE, 2 BEST_EFFORT
    durability: int = 2  #: 1 TRANSIENT_LOCAL, 2 VOLATILE


def qos_from_metadata(text: str | None) -> QoSSettings:
    """The first profile of a channel's ``offered_qos_profiles`` YAML (defaults when absent).

    ``SYSTEM_DEFAULT`` (0) entries and names instead of integers (Jazzy writes both) map to rmw's
    defaults: KEEP_LAST 10, RELIABLE, VOLATILE.
    """
    default = QoSSettings()
    if not text:
        return default
    try:
        # (libyaml's loader where installed: the pure-Python one takes ~20 ms a channel)
        profiles = yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except (yaml.YAMLError, RecursionError) as exc:
        raise ReplayError(f"offered_qos_profiles is not YAML: {exc}") from None
    if not isinstance(profiles, list) or not profiles or not isinstance(profiles[0], dict):
        return default
    p = profiles[0]
    names = {
        "history": {"keep_last": 1, "keep_all": 2},
        "reliability": {"reliable": 1, "best_effort": 2},
        "durability": {"transient_local": 1, "volatile": 2},
    }

    def integer(value: object) -> int:  # (anything else, as SYSTEM_DEFAULT: rmw's default)
        return value if isinstance(value, int) and not isinstance(value, bool) else 0

    def enum(key: str) -> int:
        value = p.get(key, 0)
        if isinstance(value, str):
            value = names[key].get(value.lower(), 0)
        value = integer(value)
        return value if value in (1, 2) else getattr(default, key)

    depth = integer(p.get("depth", 0))
    return QoSSettings(history=enum("history"), depth=depth if depth > 0 else default.depth,
                       reliability=enum("reliability"), durability=enum("durability"))


@dataclass
class ReplayStats:
    """What a replay did."""

    published: dict[str, int] = field(default_factory=dict)
    loops: int = 0
    seconds: float = 0.0
    #: largest delay of a publish behind its target time [s]
    max_late: float = 0.0
    skipped_types: tuple[str, ...] = ()
    interrupted: bool = False
    #: messages that did not decode into their type, by topic (left out, not published)
    undecodable: dict[str, int] = field(default_factory=dict)
    #: gaps in the recorded times longer than :data:`MAX_GAP_NS`, each played as that long
    cut_gaps: int = 0


#: the longest pause a replay makes between two messages [ns of recorded time]: a recording
#: whose times jump by years (a damaged or hostile file) is played, not waited out
MAX_GAP_NS = 3_600_000_000_000


def play_offsets(log_times: list[int]) -> list[int]:
    """When each message plays [ns of recorded time after the first]: its log time's offset,
    with every gap between two messages longer than :data:`MAX_GAP_NS` cut to that."""
    out, at = [], 0
    for k, t in enumerate(log_times):
        if k:
            at += min(t - log_times[k - 1], MAX_GAP_NS)
        out.append(at)
    return out


class Player:
    """Replays a recording on the ROS backend (see the module docstring).

    ``rate`` scales the speed (2 = twice as fast); ``loop`` starts again after the last message
    until :meth:`stop`; ``topics`` restricts the replay; ``delay`` [s] lets discovery match the
    publishers with subscribers before the first message (``ros2 bag play --delay``).
    """

    def __init__(
        self,
        recording: str | Path | RawRecording,
        *,
        rate: float = 1.0,
        loop: bool = False,
        topics: Iterable[str] | None = None,
        domain_id: int | None = None,
        delay: float = 0.5,
        node_name: str = "biped_opt_player",
    ) -> None:
        if not rate > 0.0 or rate == float("inf"):
            raise ReplayError(f"rate must be a positive finite number, got {rate}")
        if not delay >= 0.0:
            raise ReplayError(f"delay must be >= 0, got {delay}")
        raw = recording if isinstance(recording, RawRecording) else read_raw(recording)
        wanted = list(topics) if topics else None
        if wanted:
            unknown = sorted(set(wanted) - set(raw.channels))
            if unknown:
                raise ReplayError(f"not in {raw.path.name}: {', '.join(unknown)} (recorded: "
                                  f"{', '.join(sorted(raw.channels)) or 'nothing'})")
        self.recording = raw
        self.rate, self.loop, self.delay = float(rate), bool(loop), float(delay)
        self.topics = tuple(wanted) if wanted else tuple(raw.channels)
        self.note = raw.note
        self._stop = threading.Event()
        self._domain_id = domain_id
        self._node_name = node_name

    def stop(self) -> None:
        """Ask :meth:`run` to return after the message under way (thread-safe)."""
        self._stop.set()

    def _wait_until(self, target_ns: int) -> bool:
        """Sleep until ``target_ns`` (monotonic); False when stopped meanwhile."""
        while True:
            remaining = (target_ns - time.monotonic_ns()) * 1e-9
            if remaining <= 0.0:
                return not self._stop.is_set()
            # (in slices: a recording's gap may be centuries, more than a wait can take)
            if self._stop.wait(min(remaining, 1.0)):
                return False

    def run(self, on_publish: Callable[[str, int], None] | None = None) -> ReplayStats:
        """Play (blocking) and return the statistics. ``on_publish(topic, log_time_ns)`` is called
        after each publish (tests use it)."""
        from biped_opt import ros  # the ROS backend is only needed to play

        stats = ReplayStats(published={t: 0 for t in self.topics})
        messages = [m for m in self.recording.messages if m.topic in self.topics]
        context = ros.Context()
        ros.init(args=[], context=context, domain_id=self._domain_id)
        node = ros.Node(self._node_name, context=context)
        try:
            publishers: dict[str, tuple[Any, Callable[[bytes], Any]]] = {}
            skipped = []
            for topic in self.topics:
                channel = self.recording.channels[topic]
                cls = ros.message_type(channel.type)
                if cls is None or channel.message_encoding != "cdr":
                    skipped.append(channel.type)
                    continue
                q = qos_from_metadata(channel.metadata.get("offered_qos_profiles"))
                profile = ros.QoSProfile(
                    history=ros.HistoryPolicy(q.history), depth=q.depth,
                    reliability=ros.ReliabilityPolicy(q.reliability),
                    durability=ros.DurabilityPolicy(q.durability))
                pub = node.create_publisher(cls, topic, profile)
                # rclpy publishes serialized bytes as they are; the built-in backend needs the
                # message object
                decode = bytes if ros.BACKEND == "rclpy" else cls.deserialize
                publishers[topic] = (pub, decode)
            stats.skipped_types = tuple(skipped)
            messages = [m for m in messages if m.topic in publishers]
            if not messages:
                raise ReplayError(f"{self.recording.path.name}: no messages to replay")
            warm: set[str] = set()
            for m in messages:  # the first decode builds Cyclone's deserializer
                if m.topic not in warm:
                    try:
                        publishers[m.topic][1](m.data)
                        warm.add(m.topic)
                    except Exception:  # (counted when it is played)
                        pass
            start = time.monotonic()
            # another Python thread (an executor in the same process) may hold the GIL for up to
            # the switch interval (5 ms by default) when a deadline comes; hand it over sooner
            switch = sys.getswitchinterval()
            sys.setswitchinterval(min(switch, 5e-4))
            try:
                if self._wait_until(time.monotonic_ns() + int(self.delay * 1e9)):
                    self._play(messages, publishers, stats, on_publish)
            except KeyboardInterrupt:  # Ctrl-C (or SIGTERM mapped to it) ends a replay cleanly
                self._stop.set()
            finally:
                sys.setswitchinterval(switch)
            stats.interrupted = self._stop.is_set()
            stats.seconds = time.monotonic() - start
            return stats
        finally:
            node.destroy_node()
            ros.try_shutdown(context=context)

    def _play(self, messages: list[Any], publishers: dict[str, tuple[Any, Any]],
              stats: ReplayStats, on_publish: Callable[[str, int], None] | None) -> None:
        times = [m.log_time_ns for m in messages]
        offsets = play_offsets(times)
        stats.cut_gaps = sum(b - a > MAX_GAP_NS for a, b in zip(times, times[1:]))
        scale = 1.0 / self.rate
        while not self._stop.is_set():
            t0 = time.monotonic_ns()
            for m, offset in zip(messages, offsets):
                pub, decode = publishers[m.topic]
                try:
                    payload = decode(m.data)  # before the deadline: decoding costs no lateness
                except Exception:  # a message its writer cut or garbled: counted, not played
                    if stats.loops == 0:
                        stats.undecodable[m.topic] = stats.undecodable.get(m.topic, 0) + 1
                    continue
                target = t0 + int(offset * scale)
                if not self._wait_until(target):
                    return
                pub.publish(payload)
                stats.max_late = max(stats.max_late, (time.monotonic_ns() - target) * 1e-9)
                stats.published[m.topic] += 1
                if on_publish is not None:
                    on_publish(m.topic, m.log_time_ns)
            stats.loops += 1
            if not self.loop:
                return
