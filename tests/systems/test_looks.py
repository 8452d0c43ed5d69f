"""How a system looks (docs/SYSTEMS.md Sec. 6): declaring it, generating it, evaluating it.

The generated scene is checked end to end against closed forms written here from the geometry
(a pose is the body's coordinates; a hip is w along the body turned by th), not against the
description's own expressions. Tolerance 1e-12: the generated NumPy code evaluates the same
elementary functions, so only rounding separates it from the closed form.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import sympy as sp

from biped_opt.codegen.scene import render_scene
from biped_opt.record.cdr import compile_layout
from biped_opt.ros.interfaces import load_interfaces
from biped_opt.simulation.compiled import CompiledSystem
from biped_opt.simulation.scene import quaternions
from biped_opt.systems.description import System, SystemDescriptionError

TOL = 1e-12


def _bar() -> System:
    s = System("bar", ["x", "z", "th"], parameters={"w": 0.5})
    return s


@pytest.mark.parametrize("declare, message", [
    (lambda s: s.frame("world"), "frame 'world' is the fixed frame"),
    (lambda s: (s.frame("b"), s.frame("b")), "frame 'b' is given twice"),
    (lambda s: s.box("bx", "nowhere", (1, 1, 1)), "box 'bx': unknown frame 'nowhere'"),
    (lambda s: (s.frame("b"), s.box("bx", "b", (1, 1))), "box 'bx': size must be (x, y, z)"),
    (lambda s: s.line("l", [(0, 0, 0)]), "line 'l': needs at least two points, got 1"),
    (lambda s: (s.frame("b"), s.sphere("ball", "b", 0.1, color=(2, 0, 0))),
     "sphere 'ball': color must be 3 or 4 numbers in [0, 1]"),
    (lambda s: s.constraint("c", s.q[1], at=(0, 0)), "constraint 'c': at must be (x, y, z)"),
])
def test_a_wrong_look_is_a_clear_error(declare, message):
    with pytest.raises(SystemDescriptionError) as err:
        declare(_bar())
    assert message in str(err.value)


def test_sizes_may_not_depend_on_q_and_points_only_on_q_and_parameters():
    s = _bar()
    s.frame("b", x=s.q[0])
    s.box("bx", "b", (s.q[0], 1, 1))
    with pytest.raises(SystemDescriptionError, match="size: uses x, which is not a parameter"):
        render_scene(s)
    s = _bar()
    s.line("l", [(0, 0, 0), (s.dq[0], 0, 0)])
    with pytest.raises(SystemDescriptionError, match="uses x_dot, which is not a coordinate"):
        render_scene(s)


def test_quaternions_of_roll_pitch_yaw_match_the_rotation_matrix():
    # R = Rz(yaw) Ry(pitch) Rx(roll), built by hand, against the quaternion's matrix
    rng = np.random.default_rng(1)
    for r, p, y in rng.uniform(-3, 3, (20, 3)):
        cx, sx, cy, sy, cz, sz = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                                  math.cos(y), math.sin(y))
        rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
        ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
        rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
        qx, qy, qz, qw = quaternions(np.array([r, p, y]))
        from_q = np.array([
            [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
            [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
            [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]])
        np.testing.assert_allclose(from_q, rz @ ry @ rx, atol=TOL)


def test_the_biped_scene_matches_its_geometry_along_a_touchdown():
    compiled = CompiledSystem("biped")
    tr = compiled.simulate("touchdown", 0.1, (2.0, 0.5, 0.0), sample_dt=0.01)
    q = tr.samples[:, 1:8]
    params = compiled.parameters
    state = compiled.scene.evaluate(q, list(params.values()))
    x, z, th = q[:, 0], q[:, 1], q[:, 2]
    w = params["w"]
    assert compiled.scene.frames == ("base_link", "left_foot", "right_foot")
    np.testing.assert_allclose(state.positions[:, 0], np.c_[x, 0 * x, z], atol=TOL)
    np.testing.assert_allclose(state.quaternions[:, 0],
                               np.c_[0 * x, -np.sin(th / 2), 0 * x, np.cos(th / 2)], atol=TOL)
    for k, (hip, foot) in enumerate(((-1, 3), (1, 5))):
        feet = np.c_[q[:, foot], 0 * x, q[:, foot + 1]]
        np.testing.assert_allclose(state.positions[:, 1 + k], feet, atol=TOL)
        np.testing.assert_allclose(state.contacts[:, k], feet, atol=TOL)
        leg = state.points[("left_leg", "right_leg")[k]]
        np.testing.assert_allclose(leg[:, 0], np.c_[x + hip * w * np.cos(th), 0 * x,
                                                    z + hip * w * np.sin(th)], atol=TOL)
        np.testing.assert_allclose(leg[:, 1], feet, atol=TOL)
    np.testing.assert_allclose(state.normals, np.broadcast_to([0, 0, 1.0], state.normals.shape))
    # the body spans its hips plus its thickness: 2w + 0.06
    assert state.sizes["body"][0] == pytest.approx([2 * w + 0.06, 0.12, 0.06], abs=TOL)


def test_the_urdf_has_a_link_per_frame_on_floating_joints_with_the_visuals():
    compiled = CompiledSystem("rocking_bar")
    params = compiled.parameters
    root = ET.fromstring(compiled.scene.urdf(list(params.values()), np.zeros((1, 3))))
    assert root.tag == "robot" and root.get("name") == "rocking_bar"
    assert [link.get("name") for link in root.findall("link")] == ["world", "base_link"]
    (joint,) = root.findall("joint")
    assert joint.get("type") == "floating"
    assert joint.find("parent").get("link") == "world"
    assert joint.find("child").get("link") == "base_link"
    size = root.find("link[@name='base_link']/visual/geometry/box").get("size")
    assert [float(v) for v in size.split()] == pytest.approx([2 * params["w"], 0.08, 0.04])


def test_a_system_without_looks_has_an_empty_scene(tmp_path):
    s = System("plain", ["z"], parameters={"g": 1.0})
    s.mass_matrix = sp.Matrix([[1]])
    s.forces = [-s.p.g]
    s.constraint("floor", s.q[0])
    s.maneuver("drop", initial={s.q[0]: 1}, terminal=s.dq[0], outcome=s.q[0],
               armed_after="touchdown")
    compiled = CompiledSystem(s)
    assert compiled.scene.empty
    assert compiled.scene.evaluate(np.zeros((4, 1)), [1.0]).positions.shape == (4, 0, 3)


def test_a_sequence_of_messages_has_the_bytes_rosbags_writes():
    # a TFMessage of two transforms with other frame names than the scene's: the layout's
    # bytes against rosbags' own serializer, message for message
    ts = load_interfaces().typestore
    layout = compile_layout(ts, "tf2_msgs/msg/TFMessage",
                            {"transforms.0.header.frame_id": "map",
                             "transforms.0.child_frame_id": "odd",
                             "transforms.1.header.frame_id": "world",
                             "transforms.1.child_frame_id": "a_longer_name"},
                            {"transforms": 2})
    m = layout.empty(2)
    m["transforms.0.transform.translation.x"] = [1.5, -2.0]
    m["transforms.1.transform.rotation.w"] = [1.0, 0.5]
    m["transforms.1.header.stamp.nanosec"] = [7, 9]
    T = ts.types
    for k, data in enumerate(layout.serialize(m)):
        def tf(frame, child, x=0.0, w=0.0, ns=0):
            return T["geometry_msgs/msg/TransformStamped"](
                header=T["std_msgs/msg/Header"](
                    stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=ns), frame_id=frame),
                child_frame_id=child,
                transform=T["geometry_msgs/msg/Transform"](
                    translation=T["geometry_msgs/msg/Vector3"](x=x, y=0.0, z=0.0),
                    rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=w)))
        ref = T["tf2_msgs/msg/TFMessage"](transforms=[
            tf("map", "odd", x=[1.5, -2.0][k]),
            tf("world", "a_longer_name", w=[1.0, 0.5][k], ns=[7, 9][k])])
        assert data == bytes(ts.serialize_cdr(ref, "tf2_msgs/msg/TFMessage"))
