"""A test oracle: the biped's own variational equations, on its hand-written physics.

This was the biped-only lane's derivative engine (``biped_opt.optimal.derivatives``, since
retired); the package now differentiates every system, the biped included, with
:mod:`biped_opt.control.derivatives` and :mod:`biped_opt.control.theorem1` on generated code.
Kept here as an independent implementation to compare those with: other physics code
(:mod:`tests.paper.biped_physics`, numba Jacobians by differences of the hand-written vector field),
other event bookkeeping, and for Theorem 1 another polish and another differencing of the second
derivatives (only the starting optimum comes from the one solver).

One-sided (Bouligand) derivatives of outcomes, optimal policies and values (Theorem 1 of [1]_).

The outcome th_f(th0, u) of a maneuver is piecewise smooth: smooth while the sequence of contact
modes is fixed, and kinked or discontinuous where events become simultaneous (paper Sec. III).
This module computes its first-order sensitivities exactly (to integration accuracy) and, at the
nonsmooth points, its one-sided derivatives on each branch:

- **within a mode** the extended state x = (y, u) (inputs as constant parameters) carries the
  sensitivity matrix Z = dx / d(th0, u1, u2, u12), which solves the variational equation
  Z' = D F_J(x) Z with F_J = (f_J, 0); it is integrated with SciPy's DOP853 along each segment of
  the simulated trajectory, with D f_J from fourth-order central differences of the compiled
  vector field (D_u f_J exactly: f_J is affine in u);
- **at an event** with guard g (foot height z_j for a touchdown, reaction lambda_j for a liftoff),
  reset R (the impact Delta_J, Eq. (1b), or the identity) and vector fields F- (old mode at x-),
  F+ (new mode at x+), Z jumps by the saltation matrix
  Xi = DR + (F+ - DR F-) Dg / (Dg F-), and the event time moves by dt_e = -Dg Z / (Dg F-);
- **at the terminal event** h = z' = 0 the outcome's gradient is
  e_th^T (I - F Dh / (Dh F)) Z.

At a *simultaneous* event (th0 = 0: both feet touch down or lift off together) the sensitivity
depends on the direction v of the perturbation: the guards flip in the order of their first-order
time shifts dt_i = -Dg_i Z v / (Dg_i F-), one at a time, with a zero-length intermediate mode when
the next guard is still at zero in it (touchdown, or liftoff without actuation), or - when the
intermediate mode's guard is not at zero (force coupling makes lambda_j jump, so the liftoff
outcome jumps) - along the limiting branch trajectory, continued from the event in the
intermediate mode. The result is the Bouligand derivative: linear on each branch, piecewise linear
in v (paper Sec. III; Burden et al. 2015; Pace and Burden 2017).

The optimal policy and value derivatives follow Theorem 1, Eqs. (12)-(13): with
c(th0, u) = (th_f - th*)^2 + sum alpha_i u_i^2 and an interior optimum u*, the value derivative is
dV/dth0 = dc/dth0 (envelope theorem) and the policy derivative is
du*/dth0 = -(D_uu c)^-1 D_u(th0) c (implicit function theorem on D_u c = 0); decisions at an
active bound keep du*/dth0 = 0. The second derivatives of th_f are finite differences (in u) of the
exact first-order sensitivities, on the branch of the requested side.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numba as nb
import numpy as np
import numpy.typing as npt
from scipy.integrate import solve_ivp

from biped_opt.codegen.abi import CFG_T_END
from biped_opt.control.derivatives import DEFAULT_VARIATIONAL, VariationalOptions, saltation_matrix
from biped_opt.control.theorem1 import Derivatives
from biped_opt.errors import InvalidInputError, SimulationError
from biped_opt.paper.biped import (
    INPUT_NAMES,
    BipedParams,
    ContactMode,
    check_inputs,
    compiled_biped,
    parse_maneuver,
    simulate,
    theta0_limit,
)
from biped_opt.paper.problems import OptimalControlProblem
from biped_opt.paper.solve import optimal_policy
from biped_opt.simulation.compiled import kernel_config
from biped_opt.simulation.options import DEFAULT_OPTIONS, SimulatorOptions
from biped_opt.simulation.trajectory import Event, Status, Trajectory
from tests.paper.biped_physics import (
    BODY_DZ,
    NSTATE,
    dynamics,
    generalised_forces,
    initial_state,
    packed,
)

__all__ = [
    "PARAMETER_NAMES",
    "DEFAULT_VARIATIONAL",
    "VariationalOptions",
    "OutcomeSensitivity",
    "Derivatives",
    "outcome_sensitivity",
    "outcome_derivative",
    "saltation_matrix",
    "one_sided_derivatives",
]

Array = npt.NDArray[np.float64]

#: the parameters the outcome is differentiated with respect to, in gradient order
PARAMETER_NAMES = ("theta0", *INPUT_NAMES)
NPARAM = len(PARAMETER_NAMES)
NINPUT = len(INPUT_NAMES)
NEXT = NSTATE + NINPUT  #: extended state x = (y, u)
TH = 2  #: index of the body pitch in y
#: fourth-order central-difference step of the state Jacobian: truncation ~ h^4 |f^(5)| and
#: rounding ~ eps |f| / h balance near 1e-11 for this model's O(10) forces
_JAC_STEP = 2e-4




# --- compiled right-hand sides ----------------------------------------------------------------
@nb.njit(cache=True)
def _state_jacobian(p, mode, y, u, f0, jac, fp, lam, tmp):
    """f_J(y) into f0 and D_y f_J (14 x 14) into jac by fourth-order central differences."""
    dynamics(p, mode, y, u, f0, lam)
    n = y.shape[0]
    for k in range(n):
        tmp[k] = y[k]
    for j in range(n):
        h = _JAC_STEP * max(1.0, abs(y[j]))
        for i in range(n):
            jac[i, j] = 0.0
        for sgn, w in ((2.0, -1.0), (1.0, 8.0), (-1.0, -8.0), (-2.0, 1.0)):
            tmp[j] = y[j] + sgn * h
            dynamics(p, mode, tmp, u, fp, lam)
            for i in range(n):
                jac[i, j] += w * fp[i]
        tmp[j] = y[j]
        for i in range(n):
            jac[i, j] /= 12.0 * h


@nb.njit(cache=True)
def _input_jacobian(p, mode, y, u, f0, jac_u, fp, lam, tmp_u):
    """D_u f_J (14 x 3) into jac_u: exact, since f_J is affine in u (force coupling)."""
    for k in range(u.shape[0]):
        tmp_u[k] = u[k]
    for j in range(u.shape[0]):
        tmp_u[j] = u[j] + 1.0
        dynamics(p, mode, y, tmp_u, fp, lam)
        for i in range(y.shape[0]):
            jac_u[i, j] = fp[i] - f0[i]
        tmp_u[j] = u[j]


@nb.njit(cache=True)
def _variational_rhs(p, mode, u, w, ncols):
    """d/dt of w = (y, Z) with Z = dy / d(params), shape (14, ncols), stored row-major.

    Z' = D_y f Z + D_u f E, where E = du / d(params) = [0 | I_3] (column 0 is th0).
    """
    n = NSTATE
    y = w[:n].copy()
    out = np.empty(n + n * ncols)
    f0 = np.empty(n)
    fp = np.empty(n)
    lam = np.empty(2)
    tmp = np.empty(n)
    tmp_u = np.empty(3)
    jac = np.empty((n, n))
    jac_u = np.empty((n, 3))
    _state_jacobian(p, mode, y, u, f0, jac, fp, lam, tmp)
    _input_jacobian(p, mode, y, u, f0, jac_u, fp, lam, tmp_u)
    for i in range(n):
        out[i] = f0[i]
    for i in range(n):
        for c in range(ncols):
            acc = 0.0
            for j in range(n):
                acc += jac[i, j] * w[n + j * ncols + c]
            if c >= 1:
                acc += jac_u[i, c - 1]
            out[n + i * ncols + c] = acc
    return out


@nb.njit(cache=True)
def _foot_guard(p, mode, y, u, j):
    """Guard of foot j in ``mode``: lambda_j if the foot is down (liftoff), else z_j."""
    if mode >> j & 1:
        f = np.empty(7)
        generalised_forces(p, mode, y, u, f, 0)
        return -f[4 + 2 * j]  # lambda_j = -f_J[z_j] (M diagonal, Da_j = e_{z_j})
    return y[4 + 2 * j]


@nb.njit(cache=True)
def _foot_guard_gradient(p, mode, y, u, j):
    """D_x of the foot-j guard over the extended state x = (y, u), shape (17,)."""
    n = NSTATE
    out = np.zeros(n + 3)
    if not mode >> j & 1:
        out[4 + 2 * j] = 1.0
        return out
    tmp = y.copy()
    for k in range(n):
        h = _JAC_STEP * max(1.0, abs(y[k]))
        acc = 0.0
        for sgn, w in ((2.0, -1.0), (1.0, 8.0), (-1.0, -8.0), (-2.0, 1.0)):
            tmp[k] = y[k] + sgn * h
            acc += w * _foot_guard(p, mode, tmp, u, j)
        tmp[k] = y[k]
        out[k] = acc / (12.0 * h)
    g0 = _foot_guard(p, mode, y, u, j)
    tmp_u = u.copy()
    for k in range(3):
        tmp_u[k] = u[k] + 1.0  # lambda_j is affine in u
        out[n + k] = _foot_guard(p, mode, y, tmp_u, j) - g0
        tmp_u[k] = u[k]
    return out


# --- small numpy helpers ------------------------------------------------------------------------
def _field(p: Array, mode: int, y: Array, u: Array) -> Array:
    """Extended vector field F_J(x) = (f_J(y, u), 0), shape (17,)."""
    dy = np.empty(NSTATE)
    dynamics(p, int(mode), np.ascontiguousarray(y, dtype=np.float64), u, dy, np.empty(2))
    return np.concatenate([dy, np.zeros(NINPUT)])


def _reset_jacobian(p: Array, mode_after: int, touchdown: bool) -> Array:
    """D_x of the reset on entering ``mode_after``: Delta_J on a touchdown, else identity.

    The impact, Eq. (1b), scales each contacting foot's z' by -gamma (M diagonal, Da_j = e_zj).
    """
    dr = np.eye(NEXT)
    if touchdown:
        for j in range(2):
            if mode_after >> j & 1:
                dr[11 + 2 * j, 11 + 2 * j] = -p[8]
    return dr


def _impact(p: Array, mode_after: int, y: Array, touchdown: bool) -> Array:
    out = y.copy()
    if touchdown:
        for j in range(2):
            if mode_after >> j & 1:
                out[11 + 2 * j] *= -p[8]
    return out


# --- results ------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class OutcomeSensitivity:
    """First-order sensitivity of th_f on one branch of the outcome.

    ``gradient[k]`` = d th_f / d PARAMETER_NAMES[k] on the branch selected by ``direction``
    (a vector over PARAMETER_NAMES). Away from simultaneous events every direction gives the
    same gradient (th_f is C^1 there); at them the gradient is the linear piece of the
    Bouligand derivative that holds for ``direction``, and ``outcome`` is the branch's one-sided
    limit (it differs from th_f at the point itself where the outcome jumps).
    """

    maneuver: str
    theta0: float
    inputs: Array
    direction: Array
    outcome: float
    gradient: Array = field(repr=False)
    t_final: float
    mode_sequence: tuple[ContactMode, ...]  #: branch modes, zero-length ones included
    simultaneous: bool  #: an event with several flips was met (a nonsmooth point)
    continued: bool  #: the branch left the simulated trajectory (the outcome jumps here)
    nfev: int  #: right-hand-side evaluations of the variational equation

    @property
    def d_theta0(self) -> float:
        return float(self.gradient[0])

    def d_input(self, name: str) -> float:
        """d th_f / d ``name`` (u1, u2 or u12) on this branch."""
        if name not in INPUT_NAMES:
            raise InvalidInputError(f"input must be one of {', '.join(INPUT_NAMES)}, got {name!r}")
        return float(self.gradient[1 + INPUT_NAMES.index(name)])


# --- the driver ---------------------------------------------------------------------------------
class _Walker:
    """Carries (t, y, mode, Z) along a trajectory, through events, to the terminal event."""

    def __init__(
        self, p: Array, u: Array, direction: Array, vopts: VariationalOptions
    ) -> None:
        self.p = p
        self.u = u
        self.direction = direction
        self.vopts = vopts
        self.nfev = 0

    def flow(self, mode: int, t0: float, t1: float, y0: Array, z: Array) -> tuple[Array, Array]:
        """Integrate (y, Z) in ``mode`` from t0 to t1; Z is the (17, 4) extended sensitivity."""
        if t1 <= t0:
            return y0.copy(), z.copy()
        w0 = np.concatenate([y0, z[:NSTATE].ravel()])
        p, u = self.p, self.u

        def rhs(_t: float, w: Array) -> Array:
            return _variational_rhs(p, mode, u, w, NPARAM)

        sol = solve_ivp(
            rhs, (t0, t1), w0, method="DOP853", rtol=self.vopts.rtol, atol=self.vopts.atol
        )
        self.nfev += int(sol.nfev)
        if not sol.success:
            raise SimulationError(f"variational integration failed: {sol.message}")
        w1 = sol.y[:, -1]
        z1 = z.copy()
        z1[:NSTATE] = w1[NSTATE:].reshape(NSTATE, NPARAM)
        return w1[:NSTATE], z1

    def flip(
        self, mode: int, y: Array, z: Array, foot: int
    ) -> tuple[int, Array, Array]:
        """Apply the saltation of foot ``foot``'s guard in ``mode`` at y (the pre-event state)."""
        p, u = self.p, self.u
        touchdown = not (mode >> foot & 1)
        mode_after = mode ^ (1 << foot)
        y_after = _impact(p, mode_after, y, touchdown)
        dg = _foot_guard_gradient(p, mode, y, u, foot)
        xi = saltation_matrix(
            _reset_jacobian(p, mode_after, touchdown),
            _field(p, mode, y, u),
            _field(p, mode_after, y_after, u),
            dg,
        )
        return mode_after, y_after, xi @ z

    def time_shift(self, mode: int, y: Array, z: Array, foot: int) -> float:
        """First-order event-time shift of foot ``foot``'s guard along ``direction``."""
        dg = _foot_guard_gradient(self.p, mode, y, self.u, foot)
        rate = float(dg @ _field(self.p, mode, y, self.u))
        if rate == 0.0:
            return 0.0
        return -float(dg @ (z @ self.direction)) / rate


