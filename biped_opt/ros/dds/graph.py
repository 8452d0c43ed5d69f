"""The ``ros_discovery_info`` graph topic of rmw_dds_common (ROS.md Sec. 2).

Every context publishes one ``ParticipantEntitiesInfo`` sample listing its nodes and their
reader/writer GIDs, which is what ``ros2 node list`` reads. ``Gid`` is ``char[24]`` on Humble
(16-byte DDS GUID zero-padded) and ``char[16]`` on Jazzy; ``BIPED_OPT_GRAPH_LAYOUT=jazzy`` selects
the latter. ``char`` is declared as an octet (Cyclone 0.10 peers crash on uint8 type objects).
"""

from __future__ import annotations

import dataclasses
import os
import threading
from dataclasses import dataclass
from typing import Any

from cyclonedds.idl import IdlMeta, IdlStruct
from cyclonedds.idl import types as dt

from .lifetime import delete_dds

__all__ = ["GRAPH_TOPIC", "ServiceDirectory", "TopicDirectory", "TopicEndpointInfo", "graph_layout",
           "graph_types", "gid_bytes", "ros_type_name"]

GRAPH_TOPIC = "ros_discovery_info"
_ENV_LAYOUT = "BIPED_OPT_GRAPH_LAYOUT"
_SIZES = {"humble": 24, "jazzy": 16}
_CACHE: dict[str, tuple[Any, Any, Any]] = {}


def graph_layout() -> str:
    """``humble`` (default) or ``jazzy`` from ``$BIPED_OPT_GRAPH_LAYOUT``."""
    layout = os.environ.get(_ENV_LAYOUT, "humble").strip().lower() or "humble"
    if layout not in _SIZES:
        raise ValueError(f"{_ENV_LAYOUT} must be 'humble' or 'jazzy', got {layout!r}")
    return layout


def _struct(name: str, typename: str, fields: dict[str, tuple[Any, Any]]) -> Any:
    ns = IdlMeta.__prepare__(name, (IdlStruct,), typename=typename)
    ns["__annotations__"].update({k: v[0] for k, v in fields.items()})
    ns.update({k: v[1] for k, v in fields.items()})
    ns["__module__"] = __name__
    return dataclasses.dataclass(IdlMeta(name, (IdlStruct,), ns, typename=typename))


def graph_types(layout: str | None = None) -> tuple[Any, Any, Any]:
    """(Gid, NodeEntitiesInfo, ParticipantEntitiesInfo) IdlStructs for one layout."""
    layout = layout or graph_layout()
    if layout in _CACHE:
        return _CACHE[layout]
    size = _SIZES[layout]
    gid = _struct("Gid", "rmw_dds_common::msg::dds_::Gid_", {
        "data": (dt.array[dt.byte, size],
                 dataclasses.field(default_factory=lambda: [0] * size)),
    })
    node = _struct("NodeEntitiesInfo", "rmw_dds_common::msg::dds_::NodeEntitiesInfo_", {
        "node_namespace": (dt.bounded_str[256], ""),
        "node_name": (dt.bounded_str[256], ""),
        "reader_gid_seq": (dt.sequence[gid], dataclasses.field(default_factory=list)),
        "writer_gid_seq": (dt.sequence[gid], dataclasses.field(default_factory=list)),
    })
    info = _struct(
        "ParticipantEntitiesInfo", "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_", {
            "gid": (gid, dataclasses.field(default_factory=gid)),
            "node_entities_info_seq": (dt.sequence[node],
                                       dataclasses.field(default_factory=list)),
        })
    _CACHE[layout] = (gid, node, info)
    return _CACHE[layout]


def gid_bytes(guid_bytes: bytes, layout: str | None = None) -> list[int]:
    """A 16-byte DDS GUID as the ``data`` of a ``Gid`` (zero-padded on Humble)."""
    size = _SIZES[layout or graph_layout()]
    return list(guid_bytes[:16]) + [0] * (size - 16)


class ServiceDirectory:
    """The services on the domain, as rmw_cyclonedds derives them from discovery: every
    request reader ``rq<name>Request`` of type ``pkg::srv::dds_::Name_Request_`` is a service
    ``<name>`` of type ``pkg/srv/Name`` (also one of another participant or host, and gone as soon
    as DDS disposes of the reader: its node destroyed it, or its participant's lease expired)."""

    def __init__(self, participant: Any) -> None:
        from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsSubscription
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState

        self._reader = BuiltinDataReader(participant, BuiltinTopicDcpsSubscription)
        self._alive = ReadCondition(self._reader,
                                    SampleState.Any | ViewState.Any | InstanceState.Alive)

    def services(self) -> list[tuple[str, list[str]]]:
        """``[(name, [type, ...]), ...]`` sorted by name, as rclpy's
        ``Node.get_service_names_and_types``."""
        found: dict[str, set[str]] = {}
        for sample in _read_off_main_thread(self._reader, self._alive):
            topic, type_name = sample.topic_name, sample.type_name
            if not (topic.startswith("rq/") and topic.endswith("Request")
                    and type_name.endswith("_Request_") and "::dds_::" in type_name):
                continue
            pkg_kind, short = type_name.rsplit("::dds_::", 1)
            ros_type = pkg_kind.replace("::", "/") + "/" + short[: -len("_Request_")]
            found.setdefault(topic[2: -len("Request")], set()).add(ros_type)
        return [(name, sorted(kinds)) for name, kinds in sorted(found.items())]

    def delete(self) -> None:
        delete_dds(self._alive, self._reader)


