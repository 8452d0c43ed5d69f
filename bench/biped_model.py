"""The sagittal-plane biped of [1]_ Fig. 1, re-implemented from MODEL.md for the comparators.

Deliberately independent of biped_opt: the benchmark's
accuracy figures compare two implementations, not one with itself. Scalar ``math`` on Python
floats (the state has 14 entries; numpy's per-call overhead would dominate).

State y = (q, q'), q = (x, z, th, x1, z1, x2, z2); contact mode J is a bit mask (bit 0 = left
foot, constraint 1; bit 1 = right foot, constraint 2), so AIR = 0, LEFT = 1, RIGHT = 2, GROUND = 3.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from biped_opt.errors import BipedOptError

__all__ = [
    "AIR",
    "LEFT",
    "RIGHT",
    "GROUND",
    "MODE_NAMES",
    "ComparatorError",
    "Params",
    "MANEUVERS",
    "initial_state",
    "leg_forces",
    "rhs",
    "reactions",
    "contact_guards",
    "apply_touchdown",
]

AIR, LEFT, RIGHT, GROUND = 0, 1, 2, 3
MODE_NAMES = {AIR: "AIR", LEFT: "LEFT", RIGHT: "RIGHT", GROUND: "GROUND"}
#: side s_j of leg j: left -1, right +1
SIDES = (-1.0, 1.0)
#: the two maneuvers of [1]_ Sec. IV
MANEUVERS = ("touchdown", "liftoff")
#: initial body height of the touchdown maneuver [length]
TOUCHDOWN_HEIGHT = 1.0
#: initial leg compression of the liftoff maneuver [length]
LIFTOFF_COMPRESSION = 0.15


class ComparatorError(BipedOptError, RuntimeError):
    """A comparator simulation did not reach its terminal event (horizon, budget, contact)."""


@dataclass(frozen=True, kw_only=True)
class Params:
    """The paper's default parameters in gravity units (MODEL.md Sec. 2)."""

    mb: float = 1.0  # body mass [mass]
    Ib: float = 0.5  # body pitch inertia [mass length^2]
    mf: float = 1.0  # foot mass [mass]
    g: float = 1.0  # gravity [length / time^2]
    l0: float = 0.5  # leg rest length [length]
    w: float = 0.25  # half hip width [length]
    k: float = 27.0  # leg stiffness [force / length]
    c: float = 0.0  # leg damping [force time / length]
    gamma: float = 0.0  # restitution at touchdown [-]


DEFAULT_PARAMS = Params()


def initial_state(maneuver: str, theta0: float, p: Params = DEFAULT_PARAMS) -> tuple[list, int]:
    """Initial state and mode of a maneuver (MODEL.md Sec. 4)."""
    th = float(theta0)
    ct, st = math.cos(th), math.sin(th)
    y = [0.0] * 14
    y[2] = th
    if maneuver == "touchdown":
        # at rest, legs at rest length and perpendicular to the body: foot = body + R(th)(s w, -l0)
        y[1] = TOUCHDOWN_HEIGHT
        for j, s in enumerate(SIDES):
            y[3 + 2 * j] = s * p.w * ct + p.l0 * st
            y[4 + 2 * j] = TOUCHDOWN_HEIGHT + s * p.w * st - p.l0 * ct
        return y, AIR
    if maneuver == "liftoff":
        # at rest in double stance, vertical compressed legs, feet on the ground below the hips
        y[1] = p.l0 - LIFTOFF_COMPRESSION
        for j, s in enumerate(SIDES):
            y[3 + 2 * j] = s * p.w * ct
        return y, GROUND
    raise ValueError(f"maneuver must be one of {MANEUVERS}, got {maneuver!r}")


def leg_forces(y, mode: int, u1: float, u2: float, p: Params = DEFAULT_PARAMS):
    """(F1, n1x, n1z, F2, n2x, n2z): scalar leg forces and leg unit vectors (hip minus foot).

    F_j = k (l0 - L_j) - c L_j' + ubar_j(J); ubar_1 = u1 only in LEFT, ubar_2 = u2 only in RIGHT
    (the force coupling of [1]_ Sec. II-B).
    """
    x, z, th = y[0], y[1], y[2]
    vx, vz, vth = y[7], y[8], y[9]
    ct, st = math.cos(th), math.sin(th)
    out = []
    for j, s in enumerate(SIDES):
        ex = x + s * p.w * ct - y[3 + 2 * j]
        ez = z + s * p.w * st - y[4 + 2 * j]
        length = math.hypot(ex, ez)
        nx, nz = ex / length, ez / length
        rate = nx * (vx - s * p.w * st * vth - y[10 + 2 * j]) + nz * (
            vz + s * p.w * ct * vth - y[11 + 2 * j]
        )
        force = p.k * (p.l0 - length) - p.c * rate
        if j == 0 and mode == LEFT:
            force += u1
        elif j == 1 and mode == RIGHT:
            force += u2
        out.extend((force, nx, nz))
    return out


def rhs(y, mode: int, u, p: Params = DEFAULT_PARAMS) -> list:
    """y' of Eq. (1a) in mode J; feet in contact have z_j'' = 0 (lambda_j holds them up)."""
    u1, u2, u12 = u
    f1, n1x, n1z, f2, n2x, n2z = leg_forces(y, mode, u1, u2, p)
    th = y[2]
    ct, st = math.cos(th), math.sin(th)
    torque = p.w * (-(ct * n1z - st * n1x) * f1 + (ct * n2z - st * n2x) * f2)
    if mode == GROUND:
        torque += u12
    az1 = 0.0 if mode & 1 else (-f1 * n1z - p.mf * p.g) / p.mf
    az2 = 0.0 if mode & 2 else (-f2 * n2z - p.mf * p.g) / p.mf
    return [
        y[7], y[8], y[9], y[10], y[11], y[12], y[13],
        (f1 * n1x + f2 * n2x) / p.mb,
        (f1 * n1z + f2 * n2z - p.mb * p.g) / p.mb,
        torque / p.Ib,
        -f1 * n1x / p.mf,
        az1,
        -f2 * n2x / p.mf,
        az2,
    ]


def reactions(y, mode: int, u, p: Params = DEFAULT_PARAMS) -> tuple[float, float]:
    """Normal reactions lambda_j = mf g + F_j n_jz that keep z_j'' = 0 (Eq. (1a), a_j = z_j)."""
    f1, _, n1z, f2, _, n2z = leg_forces(y, mode, u[0], u[1], p)
    return p.mf * p.g + f1 * n1z, p.mf * p.g + f2 * n2z


def contact_guards(y, mode: int, u, p: Params = DEFAULT_PARAMS) -> tuple[float, float]:
    """Guard per foot (event: it falls through 0): z_j in the air, lambda_j on the ground."""
    lam = reactions(y, mode, u, p) if mode else (0.0, 0.0)
    return tuple(lam[j] if mode >> j & 1 else y[4 + 2 * j] for j in range(2))


def apply_touchdown(y, feet_mask: int, p: Params = DEFAULT_PARAMS) -> list:
    """Impact map Eq. (1b) for a_j = z_j and diagonal M: only z_j' jumps, to -gamma z_j'."""
    out = list(y)
    for j in range(2):
        if feet_mask >> j & 1:
            out[11 + 2 * j] = -p.gamma * out[11 + 2 * j]
    return out
