"""A mechanical system subject to unilateral constraints, written symbolically (SYSTEMS.md Sec. 1).

What a researcher writes to bring their own system: coordinates, parameters with defaults, named
inputs, the mass matrix M(q), the generalised forces f_J(q, q', u) of each contact mode J, the
unilateral constraints a_j(q) >= 0, the coefficient of restitution and the maneuvers. Everything
is a SymPy expression in the symbols the :class:`System` hands out (``sympy.physics.mechanics``
output works as long as it is expressed in them). Nothing here is numeric: the Jacobian Da, the
velocity term (d/dt Da) q' and the checks of shapes and symbols are derived by
:mod:`biped_opt.systems.derive`.

    bar = System("rocking_bar", ["x", "z", "th"], parameters={"m": 1, "w": 0.5, "g": 1})
    x, z, th = bar.q
    bar.mass_matrix = sympy.diag(bar.p.m, bar.p.m, bar.p.m * bar.p.w ** 2 / 3)
    bar.forces = lambda J: [0, -bar.p.m * bar.p.g, 0]
    bar.constraint("left", z - bar.p.w * sympy.sin(th))
    ...

A contact mode J is given to ``forces`` as a frozenset of constraint names (``"left" in J``);
any dependence of the forces on J is allowed: that is force coupling.
"""

from __future__ import annotations

import keyword
import math
import re
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import sympy as sp

from biped_opt.errors import BipedOptError

__all__ = ["System", "Body", "ManeuverDescription", "SystemDescriptionError", "Symbols", "Frame",
           "Shape", "WORLD", "SHAPE_KINDS", "IMPORTERS"]

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


class SystemDescriptionError(BipedOptError, ValueError):
    """A system description is wrong; the message names the system, the item and what is
    wrong (and the file, for a system loaded from one)."""


class Symbols:
    """Named symbols with attribute and item access (``sys.p.m``, ``sys.p["m"]``), in order."""

    def __init__(self, kind: str, names: Sequence[str], symbols: Sequence[sp.Symbol]) -> None:
        self._kind = kind
        self._by_name = dict(zip(names, symbols))

    def __getattr__(self, name: str) -> sp.Symbol:
        try:
            return self.__dict__["_by_name"][name]
        except KeyError:
            raise AttributeError(f"no {self.__dict__['_kind']} named {name!r}") from None

    def __getitem__(self, name: str) -> sp.Symbol:
        try:
            return self._by_name[name]
        except KeyError:
            raise KeyError(f"no {self._kind} named {name!r}") from None

    def __iter__(self) -> Iterator[sp.Symbol]:
        return iter(self._by_name.values())

    def __len__(self) -> int:
        return len(self._by_name)

    def names(self) -> tuple[str, ...]:
        return tuple(self._by_name)

    def __repr__(self) -> str:
        return f"{self._kind}s({', '.join(self._by_name)})"


#: a maneuver's default budget: contact events, and the time horizon
DEFAULT_MAX_EVENTS = 16
DEFAULT_HORIZON = 10.0


@dataclass(frozen=True)
class ManeuverDescription:
    """A maneuver (SYSTEMS.md Sec. 1): an initial-state family x0(s) of one scalar s, the initial
    mode, a terminal guard (ends when it falls through 0), an outcome of the final state.

    ``initial`` maps coordinates and velocities (symbols of ``System.q``/``System.dq``) to
    expressions in ``System.s`` and the parameters; those not given start at 0.
    ``armed_after="touchdown"``: the terminal guard counts only after the first touchdown.
    ``final_mode``: the mode the terminal event must happen in (None: any).
    ``s_range``: the valid range of s (beyond it other mode sequences appear).
    ``max_events``, ``horizon``: the simulation's budget, contact events and time; a run that
    uses it up before the terminal event ends with status ``MAX_EVENTS`` or ``HORIZON``.
    """

    name: str
    initial: Mapping[sp.Symbol, Any]
    mode: frozenset[str]
    terminal: Any
    outcome: Any
    armed_after: str | None = None
    final_mode: frozenset[str] | None = None
    s_range: tuple[float, float] = (-1.0, 1.0)
    description: str = ""
    extra: Mapping[str, Any] = field(default_factory=dict)
    max_events: int = DEFAULT_MAX_EVENTS
    horizon: float = DEFAULT_HORIZON


