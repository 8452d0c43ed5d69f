"""Message and service types of ``biped_opt_interfaces`` generated at run time.

The ``.msg``/``.srv``/``.action`` files of the ``msg_defs/`` interface package are the single
source of truth. :mod:`biped_opt.interface_defs` parses them into a rosbags typestore; this module
turns every definition of it into a Cyclone DDS ``IdlStruct`` dataclass whose
DDS type name follows rmw_cyclonedds (``pkg::msg::dds_::Name_``). The classes double as the Python
message classes of the built-in backend: keyword constructors, ROS field names, constants as class
attributes (``ContactMode.AIR``).

Wire details (ROS.md Sec. 2): ``uint8``/``byte``/``char`` fields are declared as
``cyclonedds.idl.types.byte`` (same octets on the wire, but no XTypes type object that crashes
Cyclone 0.10 peers); service requests and replies travel in a wrapper struct whose first member is
the 16-byte ``{uint64 guid; int64 seq}`` header of rmw_cyclonedds.
"""

from __future__ import annotations

import dataclasses
import threading
import types
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cyclonedds.idl import IdlMeta, IdlStruct
from cyclonedds.idl import types as dt

from biped_opt.interface_defs import (
    PACKAGE,
    Definitions,
    InterfaceError,
    action_to_idl,
    find_msg_defs,
    load_definitions,
    srv_to_idl,
)

__all__ = [
    "PACKAGE",
    "InterfaceError",
    "Interfaces",
    "ServiceType",
    "ActionType",
    "RequestHeader",
    "find_msg_defs",
    "srv_to_idl",
    "action_to_idl",
    "load_interfaces",
    "dds_type_name",
]

# ---------------------------------------------------------------------------------------------
# rosbags definitions -> Cyclone IdlStructs
# ---------------------------------------------------------------------------------------------

_DDS_BASE: dict[str, Any] = {
    "bool": bool, "byte": dt.byte, "char": dt.byte, "octet": dt.byte, "uint8": dt.byte,
    "int8": dt.int8, "int16": dt.int16, "uint16": dt.uint16, "int32": dt.int32,
    "uint32": dt.uint32, "int64": dt.int64, "uint64": dt.uint64, "float32": dt.float32,
    "float64": dt.float64,
}


def dds_type_name(ros_name: str) -> str:
    """rmw_cyclonedds type name: ``pkg/msg/Name`` -> ``pkg::msg::dds_::Name_``."""
    pkg, kind, name = ros_name.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def _make_request_header() -> type:
    # Built like the generated types: this module's string annotations (PEP 563) would not
    # resolve inside cyclonedds.
    namespace = IdlMeta.__prepare__(
        "RequestHeader", (IdlStruct,), typename="rmw_cyclonedds::dds_::RequestHeader_"
    )
    namespace["__annotations__"].update({"guid": dt.uint64, "seq": dt.int64})
    namespace.update({"guid": 0, "seq": 0, "__module__": __name__})
    namespace["__doc__"] = "The 16 bytes rmw_cyclonedds puts before every request and reply."
    cls = IdlMeta(
        "RequestHeader", (IdlStruct,), namespace, typename="rmw_cyclonedds::dds_::RequestHeader_"
    )
    return dataclass(cls)


#: ``struct {uint64 guid; int64 seq;}`` preceding service requests and replies (ROS.md Sec. 2).
RequestHeader: Any = _make_request_header()


def _array_factory(element_default: Any, size: int) -> Any:
    """Default factory of a fixed-size array field: ``size`` fresh element defaults."""
    if isinstance(element_default, dataclasses.Field):
        factory = element_default.default_factory

        def make() -> list[Any]:
            return [factory() for _ in range(size)]  # type: ignore[misc]
    else:

        def make() -> list[Any]:
            return [element_default] * size

    return make


@dataclass(frozen=True)
class ServiceType:
    """A service type of the built-in backend, shaped like an rclpy service class.

    ``Request``/``Response`` are the user-facing message classes; ``RequestWire``/``ResponseWire``
    the DDS types (``header`` + ``body``) with rmw_cyclonedds' names.
    """

    name: str
    Request: type
    Response: type
    RequestWire: type
    ResponseWire: type

    def __repr__(self) -> str:
        return f"<service type {self.name}>"


@dataclass(frozen=True)
class ActionType:
    """An action type of the built-in backend, shaped like an rclpy action class: ``Goal``,
    ``Result``, ``Feedback`` and ``Impl`` with the services and messages on the wire
    (``SendGoalService``, ``GetResultService``, ``CancelGoalService``, ``FeedbackMessage``,
    ``GoalStatusMessage``)."""

    name: str
    Goal: type
    Result: type
    Feedback: type
    Impl: Any

    def __repr__(self) -> str:
        return f"<action type {self.name}>"


def _checked_setattr(self: Any, name: str, value: Any) -> None:
    """Reject unknown fields, as rclpy's ``__slots__`` messages do (no silent data loss)."""
    if name not in self.__dataclass_fields__ and name != "sample_info":
        raise AttributeError(
            f"{type(self).__name__} has no field {name!r} "
            f"(fields: {', '.join(self.__dataclass_fields__)})")
    object.__setattr__(self, name, value)


