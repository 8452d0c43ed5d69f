"""``rclpy.node.Node`` on Cyclone DDS with rmw_cyclonedds' wire conventions (ROS.md Sec. 2).

Publishers and subscriptions use ``rt/<name>``; a service ``/s`` reads ``rq/sRequest`` and
writes ``rr/sReply`` with the 16-byte ``{guid, seq}`` request header; clients set ``guid``
to their request writer's instance handle and keep only replies carrying it. Service and client
endpoints carry ``serviceid=...;`` / ``clientid=...;`` USER_DATA on both their reader and writer.
"""

from __future__ import annotations

import ast
import itertools
import logging
import re
import sys
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from cyclonedds.core import InstanceState, Policy, ReadCondition, SampleState, ViewState
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from biped_opt.errors import BipedOptError

from ..interfaces import ServiceType, load_interfaces
from ..params_file import load_parameters
from . import context as _ctx
from . import graph
from .futures import Future
from .qos import QoSProfile, as_profile, qos_profile_services_default, to_dds_qos

__all__ = [
    "Node", "Publisher", "Subscription", "Service", "Client", "Timer", "Clock", "Time",
    "Parameter", "ParameterNotDeclaredException", "MutuallyExclusiveCallbackGroup",
    "ReentrantCallbackGroup", "parse_ros_args",
]

_MASK64 = (1 << 64) - 1
_ANY = SampleState.NotRead | ViewState.Any | InstanceState.Any
_TAKE_BATCH = 256


class ParameterNotDeclaredException(BipedOptError, LookupError):
    """``get_parameter`` of a name that was never declared."""


# -- callback groups -------------------------------------------------------------------------

class MutuallyExclusiveCallbackGroup:
    """Callbacks of the group never run concurrently (rclpy's default group type)."""

    def __init__(self) -> None:
        self.lock: threading.Lock | None = threading.Lock()


class ReentrantCallbackGroup:
    """Callbacks of the group may run concurrently in a MultiThreadedExecutor."""

    def __init__(self) -> None:
        self.lock: threading.Lock | None = None


# -- time ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Time:
    """``rclpy.time.Time`` subset (system clock, integer nanoseconds)."""

    nanoseconds: int = 0

    def to_msg(self) -> Any:
        cls = load_interfaces().message_class("builtin_interfaces/msg/Time")
        sec, nsec = divmod(int(self.nanoseconds), 1_000_000_000)
        return cls(sec=sec, nanosec=nsec)

    def seconds_nanoseconds(self) -> tuple[int, int]:
        return divmod(int(self.nanoseconds), 1_000_000_000)


class Clock:
    """``rclpy.clock.Clock`` subset: ``now()`` of the system clock."""

    def now(self) -> Time:
        return Time(nanoseconds=time.time_ns())


# -- parameters ------------------------------------------------------------------------------

class Parameter:
    """``rclpy.parameter.Parameter`` subset: ``Parameter(name, value=...)``, ``.value``."""

    class Type:
        NOT_SET = 0
        BOOL = 1
        INTEGER = 2
        DOUBLE = 3
        STRING = 4

    def __init__(self, name: str, type_: Any = None, value: Any = None) -> None:
        # rclpy's signature is (name, type_=None, value=None); a non-int type_ is a value.
        if type_ is not None and not isinstance(type_, int) and value is None:
            type_, value = None, type_
        self.name = name
        self.value = value
        self.type_ = type_

    def get_parameter_value(self) -> Any:
        return self.value

    def __repr__(self) -> str:
        return f"Parameter({self.name!r}, value={self.value!r})"


def _parse_value(text: str) -> Any:
    """YAML-like scalar/list parsing of ``-p name:=value`` as ROS does (true, 1, 2.5, [1, 2])."""
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    try:
        value = ast.literal_eval(text.strip())
    except (ValueError, SyntaxError):
        return text
    if isinstance(value, tuple):
        value = list(value)
    return value


