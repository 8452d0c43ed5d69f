"""``rclpy.node.Node`` on Cyclone DDS with rmw_cyclonedds' wire conventions (ROS.md Sec. 2).

Publishers and subscriptions use ``rt/<name>`` (:mod:`.entities`); services and clients
``rq/<name>Request`` and ``rr/<name>Reply`` (:mod:`.services`). A node also holds its
parameters (``--ros-args -p``, parameter files, overrides), its logger (:mod:`.log`) and clock,
and destroys every DDS entity it created, explicitly and in order, in :meth:`Node.destroy_node`.
"""

from __future__ import annotations

import ast
import re
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from cyclonedds.topic import Topic

from biped_opt.errors import BipedOptError, quoted

from ..interfaces import ServiceType, load_interfaces
from ..params_file import load_parameters
from . import context as _ctx
from .entities import Entity, Publisher, Subscription, Timer
from .lifetime import delete_dds
from .log import Logger
from .qos import QoSProfile, ReliabilityPolicy, as_profile, qos_profile_services_default
from .services import Client, Service

__all__ = [
    "Node", "Clock", "Time", "Parameter", "ParameterNotDeclaredException",
    "InvalidParameterTypeException", "RosArgumentError", "parameter_type",
    "MutuallyExclusiveCallbackGroup", "ReentrantCallbackGroup", "parse_ros_args",
]


class ParameterNotDeclaredException(BipedOptError, LookupError):
    """``get_parameter`` of a name that was never declared."""


class InvalidParameterTypeException(BipedOptError, TypeError):
    """A parameter given a value of another type than its default's (rclpy's exception of the
    same name: a node's parameters are statically typed unless declared dynamic)."""


class RosArgumentError(BipedOptError, ValueError):
    """A ``--ros-args`` section rcl could not parse (rcl: "Couldn't parse ... rule")."""


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
    """``rclpy.clock.Clock`` subset: ``now()`` of the system clock, or of ``/clock`` while ROS
    time is active (a node's ``use_sim_time``: then 0 until the first message, as rclpy)."""

    def __init__(self) -> None:
        self._ros_ns: int | None = None

    @property
    def ros_time_is_active(self) -> bool:
        return self._ros_ns is not None

    def now(self) -> Time:
        ros_ns = self._ros_ns
        return Time(nanoseconds=time.time_ns() if ros_ns is None else ros_ns)

    def _set_ros_time(self, msg: Any) -> None:
        self._ros_ns = int(msg.clock.sec) * 1_000_000_000 + int(msg.clock.nanosec)


# -- parameters ------------------------------------------------------------------------------

class Parameter:
    """``rclpy.parameter.Parameter`` subset: ``Parameter(name, value=...)``, ``.value``."""

    class Type:
        NOT_SET = 0
        BOOL = 1
        INTEGER = 2
        DOUBLE = 3
        STRING = 4
        BYTE_ARRAY = 5
        BOOL_ARRAY = 6
        INTEGER_ARRAY = 7
        DOUBLE_ARRAY = 8
        STRING_ARRAY = 9

    #: rcl_interfaces' names of the types above
    TYPE_NAMES = ("NOT_SET", "BOOL", "INTEGER", "DOUBLE", "STRING", "BYTE_ARRAY", "BOOL_ARRAY",
                  "INTEGER_ARRAY", "DOUBLE_ARRAY", "STRING_ARRAY")

    def __init__(self, name: str, type_: Any = None, value: Any = None) -> None:
        # rclpy's signature is (name, type_=None, value=None); a non-int type_ is a value.
        if type_ is not None and not isinstance(type_, int) and value is None:
            type_, value = None, type_
        self.name = name
        self.value = value
        self.type_ = type_ if type_ is not None else parameter_type(value)

    def get_parameter_value(self) -> Any:
        return self.value

    def __repr__(self) -> str:
        return f"Parameter({self.name!r}, value={self.value!r})"


_SCALAR_TYPES = ((bool, Parameter.Type.BOOL), (int, Parameter.Type.INTEGER),
                 (float, Parameter.Type.DOUBLE), (str, Parameter.Type.STRING))


def parameter_type(value: Any) -> int:
    """The ``Parameter.Type`` of a Python value, as rclpy infers it; an empty list is NOT_SET
    (it fits any array type). A list mixing types has none."""
    if value is None:
        return Parameter.Type.NOT_SET
    if isinstance(value, (bytes, bytearray)):
        return Parameter.Type.BYTE_ARRAY
    if isinstance(value, (list, tuple)):
        if not value:
            return Parameter.Type.NOT_SET
        kinds = {parameter_type(v) for v in value}
        if len(kinds) != 1 or not kinds <= {1, 2, 3, 4}:
            raise InvalidParameterTypeException(
                f"an array parameter holds values of one type, got {quoted(value)}")
        return kinds.pop() + Parameter.Type.BOOL_ARRAY - Parameter.Type.BOOL
    for cls, kind in _SCALAR_TYPES:  # bool first: a bool is an int in Python
        if isinstance(value, cls):
            return kind
    raise InvalidParameterTypeException(f"{type(value).__name__} is not a parameter type")


