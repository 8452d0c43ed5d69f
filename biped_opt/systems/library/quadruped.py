"""A 3-D quadruped with point feet (SYSTEMS.md Sec. 3b): d = 20 coordinates, n = 4 feet.

The trunk is two rigid halves joined by a two-axis spine. The spine joint sits at (x, y, z); the
front half's orientation is yaw, pitch, roll (body-fixed Z, Y, X: URDF's rpy of the front half);
the rear half turns from the front one by ``spine_pitch`` about the front half's y axis, then by
``spine_yaw`` about the resulting z axis. Each half carries two legs at its outer end, a
lateral offset w either side. A leg has three hinges: abduction about the trunk half's x axis,
flexion about the abducted frame's y axis and the knee about the thigh's y axis; thigh and
shank are uniform rods that hang along -z, and a shank's far end is a point foot. So

    q = (x, y, z, yaw, pitch, roll, spine_pitch, spine_yaw,
         <leg>_abd, <leg>_hip, <leg>_knee for leg in fl, fr, rl, rr)

(front/rear, left/right; left is +y). The four constraints are the feet's heights. Every hinge
is a torsional spring (and damper, ``c``, 0 by default) toward the standing posture: abduction
0, hip flexion ``phi``, knee -2 ``phi``, spine straight; in that posture each foot sits right
below its hip, all four at the same depth. Gravity acts on every body; the ground is
frictionless and the impacts plastic (gamma = 0).

The kinematics come from ``sympy.physics.mechanics`` (frames and points); the ten rigid bodies
are declared as a tree (SYSTEMS.md Sec. 1a): each body's frame in its parent's, its centre and
inertia, so that M(q) (dense and configuration dependent) and the velocity products and weight
follow from the tree; the springs' and dampers' generalised forces are the applied forces (a
hinge angle's generalised force is the hinge torque). The declared energy takes the kinetic
part from ``sympy.physics.mechanics``'s own velocities, a path independent of the tree's.

Maneuver ``drop`` (s = ``th0``): the posed robot from rest with its feet ``drop`` above the
ground at roll th0 and pitch th0 / 2; in flight nothing but gravity acts on it (the springs sit
at rest), so it falls as one rigid body and at th0 = 0 all four feet land at once. It ends at
the spine joint's lowest point after the first touchdown (z' rises through 0); outcome: the
roll rate there.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import sympy as sp
from sympy.physics import mechanics as me

from biped_opt.systems.description import System

__all__ = ["quadruped", "LEGS", "PARAMETERS"]

#: the legs: front/rear and left/right (left is +y)
LEGS = ("fl", "fr", "rl", "rr")
#: default parameters (SI units): trunk halves' mass and size (half-length L from the spine to a
#: hip row, hips w either side), thigh and shank masses and lengths, rods' radius, hinge
#: stiffnesses and a common damping, the standing posture's hip flexion phi, gravity, the drop
#: height of the feet and the coefficient of restitution
PARAMETERS = {"m_trunk": 3.0, "L": 0.15, "w": 0.1, "h_trunk": 0.08, "m_thigh": 0.6,
              "m_shank": 0.3, "l1": 0.2, "l2": 0.2, "r_leg": 0.02, "k_spine": 60.0,
              "k_abd": 30.0, "k_hip": 30.0, "k_knee": 30.0, "c": 0.0, "phi": 0.6, "g": 9.81,
              "drop": 0.05, "gamma": 0.0}
BASE = ("x", "y", "z", "yaw", "pitch", "roll", "spine_pitch", "spine_yaw")
JOINTS = ("abd", "hip", "knee")
#: drawing sizes: the feet's radius, the legs' width
FOOT_RADIUS, LEG_WIDTH = 0.02, 0.025


def quadruped() -> System:
    """The quadruped (see the module docstring)."""
    coords = [*BASE, *(f"{leg}_{j}" for leg in LEGS for j in JOINTS)]
    s = System("quadruped", coords, parameters=PARAMETERS, s="th0")
    p = s.p
    s.restitution = p.gamma

    # -- kinematics, in sympy.physics.mechanics's dynamic symbols (named like the coordinates)
    q = me.dynamicsymbols(" ".join(coords))
    u = me.dynamicsymbols(" ".join(f"{c}_u" for c in coords))
    x, y, z, yaw, pitch, roll, spine_pitch, spine_yaw = q[:8]
    world = me.ReferenceFrame("N")
    front = me.ReferenceFrame("F")
    front.orient_body_fixed(world, (yaw, pitch, roll), "zyx")
    bent = front.orientnew("S", "Axis", (spine_pitch, front.y))
    rear = bent.orientnew("R", "Axis", (spine_yaw, bent.z))
    origin = me.Point("O")
    origin.set_vel(world, 0)
    spine = origin.locatenew("P", x * world.x + y * world.y + z * world.z)
    spine.set_vel(world, spine.pos_from(origin).dt(world))

    base_frames = {"front": front, "rear": rear}
    bodies = []
    # the tree: each body's parent, its frame's origin and its centre from that origin
    joints: dict[str, tuple[str | None, me.Point, me.Vector]] = {}

    def rod_inertia(frame: me.ReferenceFrame, mass: sp.Expr, length: sp.Expr) -> me.Dyadic:
        across = mass * length**2 / 12
        return me.inertia(frame, across, across, mass * p.r_leg**2 / 2)

    for half, sign in (("front", 1), ("rear", -1)):
        frame = base_frames[half]
        centre = spine.locatenew(f"{half}_c", sign * p.L / 2 * frame.x)
        centre.v2pt_theory(spine, world, frame)
        m = p.m_trunk
        inertia = me.inertia(frame, m * (p.w**2 * 4 + p.h_trunk**2) / 12,
                             m * (p.L**2 + p.h_trunk**2) / 12, m * (p.L**2 + p.w**2 * 4) / 12)
        bodies.append(me.RigidBody(f"{half}_trunk", centre, frame, m, (inertia, centre)))
        joints[f"{half}_trunk"] = (None if half == "front" else "front_trunk", spine,
                                   sign * p.L / 2 * frame.x)

    feet = {}
    hips = {}
    for i, leg in enumerate(LEGS):
        abd, hip, knee = q[8 + 3 * i: 11 + 3 * i]
        frame = front if leg[0] == "f" else rear
        along = 1 if leg[0] == "f" else -1
        side = 1 if leg[1] == "l" else -1
        hip_point = spine.locatenew(f"{leg}_hip", along * p.L * frame.x + side * p.w * frame.y)
        hip_point.v2pt_theory(spine, world, frame)
        abducted = frame.orientnew(f"{leg}_A", "Axis", (abd, frame.x))
        thigh = abducted.orientnew(f"{leg}_T", "Axis", (hip, abducted.y))
        shank = thigh.orientnew(f"{leg}_K", "Axis", (knee, thigh.y))
        thigh_c = hip_point.locatenew(f"{leg}_tc", -p.l1 / 2 * thigh.z)
        thigh_c.v2pt_theory(hip_point, world, thigh)
        knee_point = hip_point.locatenew(f"{leg}_knee", -p.l1 * thigh.z)
        knee_point.v2pt_theory(hip_point, world, thigh)
        shank_c = knee_point.locatenew(f"{leg}_sc", -p.l2 / 2 * shank.z)
        shank_c.v2pt_theory(knee_point, world, shank)
        foot = knee_point.locatenew(f"{leg}_foot", -p.l2 * shank.z)
        bodies.append(me.RigidBody(f"{leg}_thigh", thigh_c, thigh, p.m_thigh,
                                   (rod_inertia(thigh, p.m_thigh, p.l1), thigh_c)))
        bodies.append(me.RigidBody(f"{leg}_shank", shank_c, shank, p.m_shank,
                                   (rod_inertia(shank, p.m_shank, p.l2), shank_c)))
        hips[leg] = hip_point
        feet[leg] = (knee_point, foot)
        joints[f"{leg}_thigh"] = (f"{'front' if leg[0] == 'f' else 'rear'}_trunk", hip_point,
                                  -p.l1 / 2 * thigh.z)
        joints[f"{leg}_shank"] = (f"{leg}_thigh", knee_point, -p.l2 / 2 * shank.z)

    # -- the bodies: each one's centre and axes in the world, in the description's symbols
    t = me.dynamicsymbols._t
    plain = {**{qi.diff(t): v for qi, v in zip(q, s.dq)}, **dict(zip(u, s.dq)),
             **dict(zip(q, s.q))}

    def to_plain(expr: sp.Expr) -> sp.Expr:
        return sp.sympify(expr).xreplace(plain)

    # each body's frame in its parent's (the front half's in the world's): a free base, the
    # spine's two hinges, and each leg's abduction and hip (thigh), then knee (shank)
    frames = {body.name: (body.frame, joints[body.name][1]) for body in bodies}
    for body in bodies:  # (parents first)
        parent, point, centre = joints[body.name]
        up_frame, up_point = (world, origin) if parent is None else frames[parent]
        offset = point.pos_from(up_point).to_matrix(up_frame).applyfunc(to_plain)
        axes = up_frame.dcm(body.frame).applyfunc(to_plain)
        s.body(body.name, body.mass, parent=parent, position=offset, rotation=axes,
               centre=centre.to_matrix(body.frame).applyfunc(to_plain),
               inertia=body.inertia[0].to_matrix(body.frame))
    s.gravity = (0, 0, -p.g)
    rest = {"spine_pitch": 0, "spine_yaw": 0, "abd": 0, "hip": p.phi, "knee": -2 * p.phi}
    stiffness = {"spine_pitch": p.k_spine, "spine_yaw": p.k_spine, "abd": p.k_abd,
                 "hip": p.k_hip, "knee": p.k_knee}
    springs = []
    hinge_force = []
    for k, name in enumerate(coords):
        kind = name if k < 8 else name.split("_", 1)[1]
        if kind not in rest:
            hinge_force.append(sp.Integer(0))
            continue
        stretch = s.q[k] - rest[kind]
        springs.append(stiffness[kind] * stretch**2 / 2)
        hinge_force.append(-stiffness[kind] * stretch - p.c * s.dq[k])
    s.forces = lambda J: hinge_force

    # -- constraints, energy, maneuver, looks
    heights = {leg: to_plain(foot.pos_from(origin).dot(world.z)) for leg, (_k, foot) in
               feet.items()}

    def world_point(point: me.Point) -> tuple[sp.Expr, sp.Expr, sp.Expr]:
        r = point.pos_from(origin)
        return tuple(to_plain(r.dot(axis)) for axis in (world.x, world.y, world.z))

    for leg, (_knee, foot) in feet.items():
        s.constraint(f"{leg}_foot", heights[leg], at=world_point(foot))
    potential = sum(body.mass * p.g * to_plain(body.masscenter.pos_from(origin).dot(world.z))
                    for body in bodies)
    kinetic = to_plain(me.kinetic_energy(world, *bodies))
    s.energy = kinetic + potential + sum(springs)
    sq = dict(zip(coords, s.q))
    depth = (p.l1 + p.l2) * sp.cos(p.phi)
    initial = {sq["z"]: depth + p.drop, sq["roll"]: s.s, sq["pitch"]: s.s / 2}
    for leg in LEGS:
        initial[sq[f"{leg}_hip"]] = p.phi
        initial[sq[f"{leg}_knee"]] = -2 * p.phi
    s.maneuver("drop", initial=initial, terminal=-s.dq[2], outcome=s.dq[5],
               armed_after="touchdown", s_range=(-0.1, 0.1),
               description="from rest in the standing posture, feet `drop` above the ground, "
                           "roll th0 and pitch th0 / 2, to the spine's lowest point after the "
                           "first touchdown; outcome: the roll rate")
    _looks(s, world, base_frames, hips, feet, to_plain, world_point)
    return s


def _rpy(world: me.ReferenceFrame, frame: me.ReferenceFrame,
         to_plain: Callable[[Any], Any]) -> tuple[Any, Any, Any]:
    """Fixed-axis roll, pitch, yaw of ``frame`` in ``world`` (R = Rz(yaw) Ry(pitch) Rx(roll),
    the columns of R being the frame's axes in world components)."""
    r = world.dcm(frame).applyfunc(to_plain)
    return (sp.atan2(r[2, 1], r[2, 2]), sp.asin(-r[2, 0]), sp.atan2(r[1, 0], r[0, 0]))


def _looks(s: System, world: me.ReferenceFrame, frames: dict[str, me.ReferenceFrame],
           hips: dict[str, me.Point], feet: dict[str, tuple[me.Point, me.Point]],
           to_plain: Callable[[Any], Any], world_point: Callable[[me.Point], Any]) -> None:
    """How it looks (SYSTEMS.md Sec. 6): each trunk half a box in its own frame
    (``base_link``: the front half, ``rear_link``), each leg a line hip-knee-foot and each
    foot a ball in frame ``<leg>_foot``."""
    p = s.p
    sq = dict(zip(s.coordinate_names, s.q))
    for name, half, sign in (("base_link", "front", 1), ("rear_link", "rear", -1)):
        frame = frames[half]
        c = [sq["x"], sq["y"], sq["z"]]
        axis = world.dcm(frame).applyfunc(to_plain)[:, 0]
        roll, pitch, yaw = ((sq["roll"], sq["pitch"], sq["yaw"]) if half == "front"
                            else _rpy(world, frame, to_plain))
        s.frame(name, x=c[0] + sign * p.L / 2 * axis[0], y=c[1] + sign * p.L / 2 * axis[1],
                z=c[2] + sign * p.L / 2 * axis[2], roll=roll, pitch=pitch, yaw=yaw)
        s.box(f"{half}_trunk", name, (p.L, 2 * p.w + 0.04, p.h_trunk),
              color=(0.20, 0.45, 0.75))
    for leg in LEGS:
        knee, foot = feet[leg]
        fx, fy, fz = world_point(foot)
        s.frame(f"{leg}_foot", x=fx, y=fy, z=fz)
        s.sphere(f"{leg}_foot", f"{leg}_foot", FOOT_RADIUS, color=(0.15, 0.15, 0.15))
        s.line(f"{leg}_leg", [world_point(hips[leg]), world_point(knee), (fx, fy, fz)],
               width=LEG_WIDTH, color=(0.85, 0.40, 0.10))
