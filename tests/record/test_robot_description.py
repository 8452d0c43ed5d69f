"""A URDF in gives the same robot out (issue: URDF out and /joint_states).

For robots imported from a URDF, ``/robot_description`` carries the robot's own tree of joints,
``/joint_states`` its joint values and ``/tf`` only world -> base. Checked with parsers that are
not the importer's:

- the emitted URDF against the original file, both read with ElementTree here: the same joints
  (type, parent, child, origin, axis, limits, dynamics, mimic) and the same links' inertials,
  number for number (the writer prints each double as the shortest text that reads back as
  itself, so equality is exact);
- both files through Pinocchio's URDF parser: the same body inertias (fixed links merged as
  Pinocchio merges them) and joint placements;
- forward kinematics: each link's world pose from Pinocchio's model of the *emitted* URDF at
  the joint values and base pose read back from the CDR of ``/joint_states`` and ``/tf`` (a mimic
  joint's value from its ``<mimic>`` tag, as robot_state_publisher does) equals the system's own
  frame of that link (the generated scene code) to 1e-12.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")

from biped_opt.record.scene import JOINT_STATES_TOPIC, MARKERS_TOPIC, SceneMessages  # noqa: E402
from biped_opt.ros.interfaces import load_interfaces  # noqa: E402
from biped_opt.simulation.compiled import _import, _scene_for, cache_dir  # noqa: E402
from biped_opt.simulation.scene import Scene  # noqa: E402
from biped_opt.systems.library.robots import ROBOT_FILES, ROBOTS  # noqa: E402
from biped_opt.systems.urdf import system_from_urdf  # noqa: E402

HERE = Path(__file__).resolve().parents[1] / "systems" / "urdf"
#: (label, how to build it, its URDF): the library's point-footed quadruped and biped, the
#: humanoid with locked joints, and the test gripper (slider, skew axis, mimic, fixed links,
#: inertias off their origins and turned)
CASES = {
    "solo12": (ROBOTS["solo12"], ROBOT_FILES["solo12"]),
    "bolt": (ROBOTS["bolt"], ROBOT_FILES["bolt"]),
    "g1": (ROBOTS["g1"], ROBOT_FILES["g1"]),
    "gripper": (lambda: system_from_urdf(HERE / "gripper.urdf", contacts="base_link+tip"),
                HERE / "gripper.urdf"),
    "hopper_fixed": (lambda: system_from_urdf(HERE / "hopper.urdf", base="fixed"),
                     HERE / "hopper.urdf"),
}
#: exact arithmetic but for rounding: FK through ~10 joints and rpy <-> quaternion conversions
#: of O(1) numbers stays within a few hundred ulps of 1
FK_TOL = 1e-12


def _scene(system) -> Scene:
    facts = _scene_for(system)
    module = _import(facts["module"], cache_dir() / f"{facts['module']}.py")
    return Scene(system.name, facts, module.scene_values, tuple(system.constraints),
                 getattr(module, "tree_values", None))


@pytest.fixture(scope="module", params=list(CASES))
def robot(request):
    build, path = CASES[request.param]
    system = build()
    return system, _scene(system), path


def _numbers(e: ET.Element | None, key: str, default: str) -> list[float]:
    text = default if e is None else e.get(key, default)
    return [float(v) for v in text.split()]


def _joints(root: ET.Element) -> dict[str, dict]:
    out = {}
    for j in root.findall("joint"):
        limit, origin = j.find("limit"), j.find("origin")
        dyn, mimic = j.find("dynamics"), j.find("mimic")
        out[j.get("name")] = {
            "type": j.get("type"), "parent": j.find("parent").get("link"),
            "child": j.find("child").get("link"),
            "xyz": _numbers(origin, "xyz", "0 0 0"), "rpy": _numbers(origin, "rpy", "0 0 0"),
            "axis": _numbers(j.find("axis"), "xyz", "1 0 0"),
            "limit": {k: float(limit.get(k)) for k in ("lower", "upper", "effort", "velocity")
                      if limit is not None and limit.get(k) is not None},
            "damping": _numbers(dyn, "damping", "0")[0],
            "mimic": None if mimic is None else (mimic.get("joint"),
                                                 float(mimic.get("multiplier", "1")),
                                                 float(mimic.get("offset", "0")))}
    return out


def _inertials(root: ET.Element) -> dict[str, list[float] | None]:
    out = {}
    for link in root.findall("link"):
        i = link.find("inertial")
        if i is None:
            out[link.get("name")] = None
            continue
        t = i.find("inertia")
        out[link.get("name")] = [
            *_numbers(i.find("origin"), "xyz", "0 0 0"),
            *_numbers(i.find("origin"), "rpy", "0 0 0"),
            float(i.find("mass").get("value")),
            *(float(t.get(k, "0")) for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"))]
    return out


def test_the_emitted_urdf_has_the_input_s_joints_and_inertias(robot):
    system, scene, path = robot
    original = ET.parse(path).getroot()
    emitted = ET.fromstring(scene.urdf([], np.zeros((1, len(system.coordinate_names)))))
    a, b = _joints(original), _joints(emitted)
    dropped = {n for n, j in a.items() if j["parent"] == "world"}
    assert set(b) == set(a) - dropped
    axis_normalised = 0
    for name, j in b.items():
        ref = a[name]
        for key in ("type", "parent", "child", "xyz", "rpy", "damping"):
            assert j[key] == ref[key], (name, key)
        if j["type"] != "fixed":
            norm = math.sqrt(sum(v * v for v in ref["axis"]))
            assert j["axis"] == [v / norm for v in ref["axis"]] if norm != 1 else j["axis"] \
                == ref["axis"], name
            axis_normalised += norm != 1
            for k, v in ref["limit"].items():
                if j["type"] == "continuous" and k in ("lower", "upper"):
                    continue  # (a continuous joint has no position limits)
                assert j["limit"][k] == v, (name, k)
        # a mimic goes out as it came in where the follower moves with its leader
        if ref["mimic"] is not None and name in system.robot.mimic:
            assert j["mimic"] == ref["mimic"], name
        else:
            assert j["mimic"] is None
    assert _inertials(emitted) == {k: v for k, v in _inertials(original).items()
                                   if k != "world"}
    assert emitted.get("name") == system.name


def _model(text: str):
    return pin.buildModelFromXML(text)


def test_pinocchio_reads_the_same_bodies_from_both(robot):
    system, scene, path = robot
    original = path.read_text()
    emitted = scene.urdf([], np.zeros((1, len(system.coordinate_names))))
    m1, m2 = _model(original), _model(emitted)
    # (a root link 'world' with its joint to the base is left out of the emitted URDF: the
    # base's pose is on /tf; the joints below it are compared by name)
    names1 = {m1.names[i]: i for i in range(1, m1.njoints)}
    names2 = [m2.names[i] for i in range(1, m2.njoints)]
    assert set(names2) <= set(names1) and len(names1) - len(names2) <= 1
    for i, name in enumerate(names2, start=1):
        j = names1[name]
        # the same numbers through the same parser: equal up to its own arithmetic on them
        np.testing.assert_allclose(m2.inertias[i].toDynamicParameters(),
                                   m1.inertias[j].toDynamicParameters(), rtol=0, atol=1e-15)
        np.testing.assert_allclose(m2.jointPlacements[i].homogeneous,
                                   m1.jointPlacements[j].homogeneous, rtol=0, atol=1e-15)


def _quaternion_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _random_samples(d: int, nc: int, n: int, seed: int) -> np.ndarray:
    """``n`` sample rows (t, q, q', mode, lambda) with q and q' uniform in [-1, 1]."""
    rng = np.random.default_rng(seed)
    samples = np.zeros((n, 2 + 2 * d + nc))
    samples[:, 0] = np.arange(n) * 0.01
    samples[:, 1 : 1 + 2 * d] = rng.uniform(-1.0, 1.0, (n, 2 * d))
    return samples


def test_links_placed_from_joint_states_and_tf_are_the_system_s_frames(robot):
    system, scene, _path = robot
    typestore = load_interfaces().typestore
    d, nc = len(system.coordinate_names), len(system.constraints)
    messages = SceneMessages(typestore, scene, list(system.defaults.values()), d)
    n = 5
    samples = _random_samples(d, nc, n, 35)
    _stamps, out = messages.messages(samples, 0)
    assert set(out) == {"/clock", "/tf", MARKERS_TOPIC, JOINT_STATES_TOPIC}
    urdf = scene.urdf([], samples[:1, 1 : 1 + d])
    model = _model(urdf)
    data = model.createData()
    mimic = {name: j["mimic"] for name, j in _joints(ET.fromstring(urdf)).items() if j["mimic"]}
    links = [lk.get("name") for lk in ET.fromstring(urdf).findall("link")]
    own = scene.evaluate(samples[:, 1 : 1 + d], list(system.defaults.values()))
    checked = 0
    for k in range(n):
        js = typestore.deserialize_cdr(out[JOINT_STATES_TOPIC][k], "sensor_msgs/msg/JointState")
        (tf,) = typestore.deserialize_cdr(out["/tf"][k], "tf2_msgs/msg/TFMessage").transforms
        assert (tf.header.frame_id, tf.child_frame_id) == ("world", scene.base)
        values = dict(zip(js.name, js.position))
        assert len(js.velocity) == len(js.name) and len(js.effort) == 0
        for follower, (leader, mult, offset) in mimic.items():
            values[follower] = mult * values[leader] + offset
        q = pin.neutral(model)
        for i in range(1, model.njoints):
            joint = model.joints[i]
            value = values[model.names[i]]
            if joint.nq == 2:  # (continuous: cos, sin)
                q[joint.idx_q : joint.idx_q + 2] = math.cos(value), math.sin(value)
            else:
                q[joint.idx_q] = value
        pin.framesForwardKinematics(model, data, q)
        r = tf.transform.rotation
        R0 = _quaternion_matrix(r.x, r.y, r.z, r.w)
        p0 = np.array([tf.transform.translation.x, tf.transform.translation.y,
                       tf.transform.translation.z])
        for link in links:
            if link not in scene.frames:
                continue
            f = model.getFrameId(link, pin.BODY)
            placement = data.oMf[f]
            at = p0 + R0 @ placement.translation
            axes = R0 @ placement.rotation
            i = scene.frames.index(link)
            np.testing.assert_allclose(at, own.positions[k, i], rtol=0, atol=FK_TOL)
            np.testing.assert_allclose(axes, _quaternion_matrix(*own.quaternions[k, i]), rtol=0,
                                       atol=FK_TOL)
            checked += 1
    # every link of the emitted URDF is a frame of the system's, each checked at n samples
    assert checked == n * len(links)


def test_efforts_are_the_inputs_when_every_joint_has_one(robot):
    system, scene, _path = robot
    typestore = load_interfaces().typestore
    d, nc = len(system.coordinate_names), len(system.constraints)
    messages = SceneMessages(typestore, scene, list(system.defaults.values()), d)
    samples = np.zeros((1, 2 + 2 * d + nc))
    inputs = np.arange(1.0, 1 + len(system.u.names()))
    _stamps, out = messages.messages(samples, 0, inputs=inputs)
    js = typestore.deserialize_cdr(out[JOINT_STATES_TOPIC][0], "sensor_msgs/msg/JointState")
    named = dict(zip(system.u.names(), inputs))
    want = [named.get(system.robot.inputs.get(j)) for j in js.name]
    if None in want:  # (a locked joint has no effort input: efforts are left empty)
        assert len(js.effort) == 0
    else:
        assert list(js.effort) == want


def test_a_recording_carries_the_joint_states_that_mcap_ros2_decodes(robot, tmp_path):
    """MCAP.md's scene topics for a tree of joints: /joint_states among them, its schema
    sensor_msgs/msg/JointState, decoded by mcap-ros2-support (not the project's reader) to the
    values the system's coordinates give."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from biped_opt.record import SweepWriter

    system, scene, _path = robot
    d, nc = len(system.coordinate_names), len(system.constraints)
    path = tmp_path / "tree.mcap"
    rng = np.random.default_rng(36)
    samples = np.zeros((4, 2 + 2 * d + nc))
    samples[:, 0] = np.arange(4) * 0.02
    samples[:, 1 : 1 + 2 * d] = rng.uniform(-1.0, 1.0, (4, 2 * d))
    with SweepWriter(path, topics=("/biped/sweep",)
                     + tuple(SceneMessages(load_interfaces().typestore, scene, [], d).topics)
                     ) as writer:
        messages = SceneMessages(writer.typestore, scene, list(system.defaults.values()), d)
        writer.write_robot_description(messages)
        assert writer.write_scene(messages, samples=samples, stamp_offset_ns=0) == 4
    got: dict[str, list] = {}
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, _message, msg in reader.iter_decoded_messages():
            got.setdefault(channel.topic, []).append((schema.name, msg))
    assert {name for name, _m in got[JOINT_STATES_TOPIC]} == {"sensor_msgs/msg/JointState"}
    positions, velocities = scene.joint_states(samples[:, 1 : 1 + d], samples[:, 1 + d : 1 + 2 * d])
    for k, (_name, msg) in enumerate(got[JOINT_STATES_TOPIC]):
        assert list(msg.name) == list(scene.joint_names)
        # the same doubles, serialized and decoded: equal
        assert list(msg.position) == list(positions[k]) and list(msg.velocity) == \
            list(velocities[k])
    ((_name, description),) = got["/robot_description"]
    assert description.data == scene.urdf([], samples[:1, 1 : 1 + d])


def test_a_simulator_serving_a_urdf_robot_publishes_its_tree(domain_id):
    """The simulator node serving ``bolt`` (in-process, on DDS): /robot_description is the
    robot's URDF, every /tf message one transform world -> base_link, every /joint_states
    message the joints at the state the reply carries for that stamp, and the first marker
    array starts with a DELETEALL."""
    import time

    from biped_opt import ros
    from biped_opt.simulation.compiled import CompiledSystem
    from tests.nodes.test_nodes import call, serving_simulator

    compiled = CompiledSystem("bolt")
    got: dict[str, list] = {"/tf": [], JOINT_STATES_TOPIC: [], MARKERS_TOPIC: [],
                            "/robot_description": []}
    with serving_simulator(domain_id, system="bolt") as (_graph, probe):
        reliable = ros.ReliabilityPolicy.RELIABLE
        for topic, typename, durability in (
                ("/tf", "tf2_msgs/msg/TFMessage", ros.DurabilityPolicy.VOLATILE),
                (JOINT_STATES_TOPIC, "sensor_msgs/msg/JointState", ros.DurabilityPolicy.VOLATILE),
                (MARKERS_TOPIC, "visualization_msgs/msg/MarkerArray",
                 ros.DurabilityPolicy.VOLATILE),
                ("/robot_description", "std_msgs/msg/String",
                 ros.DurabilityPolicy.TRANSIENT_LOCAL)):
            probe.create_subscription(ros.message_type(typename), topic, got[topic].append,
                                      ros.QoSProfile(depth=1000, reliability=reliable,
                                                     durability=durability))
        time.sleep(0.5)  # discovery
        reply = call(probe, ros.srvs.Simulate, "/biped/simulate", maneuver="drop", theta0=0.05,
                     inputs=[0.0] * len(compiled.inputs), real_time_factor=4.0)
        assert reply.success, reply.message
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline and not (
                got["/robot_description"] and got[JOINT_STATES_TOPIC] and
                got[JOINT_STATES_TOPIC][-1].header.stamp == reply.system_states[-1].header.stamp):
            time.sleep(0.05)
    scene = compiled.scene
    assert got["/robot_description"][0].data == scene.urdf([], np.zeros((1, 12)))
    states = {(s.header.stamp.sec, s.header.stamp.nanosec): s for s in reply.system_states}
    assert len(got[JOINT_STATES_TOPIC]) >= 0.9 * len(states)  # (every shown sample, reliable)
    for js in got[JOINT_STATES_TOPIC]:
        state = states[(js.header.stamp.sec, js.header.stamp.nanosec)]
        assert list(js.name) == list(scene.joint_names) and len(js.effort) == 0
        positions, velocities = scene.joint_states(np.array(state.q), np.array(state.qdot))
        # the same doubles on both paths: equal
        assert list(js.position) == list(positions[0])
        assert list(js.velocity) == list(velocities[0])
    for tf in got["/tf"]:
        (t,) = tf.transforms
        assert (t.header.frame_id, t.child_frame_id) == ("world", "base_link")
        q = np.array(states[(t.header.stamp.sec, t.header.stamp.nanosec)].q)
        assert (t.transform.translation.x, t.transform.translation.y,
                t.transform.translation.z) == tuple(q[:3])
    first = got[MARKERS_TOPIC][0].markers[0]
    assert first.action == 3 and first.ns == ""  # DELETEALL, then the scene
    assert all(m.action == 0 for a in got[MARKERS_TOPIC] for m in a.markers[1:])


# -- a system of bodies declared with System.body: the library's quadruped ----------------------

@pytest.fixture(scope="module")
def quadruped_scene():
    from biped_opt.systems.library.quadruped import quadruped

    system = quadruped()
    return system, _scene(system)


#: the quadruped's parameters changed from their defaults (lengths, masses, the hips' spread):
#: the URDF follows them without a recompile
CHANGED = {"L": 0.2, "w": 0.12, "l1": 0.25, "l2": 0.18, "m_trunk": 4.0, "m_thigh": 0.7,
           "m_shank": 0.2, "h_trunk": 0.1, "r_leg": 0.03}


@pytest.mark.parametrize("changed", [False, True])
def test_the_quadruped_s_urdf_places_its_frames_and_has_its_mass_matrix(quadruped_scene,
                                                                        changed):
    """Its bodies as links on hinges (codegen/joint_tree.py): Pinocchio's model of the emitted URDF,
    placed by /tf and /joint_states, puts the quadruped's declared frames (each trunk half's
    centre, L/2 along its x axis from the spine; each foot l2 below its knee) where the
    system's own scene code does, to 1e-12, and its mass matrix (CRBA) is the one the
    description's bodies give (NumericSystem), to 1e-12 relative, at the defaults and at changed
    parameters."""
    from biped_opt.systems.derive import derive

    system, scene = quadruped_scene
    names = list(system.defaults)
    values = dict(system.defaults)
    if changed:
        values.update(CHANGED)
    parameters = [values[k] for k in names]
    d, nc = len(system.coordinate_names), len(system.constraints)
    typestore = load_interfaces().typestore
    messages = SceneMessages(typestore, scene, parameters, d)
    assert scene.base == "front_trunk" and messages.tf_frames == ("front_trunk",)
    n = 4
    samples = _random_samples(d, nc, n, 37)
    _stamps, out = messages.messages(samples, 0)
    urdf = scene.urdf(parameters, samples[:1, 1 : 1 + d])
    assert "{" not in urdf
    model = pin.buildModelFromXML(urdf)
    data = model.createData()
    own = scene.evaluate(samples[:, 1 : 1 + d], parameters)
    numeric = derive(system).numeric(**values)
    L, l2 = values["L"], values["l2"]
    # (the system's frames: each a link's frame moved by a fixed offset in the link's axes)
    frames = {"base_link": ("front_trunk", (L / 2, 0.0, 0.0), True),
              "rear_link": ("rear_trunk", (-L / 2, 0.0, 0.0), True),
              **{f"{leg}_foot": (f"{leg}_shank", (0.0, 0.0, -l2), False)
                 for leg in ("fl", "fr", "rl", "rr")}}
    for k in range(n):
        js = typestore.deserialize_cdr(out[JOINT_STATES_TOPIC][k], "sensor_msgs/msg/JointState")
        (tf,) = typestore.deserialize_cdr(out["/tf"][k], "tf2_msgs/msg/TFMessage").transforms
        position = dict(zip(js.name, js.position))
        qp = pin.neutral(model)
        for i in range(1, model.njoints):
            joint = model.joints[i]
            value = position[model.names[i]]
            qp[joint.idx_q : joint.idx_q + 2] = np.cos(value), np.sin(value)  # (continuous)
        pin.framesForwardKinematics(model, data, qp)
        r = tf.transform.rotation
        R0 = _quaternion_matrix(r.x, r.y, r.z, r.w)
        p0 = np.array([tf.transform.translation.x, tf.transform.translation.y,
                       tf.transform.translation.z])
        for frame, (link, offset, oriented) in frames.items():
            placement = data.oMf[model.getFrameId(link, pin.BODY)]
            at = p0 + R0 @ (placement.translation + placement.rotation @ np.array(offset))
            i = scene.frames.index(frame)
            np.testing.assert_allclose(at, own.positions[k, i], rtol=0, atol=FK_TOL)
            if oriented:
                np.testing.assert_allclose(R0 @ placement.rotation,
                                           _quaternion_matrix(*own.quaternions[k, i]),
                                           rtol=0, atol=FK_TOL)
        # M: Pinocchio's with a free base in the quadruped's coordinates (x, y, z, yaw, pitch,
        # roll: a translation, then hinges about z, y, x) and hinges in its order
        root = pin.JointModelComposite(pin.JointModelTranslation())
        for hinge in (pin.JointModelRZ(), pin.JointModelRY(), pin.JointModelRX()):
            root.addJoint(hinge)
        free = pin.buildModelFromXML(urdf, root)
        fdata = free.createData()
        q = samples[k, 1 : 1 + d]
        qf = pin.neutral(free)
        qf[:6] = q[:6]
        order = list(range(6))
        for i in range(2, free.njoints):  # (joint 1 is the root)
            joint = free.joints[i]
            c = system.coordinate_names.index(free.names[i])
            qf[joint.idx_q : joint.idx_q + 2] = np.cos(q[c]), np.sin(q[c])
            order.append(c)
        M = pin.crba(free, fdata, qf)
        M = np.triu(M) + np.triu(M, 1).T
        ours = numeric.mass_matrix(q)[np.ix_(order, order)]
        assert np.abs(M - ours).max() <= 1e-12 * np.abs(ours).max()
