"""A robot's URDF as a system description (SYSTEMS.md Sec. 4a).

Two steps, each one function:

- :func:`parse_urdf` reads URDF text into a small typed model (:class:`Robot`: links with
  their inertia and shapes, joints with their type, origin, axis, limits, dynamics and mimic)
  with the standard library's XML parser, after bounding the text's size and its number of
  elements and refusing document type declarations (no entity is ever expanded: a
  "billion laughs" text is refused before parsing). Nothing else is opened: a mesh is kept as
  its file name, a string for display. A text that a network peer sent is safe to parse.
- :func:`system_from_urdf` turns a robot into a :class:`~biped_opt.systems.description.System`
  of rigid bodies (SYSTEMS.md Sec. 1a): a floating base (six coordinates, ``base_x``,
  ``base_y``, ``base_z`` and ``base_roll``, ``base_pitch``, ``base_yaw`` with
  R = Rz(yaw) Ry(pitch) Rx(roll)) or a fixed one; one coordinate per revolute, continuous or
  prismatic joint, named after it; fixed joints (and joints locked by an option) merge their
  child's mass and inertia into the parent's body, the child's frame kept for contacts and
  display; a mimic joint moves its body with the joint it follows (q = multiplier q_leader +
  offset). Joint damping is an applied force; the inputs are the joints' efforts; a PD hold of
  the posture (parameters ``kp``, ``kd``) is available. Contacts with the ground z = 0
  (frictionless, restitution ``gamma``): a named link's frame origin, the lowest point of a
  collision sphere, the four bottom corners of a collision box.

The tree algorithms are not here: ``derive`` and the generated code
(``biped_opt.codegen.tree.BodyTree``) make M and the forces from the bodies, as they do for any
description of bodies.
"""

from __future__ import annotations

import fnmatch
import keyword
import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np
import numpy.typing as npt
import sympy as sp

from biped_opt.errors import quoted
from biped_opt.systems.description import IMPORTERS, System, SystemDescriptionError
from biped_opt.systems.rotations import rotation_rpy, rotation_x, rotation_y, rotation_z

__all__ = ["Robot", "Link", "Joint", "Inertial", "Shape", "Geometry", "Pose", "Limit", "Mimic",
           "Imported", "UrdfError", "parse_urdf", "read_urdf", "system_from_urdf",
           "description_urdf", "base_link", "tree_facts", "MAX_BYTES", "MAX_ELEMENTS", "BASE",
           "OPTIONS"]

#: the largest URDF text read (bytes): a humanoid's is ~110 kB
MAX_BYTES = 4_000_000
#: the most elements a URDF may have (counted as its '<' before parsing)
MAX_ELEMENTS = 100_000
#: the most links (and so joints) a robot may have
MAX_LINKS = 1000
#: the floating base's coordinates: position of the root link's frame, then its fixed-axis
#: roll, pitch and yaw (URDF's rpy)
BASE = ("base_x", "base_y", "base_z", "base_roll", "base_pitch", "base_yaw")
#: the options a file argument may give (``robot.urdf:base=fixed,contacts=a+b``)
OPTIONS = ("base", "contacts", "lock", "massless", "friction", "name")
#: joint types
MOVING = ("revolute", "continuous", "prismatic")
JOINT_TYPES = (*MOVING, "fixed", "floating", "planar")

Array = npt.NDArray[np.float64]


class UrdfError(SystemDescriptionError):
    """A URDF cannot be read or imported; the message names the file (or text), the element
    and what is wrong."""


# -- the model -------------------------------------------------------------------------------

@dataclass(frozen=True)
class Pose:
    """A frame's origin and fixed-axis roll, pitch, yaw in its parent's (URDF ``<origin>``)."""

    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def rotation(self) -> Array:
        return _rpy_matrix(*self.rpy)


@dataclass(frozen=True)
class Inertial:
    """Mass, centre of mass frame and inertia (ixx, ixy, ixz, iyy, iyz, izz) about the centre in
    that frame's axes."""

    mass: float
    origin: Pose
    inertia: tuple[float, float, float, float, float, float]

    def tensor(self) -> Array:
        xx, xy, xz, yy, yz, zz = self.inertia
        return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


@dataclass(frozen=True)
class Geometry:
    """``box`` (size: x, y, z edges), ``sphere`` (radius), ``cylinder`` (radius, length) or
    ``mesh`` (scale x, y, z; ``filename`` kept as written, never opened)."""

    kind: str
    size: tuple[float, ...]
    filename: str = ""


@dataclass(frozen=True)
class Shape:
    """A ``<visual>`` or ``<collision>`` of a link."""

    name: str
    origin: Pose
    geometry: Geometry


@dataclass(frozen=True)
class Link:
    name: str
    inertial: Inertial | None
    visuals: tuple[Shape, ...] = ()
    collisions: tuple[Shape, ...] = ()

    @property
    def mass(self) -> float:
        return 0.0 if self.inertial is None else self.inertial.mass


@dataclass(frozen=True)
class Limit:
    """Joint limits (None where the URDF gives none)."""

    lower: float | None = None
    upper: float | None = None
    effort: float | None = None
    velocity: float | None = None


@dataclass(frozen=True)
class Mimic:
    """q = multiplier q_joint + offset."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class Joint:
    name: str
    kind: str
    parent: str
    child: str
    origin: Pose
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    limit: Limit = field(default_factory=Limit)
    damping: float = 0.0
    friction: float = 0.0
    mimic: Mimic | None = None


@dataclass(frozen=True)
class Robot:
    """A parsed URDF: its links and joints in the file's order, and the root link."""

    name: str
    links: tuple[Link, ...]
    joints: tuple[Joint, ...]
    root: str
    source: str = "<urdf text>"

    def link(self, name: str) -> Link:
        return {lk.name: lk for lk in self.links}[name]

    def joint(self, name: str) -> Joint:
        return {j.name: j for j in self.joints}[name]


@dataclass(frozen=True)
class Imported:
    """What the importer made of a robot, kept on the system (``System.robot``) for the tools
    that publish it again (joint states, a robot description): the parsed robot, the base,
    each joint's coordinate (moving joints), its leader (mimic joints: (leader, multiplier,
    offset)) or its locked value, each link's body (the moving link it is merged into; None:
    the fixed world) and pose in that body's frame, and each constraint's link."""

    robot: Robot
    base: str
    coordinates: Mapping[str, str]
    mimic: Mapping[str, tuple[str, float, float]]
    locked: Mapping[str, float]
    bodies: Mapping[str, str | None]
    frames: Mapping[str, tuple[tuple[float, ...], tuple[tuple[float, ...], ...]]]
    contacts: Mapping[str, str]
    posture: Mapping[str, float]
    inputs: Mapping[str, str]


# -- parsing ---------------------------------------------------------------------------------

