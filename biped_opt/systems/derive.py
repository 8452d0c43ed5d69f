"""From a :class:`~biped_opt.systems.description.System` to the quantities of Eq. (1).

:func:`derive` checks a description and derives what the user never types: the constraint
Jacobian Da(q) and the velocity term (d/dt Da)(q, q') q' of the constraints' accelerations
(a_j'' = Da_j q'' + that term), and the forces of every one of the 2^n contact modes. Every
check names the system (and its file), the item and what is wrong.

:class:`NumericSystem` evaluates a derived system with NumPy (SymPy's ``lambdify``) at given
parameter values. It is a :class:`~biped_opt.systems.mechanics.MechanicalSystem`, so the generic
Eq. (1) routines (reaction forces, accelerations, impact map) apply to it directly; it is the
reference the compiled kernels are checked against, not the fast path.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import sympy as sp

from biped_opt.systems.description import ManeuverDescription, System, SystemDescriptionError
from biped_opt.systems.mechanics import MechanicalSystem

__all__ = ["DerivedSystem", "DerivedManeuver", "DerivedBody", "NumericSystem", "derive",
           "mode_mask"]

Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class DerivedManeuver:
    """A maneuver with every expression checked: the initial state (2 d entries), the terminal
    guard and the outcome, and the modes as bit masks."""

    description: ManeuverDescription
    initial: tuple[sp.Expr, ...]
    mode: int
    terminal: sp.Expr
    outcome: sp.Expr
    final_mode: int | None


@dataclass(frozen=True)
class DerivedBody:
    """A rigid body of a tree (SYSTEMS.md Sec. 1a): its mass, inertia I (3 x 3, its own axes,
    parameters only) and centre (its own frame), the gravity g acting on it (world, zeros if
    none), its parent's index (-1: the world) and its frame's pose in the parent's, the
    relative angular velocity (parent's axes) and origin velocity per coordinate rate
    (3 x d each) and their accelerations at q'' = 0, and its frame's axes and origin in the
    world. The compiled code follows the tree from these (``biped_opt.codegen.tree.BodyTree``).

    In world terms (for :class:`NumericSystem` and the symbolic M and forces, derived when
    first asked for): the centre's velocity Jacobian Jv (3 x d, world axes), the angular
    velocity's Jw (3 x d, the body's axes: w = Jw q'), and av = (d/dt Jv) q', aw = (d/dt Jw) q'
    at q'' = 0; the body adds m Jv^T Jv + Jw^T I Jw to M and
    -(Jv^T m (av - g) + Jw^T (I aw + w x I w)) to the forces of every mode."""

    name: str
    mass: sp.Expr
    inertia: sp.Matrix  # (3, 3)
    gravity: sp.Matrix  # (3,)
    parent: int
    rel_rotation: sp.Matrix  # (3, 3)
    rel_position: sp.Matrix  # (3,)
    centre: sp.Matrix  # (3,)
    rel_jw: sp.Matrix  # (3, d)
    rel_jp: sp.Matrix  # (3, d)
    rel_aw: sp.Matrix  # (3,)
    rel_ap: sp.Matrix  # (3,)
    axes: sp.Matrix  # (3, 3)
    origin: sp.Matrix  # (3,)
    calculus: _Calculus = field(repr=False, compare=False)

    @functools.cached_property
    def jv(self) -> sp.Matrix:
        position = self.origin + self.axes * self.centre
        return sp.Matrix([[partial(position[r]) for partial in self.calculus.partial]
                          for r in range(3)])

    @functools.cached_property
    def jw(self) -> sp.Matrix:
        return _spin_jacobian(self.axes, self.calculus.partial, body_axes=True)

    @functools.cached_property
    def av(self) -> sp.Matrix:
        return (self.jv * self.calculus.dq).applyfunc(self.calculus.along)

    @functools.cached_property
    def aw(self) -> sp.Matrix:
        return (self.jw * self.calculus.dq).applyfunc(self.calculus.along)

    # (both unevaluated: SymPy's distributing of coefficients over these large sums would
    # take longer than the whole derivation; the values are the same)

    def mass_matrix(self) -> sp.Matrix:
        with sp.evaluate(False):
            return self.mass * self.jv.T * self.jv + self.jw.T * self.inertia * self.jw

    def forces(self, dq: sp.Matrix) -> sp.Matrix:
        """The generalised force of the body's inertia and weight at q'' = 0."""
        with sp.evaluate(False):
            w = self.jw * dq
            spin = self.inertia * w
            torque = self.inertia * self.aw + w.cross(spin)
            return -(self.jv.T * (self.mass * (self.av - self.gravity)) + self.jw.T * torque)


@dataclass(frozen=True)
class _Calculus:
    """A system's differentiators, shared by its derivation and its bodies' world terms."""

    partial: list[_Derivative]  # d/dq_k
    along: _Derivative  # d/dt at q'' = 0
    dq: sp.Matrix


@dataclass(frozen=True)
class DerivedSystem:
    """A checked description and its derived quantities (all SymPy)."""

    system: System
    given_mass: sp.Matrix | None  # (d, d): the description's M, None when it has bodies
    applied: tuple[sp.Matrix, ...]  # the forces it gives, for J = 0 .. 2^n - 1 (bit j: j on)
    constraints: sp.Matrix  # (n,)
    jacobian: sp.Matrix  # Da, (n, d)
    jacobian_rate: sp.Matrix  # (d/dt Da) q', (n,)
    restitution: sp.Expr
    maneuvers: Mapping[str, DerivedManeuver]
    #: the rigid bodies M and the forces are summed from (empty when M is given)
    bodies: tuple[DerivedBody, ...] = ()

    @functools.cached_property
    def mass_matrix(self) -> sp.Matrix:
        """M(q), (d, d): the given one, or the bodies' sum (formed only when asked for: the
        compiled code and :class:`NumericSystem` sum the bodies' parts numerically)."""
        if self.given_mass is not None:
            return self.given_mass
        mass = sp.zeros(self.ndof, self.ndof)
        for body in self.bodies:
            mass += body.mass_matrix()
        return mass

    @functools.cached_property
    def forces(self) -> tuple[sp.Matrix, ...]:
        """f_J for every mode J: the applied forces, plus the bodies' (when asked for, as
        :attr:`mass_matrix`)."""
        if not self.bodies:
            return self.applied
        dq = sp.Matrix(self.system.dq)
        inertial = sp.zeros(self.ndof, 1)
        for body in self.bodies:
            inertial += body.forces(dq)
        total: dict[sp.ImmutableMatrix, sp.Matrix] = {}  # (modes with equal forces share)
        for f in self.applied:
            total.setdefault(sp.ImmutableMatrix(f), f + inertial)
        return tuple(total[sp.ImmutableMatrix(f)] for f in self.applied)

    @property
    def ndof(self) -> int:
        return len(self.system.q)

    @property
    def nconstraints(self) -> int:
        return len(self.system.constraints)

    @property
    def constraint_names(self) -> tuple[str, ...]:
        return tuple(self.system.constraints)

    def numeric(self, **parameters: float) -> NumericSystem:
        """Evaluator at the defaults overridden by ``parameters``."""
        return NumericSystem(self, parameters)


def mode_mask(system: System, names: frozenset[str] | set[str] | tuple[str, ...]) -> int:
    """The bit mask of a set of constraint names (bit j: the j-th constraint declared)."""
    order = list(system.constraints)
    mask = 0
    for name in names:
        if name not in system.constraints:
            raise SystemDescriptionError(
                f"{system.where()}: unknown constraint {name!r} in a mode "
                f"(constraints: {', '.join(order) or 'none'})")
        mask |= 1 << order.index(name)
    return mask


def _normaliser(system: System) -> Callable[[Any], Any]:
    """A function that rewrites a user's expression into the system's own symbols: a symbol is
    matched by name whatever its assumptions (``sp.Symbol("m")`` is the parameter m), and
    ``sympy.physics.mechanics`` output is accepted as is: a dynamic symbol q(t) named like a
    coordinate becomes q, its time derivative the velocity q_dot (second derivatives are not a
    state and stay, to be reported as unknown)."""
    by_name = {str(sym): sym for sym in (*system.q, *system.dq, *system.p, *system.u, system.s)}
    coords = dict(zip((str(c) for c in system.q), zip(system.q, system.dq)))

    # the forces of 2^n modes repeat most entries (a leg's force where its input does not act):
    # each distinct expression is rewritten once (equal expressions have equal rewrites)
    memo: dict[Any, Any] = {}

    def normalise(expr: Any) -> Any:
        expr = sp.sympify(expr)
        if isinstance(expr, sp.MatrixBase):
            return expr.applyfunc(normalise)
        try:
            return memo[expr]
        except (KeyError, TypeError):
            pass
        out = _rewrite(expr)
        try:
            memo[expr] = out
        except TypeError:  # (an unhashable expression: not remembered)
            pass
        return out

    def _rewrite(expr: Any) -> Any:
        subs: dict[Any, Any] = {}
        for d in expr.atoms(sp.Derivative):
            f = d.expr
            name = getattr(getattr(f, "func", None), "__name__", None)
            if name in coords and len(d.variables) == 1 and len(f.args) == 1:
                subs[d] = coords[name][1]
        expr = expr.subs(subs) if subs else expr
        subs = {}
        for f in expr.atoms(sp.core.function.AppliedUndef):
            name = f.func.__name__
            if name in coords and len(f.args) == 1:
                subs[f] = coords[name][0]
        for sym in expr.free_symbols:
            if isinstance(sym, sp.Symbol) and str(sym) in by_name and sym != by_name[str(sym)]:
                subs[sym] = by_name[str(sym)]
        return expr.subs(subs) if subs else expr

    return normalise


def derive(system: System) -> DerivedSystem:
    """Check ``system`` and derive Da, (d/dt Da) q' and the forces of every mode."""
    where = system.where()
    normalise = _normaliser(system)
    d = len(system.q)
    dq = sp.Matrix(system.dq)
    params, inputs = set(system.p), set(system.u)
    config = set(system.q) | params
    state = config | set(system.dq) | inputs

    used: dict[Any, set[sp.Symbol]] = {}  # free symbols of each distinct entry, found once

    def free(expr: Any) -> set[sp.Symbol]:
        expr = sp.sympify(expr)
        if isinstance(expr, sp.MatrixBase):
            return set().union(*(free(e) for e in expr))
        if expr not in used:
            used[expr] = expr.free_symbols
        return used[expr]

    def check_symbols(item: str, expr: Any, allowed: set[sp.Symbol], what: str) -> None:
        unknown = sorted(str(s) for s in free(expr) - allowed)
        if unknown:
            raise SystemDescriptionError(
                f"{where}: {item}: uses {', '.join(unknown)}, which is not {what}")

    def matrix(item: str, value: Any, shape: tuple[int, int]) -> sp.Matrix:
        if value is None:
            raise SystemDescriptionError(f"{where}: {item}: not given")
        try:
            m = normalise(sp.Matrix(value))
        except (TypeError, ValueError, sp.SympifyError) as exc:
            raise SystemDescriptionError(f"{where}: {item}: not a matrix ({exc})") from None
        if shape[1] == 1 and m.shape == (1, shape[0]):
            m = m.T
        if m.shape != shape:
            want = f"{shape[0]}x{shape[1]}" if shape[1] != 1 else f"a vector of {shape[0]}"
            raise SystemDescriptionError(
                f"{where}: {item}: must be {want}, got {m.shape[0]}x{m.shape[1]}")
        return m

    # one differentiator per direction (each q_k, and the motion q'), shared by the bodies and
    # the constraints: a chain's links repeat their parents' terms, each is differentiated once
    partial = [_Derivative({system.q[k]: sp.Integer(1)}) for k in range(d)]
    along = _Derivative(dict(zip(system.q, system.dq)))
    bodies = _bodies(system, normalise, check_symbols, config, params, partial, along)
    if bodies:
        if system.mass_matrix is not None:
            raise SystemDescriptionError(
                f"{where}: mass_matrix: give either it or bodies, not both")
        mass = None
    else:
        if system.gravity is not None:
            raise SystemDescriptionError(f"{where}: gravity: acts on bodies, and none is given")
        mass = matrix("mass_matrix", system.mass_matrix, (d, d))
        check_symbols("mass_matrix", mass, config, "a coordinate or a parameter")
        if not (mass - mass.T).applyfunc(sp.simplify).is_zero_matrix:
            raise SystemDescriptionError(f"{where}: mass_matrix: must be symmetric")

    names = list(system.constraints)
    n = len(names)
    constraints = {k: normalise(v) for k, v in system.constraints.items()}
    for name, expr in constraints.items():
        check_symbols(f"constraint {name!r}", expr, config, "a coordinate or a parameter")
    a = sp.Matrix([constraints[k] for k in names]) if n else sp.zeros(0, 1)
    da = sp.Matrix(n, d, lambda j, k: partial[k](a[j])) if n else sp.zeros(0, d)
    rate = (da * dq).applyfunc(along) if n else sp.zeros(0, 1)

    applied = []
    for mask in range(1 << n):
        active = frozenset(names[j] for j in range(n) if mask >> j & 1)
        label = "{" + ", ".join(sorted(active)) + "}"
        if bodies and system.forces is None:
            value = sp.zeros(d, 1)  # (the bodies' weight may be all there is)
        else:
            try:
                value = system.forces(active) if callable(system.forces) else system.forces
            except Exception as exc:  # the user's own code: say where it failed
                raise SystemDescriptionError(
                    f"{where}: forces in mode {label}: {type(exc).__name__}: {exc}") from None
        f = matrix(f"forces in mode {label}", value, (d, 1))
        check_symbols(f"forces in mode {label}", f, state,
                      "a coordinate, velocity, parameter or input")
        applied.append(f)

    gamma = normalise(system.restitution)
    check_symbols("restitution", gamma, params, "a parameter")

    maneuvers = {}
    for name, m in system.maneuvers.items():
        item = f"maneuver {name!r}"
        coords = list(system.q) + list(system.dq)
        initial = []
        unknown = [k for k in m.initial if normalise(k) not in coords]
        if unknown:
            raise SystemDescriptionError(
                f"{where}: {item}: initial: {unknown[0]!s} is not a coordinate or velocity")
        initial_given = {normalise(k): v for k, v in m.initial.items()}
        for c in coords:
            expr = normalise(initial_given.get(c, 0))
            check_symbols(f"{item}: initial {c}", expr, params | {system.s},
                          f"a parameter or {system.s}")
            initial.append(expr)
        terminal = normalise(m.terminal)
        outcome = normalise(m.outcome)
        check_symbols(f"{item}: terminal", terminal, config | set(system.dq) | inputs,
                      "a coordinate, velocity, parameter or input")
        check_symbols(f"{item}: outcome", outcome, config | set(system.dq),
                      "a coordinate, velocity or parameter")
        try:
            mode = mode_mask(system, m.mode)
            final = None if m.final_mode is None else mode_mask(system, m.final_mode)
        except SystemDescriptionError as exc:
            raise SystemDescriptionError(f"{item}: {exc}") from None
        maneuvers[name] = DerivedManeuver(m, tuple(initial), mode, terminal, outcome, final)

    return DerivedSystem(system=system, given_mass=mass, applied=tuple(applied), constraints=a,
                         jacobian=da, jacobian_rate=rate, restitution=gamma,
                         maneuvers=maneuvers, bodies=bodies)


class _Derivative:
    """The derivative of expressions along ``direction`` (symbol: its rate), sum of
    de/ds direction[s], memoised on subexpressions: SymPy's ``diff`` walks an expression as a
    tree (each shared subexpression again, and its free symbols again at every node), which
    takes minutes for the position of a 3-D robot's foot; this walks it as the graph it is.
    The rules are the textbook ones; a function it does not know goes to ``diff``."""

    def __init__(self, direction: Mapping[sp.Symbol, sp.Expr]) -> None:
        self.direction = dict(direction)
        self.memo: dict[sp.Basic, sp.Expr] = {}

    def __call__(self, e: Any) -> sp.Expr:
        e = sp.sympify(e)
        hit = self.memo.get(e)
        if hit is None:
            hit = self.memo[e] = self._rule(e)
        return hit

    def _rule(self, e: sp.Basic) -> sp.Expr:
        if e.is_Symbol:
            return self.direction.get(e, sp.Integer(0))
        if e.is_Atom:
            return sp.Integer(0)
        if e.is_Add:
            return sp.Add(*(self(a) for a in e.args))
        if e.is_Mul:
            args = e.args
            terms = []
            for i, a in enumerate(args):
                da = self(a)
                if da != 0:
                    terms.append(sp.Mul(*args[:i], da, *args[i + 1:]))
            return sp.Add(*terms)
        if e.is_Pow:
            base, power = e.args
            db, dp = self(base), self(power)
            if dp == 0:
                return sp.Integer(0) if db == 0 else power * base ** (power - 1) * db
            return e * (dp * sp.log(base) + power * db / base)
        if isinstance(e, (sp.sin, sp.cos)):
            da = self(e.args[0])
            if da == 0:
                return sp.Integer(0)
            return (sp.cos(e.args[0]) if isinstance(e, sp.sin) else -sp.sin(e.args[0])) * da
        return sp.Add(*(e.diff(s) * v for s, v in self.direction.items()))


def _check_rotation(system: System, item: str, rot: sp.Matrix) -> None:
    """R^T R = I and det R = 1 at a few arbitrary configurations (default parameters): a
    symbolic proof would cost more than the whole derivation."""
    rng = np.random.default_rng(0)
    values = {system.p[k]: v for k, v in system.defaults.items()}
    f = sp.lambdify(list(system.q) + list(values), rot, "numpy")
    for _ in range(3):
        r = np.array(f(*rng.uniform(-2.0, 2.0, len(system.q)), *values.values()), dtype=float)
        if not (np.allclose(r.T @ r, np.eye(3), rtol=0, atol=1e-9)
                and abs(np.linalg.det(r) - 1) < 1e-9):
            raise SystemDescriptionError(
                f"{system.where()}: {item}: rotation: not a rotation matrix (R^T R = I, "
                "det R = 1) at every configuration")


def _spin_jacobian(rotation: sp.Matrix, partial: list[_Derivative], *, body_axes: bool
                   ) -> sp.Matrix:
    """The angular velocity of a frame turned by ``rotation`` per coordinate rate (3 x d):
    column k read off the skew matrix R^T dR/dq_k (in the frame's own axes) or dR/dq_k R^T
    (in the axes ``rotation`` is given in) below its diagonal, (w^_21, w^_02, w^_10); only
    those three entries are formed."""
    out = sp.zeros(3, len(partial))
    for k, along_k in enumerate(partial):
        rate = rotation.applyfunc(along_k)
        if rate.is_zero_matrix:
            continue
        # both are sum_t a[t, i] b[t, j]: (R, dR) in the frame's axes, (dR^T, R^T) else
        a, b = (rotation, rate) if body_axes else (rate.T, rotation.T)
        for r, (i, j) in enumerate(((2, 1), (0, 2), (1, 0))):
            out[r, k] = sum(a[t, i] * b[t, j] for t in range(3))
    return out


def _bodies(system: System, normalise: Callable[[Any], Any],
            check_symbols: Callable[[str, Any, set[sp.Symbol], str], None],
            config: set[sp.Symbol], params: set[sp.Symbol], partial: list[_Derivative],
            along: _Derivative) -> tuple[DerivedBody, ...]:
    """Each body's pose relative to its parent, its relative angular and origin velocities per
    coordinate rate and their accelerations at q'' = 0, and its world pose (see
    :class:`DerivedBody`), by differentiating its position and rotation: w^ = R' R^T (the
    relative angular velocity in the parent's axes, read off the skew matrix below its
    diagonal as (w^_21, w^_02, w^_10)), and d/dt (J q') = (d(J q')/dq) q'."""
    where = system.where()
    dq = sp.Matrix(system.dq)
    d = len(system.q)
    calculus = _Calculus(partial, along, dq)
    gravity = sp.zeros(3, 1)
    if system.gravity is not None:
        try:
            gravity = normalise(sp.Matrix(list(system.gravity)))
        except (TypeError, ValueError, sp.SympifyError) as exc:
            raise SystemDescriptionError(f"{where}: gravity: not a vector ({exc})") from None
        if gravity.shape != (3, 1):
            raise SystemDescriptionError(f"{where}: gravity: must be (x, y, z)")
        check_symbols("gravity", gravity, params, "a parameter")
    out: list[DerivedBody] = []
    index: dict[str, int] = {}
    mover: dict[sp.Symbol, str] = {}  # which body each coordinate moves
    for body in system.bodies.values():
        item = f"body {body.name!r}"
        mass = normalise(body.mass)
        check_symbols(f"{item}: mass", mass, params, "a parameter")
        inertia = normalise(sp.Matrix(body.inertia))
        check_symbols(f"{item}: inertia", inertia, params, "a parameter")
        centre = normalise(sp.Matrix(body.centre))
        check_symbols(f"{item}: centre", centre, params, "a parameter")
        offset = normalise(sp.Matrix(body.position))
        check_symbols(f"{item}: position", offset, config, "a coordinate or a parameter")
        if body.rotation is None:
            turn = sp.eye(3)
        else:
            turn = normalise(sp.Matrix(body.rotation))
            check_symbols(f"{item}: rotation", turn, config, "a coordinate or a parameter")
            _check_rotation(system, item, turn)
        for c in (offset.free_symbols | turn.free_symbols) & set(system.q):
            # (a coordinate may move several bodies: a mimic joint's followers turn with it)
            mover.setdefault(c, body.name)
        # relative to the parent: the angular velocity (parent's axes, w^ = R_rel' R_rel^T)
        # and the origin's velocity per coordinate rate, and their accelerations at q'' = 0
        rel_jw = _spin_jacobian(turn, partial, body_axes=False)
        rel_jp = sp.Matrix([[partial[k](offset[r]) for k in range(d)] for r in range(3)])
        rel_aw = (rel_jw * dq).applyfunc(along)
        rel_ap = (rel_jp * dq).applyfunc(along)
        # in the world: the frame's axes and origin
        parent = -1 if body.parent is None else index[body.parent]
        if parent < 0:
            axes, origin = turn, offset
        else:
            up = out[parent]
            axes, origin = up.axes * turn, up.origin + up.axes * offset
        index[body.name] = len(out)
        out.append(DerivedBody(body.name, mass, inertia, gravity, parent, turn, offset, centre,
                               rel_jw, rel_jp, rel_aw, rel_ap, axes, origin, calculus))
    idle = [str(c) for c in system.q if c not in mover] if out else []
    if idle:
        raise SystemDescriptionError(
            f"{where}: coordinate {idle[0]} moves no body: M would be singular (every "
            "coordinate of a system of bodies moves one of them)")
    return tuple(out)


class NumericSystem(MechanicalSystem):
    """A derived system evaluated with NumPy at fixed parameter values (see the module
    docstring). Inputs are given as a vector in the order of ``System.u``."""

    def __init__(self, derived: DerivedSystem, parameters: Mapping[str, float] | None = None
                 ) -> None:
        system = derived.system
        values = dict(system.defaults)
        for key, value in (parameters or {}).items():
            if key not in values:
                raise SystemDescriptionError(
                    f"{system.where()}: unknown parameter {key!r} "
                    f"(parameters: {', '.join(values) or 'none'})")
            values[key] = float(value)
        self.derived = derived
        self.values = values
        self.ndof = derived.ndof
        self.nconstraints = derived.nconstraints
        subs = {system.p[k]: v for k, v in values.items()}
        q, dq, u = list(system.q), list(system.dq), list(system.u)

        def compile_(expr: Any, args: list[Any]) -> Callable[..., Any]:
            return sp.lambdify(args, sp.sympify(expr).subs(subs), modules="numpy", cse=True)

        self._bodies = _NumericBodies(derived, subs) if derived.bodies else None
        if self._bodies is None:
            self._mass = compile_(derived.mass_matrix, q)
        distinct: dict[sp.ImmutableMatrix, Callable[..., Any]] = {}  # (modes that share forces)
        for f in derived.applied:
            distinct.setdefault(sp.ImmutableMatrix(f), compile_(f, q + dq + u))
        self._forces = [distinct[sp.ImmutableMatrix(f)] for f in derived.applied]
        self._a = compile_(derived.constraints, q)
        self._da = compile_(derived.jacobian, q)
        self._rate = compile_(derived.jacobian_rate, q + dq)
        self._gamma = float(derived.restitution.subs(subs))
        self._initial = {name: compile_(sp.Matrix(m.initial), [system.s])
                         for name, m in derived.maneuvers.items()}

    @property
    def restitution(self) -> float:
        return self._gamma

    def mass_matrix(self, q: Array) -> Array:
        if self._bodies is not None:
            return self._bodies.mass_matrix(q)
        return np.array(self._mass(*q), dtype=np.float64).reshape(self.ndof, self.ndof)

    def forces(self, q: Array, dq: Array, u: Array, mode: int) -> Array:
        u = np.asarray(u, dtype=np.float64).ravel()
        f = np.array(self._forces[mode](*q, *dq, *u), dtype=np.float64).reshape(self.ndof)
        return f if self._bodies is None else f + self._bodies.forces(q, dq)

    def constraints(self, q: Array) -> Array:
        return np.array(self._a(*q), dtype=np.float64).reshape(self.nconstraints)

    def constraint_jacobian(self, q: Array) -> Array:
        return np.array(self._da(*q), dtype=np.float64).reshape(self.nconstraints, self.ndof)

    def constraint_jacobian_rate(self, q: Array, dq: Array) -> Array:
        return np.array(self._rate(*q, *dq), dtype=np.float64).reshape(self.nconstraints)

    def initial_state(self, maneuver: str, s: float) -> tuple[Array, int]:
        """(q, q') at s, and the initial mode, of ``maneuver``."""
        try:
            fill = self._initial[maneuver]
        except KeyError:
            raise SystemDescriptionError(
                f"{self.derived.system.where()}: unknown maneuver {maneuver!r} (maneuvers: "
                f"{', '.join(self._initial) or 'none'})") from None
        y0 = np.array(fill(float(s)), dtype=np.float64).reshape(2 * self.ndof)
        return y0, self.derived.maneuvers[maneuver].mode


class _NumericBodies:
    """The bodies' parts of M and the forces (:class:`DerivedBody`), from their Jacobians and
    accelerations evaluated with NumPy and summed as matrices."""

    def __init__(self, derived: DerivedSystem, subs: Mapping[sp.Symbol, float]) -> None:
        self.d = derived.ndof
        system = derived.system
        parts = []
        for b in derived.bodies:
            parts += [b.jv, b.jw, b.av, b.aw]
        self._parts = sp.lambdify([list(system.q), list(system.dq)],
                                  [m.xreplace(subs) for m in parts], "numpy", cse=True)
        self.constants = [(float(sp.sympify(b.mass).xreplace(subs)),
                           np.array(b.inertia.xreplace(subs), dtype=np.float64),
                           np.array(b.gravity.xreplace(subs), dtype=np.float64).ravel())
                          for b in derived.bodies]

    def _evaluate(self, q: Array, dq: Array) -> list[tuple[Array, Array, Array, Array]]:
        values = self._parts(list(q), list(dq))
        out = []
        for k in range(len(self.constants)):
            jv, jw, av, aw = (np.array(v, dtype=np.float64) for v in values[4 * k:4 * k + 4])
            out.append((jv.reshape(3, self.d), jw.reshape(3, self.d), av.ravel(), aw.ravel()))
        return out

    def mass_matrix(self, q: Array) -> Array:
        m = np.zeros((self.d, self.d))
        for (jv, jw, _av, _aw), (mass, inertia, _g) in zip(
                self._evaluate(q, np.zeros(self.d)), self.constants):
            m += mass * jv.T @ jv + jw.T @ inertia @ jw
        return (m + m.T) / 2  # (symmetric to the last bit, as the compiled code's mirror)

    def forces(self, q: Array, dq: Array) -> Array:
        f = np.zeros(self.d)
        for (jv, jw, av, aw), (mass, inertia, g) in zip(self._evaluate(q, dq), self.constants):
            w = jw @ dq
            f -= jv.T @ (mass * (av - g)) + jw.T @ (inertia @ aw + np.cross(w, inertia @ w))
        return f
