"""``foxglove_bridge`` node: the running graph's topics, live, to Foxglove.

The specification is ROS.md, "Live view in Foxglove".

Serves the topics of the ROS graph over the Foxglove WebSocket protocol with the official
``foxglove-sdk`` server: open Foxglove, "Open connection", "Foxglove WebSocket",
``ws://HOST:PORT``. A client offers the WebSocket subprotocol ``foxglove.sdk.v1`` (the Foxglove
app, foxglove-sdk clients, ``foxglove_bridge`` 3.x) or ``foxglove.websocket.v1`` (clients of
``@foxglove/ws-protocol``): :class:`~biped_opt.nodes.ws_front.SubprotocolFront` listens on
``HOST:PORT``, passes either through to the SDK's server (on a loopback port of its own) and
answers any other request with HTTP 400 naming the two. Every few seconds
(``discovery_period``) the node lists the graph's topics and bridges each one whose type the
project's interfaces know (``biped_opt_interfaces`` and the ROS 2 Humble messages rosbags
knows: ``std_msgs``, ``geometry_msgs``, ``tf2_msgs``, ``visualization_msgs``,
``rosgraph_msgs``...):

- a Foxglove channel per topic with schema encoding ``ros2msg`` (the ``.msg`` text followed by
  each nested type after a line of ``=`` and ``MSG: pkg/Name``, as in our MCAP files) and
  message encoding ``cdr``: each message's CDR bytes, the 4-byte encapsulation header included,
  exactly as on the DDS wire; log time = the time the node received it [ns];
- a subscription whose QoS matches the publishers' (as rosbag2 adapts its own): reliable if
  every publisher is, else best effort (which hears both); transient local if every publisher is,
  so that the node, joining late, still gets what such a topic kept (``/biped/contact_mode``,
  ``/biped/system_info``, ``/robot_description``). The node keeps those messages too and sends
  them again when a Foxglove client subscribes to such a channel later, so a client that
  connects after the fact still sees them; clients already subscribed then get them a second
  time, with their first log time (the SDK addresses a message to the whole server, not to one
  client), and a channel's kept messages go out at most once per
  :data:`REPLAY_MIN_INTERVAL_S` (later subscriptions wait for it). A topic whose publishers' QoS
  change is subscribed again; one whose publishers are all gone is closed.

The node runs its callbacks on one thread (``run_node``), which keeps each topic's messages in
the order they came.

Parameters: ``port`` (default 8765; 0 = any free port, see :attr:`FoxgloveNode.port` and the
ready line), ``host`` (default 127.0.0.1: this machine only; 0.0.0.0 serves the network),
``topics`` (the topics to serve; empty = every topic of a known type), ``discovery_period`` [s]
(default 2), ``client_queue_bytes`` and ``max_message_bytes`` (below). A bad value stops the
node at start-up with one line naming it, as does a port it cannot listen on.

The server is read-only and bounded, whatever a client or a DDS peer sends:

- it advertises no capability: no client publishing (the SDK answers a client's advertisement
  with an error status and drops its messages), no services, no parameters, no connection
  graph, no assets;
- at most :data:`MAX_CHANNELS` topics are bridged (the others are left out, each said once in
  the log);
- each client's queue of outgoing messages holds at most ``client_queue_bytes`` (parameter,
  default :data:`CLIENT_QUEUE_BYTES`): the SDK counts its queue in messages, so no message
  larger than ``max_message_bytes`` (parameter, default :data:`MAX_MESSAGE_BYTES`) is forwarded
  (each such topic said once in the log, the messages counted) and the queue is
  ``client_queue_bytes // max_message_bytes`` messages long (at most :data:`BACKLOG`), beyond
  which the SDK drops the oldest data message (and disconnects a client whose control queue
  fills). A client that never reads thus costs the bridge at most that budget, whatever a peer
  publishes;
- each subscription keeps at most :data:`QUEUE_DEPTH` samples; a transient-local topic's kept
  messages are as many as its publishers keep (their depth), at most :data:`LATCHED_MESSAGES`,
  and at most :data:`LATCHED_BYTES`;
- names and types come from any peer on the domain: a name that is not a plain absolute topic
  name (at most 256 characters), a type no interface defines, a topic with several types are
  left out with one log line each (for at most :data:`_SKIPPED_MAX` topics);
- a sample that does not decode with its type is dropped with a log line (the backend's rule),
  so what reaches a client is always well-formed CDR of the advertised schema.
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import foxglove
from foxglove.websocket import ServerListener

from biped_opt import ros
from biped_opt.errors import InvalidParameterError, quoted
from biped_opt.nodes.parameters import float_parameter, int_parameter, string_list_parameter
from biped_opt.nodes.run import announce_ready, run_node
from biped_opt.nodes.ws_front import SubprotocolFront
from biped_opt.ros.interfaces import InterfaceError, load_interfaces

__all__ = ["FoxgloveNode", "main", "MAX_CHANNELS", "BACKLOG", "QUEUE_DEPTH", "LATCHED_MESSAGES",
           "LATCHED_BYTES", "CLIENT_QUEUE_BYTES", "MAX_MESSAGE_BYTES", "ros2msg_schema",
           "cdr_bytes", "adapted_qos", "backlog"]

#: most topics one bridge serves
MAX_CHANNELS = 256
#: the most outgoing messages queued per client (the SDK drops the oldest data message beyond)
BACKLOG = 1024
#: defaults of the parameters client_queue_bytes (what one client's queue may hold) and
#: max_message_bytes (the largest message forwarded) [bytes]: 256 messages a client
CLIENT_QUEUE_BYTES, MAX_MESSAGE_BYTES = 16 << 20, 64 << 10
#: samples a subscription holds between two takes
QUEUE_DEPTH = 100
#: messages of a transient-local topic kept for clients that subscribe later, and their bytes
LATCHED_MESSAGES = 100
LATCHED_BYTES = 16 << 20
#: how often subscriptions of clients are answered with the kept messages [s], and how long a
#: channel's kept messages wait before they go out again (a client that subscribes and
#: unsubscribes in a loop cannot make the server resend them faster)
REPLAY_PERIOD_S = 0.05
REPLAY_MIN_INTERVAL_S = 1.0
#: the longest host name or address accepted, and topic name served
_HOST_MAX = 255
_NAME_MAX = 256
#: most topics the node remembers having said it does not serve
_SKIPPED_MAX = 4096

_TOPIC_RE = re.compile(r"^(/[A-Za-z_][A-Za-z0-9_]*)+$")


def ros2msg_schema(ros_type: str) -> bytes:
    """The ``ros2msg`` schema of a message type: its definition and every nested type's, in the
    concatenated form of ROS 2 bags and Foxglove (rosbags' ``generate_msgdef``, as our MCAP
    files carry it)."""
    text, _digest = load_interfaces().typestore.generate_msgdef(ros_type, ros_version=2)
    return text.encode()


def cdr_bytes(msg: Any) -> bytes:
    """A built-in backend message's CDR bytes as they travel on DDS: the encapsulation header
    (little-endian plain CDR, ``00 01 00 00``), then the data (XCDR1, as rmw_cyclonedds)."""
    return bytes(msg.serialize(use_version_2=False))


def adapted_qos(offered: list[Any]) -> Any:
    """The subscription profile that matches every offered one (rosbag2's rule): reliable only
    if all publishers are (best effort hears both), transient local only if all publishers are
    (a volatile reader matches both, without the history), deep enough for what they keep."""
    reliable = all(q.reliability == ros.ReliabilityPolicy.RELIABLE for q in offered)
    latched = all(q.durability == ros.DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
    depth = QUEUE_DEPTH
    if latched:
        depth = min(max(int(q.depth) for q in offered), LATCHED_MESSAGES)
    return ros.QoSProfile(
        history=ros.HistoryPolicy.KEEP_LAST, depth=max(depth, 1),
        reliability=(ros.ReliabilityPolicy.RELIABLE if reliable
                     else ros.ReliabilityPolicy.BEST_EFFORT),
        durability=(ros.DurabilityPolicy.TRANSIENT_LOCAL if latched
                    else ros.DurabilityPolicy.VOLATILE))


def backlog(client_queue_bytes: int, max_message_bytes: int) -> int:
    """Messages a client's queue may hold so that it never holds more than
    ``client_queue_bytes`` of messages of at most ``max_message_bytes`` (at most
    :data:`BACKLOG`)."""
    return min(BACKLOG, client_queue_bytes // max_message_bytes)


def _profile_key(profile: Any) -> tuple[int, int, int]:
    return int(profile.reliability), int(profile.durability), int(profile.depth)


def _message_class(ros_type: str) -> tuple[type, Callable[[Any], bytes], dict[str, Any]]:
    """(message class, its CDR bytes from what a callback gets, subscription options) of a type
    the interfaces know; :class:`InterfaceError` for one they do not."""
    typestore = load_interfaces().typestore
    if ros_type not in typestore.fielddefs or "/msg/" not in ros_type:
        raise InterfaceError(f"unknown message type {ros_type!r}")
    if ros.BACKEND == "rclpy":  # pragma: no cover - (needs a ROS install)
        from rosidl_runtime_py.utilities import get_message  # type: ignore[import-not-found]

        try:
            cls = get_message(ros_type)
        except (AttributeError, ModuleNotFoundError, ValueError) as exc:
            raise InterfaceError(f"{ros_type}: {exc}") from None
        return cls, bytes, {"raw": True}  # rclpy hands the serialized message over as is
    return load_interfaces().message_class(ros_type), cdr_bytes, {}


@dataclass
class _Bridged:
    """One topic served: its Foxglove channel, its subscription, what it keeps for later
    clients."""

    ros_type: str
    channel: Any
    encode: Callable[[Any], bytes]
    profile: Any = None
    subscription: Any = None
    latched: deque[tuple[bytes, int]] | None = None
    latched_bytes: int = 0
    replayed_at: float = -math.inf  #: when the kept messages last went out (monotonic) [s]
    lock: threading.Lock = field(default_factory=threading.Lock)

    def keep(self, data: bytes, log_time: int) -> None:
        with self.lock:
            if self.latched is None:
                return
            if len(self.latched) == self.latched.maxlen:
                self.latched_bytes -= len(self.latched[0][0])
            self.latched.append((data, log_time))
            self.latched_bytes += len(data)
            while self.latched_bytes > LATCHED_BYTES and self.latched:
                self.latched_bytes -= len(self.latched.popleft()[0])

    def kept(self) -> list[tuple[bytes, int]]:
        with self.lock:
            return list(self.latched or ())


class _Listener(ServerListener):
    """The SDK's server callbacks: only subscriptions matter (to send a transient-local topic's
    kept messages); the others keep the protocol's defaults (do nothing), and what a client may
    ask beyond subscribing the SDK refuses itself, since the server advertises no capability."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.pending: set[int] = set()  # channel ids subscribed to since the last replay

    def on_subscribe(self, client: Any, channel: Any) -> None:
        # (called before the SDK routes the channel to the client: the node's timer replays)
        with self.lock:
            self.pending.add(int(channel.id))

    def take(self) -> set[int]:
        with self.lock:
            pending, self.pending = self.pending, set()
        return pending

    def defer(self, channel_ids: set[int]) -> None:
        with self.lock:
            self.pending |= channel_ids


