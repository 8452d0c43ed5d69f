# table.py: a four-legged table dropped on frictionless ground
#
# A slab (half-sizes A, B, C, mass ms; its centre x, y, z and yaw, pitch, roll, R = Rz Ry Rx)
# and four legs, each a rigid body of its own fixed to the slab (no coordinate of its own): a
# thin uniform rod of mass ml and length L hanging from the slab's bottom at (+-lx, +-ly).
# The contacts are the legs' tips. Plastic (e = 0): dropped level (s = 0) the four tips land at
# once and the table stands; tilted by a roll s, two legs land first and it falls onto the other
# two. It may spin about the vertical (`spin`). A clock body (tau = t) ends every run at T.
import sympy as sp

from biped_opt.systems import System

table = System("table", ["x", "y", "z", "yaw", "pitch", "roll", "tau"], s="s",
               parameters={"ms": 2.0, "A": 0.5, "B": 0.35, "C": 0.03, "ml": 0.15,
                           "L": 0.6, "lx": 0.42, "ly": 0.27, "g": 1.0, "e": 0.0,
                           "h0": 0.2, "spin": 0.0, "T": 4.0})
x, y, z, yaw, pitch, roll, tau = table.q
p = table.p
Rz = sp.Matrix([[sp.cos(yaw), -sp.sin(yaw), 0], [sp.sin(yaw), sp.cos(yaw), 0], [0, 0, 1]])
Ry = sp.Matrix([[sp.cos(pitch), 0, sp.sin(pitch)], [0, 1, 0], [-sp.sin(pitch), 0, sp.cos(pitch)]])
Rx = sp.Matrix([[1, 0, 0], [0, sp.cos(roll), -sp.sin(roll)], [0, sp.sin(roll), sp.cos(roll)]])
R = Rz * Ry * Rx
table.body("slab", p.ms, position=(x, y, z), rotation=R,
           inertia=(p.ms * (p.B**2 + p.C**2) / 3, p.ms * (p.A**2 + p.C**2) / 3,
                    p.ms * (p.A**2 + p.B**2) / 3))
legs = (("fl", 1, 1), ("fr", 1, -1), ("rl", -1, 1), ("rr", -1, -1))
for name, sx, sy in legs:
    # the leg's frame at its top, fixed to the slab; its centre of mass half-way down
    table.body(f"leg_{name}", p.ml, parent="slab", position=(sx * p.lx, sy * p.ly, -p.C),
               centre=(0, 0, -p.L / 2), inertia=(p.ml * p.L**2 / 12, p.ml * p.L**2 / 12, 0))
table.body("clock", 1, position=(tau, 0, 0))
table.gravity = (0, 0, -p.g)
table.restitution = p.e
for name, sx, sy in legs:
    tip = sp.Matrix([x, y, z]) + R * sp.Matrix([sx * p.lx, sy * p.ly, -p.C - p.L])
    table.constraint(name, tip[2], at=tuple(tip))
table.maneuver("drop", initial={z: p.h0 + p.C + p.L, roll: table.s, table.dq[3]: p.spin,
                                table.dq[6]: 1},
               terminal=p.T - tau, outcome=table.dq[3], s_range=(-0.3, 0.3), max_events=50,
               horizon=100,
               description="dropped from rest, its tips h0 above the ground when level, rolled "
                           "by s and spinning; outcome the yaw rate at t = T")
SYSTEM = table