def _continue(
    maneuver: str,
    theta0: float,
    t0: float,
    y0: Array,
    mode0: int,
    u: Array,
    params: BipedParams,
    options: SimulatorOptions,
    touched_down: bool,
) -> Trajectory:
    """Simulate the rest of a maneuver from (t0, y0, mode0): the limiting branch trajectory.

    The compiled kernel starts at t = 0 with every guard near zero disarmed (the feet that just
    flipped), which is exactly the state right after an event; times are shifted by t0.
    """
    name = parse_maneuver(maneuver).value
    k = compiled_biped(params)
    m = k.module
    events = np.empty((options.max_events + 1, m.EVENT_WIDTH))
    y_out = np.empty(NSTATE)
    cfg = kernel_config(options, 0.0, touched_down)
    cfg[CFG_T_END] = options.t_end - t0
    kernel, sv = k.shared_kernel()
    status, t_f, mode_f, n_ev, _, nfev, nsteps, nrej, _ = kernel.simulate_maneuver(
        k.prepared, sv, k.code(name), 0.0, u, cfg, np.empty((0, m.SAMPLE_WIDTH)),
        events, y_out, np.ascontiguousarray(y0, dtype=np.float64), int(mode0),
    )
    n_rows = n_ev + (1 if status in (Status.OK, Status.APEX_IN_CONTACT) else 0)
    rows = events[:n_rows].copy()
    rows[:, 0] += t0
    return Trajectory(
        system="biped", maneuver=name, s=theta0, inputs=tuple(u.tolist()),
        status=Status(status), t_final=t_f + t0, outcome=float(y_out[2]), y_final=y_out,
        mode_final=int(mode_f), initial_mode=int(mode0), n_events=int(n_ev), event_rows=rows,
        samples=None, nfev=nfev, nsteps=nsteps, nrejected=nrej, constraints=("left", "right"),
        budget=None,
    )