_DECLARATION = re.compile(r"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)


def read_urdf(path: str | Path) -> Robot:
    """Parse the URDF file ``path`` (at most :data:`MAX_BYTES`; nothing else is opened)."""
    path = Path(path)
    try:
        with path.open("rb") as handle:
            data = handle.read(MAX_BYTES + 1)
    except OSError as exc:
        raise UrdfError(f"{path}: cannot read the URDF ({exc.strerror or exc})") from None
    return parse_urdf(data, source=str(path))


def parse_urdf(text: str | bytes, *, source: str = "<urdf text>") -> Robot:
    """Parse URDF text (str, or UTF-8 bytes) into a :class:`Robot`, checking it: a size and
    element bound, no document type declaration or entity, known joint types, links and
    joints named once, one tree with one root, finite numbers, masses >= 0, sizes > 0."""
    if isinstance(text, bytes):
        if len(text) > MAX_BYTES:
            raise UrdfError(f"{source}: longer than {MAX_BYTES} bytes")
        try:
            text = text.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise UrdfError(f"{source}: not UTF-8 text ({exc.reason} at byte "
                            f"{exc.start})") from None
    if not isinstance(text, str):
        raise UrdfError(f"{source}: a URDF is text, got {type(text).__name__}")
    if len(text) > MAX_BYTES:
        raise UrdfError(f"{source}: longer than {MAX_BYTES} characters")
    if _DECLARATION.search(text):
        raise UrdfError(f"{source}: has a document type declaration or an entity (<!DOCTYPE, "
                        "<!ENTITY): refused, a URDF needs neither")
    if text.count("<") > MAX_ELEMENTS:
        raise UrdfError(f"{source}: more than {MAX_ELEMENTS} elements")
    text = re.sub(r"^\s*<\?xml[^>]*\?>", "", text)  # (the declaration may name an encoding)
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise UrdfError(f"{source}: not well-formed XML ({exc})") from None
    return _robot(root, source)


def _robot(root: ET.Element, source: str) -> Robot:
    if root.tag != "robot":
        raise UrdfError(f"{source}: the root element is <{root.tag}>, not <robot>")
    name = _text_attr(root, "name", source, "robot", default="robot")
    links = [_link(e, source) for e in root.findall("link")]
    joints = [_joint(e, source) for e in root.findall("joint")]
    if not links:
        raise UrdfError(f"{source}: has no <link>")
    if len(links) > MAX_LINKS or len(joints) > MAX_LINKS:
        raise UrdfError(f"{source}: more than {MAX_LINKS} links or joints")
    seen: set[str] = set()
    for link in links:
        if link.name in seen:
            raise UrdfError(f"{source}: link {quoted(link.name)} is given twice")
        seen.add(link.name)
    joint_names: set[str] = set()
    child_of: dict[str, str] = {}
    for joint in joints:
        where = f"{source}: joint {quoted(joint.name)}"
        if joint.name in joint_names:
            raise UrdfError(f"{where}: given twice")
        joint_names.add(joint.name)
        for role, link_name in (("parent", joint.parent), ("child", joint.child)):
            if link_name not in seen:
                raise UrdfError(f"{where}: {role} link {quoted(link_name)} is not a <link>")
        if joint.child in child_of:
            raise UrdfError(f"{where}: link {quoted(joint.child)} is already the child of "
                            f"joint {quoted(child_of[joint.child])}")
        child_of[joint.child] = joint.name
    roots = [lk.name for lk in links if lk.name not in child_of]
    if len(roots) != 1:
        raise UrdfError(f"{source}: the links must form one tree; roots (links no joint has "
                        f"as child): {', '.join(map(quoted, roots)) or 'none (a cycle)'}")
    # every link reachable from the root (no cycle hidden beside the tree)
    children: dict[str, list[str]] = {}
    for joint in joints:
        children.setdefault(joint.parent, []).append(joint.child)
    reached, stack = set(), [roots[0]]
    while stack:
        link_name = stack.pop()
        reached.add(link_name)
        stack += children.get(link_name, [])
    if len(reached) != len(links):
        missing = sorted(seen - reached)
        raise UrdfError(f"{source}: links not below the root {quoted(roots[0])} (a cycle): "
                        f"{', '.join(map(quoted, missing[:5]))}")
    by_name = {j.name: j for j in joints}
    for joint in joints:
        if joint.mimic is None:
            continue
        where = f"{source}: joint {quoted(joint.name)}: mimic"
        leader = by_name.get(joint.mimic.joint)
        if leader is None:
            raise UrdfError(f"{where}: no joint {quoted(joint.mimic.joint)}")
        steps, follow = 0, leader
        while follow.mimic is not None:
            steps += 1
            if follow.name == joint.name or steps > len(joints):
                raise UrdfError(f"{where}: the mimic joints form a cycle")
            follow = by_name[follow.mimic.joint]
    return Robot(name, tuple(links), tuple(joints), roots[0], source)


def _text_attr(e: ET.Element, key: str, source: str, what: str, default: str | None = None
               ) -> str:
    value = e.get(key, default)
    if value is None:
        raise UrdfError(f"{source}: {what}: missing attribute {key!r}")
    if len(value) > 4096:
        raise UrdfError(f"{source}: {what}: attribute {key!r} is longer than 4096 characters")
    return value


def _numbers(text: str | None, count: int, source: str, what: str,
             default: tuple[float, ...] | None = None) -> tuple[float, ...]:
    if text is None:
        if default is None:
            raise UrdfError(f"{source}: {what}: missing")
        return default
    parts = text.split()
    try:
        values = tuple(float(v) for v in parts)
    except ValueError:
        raise UrdfError(f"{source}: {what}: not {count} numbers: {quoted(text)}") from None
    if len(values) != count:
        raise UrdfError(f"{source}: {what}: needs {count} numbers, got {quoted(text)}")
    if not all(math.isfinite(v) for v in values):
        raise UrdfError(f"{source}: {what}: numbers must be finite, got {quoted(text)}")
    return values


def _number(e: ET.Element | None, key: str, source: str, what: str,
            default: float | None = None) -> float | None:
    if e is None or e.get(key) is None:
        return default
    return _numbers(e.get(key), 1, source, f"{what} {key}")[0]


def _pose(e: ET.Element | None, source: str, what: str) -> Pose:
    if e is None:
        return Pose()
    xyz = _numbers(e.get("xyz"), 3, source, f"{what} origin xyz", (0.0, 0.0, 0.0))
    rpy = _numbers(e.get("rpy"), 3, source, f"{what} origin rpy", (0.0, 0.0, 0.0))
    return Pose(xyz, rpy)  # type: ignore[arg-type]


def _link(e: ET.Element, source: str) -> Link:
    name = _text_attr(e, "name", source, "link")
    what = f"link {quoted(name)}"
    inertial = None
    block = e.find("inertial")
    if block is not None:
        mass = _number(block.find("mass"), "value", source, f"{what} inertial mass")
        if mass is None:
            raise UrdfError(f"{source}: {what}: inertial has no <mass value=...>")
        if mass < 0:
            raise UrdfError(f"{source}: {what}: mass must be >= 0, got {mass}")
        tensor = block.find("inertia")
        values = tuple(_number(tensor, k, source, f"{what} inertia", 0.0) or 0.0
                       for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"))
        inertial = Inertial(mass, _pose(block.find("origin"), source, f"{what} inertial"),
                            values)  # type: ignore[arg-type]
        if min(np.linalg.eigvalsh(inertial.tensor())) < -1e-12 * max(1.0, max(
                abs(v) for v in values)):
            raise UrdfError(f"{source}: {what}: inertia is not positive semidefinite")
    shapes = {kind: tuple(_shape(s, source, f"{what} {kind}") for s in e.findall(kind))
              for kind in ("visual", "collision")}
    return Link(name, inertial, shapes["visual"], shapes["collision"])


def _shape(e: ET.Element, source: str, what: str) -> Shape:
    geometry = e.find("geometry")
    if geometry is None or len(geometry) != 1:
        raise UrdfError(f"{source}: {what}: needs one <geometry> with one shape")
    g = geometry[0]
    if g.tag == "box":
        size = _numbers(g.get("size"), 3, source, f"{what} box size")
    elif g.tag == "sphere":
        size = (_number(g, "radius", source, f"{what} sphere") or 0.0,)
    elif g.tag == "cylinder":
        size = (_number(g, "radius", source, f"{what} cylinder") or 0.0,
                _number(g, "length", source, f"{what} cylinder") or 0.0)
    elif g.tag == "mesh":
        scale = _numbers(g.get("scale"), 3, source, f"{what} mesh scale", (1.0, 1.0, 1.0))
        filename = _text_attr(g, "filename", source, f"{what} mesh")
        return Shape(e.get("name", ""), _pose(e.find("origin"), source, what),
                     Geometry("mesh", scale, filename))
    else:
        raise UrdfError(f"{source}: {what}: unknown geometry <{g.tag}>")
    if not all(v > 0 for v in size):
        raise UrdfError(f"{source}: {what}: {g.tag} sizes must be > 0, got {size}")
    name = e.get("name", "") or ""
    return Shape(name[:200], _pose(e.find("origin"), source, what), Geometry(g.tag, size))


def _joint(e: ET.Element, source: str) -> Joint:
    name = _text_attr(e, "name", source, "joint")
    what = f"joint {quoted(name)}"
    kind = _text_attr(e, "type", source, what)
    if kind not in JOINT_TYPES:
        raise UrdfError(f"{source}: {what}: unknown type {quoted(kind)} (types: "
                        f"{', '.join(JOINT_TYPES)})")
    parent, child = e.find("parent"), e.find("child")
    if parent is None or child is None:
        raise UrdfError(f"{source}: {what}: needs <parent link=...> and <child link=...>")
    axis_element = e.find("axis")
    axis = _numbers(None if axis_element is None else axis_element.get("xyz"), 3, source,
                    f"{what} axis", (1.0, 0.0, 0.0))
    norm = math.sqrt(sum(v * v for v in axis))
    if kind in MOVING and norm < 1e-12:
        raise UrdfError(f"{source}: {what}: axis must not be zero")
    if kind in MOVING and abs(norm - 1) > 1e-12:
        axis = tuple(v / norm for v in axis)
    lim = e.find("limit")
    limit = Limit(*(_number(lim, k, source, f"{what} limit")
                    for k in ("lower", "upper", "effort", "velocity")))
    if kind == "continuous":
        limit = Limit(None, None, limit.effort, limit.velocity)
    if limit.lower is not None and limit.upper is not None and limit.lower > limit.upper:
        raise UrdfError(f"{source}: {what}: limit lower {limit.lower} > upper {limit.upper}")
    dyn = e.find("dynamics")
    damping = _number(dyn, "damping", source, f"{what} dynamics", 0.0) or 0.0
    friction = _number(dyn, "friction", source, f"{what} dynamics", 0.0) or 0.0
    if damping < 0 or friction < 0:
        raise UrdfError(f"{source}: {what}: damping and friction must be >= 0")
    mimic = None
    m = e.find("mimic")
    if m is not None:
        mimic = Mimic(_text_attr(m, "joint", source, f"{what} mimic"),
                      _number(m, "multiplier", source, f"{what} mimic", 1.0) or 0.0,
                      _number(m, "offset", source, f"{what} mimic", 0.0) or 0.0)
    return Joint(name, kind, _text_attr(parent, "link", source, f"{what} parent"),
                 _text_attr(child, "link", source, f"{what} child"),
                 _pose(e.find("origin"), source, what), axis,  # type: ignore[arg-type]
                 limit, damping, friction, mimic)


# -- numbers ---------------------------------------------------------------------------------

def _rpy_matrix(roll: float, pitch: float, yaw: float) -> Array:
    cr, sr, cp, sp_, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch),
                               math.sin(pitch), math.cos(yaw), math.sin(yaw))
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp_], [0.0, 1.0, 0.0], [-sp_, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return rz @ ry @ rx


def _axis_rotation(axis: Sequence[float], angle: float) -> Array:
    """Rodrigues: the turn by ``angle`` about the unit ``axis``."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                  [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def _num(x: float) -> sp.Expr:
    """A number as SymPy takes it best: exact zero and small integers as integers (so that a
    structural zero stays one), others as floats."""
    if x == 0:
        return sp.Integer(0)
    if x == int(x) and abs(x) < 1e6:
        return sp.Integer(int(x))
    return sp.Float(x)


def _sym_vec(v: Iterable[float]) -> sp.Matrix:
    return sp.Matrix([_num(float(x)) for x in v])


def _sym_mat(m: Array) -> sp.Matrix:
    return sp.Matrix(3, 3, [_num(float(x)) for x in np.asarray(m).ravel()])


def _symbolic_turn(axis: Sequence[float], angle: sp.Expr) -> sp.Matrix:
    """The turn by ``angle`` about ``axis``: an elementary rotation when the axis is one of the
    frame's (signs folded into the angle), else Rodrigues's formula."""
    for k, make in enumerate((rotation_x, rotation_y, rotation_z)):
        if all(axis[j] == 0 for j in range(3) if j != k) and abs(axis[k]) == 1:
            return make(angle if axis[k] > 0 else -angle)
    a = [_num(float(v)) for v in axis]
    K = sp.Matrix([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return sp.eye(3) + sp.sin(angle) * K + (1 - sp.cos(angle)) * (K * K)


def _identifier(name: str) -> str:
    out = re.sub(r"\W", "_", name, flags=re.ASCII)
    if not out or out[0].isdigit() or keyword.iskeyword(out):
        out = "j_" + out
    return out


# -- the system ------------------------------------------------------------------------------

@dataclass
class _Node:
    """A link's place in the merged tree: its body (the moving link it is fixed to; None:
    the world) and its pose in that body's frame."""

    body: str | None
    R: Array
    p: Array


