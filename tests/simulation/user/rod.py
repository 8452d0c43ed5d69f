# rod.py: a rod in the x-z plane bouncing on both ends, declared as a rigid body
#
# A thin rod (centre x, z; pitch th, turning its axis from x towards +z) of mass m, half-length
# w and radius of gyration kg about its centre, on frictionless ground at its two ends. Level
# (th = 0) it lands on both ends at once, every time, in one impact; tilted, the ends land in
# turn. A clock body (tau = t) ends every run at the time T. Maneuver drop: from rest at height
# h0, tilted by s.
import sympy as sp

from biped_opt.systems import System

rod = System("rod", ["x", "z", "th", "tau"], s="s",
             parameters={"m": 1.0, "w": 0.5, "kg": 0.3, "g": 1.0, "e": 1.0, "h0": 1.0,
                         "T": 10.0})
x, z, th, tau = rod.q
p = rod.p
# the rod's axes: its x along the rod, turned by th about the world's -y (x towards +z)
R = sp.Matrix([[sp.cos(th), 0, -sp.sin(th)], [0, 1, 0], [sp.sin(th), 0, sp.cos(th)]])
rod.body("rod", p.m, position=(x, 0, z), rotation=R,
         inertia=(p.m * p.kg**2 / 10, p.m * p.kg**2, p.m * p.kg**2))
rod.body("clock", 1, position=(tau, 0, 0))
rod.gravity = (0, 0, -p.g)
rod.restitution = p.e
for name, side in (("left", -1), ("right", 1)):
    end = sp.Matrix([x, 0, z]) + R * sp.Matrix([side * p.w, 0, 0])
    rod.constraint(name, end[2], at=tuple(end))
rod.maneuver("drop", initial={z: p.h0, th: rod.s, rod.dq[3]: 1}, terminal=p.T - tau,
             outcome=rod.dq[2], s_range=(-0.3, 0.3), max_events=200, horizon=100,
             description="dropped from rest at height h0 and tilt s, bouncing until t = T; "
                         "outcome the spin th'")
SYSTEM = rod
