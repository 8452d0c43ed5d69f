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

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import sympy as sp

from biped_opt.systems.description import ManeuverDescription, System, SystemDescriptionError
from biped_opt.systems.mechanics import MechanicalSystem

__all__ = ["DerivedSystem", "DerivedManeuver", "NumericSystem", "derive", "mode_mask",
           "mode_name"]

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
class DerivedSystem:
    """A checked description and its derived quantities (all SymPy)."""

    system: System
    mass_matrix: sp.Matrix  # (d, d)
    forces: tuple[sp.Matrix, ...]  # f_J for J = 0 .. 2^n - 1 (bit j: constraint j active)
    constraints: sp.Matrix  # (n,)
    jacobian: sp.Matrix  # Da, (n, d)
    jacobian_rate: sp.Matrix  # (d/dt Da) q', (n,)
    restitution: sp.Expr
    maneuvers: Mapping[str, DerivedManeuver]

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


def mode_name(mode: int, constraints: Sequence[str]) -> str:
    """A contact mode (bit j: constraint j active) by its constraints' names joined with "+"
    (``left+right``); the mode with none is ``air``."""
    names = [c for j, c in enumerate(constraints) if mode >> j & 1]
    return "+".join(names) if names else "air"


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
    q, dq = sp.Matrix(system.q), sp.Matrix(system.dq)
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
    da = a.jacobian(q) if n else sp.zeros(0, d)
    rate = ((da * dq).jacobian(q) * dq) if n else sp.zeros(0, 1)

    forces = []
    for mask in range(1 << n):
        active = frozenset(names[j] for j in range(n) if mask >> j & 1)
        label = "{" + ", ".join(sorted(active)) + "}"
        try:
            value = system.forces(active) if callable(system.forces) else system.forces
        except Exception as exc:  # the user's own code: say where it failed
            raise SystemDescriptionError(
                f"{where}: forces in mode {label}: {type(exc).__name__}: {exc}") from None
        f = matrix(f"forces in mode {label}", value, (d, 1))
        check_symbols(f"forces in mode {label}", f, state,
                      "a coordinate, velocity, parameter or input")
        forces.append(f)

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

    return DerivedSystem(system=system, mass_matrix=mass, forces=tuple(forces), constraints=a,
                         jacobian=da, jacobian_rate=rate, restitution=gamma,
                         maneuvers=maneuvers)


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

        self._mass = compile_(derived.mass_matrix, q)
        self._forces = [compile_(f, q + dq + u) for f in derived.forces]
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
        return np.array(self._mass(*q), dtype=np.float64).reshape(self.ndof, self.ndof)

    def forces(self, q: Array, dq: Array, u: Array, mode: int) -> Array:
        u = np.asarray(u, dtype=np.float64).ravel()
        return np.array(self._forces[mode](*q, *dq, *u), dtype=np.float64).reshape(self.ndof)

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
