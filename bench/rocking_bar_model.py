"""The rocking bar of SYSTEMS.md Sec. 2, written from the specification for the comparator.

q = (x, z, th); a thin bar of mass m, half-length w, I = m (2w)^2 / 12, gravity g; its ends'
heights z - w sin th (left) and z + w sin th (right) are the constraints; frictionless impacts
with restitution gamma; an optional torque u_th in the air. Maneuver ``drop``: at rest, z = 1,
th = th0, until the first apex (z' falling through 0) after the first impact, in the air.
"""

from __future__ import annotations

import math

import numpy as np

ncon = 2
M, W, G, GAMMA = 1.0, 0.5, 1.0, 0.5
INERTIA = M * (2.0 * W) ** 2 / 12.0
SIDES = (-1.0, 1.0)


def initial_state(maneuver: str, s: float):
    assert maneuver == "drop"
    return [0.0, 1.0, float(s), 0.0, 0.0, 0.0], 0


def rhs(y, mode: int, u):
    torque = float(u[0]) if len(u) and mode == 0 else 0.0
    acc = [0.0, -G, torque / INERTIA]
    if mode:  # resting contacts (not reached by ``drop``: impacts separate with gamma > 0)
        raise NotImplementedError("the comparator simulates impacts only")
    return [y[3], y[4], y[5], *acc]


def jacobian(th: float):
    return np.array([[0.0, 1.0, s * W * math.cos(th)] for s in SIDES])


def contact_guards(y, mode: int, u):
    return tuple(y[1] + s * W * math.sin(y[2]) for s in SIDES)


def constraint_rates(y):
    return jacobian(y[2]) @ np.asarray(y[3:6])


def impact(y, mode: int):
    active = [j for j in range(2) if mode >> j & 1]
    da = jacobian(y[2])[active]
    minv = np.diag([1.0 / M, 1.0 / M, 1.0 / INERTIA])
    v = np.asarray(y[3:6])
    s = da @ minv @ da.T
    v_new = v - (1.0 + GAMMA) * minv @ da.T @ np.linalg.solve(s, da @ v)
    return [*y[:3], *v_new]


def terminal(maneuver: str, y) -> float:
    return y[4]


def armed_after_touchdown(maneuver: str) -> bool:
    return True


def final_mode(maneuver: str):
    return 0


def outcome(maneuver: str, y) -> float:
    return y[5]
