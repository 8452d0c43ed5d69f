"""One-sided (Bouligand) derivatives of the outcomes of any compiled system (SYSTEMS.md Sec. 1).

The outcome o(x(t_f)) of a maneuver is piecewise smooth in p = (s, u): smooth while the order of
its contact events is fixed, kinked or discontinuous where events become simultaneous. This
module differentiates it exactly (to integration accuracy) along the trajectory that
:meth:`~biped_opt.simulation.compiled.CompiledSystem.simulate` computes, for any number d of
coordinates and n of constraints, the paper's biped included:

- **within a mode** the extended state x = (y, u) (inputs as constant parameters) carries
  Z = dx / dp, which solves Z' = D F_J(x) Z with F_J = (f_J, 0). The columns D F_J Z are
  fourth-order central differences of the compiled vector field along each column of Z (a
  difference per column, not per coordinate: 1 + m of them for m inputs), integrated with
  SciPy's DOP853 alongside y;
- **at an event** with guard g (a_j(q) in the air, the reaction lambda_j in contact, the
  terminal guard h), reset R (the impact Delta_J of Eq. (1b), or the identity) and vector
  fields F- (old mode, before the reset) and F+ (new mode, after it), Z jumps by the saltation
  matrix Xi = DR + (F+ - DR F-) Dg / (Dg F-). With restitution the mode after an impact excludes
  the constraints that separate at once (SYSTEMS.md Sec. 1), and F+ is that mode's field;
- **at the terminal event** h = 0, dx_f/dp = (I - F Dh / (Dh F)) Z, dt_f/dp = -Dh Z / (Dh F),
  and d o/dp = Do dx_f/dp.

Where several guards are at zero at once (a simultaneous event) the derivative depends on the
direction v of the perturbation: a perturbed trajectory meets the guards at times t + eps tau_i
+ o(eps) with the first-order time shifts tau_i = -Dg_i Z v / (Dg_i F), so the guards flip one
at a time in the order of tau, each with its own saltation matrix, and after each flip the
guards that are still at zero and moving toward it in the new mode are ordered again (the
rocking bar's ends flip left, right, left in one instant; n simultaneous events give up to n!
orders). Guards near zero but not at it (a point close to a simultaneous event) flip first in
the order in which they reach zero; tau only breaks ties. A guard that a flip leaves below zero
(a reaction that the new mode's force coupling made negative) flips at once. When the branch so
resolved ends in the state and mode the simulator reached, the simulated trajectory goes on;
otherwise the outcome jumps there and the branch's limiting trajectory is integrated on from the
event (with the variational equation, events located by SciPy). The result, Z v with Z the
branch's sensitivity, is the Bouligand derivative: linear on each branch, piecewise linear and
positively homogeneous in v.

Guard, reset and initial-state derivatives: Da (touchdown guards), d x0/ds, Dh and Do are
exact: SymPy differentiates the description once, and the generated functions are kept in the
cache (:mod:`biped_opt.codegen.gradients`, :meth:`CompiledSystem.gradients`); D lambda_j
(liftoff guards) and D_q of the impact are fourth-order central differences of the compiled
functions; D_q' of the impact is exact (the impact is linear in q').
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from biped_opt.codegen.status import SEPARATION_TOL
from biped_opt.errors import InvalidInputError, SimulationError
from biped_opt.simulation.compiled import CompiledSystem
from biped_opt.simulation.contacts import DependentContactsError, rank, require_independent
from biped_opt.simulation.options import DEFAULT_OPTIONS, SimulatorOptions
from biped_opt.simulation.trajectory import constraint_names

__all__ = [
    "OutcomeGradient",
    "outcome_gradient",
    "directional_derivative",
    "final_state_directional_derivative",
    "one_sided_derivatives",
    "VariationalOptions",
    "DEFAULT_VARIATIONAL",
    "saltation_matrix",
]

Array = npt.NDArray[np.float64]

#: step of the central differences, relative to the size of the perturbation's direction:
#: fourth-order truncation ~ STEP^4 and rounding ~ eps |f| / STEP balance near 1e-12
_STEP = 3e-4
#: a guard rate (Dg F) below this in size is no crossing: a foot that has just lifted off
#: (a_j = 0, a_j' = 0) does not touch down again in the same instant
_RATE_TOL = 1e-9
#: states that agree to this (relative) are the same branch point
_SAME_STATE = 1e-9
#: guards that reach zero within this time of each other reach it together (the simulator
#: locates event times to ~1e-13)
_TIE = 1e-12
#: what a refusal on dependent contacts names (biped_opt.simulation.contacts)
_METHOD = ("the B-derivative (the saltation matrices of Theorem 1's orderings of simultaneous "
           "events)")
#: flips in one instant before the resolution is declared a Zeno cascade
_MAX_FLIPS_PER_CONSTRAINT = 8
_STENCIL = ((2.0, -1.0), (1.0, 8.0), (-1.0, -8.0), (-2.0, 1.0))
_STENCIL_STEPS = np.array([step for step, _ in _STENCIL])
_STENCIL_WEIGHTS = np.array([weight for _, weight in _STENCIL])


@dataclass(frozen=True, kw_only=True)
class VariationalOptions:
    """Tolerances of the variational integration and of the branch bookkeeping."""

    rtol: float = 1e-11  # DOP853 relative tolerance on (y, Z)
    atol: float = 1e-12  # DOP853 absolute tolerance
    #: a guard within this of zero in the intermediate mode flips in the same instant
    zero_length_tol: float = 1e-8
    #: step of the central differences in u that give second derivatives of th_f
    second_order_step: float = 1e-3

    def __post_init__(self) -> None:
        for name in ("rtol", "atol", "zero_length_tol", "second_order_step"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InvalidInputError(f"{name} must be a positive number, got {value!r}")


DEFAULT_VARIATIONAL = VariationalOptions()


def saltation_matrix(
    dr: Array, f_minus: Array, f_plus: Array, dg: Array
) -> Array:
    """Xi = DR + (F+ - DR F-) Dg / (Dg F-), the first-order jump of the flow's sensitivity.

    ``dr``: reset Jacobian (n, n); ``f_minus``/``f_plus``: vector fields before/after the reset;
    ``dg``: guard gradient (n,). Raises SimulationError for a grazing event (Dg F- = 0).
    """
    rate = float(dg @ f_minus)
    if rate == 0.0 or not math.isfinite(rate):
        raise SimulationError("grazing event (guard rate 0): the saltation matrix is undefined")
    return dr + np.outer(f_plus - dr @ f_minus, dg) / rate


# --- results ------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class OutcomeGradient:
    """First-order sensitivities of one maneuver on one branch, with respect to the parameters
    ``names`` = ``(s, *inputs)`` of the system.

    ``gradient`` = d outcome / dp, ``state_gradient`` = d y_final / dp (2d rows), and
    ``time_gradient`` = d t_final / dp. Away from simultaneous events these are the derivatives
    of the smooth outcome; at them they are the linear piece of the Bouligand derivative that
    holds for ``direction`` (then ``outcome``, ``y_final`` and ``t_final`` are that branch's
    one-sided limits, which differ from the simulated values where the outcome jumps).
    """

    system: str
    maneuver: str
    s: float
    inputs: tuple[float, ...]
    names: tuple[str, ...]
    direction: Array | None
    outcome: float
    gradient: Array = field(repr=False)
    y_final: Array = field(repr=False)
    state_gradient: Array = field(repr=False)
    t_final: float
    time_gradient: Array = field(repr=False)
    #: the branch's contact modes in order (bit masks), zero-length ones included
    modes: tuple[int, ...]
    #: the constraints whose guards flipped, in order (``modes[k + 1]`` follows flip k)
    flips: tuple[int, ...]
    #: an instant had more than one flip: a nonsmooth point, or within zero_length_tol of one
    simultaneous: bool
    continued: bool  #: the branch left the simulated trajectory (the outcome jumps)
    nfev: int  #: right-hand-side evaluations of the variational equation

    def d(self, name: str) -> float:
        """d outcome / d ``name`` (s or an input) on this branch."""
        if name not in self.names:
            raise InvalidInputError(
                f"{self.system}: no parameter {name!r} (parameters: {', '.join(self.names)})")
        return float(self.gradient[self.names.index(name)])

    # the biped's names for the same things (its s is the initial pitch th0)
    @property
    def theta0(self) -> float:
        return self.s

    @property
    def d_theta0(self) -> float:
        """d outcome / d s."""
        return float(self.gradient[0])

    def d_input(self, name: str) -> float:
        """d outcome / d input ``name`` on this branch."""
        if name not in self.names[1:]:
            raise InvalidInputError(f"{self.system}: no input {name!r} "
                                    f"(inputs: {', '.join(self.names[1:]) or 'none'})")
        return self.d(name)

    @property
    def mode_sequence(self) -> tuple[int, ...]:
        return self.modes


# --- the description's gradients, per compiled system, maneuver and parameter values -----------
@dataclass(frozen=True)
class _Symbolic:
    jacobian: Callable[..., Any]  # Da(q)
    initial_rate: Callable[..., Any]  # d x0 / ds
    terminal_gradient: Callable[..., Any]  # D_(q, q', u) h
    outcome_gradient: Callable[..., Any]  # D_(q, q') o


_SYMBOLIC: weakref.WeakKeyDictionary[CompiledSystem, dict] = weakref.WeakKeyDictionary()


def _symbolic(compiled: CompiledSystem, maneuver: str) -> _Symbolic:
    """The gradients of ``maneuver`` (biped_opt.codegen.gradients) at the compiled system's
    parameter values."""
    key = (maneuver, tuple(sorted(compiled.parameters.items())))
    cache = _SYMBOLIC.setdefault(compiled, {})
    if key not in cache:
        module = compiled.gradients()
        values = tuple(compiled.parameters.values())  # (the declared order, as generated)
        k = compiled.code(maneuver)

        def bound(name: str) -> Callable[..., Any]:
            function = getattr(module, name)
            return lambda *args: function(*args, *values)

        cache[key] = _Symbolic(
            jacobian=bound("jacobian"), initial_rate=bound(f"initial_rate_{k}"),
            terminal_gradient=bound(f"terminal_gradient_{k}"),
            outcome_gradient=bound(f"outcome_gradient_{k}"))
    return cache[key]


# --- the model at one (system, maneuver, inputs) ------------------------------------------------
class _Model:
    """F_J, guards, resets and their derivatives over the extended state x = (y, u)."""

    def __init__(self, compiled: CompiledSystem, maneuver: str, u: Array) -> None:
        mod = compiled.module
        self.compiled = compiled
        self.mod = mod
        self.code = compiled.code(maneuver)
        self.sym = _symbolic(compiled, maneuver)
        self.p = compiled.prepared
        self.u = u  # width max(m, 1), as the compiled functions expect
        self.d = int(mod.NDOF)
        self.n = int(mod.NSTATE)
        self.ncon = int(mod.NCON)
        self.m = len(compiled.inputs)
        self.size = self.n + self.m  # extended state
        self.ncols = 1 + self.m  # parameters (s, u)
        self.terminal = self.ncon  # index of the terminal guard
        self.armed_after_touchdown = bool(mod.TERM_AFTER_TOUCHDOWN[self.code])
        self._lam = np.empty(max(self.ncon, 1))
        #: du/dp = [0 | I] (rows: inputs, columns: parameters)
        self.du = np.zeros((max(self.m, 1), self.ncols))
        self.du[: self.m, 1:] = np.eye(self.m)
        self.nfev = 0

    # vector fields --------------------------------------------------------------------------
    def field(self, mode: int, y: Array, u: Array | None = None) -> Array:
        """f_J(y, u), shape (2d,)."""
        out = np.empty(self.n)
        self.mod._field_at(self.p, mode, np.ascontiguousarray(y, dtype=np.float64), 0,
                           self.u if u is None else u, out, 0, self._lam, 0)
        self.nfev += 1
        return out

    def extended_field(self, mode: int, y: Array) -> Array:
        """F_J(x) = (f_J(y, u), 0), shape (2d + m,)."""
        return np.concatenate([self.field(mode, y), np.zeros(self.m)])

    def reactions(self, mode: int, y: Array, u: Array | None = None) -> Array:
        self.field(mode, y, u)
        return self._lam[: self.ncon].copy()

    def variational_rhs(self, mode: int, w: Array) -> Array:
        """d/dt of w = (y, Z_y) with Z_y = dy/dp (2d x (1 + m), row-major).

        Column c of Z_y' is D_y f Z_y[:, c] + D_u f du/dp[:, c]: the derivative of f along that
        column, by a fourth-order central difference whose step scales with the column
        (_STEP over the column's largest entry). The kernel's ``variational_field`` does it in
        one compiled call.
        """
        out = np.empty_like(w)
        field, sv = self.compiled.kernel_entry("variational_field")
        self.nfev += int(field(
            self.p, sv, mode, np.ascontiguousarray(w), self.u, self.du, _STEP, _STENCIL_STEPS,
            _STENCIL_WEIGHTS, out, self._lam))
        return out

    # guards ---------------------------------------------------------------------------------
    def enabled(self, touched: bool) -> list[int]:
        """The guards that can fire: every constraint's, and the terminal one once armed."""
        guards = list(range(self.ncon))
        if touched or not self.armed_after_touchdown:
            guards.append(self.terminal)
        return guards

    def guard(self, mode: int, y: Array, i: int, u: Array | None = None) -> float:
        """a_i in the air, lambda_i in contact, the terminal guard for i = n."""
        uu = self.u if u is None else u
        yc = np.ascontiguousarray(y, dtype=np.float64)
        if i == self.terminal:
            return float(self.mod.terminal_value(self.code, self.p, uu, yc, 0))
        if mode >> i & 1:
            return float(self.reactions(mode, yc, uu)[i])
        return float(self.mod.constraint_value(i, self.p, yc, 0))

    def guard_gradient(self, mode: int, y: Array, i: int) -> Array:
        """D_x of guard i over the extended state, shape (2d + m,)."""
        out = np.zeros(self.size)
        d, n, m = self.d, self.n, self.m
        if i == self.terminal:
            grad = np.asarray(self.sym.terminal_gradient(*y, *self.u[:m]), dtype=np.float64)
            out[:] = grad.ravel()
            return out
        if not mode >> i & 1:
            out[:d] = np.asarray(self.sym.jacobian(*y[:d]), dtype=np.float64).reshape(
                self.ncon, d)[i]
            return out
        x = np.concatenate([y, self.u[:m]])
        for k in range(self.size):
            h = _STEP * max(1.0, abs(x[k]))
            acc = 0.0
            for step, weight in _STENCIL:
                xx = x.copy()
                xx[k] += step * h
                uu = self.u.copy()
                uu[:m] = xx[n:]
                acc += weight * self.guard(mode, xx[:n], i, uu)
            out[k] = acc / (12.0 * h)
        return out

    # resets ---------------------------------------------------------------------------------
    def impact(self, mode: int, y: Array) -> Array:
        out = np.array(y, dtype=np.float64)
        self.mod.apply_impact(self.p, mode, out)
        return out

    def impact_jacobian(self, mode: int, y: Array) -> Array:
        """D_x of x -> (q, Delta_J(q) q', u): exact in q' (linear), differences in q."""
        d, n = self.d, self.n
        dr = np.eye(self.size)
        for k in range(d):
            unit = np.zeros(n)
            unit[:d] = y[:d]
            unit[d + k] = 1.0
            dr[d:n, d + k] = self.impact(mode, unit)[d:]
        for k in range(d):
            h = _STEP * max(1.0, abs(y[k]))
            acc = np.zeros(d)
            for step, weight in _STENCIL:
                yy = np.array(y, dtype=np.float64)
                yy[k] += step * h
                acc += weight * self.impact(mode, yy)[d:]
            dr[d:n, k] = acc / (12.0 * h)
        return dr

    def separated(self, entered: int, y_after: Array, touchdown: int) -> int:
        """The constraints of ``touchdown`` moving apart after the impact (they leave the
        mode at once when gamma > 0), as a bit mask."""
        rates = np.empty(max(self.ncon, 1))
        self.mod.constraint_rates(self.p, np.ascontiguousarray(y_after), 0, rates)
        tol = float(SEPARATION_TOL)
        return sum(1 << j for j in range(self.ncon) if touchdown >> j & 1 and rates[j] > tol)


# --- walking a branch ---------------------------------------------------------------------------
@dataclass
class _State:
    t: float
    mode: int
    y: Array
    z: Array  # extended sensitivity dx/dp, (2d + m, 1 + m)
    touched: bool
    modes: list[int]
    flips: list[int] = field(default_factory=list)
    simultaneous: bool = False
    continued: bool = False


class _Branch:
    """Carries (t, y, mode, Z) along the branch that ``direction`` selects."""

    def __init__(self, model: _Model, direction: Array | None, vopts: VariationalOptions,
                 options: SimulatorOptions, where: str) -> None:
        self.model = model
        self.v = direction
        self.vopts = vopts
        self.options = options
        self.where = where

    def _solve(self, st: _State, t1: float, events: list | None = None) -> Any:  # OdeResult
        mdl = self.model
        n = mdl.n
        w0 = np.concatenate([st.y, st.z[:n].ravel()])
        mode = st.mode

        def rhs(_t: float, w: Array) -> Array:
            return mdl.variational_rhs(mode, w)

        from scipy.integrate import solve_ivp

        sol = solve_ivp(rhs, (st.t, t1), w0, method="DOP853", rtol=self.vopts.rtol,
                        atol=self.vopts.atol, events=events)
        if sol.status < 0:
            raise SimulationError(f"{self.where}: variational integration failed: {sol.message}")
        return sol

    def _set(self, st: _State, t: float, w: Array) -> None:
        n = self.model.n
        st.t = t
        st.y = w[:n].copy()
        st.z = st.z.copy()
        st.z[:n] = w[n:].reshape(n, self.model.ncols)

    def flow(self, st: _State, t1: float) -> None:
        """Integrate (y, Z) in the current mode up to t1."""
        if t1 > st.t:
            sol = self._solve(st, t1)
            self._set(st, t1, sol.y[:, -1])

    def flow_to_event(self, st: _State) -> None:
        """Integrate (y, Z) in the current mode to its first guard crossing (a limiting branch
        trajectory that the simulator did not follow)."""
        mdl = self.model
        n = mdl.n
        events = []
        for i in mdl.enabled(st.touched):
            def g(_t: float, w: Array, i: int = i, mode: int = st.mode) -> float:
                return mdl.guard(mode, w[:n], i)
            g.terminal = True  # type: ignore[attr-defined]
            g.direction = -1.0  # type: ignore[attr-defined]
            events.append(g)
        sol = self._solve(st, self.options.t_end, events)
        if sol.status != 1:
            raise SimulationError(
                f"{self.where}: the branch continued from t = {st.t:.6g} reaches the horizon "
                f"t_end = {self.options.t_end} without an event")
        hits = [(float(te[0]), k) for k, te in enumerate(sol.t_events) if len(te)]
        t_e, k = min(hits)
        self._set(st, t_e, sol.y_events[k][0])

    def flip(self, st: _State, i: int) -> None:
        """Guard i (a constraint) flips at st.y: reset, new mode, saltation of Z."""
        mdl = self.model
        y = st.y
        bit = 1 << i
        touchdown = not st.mode & bit
        f_minus = mdl.extended_field(st.mode, y)
        dg = mdl.guard_gradient(st.mode, y, i)
        if touchdown:
            entered = st.mode | bit
            if entered.bit_count() >= 2 and rank(mdl.compiled, entered, y) < entered.bit_count():
                names = "+".join(constraint_names(entered, mdl.compiled.constraints))
                raise DependentContactsError(
                    f"{self.where}: the branch {None if self.v is None else self.v.tolist()} "
                    f"enters the contact mode {names}, whose constraints are dependent: "
                    f"{_METHOD} assumes independent constraints")
            y_after = mdl.impact(entered, y)
            mode = entered & ~mdl.separated(entered, y_after, bit)
            dr = mdl.impact_jacobian(entered, y)
            st.touched = True
        else:
            mode = st.mode & ~bit
            y_after = np.array(y, dtype=np.float64)
            dr = np.eye(mdl.size)
        xi = saltation_matrix(dr, f_minus, mdl.extended_field(mode, y_after), dg)
        st.z = xi @ st.z
        st.y = y_after
        st.mode = mode
        st.modes.append(mode)
        st.flips.append(i)

    def resolve(self, st: _State) -> bool:
        """Flip the guards at zero at st.t one at a time; True when the terminal guard is the
        one reached.

        The order: a reaction that the last flip made negative lifts at once; then the guards
        within ``zero_length_tol`` of zero and moving toward it, by the time they need to reach
        it at their current rate (a point near a simultaneous event has its own order), and
        among those that reach it together (within _TIE of each other) by the first-order time
        shifts along the direction. Without a direction such a tie is an error.
        """
        mdl = self.model
        tol = self.vopts.zero_length_tol
        flips = 0
        for _ in range(_MAX_FLIPS_PER_CONSTRAINT * (mdl.ncon + 1)):
            f = mdl.extended_field(st.mode, st.y)
            due: dict[int, float] = {}  # time to reach zero
            shift: dict[int, float] = {}  # first-order time shift along the direction
            for i in mdl.enabled(st.touched):
                g = mdl.guard(st.mode, st.y, i)
                if g < -tol and i != mdl.terminal and st.mode >> i & 1:
                    due[i], shift[i] = -math.inf, 0.0
                elif abs(g) <= tol:
                    dg = mdl.guard_gradient(st.mode, st.y, i)
                    rate = float(dg @ f)
                    if rate < -_RATE_TOL:
                        due[i] = max(g, 0.0) / -rate
                        shift[i] = 0.0 if self.v is None else -float(dg @ (st.z @ self.v)) / rate
            if not due:
                return False
            if len(due) > 1 or flips:
                st.simultaneous = True
            soonest = min(due.values())
            tied = [i for i in due if due[i] <= soonest + _TIE]
            if len(tied) > 1 and soonest > -math.inf and self.v is None:
                raise SimulationError(
                    f"{self.where}: events are simultaneous at t = {st.t:.12g} (guards "
                    f"{tied} at zero): the outcome is not differentiable there in general; "
                    f"give a direction to select a branch")
            first = min(tied, key=lambda i: (shift[i], i))  # then the lower index
            if first == mdl.terminal:
                return True
            self.flip(st, first)
            flips += 1
        raise SimulationError(f"{self.where}: more than {flips} flips in one instant at "
                              f"t = {st.t:.12g} (a Zeno cascade)")


def _same(a: Array, b: Array) -> bool:
    return bool(np.all(np.abs(a - b) <= _SAME_STATE * (1.0 + np.abs(b))))


def _direction(v: npt.ArrayLike | None, ncols: int, names: tuple[str, ...]) -> Array | None:
    if v is None:
        return None
    try:
        out = np.asarray(v, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise InvalidInputError(f"direction must be numbers, got {v!r}") from None
    if out.size != ncols or not np.all(np.isfinite(out)):
        raise InvalidInputError(
            f"direction must be {ncols} finite numbers over ({', '.join(names)}), got {v!r}")
    return out


def outcome_gradient(
    compiled: CompiledSystem,
    maneuver: str,
    s: float,
    inputs: Any = None,
    *,
    direction: npt.ArrayLike | None = None,
    options: SimulatorOptions = DEFAULT_OPTIONS,
    variational: VariationalOptions = DEFAULT_VARIATIONAL,
) -> OutcomeGradient:
    """Gradient of ``maneuver``'s outcome, final state and final time w.r.t. ``(s, *inputs)``.

    ``inputs`` as for :meth:`CompiledSystem.simulate`. Without ``direction`` no two guards may
    reach zero together (else SimulationError says so; events a little apart are fine, each
    in its order); with it (a vector over
    ``(s, *inputs)``) the result is the gradient of the branch the direction selects, which at a
    simultaneous event is the linear piece of the Bouligand derivative for that direction.
    Raises SimulationError when the maneuver does not reach its terminal event.
    """
    if not isinstance(compiled, CompiledSystem):
        raise InvalidInputError(f"compiled must be a CompiledSystem, got {compiled!r}")
    code = compiled.code(maneuver)
    u = compiled.input_vector(inputs)
    names = ("s", *compiled.inputs)
    v = _direction(direction, len(names), names)
    s = float(s)
    where = f"{compiled.where()}: {maneuver} at s = {s!r}"
    traj = compiled.simulate(maneuver, s, u, options=options)
    if not traj.success:
        raise SimulationError(f"{where}: the simulation ended with status {traj.status.name}")
    require_independent(compiled, traj, _METHOD)
    model = _Model(compiled, maneuver, u)
    n, m = model.n, model.m
    y0 = np.zeros(n)
    compiled.module.initial_state(code, s, model.p, y0)
    z0 = np.zeros((model.size, model.ncols))
    z0[:n, 0] = np.asarray(model.sym.initial_rate(s), dtype=np.float64).ravel()
    z0[n:, 1:] = np.eye(m)
    mode0 = int(compiled.module.INITIAL_MODE[code])
    st = _State(t=0.0, mode=mode0, y=y0, z=z0, touched=False, modes=[mode0])
    branch = _Branch(model, v, variational, options, where)

    pending = list(traj.events)
    terminal = False
    events = 0
    while not terminal:
        if pending:  # on the simulated trajectory: its next event
            event = pending.pop(0)
            branch.flow(st, event.t)
            st.y = event.state_before.copy()
            terminal = branch.resolve(st)
            if terminal and event.kind == "terminal":
                break
            if not terminal and event.kind != "terminal" \
                    and st.mode == event.mask_after and _same(st.y, event.state_after):
                st.y = event.state_after.copy()
                continue
            st.continued = True  # the branch leaves the simulated trajectory here
            pending = []
        else:  # on the branch's own limiting trajectory
            events += 1
            if events > options.max_events:
                raise SimulationError(f"{where}: more than {options.max_events} events on the "
                                      f"branch {None if v is None else v.tolist()}")
            branch.flow_to_event(st)
            terminal = branch.resolve(st)

    final_mode = int(compiled.module.FINAL_MODE[code])
    if final_mode >= 0 and st.mode != final_mode:
        raise SimulationError(f"{where}: the branch {None if v is None else v.tolist()} reaches "
                              f"its terminal event in mode {st.mode}, not {final_mode}")
    f = model.extended_field(st.mode, st.y)
    dh = model.guard_gradient(st.mode, st.y, model.terminal)
    rate = float(dh @ f)
    if rate == 0.0:
        raise SimulationError(f"{where}: grazing terminal event: not differentiable")
    dt = -(dh @ st.z) / rate
    dx = st.z + np.outer(f, dt)
    do = np.asarray(model.sym.outcome_gradient(*st.y), dtype=np.float64).ravel()
    y_final = st.y.copy()
    outcome = float(compiled.module.outcome_value(code, model.p, np.ascontiguousarray(y_final), 0))
    return OutcomeGradient(
        system=compiled.name, maneuver=maneuver, s=s, inputs=tuple(u[:m].tolist()),
        names=names, direction=v, outcome=outcome, gradient=do @ dx[:n], y_final=y_final,
        state_gradient=dx[:n].copy(), t_final=st.t, time_gradient=dt, modes=tuple(st.modes),
        flips=tuple(st.flips),
        simultaneous=st.simultaneous, continued=st.continued, nfev=model.nfev)


def directional_derivative(
    compiled: CompiledSystem, maneuver: str, s: float, inputs: Any, v: npt.ArrayLike,
    *, options: SimulatorOptions = DEFAULT_OPTIONS,
    variational: VariationalOptions = DEFAULT_VARIATIONAL,
) -> float:
    """Bouligand derivative of the outcome at (s, inputs) in the direction v over ``(s, *inputs)``:
    lim_{eps -> 0+} (o(p + eps v) - o_branch(p)) / eps, where o_branch(p) is the limit along v
    (it differs from o(p) where the outcome jumps)."""
    g = outcome_gradient(compiled, maneuver, s, inputs, direction=v, options=options,
                         variational=variational)
    return float(g.gradient @ cast(Array, g.direction))  # (v is given)


def final_state_directional_derivative(
    compiled: CompiledSystem, maneuver: str, s: float, inputs: Any, v: npt.ArrayLike,
    *, options: SimulatorOptions = DEFAULT_OPTIONS,
    variational: VariationalOptions = DEFAULT_VARIATIONAL,
) -> Array:
    """Bouligand derivative of the final state y(t_f) (2d entries) in the direction v."""
    g = outcome_gradient(compiled, maneuver, s, inputs, direction=v, options=options,
                         variational=variational)
    return g.state_gradient @ cast(Array, g.direction)  # (v is given)


def one_sided_derivatives(
    compiled: CompiledSystem, maneuver: str, s: float, inputs: Any = None,
    *, options: SimulatorOptions = DEFAULT_OPTIONS,
    variational: VariationalOptions = DEFAULT_VARIATIONAL,
) -> tuple[float, float]:
    """(left, right) derivatives of the outcome w.r.t. s at fixed inputs: the slopes of the
    branches s -> s^- and s -> s^+ follow (left = minus the Bouligand derivative along -e_s)."""
    width = 1 + len(compiled.inputs) if isinstance(compiled, CompiledSystem) else 1
    e = np.zeros(width)
    e[0] = 1.0
    left = -directional_derivative(compiled, maneuver, s, inputs, -e, options=options,
                                   variational=variational)
    right = directional_derivative(compiled, maneuver, s, inputs, e, options=options,
                                   variational=variational)
    return left, right