#: the fixed frame every declared frame's pose is given in (REP 105's name in simulators)
WORLD = "world"
#: what a shape may be: a box or a sphere fixed in a frame, a polyline between world points
SHAPE_KINDS = ("box", "sphere", "line")
#: the colours shapes take in turn when none is given (RGBA, each in [0, 1])
PALETTE = ((0.20, 0.45, 0.75, 1.0), (0.85, 0.40, 0.10, 1.0), (0.30, 0.65, 0.30, 1.0),
           (0.60, 0.35, 0.70, 1.0), (0.55, 0.55, 0.55, 1.0))


#: importers of robot descriptions by format, each registered by its own module (which
#: imports this one): ``urdf`` is :func:`biped_opt.systems.urdf.system_from_urdf`, imported
#: with ``biped_opt.systems``
IMPORTERS: dict[str, Callable[..., System]] = {}


@dataclass(frozen=True)
class Frame:
    """A body frame (SYSTEMS.md Sec. 6): its origin (x, y, z) and orientation (roll, pitch, yaw:
    fixed-axis X, Y, Z rotations, as URDF's rpy) in the world frame, expressions of q and the
    parameters. A planar system lives in the x-z plane (REP 103: x forward, z up), so its
    pitch turns x towards -z."""

    name: str
    position: tuple[Any, Any, Any]
    rpy: tuple[Any, Any, Any]


@dataclass(frozen=True)
class Body:
    """A rigid body of a tree of bodies (SYSTEMS.md Sec. 1a): the pose of its frame in its
    parent's frame (the world's for a root), its origin ``position`` (x, y, z) and its axes'
    components ``rotation`` (3 x 3, columns; None: the parent's axes), expressions of q and the
    parameters; its mass, its centre of mass ``centre`` in its own frame and its inertia about
    that centre in its own axes (3 x 3), parameters only."""

    name: str
    mass: Any
    position: tuple[Any, Any, Any]
    rotation: tuple[tuple[Any, ...], ...] | None
    inertia: tuple[tuple[Any, ...], ...]
    parent: str | None = None
    centre: tuple[Any, Any, Any] = (0, 0, 0)


@dataclass(frozen=True)
class Shape:
    """A simple shape to draw (SYSTEMS.md Sec. 6): ``box`` (edge lengths ``size``) or ``sphere``
    (``size`` = (radius,)) fixed at the origin of ``frame``, or ``line``: a polyline through
    world ``points`` (expressions of q) of width ``size`` = (width,). Sizes may depend on the
    parameters, not on q."""

    name: str
    kind: str
    frame: str
    size: tuple[Any, ...]
    points: tuple[tuple[Any, Any, Any], ...]
    color: tuple[float, float, float, float]


