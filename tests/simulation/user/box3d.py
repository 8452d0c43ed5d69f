# box3d.py: a rectangular box on frictionless ground, resting on (or bouncing off) its corners
#
# A free rigid body (centre x, y, z; yaw, pitch and roll, R = Rz(yaw) Ry(pitch) Rx(roll)) of
# half-edges a, b, c, its four bottom corners (+-a, +-b, -c in its axes) the constraints. A
# second body, a "clock" sliding freely along x with unit speed, carries tau = t, so that the
# terminal guard T - tau ends every run at the time T whatever the box does. Maneuvers:
#
# - edge: dropped from rest at centre height h0, pitched by s: the two corners of the lower edge
#   land together (mirror symmetry in y), and with restitution the box rocks from edge to edge;
# - flat: dropped from rest with its bottom h0 above the ground, rolled by s and spinning about
#   the vertical at the rate `spin`: at s = 0 all four corners land at once (their rows of Da are
#   dependent: a flat face has rank 3);
# - tumble: thrown spinning (roll s, pitch 0.3, rates wr, wp, wy): it lands corner by corner.
import sympy as sp

from biped_opt.systems import System

box = System("box3d", ["x", "y", "z", "yaw", "pitch", "roll", "tau"], s="s",
             parameters={"m": 1.0, "a": 0.4, "b": 0.25, "c": 0.15, "g": 1.0, "e": 0.0,
                         "h0": 0.3, "T": 5.0, "spin": 0.0, "wr": 0.7, "wp": -0.4, "wy": 1.3})
x, y, z, yaw, pitch, roll, tau = box.q
dx, dy, dz, dyaw, dpitch, droll, dtau = box.dq
p = box.p
Rz = sp.Matrix([[sp.cos(yaw), -sp.sin(yaw), 0], [sp.sin(yaw), sp.cos(yaw), 0], [0, 0, 1]])
Ry = sp.Matrix([[sp.cos(pitch), 0, sp.sin(pitch)], [0, 1, 0], [-sp.sin(pitch), 0, sp.cos(pitch)]])
Rx = sp.Matrix([[1, 0, 0], [0, sp.cos(roll), -sp.sin(roll)], [0, sp.sin(roll), sp.cos(roll)]])
R = Rz * Ry * Rx
# a solid box of edges 2a, 2b, 2c: I = m ((2b)^2 + (2c)^2) / 12, ...
box.body("box", p.m, position=(x, y, z), rotation=R,
         inertia=(p.m * (p.b**2 + p.c**2) / 3, p.m * (p.a**2 + p.c**2) / 3,
                  p.m * (p.a**2 + p.b**2) / 3))
box.body("clock", 1, position=(tau, 0, 0))
box.gravity = (0, 0, -p.g)
box.restitution = p.e
for name, sx, sy in (("fl", 1, 1), ("fr", 1, -1), ("rl", -1, 1), ("rr", -1, -1)):
    corner = sp.Matrix([x, y, z]) + R * sp.Matrix([sx * p.a, sy * p.b, -p.c])
    box.constraint(name, corner[2], at=tuple(corner))
box.maneuver("edge", initial={z: p.h0, pitch: box.s, dtau: 1}, terminal=p.T - tau,
             outcome=dpitch, s_range=(-0.5, 0.5), max_events=200, horizon=100,
             description="dropped pitched by s: bounces on its edges until t = T; outcome the "
                         "pitch rate")
box.maneuver("flat", initial={z: p.h0 + p.c, roll: box.s, dyaw: p.spin, dtau: 1},
             terminal=p.T - tau, outcome=dyaw, s_range=(-0.5, 0.5), max_events=200,
             horizon=100,
             description="dropped rolled by s, spinning about the vertical: lands flat at s = 0; "
                         "outcome the yaw rate at t = T")
box.maneuver("tumble", initial={z: p.h0 + p.a, roll: box.s, pitch: 0.3, droll: p.wr,
                                dpitch: p.wp, dyaw: p.wy, dtau: 1},
             terminal=p.T - tau, outcome=dyaw, s_range=(-0.5, 0.5), max_events=200,
             horizon=100,
             description="thrown spinning: lands corner by corner; outcome the yaw rate at t = T")
SYSTEM = box
