"""The interface package's definitions (``msg_defs/``) parsed into a rosbags typestore.

The ``.msg``, ``.srv`` and ``.action`` files of ``biped_opt_interfaces`` (and the standard
packages vendored beside them, ``msg_defs/vendor/<package>/``) are the single source of truth of
every message. :func:`load_definitions` parses them with rosbags (``.msg`` directly, ``.srv`` and
``.action`` after conversion to IDL, as rosidl derives their structs) and registers them in a
rosbags Humble typestore, which also supplies ``std_msgs``, ``builtin_interfaces`` and
``action_msgs``. The recordings' writer and reader encode and decode CDR with that typestore
(:mod:`biped_opt.record`), and the built-in ROS backend generates its DDS types from it
(:mod:`biped_opt.ros.interfaces`); reading a recording does not bring up a ROS backend.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import sys
import sysconfig
import threading
from pathlib import Path
from typing import Any

from biped_opt.errors import BipedOptError

__all__ = ["PACKAGE", "Definitions", "FieldDefaults", "InterfaceError", "action_to_idl",
           "find_msg_defs", "load_definitions", "srv_to_idl"]

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
    found.append(here.parents[1] / "msg_defs")
    # Installed copy (setup.py data_files -> <prefix>/share/biped_opt/msg_defs).
    for prefix in (sysconfig.get_path("data"), sys.prefix, sys.base_prefix):
        found.append(Path(prefix) / "share" / "biped_opt" / "msg_defs")
    # colcon install: <prefix>/lib/pythonX.Y/site-packages/biped_opt/interface_defs.py
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


class Definitions:
    """Every definition of ``root`` registered in one typestore (use :func:`load_definitions`,
    which parses each root once per process): ``typestore``, the names of the package's
    messages, services and actions, and scalar fields' default values.

    Parsing the files with rosbags takes 0.06 s, a tenth of a cached ``report``; what it yields
    is kept in the cache (:func:`parsed_cache`) under a key of the files' contents, the rosbags
    version and :data:`PARSED_FORMAT`, so a later process reads it back instead (any change to a
    file, or another rosbags, parses again)."""

    def __init__(self, root: Path) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.root = root
        self.typestore = get_typestore(Stores.ROS2_HUMBLE)
        files = _definition_files(root)
        cache = parsed_cache() / f"{_parsed_key(files)}.json"
        parsed = _read_parsed(cache)
        if parsed is None:
            parsed = _parse(files)
            _write_parsed(cache, parsed)
        #: scalar fields' default values (``uint64 steps 1``), by ROS type name
        self.field_defaults: dict[str, dict[str, Any]] = parsed["field_defaults"]
        self.msg_names: list[str] = parsed["msg_names"]
        self.srv_names: list[str] = parsed["srv_names"]
        self.action_names: list[str] = parsed["action_names"]
        self.typestore.register(parsed["types"])


#: (package, kind, path) of every definition, in the order they are parsed
_Files = list[tuple[str, str, Path]]
#: the layout of a parsed cache file; a new layout makes old files unread
PARSED_FORMAT = 1


def _definition_files(root: Path) -> _Files:
    """The project's package, then the standard ones vendored beside it (vendor/<package>/)."""
    folders = [(PACKAGE, root)]
    vendor = root / "vendor"
    if vendor.is_dir():
        folders += [(p.name, p) for p in sorted(vendor.iterdir()) if (p / "msg").is_dir()]
    return [(pkg, kind, path) for pkg, folder in folders for kind in ("msg", "srv", "action")
            for path in sorted((folder / kind).glob(f"*.{kind}"))]


