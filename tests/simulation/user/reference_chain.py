"""Independent reference for chain.py: SciPy's solve_ivp (DOP853) on the chain's equations of
motion derived here again, from the links' velocity Jacobians rather than from the kinetic
energy's Hessian: M(q) = sum_i m_i Jv_i^T Jv_i + I_i Jw_i^T Jw_i, and the velocity forces from the
Christoffel symbols of M, c_i = sum_jk (dM_ij/dq_k - dM_jk/dq_i / 2) q'_j q'_k. Imports nothing
from biped_opt. The event rules are those of reference_flight (the model's, MODEL.md Sec. 3),
with solve_ivp locating the roots on its dense output (steps of at most MAX_STEP, so that no
foot lands and leaves again unseen inside one step).
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp

from .reference_flight import BAND, MAX_EVENTS, REARM, T_END, Outcome, ReferenceError

PARAMETERS = {"mb": 1.0, "ml": 0.5, "lb": 0.3, "leg": 0.5, "k": 20.0, "rest": 0.9, "g": 1.0,
              "e": 0.6}
RTOL, ATOL, MAX_STEP = 1e-12, 1e-13, 0.02


@cache
def _functions():
    """(M, forces, feet heights, feet Jacobian, energy) as NumPy functions of (q, q', p)."""
    q = sp.symbols("x z th a1 a2", real=True)
    v = sp.symbols("vx vz vth va1 va2", real=True)
    mb, ml, lb, leg, k, rest, g = sp.symbols("mb ml lb leg k rest g", positive=True)
    x, z, th, a1, a2 = q
    phi1, phi2 = th + a1, th + a2  # the outer links' pitches

    def rot(angle):
        return sp.Matrix([sp.cos(angle), sp.sin(angle)])

    hinges = [sp.Matrix([x, z]) - lb * rot(th), sp.Matrix([x, z]) + lb * rot(th)]
    tips = [hinges[0] - leg * rot(phi1), hinges[1] + leg * rot(phi2)]
    bodies = [  # (mass, centre, inertia, pitch)
        (mb, sp.Matrix([x, z]), mb * lb**2 / 3, th),
        (ml, (hinges[0] + tips[0]) / 2, ml * leg**2 / 12, phi1),
        (ml, (hinges[1] + tips[1]) / 2, ml * leg**2 / 12, phi2),
    ]
    qm = sp.Matrix(q)
    M = sp.zeros(5, 5)
    for mass, centre, inertia, pitch in bodies:
        Jv = centre.jacobian(qm)
        Jw = sp.Matrix([pitch]).jacobian(qm)
        M += mass * Jv.T * Jv + inertia * Jw.T * Jw
    M = M.applyfunc(sp.expand)
    c = sp.zeros(5, 1)
    for i in range(5):
        c[i] = sum((sp.diff(M[i, j], q[kk]) - sp.diff(M[j, kk], q[i]) / 2) * v[j] * v[kk]
                   for j in range(5) for kk in range(5))
    V = sum(mass * g * centre[1] for mass, centre, _i, _p in bodies) \
        + k * (a1 - rest) ** 2 / 2 + k * (a2 + rest) ** 2 / 2
    forces = -c - sp.Matrix([V]).jacobian(qm).T
    vm = sp.Matrix(v)
    energy = (vm.T * M * vm)[0] / 2 + V
    feet = sp.Matrix([tips[0][1], tips[1][1]])
    params = (mb, ml, lb, leg, k, rest, g)
    args = (q, v, params)
    return (sp.lambdify(args, M, "numpy", cse=True), sp.lambdify(args, forces, "numpy", cse=True),
            sp.lambdify(args, feet, "numpy"), sp.lambdify(args, feet.jacobian(qm), "numpy"),
            sp.lambdify(args, energy, "numpy", cse=True))


class Chain:
    """The chain at given parameters: its vector field, guards, impact map and energy."""

    def __init__(self, **overrides):
        values = {**PARAMETERS, **overrides}
        self.gamma = values.pop("e")
        self.p = tuple(values[name] for name in ("mb", "ml", "lb", "leg", "k", "rest", "g"))
        self._M, self._f, self._feet, self._da, self._energy = _functions()

    def initial(self, tilt):
        rest = self.p[5]
        return np.array([0.0, 1.2, tilt, rest + 0.25, -rest - 0.25, 0, 0, 0, 0, 0])

    def mass(self, y):
        return np.array(self._M(y[:5], y[5:], self.p), dtype=float)

    def field(self, _t, y):
        acc = np.linalg.solve(self.mass(y), np.array(self._f(y[:5], y[5:], self.p),
                                                      dtype=float).ravel())
        return np.concatenate([y[5:], acc])

    def feet(self, y):
        return np.array(self._feet(y[:5], y[5:], self.p), dtype=float).ravel()

    def feet_rates(self, y):
        return np.array(self._da(y[:5], y[5:], self.p), dtype=float) @ y[5:]

    def energy(self, y):
        return float(self._energy(y[:5], y[5:], self.p))

    def impact(self, y, active):
        Da = np.array(self._da(y[:5], y[5:], self.p), dtype=float)[sorted(active)]
        Minv_DaT = np.linalg.solve(self.mass(y), Da.T)
        mult = np.linalg.solve(Da @ Minv_DaT, Da @ y[5:])
        return np.concatenate([y[:5], y[5:] - (1 + self.gamma) * Minv_DaT @ mult])


def simulate(chain: Chain, tilt: float, *, band=BAND, max_events=MAX_EVENTS,
             t_end=T_END) -> Outcome:
    """The ``drop`` maneuver: to the middle link's first apex after the first impact."""
    y = chain.initial(tilt)
    armed = [bool(a > REARM) for a in chain.feet(y)]
    touched = False
    t = 0.0
    out = Outcome("HORIZON", t_end, y, math.nan)

    def foot(j):
        def event(_t, yy):
            return chain.feet(yy)[j]
        event.terminal, event.direction = True, -1
        return event

    def apex(_t, yy):
        return yy[6]

    apex.terminal, apex.direction = True, -1
    while t < t_end:
        events = [foot(0), foot(1)] + ([apex] if touched else [])
        sol = solve_ivp(chain.field, (t, t_end), y, method="DOP853", rtol=RTOL, atol=ATOL,
                        max_step=MAX_STEP, events=events, dense_output=True)
        hits = [(te[0], j) for j, te in enumerate(sol.t_events) if len(te)]
        if not hits:
            out.y_final = sol.y[:, -1]
            out.outcome = out.y_final[7]
            return out
        t_hit, first = min(hits)
        y_hit = sol.sol(t_hit)
        if first == 2:
            out.status, out.t_final, out.y_final, out.outcome = "OK", t_hit, y_hit, y_hit[7]
            return out
        if not armed[first]:
            # a foot that has just bounced: it counts only after rising beyond REARM
            probe = sol.sol(np.linspace(t, t_hit, 2001))
            heights = np.array([chain.feet(probe[:, i])[first] for i in range(probe.shape[1])])
            if heights.max() <= 2 * REARM:
                raise ReferenceError("a foot hops less than the re-arming distance")
            armed[first] = True
        for j in range(2):  # a foot that rose beyond REARM on the way is armed again
            if not armed[j]:
                probe = sol.sol(np.linspace(t, t_hit, 2001))
                armed[j] = bool(max(chain.feet(probe[:, i])[j]
                                    for i in range(probe.shape[1])) > REARM)
        heights, rates = chain.feet(y_hit), chain.feet_rates(y_hit)
        flips = {first}
        for j in range(2):
            if j != first and armed[j] and rates[j] < 0.0:
                if abs(heights[j]) <= band:
                    flips.add(j)
                if band > 0 and abs(heights[j]) < 10 * band:
                    out.band_margin = min(out.band_margin, abs(abs(heights[j]) / band - 1))
        y = chain.impact(y_hit, flips)
        if np.any(chain.feet_rates(y)[sorted(flips)] <= 0.0):
            raise ReferenceError("an impacted foot does not separate")
        for j in flips:
            armed[j] = False
        t = t_hit
        touched = True
        out.events.append((t, frozenset(flips)))
        if len(out.events) >= max_events:
            out.status, out.t_final, out.y_final, out.outcome = "MAX_EVENTS", t, y, y[7]
            return out
    return out
