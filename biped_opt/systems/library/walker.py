"""The n-leg walker (SYSTEMS.md Sec. 3): the paper's biped with n >= 1 legs.

Hips at body-frame offsets s_i w, s_i evenly spaced in [-1, 1]; identical massless spring-damper
legs ending in point feet of mass mf; q = (x, z, th, x_1, z_1, ..., x_n, z_n). Input laws:
``coupled`` (the paper's: u_i acts iff leg i alone is on the ground, u_body iff all are) and
``decoupled`` (u_i acts iff foot i is on the ground, u_body never).

``walker(n, offsets=True)`` adds the foot-offset family (SYSTEMS.md Sec. 3, paper Sec. V-B):
parameters d1..dn and v1..vn (default 0) and a maneuver ``offsets`` that drops the level body
(th = 0) from z = 1 with foot i raised by s d_i, its leg compressed by as much, and moving
upward at s v_i (s is the maneuver's parameter, named th0 like the others'); at s = 0 every
foot touches down at once, and the choice of the d_i selects any of the n! touchdown orders.
``offsets`` ends at the body's nadir after touchdown. A walker dropped like that bounces
(touchdown, liftoff, touchdown, ...); to follow k rounds of such events the variant also carries
a clock, a coordinate ``clock`` of unit mass, no force and unit initial velocity (so clock = t),
and a second maneuver ``rounds`` from the same states that ends when the clock reaches the
parameter ``horizon``. The variant is opt-in, so the library's walkers (and the biped) keep
their coordinates, parameters, maneuvers and generated code.
"""

from __future__ import annotations

import sympy as sp

from biped_opt.systems.description import System, SystemDescriptionError

__all__ = ["walker", "LAWS", "hip_offsets"]

LAWS = ("coupled", "decoupled")
PARAMETERS = {"mb": 1.0, "Ib": 0.5, "mf": 1.0, "g": 1.0, "l0": 0.5, "w": 0.25, "k": 27.0,
              "c": 0.0, "gamma": 0.0}
#: initial body height of touchdown, leg compression of liftoff (MODEL.md Sec. 4)
TOUCHDOWN_HEIGHT = 1
LIFTOFF_COMPRESSION = sp.Rational(15, 100)
#: default end time of the offsets variant's ``rounds`` maneuver
OFFSETS_HORIZON = 2.0


def hip_offsets(n: int) -> list[sp.Rational]:
    """s_i, evenly spaced in [-1, 1] (n = 1: 0)."""
    if n == 1:
        return [sp.Integer(0)]
    return [sp.Rational(2 * i, n - 1) - 1 for i in range(n)]


def walker(n: int = 3, law: str = "coupled", *, name: str | None = None,
           feet: list[str] | None = None, inputs: list[str] | None = None,
           offsets: bool = False) -> System:
    """The n-leg walker with input law ``law``. ``feet`` and ``inputs`` rename the constraints
    and the inputs (u_1..u_n, u_body by default): the biped is this walker with n = 2.
    ``offsets`` adds the foot-offset family (see the module docstring)."""
    if not isinstance(n, int) or n < 1:
        raise SystemDescriptionError(f"walker: n must be an integer >= 1, got {n!r}")
    if law not in LAWS:
        raise SystemDescriptionError(f"walker: law must be one of {', '.join(LAWS)}, got {law!r}")
    feet = feet or [f"foot{i + 1}" for i in range(n)]
    inputs = inputs or [*(f"u{i + 1}" for i in range(n)), "u_body"]
    coords = ["x", "z", "th"] + [c for i in range(n) for c in (f"x{i + 1}", f"z{i + 1}")]
    parameters = dict(PARAMETERS)
    if offsets:
        coords.append("clock")
        parameters.update({f"{c}{i + 1}": 0.0 for c in "dv" for i in range(n)},
                          horizon=OFFSETS_HORIZON)
    s = System(name or f"walker{n}_{law}" + ("_offsets" if offsets else ""), coords,
               parameters=parameters, inputs=inputs, s="th0")
    p, u = s.p, list(s.u)
    x, z, th = s.q[:3]
    dx, dz, dth = s.dq[:3]
    s.mass_matrix = sp.diag(p.mb, p.mb, p.Ib, *([p.mf] * (2 * n)), *([1] if offsets else []))
    s.restitution = p.gamma
    hips = hip_offsets(n)
    for i, foot in enumerate(feet):
        s.constraint(foot, s.q[4 + 2 * i], at=(s.q[3 + 2 * i], 0, s.q[4 + 2 * i]))
    _looks(s, feet, hips)

    def forces(J: frozenset[str]) -> list[sp.Expr]:
        f = [sp.Integer(0)] * len(coords)
        f[1] = -p.mb * p.g
        for i, si in enumerate(hips):
            rx, rz = si * p.w * sp.cos(th), si * p.w * sp.sin(th)
            ex, ez = x + rx - s.q[3 + 2 * i], z + rz - s.q[4 + 2 * i]
            vx = dx - rz * dth - s.dq[3 + 2 * i]
            vz = dz + rx * dth - s.dq[4 + 2 * i]
            length = sp.sqrt(ex**2 + ez**2)
            nx, nz = ex / length, ez / length
            acting = J == {feet[i]} if law == "coupled" else feet[i] in J
            force = p.k * (p.l0 - length) - p.c * (nx * vx + nz * vz) + (u[i] if acting else 0)
            f[0] += force * nx
            f[1] += force * nz
            f[2] += (rx * nz - rz * nx) * force
            f[3 + 2 * i] = -force * nx
            f[4 + 2 * i] = -force * nz - p.mf * p.g
        if law == "coupled" and J == set(feet):
            f[2] += u[n]
        return f

    s.forces = forces
    dq = sp.Matrix(s.dq)
    springs = []
    for i, si in enumerate(hips):
        ex = x + si * p.w * sp.cos(th) - s.q[3 + 2 * i]
        ez = z + si * p.w * sp.sin(th) - s.q[4 + 2 * i]
        springs.append(p.k * (p.l0 - sp.sqrt(ex**2 + ez**2)) ** 2 / 2)
    s.energy = ((dq.T * s.mass_matrix * dq)[0, 0] / 2 + p.mb * p.g * z
                + sum(p.mf * p.g * s.q[4 + 2 * i] for i in range(n)) + sum(springs))
    body = {s.q[1]: TOUCHDOWN_HEIGHT, s.q[2]: s.s}
    for i, si in enumerate(hips):
        body[s.q[3 + 2 * i]] = si * p.w * sp.cos(s.s) + p.l0 * sp.sin(s.s)
        body[s.q[4 + 2 * i]] = TOUCHDOWN_HEIGHT + si * p.w * sp.sin(s.s) - p.l0 * sp.cos(s.s)
    s.maneuver("touchdown", initial=body, terminal=-dz, outcome=th, armed_after="touchdown",
               s_range=(-0.25, 0.25),
               description="fall from rest at z = 1 to the body's nadir after touchdown")
    stance = {s.q[1]: p.l0 - LIFTOFF_COMPRESSION, s.q[2]: s.s}
    for i, si in enumerate(hips):
        stance[s.q[3 + 2 * i]] = si * p.w * sp.cos(s.s)
    s.maneuver("liftoff", initial=stance, mode=feet, terminal=dz, outcome=th, final_mode=(),
               s_range=(-0.3, 0.3),
               description="push off from rest on all feet to the body's apex in the air")
    if offsets:
        raised = {s.q[1]: TOUCHDOWN_HEIGHT, s.dq[-1]: 1}
        for i, si in enumerate(hips):
            raised[s.q[3 + 2 * i]] = si * p.w
            raised[s.q[4 + 2 * i]] = TOUCHDOWN_HEIGHT - p.l0 + s.s * p[f"d{i + 1}"]
            raised[s.dq[4 + 2 * i]] = s.s * p[f"v{i + 1}"]
        s.maneuver("offsets", initial=raised, terminal=-dz, outcome=th, armed_after="touchdown",
                   s_range=(-0.1, 0.1),
                   description="fall from z = 1, level, foot i raised by th0 d_i and rising at "
                               "th0 v_i, to the body's nadir after touchdown")
        s.maneuver("rounds", initial=raised, terminal=p.horizon - s.q[-1], outcome=th,
                   s_range=(-0.1, 0.1),
                   description="the same fall, bouncing on until t = horizon")
    _problems(s, feet, [str(v) for v in u])
    return s


