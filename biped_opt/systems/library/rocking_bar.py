"""The rocking bar (SYSTEMS.md Sec. 2): inertial coupling gives jumps.

A thin rigid bar (mass m, half-length w, I = m (2w)^2 / 12) dropped from rest at height 1 and
pitch s onto frictionless ground with restitution gamma; its ends are the constraints. The
maneuver ends at the first apex after the first impact; its outcome is the pitch rate there.
"""

from __future__ import annotations

import sympy as sp

from biped_opt.systems.description import System

__all__ = ["rocking_bar"]


def rocking_bar() -> System:
    s = System("rocking_bar", ["x", "z", "th"],
               parameters={"m": 1.0, "w": 0.5, "g": 1.0, "gamma": 0.5}, inputs=["u_th"],
               s="th0")
    x, z, th = s.q
    m, w, g = s.p.m, s.p.w, s.p.g
    s.mass_matrix = sp.diag(m, m, m * (2 * w) ** 2 / 12)
    s.restitution = s.p.gamma
    # (the ends, for drawing: the left one at -w along the bar, which pitch th turns upwards)
    s.constraint("left", z - w * sp.sin(th), at=(x - w * sp.cos(th), 0, z - w * sp.sin(th)))
    s.constraint("right", z + w * sp.sin(th), at=(x + w * sp.cos(th), 0, z + w * sp.sin(th)))
    s.frame("base_link", x=x, z=z, pitch=-th)  # (a ROS pitch turns x towards -z)
    s.box("bar", "base_link", (2 * w, 0.08, 0.04), color=(0.20, 0.45, 0.75))
    s.forces = lambda J: [0, -m * g, s.u.u_th if not J else 0]  # the torque acts in the air
    dq = sp.Matrix(s.dq)
    s.energy = (dq.T * s.mass_matrix * dq)[0, 0] / 2 + m * g * z
    s.maneuver("drop", initial={z: 1, th: s.s}, terminal=s.dq[1], outcome=s.dq[2],
               armed_after="touchdown", final_mode=(), s_range=(-0.3, 0.3),
               description="drop from rest at z = 1 to the first apex after the first impact")
    s.problem("drop", maneuver="drop", decisions={"u_th": (-0.5, 0.5)}, weights={"u_th": 0.01},
              target=0.05)  # a spin to reach: the simultaneous impact's 0 is not a shortcut
    return s
