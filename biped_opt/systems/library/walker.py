"""The n-leg walker (SYSTEMS.md Sec. 3): the paper's biped with n >= 1 legs.

Hips at body-frame offsets s_i w, s_i evenly spaced in [-1, 1]; identical massless spring-damper
legs ending in point feet of mass mf; q = (x, z, th, x_1, z_1, ..., x_n, z_n). Input laws:
``coupled`` (the paper's: u_i acts iff leg i alone is on the ground, u_body iff all are) and
``decoupled`` (u_i acts iff foot i is on the ground, u_body never).
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


def hip_offsets(n: int) -> list[sp.Rational]:
    """s_i, evenly spaced in [-1, 1] (n = 1: 0)."""
    if n == 1:
        return [sp.Integer(0)]
    return [sp.Rational(2 * i, n - 1) - 1 for i in range(n)]


def walker(n: int = 3, law: str = "coupled", *, name: str | None = None,
           feet: list[str] | None = None, inputs: list[str] | None = None) -> System:
    """The n-leg walker with input law ``law``. ``feet`` and ``inputs`` rename the constraints
    and the inputs (u_1..u_n, u_body by default): the biped is this walker with n = 2."""
    if not isinstance(n, int) or n < 1:
        raise SystemDescriptionError(f"walker: n must be an integer >= 1, got {n!r}")
    if law not in LAWS:
        raise SystemDescriptionError(f"walker: law must be one of {', '.join(LAWS)}, got {law!r}")
    feet = feet or [f"foot{i + 1}" for i in range(n)]
    inputs = inputs or [*(f"u{i + 1}" for i in range(n)), "u_body"]
    coords = ["x", "z", "th"] + [c for i in range(n) for c in (f"x{i + 1}", f"z{i + 1}")]
    s = System(name or f"walker{n}_{law}", coords, parameters=PARAMETERS, inputs=inputs,
               s="th0")
    p, u = s.p, list(s.u)
    x, z, th = s.q[:3]
    dx, dz, dth = s.dq[:3]
    s.mass_matrix = sp.diag(p.mb, p.mb, p.Ib, *([p.mf] * (2 * n)))
    s.restitution = p.gamma
    offsets = hip_offsets(n)
    for i, foot in enumerate(feet):
        s.constraint(foot, s.q[4 + 2 * i])

    def forces(J: frozenset[str]) -> list[sp.Expr]:
        f = [sp.Integer(0)] * (3 + 2 * n)
        f[1] = -p.mb * p.g
        for i, si in enumerate(offsets):
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
    body = {s.q[1]: TOUCHDOWN_HEIGHT, s.q[2]: s.s}
    for i, si in enumerate(offsets):
        body[s.q[3 + 2 * i]] = si * p.w * sp.cos(s.s) + p.l0 * sp.sin(s.s)
        body[s.q[4 + 2 * i]] = TOUCHDOWN_HEIGHT + si * p.w * sp.sin(s.s) - p.l0 * sp.cos(s.s)
    s.maneuver("touchdown", initial=body, terminal=-dz, outcome=th, armed_after="touchdown",
               s_range=(-0.25, 0.25),
               description="fall from rest at z = 1 to the body's nadir after touchdown")
    stance = {s.q[1]: p.l0 - LIFTOFF_COMPRESSION, s.q[2]: s.s}
    for i, si in enumerate(offsets):
        stance[s.q[3 + 2 * i]] = si * p.w * sp.cos(s.s)
    s.maneuver("liftoff", initial=stance, mode=feet, terminal=dz, outcome=th, final_mode=(),
               s_range=(-0.3, 0.3),
               description="push off from rest on all feet to the body's apex in the air")
    _problems(s, feet, [str(v) for v in u])
    return s


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
