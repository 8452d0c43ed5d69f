# flat_biped.py: the paper's biped with flat feet
#
# MODEL.md Sec. 2's biped (body x, z, pitch th; two feet of mass mf on massless spring legs;
# inputs u1, u2 pushing along a leg in single stance, u12 turning the body in double stance)
# whose feet are flat horizontal soles instead of points: `corners` points (x_i + c l, z_i),
# c evenly spaced in [-1, 1], each a constraint of its own. A sole does not turn, so its corners
# touch down and lift off together and their rows of Da are the same row: dependent contacts,
# two (or four) per foot. A foot is on the ground when any of its corners is in the contact
# mode, and the input law reads the feet, not the corners: u1 acts iff the left foot alone is
# down, u2 iff the right alone, u12 iff both. Its motion is the point-foot biped's.
import sympy as sp

from biped_opt.systems import System


def make_system(corners: int = 2) -> System:
    names = {"left": [], "right": []}
    s = System(f"flat_biped{corners}", ["x", "z", "th", "x1", "z1", "x2", "z2"], s="th0",
               parameters={"mb": 1.0, "Ib": 0.5, "mf": 1.0, "g": 1.0, "l0": 0.5, "w": 0.25,
                           "k": 27.0, "c": 0.0, "gamma": 0.0, "sole": 0.06},
               inputs=["u1", "u2", "u12"])
    p = s.p
    x, z, th, x1, z1, x2, z2 = s.q
    dx, dz, dth, dx1, dz1, dx2, dz2 = s.dq
    s.mass_matrix = sp.diag(p.mb, p.mb, p.Ib, p.mf, p.mf, p.mf, p.mf)
    s.restitution = p.gamma
    feet = (("left", -1, x1, z1, dx1, dz1), ("right", 1, x2, z2, dx2, dz2))
    for foot, _side, xf, zf, _dxf, _dzf in feet:
        for k in range(corners):
            c = sp.Rational(2 * k, corners - 1) - 1
            name = f"{foot}{k + 1}"
            names[foot].append(name)
            s.constraint(name, zf, at=(xf + c * p.sole, 0, zf))

    def down(J, foot):
        return any(name in J for name in names[foot])

    def forces(J):
        left, right = down(J, "left"), down(J, "right")
        f = [0, -p.mb * p.g, 0, 0, 0, 0, 0]
        for i, (foot, side, xf, zf, dxf, dzf) in enumerate(feet):
            hx, hz = x + side * p.w * sp.cos(th), z + side * p.w * sp.sin(th)
            dhx = dx - side * p.w * sp.sin(th) * dth
            dhz = dz + side * p.w * sp.cos(th) * dth
            length = sp.sqrt((hx - xf) ** 2 + (hz - zf) ** 2)
            nx, nz = (hx - xf) / length, (hz - zf) / length
            rate = nx * (dhx - dxf) + nz * (dhz - dzf)
            alone = left and not right if foot == "left" else right and not left
            push = list(s.u)[i] if alone else 0
            F = p.k * (p.l0 - length) - p.c * rate + push
            f[0] += F * nx
            f[1] += F * nz
            f[2] += side * p.w * (sp.cos(th) * nz - sp.sin(th) * nx) * F
            f[3 + 2 * i] = -F * nx
            f[4 + 2 * i] = -F * nz - p.mf * p.g
        if left and right:
            f[2] += s.u.u12
        return f

    s.forces = forces
    # MODEL.md Sec. 4's maneuvers
    drop = {z: 1, th: s.s}
    stand = {z: p.l0 - sp.Rational(15, 100), th: s.s}
    for _foot, side, xf, zf, _dxf, _dzf in feet:
        drop[xf] = side * p.w * sp.cos(s.s) + p.l0 * sp.sin(s.s)
        drop[zf] = 1 + side * p.w * sp.sin(s.s) - p.l0 * sp.cos(s.s)
        stand[xf] = side * p.w * sp.cos(s.s)
    s.maneuver("touchdown", initial=drop, terminal=-dz, outcome=th, armed_after="touchdown",
               s_range=(-0.25, 0.25),
               description="fall from rest at z = 1 to the body's nadir after touchdown")
    s.maneuver("liftoff", initial=stand, mode=names["left"] + names["right"], terminal=dz,
               outcome=th, final_mode=(), s_range=(-0.3, 0.3),
               description="push off from rest on both soles to the body's apex in the air")
    return s