def _type_name(kind: int) -> str:
    return Parameter.TYPE_NAMES[kind]


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
        elif inside and arg in ("-p", "--param", "--params-file") and i + 1 == len(items):
            raise RosArgumentError(f"--ros-args: {arg} expects an argument")
        elif inside and arg in ("-p", "--param"):
            rule = items[i + 1]
            name, sep, value = rule.partition(":=")
            if not sep or not name:
                raise RosArgumentError(
                    f"--ros-args: couldn't parse parameter override rule {arg} {quoted(rule)}"
                    " (expected name:=value)")
            params[name] = _parse_value(value)
            try:
                parameter_type(params[name])
            except InvalidParameterTypeException as exc:
                raise RosArgumentError(f"--ros-args: {arg} {quoted(rule)}: {exc}") from None
            i += 1
        elif inside and arg == "--params-file":
            if node_name is not None:
                params.update(load_parameters(items[i + 1], node_name))
            i += 1
        i += 1
    return params


# -- names -----------------------------------------------------------------------------------

_NAME_RE = re.compile(r"^(?:~/|[~/])?[A-Za-z_][\w]*(/[A-Za-z_][\w]*)*$")


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
        self._entities: list[Entity] = []
        self.default_callback_group = MutuallyExclusiveCallbackGroup()
        self._logger = Logger(node_name if self._namespace == "/"
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
        if "use_sim_time" not in self._parameters:
            self.declare_parameter("use_sim_time", False)
        if self.get_parameter("use_sim_time").value is True:
            # rclpy's time source: /clock, best effort, the latest message only
            self._clock._ros_ns = 0
            self.create_subscription(
                load_interfaces().message_class("rosgraph_msgs/msg/Clock"), "/clock",
                self._clock._set_ros_time,
                QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))

    # names
    def get_name(self) -> str:
        return self._name

    def get_namespace(self) -> str:
        return self._namespace

    def get_fully_qualified_name(self) -> str:
        return f"{self._namespace.rstrip('/')}/{self._name}"

    def get_logger(self) -> Logger:
        return self._logger

    def get_clock(self) -> Clock:
        return self._clock

    def get_topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every topic on the domain (with a publisher or a subscription) and its types, as
        rclpy's (from DDS discovery)."""
        return self.context.topic_directory().topics()

    def get_publishers_info_by_topic(self, topic_name: str) -> list[Any]:
        """The publishers of ``topic_name`` with their types and QoS, as rclpy's (from DDS
        discovery; :class:`.graph.TopicEndpointInfo`)."""
        return self.context.topic_directory().publishers(self._resolve(topic_name))

    def get_service_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every service on the domain and its types, as rclpy's (from DDS discovery)."""
        return self.context.service_names_and_types()

    # internals
    def _topic(self, dds_name: str, dds_type: type) -> Topic:
        key = (dds_name, dds_type.__name__)
        if key not in self._topics:
            self._topics[key] = Topic(self.context.participant, dds_name, dds_type)
        return self._topics[key]

    def _add(self, entity: Entity) -> Any:
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

    def _destroy_entity(self, entity: Entity) -> bool:
        if entity in self._entities:
            self._entities.remove(entity)
            entity.destroy()
            self.context.publish_graph()
            return True
        return False

    destroy_publisher = destroy_subscription = destroy_service = _destroy_entity
    destroy_client = destroy_timer = _destroy_entity

    def destroy_node(self) -> None:
        """Leave the graph, then delete every DDS entity of the node: readers and writers (with
        their read conditions), then the topics."""
        if self._destroyed:
            return
        self._destroyed = True
        entities, self._entities = self._entities, []
        self.context.remove_node(self)
        for entity in entities:
            entity.destroy()
        topics, self._topics = list(self._topics.values()), {}
        delete_dds(*topics)
        self.context.wake()

    # parameters
    def declare_parameter(self, name: str, value: Any = None, descriptor: Any = None,
                          ignore_override: bool = False) -> Parameter:
        if name in self._parameters:
            raise ValueError(f"parameter {name!r} has already been declared")
        expected = parameter_type(value)
        if not ignore_override and name in self._overrides:
            value = self._overrides[name]
        param = Parameter(name, value=value)
        # static typing as in rclpy: an override keeps its default's type (an empty list fits
        # any array type)
        if expected != Parameter.Type.NOT_SET and param.type_ not in (
                expected, *((Parameter.Type.NOT_SET,) if isinstance(value, list) else ())):
            raise InvalidParameterTypeException(
                f"Trying to set parameter {name!r} to {quoted(value)} of type "
                f"'{_type_name(param.type_)}', expecting type '{_type_name(expected)}'")
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
    def _waitables(self) -> list[Entity]:
        return list(self._entities)
