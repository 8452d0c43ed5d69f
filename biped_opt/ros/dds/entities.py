"""What a node owns on Cyclone DDS: publishers, subscriptions, timers, and their common base.

Every entity knows the DDS entities it created and deletes them itself, children first, when it
is destroyed (:meth:`Entity.destroy`), instead of leaving them to the garbage collector
(:mod:`.lifetime`). An entity needs of its node only what :class:`Owner` names, so this module
does not depend on the node module that creates its entities.
Taking and destroying are serialised by a lock, so an executor never takes from a reader that is
being deleted. Samples that do not decode are dropped with one log line (rate-limited), never
raised out of the executor (:mod:`.wire`).
"""

from __future__ import annotations

import ctypes
import itertools
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

from cyclonedds.core import (
    DDSException,
    InstanceState,
    Policy,
    ReadCondition,
    SampleState,
    ViewState,
)
from cyclonedds.internal import dds_c_t
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader

from ..interfaces import load_interfaces
from . import graph, wire
from .lifetime import delete_dds
from .log import Logger
from .qos import QoSProfile, to_dds_qos

if TYPE_CHECKING:
    from cyclonedds.topic import Topic

    from .context import Context

__all__ = ["Entity", "Owner", "Publisher", "Subscription", "Timer", "endpoint_id",
           "ignore_deleted", "matched_handles", "type_hash_user_data", "user_data_id",
           "NOT_READ", "LOG_THROTTLE_S"]

#: read-condition mask of every reader: samples not yet taken, in any view or instance state
NOT_READ = SampleState.NotRead | ViewState.Any | InstanceState.Any
#: at most one log line per call site and this many seconds for dropped or rejected samples
LOG_THROTTLE_S = 1.0

_ID_COUNTER = itertools.count(1)


def endpoint_id(participant: Any) -> str:
    """Unique id for ``clientid=``/``serviceid=``, formatted as rmw_cyclonedds does.

    The id is a GID (24 bytes on Humble, 16 on Jazzy): the participant's 12-byte GUID prefix, a
    big-endian counter, zero padding; printed in hex, the first byte two digits wide and the
    others unpadded, separated by dots.
    """
    size = len(graph.gid_bytes(bytes(16)))
    data = participant.get_guid().bytes[:12] + next(_ID_COUNTER).to_bytes(4, "big")
    data += bytes(size - len(data))
    return f"{data[0]:02x}" + "".join(f".{b:x}" for b in data[1:])


def matched_handles(endpoint: DataReader | DataWriter) -> list[int]:
    """The instance handles of the endpoints matched with ``endpoint``: a writer's readers, a
    reader's writers.

    cyclonedds' own ``get_matched_subscriptions`` and ``get_matched_publications`` ask the C
    library for the count, allocate that many handles and ask again; the second call returns
    the count *now*, and when an endpoint matched in between (a client created while a service
    looks) the binding indexes past its buffer and raises IndexError. That is what lost the
    first reply of one of eight concurrent clients: the service's reply step raised on a pool
    thread and nothing answered. The C call fills at most the buffer it is given and returns
    the full count, so here it is repeated with a buffer of that count until the list fits.
    """
    if isinstance(endpoint, DataWriter):
        call, what = endpoint._get_matched_subscriptions, "subscriptions"
    else:
        call, what = endpoint._get_matched_publications, "publications"
    size = 8
    while True:
        handles = (dds_c_t.instance_handle * size)()
        count = call(endpoint._ref, ctypes.cast(handles, ctypes.POINTER(dds_c_t.instance_handle)),
                     size)
        if count < 0:
            raise DDSException(count, f"Occurred when getting the matched {what} of {endpoint!r}")
        if count <= size:
            return [int(h) for h in handles[:count]]
        size = count + 8  # (more matched meanwhile: room for a few more)


def type_hash_user_data(ros_type: str) -> bytes:
    """``typehash=RIHS01_...;`` that Jazzy's rmw_cyclonedds adds to endpoint USER_DATA."""
    if graph.graph_layout() != "jazzy":
        return b""
    try:
        digest = load_interfaces().typestore.hash_rihs01(ros_type)
    except Exception:  # a type rosbags cannot hash: omit it, as rmw does on failure
        return b""
    return f"typehash={digest};".encode()


def user_data_id(qos: Any, key: str) -> str | None:
    """The value of ``key=value;`` in an endpoint's USER_DATA, if any."""
    try:
        data = qos[Policy.Userdata].data
    except (KeyError, TypeError, AttributeError):
        return None
    text = bytes(data).decode("ascii", "replace")
    for item in text.split(";"):
        k, _, v = item.partition("=")
        if k.strip() == key:
            return v.strip()
    return None


class Owner(Protocol):
    """What an entity uses of the node that owns it (:class:`.node.Node`, which creates its
    entities and so sits above them): its context, its topics by DDS name, its logger."""

    context: Context

    def _topic(self, dds_name: str, dds_type: type) -> Topic: ...

    def get_logger(self) -> Logger: ...


def _ros_type(msg_type: type) -> str:
    return str(getattr(msg_type, "_ros_type", ""))