def parse_ros_args(args: Iterable[str] | None, node_name: str | None = None) -> dict[str, Any]:
    """Parameter overrides inside ``--ros-args ... [--]`` sections: ``-p name:=value`` and, for
    ``node_name``, ``--params-file FILE`` (its ``/**`` and ``node_name`` sections), later ones
    overriding earlier ones as in rcl."""
    params: dict[str, Any] = {}
    inside = False
    items = list(args or [])
    i = 0
    while i < len(items):
        arg = items[i]
        if arg == "--ros-args":
            inside = True
        elif arg == "--":
            inside = False
        elif inside and arg in ("-p", "--param") and i + 1 < len(items):
            name, sep, value = items[i + 1].partition(":=")
            if not sep:
                raise ValueError(f"--ros-args -p expects name:=value, got {items[i + 1]!r}")
            params[name] = _parse_value(value)
            i += 1
        elif inside and arg == "--params-file" and i + 1 < len(items):
            if node_name is not None:
                params.update(load_parameters(items[i + 1], node_name))
            i += 1
        i += 1
    return params


# -- names -----------------------------------------------------------------------------------

_NAME_RE = re.compile(r"^[~/]?[A-Za-z_][\w]*(/[A-Za-z_][\w]*)*$")


def _expand(name: str, namespace: str, node_name: str) -> str:
    if not name or not _NAME_RE.match(name.replace("{node}", node_name)):
        raise ValueError(f"invalid topic or service name {name!r}")
    name = name.replace("{node}", node_name)
    if name.startswith("/"):
        return name
    base = namespace.rstrip("/")
    if name.startswith("~"):
        rest = name[1:].lstrip("/")
        full = f"{base}/{node_name}"
        return f"{full}/{rest}" if rest else full
    return f"{base}/{name}"


_ID_COUNTER = itertools.count(1)


def _endpoint_id(participant: Any) -> str:
    """Unique id for ``clientid=``/``serviceid=``, formatted as rmw_cyclonedds does.

    The id is a GID (24 bytes on Humble, 16 on Jazzy): the participant's 12-byte GUID prefix, a
    big-endian counter, zero padding; printed in hex, the first byte two digits wide and the
    others unpadded, separated by dots.
    """
    size = len(graph.gid_bytes(bytes(16)))
    data = participant.get_guid().bytes[:12] + next(_ID_COUNTER).to_bytes(4, "big")
    data += bytes(size - len(data))
    return f"{data[0]:02x}" + "".join(f".{b:x}" for b in data[1:])


def _type_hash_user_data(ros_type: str) -> bytes:
    """``typehash=RIHS01_...;`` that Jazzy's rmw_cyclonedds adds to endpoint USER_DATA."""
    if graph.graph_layout() != "jazzy":
        return b""
    try:
        digest = load_interfaces().typestore.hash_rihs01(ros_type)
    except Exception:  # a type rosbags cannot hash: omit it, as rmw does on failure
        return b""
    return f"typehash={digest};".encode()


def _user_data_id(qos: Any, key: str) -> str | None:
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


def _ros_type(msg_type: type) -> str:
    return str(getattr(msg_type, "_ros_type", ""))


def _valid(samples: list[Any]) -> list[Any]:
    return [s for s in samples if getattr(getattr(s, "sample_info", None), "valid_data", True)
            and not hasattr(s, "key_sample")]


# -- entities --------------------------------------------------------------------------------

class _Entity:
    node: Node
    callback_group: Any
    condition: ReadCondition | None = None

    def _guids(self) -> tuple[list[bytes], list[bytes]]:
        return [], []

    def _take(self) -> list[Callable[[], None]]:
        return []

    def _destroy(self) -> None:
        self.condition = None


