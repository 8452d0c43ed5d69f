"""Contexts of the built-in backend: one Cyclone DDS participant per ``init``.

Mirrors ``rclpy.context.Context``: ``init(args=None, *, context=None, domain_id=None)`` creates the
participant on ``domain_id`` (else ``$ROS_DOMAIN_ID``, else 0), with participant USER_DATA
``enclave=/;`` and the ``ros_discovery_info`` writer. ``ROS_LOCALHOST_ONLY=1`` (Humble) and
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (Jazzy) select a loopback-only Cyclone configuration
unless ``CYCLONEDDS_URI`` gives one.

Shutting a context down deletes its DDS entities explicitly, children before parents: the
nodes' readers, writers and topics, the graph writer, then the participant. At interpreter exit
every context still open is shut down and the loopback domains are deleted, before the
interpreter starts tearing down (an entity left to the garbage collector then can call into a
DDS library that is itself shutting down).
"""

from __future__ import annotations

import atexit
import os
import sys
import threading
import weakref
from typing import Any

from cyclonedds.core import DDSException, GuardCondition, Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from biped_opt.errors import BipedOptError, quoted

from . import graph
from .lifetime import delete_dds

__all__ = [
    "Context", "InvalidDomainError", "NotInitializedError", "get_default_context", "init",
    "shutdown", "try_shutdown", "ok", "localhost_only", "loopback_config",
]


class NotInitializedError(BipedOptError, RuntimeError):
    """A context was used before ``init`` or after ``shutdown``."""


class InvalidDomainError(BipedOptError, ValueError):
    """A domain id (argument or ``$ROS_DOMAIN_ID``) outside 0..232, the ids whose DDS ports
    (7400 + 250 id + ...) fit in 16 bits."""


def localhost_only() -> bool:
    """True when the ROS environment asks for loopback-only discovery."""
    if os.environ.get("ROS_LOCALHOST_ONLY", "0").strip() == "1":
        return True
    return os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").strip().upper() == "LOCALHOST"


def loopback_config() -> str:
    """Cyclone XML restricting a domain to the loopback interface with unicast discovery.

    Loopback multicast is unreliable in containers, so peers are found by unicast on
    localhost over the first participant indices.
    """
    return (
        "<CycloneDDS><Domain Id=\"any\"><General><Interfaces>"
        "<NetworkInterface address=\"127.0.0.1\"/></Interfaces>"
        "<AllowMulticast>false</AllowMulticast></General>"
        "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
        "<MaxAutoParticipantIndex>60</MaxAutoParticipantIndex>"
        "<Peers><Peer Address=\"localhost\"/></Peers></Discovery>"
        "</Domain></CycloneDDS>"
    )


_DOMAINS: dict[int, Domain] = {}
_DOMAIN_LOCK = threading.Lock()
#: every context that was initialised and not yet shut down
_OPEN: weakref.WeakSet[Context] = weakref.WeakSet()


def _domain_id(domain_id: int | None) -> int:
    source = "domain_id"
    if domain_id is None:
        source = "ROS_DOMAIN_ID"
        text = os.environ.get("ROS_DOMAIN_ID", "").strip()
        try:
            domain_id = int(text) if text else 0
        except ValueError:
            raise InvalidDomainError(
                f"ROS_DOMAIN_ID must be an integer in 0..232, got {quoted(text)}") from None
    if isinstance(domain_id, bool) or not isinstance(domain_id, int) \
            or not 0 <= domain_id <= 232:
        raise InvalidDomainError(f"{source} must be an integer in 0..232, got {domain_id!r}")
    return domain_id


def _ensure_domain(domain_id: int) -> None:
    # A Domain object pins the configuration of a domain id for this process; it must exist
    # before the first participant on that id and is kept for the process lifetime.
    if not localhost_only() or os.environ.get("CYCLONEDDS_URI"):
        return
    with _DOMAIN_LOCK:
        if domain_id not in _DOMAINS:
            _DOMAINS[domain_id] = Domain(domain_id, config=loopback_config())


