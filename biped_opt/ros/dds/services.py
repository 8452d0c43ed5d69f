"""Services and clients with rmw_cyclonedds' request/reply conventions (ROS.md Sec. 2).

A service ``/s`` reads ``rq/sRequest`` and writes ``rr/sReply``; every request and reply starts
with the 16-byte header ``{guid, seq}``: the client sets ``guid`` to its request writer's
instance handle and ``seq`` to a counter, the server echoes the header, and each client keeps
only replies carrying its own guid. Service and client endpoints carry ``serviceid=...;`` /
``clientid=...;`` USER_DATA on both their reader and writer.

Where this backend does better than rmw_cyclonedds, without changing what peers see:

- **No request or reply is dropped by a reader's history.** With the service profile's
  KEEP_LAST 10 every client's reply reader receives the replies to *every* client of the
  service and keeps only the last 10 until its executor takes them: under load (8 clients on 2
  cores) a client's own reply is pushed out before it is taken and the call never completes.
  Readers of a reliable service or client therefore keep all samples (KEEP_ALL) until the
  executor takes them; replies to other clients are discarded right there, so the memory held
  is what arrived between two executor wake-ups. History is not a requested/offered policy, so
  matching with any peer is unchanged.
- **A reply stays repairable until its client has it.** Cyclone's KEEP_LAST writer drops a
  sample from its history when ``depth`` newer ones of the instance are written, acknowledged
  or not, and answers a later request for it with a GAP; a reply topic is keyless, so under
  the profile's depth 10 the replies to 10 other clients make a reply whose first
  transmission one client missed (a full socket buffer, a lossy link) unrecoverable. A
  service's reply writer therefore keeps the last :data:`REPLY_HISTORY` replies: only the
  unacknowledged ones are held (VOLATILE), and KEEP_LAST never blocks the writer on a client
  that stops acknowledging, which KEEP_ALL would (``bench/service_load.py --lossy``: keep-all
  clients lose replies at depth 10, none at this depth). What a client's *reader* drops is the
  client's own doing: rmw_cyclonedds creates it KEEP_LAST 10, and a busy client's own reply can
  be pushed out of it by replies to the other clients before it is taken, whatever the server
  does (README "ROS 2"; ``bench/service_load.py --rmw-reader`` measures it).
- **A request that does not decode is answered.** When its header is readable and the response
  type has ``bool success`` and ``string message`` (as this package's services and
  ``std_srvs`` do), the server replies ``success = false`` with the reason instead of leaving the
  client waiting; either way it logs one line (rate-limited) and keeps serving.
- **A second server is reported.** A client that gets two replies to one request logs once that
  more than one server answers the service and counts them in ``duplicate_replies``.
"""

from __future__ import annotations

import collections
import itertools
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from cyclonedds.core import ReadCondition
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader

from biped_opt.errors import BipedOptError

from ..interfaces import RequestHeader, ServiceType
from . import wire
from .entities import (
    LOG_THROTTLE_S,
    NOT_READ,
    Entity,
    Owner,
    endpoint_id,
    ignore_deleted,
    matched_handles,
    type_hash_user_data,
    user_data_id,
)
from .futures import Future
from .qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, to_dds_qos

__all__ = ["Service", "Client", "MalformedMessageError"]

_MASK64 = (1 << 64) - 1
#: replies a service's writer keeps for retransmission, if not yet acknowledged (module doc)
REPLY_HISTORY = 1000
#: replies remembered per client to tell a duplicate reply from a late one
_ANSWERED_MEMORY = 4096


class MalformedMessageError(BipedOptError, ValueError):
    """A reply that does not decode (set as the exception of the call's future)."""


def _reader_profile(qos: QoSProfile, keep_all: bool = True) -> QoSProfile:
    """The profile of a service's or client's reader: KEEP_ALL when reliable (module doc);
    the profile as given with ``keep_all=False`` (what rmw_cyclonedds creates)."""
    if not keep_all or qos.reliability == ReliabilityPolicy.BEST_EFFORT:
        return qos
    return replace(qos, history=HistoryPolicy.KEEP_ALL)


def _reply_writer_profile(qos: QoSProfile) -> QoSProfile:
    """The profile of a service's reply writer: KEEP_LAST at least :data:`REPLY_HISTORY` deep
    when reliable (module doc)."""
    if qos.reliability == ReliabilityPolicy.BEST_EFFORT or qos.history == HistoryPolicy.KEEP_ALL:
        return qos
    return replace(qos, history=HistoryPolicy.KEEP_LAST, depth=max(qos.depth, REPLY_HISTORY))


