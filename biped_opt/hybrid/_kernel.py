"""Compiled hot path of the hybrid simulator (MODEL.md Sec. 3).

One call integrates a whole maneuver: an adaptive Dormand-Prince 8(5,3) integrator with its
7th-order dense output (Hairer, Norsett and Wanner, *Solving ODEs I*, Sec. II.10; the tableau is
read from SciPy's ``dop853_coefficients``), guard monitoring, event location on the dense output
polished by re-stepping, simultaneous events, resets and termination. Everything lives in flat
float arrays; nothing allocates per step.

Guards are normalised so that every event is "the guard falls through zero":

- guard j < 2 (foot j): a_j(q) = z_j while foot j is in the air (touchdown), lambda_j while it is on
  the ground (liftoff);
- guard 2 (termination): ``term_sign * z'``: -z' ends the touchdown maneuver at the body's nadir,
  +z' ends the liftoff maneuver at its apex.

Array layouts (documented once, used by :mod:`biped_opt.hybrid.simulate`):

- ``events[k]``: ``[t, kind, touchdown_mask, liftoff_mask, mode_before, mode_after,
  y_before (14), y_after (14)]``; kind 1 = contact event, 2 = termination.
- ``samples[k]``: ``[t, y (14), mode, lambda_1, lambda_2]``; at an event two rows share its time,
  before and after the reset.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from scipy.integrate._ivp import dop853_coefficients as _dop853

from biped_opt.model.biped import NSTATE, apply_impact, dynamics, generalised_forces

# --- Status codes (mirrored by biped_opt.hybrid.trajectory.Status) ---------------------------
OK = 0
HORIZON = 1
MAX_EVENTS = 2
INCONSISTENT = 3
APEX_IN_CONTACT = 4
STEP_FAILURE = 5

EVENT_CONTACT = 1
EVENT_TERMINAL = 2
EVENT_WIDTH = 6 + 2 * NSTATE
SAMPLE_WIDTH = 1 + NSTATE + 3

NGUARDS = 3
#: |guard| below which a second armed guard moving toward zero flips with the first (MODEL.md Sec. 3)
SIMULTANEOUS_TOL = 1e-9
#: a flipped guard stays disarmed until it is farther than this from zero
REARM_TOL = 1e-10
#: Newton polishing stops once the event-time correction is below this
EVENT_TIME_TOL = 1e-13

# --- Dormand-Prince 8(5,3) tableau --------------------------------------------------------
_NSTAGES = 12
_A = np.ascontiguousarray(_dop853.A, dtype=np.float64)  # (16, 16), rows 13-15: dense stages
_B = np.ascontiguousarray(_dop853.B, dtype=np.float64)  # (12,)
_C = np.ascontiguousarray(_dop853.C, dtype=np.float64)  # (16,)
_E3 = np.ascontiguousarray(_dop853.E3, dtype=np.float64)  # (13,)
_E5 = np.ascontiguousarray(_dop853.E5, dtype=np.float64)  # (13,)
_D = np.ascontiguousarray(_dop853.D, dtype=np.float64)  # (4, 16)
_SAFETY = 0.9
_MIN_FACTOR = 0.2
_MAX_FACTOR = 10.0
_ERROR_EXPONENT = -1.0 / 8.0
_MAX_STEPS = 100_000


@nb.njit(cache=True)
def _step(p, mode, u, y, f, h, K, y_new, f_new, lam_new, tmp, rtol, atol):
    """One DOP853 step of size h from (y, f = dy/dt at y) in mode ``mode``.

    K: stage derivatives, shape (16, 14); rows 0-11 stages, row 12 = f_new on return.
    Writes y_new, f_new, lam_new (reactions at y_new); returns the scaled error norm.
    """
    n = y.shape[0]
    for i in range(n):
        K[0, i] = f[i]
    for s in range(1, _NSTAGES):
        for i in range(n):
            acc = 0.0
            for r in range(s):
                acc += _A[s, r] * K[r, i]
            tmp[i] = y[i] + h * acc
        dynamics(p, mode, tmp, u, K[s], lam_new)
    for i in range(n):
        acc = 0.0
        for r in range(_NSTAGES):
            acc += _B[r] * K[r, i]
        y_new[i] = y[i] + h * acc
    dynamics(p, mode, y_new, u, f_new, lam_new)
    err5 = 0.0
    err3 = 0.0
    for i in range(n):
        K[_NSTAGES, i] = f_new[i]
        scale = atol + rtol * max(abs(y[i]), abs(y_new[i]))
        e5 = 0.0
        e3 = 0.0
        for r in range(_NSTAGES + 1):
            e5 += _E5[r] * K[r, i]
            e3 += _E3[r] * K[r, i]
        err5 += (e5 / scale) ** 2
        err3 += (e3 / scale) ** 2
    if err5 == 0.0 and err3 == 0.0:
        return 0.0
    return abs(h) * err5 / math.sqrt((err5 + 0.01 * err3) * n)


@nb.njit(cache=True)
def _dense_coefficients(p, mode, u, y, f, h, K, y_new, f_new, F, tmp, lam):
    """Coefficients F (7, 14) of the 7th-order interpolant on the step just taken (3 more stages)."""
    n = y.shape[0]
    for s in range(_NSTAGES + 1, 16):
        for i in range(n):
            acc = 0.0
            for r in range(s):
                acc += _A[s, r] * K[r, i]
            tmp[i] = y[i] + h * acc
        dynamics(p, mode, tmp, u, K[s], lam)
    for i in range(n):
        dy = y_new[i] - y[i]
        F[0, i] = dy
        F[1, i] = h * f[i] - dy
        F[2, i] = 2.0 * dy - h * (f_new[i] + f[i])
        for r in range(4):
            acc = 0.0
            for s in range(16):
                acc += _D[r, s] * K[s, i]
            F[3 + r, i] = h * acc


@nb.njit(cache=True)
def _dense_eval(F, y, x, out):
    """Interpolant at fraction x in [0, 1] of the step that started at y."""
    for i in range(y.shape[0]):
        acc = 0.0
        for r in range(6, -1, -1):
            acc += F[r, i]
            acc *= x if (6 - r) % 2 == 0 else 1.0 - x
        out[i] = y[i] + acc


@nb.njit(cache=True)
def _hermite_eval(y0, f0, y1, f1, h, x, out):
    """Cubic Hermite interpolant (cheap, used only to detect double crossings)."""
    h00 = (1.0 + 2.0 * x) * (1.0 - x) ** 2
    h10 = x * (1.0 - x) ** 2
    h01 = x * x * (3.0 - 2.0 * x)
    h11 = x * x * (x - 1.0)
    for i in range(y0.shape[0]):
        out[i] = h00 * y0[i] + h10 * h * f0[i] + h01 * y1[i] + h11 * h * f1[i]


@nb.njit(cache=True)
def _guard(p, mode, u, term_sign, y, i, fscratch):
    """Value of guard i at state y in mode ``mode`` (see the module docstring)."""
    if i == 2:
        return term_sign * y[8]
    if mode >> i & 1:
        generalised_forces(p, mode, y, u, fscratch, 0)
        return -fscratch[4 + 2 * i]  # lambda_i = -f_J[z_i] (M diagonal, Da_i = e_zi)
    return y[4 + 2 * i]


@nb.njit(cache=True)
def _guards_at_step_end(mode, term_sign, y, lam, gv):
    """All guards at a state whose reactions lam are already known (no extra evaluation)."""
    for j in range(2):
        gv[j] = lam[j] if mode >> j & 1 else y[4 + 2 * j]
    gv[2] = term_sign * y[8]


@nb.njit(cache=True)
def _guard_rate(p, mode, u, term_sign, y, dy, i, tmp, fscratch):
    """d/dt of guard i along the flow of mode ``mode`` at y (dy = vector field at y)."""
    if i == 2:
        return term_sign * dy[8]
    if not mode >> i & 1:
        return dy[4 + 2 * i]
    # lambda_i depends on (q, q'); differentiate along the flow by a central difference.
    eps = 1e-6
    for k in range(y.shape[0]):
        tmp[k] = y[k] + eps * dy[k]
    g_plus = _guard(p, mode, u, term_sign, tmp, i, fscratch)
    for k in range(y.shape[0]):
        tmp[k] = y[k] - eps * dy[k]
    g_minus = _guard(p, mode, u, term_sign, tmp, i, fscratch)
    return (g_plus - g_minus) / (2.0 * eps)


@nb.njit(cache=True)
def _root_on_dense(p, mode, u, term_sign, F, y, i, xa, ga, xb, gb, tmp, fscratch):
    """Root in (xa, xb] of guard i on the dense output, by the Illinois method.

    Requires ga > 0 >= gb. Returns x with the bracket shrunk below 1e-15 (relative to the step).
    """
    side = 0
    x = xb
    for _ in range(200):
        if xb - xa <= 1e-15:
            break
        x = (xa * gb - xb * ga) / (gb - ga)
        if not xa < x < xb:
            x = 0.5 * (xa + xb)
        _dense_eval(F, y, x, tmp)
        gx = _guard(p, mode, u, term_sign, tmp, i, fscratch)
        if gx > 0.0:
            xa, ga = x, gx
            if side == 1:
                gb *= 0.5
            side = 1
        else:
            xb, gb = x, gx
            if gx == 0.0:
                break
            if side == -1:
                ga *= 0.5
            side = -1
    return xb


@nb.njit(cache=True)
def _record_sample(samples, ns, t, y, mode, lam):
    if ns < samples.shape[0]:
        samples[ns, 0] = t
        for k in range(NSTATE):
            samples[ns, 1 + k] = y[k]
        samples[ns, 1 + NSTATE] = mode
        samples[ns, 2 + NSTATE] = lam[0]
        samples[ns, 3 + NSTATE] = lam[1]
    return ns + 1


@nb.njit(cache=True)
def _initial_step(p, mode, u, y, f, rtol, atol, h_max, tmp, ftmp, lam):
    """Starting step size (Hairer, Norsett and Wanner, Sec. II.4), one extra evaluation."""
    n = y.shape[0]
    d0 = 0.0
    d1 = 0.0
    for i in range(n):
        scale = atol + rtol * abs(y[i])
        d0 += (y[i] / scale) ** 2
        d1 += (f[i] / scale) ** 2
    d0 = math.sqrt(d0 / n)
    d1 = math.sqrt(d1 / n)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    for i in range(n):
        tmp[i] = y[i] + h0 * f[i]
    dynamics(p, mode, tmp, u, ftmp, lam)
    d2 = 0.0
    for i in range(n):
        scale = atol + rtol * abs(y[i])
        d2 += ((ftmp[i] - f[i]) / scale) ** 2
    d2 = math.sqrt(d2 / n) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / 8.0)
    return min(100.0 * h0, h1, h_max)


@nb.njit(cache=True)
def simulate_kernel(
    p,
    y0,
    mode0,
    u,
    term_sign,
    term_after_touchdown,
    term_mode,
    t_end,
    max_events,
    rtol,
    atol,
    h_max,
    sample_dt,
    samples,
    events,
    y_out,
):
    """Integrate one maneuver from (t = 0, y0, mode0) to its terminal event.

    Parameters
    ----------
    p : (9,) model parameters; y0 : (14,) initial state; mode0 : initial contact mode;
    u : (3,) inputs (u1, u2, u12); term_sign : +1 ends at z' falling through 0 (apex), -1 at z'
    rising through 0 (nadir); term_after_touchdown : arm the termination only after the first
    touchdown; term_mode : mode the terminal event must happen in (-1: any), else status
    APEX_IN_CONTACT; t_end : horizon; max_events : contact events allowed; rtol, atol, h_max :
    integrator settings; sample_dt : spacing of dense samples (<= 0: none); samples :
    (capacity, SAMPLE_WIDTH) output; events : (max_events + 1, EVENT_WIDTH) output;
    y_out : (14,) final state output.

    Returns
    -------
    (status, t_final, mode_final, n_events, n_samples, nfev, nsteps, nrejected)
    """
    n = NSTATE
    K = np.empty((16, n))
    F = np.empty((7, n))
    y = y0.copy()
    f = np.empty(n)
    y_new = np.empty(n)
    f_new = np.empty(n)
    y_try = np.empty(n)
    f_try = np.empty(n)
    tmp = np.empty(n)
    tmp2 = np.empty(n)
    fscratch = np.empty(7)
    lam = np.zeros(2)
    lam_new = np.zeros(2)
    lam_try = np.zeros(2)
    gv = np.empty(NGUARDS)
    gv_new = np.empty(NGUARDS)
    armed = np.zeros(NGUARDS, dtype=np.bool_)
    flips = np.zeros(NGUARDS, dtype=np.bool_)
    bracket_lo = np.zeros(NGUARDS)
    bracket_hi = np.ones(NGUARDS)
    crossing = np.zeros(NGUARDS, dtype=np.bool_)

    mode = mode0
    t = 0.0
    nfev = 0
    nsteps = 0
    nrejected = 0
    n_events = 0
    ns = 0
    status = OK
    term_enabled = not term_after_touchdown
    sampling = sample_dt > 0.0
    next_sample = 0

    dynamics(p, mode, y, u, f, lam)
    nfev += 1
    _guards_at_step_end(mode, term_sign, y, lam, gv)
    for i in range(NGUARDS):
        armed[i] = gv[i] > REARM_TOL
    if not term_enabled:
        armed[2] = False
    if sampling:
        ns = _record_sample(samples, ns, t, y, mode, lam)
        next_sample = 1

    h = _initial_step(p, mode, u, y, f, rtol, atol, h_max, tmp, f_try, lam_try)
    nfev += 1
    step_rejected = False
    finished = False

    while not finished:
        if nsteps >= _MAX_STEPS or h < 1e-14 * max(1.0, t):
            status = STEP_FAILURE
            break
        if t >= t_end:
            status = HORIZON
            break
        h_step = min(h, h_max, t_end - t)
        err = _step(p, mode, u, y, f, h_step, K, y_new, f_new, lam_new, tmp, rtol, atol)
        nfev += 12
        nsteps += 1
        if not err < 1.0:
            h = h_step * max(_MIN_FACTOR, _SAFETY * err**_ERROR_EXPONENT)
            nrejected += 1
            step_rejected = True
            continue
        if err == 0.0:
            factor = _MAX_FACTOR
        else:
            factor = min(_MAX_FACTOR, _SAFETY * err**_ERROR_EXPONENT)
        if step_rejected:
            factor = min(1.0, factor)
        step_rejected = False
        h = h_step * factor

        # --- event detection: sign changes at the step's end or inside it ------------------
        _guards_at_step_end(mode, term_sign, y_new, lam_new, gv_new)
        any_crossing = False
        for i in range(NGUARDS):
            crossing[i] = False
            if armed[i] and gv[i] > 0.0:
                bracket_lo[i] = 0.0
                bracket_hi[i] = 1.0
                if gv_new[i] <= 0.0:
                    crossing[i] = True
                else:
                    # a guard can dip below zero and come back within one step
                    for xi in (1.0 / 3.0, 2.0 / 3.0):
                        _hermite_eval(y, f, y_new, f_new, h_step, xi, tmp)
                        if _guard(p, mode, u, term_sign, tmp, i, fscratch) <= 0.0:
                            crossing[i] = True
                            bracket_hi[i] = xi
                            break
                any_crossing = any_crossing or crossing[i]

        dense_ready = False
        if any_crossing or sampling:
            _dense_coefficients(
                p, mode, u, y, f, h_step, K, y_new, f_new, F, tmp, lam_try
            )
            nfev += 3
            dense_ready = True

        t_stop = t + h_step
        first = -1
        if any_crossing:
            x_first = 2.0
            for i in range(NGUARDS):
                if crossing[i]:
                    xb = bracket_hi[i]
                    if xb < 1.0:
                        _dense_eval(F, y, xb, tmp)
                        gb = _guard(p, mode, u, term_sign, tmp, i, fscratch)
                        if gb > 0.0:  # the cheap interpolant misled us: no crossing
                            continue
                    else:
                        gb = gv_new[i]
                    x = _root_on_dense(
                        p, mode, u, term_sign, F, y, i, 0.0, gv[i], xb, gb, tmp, fscratch
                    )
                    if x < x_first:
                        x_first = x
                        first = i
            if first >= 0:
                # Polish: re-step exactly to the root, then Newton on the guard of the true step.
                h_ev = x_first * h_step
                for it in range(5):
                    _step(p, mode, u, y, f, h_ev, K, y_try, f_try, lam_try, tmp, rtol, atol)
                    nfev += 12
                    g_ev = _guard(p, mode, u, term_sign, y_try, first, fscratch)
                    rate = _guard_rate(p, mode, u, term_sign, y_try, f_try, first, tmp, fscratch)
                    if rate == 0.0 or it == 4:
                        break
                    dt = -g_ev / rate
                    if abs(dt) <= EVENT_TIME_TOL or not 0.0 < h_ev + dt <= h_step:
                        break
                    h_ev += dt
                t_stop = t + h_ev

        # --- dense samples strictly inside (t, t_stop] -------------------------------------
        if sampling and dense_ready:
            while True:
                ts = next_sample * sample_dt
                if ts > t_stop or (first >= 0 and ts >= t_stop):
                    break
                _dense_eval(F, y, (ts - t) / h_step, tmp)
                dynamics(p, mode, tmp, u, tmp2, lam_try)
                nfev += 1
                ns = _record_sample(samples, ns, ts, tmp, mode, lam_try)
                next_sample += 1

        if first < 0:
            # --- plain accepted step ---------------------------------------------------------
            t = t_stop
            for k in range(n):
                y[k] = y_new[k]
                f[k] = f_new[k]
            lam[0] = lam_new[0]
            lam[1] = lam_new[1]
            for i in range(NGUARDS):
                gv[i] = gv_new[i]
                if not armed[i] and (i < 2 or term_enabled):
                    if gv[i] > REARM_TOL:
                        armed[i] = True
                    elif i < 2 and gv[i] < -REARM_TOL:
                        status = INCONSISTENT  # a disarmed contact guard went the wrong way
                        finished = True
            continue

        # --- event at t_stop: which guards flip together -----------------------------------
        t = t_stop
        for k in range(n):
            y[k] = y_try[k]
            f[k] = f_try[k]
        lam[0] = lam_try[0]
        lam[1] = lam_try[1]
        for i in range(NGUARDS):
            flips[i] = i == first
            if i != first and armed[i]:
                gi = _guard(p, mode, u, term_sign, y, i, fscratch)
                if abs(gi) <= SIMULTANEOUS_TOL:
                    flips[i] = (
                        _guard_rate(p, mode, u, term_sign, y, f, i, tmp, fscratch) < 0.0
                    )
        touchdown = 0
        liftoff = 0
        for j in range(2):
            if flips[j]:
                if mode >> j & 1:
                    liftoff |= 1 << j
                else:
                    touchdown |= 1 << j
        if touchdown | liftoff:
            row = events[n_events]
            row[0] = t
            row[1] = EVENT_CONTACT
            row[2] = touchdown
            row[3] = liftoff
            row[4] = mode
            for k in range(n):
                row[6 + k] = y[k]
            if sampling:
                ns = _record_sample(samples, ns, t, y, mode, lam)
            mode = mode ^ (touchdown | liftoff)
            if touchdown:
                apply_impact(p, mode, y)
            dynamics(p, mode, y, u, f, lam)
            nfev += 1
            row[5] = mode
            for k in range(n):
                row[6 + n + k] = y[k]
            n_events += 1
            if sampling:
                ns = _record_sample(samples, ns, t, y, mode, lam)
            if touchdown and term_after_touchdown:
                term_enabled = True
            for j in range(2):
                if touchdown >> j & 1 and lam[j] < 0.0:
                    status = INCONSISTENT  # the new contact would pull the foot into the ground
                    finished = True
            _guards_at_step_end(mode, term_sign, y, lam, gv)
            for i in range(NGUARDS):
                if flips[i]:
                    armed[i] = False
                elif i == 2 and not armed[2] and term_enabled:
                    armed[2] = gv[2] > REARM_TOL
            if not finished and n_events >= max_events and not flips[2]:
                status = MAX_EVENTS
                finished = True
        if flips[2] and not finished:
            row = events[n_events]
            row[0] = t
            row[1] = EVENT_TERMINAL
            row[2] = 0
            row[3] = 0
            row[4] = mode
            row[5] = mode
            for k in range(n):
                row[6 + k] = y[k]
                row[6 + n + k] = y[k]
            if term_mode >= 0 and mode != term_mode:
                status = APEX_IN_CONTACT
            finished = True

    if sampling:
        ns = _record_sample(samples, ns, t, y, mode, lam)
    for k in range(n):
        y_out[k] = y[k]
    return status, t, mode, n_events, ns, nfev, nsteps, nrejected


@nb.njit(cache=True, parallel=True)
def simulate_batch_kernel(
    p,
    y0s,
    modes0,
    us,
    term_sign,
    term_after_touchdown,
    term_mode,
    t_end,
    max_events,
    rtol,
    atol,
    h_max,
    events,
    y_out,
    info,
):
    """:func:`simulate_kernel` over many initial states and inputs, in parallel threads.

    y0s : (N, 14); modes0 : (N,) int; us : (N, 3); events : (N, max_events + 1, EVENT_WIDTH);
    y_out : (N, 14); info : (N, 8) receives the kernel's returned tuple per trajectory.
    """
    no_samples = np.empty((0, SAMPLE_WIDTH))
    for k in nb.prange(y0s.shape[0]):
        status, t_f, mode_f, n_ev, n_s, nfev, nsteps, nrej = simulate_kernel(
            p,
            y0s[k],
            modes0[k],
            us[k],
            term_sign,
            term_after_touchdown,
            term_mode,
            t_end,
            max_events,
            rtol,
            atol,
            h_max,
            0.0,
            no_samples,
            events[k],
            y_out[k],
        )
        info[k, 0] = status
        info[k, 1] = t_f
        info[k, 2] = mode_f
        info[k, 3] = n_ev
        info[k, 4] = n_s
        info[k, 5] = nfev
        info[k, 6] = nsteps
        info[k, 7] = nrej