class Context:
    """A ROS context: one DDS participant, its graph writer and its nodes."""

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self._participant: DomainParticipant | None = None
        self._nodes: list[Any] = []
        self._guards: list[GuardCondition] = []
        self._on_shutdown: list[Any] = []
        self._graph_writer: DataWriter | None = None
        self._graph_topic: Topic | None = None
        self._services: graph.ServiceDirectory | None = None
        self._topics: graph.TopicDirectory | None = None
        self.domain_id: int | None = None
        self.args: list[str] = []

    # -- lifecycle ---------------------------------------------------------------------------
    def init(self, args: list[str] | None = None, *, domain_id: int | None = None) -> None:
        with self._lock:
            if self._participant is not None:
                raise RuntimeError("Context.init() must only be called once")
            self.domain_id = _domain_id(domain_id)
            # rclpy: args=None means the process's command line
            self.args = list(args) if args is not None else list(sys.argv)
            _ensure_domain(self.domain_id)
            qos = Qos(Policy.Userdata(data=b"enclave=/;"))
            self._participant = DomainParticipant(self.domain_id, qos=qos)
            self._layout = graph.graph_layout()
            gid_t, node_t, info_t = graph.graph_types(self._layout)
            self._graph_types = (gid_t, node_t, info_t)
            topic = Topic(self._participant, graph.GRAPH_TOPIC, info_t, qos=Qos(
                Policy.DataRepresentation(use_cdrv0_representation=True)))
            self._graph_topic = topic
            self._graph_writer = DataWriter(self._participant, topic, qos=Qos(
                Policy.DataRepresentation(use_cdrv0_representation=True),
                Policy.Reliability.Reliable(max_blocking_time=duration(seconds=1)),
                Policy.Durability.TransientLocal,
                Policy.History.KeepLast(depth=1),
            ))
            _OPEN.add(self)
            self.publish_graph()

    def ok(self) -> bool:
        return self._participant is not None

    def shutdown(self) -> None:
        with self._lock:
            if self._participant is None:
                raise NotInitializedError("Context.shutdown(): context is not initialized")
            self._teardown()

    def try_shutdown(self) -> None:
        with self._lock:
            if self._participant is not None:
                self._teardown()

    def _teardown(self) -> None:
        for node in list(self._nodes):
            node.destroy_node()
        participant, self._participant = self._participant, None
        _OPEN.discard(self)
        for guard in list(self._guards):
            guard.set(True)  # executors waiting on this context wake up and stop
        for callback in list(self._on_shutdown):
            callback()
        if self._services is not None:
            self._services.delete()
            self._services = None
        if self._topics is not None:
            self._topics.delete()
            self._topics = None
        writer, topic = self._graph_writer, self._graph_topic
        self._graph_writer = self._graph_topic = None
        guards, self._guards = list(self._guards), []
        self._global_executor = None
        # What is left below the participant (WaitSets and GuardConditions of executors that
        # were never shut down) goes with it.
        delete_dds(writer, topic, *guards, participant)

    def on_shutdown(self, callback: Any) -> None:
        self._on_shutdown.append(callback)

    # -- helpers for nodes and executors -----------------------------------------------------
    @property
    def participant(self) -> DomainParticipant:
        if self._participant is None:
            raise NotInitializedError("context is not initialized (call init() first)")
        return self._participant

    def service_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every service on the domain (:class:`.graph.ServiceDirectory`)."""
        with self._lock:
            if self._services is None:
                self._services = graph.ServiceDirectory(self.participant)
            return self._services.services()

    def topic_directory(self) -> graph.TopicDirectory:
        """Every topic on the domain and its endpoints (:class:`.graph.TopicDirectory`)."""
        with self._lock:
            if self._topics is None:
                self._topics = graph.TopicDirectory(self.participant)
            return self._topics

    def new_guard(self) -> GuardCondition:
        guard = GuardCondition(self.participant)
        with self._lock:
            self._guards.append(guard)
        return guard

    def release_guard(self, guard: GuardCondition) -> None:
        """Forget a guard its owner is about to delete."""
        with self._lock:
            if guard in self._guards:
                self._guards.remove(guard)

    def wake(self) -> None:
        """Trigger every executor waiting on this context (node added, timer created...)."""
        for guard in list(self._guards):
            try:
                guard.set(True)
            except DDSException:
                pass  # deleted by its executor meanwhile

    def add_node(self, node: Any) -> None:
        with self._lock:
            self._nodes.append(node)
        self.publish_graph()

    def remove_node(self, node: Any) -> None:
        with self._lock:
            if node in self._nodes:
                self._nodes.remove(node)
        self.publish_graph()

    def publish_graph(self) -> None:
        """Write this participant's ``ParticipantEntitiesInfo`` (nodes and endpoint GIDs)."""
        with self._lock:
            if self._participant is None or self._graph_writer is None:
                return
            gid_t, node_t, info_t = self._graph_types
            nodes = []
            for node in self._nodes:
                readers, writers = node._endpoint_guids()
                nodes.append(node_t(
                    node_namespace=node.get_namespace(), node_name=node.get_name(),
                    reader_gid_seq=[gid_t(data=graph.gid_bytes(g, self._layout))
                                    for g in readers],
                    writer_gid_seq=[gid_t(data=graph.gid_bytes(g, self._layout))
                                    for g in writers],
                ))
            pgid = graph.gid_bytes(self._participant.get_guid().bytes, self._layout)
            self._graph_writer.write(info_t(gid=gid_t(data=pgid), node_entities_info_seq=nodes))


_default_context = Context()


@atexit.register
def _shutdown_at_exit() -> None:
    for context in list(_OPEN):
        context.try_shutdown()
    with _DOMAIN_LOCK:
        domains = list(_DOMAINS.values())
        _DOMAINS.clear()
    delete_dds(*domains)


def get_default_context() -> Context:
    return _default_context


def init(args: list[str] | None = None, *, context: Context | None = None,
         domain_id: int | None = None) -> None:
    """``rclpy.init``: initialise ``context`` (the default context when None)."""
    (context or _default_context).init(args, domain_id=domain_id)


def shutdown(*, context: Context | None = None) -> None:
    (context or _default_context).shutdown()


def try_shutdown(*, context: Context | None = None) -> None:
    (context or _default_context).try_shutdown()


def ok(*, context: Context | None = None) -> bool:
    return (context or _default_context).ok()