class Publisher(_Entity):
    """``rclpy.publisher.Publisher``: ``publish(msg)``, ``topic_name``."""

    def __init__(self, node: Node, msg_type: type, topic: str, qos: QoSProfile) -> None:
        self.node, self.msg_type, self.topic_name, self.qos_profile = node, msg_type, topic, qos
        self._writer: DataWriter | None = DataWriter(
            node.context.participant, node._topic("rt" + topic, msg_type),
            qos=to_dds_qos(qos, _type_hash_user_data(_ros_type(msg_type)) or None))

    def publish(self, msg: Any) -> None:
        if not isinstance(msg, self.msg_type):
            raise TypeError(f"{self.topic_name}: expected {self.msg_type.__name__}, "
                            f"got {type(msg).__name__}")
        if self._writer is None:
            raise RuntimeError(f"publisher on {self.topic_name} was destroyed")
        self._writer.write(msg)

    def get_subscription_count(self) -> int:
        return len(self._writer.get_matched_subscriptions()) if self._writer else 0

    def _guids(self) -> tuple[list[bytes], list[bytes]]:
        return [], ([self._writer.get_guid().bytes] if self._writer else [])

    def _destroy(self) -> None:
        self._writer = None


class Subscription(_Entity):
    """``rclpy.subscription.Subscription``: calls ``callback(msg)`` from an executor."""

    def __init__(self, node: Node, msg_type: type, topic: str, callback: Callable[[Any], None],
                 qos: QoSProfile, group: Any) -> None:
        self.node, self.msg_type, self.topic_name = node, msg_type, topic
        self.callback, self.callback_group, self.qos_profile = callback, group, qos
        self._reader: DataReader | None = DataReader(
            node.context.participant, node._topic("rt" + topic, msg_type),
            qos=to_dds_qos(qos, _type_hash_user_data(_ros_type(msg_type)) or None))
        self.condition = ReadCondition(self._reader, _ANY)

    def _take(self) -> list[Callable[[], None]]:
        if self._reader is None:
            return []
        samples = _valid(self._reader.take(N=_TAKE_BATCH))
        return [lambda s=s: self.callback(s) for s in samples]

    def _guids(self) -> tuple[list[bytes], list[bytes]]:
        return ([self._reader.get_guid().bytes] if self._reader else []), []

    def _destroy(self) -> None:
        self.condition = None
        self._reader = None


def _service_endpoints(node: Any, srv_type: ServiceType, name: str, qos: QoSProfile, key: str
                       ) -> tuple[Any, str, tuple[Any, Any], tuple[Any, Any]]:
    """What a service or a client needs for its two endpoints, as rmw_cyclonedds names them:
    (participant, endpoint id, (request topic, qos), (reply topic, qos)); both endpoints carry
    USER_DATA ``key=<id>;`` (``serviceid`` or ``clientid``)."""
    participant = node.context.participant
    ident = _endpoint_id(participant)
    user = f"{key}={ident};".encode()
    request = (node._topic(f"rq{name}Request", srv_type.RequestWire),
               to_dds_qos(qos, user + _type_hash_user_data(srv_type.name + "_Request")))
    reply = (node._topic(f"rr{name}Reply", srv_type.ResponseWire),
             to_dds_qos(qos, user + _type_hash_user_data(srv_type.name + "_Response")))
    return participant, ident, request, reply


class _RequestReply(_Entity):
    """A service's or a client's reader and writer pair (see :func:`_service_endpoints`)."""

    _reader: DataReader | None
    _writer: DataWriter | None

    def _guids(self) -> tuple[list[bytes], list[bytes]]:
        if self._reader is None or self._writer is None:
            return [], []
        return [self._reader.get_guid().bytes], [self._writer.get_guid().bytes]

    def _destroy(self) -> None:
        self.condition = None
        self._reader = self._writer = None


