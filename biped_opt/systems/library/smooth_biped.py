"""The paper's biped with its input switch smoothed over a width ``eps`` of foot height.

The coupled law switches u_i on exactly when leg i alone is on the ground and u12 when both are;
that switch is what kinks the touchdown outcome and makes the liftoff outcome jump. Here each
input acts in every contact mode, weighted by a smooth function of the feet's heights a_j (the
constraint values) instead of the mode:

    u_i  weight (1 - phi(a_i)) * prod_{j != i} phi(a_j),     u12  weight prod_j (1 - phi(a_j)),

with phi(a) = tanh(a / eps) (0 on the ground, 1 well above it; a >= 0 on every trajectory). As
eps -> 0 the weights tend to the coupled law's indicators. ``eps`` is a parameter: changing it
does not recompile. Contacts and impacts are the biped's own (rigid); only the input law differs.
Everything else (coordinates, maneuvers, problems) is copied from :func:`biped`.
"""

from __future__ import annotations

import sympy as sp

from biped_opt.systems.description import System
from biped_opt.systems.library.biped import biped

__all__ = ["smooth_biped", "EPS"]

#: default switch width (foot height; the leg rest length is 0.5)
EPS = 0.01


def smooth_biped() -> System:
    base = biped()
    feet = list(base.constraints)
    names = base.u.names()  # u1, u2 (one per foot, in order), then u12
    s = System("biped_smooth", base.coordinate_names, parameters={**base.defaults, "eps": EPS},
               inputs=names, s=str(base.s))
    s.mass_matrix = base.mass_matrix
    s.restitution = base.restitution
    for foot in feet:
        s.constraint(foot, base.constraints[foot])
    s.maneuvers = dict(base.maneuvers)
    s.problems = dict(base.problems)
    phi = {foot: sp.tanh(base.constraints[foot] / s.p.eps) for foot in feet}
    u = list(base.u)
    # the direction of each input's generalised force, read off the mode where it acts
    acting = [frozenset({foot}) for foot in feet] + [frozenset(feet)]
    direction = [sp.Matrix(base.forces(mode)).diff(ui) for mode, ui in zip(acting, u)]
    weight = [(1 - phi[foot]) * sp.Mul(*(phi[f] for f in feet if f != foot)) for foot in feet]
    weight.append(sp.Mul(*(1 - phi[f] for f in feet)))
    off = {ui: 0 for ui in u}

    def forces(J: frozenset[str]) -> list[sp.Expr]:
        f = sp.Matrix(base.forces(J)).subs(off)
        for ui, w, e in zip(u, weight, direction):
            f += ui * w * e
        return list(f)

    s.forces = forces
    return s