def system_from_urdf(source: str | Path | Robot, *, name: str | None = None,
                     base: str | None = None, contacts: Sequence[str] | str | None = None,
                     lock: Sequence[str] | str = (), massless: str = "refuse",
                     friction: str = "refuse", posture: Mapping[str, float] | None = None,
                     restitution: float = 0.0, gravity: float = 9.81, drop: float = 0.05,
                     kp: float | None = None, kd: float = 0.0,
                     s_range: tuple[float, float] = (-0.1, 0.1)) -> System:
    """A system of rigid bodies from a URDF (a path, URDF text or a parsed :class:`Robot`).

    ``base``: ``floating`` (default for a root that is not ``world``) or ``fixed``; a root
    named ``world`` takes the joint to its child (fixed or floating). ``contacts``: link names
    (or one string joined with ``+``); a link with collision spheres or boxes touches with
    their lowest points or bottom corners, any other at its frame's origin; default: the
    collision spheres and boxes of the links at the ends of the tree. ``lock``: joint names or
    shell patterns (``arm_*``) held at their posture. ``massless``: ``refuse`` (a joint that
    moves no mass: M would be singular) or ``lock``. ``friction``: ``refuse`` (a moving joint
    declaring Coulomb friction, which is not modelled) or ``ignore``. ``posture``: joint angles
    (default 0, or the middle of the limits where 0 is outside them). ``kp`` (default:
    4 m g h, m the mass and h the base's height above its lowest contact in the posture),
    ``kd``, ``restitution``, ``gravity`` and ``drop`` are the defaults of the parameters of the
    same names (``gamma`` for the restitution, ``g`` for the gravity); ``s_range`` the
    maneuvers'. See SYSTEMS.md Sec. 4a for the maneuvers and problems it declares."""
    if isinstance(source, Robot):
        robot = source
    elif isinstance(source, Path) or (isinstance(source, str) and not source.lstrip(
            "\ufeff \t\r\n").startswith("<")):
        robot = read_urdf(source)
    else:
        robot = parse_urdf(source)
    return _Importer(robot, name=name, base=base, contacts=contacts, lock=lock,
                     massless=massless, friction=friction, posture=posture or {},
                     restitution=restitution, gravity=gravity, drop=drop, kp=kp, kd=kd,
                     s_range=s_range).build()