class _RequestReply(Entity):
    """A service's or a client's reader and writer pair, named as rmw_cyclonedds names them:
    (request topic, reply topic), both endpoints with USER_DATA ``key=<id>;``."""

    _reader: DataReader | None
    _writer: DataWriter | None
    srv_type: ServiceType
    srv_name: str
    #: False gives the reader the profile's own history, as rmw_cyclonedds does (a subclass
    #: that reproduces an rmw endpoint, e.g. to measure what its clients see)
    reader_keeps_all = True

    def _endpoints(self, node: Owner, qos: QoSProfile, key: str) -> tuple[Any, Any]:
        """Create the pair; returns (request topic + qos, reply topic + qos) for the caller to
        decide which side reads; sets ``self.endpoint_id``."""
        participant = node.context.participant
        self.endpoint_id = endpoint_id(participant)
        user = f"{key}={self.endpoint_id};".encode()
        request_type, reply_type = self.srv_type.name + "_Request", self.srv_type.name + "_Response"
        request = node._topic(f"rq{self.srv_name}Request", self.srv_type.RequestWire)
        reply = node._topic(f"rr{self.srv_name}Reply", self.srv_type.ResponseWire)
        reading = key == "serviceid"
        self._reader = DataReader(
            participant, request if reading else reply,
            qos=to_dds_qos(_reader_profile(qos, self.reader_keeps_all),
                           user + type_hash_user_data(request_type if reading else reply_type)))
        self._writer = DataWriter(
            participant, reply if reading else request,
            qos=to_dds_qos(_reply_writer_profile(qos) if reading else qos,
                           user + type_hash_user_data(reply_type if reading else request_type)))
        self.condition = ReadCondition(self._reader, NOT_READ)
        return request, reply

    def _guids(self) -> tuple[list[bytes], list[bytes]]:
        reader, writer = self._reader, self._writer
        if reader is None or writer is None:
            return [], []
        return [reader.get_guid().bytes], [writer.get_guid().bytes]

    def _dds(self) -> tuple[Any, ...]:
        return (self._reader, self._writer)

    def _forget(self) -> None:
        self._reader = self._writer = None

    def _where(self) -> str:
        return self.srv_name


class Service(_RequestReply):
    """``rclpy.service.Service``: ``callback(request, response) -> response``."""

    # rmw_cyclonedds waits 100 ms for a new client's reply reader before answering and drops the
    # reply after that; on a loaded machine discovery can take longer, and a dropped reply leaves
    # the client waiting forever, so wait up to 1 s (only a client not yet matched ever waits)
    reply_wait_s = 1.0

    def __init__(self, node: Owner, srv_type: ServiceType, name: str,
                 callback: Callable[[Any, Any], Any], qos: QoSProfile, group: Any) -> None:
        super().__init__()
        self.node, self.srv_type, self.srv_name = node, srv_type, name
        self.callback, self.callback_group, self.qos_profile = callback, group, qos
        self._endpoints(node, qos, "serviceid")
        self.service_id = self.endpoint_id
        self._client_ids: dict[int, str | None] = {}
        self._ready_clients: set[str] = set()
        fields = getattr(srv_type.Response, "__annotations__", {})
        self._can_refuse = "success" in fields and "message" in fields
        self.malformed_requests = 0

    def _take(self) -> list[Callable[[], None]]:
        requests, malformed = self._take_from()
        tasks: list[Callable[[], None]] = [lambda r=r: self._handle(r) for r in requests]
        for sample in malformed:
            self.malformed_requests += 1
            refuse = sample.header is not None and self._can_refuse
            self.node.get_logger().warning(
                f"service {self.srv_name}: a request of {sample.size} bytes does not decode "
                f"({sample.reason}); " + ("answered success=false" if refuse else "dropped"),
                throttle_duration_sec=LOG_THROTTLE_S)
            if refuse:
                tasks.append(lambda s=sample: self._refuse(s))
        return tasks

    def _refuse(self, sample: wire.Malformed) -> None:
        """Answer a request that did not decode: ``success = false`` and the reason."""
        assert sample.header is not None
        response = self.srv_type.Response(
            success=False, message=f"malformed request: {sample.reason}")
        header = RequestHeader(guid=sample.header[0], seq=sample.header[1])
        self._reply(header, response, sample.publication_handle)

    def _handle(self, request: Any) -> None:
        response = self.callback(request.body, self.srv_type.Response())
        if not isinstance(response, self.srv_type.Response):
            raise TypeError(f"service {self.srv_name}: callback returned "
                            f"{type(response).__name__}, expected "
                            f"{self.srv_type.Response.__name__}")
        self._reply(request.header, response, request.sample_info.publication_handle)

    def _reply(self, header: Any, response: Any, publication: int) -> None:
        status = self._client_present(publication)
        if status == "gone":
            return  # the client disappeared (or this service was destroyed): nobody to answer
        if status == "maybe":
            self.node.get_logger().warning(
                f"service {self.srv_name}: the client's reply reader did not appear "
                f"within {self.reply_wait_s * 1e3:.0f} ms; reply dropped")
            return
        writer = self._writer
        if writer is not None:  # a service destroyed meanwhile answers nobody
            ignore_deleted(
                lambda: writer.write(self.srv_type.ResponseWire(header=header, body=response)),
                self)

    def _client_present(self, publication: int) -> str:
        """``yes``/``gone``/``maybe`` (timed out) for the client that wrote a request.

        As rmw_cyclonedds: a request writer without ``clientid`` is assumed fine; otherwise
        wait up to ``reply_wait_s`` until the reply writer has matched the reader with that id.
        """
        deadline = time.monotonic() + self.reply_wait_s
        if publication not in self._client_ids:
            with self._lock:
                reader = self._reader
                data = reader.get_matched_publication_data(publication) if reader else None
            if data is None:
                return "gone"
            self._client_ids[publication] = user_data_id(data.qos, "clientid")
        client_id = self._client_ids[publication]
        if client_id is None or client_id in self._ready_clients:
            return "yes"
        while True:
            with self._lock:
                writer = self._writer
                if writer is None:
                    return "gone"
                matched = [writer.get_matched_subscription_data(h)
                           for h in matched_handles(writer)]
            if any(d is not None and user_data_id(d.qos, "clientid") == client_id
                   for d in matched):
                self._ready_clients.add(client_id)
                return "yes"
            if time.monotonic() >= deadline:
                return "maybe"
            time.sleep(0.002)


