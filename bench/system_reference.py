"""An independent reference simulator for any mechanical system with unilateral constraints.

SciPy's ``solve_ivp`` (DOP853) with its own event location, driving a *model* object written
from SYSTEMS.md alone (``bench/walker_model.py``, ``bench/rocking_bar_model.py``); nothing here
imports biped_opt, so the benchmark's error figures compare two implementations.

The model provides ``ncon``, ``initial_state(maneuver, s) -> (y, mode)``,
``rhs(y, mode, u) -> y'``, ``contact_guards(y, mode, u)`` (a_j in the air, lambda_j in contact:
an event is a guard falling through 0), ``impact(y, mode) -> y`` (Eq. (1b) on entering mode),
``constraint_rates(y)`` (Da q'), ``terminal(maneuver, y)``, ``armed_after_touchdown(maneuver)``,
``final_mode(maneuver)`` (None: any) and ``outcome(maneuver, y)``. The rules are SYSTEMS.md
Secs. 1 and 5: simultaneous guards within 1e-9 moving toward zero flip together; a flipped guard is
disarmed until it is 1e-10 from zero (re-arming is an event of its own); with restitution an
impacted constraint moving apart leaves the mode at once.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from scipy.integrate import solve_ivp

# the same integration and event settings as the biped's comparator
from bench.solve_ivp_reference import (
    _RATE_STEP,
    ATOL,
    MAX_STEP,
    REARM_TOL,
    RTOL,
    SIMULTANEOUS_TOL,
)

__all__ = ["ReferenceError", "ReferenceResult", "simulate", "RTOL", "ATOL"]

#: an impacted constraint moving apart faster than this leaves the mode (restitution)
SEPARATION_TOL = 1e-12


class ReferenceError(RuntimeError):
    """The reference simulation did not reach its terminal event."""


class ReferenceResult(NamedTuple):
    outcome: float
    t_final: float
    modes: tuple[int, ...]
    touchdowns: tuple[int, ...]  #: the constraints (bit masks) of each impact, in order
    nfev: int


def _rate(model: Any, j: int, y: np.ndarray, mode: int, u) -> float:
    f = np.asarray(model.rhs(y, mode, u))
    hi = model.contact_guards(y + _RATE_STEP * f, mode, u)[j]
    lo = model.contact_guards(y - _RATE_STEP * f, mode, u)[j]
    return (hi - lo) / (2.0 * _RATE_STEP)


def _event(model: Any, maneuver: str, mode: int, u, j: int, *, fire: bool):
    """solve_ivp event of guard j (j = ncon: the terminal one): its falling through 0 when
    armed, else its leaving the re-arming band."""
    def guard(_t, yv):
        if j == model.ncon:
            return model.terminal(maneuver, yv)
        return model.contact_guards(yv, mode, u)[j]

    def event(t, yv):
        return guard(t, yv) if fire else abs(guard(t, yv)) - REARM_TOL

    event.terminal = True
    event.direction = -1.0 if fire else 1.0
    return event


def simulate(model: Any, maneuver: str, s: float, u=(), *, rtol: float = RTOL,
             atol: float = ATOL, t_end: float = 10.0, max_events: int = 32) -> ReferenceResult:
    n = model.ncon
    y, mode = model.initial_state(maneuver, s)
    y = np.asarray(y, dtype=float)
    term_live = not model.armed_after_touchdown(maneuver)
    guards = list(model.contact_guards(y, mode, u))
    armed = [abs(g) > REARM_TOL for g in guards] + [abs(model.terminal(maneuver, y)) > REARM_TOL]
    t = 0.0
    modes = [mode]
    touchdowns: list[int] = []
    nfev = 0
    for _ in range(3 * max_events + 8):
        current = mode

        def fun(_t, yv, current=current):
            return model.rhs(yv, current, u)

        events, roles = [], []
        for j in range(n + 1):
            if j == n and not term_live:
                continue
            ev = _event(model, maneuver, current, u, j, fire=armed[j])
            roles.append((j, "fire" if armed[j] else "rearm"))
            events.append(ev)
        sol = solve_ivp(fun, (t, t_end), y, method="DOP853", rtol=rtol, atol=atol,
                        events=events, max_step=MAX_STEP)
        nfev += sol.nfev
        if sol.status != 1:
            raise ReferenceError(f"{maneuver} at {s}: {sol.message} (status {sol.status})")
        t = float(sol.t[-1])
        y = sol.y[:, -1].copy()
        fired = [roles[i] for i, te in enumerate(sol.t_events) if te.size and te[-1] == t]
        for j, role in fired:
            if role == "rearm":
                armed[j] = True
        firing = [j for j, role in fired if role == "fire"]
        if not firing:
            continue
        if n in firing:
            final = model.final_mode(maneuver)
            if final is not None and mode != final:
                raise ReferenceError(f"{maneuver} at {s}: terminal event in mode {mode}")
            return ReferenceResult(float(model.outcome(maneuver, y)), t, tuple(modes),
                                   tuple(touchdowns), nfev)
        values = model.contact_guards(y, mode, u)
        flip = 0
        for j in range(n):
            if j in firing or (armed[j] and abs(values[j]) <= SIMULTANEOUS_TOL
                               and _rate(model, j, y, mode, u) <= 0.0):
                flip |= 1 << j
        landing = flip & ~mode
        mode ^= flip
        separated = 0
        if landing:
            y = np.asarray(model.impact(y, mode), dtype=float)
            rates = model.constraint_rates(y)
            for j in range(n):
                if landing >> j & 1 and rates[j] > SEPARATION_TOL:
                    separated |= 1 << j
            mode &= ~separated
            touchdowns.append(landing)
            if not term_live:
                term_live = True
                armed[n] = abs(model.terminal(maneuver, y)) > REARM_TOL
        new = model.contact_guards(y, mode, u)
        for j in range(n):
            if flip >> j & 1 or separated >> j & 1:
                if (landing & ~separated) >> j & 1 and new[j] < 0.0:
                    raise ReferenceError(f"inconsistent contact {j} at t = {t}")
                armed[j] = abs(new[j]) > REARM_TOL
            elif not armed[j]:
                armed[j] = abs(new[j]) > REARM_TOL
        modes.append(mode)
        if len(modes) > max_events + 1:
            break
    raise ReferenceError(f"{maneuver} at {s}: more than {max_events} contact events")
