# corner.py: a point mass tossed into the corner between the floor and a wall leaning back by psi
#
# The wall passes through the origin and leans away from the mass by psi from the vertical, so
# its normal (cos psi, sin psi) is not orthogonal to the floor's (0, 1): the two constraints are
# inertially coupled and an impact on one changes the velocity along the other. Thrown
# horizontally from x = 1 at height s, the mass hits the corner itself at s = 25/72.
import sympy as sp

from biped_opt.systems import System

corner = System("corner", ["x", "z"], s="h0",
                parameters={"m": 1.0, "g": 1.0, "psi": 0.3, "e": 0.6, "vx": 1.2})
x, z = corner.q
m, g, psi, e, vx = (corner.p[n] for n in ("m", "g", "psi", "e", "vx"))
corner.mass_matrix = sp.diag(m, m)
corner.forces = lambda J: [0, -m * g]
corner.restitution = e
corner.constraint("floor", z)
corner.constraint("wall", x * sp.cos(psi) + z * sp.sin(psi))
corner.maneuver("toss", initial={x: 1, z: corner.s, corner.dq[0]: -vx},
                terminal=corner.dq[1], armed_after="touchdown", final_mode=(),
                outcome=corner.dq[0], s_range=(0.1, 0.8),
                description="thrown at the corner from height h0; ends at the first apex "
                            "after the first impact; outcome the horizontal velocity there")
SYSTEM = corner
