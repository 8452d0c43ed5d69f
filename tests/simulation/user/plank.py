# plank.py: a plank dropped at a tilt onto the ground, bouncing on its ends
#
# A rocking bar with its own names and parameters: mass mp, half-length half, radius of gyration
# kg about its centre (a plank heavier at its ends than a uniform bar), restitution e. Its ends
# are inertially coupled through the rotation, so the impacts alternate between them, and with
# little restitution the re-impacts of one end come closer and closer together.
import sympy as sp

from biped_opt.systems import System

plank = System("plank", ["px", "pz", "phi"], s="tilt",
               parameters={"mp": 2.0, "half": 0.7, "kg": 0.4, "grav": 1.0, "e": 0.35})
px, pz, phi = plank.q
mp, half, kg, grav = (plank.p[n] for n in ("mp", "half", "kg", "grav"))
plank.mass_matrix = sp.diag(mp, mp, mp * kg**2)
plank.forces = lambda J: [0, -mp * grav, 0]
plank.restitution = plank.p.e
plank.constraint("toe", pz - half * sp.sin(phi))
plank.constraint("heel", pz + half * sp.sin(phi))
plank.maneuver("fall", initial={pz: 1, phi: plank.s}, terminal=plank.dq[1],
               armed_after="touchdown", final_mode=(), outcome=plank.dq[2],
               s_range=(-0.4, 0.4),
               description="from rest at height 1 and tilt s to the first apex after the "
                           "first impact; outcome the spin phi' there")
SYSTEM = plank
