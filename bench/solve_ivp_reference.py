"""Independent reference simulator: SciPy ``solve_ivp`` (DOP853) with its own event location.

The straightforward implementation of MODEL.md Sec. 3 the benchmark measures against: one
``solve_ivp`` call per contact mode, each guard a terminal event of direction -1 (the guard falls
through zero) located by ``solve_ivp``'s root finder on the dense output.

- Guards [1]_ Sec. II-A: z_j for a foot in the air (touchdown: z_j' := -gamma z_j', Eq. (1b)),
  lambda_j for a foot on the ground (liftoff, no velocity change).
- Simultaneous events: after the first guard, every other armed guard within
  :data:`SIMULTANEOUS_TOL` of zero and moving toward it flips at the same instant, so th0 = 0
  exactly gives AIR -> GROUND (touchdown) and GROUND -> AIR (liftoff).
- A guard that has just flipped (or starts at zero) is disarmed until |guard| > :data:`REARM_TOL`;
  re-arming is itself a terminal event (no state change), so a reset never re-triggers itself.
- Termination: touchdown at the body's nadir (z' rising through 0) after the first touchdown;
  liftoff at the apex (z' falling through 0), which must happen in AIR.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.integrate import solve_ivp

from bench import biped_model as bm

__all__ = ["ReferenceResult", "simulate", "RTOL", "ATOL"]

RTOL = 1e-11
ATOL = 1e-12
#: largest step: bounds how far a guard's double crossing can hide inside one step
MAX_STEP = 0.05
#: second guards this close to zero at an event flip with it (MODEL.md Sec. 3)
SIMULTANEOUS_TOL = 1e-9
#: a flipped guard re-arms once farther than this from zero
REARM_TOL = 1e-10
#: step of the central difference that gives a guard's time derivative (sign only)
_RATE_STEP = 1e-7


class ReferenceResult(NamedTuple):
    """Outcome th(t_f), terminal time, visited contact modes (names), right-hand sides."""

    outcome: float
    t_final: float
    mode_sequence: tuple[str, ...]
    nfev: int


def _guard_rate(j: int, y: np.ndarray, mode: int, u, p: bm.Params) -> float:
    """d/dt of contact guard j along the flow of ``mode`` (a central difference; sign is used)."""
    f = np.asarray(bm.rhs(y.tolist(), mode, u, p))
    hi = bm.contact_guards((y + _RATE_STEP * f).tolist(), mode, u, p)[j]
    lo = bm.contact_guards((y - _RATE_STEP * f).tolist(), mode, u, p)[j]
    return (hi - lo) / (2.0 * _RATE_STEP)


def _terminal(fun):
    fun.terminal = True
    return fun


def simulate(
    maneuver: str,
    theta0: float,
    u=(0.0, 0.0, 0.0),
    *,
    params: bm.Params = bm.DEFAULT_PARAMS,
    rtol: float = RTOL,
    atol: float = ATOL,
    t_end: float = 10.0,
    max_events: int = 32,
) -> ReferenceResult:
    """Simulate ``maneuver`` ("touchdown" or "liftoff") from pitch ``theta0`` with inputs ``u``.

    ``u`` = (u1, u2[, u12]). Raises :class:`~bench.biped_model.ComparatorError` if the maneuver
    does not end at its terminal event (horizon, event budget, apex in contact, inconsistency).
    """
    p = params
    uu = tuple(float(v) for v in u) + (0.0,) * (3 - len(u))
    y_list, mode = bm.initial_state(maneuver, theta0, p)
    y = np.asarray(y_list)
    touchdown = maneuver == "touchdown"
    # termination guard, normalised to "falls through zero": -z' (nadir) or +z' (apex)
    term_sign = -1.0 if touchdown else 1.0
    term_live = not touchdown  # the touchdown maneuver's nadir counts only after a touchdown

    def term_value(yv) -> float:
        return term_sign * yv[8]

    guards = bm.contact_guards(y_list, mode, uu, p)
    armed = [abs(g) > REARM_TOL for g in guards] + [abs(term_value(y_list)) > REARM_TOL]
    t = 0.0
    modes = [bm.MODE_NAMES[mode]]
    nfev = 0
    for _ in range(3 * max_events + 8):  # contact events and guard re-arming restarts
        current = mode

        def fun(_t, yv, current=current):
            return bm.rhs(yv.tolist(), current, uu, p)

        def guard_fn(j, current=current):
            if j == 2:
                return lambda _t, yv: term_value(yv)
            return lambda _t, yv: bm.contact_guards(yv.tolist(), current, uu, p)[j]

        events = []
        roles = []  # (guard index, "fire" or "rearm")
        for j in range(3):
            if j == 2 and not term_live:
                continue
            g = guard_fn(j)
            if armed[j]:
                ev = _terminal(lambda tt, yv, g=g: g(tt, yv))
                ev.direction = -1.0
                roles.append((j, "fire"))
            else:
                ev = _terminal(lambda tt, yv, g=g: abs(g(tt, yv)) - REARM_TOL)
                ev.direction = 1.0
                roles.append((j, "rearm"))
            events.append(ev)
        sol = solve_ivp(
            fun, (t, t_end), y, method="DOP853", rtol=rtol, atol=atol, events=events,
            max_step=MAX_STEP,
        )
        nfev += sol.nfev
        if sol.status == -1:
            raise bm.ComparatorError(f"solve_ivp failed: {sol.message}")
        if sol.status == 0:
            raise bm.ComparatorError(f"{maneuver}: horizon t = {t_end} reached before the end")
        t = float(sol.t[-1])
        y = sol.y[:, -1].copy()
        fired = [roles[i] for i, te in enumerate(sol.t_events) if te.size and te[-1] == t]
        for j, role in fired:
            if role == "rearm":
                armed[j] = True
                if j < 2 and not mode >> j & 1 and y[4 + 2 * j] < 0.0:
                    # the guard left zero downward: a lifted foot sank into the ground
                    raise bm.ComparatorError(
                        f"inconsistent contact at t = {t}: foot {j + 1} went through the ground"
                    )
        firing = [j for j, role in fired if role == "fire"]
        if not firing:
            continue
        if 2 in firing:
            if not touchdown and mode != bm.AIR:
                raise bm.ComparatorError(
                    f"liftoff: apex at t = {t} with mode {bm.MODE_NAMES[mode]} (a foot is"
                    f" down); modes {' -> '.join(modes)}"
                )
            return ReferenceResult(float(y[2]), t, tuple(modes), nfev)
        # simultaneous events: armed guards within the tolerance and moving toward zero flip too
        values = bm.contact_guards(y.tolist(), mode, uu, p)
        flip = 0
        for j in range(2):
            if j in firing or (
                armed[j]
                and abs(values[j]) <= SIMULTANEOUS_TOL
                and _guard_rate(j, y, mode, uu, p) <= 0.0
            ):
                flip |= 1 << j
        landing = flip & ~mode
        mode ^= flip
        if landing:
            y = np.asarray(bm.apply_touchdown(y.tolist(), landing, p))
            if touchdown and not term_live:
                term_live = True
                armed[2] = abs(term_value(y)) > REARM_TOL
        new = bm.contact_guards(y.tolist(), mode, uu, p)
        for j in range(2):
            if flip >> j & 1:
                if landing >> j & 1 and new[j] < 0.0:
                    raise bm.ComparatorError(
                        f"inconsistent contact at t = {t}: lambda_{j + 1} = {new[j]} < 0"
                    )
                armed[j] = abs(new[j]) > REARM_TOL
        modes.append(bm.MODE_NAMES[mode])
        if len(modes) > max_events + 1:
            break
    raise bm.ComparatorError(f"{maneuver}: more than {max_events} contact events")
