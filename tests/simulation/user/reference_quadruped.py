"""Independent reference for the library's quadruped: SciPy's solve_ivp (DOP853) on equations of
motion computed numerically, by a recursive pass over the kinematic tree, instead of the
library's symbolic derivation and generated code. Imports nothing from biped_opt.

The tree: three slides (x, y, z) and three hinges (yaw about the world's z, pitch about the new
y, roll about the new x) carry the front trunk half from the spine joint; two hinges (spine
pitch about the front half's y, spine yaw about the new z) carry the rear half; each half
carries two legs at its outer end (abduction about the half's x, hip flexion about the new y,
knee about the thigh's y). For every frame the pass keeps, in world components, its rotation,
origin, angular velocity, the Jacobians Jw, Jv (so omega = Jw q', v = Jv q') and the parts of
the accelerations that do not depend on q'' (a hinge about the world axis u turning at q'_k adds
u q'_k to omega and omega_parent x u q'_k to the angular acceleration; a point at r from an
origin adds omega x (omega x r) and alpha x r). The Newton-Euler inertia forces of the bodies
projected on the Jacobians then give

    M(q) = sum m Jv^T Jv + Jw^T I Jw,
    h(q, q') = sum m Jv^T a_bias + Jw^T (I alpha_bias + omega x I omega),

and M q'' = Q - h + Da_J^T lambda, Q being gravity and the hinges' springs and dampers. A
foot's height, its Jacobian row and its (d/dt Da) q' term come from the same pass.

The event rules are the model's (SYSTEMS.md Sec. 5) for what the drop meets: feet land
plastically (feet within BAND of the ground and approaching land with the first, one impact
for all of them), a foot in contact lifts off when its reaction falls through 0, the mode after
an event is the one the complementarity conditions allow, and the terminal guard (the spine's
nadir: z' rises through 0) counts after the first touchdown, ordered by time against the
contact events.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp

BAND = 1e-9  # contact guards this close to zero and closing flip together
REARM = 1e-10  # a flipped guard counts again once farther than this from zero
RTOL, ATOL = 1e-12, 1e-13
HOP_STEP = 1e-5  # the longest step while a foot or a reaction sits at zero after an event

PARAMETERS = {"m_trunk": 3.0, "L": 0.15, "w": 0.1, "h_trunk": 0.08, "m_thigh": 0.6,
              "m_shank": 0.3, "l1": 0.2, "l2": 0.2, "r_leg": 0.02, "k_spine": 60.0,
              "k_abd": 30.0, "k_hip": 30.0, "k_knee": 30.0, "c": 0.0, "phi": 0.6, "g": 9.81,
              "drop": 0.05}
LEGS = ("fl", "fr", "rl", "rr")
D = 20
X, Y, Z = np.eye(3)


class ReferenceError(RuntimeError):
    """The reference cannot decide a case."""


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` about the unit ``axis`` (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b (NumPy's cross is slow for single 3-vectors)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def _skew(r: np.ndarray) -> np.ndarray:
    return np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])


@dataclass
class Node:
    """A frame (or a point, with the frame's rotation) along the tree, in world components."""

    R: np.ndarray
    o: np.ndarray
    w: np.ndarray  # angular velocity
    alpha: np.ndarray  # angular acceleration at q'' = 0
    v: np.ndarray
    a: np.ndarray  # origin's acceleration at q'' = 0
    Jw: np.ndarray
    Jv: np.ndarray

    def hinge(self, axis: np.ndarray, q: np.ndarray, dq: np.ndarray, k: int) -> Node:
        u = self.R @ axis
        Jw = self.Jw.copy()
        Jw[:, k] += u
        return Node(self.R @ _rotation(axis, q[k]), self.o, self.w + u * dq[k],
                    self.alpha + _cross(self.w, u) * dq[k], self.v, self.a, Jw, self.Jv)

    def at(self, local: np.ndarray) -> Node:
        r = self.R @ local
        return Node(self.R, self.o + r, self.w, self.alpha, self.v + _cross(self.w, r),
                    self.a + _cross(self.alpha, r) + _cross(self.w, _cross(self.w, r)),
                    self.Jw, self.Jv - _skew(r) @ self.Jw)


@dataclass
class Body:
    mass: float
    inertia: np.ndarray  # in its own frame, about its centre
    centre: Node


class Quadruped:
    """The quadruped at given parameters: dynamics, feet, impacts, energy."""

    def __init__(self, **overrides: float) -> None:
        self.p = {**PARAMETERS, **overrides}
        p = self.p
        self.rest = np.zeros(D)
        self.stiffness = np.zeros(D)
        self.stiffness[6:8] = p["k_spine"]
        for i in range(4):
            self.rest[8 + 3 * i: 11 + 3 * i] = (0.0, p["phi"], -2 * p["phi"])
            self.stiffness[8 + 3 * i: 11 + 3 * i] = (p["k_abd"], p["k_hip"], p["k_knee"])

    def tree(self, q: np.ndarray, dq: np.ndarray) -> tuple[list[Body], list[Node]]:
        """The bodies and the feet at (q, q')."""
        p = self.p
        zero = np.zeros(3)
        Jv = np.zeros((3, D))
        Jv[:, :3] = np.eye(3)
        base = Node(np.eye(3), q[:3].copy(), zero, zero, dq[:3].copy(), zero,
                    np.zeros((3, D)), Jv)
        front = base.hinge(Z, q, dq, 3).hinge(Y, q, dq, 4).hinge(X, q, dq, 5)
        rear = front.hinge(Y, q, dq, 6).hinge(Z, q, dq, 7)
        L, w, h, m = p["L"], p["w"], p["h_trunk"], p["m_trunk"]
        box = np.diag([m * (4 * w**2 + h**2), m * (L**2 + h**2), m * (L**2 + 4 * w**2)]) / 12
        bodies = [Body(m, box, front.at(np.array([L / 2, 0, 0]))),
                  Body(m, box, rear.at(np.array([-L / 2, 0, 0])))]
        feet = []
        for i, leg in enumerate(LEGS):
            half, along = (front, 1) if leg[0] == "f" else (rear, -1)
            side = 1 if leg[1] == "l" else -1
            k = 8 + 3 * i
            hip = half.at(np.array([along * L, side * w, 0.0]))
            thigh = hip.hinge(X, q, dq, k).hinge(Y, q, dq, k + 1)
            knee = thigh.at(np.array([0, 0, -p["l1"]]))
            shank = knee.hinge(Y, q, dq, k + 2)
            for mass, length, frame in ((p["m_thigh"], p["l1"], thigh),
                                        (p["m_shank"], p["l2"], shank)):
                across = mass * length**2 / 12
                rod = np.diag([across, across, mass * p["r_leg"] ** 2 / 2])
                bodies.append(Body(mass, rod, frame.at(np.array([0, 0, -length / 2]))))
            feet.append(shank.at(np.array([0, 0, -p["l2"]])))
        return bodies, feet

    def dynamics(self, y: np.ndarray):
        """M, the forces Q - h (everything but the reactions), the feet's heights, their
        Jacobian Da and the term (d/dt Da) q'."""
        q, dq = y[:D], y[D:]
        bodies, feet = self.tree(q, dq)
        M = np.zeros((D, D))
        f = -self.stiffness * (q - self.rest)
        f[6:] -= self.p["c"] * dq[6:]
        for b in bodies:
            c = b.centre
            inertia = c.R @ b.inertia @ c.R.T
            M += b.mass * c.Jv.T @ c.Jv + c.Jw.T @ inertia @ c.Jw
            f -= b.mass * c.Jv.T @ (c.a + np.array([0, 0, self.p["g"]]))
            f -= c.Jw.T @ (inertia @ c.alpha + _cross(c.w, inertia @ c.w))
        heights = np.array([foot.o[2] for foot in feet])
        Da = np.array([foot.Jv[2] for foot in feet])
        rate = np.array([foot.a[2] for foot in feet])
        return M, f, heights, Da, rate

    def mass(self, q: np.ndarray) -> np.ndarray:
        return self.dynamics(np.concatenate([q, np.zeros(D)]))[0]

    def accelerations(self, y: np.ndarray, mode: frozenset[int]):
        """(q'', lambda over all four feet) in ``mode``."""
        M, f, _h, Da, rate = self.dynamics(y)
        lam = np.zeros(4)
        active = sorted(mode)
        if active:
            A = Da[active]
            MinvAT = np.linalg.solve(M, A.T)
            lam[active] = -np.linalg.solve(A @ MinvAT, A @ np.linalg.solve(M, f) + rate[active])
        return np.linalg.solve(M, f + Da.T @ lam), lam

    def energy(self, y: np.ndarray) -> float:
        q, dq = y[:D], y[D:]
        bodies, _feet = self.tree(q, dq)
        M = self.dynamics(y)[0]
        potential = sum(b.mass * self.p["g"] * b.centre.o[2] for b in bodies)
        springs = float(self.stiffness @ (q - self.rest) ** 2) / 2
        return float(dq @ M @ dq) / 2 + potential + springs

    def feet(self, y: np.ndarray) -> np.ndarray:
        return np.array([f.o[2] for f in self.tree(y[:D], y[D:])[1]])

    def impact(self, y: np.ndarray, active: frozenset[int]) -> np.ndarray:
        """The plastic impact of Eq. (1b) into ``active``."""
        M, _f, _h, Da, _r = self.dynamics(y)
        A = Da[sorted(active)]
        MinvAT = np.linalg.solve(M, A.T)
        dq = y[D:] - MinvAT @ np.linalg.solve(A @ MinvAT, A @ y[D:])
        return np.concatenate([y[:D], dq])

    def initial(self, th0: float) -> np.ndarray:
        p = self.p
        y = np.zeros(2 * D)
        y[2] = (p["l1"] + p["l2"]) * math.cos(p["phi"]) + p["drop"]
        y[4], y[5] = th0 / 2, th0
        y[8:20] = self.rest[8:20]
        return y

    def field(self, mode: frozenset[int]):
        def rhs(_t, y):
            return np.concatenate([y[D:], self.accelerations(y, mode)[0]])
        return rhs

    def settle(self, y: np.ndarray, mode: frozenset[int]) -> frozenset[int]:
        """The mode complementarity allows (SYSTEMS.md Sec. 5): the largest subset of ``mode``
        whose feet all press and whose released feet do not accelerate into the ground."""
        if min(self.accelerations(y, mode)[1][sorted(mode)], default=0.0) >= -1e-10:
            return mode
        for size in range(len(mode), -1, -1):
            for kept in itertools.combinations(sorted(mode), size):
                sub = frozenset(kept)
                acc, lam = self.accelerations(y, sub)
                rate = self.dynamics(y)[4]
                Da = self.dynamics(y)[3]
                free = [j for j in mode if j not in sub]
                if all(lam[j] >= -1e-10 for j in sub) and \
                        all(Da[j] @ acc + rate[j] >= -1e-10 for j in free):
                    return sub
        raise ReferenceError("no contact mode fits")


@dataclass
class Outcome:
    status: str
    t_final: float
    y_final: np.ndarray
    outcome: float
    #: (time, feet that touched down, feet that lifted off, the mode after the event: a foot
    #: that lands while complementarity lets it leave at once is among the first, not in the
    #: last)
    events: list[tuple[float, frozenset[int], frozenset[int], frozenset[int]]] = \
        field(default_factory=list)
    #: min | |g| / BAND - 1 | over the closing guards near zero at the contact events
    band_margin: float = math.inf
    #: the state just before and just after the first impact
    first_impact: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def times(self) -> list[float]:
        return [t for t, *_rest in self.events]


def simulate(robot: Quadruped, th0: float, *, band: float = BAND, max_events: int = 16,
             t_end: float = 10.0) -> Outcome:
    """The ``drop`` maneuver: from rest in the air to the spine's nadir after the first
    touchdown; outcome: the roll rate there."""
    y = robot.initial(th0)
    mode: frozenset[int] = frozenset()
    armed = [True] * 4  # contact guards (heights in the air, reactions in contact)
    touched = False
    t = 0.0
    out = Outcome("HORIZON", t_end, y, math.nan)

    def guard_value(j, yy):
        if j in mode:
            return robot.accelerations(yy, mode)[1][j]
        return robot.feet(yy)[j]

    def guard(j):
        """An armed guard's event: it falls through 0. A disarmed one's (it sits at zero after
        an event): it rises through 2 REARM, where it is armed again, so that a foot released
        at rest is followed however short its hop (it starts at zero to rounding, a sign change
        that solve_ivp would not see)."""
        if armed[j]:
            def g(_t, yy):
                return guard_value(j, yy)
            g.terminal, g.direction = True, -1
        else:
            def g(_t, yy):
                return guard_value(j, yy) - 2 * REARM
            g.terminal, g.direction = True, 1
        return g

    def nadir(_t, yy):
        return -yy[D + 2]

    nadir.terminal, nadir.direction = True, -1
    while t < t_end:
        events = [guard(j) for j in range(4)] + ([nadir] if touched else [])
        # short steps while a guard is disarmed: a hop of a released foot can be a fraction of
        # a millisecond, and solve_ivp sees a root only as a sign change between step ends
        sol = solve_ivp(robot.field(mode), (t, t_end), y, method="DOP853", rtol=RTOL,
                        atol=ATOL, events=events, dense_output=True,
                        max_step=np.inf if all(armed) else HOP_STEP)
        hits = [(te[0], j) for j, te in enumerate(sol.t_events) if len(te)]
        if not hits:
            out.y_final = sol.y[:, -1]
            return out
        t_hit, first = min(hits)
        # a disarmed guard must not sink below its surface without rising first
        probe = sol.sol(np.linspace(t, t_hit, 401))
        for j in range(4):
            if not armed[j] and min(guard_value(j, probe[:, i])
                                    for i in range(probe.shape[1])) < -BAND:
                raise ReferenceError("a released foot sinks without rising first")
        if first < 4 and not armed[first]:
            armed[first] = True  # (risen clear of zero: watched from here)
            y, t = sol.sol(t_hit), t_hit
            continue
        y_hit = sol.sol(t_hit)
        if first == 4:
            out.status, out.t_final, out.y_final = "OK", t_hit, y_hit
            out.outcome = y_hit[D + 5]
            return out
        M, f, heights, Da, rate = robot.dynamics(y_hit)
        lam = robot.accelerations(y_hit, mode)[1]
        rates = Da @ y_hit[D:]
        down, up = set(), set()
        for j in range(4):
            value, closing = (lam[j], None) if j in mode else (heights[j], rates[j] < 0)
            if j == first or (armed[j] and abs(value) <= band and closing is not False):
                (up if j in mode else down).add(j)
            if j != first and armed[j] and band > 0 and abs(value) < 10 * band:
                out.band_margin = min(out.band_margin, abs(abs(value) / band - 1))
        new = (mode | down) - up
        if down:
            before = y_hit
            y_hit = robot.impact(y_hit, mode | down)
            if out.first_impact is None:
                out.first_impact = (before, y_hit)
            touched = True
        mode = robot.settle(y_hit, frozenset(new))
        for j in range(4):
            after = robot.accelerations(y_hit, mode)[1][j] if j in mode else robot.feet(y_hit)[j]
            if j in down | up and abs(after) <= REARM:
                armed[j] = False
        y, t = y_hit, t_hit
        out.events.append((t, frozenset(down), frozenset(up), mode))
        if len(out.events) >= max_events:
            out.status, out.t_final, out.y_final, out.outcome = "MAX_EVENTS", t, y, y[D + 5]
            return out
    return out
