"""Message and service types of ``biped_opt_interfaces`` generated at run time.

The ``.msg``/``.srv`` files of the ``msg_defs/`` interface package are the single source of truth.
This module parses them with rosbags (``.msg`` directly, ``.srv`` halves after conversion to IDL),
registers them in a rosbags Humble typestore (which also supplies ``std_msgs`` and
``builtin_interfaces``) and turns every definition into a Cyclone DDS ``IdlStruct`` dataclass whose
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
import os
import re
import sys
import sysconfig
import threading
import types
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cyclonedds.idl import IdlMeta, IdlStruct
from cyclonedds.idl import types as dt

from biped_opt.errors import BipedOptError

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

PACKAGE = "biped_opt_interfaces"
_ENV_MSG_DEFS = "BIPED_OPT_MSG_DEFS"


class InterfaceError(BipedOptError, ValueError):
    """An interface definition cannot be found, parsed or converted."""


# ---------------------------------------------------------------------------------------------
# Locating msg_defs
# ---------------------------------------------------------------------------------------------

def _candidates() -> list[Path]:
    here = Path(__file__).resolve()
    found: list[Path] = []
    env = os.environ.get(_ENV_MSG_DEFS)
    if env:
        found.append(Path(env))
    # Source checkout or editable install: msg_defs/ sits next to the biped_opt package.
    found.append(here.parents[2] / "msg_defs")
    # Installed copy (setup.py data_files -> <prefix>/share/biped_opt/msg_defs).
    for prefix in (sysconfig.get_path("data"), sys.prefix, sys.base_prefix):
        found.append(Path(prefix) / "share" / "biped_opt" / "msg_defs")
    # colcon install: <prefix>/lib/pythonX.Y/site-packages/biped_opt/ros/interfaces.py
    for parent in here.parents:
        found.append(parent / "share" / "biped_opt" / "msg_defs")
    # A built biped_opt_interfaces package on the ament prefix path installs msg/ and srv/.
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            found.append(Path(prefix) / "share" / PACKAGE)
    return found


def find_msg_defs() -> Path:
    """Directory holding ``msg/*.msg`` and ``srv/*.srv`` of ``biped_opt_interfaces``.

    Searched in order: ``$BIPED_OPT_MSG_DEFS``, the source tree, ``share/biped_opt/msg_defs``
    of the installation prefix, and ``share/biped_opt_interfaces`` on ``AMENT_PREFIX_PATH``.
    """
    tried = _candidates()
    for path in tried:
        if (path / "msg").is_dir() and any((path / "msg").glob("*.msg")):
            return path
    raise InterfaceError(
        "cannot find the biped_opt_interfaces definitions (msg/*.msg); set "
        f"{_ENV_MSG_DEFS}; tried: " + ", ".join(str(p) for p in tried)
    )


# ---------------------------------------------------------------------------------------------
# .srv -> IDL
# ---------------------------------------------------------------------------------------------

_IDL_BASE = {
    "bool": "boolean", "byte": "octet", "char": "uint8", "float32": "float", "float64": "double",
    "int8": "int8", "uint8": "uint8", "int16": "int16", "uint16": "uint16", "int32": "int32",
    "uint32": "uint32", "int64": "int64", "uint64": "uint64", "string": "string",
    "wstring": "wstring",
}
_FIELD_RE = re.compile(
    r"^(?P<type>[A-Za-z][\w/]*(?:<=\d+)?)(?P<arr>\[(?:<=)?\d*\])?\s+(?P<name>[A-Za-z]\w*)"
    r"(?:\s*(?P<eq>=)?\s*(?P<value>.+))?$"
)


def _strip_comment(line: str) -> str:
    # '#' inside a quoted string constant is rare in ROS files; none of ours has one.
    return line.split("#", 1)[0].strip()


def _idl_type(rostype: str, pkg: str) -> str:
    bound = None
    if "<=" in rostype:
        rostype, bound_text = rostype.split("<=")
        bound = int(bound_text)
    if rostype in _IDL_BASE:
        idl = _IDL_BASE[rostype]
        return f"{idl}<{bound}>" if bound is not None else idl
    if bound is not None:
        raise InterfaceError(f"bound on non-string type {rostype!r}")
    if rostype == "Header":
        return "std_msgs::msg::Header"
    parts = rostype.split("/")
    if len(parts) == 1:
        return f"{pkg}::msg::{parts[0]}"
    if len(parts) == 2:
        return f"{parts[0]}::msg::{parts[1]}"
    return "::".join(parts)


#: a scalar field's default value in a definition (``uint64 steps 1``): the value rclpy's
#: constructor gives the field (the wire has no defaults), by type name, then field
FieldDefaults = dict[str, dict[str, Any]]


def _default_value(idl: str, text: str, where: str) -> Any:
    text = text.strip()
    try:
        if idl.startswith(("string", "wstring")):
            return text.strip("'\"")
        if idl == "boolean":
            return text.lower() in ("true", "1")
        if idl in ("float", "double"):
            return float(text)
        if idl in _IDL_BASE.values():
            return int(text, 0)
    except ValueError:
        pass
    raise InterfaceError(f"{where}: default value {text!r} of a {idl} field is not supported")


def _half_to_idl(text: str, pkg: str, struct: str,
                 defaults: FieldDefaults | None = None) -> str:
    consts: list[str] = []
    members: list[str] = []
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = _strip_comment(raw)
        if not line:
            continue
        match = _FIELD_RE.match(line)
        if match is None:
            raise InterfaceError(f"{struct}: cannot parse line {lineno}: {raw!r}")
        idl = _idl_type(match["type"], pkg)
        name, arr = match["name"], match["arr"]
        if match["eq"]:
            if arr:
                raise InterfaceError(f"{struct}: array constant {name!r} is not supported")
            value = match["value"].strip()
            if idl.startswith("string"):
                value = '"' + value.strip("'\"") + '"'
            elif idl == "boolean":
                value = "TRUE" if value.lower() in ("true", "1") else "FALSE"
            consts.append(f"const {idl} {name} = {value};")
            continue
        if match["value"]:
            # (IDL has no field defaults: kept aside for the message class; an array's or a
            # message's default is refused rather than silently dropped)
            if arr or defaults is None:
                raise InterfaceError(
                    f"{struct}: default value of field {name!r} is not supported")
            defaults.setdefault(struct, {})[name] = _default_value(
                idl, match["value"], f"{struct}.{name}")
        if not arr:
            members.append(f"{idl} {name};")
        elif arr == "[]":
            members.append(f"sequence<{idl}> {name};")
        elif arr.startswith("[<="):
            members.append(f"sequence<{idl}, {int(arr[3:-1])}> {name};")
        else:
            members.append(f"{idl} {name}[{int(arr[1:-1])}];")
    if not members:
        members.append("uint8 structure_needs_at_least_one_member;")
    out = []
    if consts:
        out.append(f"module {struct}_Constants {{ " + " ".join(consts) + " };")
    out.append(f"struct {struct} {{ " + " ".join(members) + " };")
    return " ".join(out)


def srv_to_idl(text: str, pkg: str, name: str, defaults: FieldDefaults | None = None) -> str:
    """IDL text for the ``Name_Request``/``Name_Response`` structs of a ``.srv`` definition
    (scalar fields' default values go to ``defaults``, when given, by struct name)."""
    halves = re.split(r"^\s*---\s*$", text, flags=re.MULTILINE)
    if len(halves) != 2:
        raise InterfaceError(f"{pkg}/srv/{name}: expected exactly one '---' separator")
    body = " ".join(
        _half_to_idl(half, pkg, f"{name}_{suffix}", defaults)
        for half, suffix in zip(halves, ("Request", "Response"))
    )
    return f"module {pkg} {{ module srv {{ {body} }}; }};\n"


#: ``action_msgs/srv/CancelGoal`` (rosbags' typestore has action_msgs' messages, not its service)
CANCEL_GOAL_SRV = """\
action_msgs/GoalInfo goal_info
---
int8 ERROR_NONE = 0
int8 ERROR_REJECTED = 1
int8 ERROR_UNKNOWN_GOAL_ID = 2
int8 ERROR_GOAL_TERMINATED = 3
int8 return_code
action_msgs/GoalInfo[] goals_canceling
"""


def action_to_idl(text: str, pkg: str, name: str, defaults: FieldDefaults | None = None
                  ) -> str:
    """IDL text for an ``.action`` definition: ``Name_Goal``, ``Name_Result``,
    ``Name_Feedback`` and the structs rosidl derives from them (``Name_SendGoal_Request`` /
    ``_Response``, ``Name_GetResult_Request`` / ``_Response``, ``Name_FeedbackMessage``)."""
    parts = re.split(r"^\s*---\s*$", text, flags=re.MULTILINE)
    if len(parts) != 3:
        raise InterfaceError(f"{pkg}/action/{name}: expected exactly two '---' separators")
    body = [_half_to_idl(part, pkg, f"{name}_{suffix}", defaults)
            for part, suffix in zip(parts, ("Goal", "Result", "Feedback"))]
    uuid, own = "unique_identifier_msgs::msg::UUID", f"{pkg}::action::{name}"
    body += [
        f"struct {name}_SendGoal_Request {{ {uuid} goal_id; {own}_Goal goal; }};",
        f"struct {name}_SendGoal_Response {{ boolean accepted; "
        "builtin_interfaces::msg::Time stamp; };",
        f"struct {name}_GetResult_Request {{ {uuid} goal_id; }};",
        f"struct {name}_GetResult_Response {{ int8 status; {own}_Result result; }};",
        f"struct {name}_FeedbackMessage {{ {uuid} goal_id; {own}_Feedback feedback; }};",
    ]
    return f"module {pkg} {{ module action {{ {' '.join(body)} }}; }};\n"


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

    def __init__(self, root: Path) -> None:
        from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

        self.root = root
        self.typestore = get_typestore(Stores.ROS2_HUMBLE)
        defs: dict[str, Any] = {}
        #: scalar fields' default values (``uint64 steps 1``), by ROS type name
        self.field_defaults: dict[str, dict[str, Any]] = {}
        self.msg_names: list[str] = []
        self.srv_names: list[str] = []
        self.action_names: list[str] = []
        # the project's package, then the standard ones vendored beside it (vendor/<package>/)
        folders = [(PACKAGE, root)]
        vendor = root / "vendor"
        if vendor.is_dir():
            folders += [(p.name, p) for p in sorted(vendor.iterdir()) if (p / "msg").is_dir()]
        cancel_goal = False
        for pkg, folder in folders:
            for path in sorted((folder / "msg").glob("*.msg")):
                ros_name = f"{pkg}/msg/{path.stem}"
                try:
                    defs.update(get_types_from_msg(path.read_text(), ros_name))
                except Exception as exc:  # rosbags raises its own error types
                    raise InterfaceError(f"{path.name}: {exc}") from exc
                self.msg_names.append(ros_name)
            for kind, suffix, convert in (("srv", "srv", srv_to_idl),
                                          ("action", "action", action_to_idl)):
                paths = sorted((folder / kind).glob(f"*.{suffix}"))
                if kind == "action" and paths and not cancel_goal:
                    defs.update(get_types_from_idl(srv_to_idl(CANCEL_GOAL_SRV, "action_msgs",
                                                              "CancelGoal")))
                    cancel_goal = True
                for path in paths:
                    found: FieldDefaults = {}
                    try:
                        defs.update(get_types_from_idl(convert(path.read_text(), pkg, path.stem,
                                                               found)))
                    except InterfaceError:
                        raise
                    except Exception as exc:
                        raise InterfaceError(f"{path.name}: {exc}") from exc
                    for struct, values in found.items():
                        self.field_defaults[f"{pkg}/{kind}/{struct}"] = values
                    (self.srv_names if kind == "srv" else self.action_names).append(
                        f"{pkg}/{kind}/{path.stem}")
        self.typestore.register(defs)
        self._classes: dict[str, type] = {}
        self.services: dict[str, ServiceType] = {}
        self.actions: dict[str, ActionType] = {}
        for ros_name in self.msg_names:
            self.message_class(ros_name)
        for ros_name in self.srv_names:
            self._service(ros_name)
        for ros_name in self.action_names:
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
        given = self.field_defaults.get(ros_name, {})
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
_CACHE: dict[Path, Interfaces] = {}


def load_interfaces(root: Path | None = None) -> Interfaces:
    """Parse ``msg_defs`` (found by :func:`find_msg_defs` when ``root`` is None), cached."""
    root = (root or find_msg_defs()).resolve()
    with _LOCK:
        if root not in _CACHE:
            _CACHE[root] = Interfaces(root)
        return _CACHE[root]
