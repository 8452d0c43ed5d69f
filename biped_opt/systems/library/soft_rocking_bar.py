"""The rocking bar (SYSTEMS.md Sec. 2) with soft contacts of width ``eps``: a smoothed model.

The rigid bar's ends are unilateral constraints with impacts; which end lands first decides the
outcome, and the outcome jumps where the order changes. Here each end instead meets the ground
through a smooth penalty force along the vertical,

    f_j = k eps softplus(-a_j / eps) - c sigma(-a_j / eps) a_j',   k = m g w / eps^2,

with a_j the end's height (the rigid model's constraint), softplus(x) = log(1 + e^x) and
sigma(x) = 1 / (1 + e^-x). The stiffness makes the penetration at the drop's impact speed about
2 eps; the damping c = 2 zeta sqrt(k m_end), zeta = -ln(gamma) / sqrt(pi^2 + ln(gamma)^2), would
give a linear contact of that stiffness the rigid model's coefficient of restitution gamma for
one end landing alone (m_end = m I / (I + m w^2) = m / 4, the bar's mass seen at a level end).
This contact switches on over eps, so its restitution is not exactly gamma, and eps -> 0 does
not recover the rigid bar (the gradient study's finding: smoothing changes the problem). The
torque u_th, which the rigid model applies in the air only, is weighted by
sigma(a_left / eps) sigma(a_right / eps). No constraints, no events but the terminal one: the
whole maneuver is one smooth vector field.

The maneuver ends, as the rigid one, at the first apex after landing: its terminal guard z' is
armed only once z' > 0 (the kernel arms a guard when it leaves zero upward), so the fall from
rest does not end it. ``eps`` is a parameter: changing it does not recompile.
"""

from __future__ import annotations

import sympy as sp

from biped_opt.systems.description import System
from biped_opt.systems.library.rocking_bar import rocking_bar

__all__ = ["soft_rocking_bar", "EPS"]

#: default contact width (the bar's half-length is 0.5)
EPS = 0.01


def soft_rocking_bar() -> System:
    base = rocking_bar()
    s = System("rocking_bar_soft", base.coordinate_names,
               parameters={**base.defaults, "eps": EPS}, inputs=base.u.names(), s=str(base.s))
    m, w, g, eps, gamma = s.p.m, s.p.w, s.p.g, s.p.eps, s.p.gamma
    s.mass_matrix = base.mass_matrix
    q, dq = sp.Matrix(s.q), sp.Matrix(s.dq)
    k = m * g * w / eps**2
    zeta = -sp.log(gamma) / sp.sqrt(sp.pi**2 + sp.log(gamma) ** 2)
    inertia = base.mass_matrix[2, 2]
    c = 2 * zeta * sp.sqrt(k * m * inertia / (inertia + m * w**2))
    gravity = sp.Matrix([0, -m * g, 0])
    contact = sp.zeros(3, 1)
    air = sp.Integer(1)
    for a in base.constraints.values():
        da = sp.Matrix([a]).jacobian(q)  # the end's height gradient: its force's direction
        rate = (da * dq)[0]
        pressed = 1 / (1 + sp.exp(a / eps))  # sigma(-a / eps)
        force = k * eps * sp.log(1 + sp.exp(-a / eps)) - c * pressed * rate
        contact += da.T * force
        air *= 1 / (1 + sp.exp(-a / eps))  # sigma(a / eps)
    torque = sp.Matrix([0, 0, s.u.u_th * air])
    total = list(gravity + contact + torque)
    s.forces = lambda J: total
    (drop,) = base.maneuvers.values()
    x, z, th = s.q
    s.maneuver("drop", initial={z: 1, th: s.s}, terminal=s.dq[1], outcome=s.dq[2],
               s_range=drop.s_range,
               description="drop from rest at z = 1 onto soft ground, to the first apex after "
                           "landing")
    s.problems = dict(base.problems)
    return s