def ros_type_name(dds_type: str) -> str | None:
    """rmw_cyclonedds' DDS type name ``pkg::msg::dds_::Name_`` as ``pkg/msg/Name`` (None for a
    name of another form)."""
    head, sep, short = dds_type.rpartition("::dds_::")
    if not sep or not head or not short.endswith("_") or len(short) < 2:
        return None
    return head.replace("::", "/") + "/" + short[:-1]


@dataclass(frozen=True)
class TopicEndpointInfo:
    """``rclpy.topic_endpoint_info.TopicEndpointInfo`` subset: one publisher or subscription of
    a topic, seen through DDS discovery (``node_name``/``node_namespace`` are rmw's
    "unknown" names: discovery alone does not say which node owns an endpoint)."""

    topic_type: str
    endpoint_gid: bytes
    qos_profile: Any  #: a :class:`.qos.QoSProfile`
    node_name: str = "_NODE_NAME_UNKNOWN_"
    node_namespace: str = "_NODE_NAMESPACE_UNKNOWN_"


#: most endpoints one graph query reads (the buffers of a read are allocated for this many)
MAX_ENDPOINTS = 16384


def _read_off_main_thread(reader: Any, condition: Any) -> list[Any]:
    """``reader.read`` of every sample ``condition`` selects, in a thread of its own when called
    from the main thread: PyPI cyclonedds builds each built-in sample with Python calls, and a
    signal handler that raises in one of them (Ctrl-C, SIGTERM as nodes install it) would come
    out as a plain ``Exception("... errored.")``, the interrupt lost. Signal handlers run in the
    main thread only, so there the interrupt ends the wait instead, as it should."""
    if threading.current_thread() is not threading.main_thread():
        return list(reader.read(N=MAX_ENDPOINTS, condition=condition))
    box: dict[str, Any] = {}

    def read() -> None:
        try:
            box["samples"] = list(reader.read(N=MAX_ENDPOINTS, condition=condition))
        except BaseException as exc:
            box["error"] = exc

    worker = threading.Thread(target=read, name="biped_opt-graph-read", daemon=True)
    worker.start()
    worker.join()
    if "error" in box:
        raise box["error"]
    return box["samples"]


def _profile(qos: Any) -> Any:
    """The :class:`.qos.QoSProfile` of a discovered endpoint's DDS QoS."""
    from cyclonedds.core import Policy

    from .qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    def policy(kind: Any) -> Any:
        try:
            return qos[kind]
        except (KeyError, TypeError):
            return None

    history, reliability = policy(Policy.History), policy(Policy.Reliability)
    durability = policy(Policy.Durability)
    keep_all = isinstance(history, type(Policy.History.KeepAll))
    depth = int(getattr(history, "depth", 1) or 1)
    best_effort = isinstance(reliability, type(Policy.Reliability.BestEffort))
    # volatile is DDS's default, and every durability beyond it keeps history for late joiners
    volatile = durability is None or isinstance(durability, type(Policy.Durability.Volatile))
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE if volatile else DurabilityPolicy.TRANSIENT_LOCAL)


class TopicDirectory:
    """The topics on the domain as rmw_cyclonedds derives them from discovery: every writer or
    reader of ``rt/<name>`` with a type named ``pkg::msg::dds_::Name_`` is an endpoint of the
    topic ``<name>`` of type ``pkg/msg/Name``, this participant's own included (as rclpy's graph
    queries include the node's own endpoints)."""

    def __init__(self, participant: Any) -> None:
        from cyclonedds.builtin import (
            BuiltinDataReader,
            BuiltinTopicDcpsPublication,
            BuiltinTopicDcpsSubscription,
        )
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState

        alive = SampleState.Any | ViewState.Any | InstanceState.Alive
        self._readers = {}
        self._conditions = []
        for kind, topic in (("publisher", BuiltinTopicDcpsPublication),
                            ("subscription", BuiltinTopicDcpsSubscription)):
            reader = BuiltinDataReader(participant, topic)
            condition = ReadCondition(reader, alive)
            self._readers[kind] = (reader, condition)
            self._conditions.append(condition)

    def _endpoints(self, kind: str) -> list[tuple[str, TopicEndpointInfo]]:
        reader, condition = self._readers[kind]
        out = []
        for sample in _read_off_main_thread(reader, condition):
            topic, ros_type = sample.topic_name, ros_type_name(sample.type_name)
            if not topic.startswith("rt/") or ros_type is None:
                continue
            out.append((topic[2:], TopicEndpointInfo(ros_type, sample.key.bytes,
                                                     _profile(sample.qos))))
        return out

    def topics(self) -> list[tuple[str, list[str]]]:
        """``[(name, [type, ...]), ...]`` sorted by name, as rclpy's
        ``Node.get_topic_names_and_types``."""
        found: dict[str, set[str]] = {}
        for kind in self._readers:
            for name, info in self._endpoints(kind):
                found.setdefault(name, set()).add(info.topic_type)
        return [(name, sorted(kinds)) for name, kinds in sorted(found.items())]

    def publishers(self, topic: str) -> list[TopicEndpointInfo]:
        """The writers of ``topic`` (a fully qualified name), as rclpy's
        ``Node.get_publishers_info_by_topic``."""
        return [info for name, info in self._endpoints("publisher") if name == topic]

    def delete(self) -> None:
        delete_dds(*self._conditions, *(reader for reader, _ in self._readers.values()))