class System:
    """A mechanical system subject to unilateral constraints, described symbolically.

    ``coordinates`` names q (d of them); the velocities are ``<name>_dot``. ``parameters`` maps
    names to default values (runtime data: changing one never recompiles); ``inputs`` names the
    inputs u. ``restitution`` may be a number or an expression in the parameters.
    """

    def __init__(self, name: str, coordinates: Sequence[str], *,
                 parameters: Mapping[str, float] | None = None, inputs: Sequence[str] = (),
                 restitution: Any = 0, s: str = "s") -> None:
        _check_name("system name", name, name)
        self.name = name
        coordinates = list(coordinates)
        parameters = dict(parameters or {})
        inputs = list(inputs)
        taken: dict[str, str] = {}
        for kind, names in (("coordinate", coordinates),
                            ("velocity", [f"{c}_dot" for c in coordinates]),
                            ("parameter", list(parameters)), ("input", inputs), ("s", [s])):
            for item in names:
                _check_name(kind, item, name)
                if item in taken:
                    raise SystemDescriptionError(
                        f"{name}: {kind} {item!r} is also a {taken[item]} name")
                taken[item] = kind
        if not coordinates:
            raise SystemDescriptionError(f"{name}: coordinates: at least one is needed")
        for key, value in parameters.items():
            try:
                parameters[key] = float(value)
            except (TypeError, ValueError):
                raise SystemDescriptionError(
                    f"{name}: parameter {key!r}: default must be a number, got {value!r}"
                ) from None
        self.q = tuple(sp.Symbol(c, real=True) for c in coordinates)
        self.dq = tuple(sp.Symbol(f"{c}_dot", real=True) for c in coordinates)
        self.p = Symbols("parameter", list(parameters),
                         [sp.Symbol(k, real=True) for k in parameters])
        self.u = Symbols("input", inputs, [sp.Symbol(k, real=True) for k in inputs])
        self.s = sp.Symbol(s, real=True)
        self.defaults: dict[str, float] = parameters
        self.mass_matrix: Any = None
        self.forces: Callable[[frozenset[str]], Any] | Any = None
        #: rigid bodies, instead of ``mass_matrix`` (see :meth:`body`), and the acceleration
        #: of gravity (world x, y, z) that acts on each of them, if any
        self.bodies: dict[str, Body] = {}
        self.gravity: Any = None
        self.restitution: Any = restitution
        #: the total energy (kinetic plus potential), an expression in q, q' and the
        #: parameters, if declared: ``biped-opt systems FILE --check`` tests the forces with it
        #: (:mod:`biped_opt.simulation.energy`)
        self.energy: Any = None
        self.constraints: dict[str, Any] = {}
        #: where each constraint touches, for drawing: a world point (x, y, z) and the
        #: direction its force lambda pushes (SYSTEMS.md Sec. 6)
        self.contact_points: dict[str, tuple[tuple[Any, Any, Any], tuple[Any, Any, Any]]] = {}
        #: how the system looks (SYSTEMS.md Sec. 6): body frames and shapes, by name
        self.frames: dict[str, Frame] = {}
        self.shapes: dict[str, Shape] = {}
        self.maneuvers: dict[str, ManeuverDescription] = {}
        #: optimal-control problems by name (see :mod:`biped_opt.control.problems`)
        self.problems: dict[str, dict[str, Any]] = {}
        #: what a system imported from a robot description keeps of it (for a URDF:
        #: :class:`biped_opt.systems.urdf.Imported`), None for one written with this API
        self.robot: Any = None
        self.source: str | None = None  #: the file a system was loaded from, for messages
        #: the files a system file read: itself, then modules beside it that it imported
        self.reads: tuple[Path, ...] = ()

    @classmethod
    def from_urdf(cls, source: str | Path, **options: Any) -> System:
        """A system of rigid bodies from a robot's URDF (a path or the URDF text itself):
        :func:`biped_opt.systems.urdf.system_from_urdf`, whose keyword options it takes
        (``base``, ``contacts``, ``lock``, ``posture``, ...; SYSTEMS.md Sec. 4a)."""
        return IMPORTERS["urdf"](source, **options)

    # -- building ---------------------------------------------------------------------------
    @property
    def coordinate_names(self) -> tuple[str, ...]:
        return tuple(str(c) for c in self.q)

    def constraint(self, name: str, expression: Any, *, at: Sequence[Any] | None = None,
                   normal: Sequence[Any] = (0, 0, 1)) -> System:
        """Unilateral constraint a_j(q) >= 0 named ``name`` (contact where it is 0). ``at``, the
        world point (x, y, z) where it touches, and ``normal``, the direction of its force,
        are for drawing only (the contact force's arrow)."""
        _check_name("constraint name", name, self.name)
        if name in self.constraints:
            raise SystemDescriptionError(f"{self.name}: constraint {name!r} is given twice")
        self.constraints[name] = expression
        if at is not None:
            self.contact_points[name] = (_triple(self, f"constraint {name!r}: at", at),
                                         _triple(self, f"constraint {name!r}: normal", normal))
        return self

    def body(self, name: str, mass: Any = 0, *, position: Sequence[Any] = (0, 0, 0),
             rotation: Any = None, inertia: Any = (0, 0, 0), parent: str | None = None,
             centre: Sequence[Any] = (0, 0, 0)) -> System:
        """A rigid body (see :class:`Body`), instead of giving ``mass_matrix``: the bodies
        form a tree (``parent``: a body declared before, None: the world), each coordinate
        moving one body relative to its parent (a joint: a hinge, a slider, a ball, a free
        base); M(q) is then the sum of the bodies' m Jv^T Jv + Jw^T I Jw, and their velocity
        products (Coriolis, centrifugal, gyroscopic) and weight (``gravity``) join the forces
        of every mode (SYSTEMS.md Sec. 1a). ``inertia`` is (Ixx, Iyy, Izz) or a symmetric
        3 x 3 matrix in the body's axes. A massless body is a frame between joints."""
        _check_name("body name", name, self.name)
        if name in self.bodies:
            raise SystemDescriptionError(f"{self.name}: body {name!r} is given twice")
        item = f"{self.name}: body {name!r}"
        if parent is not None and parent not in self.bodies:
            raise SystemDescriptionError(
                f"{item}: parent {parent!r} is not a body declared before it (bodies: "
                f"{', '.join(self.bodies) or 'none'})")
        matrix = _matrix3(item + ": inertia", inertia)
        if matrix != tuple(zip(*matrix)):
            raise SystemDescriptionError(f"{item}: inertia: must be symmetric")
        rot = None if rotation is None else _matrix3(item + ": rotation", rotation)
        self.bodies[name] = Body(name, mass, _triple(self, f"body {name!r}: position", position),
                                 rot, matrix, parent,
                                 _triple(self, f"body {name!r}: centre", centre))
        return self

    def frame(self, name: str, *, x: Any = 0, y: Any = 0, z: Any = 0, roll: Any = 0,
              pitch: Any = 0, yaw: Any = 0) -> System:
        """Declare a body frame (see :class:`Frame`); its transform from ``world`` is
        published on ``/tf`` and drawn by the animations."""
        _check_name("frame name", name, self.name)
        if name == WORLD or name in self.frames:
            raise SystemDescriptionError(
                f"{self.name}: frame {name!r} is " + ("the fixed frame" if name == WORLD
                                                       else "given twice"))
        self.frames[name] = Frame(name, (x, y, z), (roll, pitch, yaw))
        return self

    def box(self, name: str, frame: str, size: Sequence[Any], *,
            color: Sequence[float] | None = None) -> System:
        """A box of edge lengths ``size`` (x, y, z) centred on ``frame``'s origin."""
        return self._shape(name, "box", frame, _triple(self, f"box {name!r}: size", size), (),
                           color)

    def sphere(self, name: str, frame: str, radius: Any, *,
               color: Sequence[float] | None = None) -> System:
        """A sphere of ``radius`` centred on ``frame``'s origin."""
        return self._shape(name, "sphere", frame, (radius,), (), color)

    def line(self, name: str, points: Sequence[Sequence[Any]], *, width: Any = 0.02,
             color: Sequence[float] | None = None) -> System:
        """A polyline through the world ``points`` (each (x, y, z), expressions of q): a leg,
        a link, a spring."""
        pts = tuple(_triple(self, f"line {name!r}: point", p) for p in points)
        if len(pts) < 2:
            raise SystemDescriptionError(
                f"{self.name}: line {name!r}: needs at least two points, got {len(pts)}")
        return self._shape(name, "line", WORLD, (width,), pts, color)

    def _shape(self, name: str, kind: str, frame: str, size: tuple[Any, ...],
               points: tuple[tuple[Any, Any, Any], ...], color: Sequence[float] | None
               ) -> System:
        _check_name("shape name", name, self.name)
        if name in self.shapes:
            raise SystemDescriptionError(f"{self.name}: shape {name!r} is given twice")
        if kind != "line" and frame not in self.frames:
            raise SystemDescriptionError(
                f"{self.name}: {kind} {name!r}: unknown frame {frame!r} (frames: "
                f"{', '.join(self.frames) or 'none; declare one with frame()'})")
        rgba = PALETTE[len(self.shapes) % len(PALETTE)] if color is None else tuple(color)
        if len(rgba) == 3:
            rgba = (*rgba, 1.0)
        if len(rgba) != 4 or not all(isinstance(c, (int, float)) and not isinstance(c, bool)
                                     and 0 <= c <= 1 for c in rgba):
            raise SystemDescriptionError(
                f"{self.name}: {kind} {name!r}: color must be 3 or 4 numbers in [0, 1], "
                f"got {color!r}")
        self.shapes[name] = Shape(name, kind, frame, size, points,
                                  tuple(float(c) for c in rgba))  # type: ignore[arg-type]
        return self

    def maneuver(self, name: str, *, initial: Mapping[Any, Any], terminal: Any, outcome: Any,
                 mode: Iterable[str] = (), armed_after: str | None = None,
                 final_mode: Iterable[str] | None = None,
                 s_range: tuple[float, float] = (-1.0, 1.0), description: str = "",
                 max_events: int = DEFAULT_MAX_EVENTS, horizon: float = DEFAULT_HORIZON,
                 **extra: Any) -> System:
        """Add a maneuver (see :class:`ManeuverDescription`)."""
        _check_budget(self.name, name, max_events, horizon)
        _check_name("maneuver name", name, self.name)
        if name in self.maneuvers:
            raise SystemDescriptionError(f"{self.name}: maneuver {name!r} is given twice")
        if armed_after not in (None, "touchdown"):
            raise SystemDescriptionError(
                f"{self.name}: maneuver {name!r}: armed_after must be None or 'touchdown', "
                f"got {armed_after!r}")
        lo, hi = (float(v) for v in s_range)
        if not lo < hi:
            raise SystemDescriptionError(
                f"{self.name}: maneuver {name!r}: s_range must have lo < hi, got {s_range!r}")
        self.maneuvers[name] = ManeuverDescription(
            name=name, initial=dict(initial), mode=frozenset(mode), terminal=terminal,
            outcome=outcome, armed_after=armed_after,
            final_mode=None if final_mode is None else frozenset(final_mode),
            s_range=(lo, hi), description=description, extra=dict(extra),
            max_events=max_events, horizon=float(horizon))
        return self

    def problem(self, name: str, *, maneuver: str, decisions: Mapping[str, Sequence[float]],
                weights: Mapping[str, float] | None = None,
                fixed: Mapping[str, float] | None = None, target: float = 0.0,
                outcome_weight: float = 1.0,
                final_state: Mapping[str, Sequence[float]] | None = None) -> System:
        """Declare an optimal-control problem on this system: minimise
        outcome_weight (outcome - target)^2 + sum W (y_k(t_f) - r_k)^2 + sum alpha_i u_i^2 over
        ``decisions`` (input -> (lower, upper)); ``weights`` are the alpha_i, ``fixed`` the other
        inputs, ``final_state`` maps coordinates or velocities to (W, r). Checked when used
        (:func:`biped_opt.control.problems.get_problem`)."""
        _check_name("problem name", name, self.name)
        if name in self.problems:
            raise SystemDescriptionError(f"{self.name}: problem {name!r} is given twice")
        self.problems[name] = {
            "maneuver": maneuver, "decisions": dict(decisions), "weights": dict(weights or {}),
            "fixed": dict(fixed or {}), "target": target, "outcome_weight": outcome_weight,
            "final_state": dict(final_state or {})}
        return self

    def where(self) -> str:
        """How messages name this system: its file when it came from one."""
        return f"{self.source}: {self.name}" if self.source else self.name

    def __repr__(self) -> str:
        return (f"System({self.name!r}, d={len(self.q)}, constraints={list(self.constraints)}, "
                f"inputs={list(self.u.names())}, maneuvers={list(self.maneuvers)})")