def _parse(files: _Files) -> dict[str, Any]:
    """The rosbags types of ``files`` (``.srv`` and ``.action`` through IDL), their names and
    fields' default values."""
    from rosbags.typesys import get_types_from_idl, get_types_from_msg

    types: dict[str, Any] = {}
    out: dict[str, Any] = {"types": types, "field_defaults": {}, "msg_names": [],
                           "srv_names": [], "action_names": []}
    converters = {"srv": srv_to_idl, "action": action_to_idl}
    cancel_goal = False
    for pkg, kind, path in files:
        ros_name = f"{pkg}/{kind}/{path.stem}"
        if kind == "msg":
            try:
                types.update(get_types_from_msg(path.read_text(), ros_name))
            except Exception as exc:  # rosbags raises its own error types
                raise InterfaceError(f"{path.name}: {exc}") from exc
            out["msg_names"].append(ros_name)
            continue
        if kind == "action" and not cancel_goal:
            types.update(get_types_from_idl(srv_to_idl(CANCEL_GOAL_SRV, "action_msgs",
                                                       "CancelGoal")))
            cancel_goal = True
        found: FieldDefaults = {}
        try:
            types.update(get_types_from_idl(converters[kind](path.read_text(), pkg, path.stem,
                                                             found)))
        except InterfaceError:
            raise
        except Exception as exc:
            raise InterfaceError(f"{path.name}: {exc}") from exc
        for struct, values in found.items():
            out["field_defaults"][f"{pkg}/{kind}/{struct}"] = values
        out[f"{kind}_names"].append(ros_name)
    return out


def parsed_cache() -> Path:
    """Where parsed definitions are kept: ``interfaces/`` beside the compiled systems."""
    from biped_opt.simulation.compiled import cache_dir

    return cache_dir().parent / "interfaces"


def _parsed_key(files: _Files) -> str:
    from importlib.metadata import version

    digest = hashlib.sha256(f"{PARSED_FORMAT} rosbags {version('rosbags')}".encode())
    for pkg, kind, path in files:
        text = path.read_bytes()
        digest.update(f"\0{pkg}/{kind}/{path.name} {len(text)}\0".encode())
        digest.update(text)
    return digest.hexdigest()[:32]


def _to_json(value: Any) -> Any:
    """rosbags' parse (tuples, lists, dicts, strings, numbers and its Nodetype) as JSON data:
    a tuple as {"t": [...]}, a Nodetype as {"n": value}; lists stay lists."""
    from rosbags.interfaces import Nodetype

    if isinstance(value, Nodetype):
        return {"n": int(value)}
    if isinstance(value, tuple):
        return {"t": [_to_json(v) for v in value]}
    if isinstance(value, list):
        return [_to_json(v) for v in value]
    if isinstance(value, dict):
        return {k: _to_json(v) for k, v in value.items()}
    if value is None or isinstance(value, (str, int, float)):
        return value
    raise TypeError(f"cannot keep a {type(value).__name__} of a parsed definition")


def _from_json(value: Any) -> Any:
    from rosbags.interfaces import Nodetype

    if isinstance(value, list):
        return [_from_json(v) for v in value]
    if isinstance(value, dict):
        if set(value) == {"n"}:
            return Nodetype(value["n"])
        if set(value) == {"t"}:
            return tuple(_from_json(v) for v in value["t"])
        return {k: _from_json(v) for k, v in value.items()}
    return value


def _read_parsed(path: Path) -> dict[str, Any] | None:
    """The parse kept at ``path``; None when there is none or it is not whole (then parsed
    again and written anew)."""
    try:
        data = json.loads(path.read_text())
        parsed = {"types": _from_json(data["types"]),
                  "field_defaults": data["field_defaults"]}
        for key in ("msg_names", "srv_names", "action_names"):
            parsed[key] = [str(name) for name in data[key]]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return parsed


def _write_parsed(path: Path, parsed: dict[str, Any]) -> None:
    """Keep a parse for later processes, written whole then renamed; a cache that cannot be
    written only costs the next process the parse."""
    from biped_opt.simulation.compiled import write_whole

    try:
        text = json.dumps({**parsed, "types": _to_json(parsed["types"])})
        path.parent.mkdir(parents=True, exist_ok=True)
        write_whole(path, text)
    except (OSError, TypeError, ValueError):
        pass


_LOCK = threading.Lock()
_CACHE: dict[Path, Definitions] = {}


def load_definitions(root: Path | None = None) -> Definitions:
    """Parse ``msg_defs`` (found by :func:`find_msg_defs` when ``root`` is None), cached."""
    root = (root or find_msg_defs()).resolve()
    with _LOCK:
        if root not in _CACHE:
            _CACHE[root] = Definitions(root)
        return _CACHE[root]
