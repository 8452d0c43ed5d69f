"""Independent reference for the planar chain (chain.py here; the library's ``chain(segments)``):
SciPy's solve_ivp (DOP853) on the chain's equations of motion derived here again, from the links'
velocity Jacobians rather than from the kinetic energy's Hessian:
M(q) = sum_i m_i Jv_i^T Jv_i + I_i Jw_i^T Jw_i, and the velocity forces from the Christoffel
symbols of M, c_i = sum_jk (dM_ij/dq_k - dM_jk/dq_i / 2) q'_j q'_k. Imports nothing from
biped_opt. The event rules are those of reference_flight (the model's, MODEL.md Sec. 3), with
solve_ivp locating the roots on its dense output (steps of at most MAX_STEP, so that no foot lands
and leaves again unseen inside one step).

The chain: a middle link (centre x, z, pitch th, half-length lb) with a leg hinged at each end;
a leg is ``segments`` links in series, each hinge angle relative to the link before it (the
joints a, b, c, d from the middle link outwards; 1 the left leg, 2 the right one), a torsional
spring at every hinge around +-rest (the legs mirror each other), the last link's end a foot on
the ground. q = (x, z, th, a1, a2, b1, b2, ...).
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp

from .reference_flight import BAND, MAX_EVENTS, REARM, T_END, Outcome, ReferenceError

#: one link per leg (chain.py's): middle link mb, lb; leg link ml, leg; spring k around rest
PARAMETERS = {"mb": 1.0, "ml": 0.5, "lb": 0.3, "leg": 0.5, "k": 20.0, "rest": 0.9, "g": 1.0,
              "e": 0.6}
#: more links per leg: (mass, length, spring, rest angle) of each leg's links from the hip on
LINKS = {
    2: ((0.5, 0.35, 20.0, 0.9), (0.5, 0.35, 10.0, 0.2)),
    3: ((0.5, 0.25, 20.0, 0.9), (0.6, 0.25, 10.0, 0.2), (0.8, 0.2, 10.0, 0.2)),
    4: ((0.5, 0.2, 20.0, 0.9), (0.6, 0.2, 10.0, 0.2), (0.7, 0.15, 10.0, 0.2),
        (0.8, 0.15, 10.0, 0.1)),
}
JOINTS = "abcd"
RTOL, ATOL, MAX_STEP = 1e-12, 1e-13, 0.02
#: how far beyond rest the hips start (the other hinges start at rest)
SPREAD = 0.25
HEIGHT = 1.2


def parameters(segments: int = 1) -> dict[str, float]:
    """The chain's parameters by name (``e`` its restitution): link j >= 2 of each leg has
    ``ml<j>``, ``leg<j>``, ``k<j>``, ``rest<j>``; link 1 has ``ml``, ``leg``, ``k``, ``rest``."""
    if segments == 1:
        return dict(PARAMETERS)
    out = {"mb": 1.0, "lb": 0.3, "g": 1.0, "e": 0.6}
    for j, (mass, length, spring, rest) in enumerate(LINKS[segments], start=1):
        tail = "" if j == 1 else str(j)
        out.update({f"ml{tail}": mass, f"leg{tail}": length, f"k{tail}": spring,
                    f"rest{tail}": rest})
    return out


def coordinate_names(segments: int = 1) -> list[str]:
    return ["x", "z", "th"] + [f"{JOINTS[j]}{i}" for j in range(segments) for i in (1, 2)]


@cache
def _functions(segments: int):
    """(parameter names, M, forces, feet heights, feet Jacobian, energy) as NumPy functions of
    (q, q', p)."""
    names = coordinate_names(segments)
    q = sp.symbols(names, real=True)
    v = sp.symbols([f"v{n}" for n in names], real=True)
    pnames = [n for n in parameters(segments) if n != "e"]
    p = dict(zip(pnames, sp.symbols(pnames, positive=True)))
    x, z, th = q[:3]

    def rot(angle):
        return sp.Matrix([sp.cos(angle), sp.sin(angle)])

    def link(j, what):
        return p[what if j == 0 else f"{what}{j + 1}"]

    # (mass, centre, inertia, pitch) of every body: the middle link, then each leg outwards
    bodies = [(p["mb"], sp.Matrix([x, z]), p["mb"] * p["lb"] ** 2 / 3, th)]
    springs = 0
    tips = []
    for leg, side in ((0, -1), (1, 1)):  # the left leg points along -rot(pitch)
        joint = sp.Matrix([x, z]) + side * p["lb"] * rot(th)
        pitch = th
        for j in range(segments):
            angle = q[3 + 2 * j + leg]
            pitch = pitch + angle
            end = joint + side * link(j, "leg") * rot(pitch)
            bodies.append((link(j, "ml"), (joint + end) / 2, link(j, "ml") * link(j, "leg") ** 2
                           / 12, pitch))
            springs += link(j, "k") * (angle + side * link(j, "rest")) ** 2 / 2
            joint = end
        tips.append(joint)
    d = len(q)
    qm = sp.Matrix(q)
    M = sp.zeros(d, d)
    for mass, centre, inertia, pitch in bodies:
        Jv = centre.jacobian(qm)
        Jw = sp.Matrix([pitch]).jacobian(qm)
        M += mass * Jv.T * Jv + inertia * Jw.T * Jw
    M = M.applyfunc(sp.expand)
    dM = [M.diff(qk) for qk in q]  # dM[k][i, j] = dM_ij / dq_k
    c = sp.zeros(d, 1)
    for i in range(d):
        c[i] = sum((dM[kk][i, j] - dM[i][j, kk] / 2) * v[j] * v[kk]
                   for j in range(d) for kk in range(d))
    V = sum(mass * p["g"] * centre[1] for mass, centre, _i, _p in bodies) + springs
    forces = -c - sp.Matrix([V]).jacobian(qm).T
    vm = sp.Matrix(v)
    energy = (vm.T * M * vm)[0] / 2 + V
    feet = sp.Matrix([tips[0][1], tips[1][1]])
    args = (q, v, tuple(p.values()))
    return (tuple(pnames), sp.lambdify(args, M, "numpy", cse=True),
            sp.lambdify(args, forces, "numpy", cse=True), sp.lambdify(args, feet, "numpy"),
            sp.lambdify(args, feet.jacobian(qm), "numpy"),
            sp.lambdify(args, energy, "numpy", cse=True))


class Chain:
    """The chain with ``segments`` links per leg at given parameters: its vector field, guards,
    impact map and energy."""

    def __init__(self, segments: int = 1, **overrides):
        if segments not in (1, *LINKS):
            raise ValueError(f"segments must be 1..{max(LINKS)}, got {segments!r}")
        self.segments = segments
        self.d = 3 + 2 * segments
        values = {**parameters(segments), **overrides}
        self.gamma = values.pop("e")
        pnames, self._M, self._f, self._feet, self._da, self._energy = _functions(segments)
        self.p = tuple(values[name] for name in pnames)
        self.values = values

    def initial(self, tilt):
        """At rest at height HEIGHT and pitch ``tilt``, the hips spread SPREAD beyond rest."""
        y = np.zeros(2 * self.d)
        y[1], y[2] = HEIGHT, tilt
        for j in range(self.segments):
            rest = self.values["rest" if j == 0 else f"rest{j + 1}"]
            extra = SPREAD if j == 0 else 0.0
            y[3 + 2 * j], y[4 + 2 * j] = rest + extra, -rest - extra
        return y

    def _args(self, y):
        return y[:self.d], y[self.d:], self.p

    def mass(self, y):
        return np.array(self._M(*self._args(y)), dtype=float)

    def field(self, _t, y):
        acc = np.linalg.solve(self.mass(y),
                              np.array(self._f(*self._args(y)), dtype=float).ravel())
        return np.concatenate([y[self.d:], acc])

    def feet(self, y):
        return np.array(self._feet(*self._args(y)), dtype=float).ravel()

    def feet_rates(self, y):
        return np.array(self._da(*self._args(y)), dtype=float) @ y[self.d:]

    def energy(self, y):
        return float(self._energy(*self._args(y)))

    def impact(self, y, active):
        d = self.d
        Da = np.array(self._da(*self._args(y)), dtype=float)[sorted(active)]
        Minv_DaT = np.linalg.solve(self.mass(y), Da.T)
        mult = np.linalg.solve(Da @ Minv_DaT, Da @ y[d:])
        return np.concatenate([y[:d], y[d:] - (1 + self.gamma) * Minv_DaT @ mult])


def simulate(chain: Chain, tilt: float, *, band=BAND, max_events=MAX_EVENTS,
             t_end=T_END) -> Outcome:
    """The ``drop`` maneuver: to the middle link's first apex after the first impact; the
    outcome is the middle link's pitch rate there."""
    d = chain.d
    dz, dth = d + 1, d + 2  # z' and th' in the state
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
        return yy[dz]

    apex.terminal, apex.direction = True, -1
    while t < t_end:
        events = [foot(0), foot(1)] + ([apex] if touched else [])
        sol = solve_ivp(chain.field, (t, t_end), y, method="DOP853", rtol=RTOL, atol=ATOL,
                        max_step=MAX_STEP, events=events, dense_output=True)
        hits = [(te[0], j) for j, te in enumerate(sol.t_events) if len(te)]
        if not hits:
            out.y_final = sol.y[:, -1]
            out.outcome = out.y_final[dth]
            return out
        t_hit, first = min(hits)
        y_hit = sol.sol(t_hit)
        if first == 2:
            out.status, out.t_final, out.y_final, out.outcome = "OK", t_hit, y_hit, y_hit[dth]
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
            out.status, out.t_final, out.y_final, out.outcome = "MAX_EVENTS", t, y, y[dth]
            return out
    return out