def _names(value: Sequence[str] | str | None) -> tuple[str, ...] | None:
    if value is None:
        return None
    if isinstance(value, str):
        return tuple(v for v in value.split("+") if v)
    return tuple(value)


class _Importer:
    def __init__(self, robot: Robot, *, name: str | None, base: str | None,
                 contacts: Sequence[str] | str | None, lock: Sequence[str] | str,
                 massless: str, friction: str, posture: Mapping[str, float],
                 restitution: float, gravity: float, drop: float, kp: float | None,
                 kd: float, s_range: tuple[float, float]) -> None:
        self.robot = robot
        self.where = robot.source
        for option, value, allowed in (("base", base, (None, "floating", "fixed")),
                                       ("massless", massless, ("refuse", "lock")),
                                       ("friction", friction, ("refuse", "ignore"))):
            if value not in allowed:
                raise UrdfError(f"{self.where}: option {option} must be one of "
                                f"{', '.join(str(a) for a in allowed if a)}, got {quoted(value)}")
        for option, number in (("restitution", restitution), ("gravity", gravity),
                               ("drop", drop), ("kd", kd), ("kp", kp)):
            if number is not None and (isinstance(number, bool) or not isinstance(
                    number, (int, float)) or not math.isfinite(number) or number < 0):
                raise UrdfError(f"{self.where}: option {option} must be a number >= 0, "
                                f"got {quoted(number)}")
        self.name = _identifier(name or robot.name)
        self.joints = {j.name: j for j in robot.joints}
        self.links = {lk.name: lk for lk in robot.links}
        self.parent_joint = {j.child: j for j in robot.joints}
        self.children: dict[str, list[Joint]] = {}
        for j in robot.joints:
            self.children.setdefault(j.parent, []).append(j)
        self.base = self._base(base)
        #: the link of the base body (floating) or fixed to the world (fixed)
        self.top = robot.root
        if robot.root == "world" and self.base == "floating":
            self.top = self.children["world"][0].child
        self.contact_names = _names(contacts)
        self.lock_patterns = _names(lock) or ()
        self.massless, self.friction = massless, friction
        self.posture = self._posture(posture)
        self.restitution, self.gravity, self.drop = restitution, gravity, drop
        self.kp, self.kd, self.s_range = kp, kd, s_range

    def _base(self, base: str | None) -> str:
        root = self.robot.root
        if root != "world":
            return base or "floating"
        joints = self.children.get(root, [])
        if len(joints) != 1 or joints[0].kind not in ("fixed", "floating"):
            raise UrdfError(f"{self.where}: the link 'world' must have one fixed or floating "
                            "joint to the robot")
        kind = "fixed" if joints[0].kind == "fixed" else "floating"
        if base is not None and base != kind:
            raise UrdfError(f"{self.where}: option base={base} contradicts the URDF's "
                            f"{joints[0].kind} joint {quoted(joints[0].name)} from 'world'")
        return kind

    def _posture(self, posture: Mapping[str, float]) -> dict[str, float]:
        out = {}
        for jname, value in posture.items():
            joint = self.joints.get(jname)
            if joint is None or joint.kind not in MOVING:
                raise UrdfError(f"{self.where}: posture: no revolute, continuous or prismatic "
                                f"joint {quoted(jname)}")
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise UrdfError(f"{self.where}: posture: {jname} must be a finite number")
            out[jname] = float(value)
        for joint in self.robot.joints:
            if joint.kind in MOVING and joint.name not in out and joint.mimic is None:
                lo, hi = joint.limit.lower, joint.limit.upper
                out[joint.name] = (0.0 if lo is None or hi is None or lo <= 0 <= hi
                                   else (lo + hi) / 2)
        for joint in self.robot.joints:  # (followers from their leaders)
            if joint.kind in MOVING and joint.mimic is not None and joint.name not in posture:
                leader, mult, offset = self._leader(joint)
                out[joint.name] = mult * out[leader] + offset
        return out

    def _leader(self, joint: Joint) -> tuple[str, float, float]:
        """The non-mimic joint a mimic joint follows, through chains of mimics, and the
        composed multiplier and offset."""
        mult, offset = 1.0, 0.0
        while joint.mimic is not None:
            m = joint.mimic
            # q = m.multiplier q_leader + m.offset, composed with what came before
            offset += mult * m.offset
            mult *= m.multiplier
            joint = self.joints[m.joint]
        if joint.kind not in MOVING:
            raise UrdfError(f"{self.where}: a mimic joint follows {quoted(joint.name)}, a "
                            f"{joint.kind} joint")
        return joint.name, mult, offset

    # -- which joints move -------------------------------------------------------------------
    def _locked(self) -> dict[str, float]:
        locked: dict[str, float] = {}
        moving = [j for j in self.robot.joints if j.kind in MOVING]
        for pattern in self.lock_patterns:
            hits = [j.name for j in moving if fnmatch.fnmatchcase(j.name, pattern)]
            if not hits:
                raise UrdfError(f"{self.where}: lock: {quoted(pattern)} names no revolute, "
                                "continuous or prismatic joint")
            for h in hits:
                locked[h] = self.posture[h]
        # a follower of a locked leader is locked with it, and a leader with all its followers
        # stays free
        for joint in moving:
            if joint.mimic is not None and joint.name not in locked:
                leader = self._leader(joint)[0]
                if leader in locked:
                    locked[joint.name] = self.posture[joint.name]
        for joint in self.robot.joints:
            if joint.kind in ("floating", "planar") and not (
                    joint.kind == "floating" and joint.parent == "world"):
                raise UrdfError(f"{self.where}: joint {quoted(joint.name)}: a {joint.kind} "
                                "joint inside the tree is not supported (only a floating "
                                "joint from 'world', the floating base)")
        return locked

    def _subtree_mass(self, link: str) -> tuple[float, list[str]]:
        """The mass of ``link`` and every link below it, and their names."""
        total, names, stack = 0.0, [], [link]
        while stack:
            current = stack.pop()
            total += self.links[current].mass
            names.append(current)
            stack += [j.child for j in self.children.get(current, [])]
        return total, names

    def _massless(self, locked: dict[str, float]) -> None:
        """Refuse (or lock) moving joints that move no mass."""
        for joint in self.robot.joints:
            if joint.kind not in MOVING or joint.name in locked:
                continue
            mass, names = self._subtree_mass(joint.child)
            if mass > 0:
                continue
            if self.massless == "lock":
                locked[joint.name] = self.posture[joint.name]
                continue
            raise UrdfError(
                f"{self.where}: joint {quoted(joint.name)} moves only links of zero mass "
                f"({', '.join(names[:6])}{', ...' if len(names) > 6 else ''}): M would be "
                f"singular; lock it (lock={joint.name}) or all such joints (massless=lock)")

    def build(self) -> System:
        locked = self._locked()
        self._massless(locked)
        robot = self.robot
        where = self.where
        if self.friction == "refuse":
            for joint in robot.joints:
                if joint.kind in MOVING and joint.name not in locked and joint.friction > 0:
                    raise UrdfError(
                        f"{where}: joint {quoted(joint.name)} declares Coulomb friction "
                        f"{joint.friction}, which the simulator does not model (a set-valued "
                        "force); import with friction=ignore to leave it out, or lock the joint")
        free = [j for j in robot.joints if j.kind in MOVING and j.name not in locked]
        leaders = [j for j in free if j.mimic is None]
        coordinates = {j.name: _identifier(j.name) for j in leaders}
        names = [*(BASE if self.base == "floating" else ()), *coordinates.values()]
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise UrdfError(f"{where}: joint names give the coordinate names {dup} twice "
                            "(names are made identifiers: other characters become _)")
        inputs = {j.name: f"{coordinates[j.name]}_effort" for j in leaders}
        parameters = {"g": self.gravity, "gamma": self.restitution, "drop": self.drop,
                      "kp": 0.0, "kd": self.kd}
        try:
            s = System(self.name, names, parameters=parameters, inputs=list(inputs.values()),
                       s="s")
        except SystemDescriptionError as exc:
            raise UrdfError(f"{where}: {exc}") from None
        s.source = where
        s.restitution = s.p.gamma
        s.gravity = (0, 0, -s.p.g)
        q = dict(zip(s.coordinate_names, s.q))
        angle: dict[str, sp.Expr] = {}
        mimic: dict[str, tuple[str, float, float]] = {}
        for j in free:
            if j.mimic is None:
                angle[j.name] = q[coordinates[j.name]]
            else:
                leader, mult, offset = self._leader(j)
                mimic[j.name] = (leader, mult, offset)
                angle[j.name] = _num(mult) * q[coordinates[leader]] + _num(offset)

        # the merged tree: each link's body and its pose in the body's frame
        nodes: dict[str, _Node] = {}
        top = self.top
        root_body = top if self.base == "floating" else None
        nodes[top] = _Node(root_body, np.eye(3), np.zeros(3))
        order = [top]
        if top != robot.root:  # (a floating joint from 'world': the world stays put)
            nodes[robot.root] = _Node(None, np.eye(3), np.zeros(3))
        poses: dict[str, tuple[sp.Matrix, sp.Matrix]] = {}  # body -> (origin, axes) in world
        relative: dict[str, tuple[sp.Matrix, sp.Matrix]] = {}  # body -> pose in its parent
        body_parent: dict[str, str | None] = {}
        if root_body is not None:
            x, y, z, roll, pitch, yaw = (q[n] for n in BASE)
            poses[root_body] = relative[root_body] = (sp.Matrix([x, y, z]),
                                                      rotation_rpy(roll, pitch, yaw))
        stack = [top]
        while stack:
            link = stack.pop(0)
            for joint in self.children.get(link, []):
                up = nodes[link]
                R0 = up.R @ joint.origin.rotation()
                p0 = up.p + up.R @ np.array(joint.origin.xyz)
                if joint.kind in MOVING and joint.name in angle:
                    nodes[joint.child] = _Node(joint.child, np.eye(3), np.zeros(3))
                    body_parent[joint.child] = up.body
                    th = angle[joint.name]
                    if joint.kind == "prismatic":
                        rel_R = _sym_mat(R0)
                        rel_p = _sym_vec(p0) + _sym_mat(R0) * _sym_vec(joint.axis) * th
                    else:
                        rel_R = _sym_mat(R0) * _symbolic_turn(joint.axis, th)
                        rel_p = _sym_vec(p0)
                    if up.body is None:
                        poses[joint.child] = (rel_p, rel_R)
                    else:
                        o, A = poses[up.body]
                        poses[joint.child] = (o + A * rel_p, A * rel_R)
                    relative[joint.child] = (rel_p, rel_R)
                else:
                    value = locked.get(joint.name, 0.0)
                    if joint.kind == "prismatic":
                        R, p = R0, p0 + R0 @ (np.array(joint.axis) * value)
                    elif joint.kind in MOVING:
                        R, p = R0 @ _axis_rotation(joint.axis, value), p0
                    else:  # fixed (or floating from world, handled as the base)
                        R, p = R0, p0
                    nodes[joint.child] = _Node(up.body, R, p)
                order.append(joint.child)
                stack.append(joint.child)

        # bodies: each moving link with its fixed descendants' mass merged
        bodies = [b for b in order if nodes[b].body == b]
        groups: dict[str, list[str]] = {b: [] for b in bodies}
        for link in order:
            owner = nodes[link].body
            if owner is not None:
                groups[owner].append(link)
        if self.base == "floating" and sum(self.links[lk].mass for lk in order) <= 0:
            raise UrdfError(f"{where}: the robot has no mass")
        for b in bodies:
            mass, centre, inertia = self._merged(groups[b], nodes)
            if b == root_body and mass <= 0:
                raise UrdfError(
                    f"{where}: the floating base's links ({', '.join(groups[b][:6])}) have "
                    "no mass, which the six base coordinates need (M would be singular)")
            rel = relative[b]
            s.body(_identifier(b), _num(mass), parent=(None if body_parent.get(b) is None
                                                       else _identifier(body_parent[b] or "")),
                   position=tuple(rel[0]), rotation=rel[1], centre=tuple(_sym_vec(centre)),
                   inertia=_sym_mat(inertia))

        # the world pose of every link, for contacts and display
        def world(link: str) -> tuple[sp.Matrix, sp.Matrix]:
            node = nodes[link]
            if node.body is None:
                return _sym_vec(node.p), _sym_mat(node.R)
            o, A = poses[node.body]
            return o + A * _sym_vec(node.p), A * _sym_mat(node.R)

        self._applied(s, leaders, free, coordinates, inputs, mimic, q)
        contacts = self._contacts(s, nodes, world, order)
        imported = Imported(
            robot=robot, base=self.base, coordinates=coordinates, mimic=mimic, locked=locked,
            bodies={lk: nodes[lk].body for lk in order},
            frames={lk: (tuple(float(v) for v in nodes[lk].p),
                         tuple(tuple(float(v) for v in row) for row in nodes[lk].R))
                    for lk in order},
            contacts={c: link for c, (link, _p, _r) in contacts.items()},
            posture={j: self.posture[j] for j in coordinates}, inputs=inputs)
        s.robot = imported
        self._maneuvers(s, contacts, coordinates, mimic, free, order, locked)
        self._looks(s, world, order, nodes, contacts)
        return s

    def _merged(self, links: list[str], nodes: Mapping[str, _Node]
                ) -> tuple[float, Array, Array]:
        """Mass, centre and inertia about the centre (body axes) of links fixed to one body:
        each link's inertia turned into the body's axes, moved to the common centre by the
        parallel-axis theorem."""
        parts = []
        for link in links:
            inertial = self.links[link].inertial
            if inertial is None or inertial.mass == 0 and not any(inertial.inertia):
                continue
            node = nodes[link]
            R = node.R @ inertial.origin.rotation()
            centre = node.p + node.R @ np.array(inertial.origin.xyz)
            turned = R @ inertial.tensor() @ R.T
            parts.append((inertial.mass, centre, (turned + turned.T) / 2))
        mass = sum(m for m, _c, _i in parts)
        if not parts:
            return 0.0, np.zeros(3), np.zeros((3, 3))
        if len(parts) == 1:
            return parts[0]
        centre = sum(m * c for m, c, _i in parts) / mass if mass > 0 else np.zeros(3)
        inertia = np.zeros((3, 3))
        for m, c, i in parts:
            r = c - centre
            inertia += i + m * (r @ r * np.eye(3) - np.outer(r, r))
        return mass, centre, (inertia + inertia.T) / 2

    def _applied(self, s: System, leaders: list[Joint], free: list[Joint],
                 coordinates: Mapping[str, str], inputs: Mapping[str, str],
                 mimic: Mapping[str, tuple[str, float, float]], q: Mapping[str, sp.Symbol]
                 ) -> None:
        """Efforts, joint damping and the PD hold: f_k = u_k - c_k q_k' + kp (q0_k - q_k) -
        kd q_k' on each joint's coordinate; a mimic joint's damping acts on its leader through
        its multiplier (its velocity is multiplier q_leader', its torque's work too)."""
        dq = dict(zip(s.coordinate_names, s.dq))
        force: dict[str, sp.Expr] = {c: sp.Integer(0) for c in s.coordinate_names}
        for j in leaders:
            c = coordinates[j.name]
            f = s.u[inputs[j.name]] - _num(j.damping) * dq[c]
            f += s.p.kp * (_num(self.posture[j.name]) - q[c]) - s.p.kd * dq[c]
            force[c] += f
        for j in free:
            if j.mimic is not None and j.damping > 0:
                leader, mult, _off = mimic[j.name]
                c = coordinates[leader]
                force[c] -= _num(j.damping * mult * mult) * dq[c]
        values = [force[c] for c in s.coordinate_names]
        s.forces = values

    def _contacts(self, s: System, nodes: Mapping[str, _Node], world: Any, order: list[str]
                  ) -> dict[str, tuple[str, Array, float]]:
        """The constraints: (link, point in the link's frame, radius) by name."""
        names = self.contact_names
        if names is None:
            parents = {nodes[self.parent_joint[lk].parent].body for lk in order
                       if lk in self.parent_joint and nodes[lk].body == lk}
            leaves = {lk for lk in order if nodes[lk].body not in parents}
            names = tuple(lk for lk in order if lk in leaves and any(
                c.geometry.kind in ("sphere", "box") for c in self.links[lk].collisions))
            if not names and self.base == "floating":
                raise UrdfError(
                    f"{self.where}: no contacts: the links at the ends of the tree have no "
                    "collision sphere or box; name the links that touch the ground "
                    "(contacts=FOOT_A+FOOT_B)")
        out: dict[str, tuple[str, Array, float]] = {}
        for link in names:
            if link not in self.links:
                raise UrdfError(f"{self.where}: contacts: no link {quoted(link)}")
            if nodes[link].body is None:
                raise UrdfError(f"{self.where}: contacts: link {quoted(link)} is fixed to the "
                                "world")
            shapes = [c for c in self.links[link].collisions
                      if c.geometry.kind in ("sphere", "box")]
            base = _identifier(link)
            if not shapes:
                out[base] = (link, np.zeros(3), 0.0)
            for k, shape in enumerate(shapes):
                tag = base if len(shapes) == 1 else f"{base}_{k + 1}"
                R = shape.origin.rotation()
                c = np.array(shape.origin.xyz)
                if shape.geometry.kind == "sphere":
                    out[tag] = (link, c, shape.geometry.size[0])
                    continue
                hx, hy, hz = (v / 2 for v in shape.geometry.size)
                for corner, sx, sy in (("fl", 1, 1), ("fr", 1, -1), ("rl", -1, 1),
                                       ("rr", -1, -1)):
                    out[f"{tag}_{corner}"] = (link, c + R @ np.array([sx * hx, sy * hy, -hz]),
                                              0.0)
        for cname, (link, point, radius) in out.items():
            o, A = world(link)
            at = o + A * _sym_vec(point)
            try:
                s.constraint(cname, at[2] - _num(radius),
                             at=(at[0], at[1], at[2] - _num(radius)))
            except SystemDescriptionError as exc:
                raise UrdfError(f"{self.where}: contacts: {exc}") from None
        return out

    # -- maneuvers and problems ----------------------------------------------------------------
    def _kinematics(self, order: list[str], joint_values: Mapping[str, float]
                    ) -> dict[str, tuple[Array, Array, list[tuple[str, Array, Array, str]]]]:
        """Every link's pose in the base's (or world's) frame at ``joint_values``, and the
        joints above it: (name, axis, a point on it, kind), in the same frame."""
        out: dict[str, tuple[Array, Array, list[tuple[str, Array, Array, str]]]] = {
            order[0]: (np.eye(3), np.zeros(3), [])}
        for link in order[1:]:
            joint = self.parent_joint[link]
            R_up, p_up, chain = out[joint.parent]
            R0 = R_up @ joint.origin.rotation()
            p0 = p_up + R_up @ np.array(joint.origin.xyz)
            value = joint_values.get(joint.name, 0.0)
            axis = R0 @ np.array(joint.axis)
            if joint.kind == "prismatic":
                out[link] = (R0, p0 + axis * value, chain + [(joint.name, axis, p0, "p")])
            elif joint.kind in MOVING:
                out[link] = (R0 @ _axis_rotation(joint.axis, value), p0,
                             chain + [(joint.name, axis, p0, "r")])
            else:
                out[link] = (R0, p0, chain)
        return out

    def _maneuvers(self, s: System, contacts: Mapping[str, tuple[str, Array, float]],
                   coordinates: Mapping[str, str], mimic: Mapping[str, tuple[str, float, float]],
                   free: list[Joint], order: list[str], locked: Mapping[str, float]) -> None:
        q = dict(zip(s.coordinate_names, s.q))
        dq = dict(zip(s.coordinate_names, s.dq))
        values = {j.name: self.posture[j.name] for j in free}
        values.update(locked)
        kin = self._kinematics(order, values)
        initial_joints = {q[coordinates[j]]: _num(v) for j, v in self.posture.items()
                          if j in coordinates}
        total = sum(self.links[lk].mass for lk in order)
        points = {}
        for cname, (link, point, radius) in contacts.items():
            R, p, chain = kin[link]
            points[cname] = (p + R @ point, radius, chain)
        if self.base == "fixed":  # (kp's default: a fixed base needs no posture hold)
            s.defaults["kp"] = float(self.kp or 0.0)
            lead = next(iter(coordinates.values()), None)
            if lead is None:
                raise UrdfError(f"{self.where}: a fixed base and no moving joint: nothing "
                                "moves")
            k = q[lead]
            start = initial_joints.get(k, sp.Integer(0))
            s.maneuver("swing", initial={**initial_joints, k: start + s.s},
                       terminal=dq[lead] * (k - start - s.s), outcome=k,
                       s_range=self.s_range,
                       description=f"from rest in the posture with {lead} turned by s, to its "
                                   f"first turning point; outcome: {lead} there")
            return
        if not points:
            return
        heights = {c: float(p[2]) - r for c, (p, r, _ch) in points.items()}
        low = min(heights.values())
        depth = -low  # the base's height above its lowest contact, level, in the posture
        s.defaults["kp"] = float(self.kp if self.kp is not None
                                 else 4 * total * self.gravity * max(depth, 0.0))
        # drop: roll s, pitch s / 2; z so that the lowest contact is `drop` above the ground
        roll, pitch = s.s, s.s / 2
        row = sp.Matrix([[-sp.sin(pitch), sp.cos(pitch) * sp.sin(roll),
                          sp.cos(pitch) * sp.cos(roll)]])
        lows = [(row * _sym_vec(p))[0] - _num(r) for c, (p, r, _ch) in points.items()]
        lowest = sp.Min(*lows, evaluate=False) if len(lows) > 1 else lows[0]
        base = {q["base_roll"]: roll, q["base_pitch"]: pitch}
        s.maneuver("drop", initial={**initial_joints, **base, q["base_z"]: s.p.drop - lowest},
                   terminal=-dq["base_z"], outcome=dq["base_roll"], armed_after="touchdown",
                   s_range=self.s_range,
                   description="from rest in the posture, its lowest contact `drop` above the "
                               "ground, the base rolled by s and pitched by s / 2, to the "
                               "base's lowest point after the first touchdown; outcome: the "
                               "roll rate there")
        efforts: dict[str, tuple[float, float]] = {}
        for jn, c in coordinates.items():
            effort = self.joints[jn].limit.effort
            if effort:
                efforts[f"{c}_effort"] = (-effort, effort)
        if efforts:
            s.problem("drop", maneuver="drop", decisions=efforts,
                      weights={k: 1e-6 for k in efforts}, target=0.0)
        # stand: on the contacts that touch in the posture, the base pushed down at s
        down = [c for c, h in heights.items() if h - low <= 1e-9]
        rows = []
        cols = list(coordinates)
        for c in down:
            point, _r, chain = points[c]
            row_ = np.zeros(len(cols))
            for jname, axis, origin, kind in chain:
                leader, mult = (mimic[jname][0], mimic[jname][1]) if jname in mimic else \
                    (jname, 1.0)
                if leader not in coordinates:
                    continue  # (locked)
                rate = axis if kind == "p" else np.cross(axis, point - origin)
                row_[cols.index(leader)] += mult * rate[2]
            rows.append(row_)
        if not rows or not cols:
            return
        A = np.array(rows)
        # joint rates w with A w = 1 (the base's z rate is -1 times s: A w - 1 = 0)
        w, *_ = np.linalg.lstsq(A, np.ones(len(rows)), rcond=None)
        if np.abs(A @ w - 1).max() > 1e-12 * max(1.0, np.abs(A).max()):
            return  # (the joints cannot keep the contacts still while the base goes down)
        velocities = {dq[coordinates[j]]: _num(float(v)) * s.s for j, v in zip(cols, w)
                      if v != 0}
        s.maneuver("stand", initial={**initial_joints, q["base_z"]: _num(depth),
                                     dq["base_z"]: -s.s, **velocities},
                   mode=down, terminal=-dq["base_z"], outcome=q["base_z"],
                   s_range=(0.0, 0.5),
                   description="level in the posture on the contacts that touch, the base "
                               "pushed down at speed s (the contacts kept still), to the "
                               "base's lowest point; outcome: the base's height there")
        if efforts:
            s.problem("stand", maneuver="stand", decisions=efforts,
                      weights={k: 1e-6 for k in efforts}, target=float(depth))

    # -- looks -----------------------------------------------------------------------------
    def _looks(self, s: System, world: Any, order: list[str], nodes: Mapping[str, _Node],
               contacts: Mapping[str, tuple[str, Array, float]]) -> None:
        """Every link's frame (named after it), its collision boxes and spheres drawn in it
        (visual ones where it has no collision shape), and a line through each moving link's
        origin and its parent body's: the skeleton."""
        frames: dict[str, str] = {}
        for link in order:
            fname = _identifier(link)
            if fname in frames.values() or fname == "world":
                continue
            o, A = world(link)
            roll = sp.atan2(A[2, 1], A[2, 2])
            pitch = sp.asin(-A[2, 0])
            yaw = sp.atan2(A[1, 0], A[0, 0])
            s.frame(fname, x=o[0], y=o[1], z=o[2], roll=roll, pitch=pitch, yaw=yaw)
            frames[link] = fname
        count = 0
        for link in order:
            if link not in frames:
                continue
            lk = self.links[link]
            shapes = [c for c in lk.collisions if c.geometry.kind in ("sphere", "box")] or [
                v for v in lk.visuals if v.geometry.kind in ("sphere", "box")]
            for shape in shapes:
                if any(shape.origin.xyz) or any(shape.origin.rpy):
                    # (a shape off its link's origin gets a frame of its own)
                    o, A = world(link)
                    Rs = _sym_mat(shape.origin.rotation())
                    o2, A2 = o + A * _sym_vec(shape.origin.xyz), A * Rs
                    fname = f"{frames[link]}_shape{count}"
                    s.frame(fname, x=o2[0], y=o2[1], z=o2[2],
                            roll=sp.atan2(A2[2, 1], A2[2, 2]), pitch=sp.asin(-A2[2, 0]),
                            yaw=sp.atan2(A2[1, 0], A2[0, 0]))
                else:
                    fname = frames[link]
                g = shape.geometry
                if g.kind == "box":
                    s.box(f"shape{count}", fname, tuple(_num(v) for v in g.size))
                else:
                    s.sphere(f"shape{count}", fname, _num(g.size[0]))
                count += 1
        for link in order:
            joint = self.parent_joint.get(link)
            if joint is None or nodes[link].body != link:
                continue
            a, _A = world(link)
            b, _B = world(joint.parent)
            s.line(f"{_identifier(link)}_bone", [tuple(b), tuple(a)], width=0.01,
                   color=(0.55, 0.55, 0.55))