class Service(_RequestReply):
    """``rclpy.service.Service``: ``callback(request, response) -> response``."""

    # rmw_cyclonedds waits 100 ms for a new client's reply reader before answering and drops the
    # reply after that; on a loaded machine discovery can take longer, and a dropped reply leaves
    # the client waiting forever, so wait up to 1 s (only a client not yet matched ever waits)
    reply_wait_s = 1.0

    def __init__(self, node: Node, srv_type: ServiceType, name: str,
                 callback: Callable[[Any, Any], Any], qos: QoSProfile, group: Any) -> None:
        self.node, self.srv_type, self.srv_name = node, srv_type, name
        self.callback, self.callback_group, self.qos_profile = callback, group, qos
        participant, self.service_id, request, reply = _service_endpoints(
            node, srv_type, name, qos, "serviceid")
        self._reader: DataReader | None = DataReader(participant, *request)
        self._writer: DataWriter | None = DataWriter(participant, *reply)
        self.condition = ReadCondition(self._reader, _ANY)
        self._client_ids: dict[int, str | None] = {}
        self._ready_clients: set[str] = set()

    def _take(self) -> list[Callable[[], None]]:
        if self._reader is None:
            return []
        return [lambda s=s: self._handle(s) for s in _valid(self._reader.take(N=_TAKE_BATCH))]

    def _handle(self, wire: Any) -> None:
        response = self.callback(wire.body, self.srv_type.Response())
        if not isinstance(response, self.srv_type.Response):
            raise TypeError(f"service {self.srv_name}: callback returned "
                            f"{type(response).__name__}, expected "
                            f"{self.srv_type.Response.__name__}")
        writer = self._writer
        if writer is None:
            return
        status = self._client_present(wire.sample_info.publication_handle)
        if status == "gone":
            return  # the client disappeared: nobody to answer
        if status == "maybe":
            self.node.get_logger().warning(
                f"service {self.srv_name}: the client's reply reader did not appear "
                f"within {self.reply_wait_s * 1e3:.0f} ms; reply dropped")
            return
        writer.write(self.srv_type.ResponseWire(header=wire.header, body=response))

    def _client_present(self, publication: int) -> str:
        """``yes``/``gone``/``maybe`` (timed out) for the client that wrote a request.

        As rmw_cyclonedds: a request writer without ``clientid`` is assumed fine; otherwise
        wait up to ``reply_wait_s`` until the reply writer has matched the reader with that id.
        """
        reader, deadline = self._reader, time.monotonic() + self.reply_wait_s
        if reader is None:
            return "gone"
        if publication not in self._client_ids:
            data = reader.get_matched_publication_data(publication)
            if data is None:
                return "gone"
            self._client_ids[publication] = _user_data_id(data.qos, "clientid")
        client_id = self._client_ids[publication]
        if client_id is None or client_id in self._ready_clients:
            return "yes"
        while self._writer is not None:
            for handle in self._writer.get_matched_subscriptions():
                data = self._writer.get_matched_subscription_data(handle)
                if data is not None and _user_data_id(data.qos, "clientid") == client_id:
                    self._ready_clients.add(client_id)
                    return "yes"
            if time.monotonic() >= deadline:
                return "maybe"
            time.sleep(0.002)
        return "gone"