class FoxgloveNode(ros.Node):
    """Serves the graph's topics to Foxglove (see the module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("foxglove_bridge", **kwargs)
        self._lock = threading.Lock()
        self._bridged: dict[str, _Bridged] = {}
        self._server: Any = None
        self._front: SubprotocolFront | None = None
        self.declare_parameter("port", 8765)
        self.declare_parameter("host", "127.0.0.1")
        self.declare_parameter("topics", [])
        self.declare_parameter("discovery_period", 2.0)
        self.declare_parameter("client_queue_bytes", CLIENT_QUEUE_BYTES)
        self.declare_parameter("max_message_bytes", MAX_MESSAGE_BYTES)
        port = int_parameter(self, "port", 0)
        if port > 65535:
            raise InvalidParameterError(f"port must be an integer in 0..65535, got {port}")
        host = self.get_parameter("host").value
        if not isinstance(host, str) or not host.strip() or len(host) > _HOST_MAX \
                or any(c.isspace() or not c.isprintable() for c in host):
            raise InvalidParameterError(
                f"host must be a host name or address, got {quoted(host)}")
        topics = string_list_parameter(self, "topics")
        for name in topics:
            if not _TOPIC_RE.match(name):
                raise InvalidParameterError(
                    f"topics: {quoted(name)} is not an absolute topic name (/a/b)")
        if len(topics) > MAX_CHANNELS:
            raise InvalidParameterError(
                f"topics: at most {MAX_CHANNELS} topics, got {len(topics)}")
        period = float_parameter(self, "discovery_period")
        #: the largest message forwarded, and what one client's queue may hold [bytes]
        self.max_message_bytes = int_parameter(self, "max_message_bytes", 1024)
        self.client_queue_bytes = int_parameter(self, "client_queue_bytes", 1024)
        if self.client_queue_bytes < self.max_message_bytes:
            raise InvalidParameterError(
                f"client_queue_bytes ({self.client_queue_bytes}) must hold at least one message "
                f"of max_message_bytes ({self.max_message_bytes})")
        #: messages not forwarded for being larger than max_message_bytes, by topic
        self.oversized: dict[str, int] = {}
        self.wanted: frozenset[str] = frozenset(topics)
        self._skipped: set[str] = set()  # topics said once not to be served
        self._listener = _Listener()
        self._server = self._start_server(host, port)
        assert self._front is not None
        #: the port the server listens on (the one chosen when ``port`` is 0)
        self.port: int = int(self._front.port)
        self.url = f"ws://{host}:{self.port}"
        self._discover()
        self._discovery_timer = self.create_timer(period, self._discover)
        self._replay_timer = self.create_timer(REPLAY_PERIOD_S, self._replay)
        announce_ready(self, serves=(f"{self.url} (Foxglove WebSocket)",))

    def _start_server(self, host: str, port: int) -> Any:
        """The SDK's server on a loopback port of its own, behind :class:`SubprotocolFront` on
        ``host:port`` (the subprotocols accepted, ROS.md Sec. 7)."""
        self._context = foxglove.Context()  # (this node's channels only)
        try:
            server = foxglove.start_server(
                name="biped_opt", host="127.0.0.1", port=0, capabilities=[],
                server_listener=self._listener, supported_encodings=[], services=None,
                context=self._context,
                message_backlog_size=backlog(self.client_queue_bytes, self.max_message_bytes))
        except Exception as exc:  # the SDK's error for an address it cannot bind
            text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            text = text.removeprefix("FoxgloveError: ")
            raise InvalidParameterError(
                f"host, port: cannot listen on 127.0.0.1 (the server behind the front): "
                f"{text}") from None
        try:
            self._front = SubprotocolFront(host, port, int(server.port))
        except OSError as exc:
            server.stop()
            raise InvalidParameterError(
                f"host, port: cannot listen on {host}:{port}: {exc.strerror or exc}") from None
        return server

    # -- discovery ------------------------------------------------------------------------
    def bridged(self) -> dict[str, str]:
        """The topics served now and their types."""
        with self._lock:
            return {name: b.ros_type for name, b in self._bridged.items()}

    def _say_once(self, topic: str, text: str) -> None:
        if topic not in self._skipped and len(self._skipped) < _SKIPPED_MAX:
            self._skipped.add(topic)
            self.get_logger().info(text)

    def _discover(self) -> None:
        """Serve the topics with a publisher and a known type, close those without publisher.
        Names and types come from any peer on the domain: a name that is not a plain absolute
        topic name is left out, and publishers are looked up only for topics that could be
        served (a known type, room for another channel)."""
        known = load_interfaces().typestore.fielddefs
        seen: set[str] = set()
        for name, types in self.get_topic_names_and_types():
            if self.wanted and name not in self.wanted:
                continue
            if len(name) > _NAME_MAX or not _TOPIC_RE.match(name):
                self._say_once(name, f"not serving {quoted(name[:_NAME_MAX])}: not a topic name")
                continue
            if len(types) != 1:
                self._say_once(name, f"not serving {name}: it has several types "
                                     f"({', '.join(types[:4])})")
                continue
            ros_type = types[0]
            if ros_type not in known or "/msg/" not in ros_type:
                self._say_once(name, f"not serving {name}: type {quoted(ros_type)} is not known")
                continue
            with self._lock:
                full = name not in self._bridged and len(self._bridged) >= MAX_CHANNELS
            if full:
                self._say_once(name, f"not serving {name}: already serving {MAX_CHANNELS} "
                                     "topics (the most one bridge serves)")
                continue
            offered = [p.qos_profile for p in self.get_publishers_info_by_topic(name)
                       if p.topic_type == ros_type]
            if not offered:
                continue  # (only subscriptions, ours included)
            seen.add(name)
            try:
                self._serve(name, ros_type, adapted_qos(offered))
            except Exception as exc:  # (one topic's trouble never stops the others)
                self._say_once(name, f"not serving {name}: {type(exc).__name__}: {exc}")
        with self._lock:
            gone = [name for name in self._bridged if name not in seen]
        for name in gone:
            self._close(name)

    def _serve(self, name: str, ros_type: str, profile: Any) -> None:
        with self._lock:
            entry = self._bridged.get(name)
        if entry is not None and entry.ros_type != ros_type:
            self._close(name)
            entry = None
        if entry is None:
            entry = self._open(name, ros_type)
        if entry.profile is not None and _profile_key(entry.profile) == _profile_key(profile):
            return
        # a new topic, or its publishers changed QoS: (re)subscribe with the matching profile
        # (a transient-local topic then delivers what it keeps once more)
        if entry.subscription is not None:
            self.destroy_subscription(entry.subscription)
            entry.subscription = None
        latched = profile.durability == ros.DurabilityPolicy.TRANSIENT_LOCAL
        with entry.lock:
            # as many as the topic keeps for late joiners (its publishers' depth, bounded)
            entry.latched = deque(entry.latched or (), maxlen=int(profile.depth)) if latched \
                else None
            entry.latched_bytes = sum(len(d) for d, _ in entry.latched or ())
        cls, entry.encode, options = _message_class(ros_type)
        entry.subscription = self.create_subscription(
            cls, name, lambda msg, e=entry, n=name: self._forward(e, msg, n), profile,
            **options)
        entry.profile = profile
        reliable = profile.reliability == ros.ReliabilityPolicy.RELIABLE
        self.get_logger().info(
            f"serving {name} ({ros_type}; {'reliable' if reliable else 'best effort'}, "
            f"{'transient local' if latched else 'volatile'})")

    def _open(self, name: str, ros_type: str) -> _Bridged:
        _message_class(ros_type)  # (a type the interfaces know, before a channel exists)
        schema = foxglove.Schema(name=ros_type, encoding="ros2msg", data=ros2msg_schema(ros_type))
        channel = foxglove.Channel(name, schema=schema, message_encoding="cdr",
                                   context=self._context)
        entry = _Bridged(ros_type=ros_type, channel=channel, encode=cdr_bytes)
        with self._lock:
            self._bridged[name] = entry
        return entry

    def _close(self, name: str) -> None:
        with self._lock:
            entry = self._bridged.pop(name, None)
        if entry is None:
            return
        if entry.subscription is not None:
            self.destroy_subscription(entry.subscription)
        entry.channel.close()
        self.get_logger().info(f"stopped serving {name}: no publisher left")

    # -- messages -------------------------------------------------------------------------
    def _forward(self, entry: _Bridged, msg: Any, name: str = "") -> None:
        data = entry.encode(msg)
        if len(data) > self.max_message_bytes:  # (else one client's queue could exceed its budget)
            self.oversized[name] = self.oversized.get(name, 0) + 1
            self._say_once(f"{name} (size)", f"not forwarding messages of {name} larger than "
                                              f"max_message_bytes = {self.max_message_bytes} "
                                              f"(one of {len(data)} bytes)")
            return
        now = time.time_ns()
        entry.channel.log(data, log_time=now)
        entry.keep(data, now)

    def _replay(self) -> None:
        pending = self._listener.take()
        if not pending:
            return
        with self._lock:
            entries = [e for e in self._bridged.values() if e.channel.id() in pending]
        now, later = time.monotonic(), set()
        for entry in entries:
            if now - entry.replayed_at < REPLAY_MIN_INTERVAL_S:
                later.add(entry.channel.id())
                continue
            entry.replayed_at = now
            for data, log_time in entry.kept():
                entry.channel.log(data, log_time=log_time)
        if later:
            self._listener.defer(later)

    # -- lifecycle ------------------------------------------------------------------------
    def destroy_node(self) -> None:
        front, self._front = self._front, None
        if front is not None:
            front.stop()
        server, self._server = self._server, None
        if server is not None:
            server.stop()
        with self._lock:
            entries, self._bridged = list(self._bridged.values()), {}
        for entry in entries:
            entry.channel.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    run_node(FoxgloveNode, args)


if __name__ == "__main__":
    main()
