"""Fixed-step RK4 + bisection "relaxation" simulator, in the style of the paper's algorithm.

[1]_ simulates with a fixed-step integrator and resolves contact events only to within an
*event strip*: when a guard changes sign during a step of ``dt`` = 1e-3, the step is bisected
(re-integrating from the step's start) until the crossing is bracketed within ``strip`` = 1e-5 in
time; the state at the far end of the bracket, already past the guard, is taken as the event
state, every guard that has crossed by then flips (so events closer than the strip in time merge
into one simultaneous event), the reset Eq. (1b) is applied and integration continues.

Its outcomes carry O(strip) and O(dt^4) errors (about 1e-5 to 1e-3 here): the benchmark shows
what event location to 1e-10 buys. Pure Python on the model of :mod:`bench.biped_model`.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

from bench import biped_model as bm
from bench.solve_ivp_reference import ReferenceResult

__all__ = ["simulate", "DT", "STRIP"]

#: fixed time step of the integrator
DT = 1e-3
#: event strip: events are bracketed to this width in time
STRIP = 1e-5
#: a foot in the air this far below the ground sank through it: far deeper than the strip's
#: overshoot at touchdown (STRIP * |z_j'| ~ 1e-5), which stays as a residual penetration
SINK_TOL = 1e-4


def _rk4(y: list, mode: int, u, p: bm.Params, h: float) -> list:
    """One classical Runge-Kutta step of size h in mode ``mode``."""
    k1 = bm.rhs(y, mode, u, p)
    k2 = bm.rhs([a + 0.5 * h * b for a, b in zip(y, k1)], mode, u, p)
    k3 = bm.rhs([a + 0.5 * h * b for a, b in zip(y, k2)], mode, u, p)
    k4 = bm.rhs([a + h * b for a, b in zip(y, k3)], mode, u, p)
    return [
        a + h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
        for a, b1, b2, b3, b4 in zip(y, k1, k2, k3, k4)
    ]


def simulate(
    maneuver: str,
    theta0: float,
    u=(0.0, 0.0, 0.0),
    *,
    params: bm.Params = bm.DEFAULT_PARAMS,
    dt: float = DT,
    strip: float = STRIP,
    t_end: float = 10.0,
    max_events: int = 32,
) -> ReferenceResult:
    """Simulate ``maneuver`` from pitch ``theta0`` with inputs ``u`` = (u1, u2[, u12]).

    Same result type as :func:`bench.solve_ivp_reference.simulate`; ``nfev`` counts right-hand
    sides. A guard fires when it goes from strictly positive to <= 0 within a step, which also
    keeps a guard that a reset left at (or just past) zero from re-firing.
    """
    p = params
    uu = tuple(float(v) for v in u) + (0.0,) * (3 - len(u))
    y, mode = bm.initial_state(maneuver, theta0, p)
    touchdown = maneuver == "touchdown"
    term_sign = -1.0 if touchdown else 1.0
    term_live = not touchdown
    t = 0.0
    modes = [bm.MODE_NAMES[mode]]
    nfev = 0

    def guards(yv: list) -> tuple[float, float, float]:
        g1, g2 = bm.contact_guards(yv, mode, uu, p)
        return g1, g2, (term_sign * yv[8] if term_live else 1.0)

    def crossed(before, after) -> list[int]:
        return [j for j in range(3) if before[j] > 0.0 and after[j] <= 0.0]

    g_now = guards(y)
    while t < t_end:
        y_new = _rk4(y, mode, uu, p, dt)
        nfev += 4
        g_new = guards(y_new)
        hits = crossed(g_now, g_new)
        if not hits:
            t, y, g_now = t + dt, y_new, g_new
            for j in range(2):
                if not mode >> j & 1 and y[4 + 2 * j] < -SINK_TOL:
                    raise bm.ComparatorError(
                        f"inconsistent contact at t = {t}: foot {j + 1} went through the ground"
                    )
            continue
        lo, hi = 0.0, dt
        y_hi = y_new
        while hi - lo > strip:
            mid = 0.5 * (lo + hi)
            y_mid = _rk4(y, mode, uu, p, mid)
            nfev += 4
            if crossed(g_now, guards(y_mid)):
                hi, y_hi = mid, y_mid
            else:
                lo = mid
        t += hi
        y = y_hi
        hits = crossed(g_now, guards(y))
        if 2 in hits:
            if not touchdown and mode != bm.AIR:
                raise bm.ComparatorError(
                    f"liftoff: apex at t = {t} with mode {bm.MODE_NAMES[mode]} (a foot is"
                    f" down); modes {' -> '.join(modes)}"
                )
            return ReferenceResult(float(y[2]), t, tuple(modes), nfev)
        flip = sum(1 << j for j in hits)
        landing = flip & ~mode
        mode ^= flip
        if landing:
            y = bm.apply_touchdown(y, landing, p)
            term_live = True
        modes.append(bm.MODE_NAMES[mode])
        if len(modes) > max_events + 1:
            raise bm.ComparatorError(f"{maneuver}: more than {max_events} contact events")
        g_now = guards(y)
    raise bm.ComparatorError(f"{maneuver}: horizon t = {t_end} reached before the end")