def from_file_arguments(path: Path, arguments: Mapping[str, Any]) -> System:
    """:func:`system_from_urdf` with the options of a file argument
    (``robot.urdf:base=fixed,contacts=A+B,lock=arm_*``)."""
    unknown = [k for k in arguments if k not in OPTIONS]
    if unknown:
        raise UrdfError(f"{path}: unknown option {unknown[0]} (options: {', '.join(OPTIONS)})")
    text = {k: str(v) for k, v in arguments.items()}
    return system_from_urdf(path, name=text.get("name"), base=text.get("base"),
                            contacts=text.get("contacts"), lock=text.get("lock", ()),
                            massless=text.get("massless", "refuse"),
                            friction=text.get("friction", "refuse"))


IMPORTERS["urdf"] = system_from_urdf  # (System.from_urdf)


# -- the robot description out ----------------------------------------------------------------

def _fmt(values: Iterable[float]) -> str:
    """Numbers as URDF attributes, each the shortest text that reads back as the same double."""
    return " ".join(repr(float(v)) for v in values)


def _origin(pose: Pose) -> str:
    return f'<origin xyz="{_fmt(pose.xyz)}" rpy="{_fmt(pose.rpy)}"/>'


def _geometry(g: Geometry) -> str | None:
    if g.kind == "box":
        return f'<box size="{_fmt(g.size)}"/>'
    if g.kind == "sphere":
        return f'<sphere radius="{_fmt(g.size)}"/>'
    if g.kind == "cylinder":
        return f'<cylinder radius="{_fmt(g.size[:1])}" length="{_fmt(g.size[1:])}"/>'
    return None  # (a mesh names a file: left out, see description_urdf)