def _check_name(kind: str, name: Any, system: str) -> None:
    if not isinstance(name, str) or not _NAME.match(name) or keyword.iskeyword(name):
        raise SystemDescriptionError(
            f"{system}: {kind} must be a Python identifier, got {name!r}")


def _triple(system: System, what: str, value: Any) -> tuple[Any, Any, Any]:
    """Three expressions (x, y, z)."""
    try:
        items = tuple(value)
    except TypeError:
        items = ()
    if len(items) != 3:
        raise SystemDescriptionError(f"{system.name}: {what} must be (x, y, z), got {value!r}")
    return items


def _matrix3(item: str, value: Any) -> tuple[tuple[Any, ...], ...]:
    """A 3 x 3 matrix from one, or from its diagonal (three entries)."""
    try:
        m = sp.Matrix(value)
    except (TypeError, ValueError, sp.SympifyError) as exc:
        raise SystemDescriptionError(f"{item}: not a matrix ({exc})") from None
    if m.shape in ((3, 1), (1, 3)):
        m = sp.diag(*m)
    if m.shape != (3, 3):
        raise SystemDescriptionError(
            f"{item}: must be 3 x 3 or three diagonal entries, got {m.shape[0]}x{m.shape[1]}")
    return tuple(tuple(m[i, j] for j in range(3)) for i in range(3))


def _check_budget(system: str, maneuver: str, max_events: Any, horizon: Any) -> None:
    """A maneuver's event budget is a positive integer, its horizon a positive number."""
    if isinstance(max_events, bool) or not isinstance(max_events, int) or max_events < 1:
        raise SystemDescriptionError(
            f"{system}: maneuver {maneuver!r}: max_events must be a positive integer, "
            f"got {max_events!r}")
    if isinstance(horizon, bool) or not isinstance(horizon, (int, float)) \
            or not math.isfinite(horizon) or horizon <= 0:
        raise SystemDescriptionError(
            f"{system}: maneuver {maneuver!r}: horizon must be a positive number, "
            f"got {horizon!r}")
