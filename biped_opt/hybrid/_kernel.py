"""Compiled hot path of the hybrid simulator (MODEL.md Sec. 3).

One call integrates a whole maneuver: an adaptive Dormand-Prince 8(5,3) integrator with its
7th-order dense output (Hairer, Norsett and Wanner, *Solving ODEs I*, Sec. II.10; the step itself is
the unrolled code of :mod:`biped_opt.hybrid._dop853`, generated from SciPy's tableau), guard
monitoring at the step ends and at every stage (so a guard that dips below zero inside a step is
not missed), event location as the root of the guard on the dense output (regula falsi with the
Anderson-Bjorck modification, bracket < 1e-13 of the step; the interpolant is as accurate as the
step, so event times are good to ~1e-12), simultaneous events, resets and termination.
Everything lives in flat float arrays; nothing allocates per step. The guards and their sign
convention ("every event is a guard falling through zero") are described in
:mod:`biped_opt.hybrid._guards`.

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

from biped_opt._jit import HOT_PATH
from biped_opt.hybrid._dop853 import WORKSPACE, dense_coefficients
from biped_opt.hybrid._dop853 import step as dop853_step
from biped_opt.hybrid._guards import NGUARDS, guard_values
from biped_opt.maneuvers import fill_initial_state
from biped_opt.model.biped import NSTATE, apply_impact, dynamics, foot_support, leg_forces

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

#: |guard| below which another armed guard moving toward zero flips with the first (MODEL.md 3)
SIMULTANEOUS_TOL = 1e-9
#: a flipped guard stays disarmed until it is farther than this from zero
REARM_TOL = 1e-10

# --- Dormand-Prince 8(5,3) step control --------------------------------------------------
_SAFETY = 0.9
_MIN_FACTOR = 0.2
_MAX_FACTOR = 10.0
_MAX_STEPS = 100_000
#: A step size that is a guess rather than the controller's prediction (the first step, the first
#: after an event) may be rejected by any factor its error estimate asks for, down to this one.
_MIN_FACTOR_TRIAL = 1e-3
#: After an event the controller's prediction comes from the previous mode's dynamics; starting
#: the new mode at this fraction of it avoids most rejected first steps (the benchmark cases take
#: ~4% fewer evaluations with these two settings).
_EVENT_STEP_FRACTION = 0.7
#: Event roots are located to this fraction of the step: 1e-13 of a step is ~4e-15 in time,
#: about where the guards' rounding noise leaves the root undetermined anyway.
_ROOT_XTOL = 1e-13


@nb.njit(**HOT_PATH, inline="always")
def _inverse_eighth_root(err):
    """err ** (-1/8), the step-size law of an 8th-order method, by three square roots (a general
    power is a slower libm call, taken once per step)."""
    return 1.0 / math.sqrt(math.sqrt(math.sqrt(err)))


@nb.njit(**HOT_PATH, inline="always")
def _interpolant(y0, f0, f1, f2, f3, f4, f5, f6, x):
    """One component of the 7th-order interpolant at fraction x in [0, 1] of a step, from its
    value y0 at the step's start and its coefficients f0..f6 (SciPy's Dop853DenseOutput form,
    in which x and 1 - x alternate as the factors)."""
    xm = 1.0 - x
    return y0 + x * (f0 + xm * (f1 + x * (f2 + xm * (f3 + x * (f4 + xm * (f5 + x * f6))))))


@nb.njit(**HOT_PATH)
def _dense_eval(F, y, x, out):
    """Interpolant at fraction x in [0, 1] of the step that started at y."""
    for i in range(y.shape[0]):
        out[i] = _interpolant(
            y[i], F[0, i], F[1, i], F[2, i], F[3, i], F[4, i], F[5, i], F[6, i], x
        )


@nb.njit(**HOT_PATH)
def _dense_component(F, y, x, k):
    """Component k of the interpolant at x (what a position or velocity guard needs)."""
    return _interpolant(y[k], F[0, k], F[1, k], F[2, k], F[3, k], F[4, k], F[5, k], F[6, k], x)


@nb.njit(**HOT_PATH, inline="always")
def _guard_component(mode, term_sign, i):
    """(k, sign) such that guard i is sign * y[k] (k = 8, the body's z', for the termination;
    k = 4 + 2 i, the foot's height, for a foot in the air), or (-1, 1.0) when it is the reaction
    force of a foot on the ground."""
    if i == 2:
        return 8, term_sign
    if not mode >> i & 1:
        return 4 + 2 * i, 1.0
    return -1, 1.0


@nb.njit(**HOT_PATH, inline="always")
def _reaction(p, mode, u, y, j):
    """lambda_j at the state y, foot j on the ground: from the legs' forces only (no branch on
    j, so that inlined into the root search it adds no reference counting)."""
    f1, _, n1z, f2, _, n2z, _ = leg_forces(p, mode, y, 0, u)
    w = float(j)
    return (1.0 - w) * foot_support(p, f1, n1z) + w * foot_support(p, f2, n2z)


@nb.njit(**HOT_PATH)
def _guard_on_dense(p, mode, u, term_sign, F, y, x, i, tmp):
    """Guard i on the interpolant at x: one component for a foot height or the body's z', the
    whole state (and the leg forces) only for a reaction force."""
    k, sign = _guard_component(mode, term_sign, i)
    if k >= 0:
        return sign * _dense_component(F, y, x, k)
    _dense_eval(F, y, x, tmp)
    return _reaction(p, mode, u, tmp, i)


@nb.njit(**HOT_PATH)
def _guard_rate(p, mode, u, term_sign, y, dy, i, tmp):
    """d/dt of guard i along the flow of mode ``mode`` at y (dy = vector field at y)."""
    k, sign = _guard_component(mode, term_sign, i)
    if k >= 0:
        return sign * dy[k]
    # lambda_i depends on (q, q'); differentiate along the flow by a central difference.
    eps = 1e-6
    for m in range(y.shape[0]):
        tmp[m] = y[m] + eps * dy[m]
    g_plus = _reaction(p, mode, u, tmp, i)
    for m in range(y.shape[0]):
        tmp[m] = y[m] - eps * dy[m]
    g_minus = _reaction(p, mode, u, tmp, i)
    return (g_plus - g_minus) / (2.0 * eps)


@nb.njit(**HOT_PATH)
def _root_on_dense(p, mode, u, term_sign, F, y, i, xa, ga, xb, gb, tmp):
    """Root in (xa, xb] of guard i on the dense output, by regula falsi with the Anderson-Bjorck
    modification: 6.4 iterates per event over 40 of the benchmark's cases, against 7.8 for the
    Illinois method.

    Requires ga > 0 >= gb. Returns x with the bracket shrunk below _ROOT_XTOL of the step.
    A foot height or the body's z' is one component of the interpolant: its eight coefficients
    are read once and the iteration is arithmetic on them. Only a reaction force needs the
    whole interpolated state and the legs' forces at every iterate.
    """
    k, sign = _guard_component(mode, term_sign, i)
    one_component = k >= 0
    c = max(k, 0)  # (the coefficients are read but unused for a reaction force)
    y0, f0, f1, f2 = y[c], F[0, c], F[1, c], F[2, c]
    f3, f4, f5, f6 = F[3, c], F[4, c], F[5, c], F[6, c]
    side = 0
    x = xb
    for _ in range(200):
        if xb - xa <= _ROOT_XTOL:
            break
        x = (xa * gb - xb * ga) / (gb - ga)
        if not xa < x < xb:
            x = 0.5 * (xa + xb)
        # at least half the tolerance inside the bracket: once x is that close to the root,
        # the next iterate lands on its other side and closes the bracket
        x = min(max(x, xa + 0.5 * _ROOT_XTOL), xb - 0.5 * _ROOT_XTOL)
        if one_component:
            gx = sign * _interpolant(y0, f0, f1, f2, f3, f4, f5, f6, x)
        else:
            _dense_eval(F, y, x, tmp)
            gx = _reaction(p, mode, u, tmp, i)
        # an end kept twice in a row has its value scaled down (Anderson-Bjorck's factor, or
        # Illinois' 0.5 when that is not positive), so both ends keep moving
        if gx > 0.0:
            if side == 1:
                m = 1.0 - gx / ga
                gb *= m if m > 0.0 else 0.5
            xa, ga = x, gx
            side = 1
        else:
            if gx == 0.0:
                xb = x
                break
            if side == -1:
                m = 1.0 - gx / gb
                ga *= m if m > 0.0 else 0.5
            xb, gb = x, gx
            side = -1
    return xb


@nb.njit(**HOT_PATH)
def _record_sample(samples, ns, t, y, mode, lam):
    if ns < samples.shape[0]:
        samples[ns, 0] = t
        for k in range(NSTATE):
            samples[ns, 1 + k] = y[k]
        samples[ns, 1 + NSTATE] = mode
        samples[ns, 2 + NSTATE] = lam[0]
        samples[ns, 3 + NSTATE] = lam[1]
    return ns + 1


@nb.njit(**HOT_PATH)
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


#: layout of the ``cfg`` vector of :func:`simulate_kernel`
CFG_TERM_SIGN = 0  # +1: end when z' falls through 0 (apex); -1: when it rises through 0 (nadir)
CFG_TERM_AFTER_TOUCHDOWN = 1  # 1: the terminal event counts only after the first touchdown
CFG_TERM_MODE = 2  # mode the terminal event must happen in (-1: any), else APEX_IN_CONTACT
CFG_T_END = 3  # time horizon
CFG_MAX_EVENTS = 4  # contact events allowed
CFG_RTOL = 5
CFG_ATOL = 6
CFG_H_MAX = 7  # largest step
CFG_SAMPLE_DT = 8  # spacing of dense samples (<= 0: none)
CFG_SIZE = 9


@nb.njit(**HOT_PATH)
def simulate_kernel(p, y0, mode0, u, cfg, samples, events, y_out):
    """Integrate one maneuver from (t = 0, y0, mode0) to its terminal event.

    Parameters
    ----------
    p : (9,) model parameters; y0 : (14,) initial state; mode0 : initial contact mode;
    u : (3,) inputs (u1, u2, u12); cfg : (CFG_SIZE,) settings, see the CFG_* indices;
    samples : (capacity, SAMPLE_WIDTH) output; events : (max_events + 1, EVENT_WIDTH) output;
    y_out : (14,) final state output.

    Returns
    -------
    (status, t_final, mode_final, n_events, n_samples, nfev, nsteps, nrejected)
    """
    term_sign = cfg[CFG_TERM_SIGN]
    term_after_touchdown = cfg[CFG_TERM_AFTER_TOUCHDOWN] != 0.0
    term_mode = int(cfg[CFG_TERM_MODE])
    t_end = cfg[CFG_T_END]
    max_events = int(cfg[CFG_MAX_EVENTS])
    rtol = cfg[CFG_RTOL]
    atol = cfg[CFG_ATOL]
    h_max = cfg[CFG_H_MAX]
    sample_dt = cfg[CFG_SAMPLE_DT]

    n = NSTATE
    # one allocation carved into views (a dozen separate small arrays cost more than a step):
    # workspace, interpolant (7 n), six states, three reaction pairs, three guard triples
    buf = np.zeros(WORKSPACE + 7 * n + 6 * n + 3 * 2 + 3 * NGUARDS)
    W = buf[:WORKSPACE]
    o = WORKSPACE
    F = buf[o : o + 7 * n].reshape((7, n))
    o += 7 * n
    y = buf[o : o + n]
    f = buf[o + n : o + 2 * n]
    y_new = buf[o + 2 * n : o + 3 * n]
    f_new = buf[o + 3 * n : o + 4 * n]
    tmp = buf[o + 4 * n : o + 5 * n]
    tmp2 = buf[o + 5 * n : o + 6 * n]
    o += 6 * n
    lam = buf[o : o + 2]
    lam_new = buf[o + 2 : o + 4]
    lam_tmp = buf[o + 4 : o + 6]
    gv = buf[o + 6 : o + 9]
    gv_new = buf[o + 9 : o + 12]
    probe = buf[o + 12 : o + 15]
    flags = np.zeros(2 * NGUARDS, dtype=np.bool_)
    armed = flags[:NGUARDS]
    flips = flags[NGUARDS:]
    for k in range(n):
        y[k] = y0[k]

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
    guard_values(mode, term_sign, y, lam, gv)
    for i in range(NGUARDS):
        armed[i] = gv[i] > REARM_TOL
    if not term_enabled:
        armed[2] = False
    if sampling:
        ns = _record_sample(samples, ns, t, y, mode, lam)
        next_sample = 1

    h = _initial_step(p, mode, u, y, f, rtol, atol, h_max, tmp, tmp2, lam_tmp)
    nfev += 1
    trial = True
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
        err = dop853_step(
            p, mode, u, term_sign, y, f, h_step, W, y_new, f_new, lam_new, rtol, atol, probe
        )
        nfev += 12
        nsteps += 1
        if not err < 1.0:
            h = h_step * max(_MIN_FACTOR_TRIAL if trial else _MIN_FACTOR,
                             _SAFETY * _inverse_eighth_root(err))
            nrejected += 1
            step_rejected = True
            continue
        if err == 0.0:
            factor = _MAX_FACTOR
        else:
            factor = min(_MAX_FACTOR, _SAFETY * _inverse_eighth_root(err))
        if step_rejected:
            factor = min(1.0, factor)
        step_rejected = False
        trial = False
        h = h_step * factor

        # --- event detection: a sign change at the step's end, or at a stage inside it -----
        guard_values(mode, term_sign, y_new, lam_new, gv_new)
        any_candidate = False
        for i in range(NGUARDS):
            if armed[i] and gv[i] > 0.0 and (gv_new[i] <= 0.0 or probe[i] <= 1.0):
                any_candidate = True

        dense_ready = False
        if any_candidate or sampling:
            dense_coefficients(p, mode, u, y, f, h_step, W, y_new, f_new, F)
            nfev += 3
            dense_ready = True

        first = -1
        x_first = 2.0
        if any_candidate:
            for i in range(NGUARDS):
                if not (armed[i] and gv[i] > 0.0):
                    continue
                if gv_new[i] <= 0.0:
                    xb = 1.0
                    gb = gv_new[i]
                elif probe[i] <= 1.0:
                    # confirm the stage's hint on the interpolant, scanning up to the stage
                    xb = -1.0
                    gb = 0.0
                    for m in range(1, 9):
                        xm = probe[i] * m / 8.0
                        gm = _guard_on_dense(p, mode, u, term_sign, F, y, xm, i, tmp)
                        if gm <= 0.0:
                            xb = xm
                            gb = gm
                            break
                    if xb < 0.0:
                        continue
                else:
                    continue
                x = _root_on_dense(
                    p, mode, u, term_sign, F, y, i, 0.0, gv[i], xb, gb, tmp
                )
                if x < x_first:
                    x_first = x
                    first = i
        t_stop = t + h_step if first < 0 else t + x_first * h_step

        # --- dense samples inside (t, t_stop] (before an event: strictly before it) ----------
        if sampling and dense_ready:
            while True:
                ts = next_sample * sample_dt
                if ts > t_stop or (first >= 0 and ts >= t_stop):
                    break
                _dense_eval(F, y, (ts - t) / h_step, tmp)
                dynamics(p, mode, tmp, u, tmp2, lam_tmp)
                nfev += 1
                ns = _record_sample(samples, ns, ts, tmp, mode, lam_tmp)
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

        # --- event at t_stop: the state is the 7th-order interpolant at the root -----------
        t = t_stop
        _dense_eval(F, y, x_first, tmp)
        for k in range(n):
            y[k] = tmp[k]
        dynamics(p, mode, y, u, f, lam)
        nfev += 1
        guard_values(mode, term_sign, y, lam, gv_new)  # every guard at the event
        for i in range(NGUARDS):
            flips[i] = i == first
            if i != first and armed[i]:
                if abs(gv_new[i]) <= SIMULTANEOUS_TOL:
                    flips[i] = (
                        _guard_rate(p, mode, u, term_sign, y, f, i, tmp) < 0.0
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
            guard_values(mode, term_sign, y, lam, gv)
            for i in range(NGUARDS):
                if flips[i]:
                    armed[i] = False
                elif i == 2 and not armed[2] and term_enabled:
                    armed[2] = gv[2] > REARM_TOL
            h *= _EVENT_STEP_FRACTION
            trial = True
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


@nb.njit(**HOT_PATH)
def simulate_maneuver(p, code, theta0, mode0, u, cfg, samples, events, y_out):
    """:func:`simulate_kernel` from the initial state of maneuver ``code`` (ManeuverSpec.code)
    at pitch theta0, built here rather than by the caller (one compiled call per trajectory)."""
    y0 = np.empty(NSTATE)
    fill_initial_state(code, theta0, p, y0)
    return simulate_kernel(p, y0, mode0, u, cfg, samples, events, y_out)


@nb.njit(**HOT_PATH, parallel=True)
def simulate_batch_kernel(p, code, thetas, mode0, us, cfg, events, y_out, info):
    """:func:`simulate_maneuver` over many initial pitches and inputs, in parallel threads.

    thetas : (N,); us : (N, 3); cfg : as for simulate_kernel (no samples);
    events : (N, max_events + 1, EVENT_WIDTH); y_out : (N, 14); info : (N, 8) receives the
    kernel's returned tuple per trajectory.
    """
    no_samples = np.empty((0, SAMPLE_WIDTH))
    for k in nb.prange(thetas.shape[0]):
        status, t_f, mode_f, n_ev, n_s, nfev, nsteps, nrej = simulate_maneuver(
            p, code, thetas[k], mode0, us[k], cfg, no_samples, events[k], y_out[k]
        )
        info[k, 0] = status
        info[k, 1] = t_f
        info[k, 2] = mode_f
        info[k, 3] = n_ev
        info[k, 4] = n_s
        info[k, 5] = nfev
        info[k, 6] = nsteps
        info[k, 7] = nrej