class Client(_RequestReply):
    """``rclpy.client.Client``: ``wait_for_service``, ``call_async -> Future``, ``call``."""

    def __init__(self, node: Node, srv_type: ServiceType, name: str, qos: QoSProfile,
                 group: Any) -> None:
        self.node, self.srv_type, self.srv_name = node, srv_type, name
        self.callback_group, self.qos_profile = group, qos
        participant, self.client_id, request, reply = _service_endpoints(
            node, srv_type, name, qos, "clientid")
        self._writer: DataWriter | None = DataWriter(participant, *request)
        self._reader: DataReader | None = DataReader(participant, *reply)
        self.condition = ReadCondition(self._reader, _ANY)
        self.guid = self._writer.get_instance_handle() & _MASK64
        self._seq = itertools.count(1)
        self._pending: dict[int, Future] = {}
        self._lock = threading.Lock()

    def service_is_ready(self) -> bool:
        """A server whose request reader and reply writer (same ``serviceid``) are matched."""
        if self._writer is None or self._reader is None:
            return False
        reader_handles = self._writer.get_matched_subscriptions()
        writer_handles = self._reader.get_matched_publications()
        needles = {_user_data_id(d.qos, "serviceid") for d in (
            self._writer.get_matched_subscription_data(h) for h in reader_handles)
            if d is not None} - {None}
        if not needles:
            # Servers without ids (older rmw, plain DDS): matched endpoints are enough.
            return bool(reader_handles) and bool(writer_handles)
        return any(
            d is not None and _user_data_id(d.qos, "serviceid") in needles
            for d in (self._reader.get_matched_publication_data(h) for h in writer_handles))

    def wait_for_service(self, timeout_sec: float | None = None) -> bool:
        deadline = None if timeout_sec is None else time.monotonic() + timeout_sec
        while self.node.context.ok():
            if self.service_is_ready():
                return True
            if deadline is not None and time.monotonic() >= deadline:
                return False
            time.sleep(0.01)
        return False

    def call_async(self, request: Any) -> Future:
        if not isinstance(request, self.srv_type.Request):
            raise TypeError(f"{self.srv_name}: expected {self.srv_type.Request.__name__}, "
                            f"got {type(request).__name__}")
        if self._writer is None:
            raise RuntimeError(f"client of {self.srv_name} was destroyed")
        future = Future()
        with self._lock:
            seq = next(self._seq)
            self._pending[seq] = future
        wire = self.srv_type.RequestWire(body=request)
        wire.header.guid, wire.header.seq = self.guid, seq
        self._writer.write(wire)
        return future

    def call(self, request: Any, timeout_sec: float | None = None) -> Any:
        """Blocking call; another thread must be spinning the node (as in rclpy)."""
        future = self.call_async(request)
        if not future.wait(timeout_sec):
            future.cancel()
            return None
        return future.result()

    def _take(self) -> list[Callable[[], None]]:
        if self._reader is None:
            return []
        tasks = []
        for wire in _valid(self._reader.take(N=_TAKE_BATCH)):
            if (wire.header.guid & _MASK64) != self.guid:
                continue  # a reply to another client on the same service
            with self._lock:
                future = self._pending.pop(wire.header.seq, None)
            if future is not None:
                tasks.append(lambda f=future, b=wire.body: f.set_result(b))
        return tasks

    def _destroy(self) -> None:
        super()._destroy()
        with self._lock:
            pending, self._pending = self._pending, {}
        for future in pending.values():
            future.cancel()


class Timer(_Entity):
    """``rclpy.timer.Timer``: periodic ``callback()`` run by an executor."""

    def __init__(self, node: Node, period_sec: float, callback: Callable[[], None],
                 group: Any) -> None:
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
        return None if self._canceled else self._next - time.monotonic_ns()

    def _take(self) -> list[Callable[[], None]]:
        now = time.monotonic_ns()
        if self._canceled or now < self._next:
            return []
        # Skip missed periods instead of bursting, like rcl timers.
        missed = (now - self._next) // self.timer_period_ns
        self._next += (missed + 1) * self.timer_period_ns
        return [self.callback]


# -- logging ---------------------------------------------------------------------------------

_LOG_PARENT = "biped_opt.ros.nodes"


class _RosFormatter(logging.Formatter):
    """rclpy's console format: ``[INFO] [1700000000.123456789] [node]: message``."""

    def format(self, record: logging.LogRecord) -> str:
        level = {"WARNING": "WARN", "CRITICAL": "FATAL"}.get(record.levelname, record.levelname)
        name = record.name[len(_LOG_PARENT) + 1:]
        return f"[{level}] [{record.created:.9f}] [{name}]: {record.getMessage()}"


