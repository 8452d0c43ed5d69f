# chain.py: a planar three-link chain dropped at a tilt, its outer links on spring hinges
#
# A middle link (centre x, z, pitch th) with an outer link hinged at each end; each hinge's
# angle is relative to the middle link (a1, a2), as the angles a motor or a spring sees, so an
# outer link's pitch is th + a_i. Torsional springs hold the hinges near +-rest; the outer ends
# are feet that bounce on the ground. The mass matrix follows from the kinetic energy (full and
# configuration-dependent), the forces from Lagrange's equations.
import sympy as sp

from biped_opt.systems import System

chain = System("chain", ["x", "z", "th", "a1", "a2"], s="tilt", restitution=0.6,
               parameters={"mb": 1.0, "ml": 0.5, "lb": 0.3, "leg": 0.5, "k": 20.0,
                           "rest": 0.9, "g": 1.0})
q, dq = sp.Matrix(chain.q), sp.Matrix(chain.dq)
x, z, th, a1, a2 = chain.q
mb, ml, lb, leg, k, rest, g = (chain.p[n] for n in ("mb", "ml", "lb", "leg", "k", "rest", "g"))

hinge1 = sp.Matrix([x - lb * sp.cos(th), z - lb * sp.sin(th)])
hinge2 = sp.Matrix([x + lb * sp.cos(th), z + lb * sp.sin(th)])
out1 = -sp.Matrix([sp.cos(th + a1), sp.sin(th + a1)])  # along the left link, outwards
out2 = sp.Matrix([sp.cos(th + a2), sp.sin(th + a2)])
centres = [sp.Matrix([x, z]), hinge1 + leg / 2 * out1, hinge2 + leg / 2 * out2]
feet = [hinge1 + leg * out1, hinge2 + leg * out2]
masses = [mb, ml, ml]
inertias = [mb * (2 * lb) ** 2 / 12, ml * leg**2 / 12, ml * leg**2 / 12]
spins = [chain.dq[2], chain.dq[2] + chain.dq[3], chain.dq[2] + chain.dq[4]]

T = sum(m / 2 * ((c.jacobian(q) * dq).T * (c.jacobian(q) * dq))[0] + i / 2 * w**2
        for m, c, i, w in zip(masses, centres, inertias, spins))
V = sum(m * g * c[1] for m, c in zip(masses, centres)) \
    + k / 2 * (a1 - rest) ** 2 + k / 2 * (a2 + rest) ** 2
M = sp.hessian(T, chain.dq)
chain.mass_matrix = M
momentum = M * dq
lagrange = (sp.Matrix([T]).jacobian(q).T - momentum.jacobian(q) * dq
            - sp.Matrix([V]).jacobian(q).T)
chain.forces = lambda J: lagrange
chain.constraint("foot1", feet[0][1])
chain.constraint("foot2", feet[1][1])
chain.maneuver("drop", initial={z: 1.2, th: chain.s, a1: rest + 0.25, a2: -rest - 0.25},
               terminal=chain.dq[1], armed_after="touchdown", final_mode=(),
               outcome=chain.dq[2], s_range=(-0.2, 0.2),
               description="from rest at height 1.2 and pitch s, hinges spread beyond rest, "
                           "to the middle link's first apex after the first impact")
SYSTEM = chain
