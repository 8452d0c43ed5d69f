"""The n-leg walker of SYSTEMS.md Sec. 3, written from the specification for the comparator.

Body (mass mb, pitch inertia Ib) with hips at body-frame offsets s_i w, s_i evenly spaced in
[-1, 1]; massless spring-damper legs F_i = k (l0 - L_i) - c L_i' + ubar_i pushing hip and foot
apart; point feet of mass mf; q = (x, z, th, x_1, z_1, ..., x_n, z_n); constraints z_i >= 0.
A foot on the ground has z_i'' = 0, held by lambda_i = mf g + F_i n_iz, and slides freely in x.
Input laws: ``coupled`` (u_i acts iff foot i alone is down, u_body iff all are) and
``decoupled`` (u_i iff foot i is down, u_body never). Plastic touchdown (gamma = 0).
"""

from __future__ import annotations

import math

MB, IB, MF, G, L0, W, K, C = 1.0, 0.5, 1.0, 1.0, 0.5, 0.25, 27.0, 0.0
TOUCHDOWN_HEIGHT = 1.0
LIFTOFF_COMPRESSION = 0.15


class Walker:
    def __init__(self, n: int = 3, law: str = "coupled") -> None:
        self.n = self.ncon = n
        self.law = law
        self.sides = [0.0] if n == 1 else [2.0 * i / (n - 1) - 1.0 for i in range(n)]
        self.d = 3 + 2 * n

    def initial_state(self, maneuver: str, s: float):
        th = float(s)
        y = [0.0] * (2 * self.d)
        y[2] = th
        ct, st = math.cos(th), math.sin(th)
        if maneuver == "touchdown":
            y[1] = TOUCHDOWN_HEIGHT
            for i, si in enumerate(self.sides):
                y[3 + 2 * i] = si * W * ct + L0 * st
                y[4 + 2 * i] = TOUCHDOWN_HEIGHT + si * W * st - L0 * ct
            return y, 0
        y[1] = L0 - LIFTOFF_COMPRESSION
        for i, si in enumerate(self.sides):
            y[3 + 2 * i] = si * W * ct
        return y, (1 << self.n) - 1

    def _acting(self, i: int, mode: int) -> bool:
        if self.law == "coupled":
            return mode == 1 << i
        return bool(mode >> i & 1)

    def legs(self, y, mode: int, u):
        """Per leg: (F_i, n_ix, n_iz, r_ix, r_iz) with r_i the hip's offset from the body."""
        d = self.d
        x, z, th = y[0], y[1], y[2]
        vx, vz, vth = y[d], y[d + 1], y[d + 2]
        ct, st = math.cos(th), math.sin(th)
        out = []
        for i, si in enumerate(self.sides):
            rx, rz = si * W * ct, si * W * st
            ex, ez = x + rx - y[3 + 2 * i], z + rz - y[4 + 2 * i]
            length = math.hypot(ex, ez)
            nx, nz = ex / length, ez / length
            rate = nx * (vx - rz * vth - y[d + 3 + 2 * i]) + nz * (vz + rx * vth - y[d + 4 + 2 * i])
            force = K * (L0 - length) - C * rate
            if self._acting(i, mode):
                force += u[i]
            out.append((force, nx, nz, rx, rz))
        return out

    def rhs(self, y, mode: int, u):
        d = self.d
        fx, fz, torque = 0.0, -MB * G, 0.0
        acc_feet = []
        for i, (force, nx, nz, rx, rz) in enumerate(self.legs(y, mode, u)):
            fx += force * nx
            fz += force * nz
            torque += (rx * nz - rz * nx) * force
            down = mode >> i & 1
            acc_feet += [-force * nx / MF, 0.0 if down else (-force * nz - MF * G) / MF]
        if self.law == "coupled" and mode == (1 << self.n) - 1:
            torque += u[self.n]
        return [*y[d:], fx / MB, fz / MB, torque / IB, *acc_feet]

    def contact_guards(self, y, mode: int, u):
        legs = self.legs(y, mode, u) if mode else None
        return tuple(MF * G + legs[i][0] * legs[i][2] if mode >> i & 1 else y[4 + 2 * i]
                     for i in range(self.n))

    def constraint_rates(self, y):
        return [y[self.d + 4 + 2 * i] for i in range(self.n)]

    def impact(self, y, mode: int):
        out = list(y)
        for i in range(self.n):
            if mode >> i & 1:
                out[self.d + 4 + 2 * i] = 0.0  # plastic: the foot's vertical velocity stops
        return out

    def terminal(self, maneuver: str, y) -> float:
        return -y[self.d + 1] if maneuver == "touchdown" else y[self.d + 1]

    def armed_after_touchdown(self, maneuver: str) -> bool:
        return maneuver == "touchdown"

    def final_mode(self, maneuver: str):
        return None if maneuver == "touchdown" else 0

    def outcome(self, maneuver: str, y) -> float:
        return y[2]
