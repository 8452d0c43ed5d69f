"""Independent reference for rigid contacts: rigid bodies on a flat frictionless floor and a
planar point-foot biped, with simultaneous and dependent contacts. Imports nothing from
biped_opt (only the grid-and-bisection search for coincidences is shared, with
``reference_flight``): the physics and the event rules are written again here from SYSTEMS.md
Secs. 1 and 5 and MODEL.md Secs. 1-4, in plain NumPy and SciPy, in another formulation than
the simulator's.

**Rigid bodies** (:class:`RigidBody`) are Newton-Euler bodies: the state is the centre of mass
p, the rotation matrix R (its columns the body's axes in the world), the centre's velocity v
(world) and the angular velocity w in the body's axes; there are no generalised coordinates and
no Euler angles. The equations are p' = v, R' = R [w]x, m v' = m g + sum lambda_k e_z, I w' =
-w x I w + sum lambda_k (r_k x R^T e_z), contact k at the body point r_k (from the centre, body
axes) with height a_k = p_z + e_z . R r_k. A contact's row of Da in the velocities (v, w) is
(e_z, r_k x R^T e_z), its acceleration a_k'' = Da_k (v', w') + e_z . R (w x (w x r_k)). A
flight whose angular velocity is a principal axis of inertia (the body not spinning, or
spinning about a principal axis) is closed form: p on a parabola, R(t) = R(0) exp(t [w]x)
(Rodrigues), w constant; so is a body resting on a face (contacts of rank 3) that spins about
the vertical, a principal axis (it turns uniformly and slides at constant velocity). Their
guards' roots are isolated with certified bounds, as in ``reference_flight``. Every other flow
(a tumbling flight, motion on one, two or four corners) is integrated by SciPy's DOP853 at rtol
1e-12 (atol 1e-14), at most H_MAX per step, each step's guards sampled at SAMPLES points of its
dense output (and, for heights, the lowest point between two samples where the rate changes
sign), roots bracketed and solved by Brent's method to ~1e-15.

**Contacts.** With M = L L^T (Cholesky) and G = Da_S L^-T, the constrained acceleration and the
impact are M-orthogonal projections, computed by minimum-norm least squares on G (so that
dependent rows, a flat face's four corners, need no choice of a subset): an impact changes the
velocity by L^-T x with x the least-norm solution of G x = -(1 + gamma) Da_S v- (Newton's law
on every row of S); a contact mode S accelerates by L^-T x with G x = -(Da_S v'_free + h_S);
its reactions are the least-squares lambda with G^T lambda = x (unique for independent rows).
Which constraints at rest on their surface stay in contact after an event is the solution of
the acceleration-level complementarity problem, solved as a least-distance program by Lawson
and Hanson's NNLS construction (min |x| subject to G x >= -b; a_S'' = G x + b is unique even
when the rows are dependent): the constraints whose a'' is 0 stay in contact, the others leave
with the velocity the impact gave them. (With force coupling, forces that depend on the contact
mode as the biped's inputs do, no single complementarity problem describes the choice; there
the reference applies SYSTEMS.md's rule as written: the subsets of the constraints at rest,
largest first, the first with every reaction >= 0 and every released a'' >= 0.)

**Event rules** (the model's, SYSTEMS.md Sec. 5 and the kernel's rules under test): the
earliest root of a guard (a height in the air, falling through 0 after having been above 0; a
reaction in contact, falling through 0; the terminal guard, ordered by time and never merged);
at a contact event every other constraint in the air within BAND of its surface and approaching
it joins the impact (whatever happened at earlier events), and every other reaction within BAND
of 0 and falling joins the liftoff; the impact is Newton's law on the constraints at their
surface after the event; with restitution an impacted constraint moving apart at more than
1e-12 leaves at once (a bounce); a constraint left at ~0 by an event is watched from the moment
it is above its surface (certified in a closed-form flight; in a numeric flow from the first
sample where it is more than LIVE = 1e-13 above it, 1e3 times a height's rounding). The
reported contact mode is every constraint that stays in contact plus every other constraint
within BAND of its surface whose row depends on theirs (held). ``band`` smaller than BAND
switches the merging of events that are apart by more than rounding off: that is how
coincidences are located (there the order of two events swaps).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import DOP853
from scipy.optimize import brentq, nnls

from tests.simulation.user.reference_flight import changes

BAND = 1e-9  # contact guards this close to zero and closing flip together
#: the band used to locate coincidences: only events apart by rounding (a symmetric pair of
#: corners, whose heights differ by ~1e-17) still merge
BAND_OFF = 1e-13
SEPARATION = 1e-12  # an impacted constraint moving apart faster than this bounces
REARM = 1e-10  # a guard nearer 0 than this at the start of a flow was reset by the event
LIVE = 1e-13  # (see _Sim._numeric)
RTOL, ATOL = 1e-12, 1e-14  # DOP853 of the numeric flows
H_MAX = 0.02  # largest step of the numeric flows
SAMPLES = 16  # guard samples per step of a numeric flow
#: a''_j of a constraint at rest on its surface: below this (relative to the problem's scale)
#: it stays in contact, above AMBIGUOUS it leaves; in between the reference cannot decide
CONTACT_TOL, AMBIGUOUS = 1e-11, 1e-7
#: rows of Da farther than this (relative) from the span of others are independent
RANK_TOL = 1e-9
EPS = np.finfo(float).eps


class ReferenceError(RuntimeError):
    """The reference cannot decide a case (a guard grazing zero, a tie it cannot order)."""


@dataclass
class Event:
    t: float
    entered: frozenset[int]
    left: frozenset[int]
    before: frozenset[int]
    after: frozenset[int]
    y_before: np.ndarray = field(repr=False)
    y_after: np.ndarray = field(repr=False)


@dataclass
class Run:
    status: str  # the simulator's names: "OK", "APEX_IN_CONTACT", "MAX_EVENTS", "HORIZON"
    t_final: float
    y_final: np.ndarray
    mode_final: frozenset[int]
    events: list[Event] = field(default_factory=list)
    #: how far, relative to BAND, the closing guards near zero at the contact events were from
    #: the band's edge: min | |g| / BAND - 1 | (near 0: a rounding error decides a merge)
    band_margin: float = math.inf

    @property
    def times(self) -> list[float]:
        return [e.t for e in self.events]

    @property
    def signature(self) -> tuple:
        return (self.status, tuple((tuple(sorted(e.entered)), tuple(sorted(e.left)))
                                   for e in self.events))


# -- a mechanical system with unilateral constraints, in its own velocities -----------------

class Model:
    """y = (positions (nq), velocities (nv)); subclasses give the physics."""

    n: int  # constraints
    nq: int
    nv: int
    gamma: float

    def pos_rate(self, y):  # d positions / dt
        raise NotImplementedError

    def mass(self, y):  # nv x nv
        raise NotImplementedError

    def force(self, y, contact: frozenset[int]):  # generalised forces but the reactions
        raise NotImplementedError

    def jac(self, y):  # Da, n x nv
        raise NotImplementedError

    def drift(self, y):  # (d/dt Da) v
        raise NotImplementedError

    def heights(self, y):  # a(q)
        raise NotImplementedError

    def flight(self, y, contact):
        """A closed-form motion from y in the contact set (a callable t -> (y(t), heights and
        their first three derivatives)) with bounds on the heights' second and third
        derivatives, or None."""
        return None

    #: whether the forces depend on the contact mode (force coupling): then the mode after an
    #: event is chosen by SYSTEMS.md Sec. 5's rule as it is written (the subsets of the
    #: constraints at rest, largest first, the first with lambda >= 0 and a'' >= 0 for the
    #: released), since no single complementarity problem describes it
    coupled = False

    # generic parts

    def rates(self, y):
        return self.jac(y) @ y[self.nq:]

    def _chol(self, y):
        """L^-1 with M = L L^T (the mass matrices here are constant: cached)."""
        if "_Linv" not in self.__dict__:
            self._Linv = np.linalg.inv(np.linalg.cholesky(self.mass(y)))
        return self._Linv

    @staticmethod
    def _G(Linv, Da):
        """G = Da L^-T (rows: the constraints)."""
        return Da @ Linv.T

    @staticmethod
    def _lift(Linv, x):
        """L^-T x: a velocity from M^(1/2)-coordinates."""
        return Linv.T @ x

    def accel(self, y, contact: frozenset[int]):
        """(v', lambda) in the contact mode: a_S'' = 0, the least-norm correction."""
        L = self._chol(y)
        f = self.force(y, contact)
        free = self._lift(L, L @ f)
        lam = np.zeros(self.n)
        if not contact:
            return free, lam
        S = sorted(contact)
        Da = self.jac(y)[S]
        G = self._G(L, Da)
        b = Da @ free + self.drift(y)[S]
        x = np.linalg.lstsq(G, -b, rcond=None)[0]
        lam[S] = np.linalg.lstsq(G.T, x, rcond=None)[0]
        return free + self._lift(L, x), lam

    def field(self, y, contact):
        acc, _ = self.accel(y, contact)
        return np.concatenate([self.pos_rate(y), acc])

    def rank(self, y, S) -> int:
        if not S:
            return 0
        Da = self.jac(y)[sorted(S)]
        Da = Da / np.linalg.norm(Da, axis=1, keepdims=True)
        sv = np.linalg.svd(Da, compute_uv=False)
        return int(np.sum(sv > RANK_TOL * sv[0]))

    def depends(self, y, S, j) -> bool:
        """Row j of Da lies in the span of the rows of S."""
        if not S:
            return False
        Da = self.jac(y)
        rows = Da[sorted(S)]
        coef = np.linalg.lstsq(rows.T, Da[j], rcond=None)[0]
        return np.linalg.norm(rows.T @ coef - Da[j]) <= RANK_TOL * np.linalg.norm(Da[j])

    def impact(self, y, S):
        """Newton's law on every row of S: Da_S v+ = -gamma Da_S v-, the M-least change."""
        S = sorted(S)
        L = self._chol(y)
        Da = self.jac(y)[S]
        v = y[self.nq:]
        x = np.linalg.lstsq(self._G(L, Da), -(1.0 + self.gamma) * (Da @ v), rcond=None)[0]
        return np.concatenate([y[:self.nq], v + self._lift(L, x)])

    def _enumerate(self, y, surface):
        S = sorted(surface)
        if self.rank(y, surface) < len(S):
            raise ReferenceError("force coupling with dependent contacts: not modelled")
        acc, lam = self.accel(y, frozenset(S))
        if all(lam[j] >= 0.0 for j in S):
            return frozenset(S)
        for size in range(len(S), -1, -1):
            for mask in range(1 << self.n):
                cand = frozenset(j for j in range(self.n) if mask >> j & 1)
                if len(cand) != size or not cand <= surface:
                    continue
                acc, lam = self.accel(y, cand)
                a2 = self.jac(y) @ acc + self.drift(y)
                if all(lam[j] >= -1e-10 for j in cand) and all(
                        a2[j] >= -1e-10 for j in S if j not in cand):
                    return cand
        raise ReferenceError("no contact mode fits (INCONSISTENT)")

    def separation(self, y, S):
        """a'' of the constraints S (at rest on their surface) under complementarity: the
        least-distance program min |x| s.t. G x + b >= 0 by NNLS (Lawson & Hanson, ch. 23)."""
        S = sorted(S)
        L = self._chol(y)
        f = self.force(y, frozenset(S))
        free = self._lift(L, L @ f)
        Da = self.jac(y)[S]
        G = self._G(L, Da)
        b = Da @ free + self.drift(y)[S]
        scale = max(1.0, float(np.max(np.abs(b))))
        E = np.vstack([G.T, -b[None, :] / scale])
        target = np.zeros(E.shape[0])
        target[-1] = 1.0
        u, _ = nnls(E, target, maxiter=50 * E.shape[1])
        r = E @ u - target
        if abs(r[-1]) < 1e-12:
            raise ReferenceError("no contact forces keep the constraints out of the surface")
        x = -r[:-1] / r[-1] * scale
        return dict(zip(S, G @ x + b)), scale

    def stay(self, y, surface):
        """The constraints of ``surface`` (at rest on it) that stay in contact, and with them
        every other constraint within BAND of its surface whose row depends on theirs."""
        if not surface:
            return frozenset()
        if self.coupled:
            stay = set(self._enumerate(y, surface))
        else:
            acc, scale = self.separation(y, surface)
            stay = set()
            for j, a2 in acc.items():
                if abs(a2) <= CONTACT_TOL * scale:
                    stay.add(j)
                elif abs(a2) < AMBIGUOUS * scale:
                    raise ReferenceError(f"constraint {j}: separation acceleration {a2:.3g} "
                                         "is too close to 0 to tell contact from release")
        a = self.heights(y)
        for j in range(self.n):
            if j not in stay and abs(a[j]) <= BAND and self.depends(y, stay, j):
                stay.add(j)
        return frozenset(stay)


# -- rigid body -------------------------------------------------------------------------------

def skew(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def rodrigues(w, t):
    """exp(t [w]x)."""
    n = np.linalg.norm(w)
    if n == 0.0:
        return np.eye(3)
    K = skew(w / n)
    th = n * t
    return np.eye(3) + math.sin(th) * K + (1.0 - math.cos(th)) * (K @ K)


def rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


class RigidBody(Model):
    """One rigid body: mass, inertia tensor about the centre in body axes, contact points
    (from the centre, body axes), gravity g along -z, restitution gamma. y = (p, R (row-major),
    v, w): 18 numbers."""

    nq, nv = 12, 6

    def __init__(self, mass, inertia, points, g, gamma):
        self.m = float(mass)
        self.I = np.array(inertia, dtype=float)
        if self.I.shape == (3,):
            self.I = np.diag(self.I)
        self.points = np.array(points, dtype=float)
        self.g = float(g)
        self.gamma = float(gamma)
        self.n = len(self.points)
        self.M = np.zeros((6, 6))
        self.M[:3, :3] = self.m * np.eye(3)
        self.M[3:, 3:] = self.I

    @staticmethod
    def state(p, R, v, w):
        return np.concatenate([p, np.asarray(R).ravel(), v, w]).astype(float)

    @staticmethod
    def parts(y):
        return y[:3], y[3:12].reshape(3, 3), y[12:15], y[15:18]

    def pos_rate(self, y):
        _p, R, v, w = self.parts(y)
        return np.concatenate([v, (R @ skew(w)).ravel()])

    def mass(self, y):
        return self.M

    def force(self, y, contact):
        w = y[15:18]
        return np.concatenate([[0.0, 0.0, -self.m * self.g], -np.cross(w, self.I @ w)])

    def jac(self, y):
        R = y[3:12].reshape(3, 3)
        nb = R[2]  # R^T e_z
        Da = np.zeros((self.n, 6))
        Da[:, 2] = 1.0
        Da[:, 3:] = np.cross(self.points, nb)
        return Da

    def drift(self, y):
        R, w = y[3:12].reshape(3, 3), y[15:18]
        return np.cross(w, np.cross(w, self.points)) @ R[2]

    def heights(self, y):
        return y[2] + self.points @ y[3:12].reshape(3, 3)[2]

    def flight(self, y, contact):
        """Closed form when w is a principal axis (to rounding): w stays constant in the body
        and R(t) = R(0) exp(t [w]x); in the air the centre falls on a parabola. The guards'
        second derivatives are bounded by g + |w|^2 |r_k|, their third by |w|^3 |r_k|.
        Resting on a face (contacts of rank 3, i.e. a plane of the body on the ground, at
        rest on it) with w along the vertical, a principal axis, the body turns uniformly
        about the vertical and slides at constant velocity: the contact forces carry its
        weight and no moment, whatever they are individually (they need not be known)."""
        p0, R0, v0, w = (a.copy() for a in self.parts(y))
        # (w x I w: the angular acceleration a flight would have; below 1e-14 the closed form
        # is exact to ~1e-13 over the runs' ten time units)
        if np.linalg.norm(np.linalg.solve(self.I, np.cross(w, self.I @ w))) > 1e-14:
            return None
        gvec = np.array([0.0, 0.0, -self.g])
        if contact:
            nb = R0[2]  # the vertical in body axes
            rates = self.rates(y)[sorted(contact)]
            if (self.rank(y, contact) != 3 or np.max(np.abs(rates)) > 1e-12
                    or np.linalg.norm(np.cross(w, nb)) > 1e-14
                    or abs(v0[2]) > 1e-12):
                return None
            v0[2] = 0.0
            gvec = np.zeros(3)
            w = np.dot(w, nb) * nb
        r = self.points
        wr = np.cross(w, r)
        wwr = np.cross(w, wr)
        www = np.cross(w, wwr)
        nw = np.linalg.norm(w)
        rn = np.linalg.norm(r, axis=1)

        def at(t):
            Rt = R0 @ rodrigues(w, t)
            e = Rt[2]
            yt = self.state(p0 + v0 * t + 0.5 * gvec * t * t, Rt, v0 + gvec * t, w)
            return (yt, p0[2] + v0[2] * t + 0.5 * gvec[2] * t * t + r @ e,
                    v0[2] + gvec[2] * t + wr @ e, gvec[2] + wwr @ e, www @ e)

        return at, -gvec[2] + nw * nw * rn, nw ** 3 * rn


def euler_state(q, qd, offset=(0.0, 0.0, 0.0)):
    """The rigid-body state of a body placed by (x, y, z, yaw, pitch, roll), R = Rz Ry Rx, and
    their rates (the simulator's coordinates of box3d.py and table.py); ``offset``: the centre
    of mass in the body's axes (its frame origin is at (x, y, z))."""
    x, y, z, yaw, pitch, roll = q[:6]
    xd, yd, zd, yawd, pitchd, rolld = qd[:6]
    Rz, Ry, Rx = rot_z(yaw), rot_y(pitch), rot_x(roll)
    R = Rz @ Ry @ Rx
    w_world = (yawd * np.array([0.0, 0.0, 1.0]) + pitchd * (Rz @ [0.0, 1.0, 0.0])
               + rolld * (Rz @ Ry @ [1.0, 0.0, 0.0]))
    w = R.T @ w_world
    d = np.asarray(offset, dtype=float)
    p = np.array([x, y, z]) + R @ d
    v = np.array([xd, yd, zd]) + R @ np.cross(w, d)
    return RigidBody.state(p, R, v, w)


# -- the point-foot biped (MODEL.md Sec. 2) ---------------------------------------------------

class PointBiped(Model):
    """The paper's sagittal biped, written again from MODEL.md Sec. 2: q = (x, z, th, x1, z1,
    x2, z2), M = diag(mb, mb, Ib, mf, mf, mf, mf), massless spring legs from the hips
    (x + s_j w cos th, z + s_j w sin th), s = (-1, +1), to point feet; u_j pushes leg j iff
    foot j alone is down, u12 turns the body iff both are. Constraints: z1, z2 >= 0."""

    nq = nv = 7
    n = 2
    coupled = True

    def __init__(self, u=(0.0, 0.0, 0.0), *, mb=1.0, Ib=0.5, mf=1.0, g=1.0, l0=0.5, w=0.25,
                 k=27.0, c=0.0, gamma=0.0):
        self.u = tuple(float(v) for v in u)
        self.mb, self.Ib, self.mf, self.g = mb, Ib, mf, g
        self.l0, self.w, self.k, self.c, self.gamma = l0, w, k, c, gamma
        self.M = np.diag([mb, mb, Ib, mf, mf, mf, mf])

    def pos_rate(self, y):
        return y[7:].copy()

    def mass(self, y):
        return self.M

    def force(self, y, contact):
        x, z, th, *feet = y[:7]
        dx, dz, dth, *dfeet = y[7:]
        f = np.zeros(7)
        f[1] = -self.mb * self.g
        for j, s in enumerate((-1.0, 1.0)):
            hx = x + s * self.w * math.cos(th)
            hz = z + s * self.w * math.sin(th)
            dhx = dx - s * self.w * math.sin(th) * dth
            dhz = dz + s * self.w * math.cos(th) * dth
            ex, ez = hx - feet[2 * j], hz - feet[2 * j + 1]
            length = math.hypot(ex, ez)
            nx, nz = ex / length, ez / length
            dlen = nx * (dhx - dfeet[2 * j]) + nz * (dhz - dfeet[2 * j + 1])
            push = self.u[j] if contact == {j} else 0.0
            F = self.k * (self.l0 - length) - self.c * dlen + push
            f[0] += F * nx
            f[1] += F * nz
            f[2] += s * self.w * (math.cos(th) * nz - math.sin(th) * nx) * F
            f[3 + 2 * j] = -F * nx
            f[4 + 2 * j] = -F * nz - self.mf * self.g
        if contact == {0, 1}:
            f[2] += self.u[2]
        return f

    def jac(self, y):
        Da = np.zeros((2, 7))
        Da[0, 4] = Da[1, 6] = 1.0
        return Da

    def drift(self, y):
        return np.zeros(2)

    def heights(self, y):
        return y[[4, 6]].copy()


def biped_start(maneuver, th0, l0=0.5, w=0.25):
    """MODEL.md Sec. 4's initial states: (y0, initial contact set)."""
    c, s = math.cos(th0), math.sin(th0)
    y = np.zeros(14)
    y[2] = th0
    if maneuver == "touchdown":
        y[1] = 1.0
        for j, side in enumerate((-1.0, 1.0)):
            y[3 + 2 * j] = side * w * c + l0 * s
            y[4 + 2 * j] = 1.0 + side * w * s - l0 * c
        return y, frozenset()
    y[1] = l0 - 0.15
    for j, side in enumerate((-1.0, 1.0)):
        y[3 + 2 * j] = side * w * c
    return y, frozenset({0, 1})


# -- the hybrid simulation ---------------------------------------------------------------------

@dataclass
class Terminal:
    """The terminal guard: ``T`` (the run ends at t = T, a clock's T - tau) or ``guard`` (a
    function of y, ending the run where it falls through 0, armed once above 1e-10 and, with
    ``after_touchdown``, after the first touchdown); ``final_mode``: the contact set the end
    must find (None: any)."""

    T: float | None = None
    guard: Callable[[np.ndarray], float] | None = None
    after_touchdown: bool = False
    final_mode: frozenset[int] | None = None


def _first_fall(fun, a, stop, G):
    """The first root after a (where g > 0) at which g falls through 0, before stop, or None.
    fun(t) -> (g, g'), |g''| <= G on the interval: from a point where g > 0 with rate g' there
    is no root before (g' + sqrt(g'^2 + 2 G g)) / G, and once g' < 0 with G g < g'^2 / 4 the
    guard decreases to exactly one root within 2 g / |g'| (Brent's method)."""
    for _ in range(1_000_000):
        if a >= stop:
            return None
        ga, ra = fun(a)
        if ga <= 0.0:
            raise ReferenceError(f"a guard is not positive at t = {a} ({ga})")
        if G == 0.0:  # a straight line
            return None if ra >= 0.0 or a + ga / -ra > stop else a + ga / -ra
        if ra < 0.0 and G * ga < 0.25 * ra * ra:
            b = a + 2.0 * ga / -ra
            if b > stop and fun(stop)[0] > 0.0:
                return None
            b = min(b, stop)
            return brentq(lambda t: fun(t)[0], a, b, xtol=1e-16, rtol=4 * EPS, maxiter=500)
        a += 0.9 * (ra + math.sqrt(ra * ra + 2.0 * G * ga)) / G
    raise ReferenceError(f"a guard grazes zero near t = {a}")


def _watch_from(fun, G, G3, stop):
    """Where a guard left at ~0 by an event (g(0) <= 0) is certainly above 0, from where its
    return is searched; None when it does not rise before stop. fun(t) -> (g, g', g'')."""
    g0, r0, c0 = fun(0.0)
    if r0 * r0 > 4.0 * G * abs(g0):  # g >= g0 + r0 t - G t^2 / 2 > 0 at t = r0 / G
        if r0 < 0.0:
            raise ReferenceError("a reset constraint goes into its surface")
        return r0 / G
    # at rest on its surface (a release): g'' > 0 lifts it; g'' >= c0 - G3 t
    if c0 <= 0.0 or c0 * c0 < 1e3 * G3 * max(abs(r0), 1e-300) or c0 < 1e-9:
        raise ReferenceError(f"a released constraint does not clearly rise (a' = {r0:.3g}, "
                             f"a'' = {c0:.3g})")
    t = 0.5 * c0 / G3 if G3 > 0 else 1.0
    t = min(t, stop)
    while True:
        g, r, _ = fun(t)
        if g > 0.0 and r > 0.0:
            return t
        t *= 0.5
        if t < 1e-9:
            raise ReferenceError("a released constraint does not rise")


class _Sim:
    def __init__(self, model: Model, terminal: Terminal, band: float, t_end: float,
                 max_events: int):
        self.m = model
        self.term = terminal
        self.band = band
        self.t_end = t_end
        self.max_events = max_events

    # the guards of mode C at y: heights in the air, reactions in contact (independent C)
    def guards(self, y, C, dependent):
        g = self.m.heights(y)
        if C:
            _acc, lam = self.m.accel(y, C)
            for j in C:
                g[j] = math.inf if dependent else lam[j]
        return g

    def term_value(self, y):
        return self.term.guard(y) if self.term.guard is not None else math.inf

    def run(self, y, C) -> Run:
        m = self.m
        t = 0.0
        C = frozenset(C)
        out = self.out = Run("HORIZON", self.t_end, y, C)  # (partial, after an exception)
        if C:
            C = m.stay(y, C)
        term_enabled = not self.term.after_touchdown
        stop = self.t_end if self.term.T is None else min(self.t_end, self.term.T)
        while True:
            dependent = m.rank(y, C) < len(C)
            flight = m.flight(y, C) if self.term.guard is None else None
            if flight is not None:
                if C:  # (at rest: the contact forces are statics, the same at every instant)
                    acc, scale = m.separation(y, C)
                    if max(acc.values()) > CONTACT_TOL * scale:
                        raise ReferenceError("a contact of a resting body would leave")
                hit = self._closed_form(flight, C, stop - t)
            else:
                hit = self._numeric(y, C, dependent, stop - t, term_enabled)
            tau, y_hit, first = hit
            t += tau
            if first is None:  # the end of the time: T (OK) or the horizon
                out.t_final, out.y_final, out.mode_final = t, y_hit, C
                if self.term.T is not None and stop == self.term.T:
                    out.status = self._final_status(C)
                return out
            if first == m.n:  # the terminal guard, by time before every contact event
                out.t_final, out.y_final, out.mode_final = t, y_hit, C
                out.status = self._final_status(C)
                return out
            term_before = self.term_value(y_hit) if term_enabled else -math.inf
            y, C, touched = self._event(t, y_hit, C, first, dependent, out)
            if touched:
                term_enabled = True
            if len(out.events) >= self.max_events:
                out.status, out.t_final, out.y_final, out.mode_final = "MAX_EVENTS", t, y, C
                return out
            if term_before > 1e-10 and self.term_value(y) <= 0.0:  # the reset ends the run
                out.status, out.t_final, out.y_final, out.mode_final = (
                    self._final_status(C), t, y, C)
                return out

    def _final_status(self, C):
        if self.term.final_mode is not None and C != self.term.final_mode:
            return "APEX_IN_CONTACT"
        return "OK"

    # -- a closed-form flight ------------------------------------------------------------
    def _closed_form(self, flight, C, stop):
        at, G, G3 = flight
        n = self.m.n
        roots = []
        for j in range(n):
            if j in C:
                continue

            def fun(t, j=j):
                _y, g, r, _c, _j = at(t)
                return g[j], r[j]

            def fun3(t, j=j):
                _y, g, r, c, _j = at(t)
                return g[j], r[j], c[j]

            g0 = at(0.0)[1][j]
            start = 0.0 if g0 > 0.0 else _watch_from(fun3, G[j], G3[j], stop)
            if start is None:
                continue
            root = _first_fall(fun, start, stop, G[j])
            if root is not None:
                roots.append((root, j))
        if not roots:
            return stop, at(stop)[0], None
        tau, first = min(roots)
        return tau, at(tau)[0], first

    # -- a numeric flow ------------------------------------------------------------------
    def _numeric(self, y0, C, dependent, stop, term_enabled):
        m = self.m
        n = m.n
        use_term = self.term.guard is not None

        def fun(_t, y):
            return m.field(y, C)

        def all_guards(y):
            g = self.guards(y, C, dependent)
            return np.append(g, self.term_value(y) if use_term else math.inf)

        g_prev = all_guards(y0)
        # a guard left at ~0 by the event (a reset constraint; its value and rate there are
        # rounding of either sign) is watched from the first sample where it is clearly above
        # 0 (LIVE: 1e3 times a height's rounding; flights below that are not resolved here)
        live = [g_prev[j] > REARM for j in range(n)]
        live.append(use_term and term_enabled and g_prev[n] > 1e-10)
        r_prev = m.rates(y0)
        solver = DOP853(fun, 0.0, y0, stop, max_step=H_MAX, rtol=RTOL, atol=ATOL)
        while True:
            t_a = solver.t
            msg = solver.step()
            if solver.status == "failed":
                raise ReferenceError(f"DOP853 failed: {msg}")
            t_b = solver.t
            dense = solver.dense_output()
            hits = []
            for k in range(1, SAMPLES + 1):
                x = t_b if k == SAMPLES else t_a + (t_b - t_a) * k / SAMPLES
                x_prev = t_a + (t_b - t_a) * (k - 1) / SAMPLES
                yk = dense(x)
                g = all_guards(yk)
                r = m.rates(yk)
                for j in range(n + 1):
                    if not live[j]:
                        if j < n and g[j] > LIVE:
                            live[j] = True  # (a reset constraint above its surface again)
                        elif j == n and use_term and term_enabled and g[j] > 1e-10:
                            live[j] = True
                        continue
                    if g_prev[j] > 0.0 and g[j] <= 0.0:
                        hits.append((self._root(dense, all_guards, j, x_prev, x), j))
                    elif (j < n and j not in C and g_prev[j] > 0.0 and r_prev[j] < 0.0
                          and r[j] > 0.0):
                        low = brentq(lambda s, j=j, dense=dense: m.rates(dense(s))[j],
                                     x_prev, x, xtol=1e-16, rtol=4 * EPS)
                        if all_guards(dense(low))[j] <= 0.0:
                            hits.append((self._root(dense, all_guards, j, x_prev, low), j))
                if dependent:
                    acc, scale = m.separation(yk, C)
                    if any(a2 > CONTACT_TOL * scale for a2 in acc.values()):
                        raise ReferenceError("a contact of a dependent set would leave: not "
                                             "modelled by the reference")
                g_prev, r_prev = g, r
                if hits:
                    tau, first = min(hits)
                    return tau, dense(tau), first
            if solver.status == "finished":
                return stop, solver.y.copy(), None

    @staticmethod
    def _root(dense, all_guards, j, a, b):
        return brentq(lambda s: all_guards(dense(s))[j], a, b, xtol=1e-15, rtol=4 * EPS,
                      maxiter=500)

    # -- an event -------------------------------------------------------------------------
    def _event(self, t, y, C, first, dependent, out):
        m = self.m
        a = m.heights(y)
        r = m.rates(y)
        flips = {first}
        for j in range(m.n):
            if j == first or j in C:
                continue
            if r[j] < -SEPARATION and abs(a[j]) < 10 * self.band:
                out.band_margin = min(out.band_margin, abs(abs(a[j]) / self.band - 1.0))
                if abs(a[j]) <= self.band:
                    flips.add(j)
        if C and not dependent:
            _acc, lam = m.accel(y, C)
            f = m.field(y, C)
            eps = 1e-6
            dlam = (m.accel(y + eps * f, C)[1] - m.accel(y - eps * f, C)[1]) / (2 * eps)
            for j in C:
                if j != first and dlam[j] < 0.0 and abs(lam[j]) < 10 * self.band:
                    out.band_margin = min(out.band_margin, abs(abs(lam[j]) / self.band - 1.0))
                    if abs(lam[j]) <= self.band:
                        flips.add(j)
        entered = frozenset(flips - C)
        left = frozenset(flips & C)
        surface = (C | entered) - left
        y_after = y
        if entered:
            y_after = m.impact(y, surface)
            r_after = m.rates(y_after)
            surface = frozenset(j for j in surface
                                if not (j in entered and r_after[j] > SEPARATION))
        after = m.stay(y_after, surface)
        out.events.append(Event(t, entered, left, C, after, y.copy(), y_after.copy()))
        return y_after, after, bool(entered)


def simulate(model: Model, y0, contact=(), *, terminal: Terminal, band=BAND, t_end=100.0,
             max_events=200) -> Run:
    """Run ``model`` from y0 in the contact set ``contact`` to the terminal event."""
    return _Sim(model, terminal, band, t_end, max_events).run(np.asarray(y0, dtype=float),
                                                              frozenset(contact))


def coincidences(run_at, lo, hi, num, *, xtol=1e-15):
    """Where the event sequence of ``run_at(s, band)`` changes on [lo, hi] with merging off
    (BAND_OFF): a grid of ``num`` points, then bisection of every change (the same search as
    ``reference_flight``'s)."""
    return changes(lambda s: run_at(s, BAND_OFF).signature, lo, hi, num, xtol=xtol)


# -- the suite's systems, written again from their physics -------------------------------------

BOX = {"m": 1.0, "a": 0.4, "b": 0.25, "c": 0.15, "g": 1.0, "h0": 0.3}
#: the corners of box3d.py in its order: fl, fr, rl, rr (x forward, y left, z up)
CORNERS = ((1, 1), (1, -1), (-1, 1), (-1, -1))


def box(e, *, m=1.0, a=0.4, b=0.25, c=0.15, g=1.0):
    """box3d.py: a solid box of edges 2a, 2b, 2c, its bottom corners the contacts."""
    inertia = m / 3 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    return RigidBody(m, inertia, [(sx * a, sy * b, -c) for sx, sy in CORNERS], g, e)


def box_start(maneuver, s, *, a=0.4, c=0.15, h0=0.3, spin=0.0, wr=0.7, wp=-0.4, wy=1.3):
    """box3d.py's initial states (yaw, pitch, roll and their rates, R = Rz Ry Rx)."""
    if maneuver == "edge":
        return euler_state([0, 0, h0, 0, s, 0], [0] * 6)
    if maneuver == "flat":
        return euler_state([0, 0, h0 + c, 0, 0, s], [0, 0, 0, spin, 0, 0])
    return euler_state([0, 0, h0 + a, 0, 0.3, s], [0, 0, 0, wy, wp, wr])


TABLE = {"ms": 2.0, "A": 0.5, "B": 0.35, "C": 0.03, "ml": 0.15, "L": 0.6, "lx": 0.42,
         "ly": 0.27, "g": 1.0, "h0": 0.2}


def table_parts(*, ms=2.0, A=0.5, B=0.35, C=0.03, ml=0.15, L=0.6, lx=0.42, ly=0.27):
    """table.py as one rigid body: (mass, centre of mass in the slab's frame, inertia about
    it in the slab's axes, the legs' tips from the centre of mass) by the parallel-axis
    theorem over the slab and the four legs (thin rods of mass ml, length L)."""
    parts = [(ms, np.zeros(3), ms / 3 * np.diag([B * B + C * C, A * A + C * C, A * A + B * B]))]
    for sx, sy in CORNERS:
        parts.append((ml, np.array([sx * lx, sy * ly, -C - L / 2]),
                      ml * L * L / 12 * np.diag([1.0, 1.0, 0.0])))
    mass = sum(pm for pm, _, _ in parts)
    com = sum(pm * pc for pm, pc, _ in parts) / mass
    inertia = np.zeros((3, 3))
    for pm, pc, pi in parts:
        d = pc - com
        inertia += pi + pm * (d @ d * np.eye(3) - np.outer(d, d))
    tips = [np.array([sx * lx, sy * ly, -C - L]) - com for sx, sy in CORNERS]
    return mass, com, inertia, tips


def table(e=0.0, *, g=1.0, **sizes):
    mass, _com, inertia, tips = table_parts(**sizes)
    return RigidBody(mass, inertia, tips, g, e)


def table_start(s, *, spin=0.0, C=0.03, L=0.6, h0=0.2, **sizes):
    _mass, com, _inertia, _tips = table_parts(C=C, L=L, **sizes)
    return euler_state([0, 0, h0 + C + L, 0, 0, s], [0, 0, 0, spin, 0, 0], offset=com)


def rod(e, *, m=1.0, w=0.5, kg=0.3, g=1.0):
    """rod.py: a rod of half-length w, radius of gyration kg, its ends the contacts (its
    inertia about its own axis, kg^2 m / 10, is never excited: it turns about y only)."""
    return RigidBody(m, [m * kg * kg / 10, m * kg * kg, m * kg * kg], [(-w, 0, 0), (w, 0, 0)],
                     g, e)


def rod_start(s, *, h0=1.0):
    """Tilted by s (its axis turned from x towards +z: a rotation by -s about y)."""
    return RigidBody.state([0, 0, h0], rot_y(-s), [0, 0, 0], [0, 0, 0])


def rod_state(y):
    """The simulator's rod coordinates (x, z, th, tau) and rates as a rigid-body state."""
    x, z, th = y[0], y[1], y[2]
    dx, dz, dth = y[4], y[5], y[6]
    return RigidBody.state([x, 0, z], rot_y(-th), [dx, 0, dz], [0, -dth, 0])