class _StderrHandler(logging.Handler):
    """Writes to whatever ``sys.stderr`` is at emit time (redirections are honoured)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            sys.stderr.write(self.format(record) + "\n")
            sys.stderr.flush()
        except Exception:  # never let logging break a callback
            self.handleError(record)


def _log_parent() -> logging.Logger:
    parent = logging.getLogger(_LOG_PARENT)
    if not parent.handlers:
        # Like rclpy: INFO and above to stderr, independent of the application's logging setup.
        handler = _StderrHandler()
        handler.setFormatter(_RosFormatter())
        parent.addHandler(handler)
        parent.setLevel(logging.INFO)
        parent.propagate = False
    return parent


class _Logger:
    """``rclpy`` logger subset on :mod:`logging` (``info``, ``warn``, ``error``...)."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._log = _log_parent().getChild(name)

    def debug(self, msg: str, **_: Any) -> bool:
        self._log.debug(msg)
        return True

    def info(self, msg: str, **_: Any) -> bool:
        self._log.info(msg)
        return True

    def warning(self, msg: str, **_: Any) -> bool:
        self._log.warning(msg)
        return True

    warn = warning

    def error(self, msg: str, **_: Any) -> bool:
        self._log.error(msg)
        return True

    def fatal(self, msg: str, **_: Any) -> bool:
        self._log.critical(msg)
        return True

    def get_child(self, name: str) -> _Logger:
        return _Logger(f"{self.name}.{name}")


# -- node ------------------------------------------------------------------------------------