def base_link(imported: Imported) -> str:
    """The link whose pose in the world goes on ``/tf``: the root link, or, when the URDF's root
    is ``world``, the link its one joint carries."""
    robot = imported.robot
    if robot.root != "world":
        return robot.root
    return next(j.child for j in robot.joints if j.parent == "world")


def description_urdf(imported: Imported, name: str) -> str:
    """The robot as a URDF again, for ``/robot_description`` (ROS.md Sec. 6): every link from
    :func:`base_link` down with its inertial as read, its box, sphere and cylinder collisions,
    and visuals (its box, sphere and cylinder visuals, else its collisions); every joint below
    it with its type, origin, axis, limits and dynamics as read, and its mimic where the
    importer made it a follower (a locked joint keeps its type: its value is on
    ``/joint_states``). Left out: the link ``world`` and its joint (the base's pose is on
    ``/tf``), meshes (they name files a viewer would open), materials. Numbers are written as
    the shortest text that reads back as the same double, so the kinematics and inertias that
    come back are the ones that went in."""
    robot = imported.robot
    top = base_link(imported)
    below = {top}
    stack = [top]
    children: dict[str, list[Joint]] = {}
    for j in robot.joints:
        children.setdefault(j.parent, []).append(j)
    while stack:
        parent = stack.pop(0)
        for j in children.get(parent, []):
            below.add(j.child)
            stack.append(j.child)
    joints = [j for j in robot.joints if j.parent in below]
    out = ['<?xml version="1.0"?>', f"<robot name={quoteattr(name)}>"]
    for link in robot.links:
        if link.name not in below:
            continue
        out.append(f"  <link name={quoteattr(link.name)}>")
        if link.inertial is not None:
            i = link.inertial
            xx, xy, xz, yy, yz, zz = (repr(float(v)) for v in i.inertia)
            out += ["    <inertial>", f"      {_origin(i.origin)}",
                    f'      <mass value="{_fmt([i.mass])}"/>',
                    f'      <inertia ixx="{xx}" ixy="{xy}" ixz="{xz}" iyy="{yy}" iyz="{yz}" '
                    f'izz="{zz}"/>', "    </inertial>"]
        collisions = [(s, g) for s in link.collisions if (g := _geometry(s.geometry))]
        visuals = [(s, g) for s in link.visuals if (g := _geometry(s.geometry))] or collisions
        for tag, shapes in (("visual", visuals), ("collision", collisions)):
            for shape, geometry in shapes:
                named = f" name={quoteattr(shape.name)}" if shape.name else ""
                out += [f"    <{tag}{named}>", f"      {_origin(shape.origin)}",
                        f"      <geometry>{geometry}</geometry>", f"    </{tag}>"]
        out.append("  </link>")
    for j in joints:
        out += [f"  <joint name={quoteattr(j.name)} type={quoteattr(j.kind)}>",
                f"    {_origin(j.origin)}", f"    <parent link={quoteattr(j.parent)}/>",
                f"    <child link={quoteattr(j.child)}/>"]
        if j.kind in MOVING:
            out.append(f'    <axis xyz="{_fmt(j.axis)}"/>')
            lim = j.limit
            values = {"lower": lim.lower, "upper": lim.upper, "effort": lim.effort,
                      "velocity": lim.velocity}
            if j.kind == "continuous":
                values["lower"] = values["upper"] = None
            if j.kind != "continuous" or lim.effort is not None or lim.velocity is not None:
                # (URDF requires effort and velocity on a limit: 0 where none was read)
                values["effort"] = values["effort"] or 0.0
                values["velocity"] = values["velocity"] or 0.0
                attrs = " ".join(f'{k}="{_fmt([v])}"' for k, v in values.items()
                                 if v is not None)
                out.append(f"    <limit {attrs}/>")
            if j.damping or j.friction:
                out.append(f'    <dynamics damping="{_fmt([j.damping])}" '
                           f'friction="{_fmt([j.friction])}"/>')
            if j.name in imported.mimic and j.mimic is not None:
                m = j.mimic
                out.append(f"    <mimic joint={quoteattr(m.joint)} multiplier="
                           f'"{_fmt([m.multiplier])}" offset="{_fmt([m.offset])}"/>')
        out.append("  </joint>")
    out.append("</robot>")
    return "\n".join(out) + "\n"


