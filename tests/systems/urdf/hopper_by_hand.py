# The hopper of hopper.urdf written by hand with the bodies API (the round trip of
# tests/systems/test_urdf.py): the same coordinates, parameters, inputs and contacts.
import sympy as sp

from biped_opt.systems import System, rotation_rpy, rotation_y

hop = System("hopper", ["base_x", "base_y", "base_z", "base_roll", "base_pitch", "base_yaw",
                        "left_hip", "right_hip"],
             parameters={"g": 9.81, "gamma": 0.0, "drop": 0.05, "kp": 12.08592, "kd": 0.0},
             inputs=["left_hip_effort", "right_hip_effort"])
x, y, z, roll, pitch, yaw, left, right = hop.q
p = hop.p
R = rotation_rpy(roll, pitch, yaw)
hop.body("body", 1.0, position=(x, y, z), rotation=R, inertia=(0.01, 0.01, 0.01))
legs = {"left": (left, 0.1), "right": (right, -0.1)}
for side, (angle, offset) in legs.items():
    hop.body(f"{side}_leg", 0.2, parent="body", position=(0, offset, 0),
             rotation=rotation_y(angle), centre=(0, 0, -0.1), inertia=(0.001, 0.001, 0.0001))
    foot = sp.Matrix([x, y, z]) + R * (sp.Matrix([0, offset, 0])
                                       + rotation_y(angle) * sp.Matrix([0, 0, -0.2]))
    hop.constraint(f"{side}_foot", foot[2] - 0.02)
hop.gravity = (0, 0, -p.g)
hop.restitution = p.gamma
efforts = list(hop.u)
hop.forces = [0] * 6 + [efforts[k] - p.kp * q - p.kd * hop.dq[6 + k]
                        for k, q in enumerate((left, right))]
hop.maneuver("drop", initial={z: 0.27}, terminal=-hop.dq[2], outcome=hop.dq[3],
             armed_after="touchdown")
SYSTEM = hop