class Node:
    """``rclpy.node.Node(node_name, *, context, namespace, parameter_overrides)``."""

    def __init__(self, node_name: str, *, context: Any = None, cli_args: list[str] | None = None,
                 namespace: str | None = None, use_global_arguments: bool = True,
                 parameter_overrides: list[Parameter] | None = None,
                 allow_undeclared_parameters: bool = False,
                 automatically_declare_parameters_from_overrides: bool = False,
                 **_ignored: Any) -> None:
        if not re.match(r"^[A-Za-z_]\w*$", node_name):
            raise ValueError(f"invalid node name {node_name!r}")
        self.context = context or _ctx.get_default_context()
        if not self.context.ok():
            raise _ctx.NotInitializedError("Node(): the context is not initialized")
        namespace = namespace or "/"
        if not namespace.startswith("/"):
            namespace = "/" + namespace
        self._name, self._namespace = node_name, namespace.rstrip("/") or "/"
        self._topics: dict[tuple[str, str], Topic] = {}
        self._entities: list[_Entity] = []
        self.default_callback_group = MutuallyExclusiveCallbackGroup()
        self._logger = _Logger(node_name if self._namespace == "/"
                               else f"{self._namespace.strip('/').replace('/', '.')}.{node_name}")
        self._clock = Clock()
        self._overrides: dict[str, Any] = {}
        if use_global_arguments:
            self._overrides.update(parse_ros_args(self.context.args, node_name))
        self._overrides.update(parse_ros_args(cli_args, node_name))
        for param in parameter_overrides or []:
            self._overrides[param.name] = param.value
        self._allow_undeclared = allow_undeclared_parameters
        self._parameters: dict[str, Parameter] = {}
        if automatically_declare_parameters_from_overrides:
            for name, value in self._overrides.items():
                self._parameters[name] = Parameter(name, value=value)
        self._destroyed = False
        self.context.add_node(self)

    # names
    def get_name(self) -> str:
        return self._name

    def get_namespace(self) -> str:
        return self._namespace

    def get_fully_qualified_name(self) -> str:
        return f"{self._namespace.rstrip('/')}/{self._name}"

    def get_logger(self) -> _Logger:
        return self._logger

    def get_clock(self) -> Clock:
        return self._clock

    # internals
    def _topic(self, dds_name: str, dds_type: type) -> Topic:
        key = (dds_name, dds_type.__name__)
        if key not in self._topics:
            self._topics[key] = Topic(self.context.participant, dds_name, dds_type)
        return self._topics[key]

    def _add(self, entity: _Entity) -> Any:
        self._entities.append(entity)
        self.context.publish_graph()
        self.context.wake()
        return entity

    def _endpoint_guids(self) -> tuple[list[bytes], list[bytes]]:
        readers: list[bytes] = []
        writers: list[bytes] = []
        for entity in self._entities:
            r, w = entity._guids()
            readers += r
            writers += w
        return readers, writers

    def _resolve(self, name: str) -> str:
        return _expand(name, self._namespace, self._name)

    def _check(self) -> None:
        if self._destroyed:
            raise RuntimeError(f"node {self._name} was destroyed")

    # entities
    def create_publisher(self, msg_type: type, topic: str, qos_profile: QoSProfile | int,
                         **_ignored: Any) -> Publisher:
        self._check()
        return self._add(Publisher(self, msg_type, self._resolve(topic), as_profile(qos_profile)))

    def create_subscription(self, msg_type: type, topic: str, callback: Callable[[Any], None],
                            qos_profile: QoSProfile | int, *, callback_group: Any = None,
                            **_ignored: Any) -> Subscription:
        self._check()
        return self._add(Subscription(self, msg_type, self._resolve(topic), callback,
                                      as_profile(qos_profile),
                                      callback_group or self.default_callback_group))

    def create_service(self, srv_type: ServiceType, srv_name: str,
                       callback: Callable[[Any, Any], Any], *,
                       qos_profile: QoSProfile = qos_profile_services_default,
                       callback_group: Any = None) -> Service:
        self._check()
        return self._add(Service(self, srv_type, self._resolve(srv_name), callback,
                                 as_profile(qos_profile),
                                 callback_group or self.default_callback_group))

    def create_client(self, srv_type: ServiceType, srv_name: str, *,
                      qos_profile: QoSProfile = qos_profile_services_default,
                      callback_group: Any = None) -> Client:
        self._check()
        return self._add(Client(self, srv_type, self._resolve(srv_name),
                                as_profile(qos_profile),
                                callback_group or self.default_callback_group))

    def create_timer(self, timer_period_sec: float, callback: Callable[[], None],
                     callback_group: Any = None, **_ignored: Any) -> Timer:
        self._check()
        timer = Timer(self, float(timer_period_sec), callback,
                      callback_group or self.default_callback_group)
        self._entities.append(timer)
        self.context.wake()
        return timer

    def _destroy_entity(self, entity: _Entity) -> bool:
        if entity in self._entities:
            self._entities.remove(entity)
            entity._destroy()
            self.context.publish_graph()
            return True
        return False

    destroy_publisher = destroy_subscription = destroy_service = _destroy_entity
    destroy_client = destroy_timer = _destroy_entity

    def destroy_node(self) -> None:
        if self._destroyed:
            return
        self._destroyed = True
        for entity in self._entities:
            entity._destroy()
        self._entities.clear()
        self._topics.clear()
        self.context.remove_node(self)
        self.context.wake()

    # parameters
    def declare_parameter(self, name: str, value: Any = None, descriptor: Any = None,
                          ignore_override: bool = False) -> Parameter:
        if name in self._parameters:
            raise ValueError(f"parameter {name!r} has already been declared")
        if not ignore_override and name in self._overrides:
            value = self._overrides[name]
        param = Parameter(name, value=value)
        self._parameters[name] = param
        return param

    def declare_parameters(self, namespace: str, parameters: list[tuple[Any, ...]]
                           ) -> list[Parameter]:
        prefix = f"{namespace}." if namespace else ""
        return [self.declare_parameter(prefix + p[0], *p[1:2]) for p in parameters]

    def has_parameter(self, name: str) -> bool:
        return name in self._parameters

    def get_parameter(self, name: str) -> Parameter:
        if name in self._parameters:
            return self._parameters[name]
        if self._allow_undeclared:
            return Parameter(name, value=None)
        raise ParameterNotDeclaredException(f"parameter {name!r} is not declared")

    def get_parameters(self, names: list[str]) -> list[Parameter]:
        return [self.get_parameter(n) for n in names]

    def set_parameters(self, parameters: list[Parameter]) -> list[Any]:
        for param in parameters:
            if param.name not in self._parameters and not self._allow_undeclared:
                raise ParameterNotDeclaredException(f"parameter {param.name!r} is not declared")
            self._parameters[param.name] = Parameter(param.name, value=param.value)
        return [True] * len(parameters)

    # executor interface
    def _waitables(self) -> list[_Entity]:
        return list(self._entities)