class Interfaces:
    """All generated types: ``msg`` classes by ROS name and service types.

    Use :func:`load_interfaces`; it caches one instance per process so that every DDS type
    is created once.
    """

    def __init__(self, definitions: Definitions) -> None:
        #: the parsed definitions the classes are made from (their typestore, names, defaults)
        self.definitions = definitions
        self.typestore = definitions.typestore
        self.msg_names = definitions.msg_names
        self._classes: dict[str, type] = {}
        self.services: dict[str, ServiceType] = {}
        self.actions: dict[str, ActionType] = {}
        for ros_name in self.msg_names:
            self.message_class(ros_name)
        for ros_name in definitions.srv_names:
            self._service(ros_name)
        for ros_name in definitions.action_names:
            self._action(ros_name)

    def message_class(self, ros_name: str) -> type:
        """IdlStruct class of the ROS type ``pkg/msg/Name`` (generated on first use)."""
        cls = self._classes.get(ros_name)
        if cls is not None:
            return cls
        if ros_name not in self.typestore.fielddefs:
            raise InterfaceError(f"unknown message type {ros_name!r}")
        consts, fields = self.typestore.fielddefs[ros_name]
        annotations: dict[str, Any] = {}
        defaults: dict[str, Any] = {}
        given = self.definitions.field_defaults.get(ros_name, {})
        for fname, desc in fields:
            annotations[fname], defaults[fname] = self._field(desc)
            if fname in given:
                defaults[fname] = given[fname]
        pkg, kind, short = ros_name.split("/")
        if kind == "msg" or short.endswith("_FeedbackMessage"):  # (a topic's type)
            typename = f"{pkg}::{kind}::dds_::{short}_"
        else:
            # User-facing service halves; the wire type with rmw's name is the wrapper.
            typename = f"{pkg}::{kind}::{short}"
        namespace = IdlMeta.__prepare__(short, (IdlStruct,), typename=typename)
        namespace["__annotations__"].update(annotations)
        namespace.update(defaults)
        namespace["__module__"] = f"{pkg}.{kind}"
        namespace["__qualname__"] = short
        namespace["_ros_type"] = ros_name
        namespace["__setattr__"] = _checked_setattr
        cls = IdlMeta(short, (IdlStruct,), namespace, typename=typename)
        cls = dataclass(cls)
        for cname, _ctype, value in consts:
            setattr(cls, cname, value)
        self._classes[ros_name] = cls
        return cls

    def _field(self, desc: tuple[Any, Any]) -> tuple[Any, Any]:
        """(annotation, dataclass default) of one rosbags field description."""
        kind, args = desc
        kind = int(kind)
        if kind == 1:  # BASE
            base, bound = args
            if base == "string":
                return (dt.bounded_str[bound] if bound else str), ""
            if base not in _DDS_BASE:
                raise InterfaceError(f"unsupported base type {base!r}")
            ann = _DDS_BASE[base]
            return ann, (False if ann is bool else 0.0 if base.startswith("float") else 0)
        if kind == 2:  # NAME
            cls = self.message_class(args)
            return cls, dataclasses.field(default_factory=cls)
        if kind in (3, 4):  # ARRAY, SEQUENCE
            sub, size = args
            sub_ann, sub_default = self._field(sub)
            if kind == 3:
                return dt.array[sub_ann, size], dataclasses.field(
                    default_factory=_array_factory(sub_default, size))
            ann = dt.sequence[sub_ann, size] if size else dt.sequence[sub_ann]
            return ann, dataclasses.field(default_factory=list)
        raise InterfaceError(f"unsupported field description {desc!r}")

    def _service(self, ros_name: str) -> ServiceType:
        pkg, kind, short = ros_name.split("/")
        req = self.message_class(f"{ros_name}_Request")
        rsp = self.message_class(f"{ros_name}_Response")
        wires = []
        for half, cls in (("Request", req), ("Response", rsp)):
            typename = f"{pkg}::{kind}::dds_::{short}_{half}_"
            namespace = IdlMeta.__prepare__(f"{short}_{half}_", (IdlStruct,), typename=typename)
            namespace["__annotations__"].update({"header": RequestHeader, "body": cls})
            namespace["header"] = dataclasses.field(default_factory=RequestHeader)
            namespace["body"] = dataclasses.field(default_factory=cls)
            wire = IdlMeta(f"{short}_{half}_", (IdlStruct,), namespace, typename=typename)
            wires.append(dataclass(wire))
        svc = ServiceType(ros_name, req, rsp, wires[0], wires[1])
        self.services[ros_name] = svc
        return svc

    def _action(self, ros_name: str) -> ActionType:
        impl = types.SimpleNamespace(
            SendGoalService=self._service(f"{ros_name}_SendGoal"),
            GetResultService=self._service(f"{ros_name}_GetResult"),
            CancelGoalService=self.services.get("action_msgs/srv/CancelGoal")
            or self._service("action_msgs/srv/CancelGoal"),
            FeedbackMessage=self.message_class(f"{ros_name}_FeedbackMessage"),
            GoalStatusMessage=self.message_class("action_msgs/msg/GoalStatusArray"))
        action = ActionType(ros_name, self.message_class(f"{ros_name}_Goal"),
                            self.message_class(f"{ros_name}_Result"),
                            self.message_class(f"{ros_name}_Feedback"), impl)
        self.actions[ros_name] = action
        return action


_LOCK = threading.Lock()
_CACHE: dict[int, Interfaces] = {}


def load_interfaces(root: Path | None = None) -> Interfaces:
    """The classes of the definitions :func:`~biped_opt.interface_defs.load_definitions` gives
    for ``root``, made once per process (every DDS type is created once)."""
    definitions = load_definitions(root)
    with _LOCK:  # (keyed by the definitions, which load_definitions keeps: one per root)
        if id(definitions) not in _CACHE:
            _CACHE[id(definitions)] = Interfaces(definitions)
        return _CACHE[id(definitions)]
