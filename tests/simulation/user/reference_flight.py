"""Independent reference for systems whose flights have closed forms: point masses against
straight walls (corner.py, stack.py) and a rigid bar on its ends (plank.py, the library's
rocking_bar). Imports nothing from biped_opt: the mass matrices, constraints and impact maps
below are written again from the physics, in plain NumPy.

Every flight is closed form (parabolas; a bar also spins at a constant rate), so a guard's value,
rate and a bound G on its second derivative are exact along it. Event isolation is certified:
from a point where the guard is g > 0 with rate g', it has no root before
(g' + sqrt(g'^2 + 2 G g)) / G, and once g' < 0 with G g / g'^2 < 1/4 it is decreasing and has
exactly one root within 2 g / |g'|, found by Brent's method. No root is skipped however close two
impacts are (a bar end's re-impacts 1e-7 apart included).

The event rules are the model's (MODEL.md Sec. 3): the earliest root among the armed guards;
every other armed contact guard within BAND of zero and moving toward it flips in the same
instant (one impact map for all of them); a flipped guard is disarmed until it is farther than
1e-10 from zero; the terminal guard is ordered by time against the contact events, never merged
with them, and counts only after the first touchdown. ``band=0`` turns the merging off (events
ordered by time alone), which is how coincidences are located: there the order of two events
swaps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

BAND = 1e-9  # contact guards this close to zero and closing flip together
REARM = 1e-10  # a flipped guard counts again once farther than this from zero
MAX_EVENTS = 16  # the simulator's default budget of contact events
T_END = 10.0  # and its default horizon


class ReferenceError(RuntimeError):
    """The reference cannot decide a case (a guard grazing zero, a hop too small to tell)."""


@dataclass
class Outcome:
    status: str  # the simulator's names: "OK", "MAX_EVENTS", "HORIZON", "INCONSISTENT"
    t_final: float
    y_final: np.ndarray
    outcome: float
    events: list[tuple[float, frozenset[int]]] = field(default_factory=list)
    #: how far, relative to BAND, the closing guards near zero at the contact events were from
    #: the band's edge: min | |g| / BAND - 1 | (near 0: the case sits on the edge, where a
    #: rounding error decides whether two impacts merge)
    band_margin: float = math.inf

    @property
    def times(self) -> list[float]:
        return [t for t, _ in self.events]

    @property
    def signature(self) -> tuple:
        return (self.status, tuple(tuple(sorted(j)) for _, j in self.events))


class AffineSystem:
    """Point masses in uniform gravity against flat walls: M constant, forces constant, the
    constraints a(q) = A q + c. A flight is q0 + v0 t + acc t^2 / 2, each guard a quadratic."""

    def __init__(self, mass, force, A, c, restitution, y0, terminal, outcome):
        self.M = np.asarray(mass, dtype=float)
        self.A = np.atleast_2d(np.asarray(A, dtype=float))
        self.c = np.asarray(c, dtype=float)
        self.gamma = float(restitution)
        self.acc = np.linalg.solve(self.M, np.asarray(force, dtype=float))
        self.y0 = np.asarray(y0, dtype=float)
        self.terminal = np.asarray(terminal, dtype=float)  # T(y) = terminal . y
        self.outcome = outcome
        self.d = self.M.shape[0]
        self.n = self.A.shape[0]

    def state(self, y, t):
        d = self.d
        q, v = y[:d], y[d:]
        return np.concatenate([q + v * t + self.acc * t * t / 2, v + self.acc * t])

    def guards(self, y):
        """The contact guards and the terminal guard, and their rates."""
        d = self.d
        q, v = y[:d], y[d:]
        g = np.append(self.A @ q + self.c, self.terminal @ y)
        rate = np.append(self.A @ v, self.terminal[:d] @ v + self.terminal[d:] @ self.acc)
        return g, rate

    def curvature(self, y):
        """|g''| of every guard along a flight (constant: the guards are quadratics)."""
        return np.append(np.abs(self.A @ self.acc), abs(self.terminal[: self.d] @ self.acc))

    def jacobian(self, q):
        return self.A

    def impact(self, y, active):
        return _impact(self.M, self.jacobian(y[: self.d])[sorted(active)], self.gamma, y,
                       self.d)


class Bar:
    """A rigid bar (x, z, pitch th) of mass m, half-length w, moment of inertia I about its
    centre, on the ground at its ends: a_j = z + s_j w sin th, s = (-1, +1). In flight the centre
    falls on a parabola and the bar spins at a constant rate. Terminal guard: z' (the apex)."""

    def __init__(self, m, w, inertia, g, restitution, tilt, z0=1.0):
        self.M = np.diag([m, m, inertia])
        self.w, self.g, self.gamma = w, g, float(restitution)
        self.y0 = np.array([0.0, z0, tilt, 0.0, 0.0, 0.0])
        self.sides = np.array([-1.0, 1.0])
        self.d, self.n = 3, 2

    def state(self, y, t):
        x, z, th, vx, vz, om = y
        return np.array([x + vx * t, z + vz * t - self.g * t * t / 2, th + om * t,
                         vx, vz - self.g * t, om])

    def guards(self, y):
        _x, z, th, _vx, vz, om = y
        g = np.append(z + self.sides * self.w * math.sin(th), vz)
        rate = np.append(vz + self.sides * self.w * om * math.cos(th), -self.g)
        return g, rate

    def curvature(self, y):
        """Bounds on |g''| along a flight: z'' = -g, (w sin th)'' = -w om^2 sin th."""
        om = y[5]
        return np.append(np.full(2, self.g + self.w * om * om), 0.0)

    def jacobian(self, q):
        c = self.w * math.cos(q[2])
        return np.array([[0.0, 1.0, -c], [0.0, 1.0, c]])

    def impact(self, y, active):
        return _impact(self.M, self.jacobian(y[:3])[sorted(active)], self.gamma, y, 3)

    @staticmethod
    def outcome(y):
        return y[5]