def _initial_sensitivity(maneuver: str, theta0: float, params: BipedParams) -> Array:
    """Z(0): d y0 / d th0 by a fourth-order difference of the smooth initial state; du/du = I.

    initial_state is a trigonometric polynomial in th0, so the stencil's truncation error is
    ~1e-20 and its rounding error ~1e-11. Near the end of the valid range the one-sided stencil
    keeps every evaluation inside it.
    """
    z = np.zeros((NEXT, NPARAM))
    name = parse_maneuver(maneuver).value
    h = 1e-5

    def y0(th: float) -> Array:
        return initial_state(name, th, params)[0]

    if abs(theta0) + 2 * h <= theta0_limit(name):
        stencil = ((2.0, -1.0), (1.0, 8.0), (-1.0, -8.0), (-2.0, 1.0))
    else:
        sgn = -1.0 if theta0 > 0 else 1.0  # step toward the interior
        stencil = tuple(
            (sgn * k, sgn * w)
            for k, w in ((0, -25.0), (1, 48.0), (2, -36.0), (3, 16.0), (4, -3.0))
        )
    acc = np.zeros(NSTATE)
    for k, w in stencil:
        acc += w * y0(theta0 + k * h)
    z[:NSTATE, 0] = acc / (12.0 * h)
    z[NSTATE:, 1:] = np.eye(NINPUT)
    return z