#: drawing sizes: the body's thickness and depth, the feet's radius, the legs' width
BODY_THICKNESS, BODY_DEPTH, FOOT_RADIUS, LEG_WIDTH = 0.06, 0.12, 0.035, 0.02


def _looks(s: System, feet: list[str], hips: list[sp.Rational]) -> None:
    """How the walker looks (SYSTEMS.md Sec. 6): the body as a bar between its outer hips
    (frame ``base_link``, pitch -th: th turns x towards +z, a ROS pitch towards -z), each foot
    as a ball (frame and sphere ``<foot>``, or ``<foot>_foot`` where the foot's name does not
    say foot: ``foot1``, ``left_foot``) and each leg as a line from its hip to its foot."""
    x, z, th = s.q[:3]
    w = s.p.w
    s.frame("base_link", x=x, z=z, pitch=-th)
    span = 2 * w * max(abs(h) for h in hips) if len(hips) > 1 else w
    s.box("body", "base_link", (span + BODY_THICKNESS, BODY_DEPTH, BODY_THICKNESS),
          color=(0.20, 0.45, 0.75))
    for i, (foot, si) in enumerate(zip(feet, hips)):
        xf, zf = s.q[3 + 2 * i], s.q[4 + 2 * i]
        name = foot if "foot" in foot else f"{foot}_foot"
        s.frame(name, x=xf, z=zf)
        s.sphere(name, name, FOOT_RADIUS, color=(0.15, 0.15, 0.15))
        hip = (x + si * w * sp.cos(th), 0, z + si * w * sp.sin(th))
        s.line(f"{foot}_leg", [hip, (xf, 0, zf)], width=LEG_WIDTH, color=(0.85, 0.40, 0.10))


def _problems(s: System, feet: list[str], u: list[str]) -> None:
    """MODEL.md Sec. 5's problems for n legs (for n = 2 exactly the paper's Eqs. (14), (15)
    and the liftoff variant): leg weights spaced geometrically between the paper's two."""
    n = len(feet)
    legs, body = u[:n], u[n]

    def spaced(a: float, b: float) -> list[float]:
        return [a] if n == 1 else [a * (b / a) ** (i / (n - 1)) for i in range(n)]

    s.problem("touchdown", maneuver="touchdown", decisions={k: (-0.5, 1.5) for k in legs},
              weights=dict(zip(legs, spaced(3e-4, 3e-3))), target=-0.1)
    s.problem("liftoff", maneuver="liftoff", decisions={body: (-0.5, 0.5)},
              weights={body: 0.01}, fixed=dict(zip(legs, spaced(1.5, 3.0))), target=0.01)
    s.problem("liftoff_variant", maneuver="liftoff", decisions={k: (0.0, 3.0) for k in legs},
              weights=dict(zip(legs, spaced(1e-5, 2e-5))), target=-0.02)