def _impact(M, Da, gamma, y, d):
    """q'+ = (I - (1 + gamma) M^-1 Da^T (Da M^-1 Da^T)^-1 Da) q'- (Newton's law on the rows
    of Da): the constraint velocities Da q' are reversed and scaled by gamma."""
    v = y[d:]
    Minv_DaT = np.linalg.solve(M, Da.T)
    mult = np.linalg.solve(Da @ Minv_DaT, Da @ v)
    return np.concatenate([y[:d], v - (1 + gamma) * Minv_DaT @ mult])


def _guard_along(system, y, j, t):
    g, rate = system.guards(system.state(y, t))
    return g[j], rate[j]


def _first_fall(system, y, j, start, stop, G):
    """The first root after ``start`` (where guard j is > 0) and before ``stop`` at which
    guard j falls through zero on the flight from y, or None (certified, see the module)."""
    a = start
    for _ in range(200_000):
        if a >= stop:
            return None
        ga, ra = _guard_along(system, y, j, a)
        if ga <= 0.0:
            raise ReferenceError(f"guard {j} is not positive at t = {a} ({ga})")
        if G == 0.0:
            if ra >= 0.0:
                return None  # a straight line going up
            root = a + ga / -ra
            return root if root <= stop else None
        if ra < 0.0 and G * ga < 0.25 * ra * ra:
            b = a + 2.0 * ga / -ra
            if b > stop and _guard_along(system, y, j, stop)[0] > 0.0:
                return None
            b = min(b, stop)
            return brentq(lambda t: _guard_along(system, y, j, t)[0], a, b,
                          xtol=1e-16, rtol=4 * np.finfo(float).eps, maxiter=500)
        a += 0.9 * (ra + math.sqrt(ra * ra + 2.0 * G * ga)) / G
    raise ReferenceError(f"guard {j} grazes zero near t = {a}")


def _armed_from(system, y, j, G):
    """When a disarmed guard j (near zero after its impact, moving away at rate g' > 0) is
    armed again on the flight from y: the first time it exceeds REARM. Where the certified bound
    does not settle it (g'^2 / (2G) too small) the hop's top is found as the root of g' and the
    guard is armed where it passes REARM on the way up. None when it never leaves zero by REARM
    (then the constraint is violated: ``_sinks`` tells); ReferenceError when its top is too
    close to REARM to decide."""
    g, rate = _guard_along(system, y, j, 0.0)
    if g > REARM:
        return 0.0
    if rate <= 0.0:
        return None  # (a terminal z' left at or below 1e-10: it only decreases in flight)
    if G == 0.0:
        return (REARM - g) / rate * 1.5
    t = rate / G
    if g + rate * t - G * t * t / 2 > 2 * REARM:
        return t  # certainly beyond REARM there, and no root before
    hi = t
    while _guard_along(system, y, j, hi)[1] > 0.0:
        hi *= 2.0
        if hi > 1e3:
            return None
    top = brentq(lambda s: _guard_along(system, y, j, s)[1], t, hi, xtol=1e-18)
    g_top = _guard_along(system, y, j, top)[0]
    if abs(g_top / REARM - 1.0) < 0.05:
        raise ReferenceError(f"guard {j} hops within 5% of the re-arming distance")
    return top if g_top > REARM else None


def _sinks(system, y, j, stop):
    """When a guard that never re-armed falls below -REARM on the flight from y (None: not
    before ``stop``); the simulator reports that as an inconsistency."""
    _g, rate = _guard_along(system, y, j, 0.0)
    hi = max(rate, 0.0) / max(system.curvature(y)[j], 1e-300) + 1e-12
    while _guard_along(system, y, j, hi)[0] > -REARM:
        hi *= 2.0
        if hi > stop:
            return None
    return brentq(lambda s: _guard_along(system, y, j, s)[0] + REARM, 0.0, hi, xtol=1e-18)