class Entity:
    """Base of everything a node owns: a read condition for the executor's WaitSet (or None),
    ``_take`` returning the callbacks that are ready, ``_guids`` for the graph, ``destroy``."""

    node: Owner
    callback_group: Any = None
    condition: ReadCondition | None = None

    def __init__(self) -> None:
        self._lock = threading.Lock()  # serialises _take against destroy
        self._destroyed = False

    def _dds(self) -> tuple[Any, ...]:
        """The DDS entities this one created, in deletion order."""
        return ()

    def _guids(self) -> tuple[list[bytes], list[bytes]]:
        return [], []

    def _take(self) -> list[Callable[[], None]]:
        return []

    def _take_from(self, reader_attr: str = "_reader") -> tuple[list[Any], list[wire.Malformed]]:
        """(decoded samples, malformed ones) taken from the reader; nothing once destroyed."""
        with self._lock:
            reader = getattr(self, reader_attr, None)
            if reader is None:
                return [], []
            return wire.take(reader)

    def _log_malformed(self, sample: wire.Malformed) -> None:
        self.node.get_logger().warning(
            f"dropped a sample of {sample.size} bytes on {self._where()} that does not "
            f"decode: {sample.reason}", throttle_duration_sec=LOG_THROTTLE_S)

    def _where(self) -> str:
        return type(self).__name__

    @property
    def destroyed(self) -> bool:
        return self._destroyed

    def _triggered(self) -> bool:
        """Whether the read condition has samples to take: False without one, and once
        destroyed. Under the lock, since another thread may destroy the entity while an
        executor looks (a deleted condition raises DDS_RETCODE_BAD_PARAMETER)."""
        with self._lock:
            return self.condition is not None and bool(self.condition.is_triggered())

    def destroy(self) -> None:
        """Release the DDS entities (idempotent)."""
        with self._lock:
            if self._destroyed:
                return
            self._destroyed = True
            owned = (self.condition, *self._dds())
            self.condition = None
            self._forget()
        delete_dds(*owned)

    def _forget(self) -> None:
        """Drop the references to the DDS entities (under the lock)."""


class Publisher(Entity):
    """``rclpy.publisher.Publisher``: ``publish(msg)``, ``topic_name``."""

    def __init__(self, node: Owner, msg_type: type, topic: str, qos: QoSProfile) -> None:
        super().__init__()
        self.node, self.msg_type, self.topic_name, self.qos_profile = node, msg_type, topic, qos
        self._writer: DataWriter | None = DataWriter(
            node.context.participant, node._topic("rt" + topic, msg_type),
            qos=to_dds_qos(qos, type_hash_user_data(_ros_type(msg_type)) or None))

    def publish(self, msg: Any) -> None:
        if not isinstance(msg, self.msg_type):
            raise TypeError(f"{self.topic_name}: expected {self.msg_type.__name__}, "
                            f"got {type(msg).__name__}")
        writer = self._writer
        if writer is None:
            raise RuntimeError(f"publisher on {self.topic_name} was destroyed")
        writer.write(msg)

    def get_subscription_count(self) -> int:
        writer = self._writer
        return len(matched_handles(writer)) if writer else 0

    def _guids(self) -> tuple[list[bytes], list[bytes]]:
        return [], ([self._writer.get_guid().bytes] if self._writer else [])

    def _dds(self) -> tuple[Any, ...]:
        return (self._writer,)

    def _forget(self) -> None:
        self._writer = None


class Subscription(Entity):
    """``rclpy.subscription.Subscription``: calls ``callback(msg)`` from an executor."""

    def __init__(self, node: Owner, msg_type: type, topic: str, callback: Callable[[Any], None],
                 qos: QoSProfile, group: Any) -> None:
        super().__init__()
        self.node, self.msg_type, self.topic_name = node, msg_type, topic
        self.callback, self.callback_group, self.qos_profile = callback, group, qos
        self._reader: DataReader | None = DataReader(
            node.context.participant, node._topic("rt" + topic, msg_type),
            qos=to_dds_qos(qos, type_hash_user_data(_ros_type(msg_type)) or None))
        self.condition = ReadCondition(self._reader, NOT_READ)

    def _take(self) -> list[Callable[[], None]]:
        samples, malformed = self._take_from()
        for sample in malformed:
            self._log_malformed(sample)
        return [lambda s=s: self.callback(s) for s in samples]

    def _where(self) -> str:
        return f"{self.topic_name} ({self.msg_type.__name__})"

    def _guids(self) -> tuple[list[bytes], list[bytes]]:
        return ([self._reader.get_guid().bytes] if self._reader else []), []

    def _dds(self) -> tuple[Any, ...]:
        return (self._reader,)

    def _forget(self) -> None:
        self._reader = None


class Timer(Entity):
    """``rclpy.timer.Timer``: periodic ``callback()`` run by an executor."""

    def __init__(self, node: Owner, period_sec: float, callback: Callable[[], None],
                 group: Any) -> None:
        super().__init__()
        if not period_sec > 0:
            raise ValueError(f"timer_period_sec must be > 0, got {period_sec}")
        self.node, self.callback, self.callback_group = node, callback, group
        self.timer_period_ns = int(round(period_sec * 1e9))
        self._next = time.monotonic_ns() + self.timer_period_ns
        self._canceled = False

    @property
    def is_canceled(self) -> bool:
        return self._canceled

    def cancel(self) -> None:
        self._canceled = True

    def reset(self) -> None:
        self._canceled = False
        self._next = time.monotonic_ns() + self.timer_period_ns
        self.node.context.wake()

    def time_until_next_call(self) -> int | None:
        return None if self._canceled or self._destroyed else self._next - time.monotonic_ns()

    def _take(self) -> list[Callable[[], None]]:
        now = time.monotonic_ns()
        if self._canceled or self._destroyed or now < self._next:
            return []
        # Skip missed periods instead of bursting, like rcl timers.
        missed = (now - self._next) // self.timer_period_ns
        self._next += (missed + 1) * self.timer_period_ns
        return [self.callback]


def ignore_deleted(call: Callable[[], Any], entity: Entity) -> Any:
    """Run ``call``; a DDS error because ``entity`` was destroyed meanwhile returns None."""
    try:
        return call()
    except DDSException:
        if entity.destroyed:
            return None
        raise