def tree_facts(system: System) -> dict[str, Any] | None:
    """What ``/robot_description``, ``/joint_states`` and ``/tf`` need of a system imported
    from a URDF, as JSON data a cached start reads without SymPy (None for any other system):
    the URDF (:func:`description_urdf`), the base link, the indices of the six base
    coordinates in q (floating base) or the base's fixed pose (x, y, z, roll, pitch, yaw), and
    per published joint (every revolute, continuous or prismatic joint that is not a follower
    of a mimic, in the file's order): its name, the index of its coordinate in q (-1: locked)
    and its value when locked, and the index of its effort among the inputs (-1: none)."""
    imported = system.robot
    if not isinstance(imported, Imported):
        return None
    robot = imported.robot
    names = list(system.coordinate_names)
    inputs = list(system.u.names())
    top = base_link(imported)
    if imported.base == "floating":
        base_q: list[int] | None = [names.index(c) for c in BASE]
        base_pose = None
    else:
        base_q = None
        joint = next((j for j in robot.joints if j.child == top), None)
        pose = joint.origin if joint is not None else Pose()
        base_pose = [*pose.xyz, *pose.rpy]
    joints = []
    for j in robot.joints:
        if j.kind not in MOVING or j.name in imported.mimic:
            continue
        coordinate = imported.coordinates.get(j.name)
        index = names.index(coordinate) if coordinate is not None else -1
        value = float(imported.locked.get(j.name, 0.0))
        effort = imported.inputs.get(j.name)
        joints.append([j.name, index, value, inputs.index(effort) if effort in inputs else -1])
    return {"urdf": description_urdf(imported, system.name), "base": top,
            "base_coordinates": base_q, "base_pose": base_pose, "joints": joints}
