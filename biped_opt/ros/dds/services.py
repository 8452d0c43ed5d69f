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
- **Clients are served in turn.** A service queues requests per client (a DDS participant: one
  process, however many clients it creates) and serves the clients in turn, at most
  :data:`MAX_QUEUED_PER_CLIENT` waiting per client (more are answered :data:`TOO_MANY`): one
  client's flood delays another's request by at most one request of each client ahead of it,
  not by the whole flood. A node may give a service a ``quick_reply`` (its cache) that answers
  as requests are taken, before any queue.
- **No reply waits on a serving thread.** rmw_cyclonedds waits (100 ms) for a new client's
  reply reader to match before it answers, on the thread that serves. Here a reply to a client
  whose reader has not matched yet is held by a thread of the service's own, sent when the
  reader appears, dropped after ``reply_wait_s`` (one warning a second at most) and the client
  remembered: its later replies get one look, so a client that never reads costs the service
  nothing.
- **A second server is reported.** A client that gets two replies to one request logs once that
  more than one server answers the service and counts them in ``duplicate_replies``.
"""

from __future__ import annotations

import collections
import itertools
import os
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any, NamedTuple

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

__all__ = ["Service", "Client", "MalformedMessageError", "MAX_QUEUED_PER_CLIENT", "TOO_MANY"]

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


#: most requests of one client waiting in one service's queue; more are answered
#: :data:`TOO_MANY` at once. A client is a DDS participant (one process, however many clients
#: it creates), so a peer cannot buy more turns by making more clients.
MAX_QUEUED_PER_CLIENT = 32
#: the refusal of a request beyond :data:`MAX_QUEUED_PER_CLIENT`
TOO_MANY = "busy: too many requests from this client"
#: replies a service holds for clients whose reply reader has not appeared yet; beyond this the
#: oldest is dropped
MAX_HELD_REPLIES = 1024
#: request writers (and matched reply readers) a service remembers
_REMEMBERED = 4096


def _matched_data(lookup: Callable[[int], Any], handle: int) -> Any:
    """What DDS knows of a matched endpoint, or None: gone meanwhile, or the binding's
    conversion of its QoS failed ("Callfunc cqos errored", seen now and then while endpoints
    are created and deleted around it; the caller looks again later)."""
    try:
        return lookup(handle)
    except Exception:
        return None


class _FairQueue:
    """Requests waiting to be served, one queue per client, taken in turn: the client served
    goes to the back of the line, so a client that sends many waits behind every other once
    per request, and one that sends a few is never behind more than one request of each."""

    def __init__(self, cap: int) -> None:
        self.cap = cap
        self._lock = threading.Lock()
        self._queues: collections.OrderedDict[Any, collections.deque[Any]] = \
            collections.OrderedDict()
        self._size = 0

    def __len__(self) -> int:
        return self._size

    def put(self, client: Any, item: Any) -> bool:
        """Queue ``item`` of ``client``; False (nothing queued) when it has ``cap`` waiting."""
        with self._lock:
            queue = self._queues.get(client)
            if queue is None:
                queue = self._queues[client] = collections.deque()
            elif len(queue) >= self.cap:
                return False
            queue.append(item)
            self._size += 1
            return True

    def pop(self) -> Any:
        """The next request in turn, or None."""
        with self._lock:
            if not self._queues:
                return None
            client, queue = next(iter(self._queues.items()))
            item = queue.popleft()
            self._size -= 1
            if queue:
                self._queues.move_to_end(client)
            else:
                del self._queues[client]
            return item

    def clear(self) -> None:
        with self._lock:
            self._queues.clear()
            self._size = 0


class _Requester(NamedTuple):
    """What a service knows of the writer of a request: its client's ``clientid`` (None: a
    writer without one, a plain DDS peer) and the participant it belongs to (the fair queue's
    key)."""

    client_id: str | None
    participant: Any


class _Held(NamedTuple):
    deadline: float
    publication: int
    header: Any
    response: Any


class Service(_RequestReply):
    """``rclpy.service.Service``: ``callback(request, response) -> response``.

    Requests are queued per client and served in turn (:class:`_FairQueue`), at most
    :attr:`concurrency` at once, a client's requests beyond :data:`MAX_QUEUED_PER_CLIENT`
    refused ``busy``. :attr:`quick_reply` (None, or ``f(request) -> response or None``) runs as
    each request is taken, on the executor's own thread: what it answers (a cached answer)
    never waits behind the computations in the queue. A reply to a client whose reply reader
    the service has not matched yet waits in a thread of the service's own (:meth:`_reply`),
    never on the thread that serves.
    """

    # rmw_cyclonedds waits 100 ms for a new client's reply reader before answering and drops the
    # reply after that; on a loaded machine discovery can take longer, and a dropped reply leaves
    # the client waiting forever, so wait up to 5 s (only a client not yet matched ever waits;
    # eight clients made at once on two busy cores once took over 1 s to be matched)
    reply_wait_s = 5.0

    def __init__(self, node: Owner, srv_type: ServiceType, name: str,
                 callback: Callable[[Any, Any], Any], qos: QoSProfile, group: Any) -> None:
        super().__init__()
        self.node, self.srv_type, self.srv_name = node, srv_type, name
        self.callback, self.callback_group, self.qos_profile = callback, group, qos
        self._endpoints(node, qos, "serviceid")
        self.service_id = self.endpoint_id
        fields = getattr(srv_type.Response, "__annotations__", {})
        self._can_refuse = "success" in fields and "message" in fields
        self.malformed_requests = 0
        #: requests answered busy because their client had too many waiting
        self.refused_busy = 0
        #: replies dropped because the client's reply reader never appeared
        self.dropped_replies = 0
        self.quick_reply: Callable[[Any], Any] | None = None
        #: requests served at once: one in a mutually exclusive group, else one per core
        self.concurrency = 1 if getattr(group, "lock", None) is not None else \
            max(1, os.cpu_count() or 1)
        self._queue = _FairQueue(MAX_QUEUED_PER_CLIENT)
        self._in_flight = 0
        self._slots = threading.Lock()
        self._requesters: collections.OrderedDict[int, _Requester] = collections.OrderedDict()
        self._known_readers: dict[int, str | None] = {}  # reply reader handle -> clientid
        self._matched_ids: frozenset[str] = frozenset()
        self._absent: collections.OrderedDict[str, None] = collections.OrderedDict()
        self._held: collections.deque[_Held] = collections.deque()
        self._held_lock = threading.Condition(threading.Lock())
        self._waiter: threading.Thread | None = None

    # -- taking and queueing (the executor's thread) -----------------------------------------
    def _triggered(self) -> bool:
        return super()._triggered() or (len(self._queue) > 0
                                        and self._in_flight < self.concurrency)

    def _take(self) -> list[Callable[[], None]]:
        requests, malformed = self._take_from()
        for request in requests:
            publication = request.sample_info.publication_handle
            response = self._quick(request.body)
            if response is not None:
                self._reply(request.header, response, publication)
                continue
            requester = self._requester(publication)
            client = requester.participant if requester is not None else publication
            if not self._queue.put(client, request):
                self._too_many(request, publication)
        for sample in malformed:
            self.malformed_requests += 1
            refuse = sample.header is not None and self._can_refuse
            self.node.get_logger().warning(
                f"service {self.srv_name}: a request of {sample.size} bytes does not decode "
                f"({sample.reason}); " + ("answered success=false" if refuse else "dropped"),
                throttle_duration_sec=LOG_THROTTLE_S)
            if refuse:
                self._refuse(sample)
        with self._slots:
            count = max(0, min(len(self._queue), self.concurrency - self._in_flight))
            self._in_flight += count
        return [self._serve_next] * count

    def _quick(self, body: Any) -> Any:
        """:attr:`quick_reply`'s answer to ``body``, or None (also when it fails: the request
        then takes the queue, where a failure is answered)."""
        quick = self.quick_reply
        if quick is None:
            return None
        try:
            response = quick(body)
        except Exception:  # (the request goes the long way and fails there, answered)
            return None
        return response if isinstance(response, self.srv_type.Response) else None

    def _too_many(self, request: Any, publication: int) -> None:
        self.refused_busy += 1
        self.node.get_logger().warning(
            f"service {self.srv_name}: a client has {MAX_QUEUED_PER_CLIENT} requests waiting; "
            + ("answered busy" if self._can_refuse else "request dropped"),
            throttle_duration_sec=LOG_THROTTLE_S)
        if self._can_refuse:
            response = self.srv_type.Response(
                success=False, message=f"{TOO_MANY} ({MAX_QUEUED_PER_CLIENT} waiting); retry")
            self._reply(request.header, response, publication)

    def _refuse(self, sample: wire.Malformed) -> None:
        """Answer a request that did not decode: ``success = false`` and the reason."""
        assert sample.header is not None
        response = self.srv_type.Response(
            success=False, message=f"malformed request: {sample.reason}")
        header = RequestHeader(guid=sample.header[0], seq=sample.header[1])
        self._reply(header, response, sample.publication_handle)

    # -- serving (a pool thread) -------------------------------------------------------------
    def _serve_next(self) -> None:
        try:
            request = self._queue.pop()
            if request is not None:
                try:
                    self._handle(request)
                except Exception as exc:  # a bug in the callback: one failed request
                    self._failed(request, exc)
        finally:
            with self._slots:
                self._in_flight -= 1
            self.node.context.wake()  # (the executor takes the next one in turn)

    def _handle(self, request: Any) -> None:
        response = self.callback(request.body, self.srv_type.Response())
        if not isinstance(response, self.srv_type.Response):
            raise TypeError(f"service {self.srv_name}: callback returned "
                            f"{type(response).__name__}, expected "
                            f"{self.srv_type.Response.__name__}")
        self._reply(request.header, response, request.sample_info.publication_handle)

    def _failed(self, request: Any, exc: Exception) -> None:
        self.node.get_logger().error(
            f"service {self.srv_name}: the callback raised {type(exc).__name__}: "
            f"{str(exc)[:200]}", throttle_duration_sec=LOG_THROTTLE_S)
        if self._can_refuse:
            response = self.srv_type.Response(
                success=False, message=f"internal error: {type(exc).__name__}")
            self._reply(request.header, response, request.sample_info.publication_handle)

    # -- replying ----------------------------------------------------------------------------
    def _requester(self, publication: int) -> _Requester | None:
        """Who wrote requests from ``publication`` (remembered); None when the request reader
        cannot tell now (the writer is gone, or the binding failed to convert its data)."""
        known = self._requesters.get(publication)
        if known is not None:
            return known
        with self._lock:
            reader = self._reader
            data = (_matched_data(reader.get_matched_publication_data, publication)
                    if reader else None)
        if data is None:
            return None
        found = _Requester(user_data_id(data.qos, "clientid"),
                           getattr(data, "participant_key", None) or publication)
        self._requesters[publication] = found
        while len(self._requesters) > _REMEMBERED:
            self._requesters.popitem(last=False)
        return found

    def _reply(self, header: Any, response: Any, publication: int) -> None:
        """Send ``response`` now if the client's reply reader is matched (or the client has no
        ``clientid``: a plain DDS peer, as rmw assumes), else hold it for the reply waiter: up
        to ``reply_wait_s`` for a new client, one look for a client whose reader never appeared
        before. Never waits on the calling thread."""
        requester = self._requester(publication)
        if requester is not None and (requester.client_id is None
                                      or requester.client_id in self._matched_ids):
            self._write(header, response)
            return
        absent = requester is not None and requester.client_id in self._absent
        held = _Held(time.monotonic() + (0.0 if absent else self.reply_wait_s), publication,
                     header, response)
        with self._held_lock:
            if self._destroyed:
                return
            if len(self._held) >= MAX_HELD_REPLIES:
                self._held.popleft()
                self._drop("more replies waiting for their clients than the service holds")
            self._held.append(held)
            if self._waiter is None:
                self._waiter = threading.Thread(target=self._wait_for_readers, daemon=True,
                                                name=f"replies {self.srv_name}")
                self._waiter.start()
            self._held_lock.notify()

    def _write(self, header: Any, response: Any) -> None:
        writer = self._writer
        if writer is not None:  # a service destroyed meanwhile answers nobody
            ignore_deleted(
                lambda: writer.write(self.srv_type.ResponseWire(header=header, body=response)),
                self)

    def _drop(self, why: str) -> None:
        self.dropped_replies += 1
        self.node.get_logger().warning(f"service {self.srv_name}: reply dropped: {why}",
                                       throttle_duration_sec=LOG_THROTTLE_S)

    def _refresh_matched(self) -> None:
        """The clientids of the reply readers the writer has matched now."""
        with self._lock:
            writer = self._writer
            if writer is None:
                return
            try:
                handles = matched_handles(writer)
            except Exception:  # (destroyed meanwhile)
                return
            for handle in handles:
                if handle not in self._known_readers:
                    data = _matched_data(writer.get_matched_subscription_data, handle)
                    if data is not None:  # (else: look again at the next refresh)
                        self._known_readers[handle] = user_data_id(data.qos, "clientid")
        current = set(handles)
        for handle in [h for h in self._known_readers if h not in current]:
            del self._known_readers[handle]
        self._matched_ids = frozenset(i for i in self._known_readers.values() if i is not None)

    def _wait_for_readers(self) -> None:
        """The reply waiter: every few milliseconds while replies are held, send those whose
        reader has appeared and drop those past their deadline (the client remembered, so that
        its next replies cost one look)."""
        while True:
            with self._held_lock:
                while not self._held and not self._destroyed:
                    self._held_lock.wait()
                if self._destroyed:
                    self._held.clear()
                    self._waiter = None
                    return
                held, self._held = self._held, collections.deque()
            self._refresh_matched()
            now, keep = time.monotonic(), []
            for item in held:
                requester = self._requester(item.publication)
                if requester is not None and (requester.client_id is None
                                              or requester.client_id in self._matched_ids):
                    self._write(item.header, item.response)
                    if requester.client_id is not None:
                        self._absent.pop(requester.client_id, None)
                elif now >= item.deadline:
                    if requester is None:
                        continue  # the client is gone: nobody to answer
                    if requester.client_id is not None:
                        self._absent[requester.client_id] = None
                        while len(self._absent) > _REMEMBERED:
                            self._absent.popitem(last=False)
                    self._drop(f"the client's reply reader did not appear within "
                               f"{self.reply_wait_s * 1e3:.0f} ms")
                else:
                    keep.append(item)
            if keep:
                with self._held_lock:
                    self._held.extendleft(reversed(keep))
                time.sleep(0.002)

    def destroy(self) -> None:
        super().destroy()
        self._queue.clear()
        with self._held_lock:
            self._held.clear()
            self._held_lock.notify_all()


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
            readers = [_matched_data(self._writer.get_matched_subscription_data, h)
                       for h in matched_handles(self._writer)]
            writers = [_matched_data(self._reader.get_matched_publication_data, h)
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