def _check_direction(direction: npt.ArrayLike | None, side: int | None) -> Array:
    if direction is None:
        v = np.zeros(NPARAM)
        v[0] = 1.0 if side is None else float(side)
        return v
    try:
        v = np.asarray(direction, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise InvalidInputError(f"direction must be numbers, got {direction!r}") from None
    if v.size > NPARAM or not np.all(np.isfinite(v)):
        raise InvalidInputError(
            f"direction must be at most {NPARAM} finite numbers over {PARAMETER_NAMES}, "
            f"got {direction!r}"
        )
    out = np.zeros(NPARAM)
    out[: v.size] = v
    return out


def outcome_sensitivity(
    maneuver: str,
    theta0: float,
    inputs: npt.ArrayLike | None = None,
    *,
    direction: npt.ArrayLike | None = None,
    params: BipedParams | None = None,
    options: SimulatorOptions = DEFAULT_OPTIONS,
    variational: VariationalOptions = DEFAULT_VARIATIONAL,
) -> OutcomeSensitivity:
    """Gradient of th_f w.r.t. (th0, u1, u2, u12) on the branch selected by ``direction``.

    ``direction`` is a perturbation over PARAMETER_NAMES (default +d th0); it matters only at a
    simultaneous event, where the guards flip in the order of their first-order time shifts
    along it (ties: left foot first). Raises SimulationError if the maneuver does not reach its
    terminal event.
    """
    name = parse_maneuver(maneuver).value
    p_obj = params if params is not None else BipedParams()
    p = packed(p_obj)
    u = check_inputs(inputs)
    v = _check_direction(direction, None)
    traj = simulate(name, theta0, u, params=p_obj, options=options)
    if not traj.success:
        raise SimulationError(
            f"{name} at theta0 = {theta0}: {traj.message} (status {traj.status.name})"
        )
    walker = _Walker(p, u, v, variational)
    z = _initial_sensitivity(name, float(theta0), p_obj)
    y, m0 = initial_state(name, theta0, p_obj)
    mode = int(m0)
    t = 0.0
    modes = [ContactMode(mode)]
    pending: list[Event] = list(traj.contact_events)
    t_final, y_final = traj.t_final, traj.state_final
    simultaneous = continued = False
    touched_down = False
    while pending:
        e = pending.pop(0)
        _, z = walker.flow(mode, t, e.t, y, z)
        # the feet that switched (bit j = foot j + 1): touchdowns first, then liftoffs
        feet = [j for mask in (e.mask_entered, e.mask_left) for j in range(2) if mask >> j & 1]
        touched_down = touched_down or bool(e.mask_entered)
        y_cur = e.state_before
        if len(feet) == 1:
            mode, y_cur, z = walker.flip(mode, y_cur, z, feet[0])
            modes.append(ContactMode(mode))
            y, t = e.state_after, e.t
            continue
        simultaneous = True
        remaining = list(feet)
        while remaining:
            # A guard at zero in the current mode flips in this instant, in the order of the
            # first-order time shifts; one already below zero (a reaction that the new mode's
            # force coupling made negative) flips at once, before them.
            guards = {j: _foot_guard(p, mode, y_cur, u, j) for j in remaining}
            at_zero = [j for j in remaining if guards[j] <= variational.zero_length_tol]
            if not at_zero:
                break
            keys = [
                walker.time_shift(mode, y_cur, z, j)
                if guards[j] >= -variational.zero_length_tol else -math.inf
                for j in at_zero
            ]
            foot = at_zero[int(np.argmin(keys))]  # argmin keeps the first (left) on ties
            mode, y_cur, z = walker.flip(mode, y_cur, z, foot)
            modes.append(ContactMode(mode))
            remaining.remove(foot)
        y, t = y_cur, e.t
        if remaining:
            # The intermediate mode's guard is not at zero: the branch's limiting trajectory
            # spends a finite time in it. Continue the simulation from here along that branch.
            continued = True
            rest = _continue(
                name, float(theta0), e.t, y_cur, mode, u, p_obj, options, touched_down
            )
            if not rest.success:
                raise SimulationError(
                    f"{name} at theta0 = {theta0}, branch {v.tolist()}: {rest.message}"
                )
            pending = list(rest.contact_events)
            t_final, y_final = rest.t_final, rest.state_final
    _, z = walker.flow(mode, t, t_final, y, z)
    f_final = _field(p, mode, y_final, u)
    if f_final[BODY_DZ] == 0.0:
        raise SimulationError("grazing terminal event (z'' = 0): th_f is not differentiable")
    gradient = z[TH] - f_final[TH] * z[BODY_DZ] / f_final[BODY_DZ]
    return OutcomeSensitivity(
        maneuver=name,
        theta0=float(theta0),
        inputs=u,
        direction=v,
        outcome=float(y_final[TH]),
        gradient=gradient,
        t_final=float(t_final),
        mode_sequence=tuple(modes),
        simultaneous=simultaneous,
        continued=continued,
        nfev=walker.nfev,
    )


def outcome_derivative(
    maneuver: str,
    theta0: float,
    inputs: npt.ArrayLike | None = None,
    side: int = 1,
    *,
    params: BipedParams | None = None,
    options: SimulatorOptions = DEFAULT_OPTIONS,
    variational: VariationalOptions = DEFAULT_VARIATIONAL,
) -> float:
    """One-sided derivative of th_f w.r.t. th0: side = +1 from the right, -1 from the left.

    Away from simultaneous events both sides agree; at them this is the slope of the branch the
    side selects (for the liftoff jump, of the branch's continuous extension).
    """
    if side not in (-1, 1):
        raise InvalidInputError(f"side must be -1 or +1, got {side!r}")
    sens = outcome_sensitivity(
        maneuver, theta0, inputs, direction=(float(side), 0.0, 0.0, 0.0), params=params,
        options=options, variational=variational,
    )
    return sens.d_theta0


# --- optimal policy and value: Theorem 1, Eqs. (12)-(13) ----------------------------------------
@dataclass(frozen=True)
class _BranchData:
    """Cost derivatives on one branch at (th0, u): everything Eqs. (12)-(13) need."""

    outcome: float
    g_theta: float  # d th_f / d th0
    g_u: Array  # d th_f / d decisions, (m,)
    g_uu: Array  # d2 th_f / d decisions^2, (m, m), finite differences of exact g_u
    g_utheta: Array  # d2 th_f / (d decisions d th0), (m,)
    modes: tuple[ContactMode, ...]


class _BranchCost:
    """th_f and its derivatives on the branch a side selects, as functions of the decisions."""

    def __init__(
        self, problem: OptimalControlProblem, theta0: float, side: int,
        vopts: VariationalOptions,
    ) -> None:
        self.problem = problem
        self.theta0 = theta0
        self.side = side
        self.vopts = vopts
        self.idx = [1 + INPUT_NAMES.index(d) for d in problem.decisions]
        self.nsens = 0

    def inputs(self, x: Array) -> Array:
        u = self.problem.inputs(dict(zip(self.problem.decisions, (float(v) for v in x))))
        return u

    def sensitivity(self, x: Array) -> OutcomeSensitivity:
        self.nsens += 1
        return outcome_sensitivity(
            self.problem.maneuver, self.theta0, self.inputs(x),
            direction=(float(self.side), 0.0, 0.0, 0.0), params=self.problem.params,
            options=self.problem.options, variational=self.vopts,
        )

    def data(self, x: Array) -> _BranchData:
        """First derivatives exactly; second by differences of them in each decision.

        The fourth-order central stencil (step h) has truncation ~h^4 and rounding
        ~(sensitivity error 1e-11) / h; every stencil point must stay on the centre's branch
        (same mode order), else h shrinks, and at last a one-sided second-order stencil on the
        side that stays is used.
        """
        centre = self.sensitivity(x)
        m = x.size
        g_uu = np.zeros((m, m))
        g_ut = np.zeros(m)
        for b in range(m):
            col = self._differentiate(x, b, centre)
            g_uu[:, b] = col[self.idx]
            g_ut[b] = col[0]
        g_uu = 0.5 * (g_uu + g_uu.T)
        return _BranchData(
            outcome=centre.outcome,
            g_theta=centre.d_theta0,
            g_u=centre.gradient[self.idx],
            g_uu=g_uu,
            g_utheta=g_ut,
            modes=centre.mode_sequence,
        )

    def _differentiate(self, x: Array, b: int, centre: OutcomeSensitivity) -> Array:
        """d gradient / d x_b on the centre's branch."""

        def grad_at(offset: float) -> OutcomeSensitivity:
            xx = x.copy()
            xx[b] += offset
            return self.sensitivity(xx)

        def same(s: OutcomeSensitivity) -> bool:
            return s.mode_sequence == centre.mode_sequence and s.continued == centre.continued

        h = self.vopts.second_order_step
        lo, hi = self.problem.bounds[b]
        # stay inside the box: beyond a bound the outcome may be nonsmooth in the decision
        # (a negative single-stance force can make a phase vanish), and it is never needed there
        inside = x[b] - 2 * h >= lo and x[b] + 2 * h <= hi
        for _ in range(3 if inside else 0):
            pts = {k: grad_at(k * h) for k in (-2, -1, 1, 2)}
            if all(same(s) for s in pts.values()):
                return (
                    -pts[2].gradient + 8 * pts[1].gradient - 8 * pts[-1].gradient
                    + pts[-2].gradient
                ) / (12.0 * h)
            h /= 8.0
        h = min(h, self.vopts.second_order_step / 8.0)
        sides = (1, -1) if x[b] - lo <= hi - x[b] else (-1, 1)
        for sgn in sides:
            if not lo <= x[b] + sgn * 2 * h <= hi:
                continue
            pts = {k: grad_at(sgn * k * h) for k in (1, 2)}
            # the centre may sit on the edge of the branch the side points into (a decision on
            # its bound where a phase vanishes): its sensitivities are that branch's limits
            if (pts[1].mode_sequence, pts[1].continued) == (
                pts[2].mode_sequence, pts[2].continued
            ) and pts[1].mode_sequence == centre.mode_sequence:
                return sgn * (
                    -3 * centre.gradient + 4 * pts[1].gradient - pts[2].gradient
                ) / (2.0 * h)
        raise SimulationError(
            f"{self.problem.name} at theta0 = {self.theta0}: the branch changes within "
            f"{h:.1e} of {self.problem.decisions[b]} = {x[b]}; second derivatives undefined"
        )


def _cost_derivatives(
    problem: OptimalControlProblem, x: Array, d: _BranchData
) -> tuple[float, Array, Array, Array]:
    """c_theta, c_u, c_uu, c_u,theta of c = (th_f - th*)^2 + sum alpha u^2 (Eqs. (14), (15))."""
    alpha = np.asarray(problem.alphas, dtype=np.float64)
    slope = problem.outcome_slope(d.outcome)  # 2 (th_f - th*)
    c_t = slope * d.g_theta
    c_u = slope * d.g_u + 2.0 * alpha * x
    c_uu = 2.0 * np.outer(d.g_u, d.g_u) + slope * d.g_uu + 2.0 * np.diag(alpha)
    c_ut = 2.0 * d.g_theta * d.g_u + slope * d.g_utheta
    return c_t, c_u, c_uu, c_ut


#: a decision within this of a bound is on it
_BOUND_TOL = 1e-9
#: |D_u c| below this counts as zero (first-order condition holds)
_GRADIENT_TOL = 1e-8


def _on_bound(problem: OptimalControlProblem, x: Array) -> list[int]:
    """Per decision: -1 on the lower bound, +1 on the upper, 0 inside."""
    out = []
    for xi, (lo, hi) in zip(x, problem.bounds):
        out.append(-1 if xi - lo <= _BOUND_TOL else 1 if hi - xi <= _BOUND_TOL else 0)
    return out


def _free_solve(h: Array, rhs: Array, free: list[int]) -> Array:
    """Solve h[F, F] s_F = rhs[F] with s = 0 off F; decisions with a zero row stay at 0."""
    s = np.zeros(rhs.size)
    live = [i for i in free if np.any(h[i, free] != 0.0) or rhs[i] != 0.0]
    if live:
        sub = h[np.ix_(live, live)]
        s[live] = np.linalg.lstsq(sub, rhs[live], rcond=None)[0]
    return s


def _polish(
    problem: OptimalControlProblem, branch: _BranchCost, x: Array
) -> tuple[Array, _BranchData]:
    """Newton on D_u c = 0 on the branch, decisions at an active bound held (active set)."""
    d = branch.data(x)
    for _ in range(4):
        _, c_u, c_uu, _ = _cost_derivatives(problem, x, d)
        bound = _on_bound(problem, x)
        # held: on a bound with the gradient pushing out of the box
        free = [i for i in range(x.size) if not bound[i] * c_u[i] < 0.0]
        step = _free_solve(c_uu, -c_u, free)
        lo = np.array([b[0] for b in problem.bounds])
        hi = np.array([b[1] for b in problem.bounds])
        x_new = np.clip(x + step, lo, hi)
        if np.max(np.abs(x_new - x), initial=0.0) <= 1e-13:
            break
        x = x_new
        d = branch.data(x)
        if np.max(np.abs(step), initial=0.0) <= 1e-9:
            break  # quadratic convergence: the next step would be below 1e-13
    return x, d


def _policy_slope(
    problem: OptimalControlProblem, x: Array, d: _BranchData, side: int
) -> tuple[Array, tuple[str, ...]]:
    """du*/dth0 on one side by the implicit function theorem; bounds as an active set, (13)."""
    _, c_u, c_uu, c_ut = _cost_derivatives(problem, x, d)
    bound = _on_bound(problem, x)
    held = {i for i in range(x.size) if bound[i] != 0 and abs(c_u[i]) > _GRADIENT_TOL}
    for _ in range(x.size + 1):
        free = [i for i in range(x.size) if i not in held]
        s = _free_solve(c_uu, -c_ut, free)
        # a decision on its bound whose slope would leave the box on this side stays there
        leaving = {i for i in free if bound[i] != 0 and bound[i] * side * s[i] > 0.0}
        if not leaving:
            break
        held |= leaving
    s[list(held)] = 0.0
    return s, tuple(problem.decisions[i] for i in sorted(held))


def one_sided_derivatives(
    problem: OptimalControlProblem,
    theta0: float,
    *,
    params: BipedParams | None = None,
    variational: VariationalOptions = DEFAULT_VARIATIONAL,
    probe: float = 1e-7,
) -> Derivatives:
    """One-sided derivatives of the optimal outcome, value and policy (Theorem 1, (12)-(13)).

    ``problem`` is an :class:`~biped_opt.paper.problems.OptimalControlProblem`; ``params``
    overrides its biped parameters. For each side the optimum is taken from
    :func:`~biped_opt.paper.solve.optimal_policy` at theta0 + side * ``probe`` (which tells
    the branch the side follows, also where the policy jumps), then polished by Newton's method
    on that branch *at* theta0 (exact first derivatives, differenced second derivatives).
    With c(th0, u) = (th_f - th*)^2 + sum alpha u^2 and u* that optimum:

    - value: dV/dth0 = D_th0 c + D_u c du*/dth0, i.e. D_th0 c at an interior optimum
      (envelope theorem, Eq. (12));
    - policy: du*/dth0 = -(D_uu c)^-1 D_u,th0 c on the free decisions (implicit function
      theorem on D_u c = 0, Eq. (13)); a decision on an active bound has slope 0 on that side.

    At a simultaneous event the branch is the one the side's perturbation direction
    (+-d th0, inputs fixed) selects. ``probe`` (default 1e-7, at most 1e-3) must exceed the
    accuracy to which a policy jump at theta0 is located and stay below the distance to the
    next nonsmooth point. Raises SimulationError when no optimum or no branch is found.
    """
    if not isinstance(problem, OptimalControlProblem):
        raise InvalidInputError(f"problem must be an OptimalControlProblem, got {problem!r}")
    if _probe_invalid(probe):
        raise InvalidInputError(f"probe must be a small positive number, got {probe!r}")
    if params is not None:
        problem = dataclasses.replace(problem, params=params)
    limit = theta0_limit(problem.maneuver)
    th0 = float(theta0)
    if not math.isfinite(th0) or abs(th0) > limit:
        raise InvalidInputError(
            f"theta0 = {theta0} is outside the valid range |theta0| <= {limit}"
        )
    sides = {}
    nsens = 0
    for side in (-1, 1):
        th_probe = th0 + side * probe
        if abs(th_probe) > limit:
            th_probe = th0
        start = optimal_policy(problem, th_probe)
        if not start.success:
            raise SimulationError(
                f"{problem.name} at theta0 = {th_probe}: no optimum ({start.message})"
            )
        branch = _BranchCost(problem, th0, side, variational)
        x0 = np.array([start.policy[d] for d in problem.decisions], dtype=np.float64)
        x, d = _polish(problem, branch, x0)
        slope, held = _policy_slope(problem, x, d, side)
        c_t, c_u, _, _ = _cost_derivatives(problem, x, d)
        value = float(problem.cost(d.outcome, branch.inputs(x)))
        nsens += branch.nsens
        sides[side] = (x, d, slope, held, c_t + float(c_u @ slope), value)
    left, right = sides[-1], sides[1]
    names = problem.decisions
    return Derivatives(
        problem=problem.name,
        theta0=th0,
        outcome=(left[1].g_theta + float(left[1].g_u @ left[2]),
                 right[1].g_theta + float(right[1].g_u @ right[2])),
        value=(float(left[4]), float(right[4])),
        policy={n: (float(left[2][i]), float(right[2][i])) for i, n in enumerate(names)},
        outcome_limits=(left[1].outcome, right[1].outcome),
        value_limits=(left[5], right[5]),
        policy_limits={n: (float(left[0][i]), float(right[0][i])) for i, n in enumerate(names)},
        branches=tuple("->".join(m.name for m in side[1].modes) for side in (left, right)),
        at_bound=(left[3], right[3]),
        nsens=nsens,
    )


def _probe_invalid(probe: float) -> bool:
    return not (isinstance(probe, (int, float)) and math.isfinite(probe) and 0 < probe <= 1e-3)
