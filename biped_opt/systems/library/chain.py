"""The planar chain (SYSTEMS.md Sec. 3a): a dense, configuration-dependent mass matrix.

A middle link (centre x, z, pitch th, half-length lb, mass mb) with a leg hinged at each end.
A leg is ``segments`` links in series, each hinge angle relative to the link before it (as a
motor or a spring sees it), so a link's pitch is th plus the angles of the hinges between it
and the middle link. The hinges are named by a letter from the middle link outwards (a: hip,
b: knee, c: ankle, d: toe) and by the leg (1 left, 2 right): q = (x, z, th, a1, a2, b1, b2, ...),
d = 3 + 2 segments. A torsional spring holds every hinge near its rest angle, +rest_j on the
left and -rest_j on the right (the legs mirror each other); the last link's end is the leg's
foot, a unilateral constraint on its height (``foot1``, ``foot2``), with restitution 0.6.
The mass matrix is the kinetic energy's Hessian in the velocities, the forces follow from
Lagrange's equations; no damping and no inputs, so the declared energy is conserved in flight.

``chain()`` (one link per leg, d = 5) is the chain of the user-system suite
(``tests/simulation/user/chain.py``): the same parameters, coordinates, expressions and
maneuver. With more links (LINKS) the legs are nearly straight and their outer links no lighter
than the inner ones: a light outer link bounces off the ground in ever smaller hops while the
middle link still presses down (a Zeno cascade), and light short links make the fastest mode in
flight, which sets the integrator's step, fast. The maneuver shows the same as with one link:
at s = 0 both feet land at once, on either side of it the lower one first.
"""

from __future__ import annotations

import sympy as sp

from biped_opt.systems.description import System, SystemDescriptionError

__all__ = ["chain", "LINKS", "MAX_SEGMENTS", "chain_coordinates"]

#: one link per leg: the middle link (mb, half-length lb), the leg link (ml, leg), its spring
#: (k around rest), gravity
PARAMETERS = {"mb": 1.0, "ml": 0.5, "lb": 0.3, "leg": 0.5, "k": 20.0, "rest": 0.9, "g": 1.0}
#: more links per leg: each leg's links from the hip outwards, (mass, length, spring, rest
#: angle of the hinge at its inner end); link 1's are ml, leg, k, rest, link j's ml<j>, leg<j>,
#: k<j>, rest<j>. Chosen so that the drop ends after 1-4 impacts, never in a foot's Zeno
#: cascade, at each s of a 17-point grid over its range (9 points for four links), and the
#: fastest mode in flight stays at 67, 97, 138 rad/s (one link: 45)
LINKS: dict[int, tuple[tuple[float, float, float, float], ...]] = {
    2: ((0.5, 0.35, 20.0, 0.9), (0.5, 0.35, 10.0, 0.2)),
    3: ((0.5, 0.25, 20.0, 0.9), (0.6, 0.25, 10.0, 0.2), (0.8, 0.2, 10.0, 0.2)),
    4: ((0.5, 0.2, 20.0, 0.9), (0.6, 0.2, 10.0, 0.2), (0.7, 0.15, 10.0, 0.2),
        (0.8, 0.15, 10.0, 0.1)),
}
MAX_SEGMENTS = 4
JOINTS = "abcd"
RESTITUTION = 0.6
#: the drop's start: the middle link's height, and how far beyond rest the hips are spread
HEIGHT, SPREAD = 1.2, 0.25
#: drawing sizes: the links' depth and thickness, the feet's radius
DEPTH, THICKNESS, FOOT_RADIUS = 0.12, 0.05, 0.035


def chain_coordinates(segments: int) -> list[str]:
    """x, z, th, then the hinges outwards, left before right: a1, a2, b1, b2, ..."""
    return ["x", "z", "th"] + [f"{JOINTS[j]}{i}" for j in range(segments) for i in (1, 2)]


# (the parameters in the order of PARAMETERS, the further links' after them)
_ORDER = {k: i for i, k in enumerate(PARAMETERS)}


def _parameters(segments: int) -> dict[str, float]:
    if segments == 1:
        return dict(PARAMETERS)
    out = {k: v for k, v in PARAMETERS.items() if k in ("mb", "lb", "g")}
    for j, (mass, length, spring, rest) in enumerate(LINKS[segments], start=1):
        tail = "" if j == 1 else str(j)
        out.update({f"ml{tail}": mass, f"leg{tail}": length, f"k{tail}": spring,
                    f"rest{tail}": rest})
    return dict(sorted(out.items(), key=lambda kv: _ORDER.get(kv[0], len(_ORDER))))