def simulate(system, *, band=BAND, max_events=MAX_EVENTS, t_end=T_END) -> Outcome:
    """The maneuver from system.y0 to its terminal event (armed after the first touchdown)."""
    n = system.n
    y = system.y0.copy()
    g, _ = system.guards(y)
    armed = [gj > REARM for gj in g[:n]] + [False]
    term_enabled = False
    t = 0.0
    out = Outcome("HORIZON", t_end, y, math.nan)
    while True:
        G = system.curvature(y)
        firsts = []
        starts: list[float | None] = [None] * (n + 1)
        for j in range(n + 1):
            if j == n and not term_enabled:
                continue
            starts[j] = 0.0 if armed[j] else _armed_from(system, y, j, G[j])
            if starts[j] is None and j < n:
                sink = _sinks(system, y, j, t_end - t)
                if sink is not None:
                    firsts.append((sink, -1))
            if starts[j] is None or (armed[j] and system.guards(y)[0][j] <= 0.0):
                continue  # (an armed terminal guard left at or below 0 never rises again)
            root = _first_fall(system, y, j, starts[j], t_end - t, G[j])
            if root is not None:
                firsts.append((root, j))
        if not firsts:
            out.y_final = system.state(y, t_end - t)
            out.outcome = system.outcome(out.y_final)
            return out
        tau, first = min(firsts)
        y_event = system.state(y, tau)
        t += tau
        if first == -1:  # a hop too small to re-arm its guard: the end sinks into the ground
            out.status, out.t_final, out.y_final = "INCONSISTENT", t, y_event
            out.outcome = system.outcome(y_event)
            return out
        if first == n:  # the terminal event, by time before every contact event
            out.status, out.t_final, out.y_final = "OK", t, y_event
            out.outcome = system.outcome(y_event)
            return out
        g, rate = system.guards(y_event)
        # a guard disarmed when this flight began counts once it was re-armed before the event
        armed = [starts[j] is not None and starts[j] <= tau for j in range(n)] + [armed[n]]
        flips = {first}
        for j in range(n):
            if j == first or not armed[j] or rate[j] >= 0.0:
                continue
            if abs(g[j]) <= band:
                flips.add(j)
            if band > 0 and abs(g[j]) < 10 * band:
                out.band_margin = min(out.band_margin, abs(abs(g[j]) / band - 1.0))
        y = system.impact(y_event, flips)
        out.events.append((t, frozenset(flips)))
        g_after, rate_after = system.guards(y)
        for j in flips:
            if rate_after[j] <= 0.0:
                raise ReferenceError("an impacted constraint does not separate (gamma = 0?)")
            armed[j] = False
        term_enabled = True
        armed[n] = armed[n] or g_after[n] > REARM
        if len(out.events) >= max_events:
            out.status, out.t_final, out.y_final = "MAX_EVENTS", t, y
            out.outcome = system.outcome(y)
            return out


# -- the systems of this suite, written again from their physics -------------------------------

def corner(h0, *, m=1.0, g=1.0, psi=0.3, e=0.6, vx=1.2):
    """corner.py: floor z >= 0, wall x cos psi + z sin psi >= 0."""
    A = [[0.0, 1.0], [math.cos(psi), math.sin(psi)]]
    return AffineSystem(np.diag([m, m]), [0.0, -m * g], A, [0.0, 0.0], e,
                        [1.0, h0, -vx, 0.0], [0, 0, 0, 1.0], lambda y: y[2])


def stack(v0, *, m_low=1.0, m_top=0.25, r=0.1, g=1.0, e=0.8):
    """stack.py: ground low >= 0, gap top - low - r >= 0."""
    A = [[1.0, 0.0], [-1.0, 1.0]]
    return AffineSystem(np.diag([m_low, m_top]), [-m_low * g, -m_top * g], A, [0.0, -r], e,
                        [1.0, 1.0 + r + 0.2, 0.0, -v0], [0, 0, 1.0, 0], lambda y: y[3])


def plank(tilt, *, mp=2.0, half=0.7, kg=0.4, grav=1.0, e=0.35):
    """plank.py: a bar of radius of gyration kg (I = mp kg^2)."""
    return Bar(mp, half, mp * kg * kg, grav, e, tilt)


def rocking_bar(th0, *, m=1.0, w=0.5, g=1.0, gamma=0.5):
    """The library's rocking bar (a uniform bar: I = m (2 w)^2 / 12)."""
    return Bar(m, w, m * (2 * w) ** 2 / 12, g, gamma, th0)


def changes(signature, lo, hi, num, *, xtol=1e-15):
    """Where ``signature(s)`` changes on [lo, hi]: a grid of ``num`` points, then bisection of
    every change to ``xtol`` (relative)."""
    grid = np.linspace(lo, hi, num)
    sigs = [signature(s) for s in grid]
    found = []
    for a, b, sa, sb in zip(grid[:-1], grid[1:], sigs[:-1], sigs[1:]):
        if sa == sb:
            continue
        while b - a > xtol * max(1.0, abs(a)):
            mid = 0.5 * (a + b)
            if mid in (a, b):
                break
            if signature(mid) == sa:
                a = mid
            else:
                b = mid
        found.append(0.5 * (a + b))
    return found


def coincidences(make, lo, hi, num, *, xtol=1e-15):
    """Where the event sequence of ``make(s)`` changes on [lo, hi] with events ordered by
    time alone (band 0): :func:`changes` of its signature."""
    return changes(lambda s: simulate(make(s), band=0.0).signature, lo, hi, num, xtol=xtol)