class Client(_RequestReply):
    """``rclpy.client.Client``: ``wait_for_service``, ``call_async -> Future``, ``call``,
    ``remove_pending_request``."""

    def __init__(self, node: Owner, srv_type: ServiceType, name: str, qos: QoSProfile,
                 group: Any) -> None:
        super().__init__()
        self.node, self.srv_type, self.srv_name = node, srv_type, name
        self.callback_group, self.qos_profile = group, qos
        self._endpoints(node, qos, "clientid")
        self.client_id = self.endpoint_id
        assert self._writer is not None
        self.guid = self._writer.get_instance_handle() & _MASK64
        self._seq = itertools.count(1)
        self._pending: dict[int, Future] = {}
        self._answered: collections.deque[int] = collections.deque(maxlen=_ANSWERED_MEMORY)
        self._pending_lock = threading.Lock()
        #: replies to a request that was already answered (more than one server)
        self.duplicate_replies = 0

    def service_is_ready(self) -> bool:
        """A server whose request reader and reply writer (same ``serviceid``) are matched."""
        with self._lock:
            if self._writer is None or self._reader is None:
                return False
            readers = [self._writer.get_matched_subscription_data(h)
                       for h in matched_handles(self._writer)]
            writers = [self._reader.get_matched_publication_data(h)
                       for h in matched_handles(self._reader)]
        needles = {user_data_id(d.qos, "serviceid") for d in readers if d is not None} - {None}
        if not needles:
            # Servers without ids (older rmw, plain DDS): matched endpoints are enough.
            return bool(readers) and bool(writers)
        return any(d is not None and user_data_id(d.qos, "serviceid") in needles
                   for d in writers)

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
        future = Future()
        with self._pending_lock:
            seq = next(self._seq)
            self._pending[seq] = future
        sample = self.srv_type.RequestWire(body=request)
        sample.header.guid, sample.header.seq = self.guid, seq
        writer = self._writer
        if writer is None:
            raise RuntimeError(f"client of {self.srv_name} was destroyed")
        writer.write(sample)
        return future

    def call(self, request: Any, timeout_sec: float | None = None) -> Any:
        """Blocking call; another thread must be spinning the node (as in rclpy)."""
        future = self.call_async(request)
        if not future.wait(timeout_sec):
            self.remove_pending_request(future)
            future.cancel()
            return None
        return future.result()

    def remove_pending_request(self, future: Future) -> None:
        """Forget a request (its reply, if one comes, is then ignored), as rclpy's."""
        with self._pending_lock:
            for seq, pending in list(self._pending.items()):
                if pending is future:
                    del self._pending[seq]

    def _take(self) -> list[Callable[[], None]]:
        replies, malformed = self._take_from()
        tasks = []
        for reply in replies:
            if (reply.header.guid & _MASK64) != self.guid:
                continue  # a reply to another client of the same service
            future = self._settle(reply.header.seq)
            if future is not None:
                tasks.append(lambda f=future, b=reply.body: f.set_result(b))
        for sample in malformed:
            if sample.header is not None and (sample.header[0] & _MASK64) != self.guid:
                continue  # another client's reply: not ours to report
            self._log_malformed(sample)
            if sample.header is None:
                continue
            future = self._settle(sample.header[1])
            if future is not None:
                error = MalformedMessageError(
                    f"{self.srv_name}: the reply does not decode ({sample.reason})")
                tasks.append(lambda f=future, e=error: f.set_exception(e))
        return tasks

    def _settle(self, seq: int) -> Future | None:
        """The pending future of ``seq``, now answered; None for a duplicate or late reply."""
        with self._pending_lock:
            future = self._pending.pop(seq, None)
            if future is not None:
                self._answered.append(seq)
                return None if future.done() else future
            duplicate = seq in self._answered
        if duplicate:
            self.duplicate_replies += 1
            if self.duplicate_replies == 1:
                self.node.get_logger().warning(
                    f"client of {self.srv_name}: a second reply to one request; more than one "
                    "server answers this service (each answer after the first is ignored)")
        return None

    def destroy(self) -> None:
        super().destroy()
        with self._pending_lock:
            pending, self._pending = self._pending, {}
        for future in pending.values():
            future.cancel()