def chain(segments: int = 1, *, name: str | None = None) -> System:
    """The planar chain with ``segments`` links per leg (1..MAX_SEGMENTS), d = 3 + 2 segments;
    named ``chain`` (one link) or ``chain<d>``."""
    if isinstance(segments, bool) or not isinstance(segments, int) \
            or not 1 <= segments <= MAX_SEGMENTS:
        raise SystemDescriptionError(
            f"chain: segments must be an integer in 1..{MAX_SEGMENTS}, got {segments!r}")
    d = 3 + 2 * segments
    s = System(name or ("chain" if segments == 1 else f"chain{d}"), chain_coordinates(segments),
               s="tilt", restitution=RESTITUTION, parameters=_parameters(segments))
    q, dq = sp.Matrix(s.q), sp.Matrix(s.dq)
    x, z, th = s.q[:3]
    p = s.p

    def link(j: int, what: str) -> sp.Symbol:
        return p[what if j == 0 else f"{what}{j + 1}"]

    mb, lb, g = p.mb, p.lb, p.g
    # every body's mass, centre, moment of inertia about it and angular velocity: the middle
    # link, then the left leg's links outwards, then the right leg's
    masses, centres, inertias, spins = [mb], [sp.Matrix([x, z])], [mb * (2 * lb) ** 2 / 12], \
        [s.dq[2]]
    chains: list[list[sp.Matrix]] = []  # each leg's hinge, joints and foot
    for leg, side in ((0, -1), (1, 1)):  # the left leg's links point along -(cos, sin)
        point = sp.Matrix([x + side * lb * sp.cos(th), z + side * lb * sp.sin(th)])
        points = [point]
        pitch, spin = th, s.dq[2]
        for j in range(segments):
            pitch, spin = pitch + s.q[3 + 2 * j + leg], spin + s.dq[3 + 2 * j + leg]
            out = side * sp.Matrix([sp.cos(pitch), sp.sin(pitch)])
            length, mass = link(j, "leg"), link(j, "ml")
            masses.append(mass)
            centres.append(point + length / 2 * out)
            inertias.append(mass * length**2 / 12)
            spins.append(spin)
            point = point + length * out
            points.append(point)
        chains.append(points)
    # M = sum of m J^T J + I w^T w over the bodies (J: the centre's Jacobian, w: the
    # angular velocity's coefficients, constant here), and Lagrange's equations through the
    # derivatives of M: dT/dq_k = q'^T (dM/dq_k) q' / 2, d/dt(M q') = M q'' + sum_k dM/dq_k q'
    # q'_k; the same as differentiating T itself, with far smaller expressions to differentiate
    M = sp.zeros(d, d)
    for m, c, i, w in zip(masses, centres, inertias, spins):
        J = c.jacobian(q)
        W = sp.Matrix([[sp.diff(w, v) for v in s.dq]])
        M += m * J.T * J + i * W.T * W
    M = M.applyfunc(sp.expand)
    V = sum(m * g * c[1] for m, c in zip(masses, centres)) \
        + sum(link(j, "k") / 2 * (s.q[3 + 2 * j + leg] + side * link(j, "rest")) ** 2
              for j in range(segments) for leg, side in ((0, -1), (1, 1)))
    T = (dq.T * M * dq)[0] / 2
    s.mass_matrix = M
    dM = [M.diff(v) for v in s.q]
    lagrange = (sp.Matrix([(dq.T * dM[k] * dq)[0] / 2 for k in range(d)])
                - sum((dM[k] * dq * dq[k] for k in range(d)), sp.zeros(d, 1))
                - sp.Matrix([V]).jacobian(q).T)
    s.forces = lambda J: lagrange
    s.energy = T + V
    feet = [points[-1] for points in chains]
    for i, foot in enumerate(feet):
        s.constraint(f"foot{i + 1}", foot[1], at=(foot[0], 0, foot[1]))
    _looks(s, chains, segments)
    initial = {s.q[1]: HEIGHT, s.q[2]: s.s}
    for j in range(segments):
        rest = link(j, "rest") + (SPREAD if j == 0 else 0)
        initial[s.q[3 + 2 * j]], initial[s.q[4 + 2 * j]] = rest, -rest
    spread = ("hinges spread beyond rest" if segments == 1
              else "hips spread beyond rest, the other hinges at rest")
    s.maneuver("drop", initial=initial, terminal=s.dq[1], armed_after="touchdown",
               final_mode=(), outcome=s.dq[2], s_range=(-0.2, 0.2),
               description=f"from rest at height 1.2 and pitch s, {spread}, "
                           "to the middle link's first apex after the first impact")
    return s


def _looks(s: System, chains: list[list[sp.Matrix]], segments: int) -> None:
    """How the chain looks (SYSTEMS.md Sec. 6): the middle link as a box in frame
    ``base_link`` (pitch -th: th turns x towards +z, a ROS pitch towards -z), each leg as a
    line through its hinges to its foot, and each foot as a ball in frame ``foot<i>``."""
    x, z, th = s.q[:3]
    s.frame("base_link", x=x, z=z, pitch=-th)
    s.box("body", "base_link", (2 * s.p.lb, DEPTH, THICKNESS), color=(0.20, 0.45, 0.75))
    for i, points in enumerate(chains, start=1):
        s.line(f"leg{i}", [(pt[0], 0, pt[1]) for pt in points], width=THICKNESS / 2,
               color=(0.85, 0.40, 0.10))
        foot = points[-1]
        s.frame(f"foot{i}", x=foot[0], z=foot[1])
        s.sphere(f"foot{i}", f"foot{i}", FOOT_RADIUS, color=(0.15, 0.15, 0.15))
