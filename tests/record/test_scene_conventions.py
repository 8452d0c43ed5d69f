"""The scene topics (ROS.md Sec. 6) as ROS tools see them: recordings of the biped and of the
rocking bar decoded by independent readers (rosbags with its own ROS 2 Humble definitions, through
its rosbag2 Reader too, and mcap-ros2-support from the schema text in the file), checked against
the conventions (names, types, offered QoS, REP 103/105 frames, robot_state_publisher's URDF) and
against closed forms of the recorded states; then the live topics of a running simulator, and a
node on simulated time.

Expected values are written out here from the documents (ROS.md's table, SYSTEMS.md Sec. 6 and
the library's descriptions), not read from the code under test.
"""

from __future__ import annotations

import json
import threading
import time
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.interfaces import QosDurability, QosHistory, QosReliability
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from biped_opt import ros
from biped_opt.nodes import convert
from biped_opt.paper.biped import compiled_biped, simulate
from biped_opt.piecewise import theta_grid
from biped_opt.record import SweepWriter
from biped_opt.record.rosbag2 import export_rosbag2
from biped_opt.record.scene import (
    DELETEALL,
    JOINT_STATES_TOPIC,
    SCENE_TOPICS,
    SceneMessages,
)
from biped_opt.record.writer import BIPED_TOPICS, SYSTEM_TOPICS
from biped_opt.ros.interfaces import load_interfaces
from biped_opt.simulation.compiled import CompiledSystem
from biped_opt.systems.library.walker import BODY_DEPTH, BODY_THICKNESS, FOOT_RADIUS, LEG_WIDTH

NS = 1_000_000_000
#: poses are float64 all the way from the same q: the closed forms agree to rounding (a few ulp
#: of numbers of order 1); 1e-12 allows for that and nothing else
TOL = 1e-12

#: ROS.md Sec. 6: topic -> (type, history depth, reliable, durability)
TABLE = {
    "/clock": ("rosgraph_msgs/msg/Clock", 1, QosDurability.VOLATILE),
    "/tf": ("tf2_msgs/msg/TFMessage", 100, QosDurability.VOLATILE),
    "/biped/markers": ("visualization_msgs/msg/MarkerArray", 10, QosDurability.VOLATILE),
    "/robot_description": ("std_msgs/msg/String", 1, QosDurability.TRANSIENT_LOCAL),
}
#: the scene topics the recorder writes for a system that is not a tree of joints (the walker,
#: the bar): all but /joint_states (SceneMessages.topics)
PLANAR_SCENE = tuple(t for t in SCENE_TOPICS if t != JOINT_STATES_TOPIC)
#: visualization_msgs/Marker type constants (the message definition's)
ARROW, CUBE, SPHERE, LINE_STRIP, SPHERE_LIST = 0, 1, 2, 4, 7
#: the frames each system declares (SYSTEMS.md Sec. 6: the walker's body and feet, the bar)
FRAMES = {"biped": ["base_link", "left_foot", "right_foot"], "rocking_bar": ["base_link"]}
#: biped recordings: touchdown at its paper inputs over an interval holding the simultaneous
#: touchdown at th0 = 0; the bar: its drop with a spin input
CASES = {"biped": ("touchdown", (2.0, 0.5, 0.0), -0.1, 0.1),
         "rocking_bar": ("drop", (0.2,), -0.2, 0.2)}


# -- recordings as the recorder writes them ----------------------------------------------------

def record_biped_sweep(path: Path, *, maneuver: str = "touchdown", lo: float = -0.1,
                       hi: float = 0.1, num: int = 3, dt: float = 0.02,
                       inputs: tuple[float, ...] = (2.0, 0.5, 0.0)) -> dict[float, Any]:
    """A fixed-input sweep of the biped with its scene, written as the recorder writes one
    (states, contact modes at the events, SweepPoints, the URDF, /clock, /tf, markers); returns
    {th0: trajectory}."""
    compiled = compiled_biped()
    out = {}
    with SweepWriter(path, metadata={"maneuver": maneuver, "theta0_min": str(lo),
                                     "theta0_max": str(hi), "num": str(num),
                                     "optimal": "False", "fixed_inputs": json.dumps(inputs)},
                     topics=BIPED_TOPICS + PLANAR_SCENE) as w:
        scene = _described(w, compiled)
        offset = 0
        for th in theta_grid(lo, hi, num):
            tr = simulate(maneuver, float(th), inputs, sample_dt=dt)
            w.write_states(maneuver=maneuver, theta0=float(th), samples=tr.samples,
                           stamp_offset_ns=offset)
            w.write_scene(scene, samples=tr.samples, stamp_offset_ns=offset)
            for t, mode in zip([0.0, *tr.event_times], tr.mode_sequence):
                ns = offset + round(t * NS)
                w.write("/biped/contact_mode", {"header": _header(ns), "mode": int(mode)}, ns)
            end = offset + round(tr.t_final * NS)
            w.write("/biped/sweep", {
                "header": _header(offset), "maneuver": maneuver, "theta0": float(th),
                "policy": list(inputs), "value": 0.0, "outcome": tr.outcome,
                "t_final": tr.t_final, "mode_sequence": [int(m) for m in tr.mode_sequence],
                "event_times": [float(t) for t in tr.event_times]}, end)
            out[float(th)] = tr
            offset = end + NS // 2
    return out


def record_system_sweep(path: Path, name: str, maneuver: str, inputs: tuple[float, ...],
                        lo: float, hi: float, num: int = 3, dt: float = 0.02) -> dict[float, Any]:
    """The same for another system (SystemState samples); returns {s: trajectory}."""
    compiled = CompiledSystem(name)
    info = convert.system_info_fields(compiled, name)
    out = {}
    with SweepWriter(path, metadata={"system": name, "maneuver": maneuver}, system=info,
                     topics=SYSTEM_TOPICS + PLANAR_SCENE) as w:
        scene = _described(w, compiled)
        offset = 0
        for s in theta_grid(lo, hi, num):
            tr = compiled.simulate(maneuver, float(s), list(inputs), sample_dt=dt)
            w.write_system_states(maneuver=maneuver, s=float(s), samples=tr.samples,
                                  ndof=len(compiled.coordinates), stamp_offset_ns=offset)
            w.write_scene(scene, samples=tr.samples, stamp_offset_ns=offset)
            out[float(s)] = tr
            offset += round((tr.t_final + 0.5) * NS)
    return out


def _described(writer: SweepWriter, compiled: Any) -> SceneMessages:
    """The scene of ``compiled``, its URDF written first (as the recorder does)."""
    scene = SceneMessages(writer.typestore, compiled.scene, list(compiled.parameters.values()),
                          len(compiled.coordinates))
    assert tuple(scene.topics) == PLANAR_SCENE  # (what the recorder asks the writer for)
    writer.write_robot_description(scene)
    return scene


def _header(ns: int) -> dict[str, Any]:
    return {"stamp": {"sec": ns // NS, "nanosec": ns % NS}, "frame_id": "biped"}


def _stamp(header: Any) -> int:
    return int(header.stamp.sec) * NS + int(header.stamp.nanosec)


# -- the recordings, read by both readers ------------------------------------------------------

class Decoded:
    """One recording: per topic its channel metadata, schema, and (log time, mcap-ros2 message,
    rosbags message) of every message; the states as {stamp: row} (t, q, qdot, mode, lambda)."""

    def __init__(self, path: Path, name: str) -> None:
        self.path, self.name = path, name
        humble = get_typestore(Stores.ROS2_HUMBLE)
        factory = DecoderFactory()
        self.channels: dict[str, Any] = {}
        self.schemas: dict[str, Any] = {}
        self.messages: dict[str, list[tuple[int, Any, Any]]] = defaultdict(list)
        self.states: dict[int, np.ndarray] = {}
        decoders: dict[int, Any] = {}
        with open(path, "rb") as stream:
            reader = make_reader(stream)
            # (file order: the writer's, where an event's post-reset row follows its pre-reset
            # row of the same stamp; every topic's messages are in stamp order in it)
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                self.channels[channel.topic] = channel
                self.schemas[channel.topic] = schema
                if channel.id not in decoders:
                    decoders[channel.id] = factory.decoder_for("cdr", schema)
                msg = decoders[channel.id](message.data)
                if channel.topic in TABLE:
                    ours = humble.deserialize_cdr(message.data, schema.name)
                    self.messages[channel.topic].append((message.log_time, msg, ours))
                elif channel.topic in ("/biped/state", "/biped/system_state"):
                    # (an event's pre-reset and post-reset rows share a stamp: the later wins)
                    self.states[_stamp(msg.header)] = np.array(
                        [msg.t, *msg.q, *msg.qdot, msg.contact_mode, *msg.contact_force])


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> dict[str, tuple[Decoded, dict[float, Any]]]:
    out = {}
    for name, (maneuver, inputs, lo, hi) in CASES.items():
        path = tmp_path_factory.mktemp("scene") / f"{name}.mcap"
        if name == "biped":
            trs = record_biped_sweep(path, maneuver=maneuver, lo=lo, hi=hi, inputs=inputs)
        else:
            trs = record_system_sweep(path, name, maneuver, inputs, lo, hi)
        out[name] = (Decoded(path, name), trs)
    return out


@pytest.fixture(params=sorted(CASES))
def rec(request, recordings) -> Decoded:
    return recordings[request.param][0]


# -- names, types, QoS, definitions --------------------------------------------------------------

def test_topics_types_and_offered_qos_are_the_tables(rec):
    humble = get_typestore(Stores.ROS2_HUMBLE)
    assert set(TABLE) <= set(rec.channels)
    for topic, (typename, depth, durability) in TABLE.items():
        channel, schema = rec.channels[topic], rec.schemas[topic]
        assert schema.name == typename and schema.encoding == "ros2msg"
        assert channel.message_encoding == "cdr"
        # the standard definitions: Humble's text and type hash, as rosbags knows them
        assert schema.data.decode() == humble.generate_msgdef(typename, ros_version=2)[0]
        assert channel.metadata["topic_type_hash"] == humble.hash_rihs01(typename)
        # rosbag2's offered_qos_profiles YAML, enums as integers (1 = KEEP_LAST / RELIABLE /
        # TRANSIENT_LOCAL, 2 = VOLATILE)
        (qos,) = yaml.safe_load(channel.metadata["offered_qos_profiles"])
        assert qos["history"] == 1 and qos["depth"] == depth and qos["reliability"] == 1
        assert qos["durability"] == durability.value
        assert len(rec.messages[topic]) >= 1


def test_rosbags_rosbag2_reader_opens_the_exported_bag(rec, tmp_path):
    """rosbags' own rosbag2 Reader, on the MCAP storage folder with the metadata.yaml this
    project writes: same topics, types, QoS and messages, decoded by rosbags' definitions."""
    bag = export_rosbag2(rec.path, tmp_path / "bag")
    humble = get_typestore(Stores.ROS2_HUMBLE)
    with Reader(bag) as reader:
        conns = {c.topic: c for c in reader.connections}
        for topic, (typename, depth, durability) in TABLE.items():
            c = conns[topic]
            assert c.msgtype == typename and c.msgcount == len(rec.messages[topic])
            (qos,) = c.ext.offered_qos_profiles
            assert qos.history == QosHistory.KEEP_LAST and qos.depth == depth
            assert qos.reliability == QosReliability.RELIABLE and qos.durability == durability
        wanted = [conns[t] for t in TABLE]
        got: dict[str, list[tuple[int, Any]]] = defaultdict(list)
        for conn, log_time, data in reader.messages(connections=wanted):
            got[conn.topic].append((log_time, humble.deserialize_cdr(data, conn.msgtype)))
    for topic in TABLE:
        assert [t for t, _ in got[topic]] == [t for t, _m, _o in rec.messages[topic]]
    # the two decoders agree field by field (a sample of each topic)
    for (_, a), (_, _m, b) in zip(got["/tf"][::17], rec.messages["/tf"][::17]):
        assert a == b
    assert got["/robot_description"][0][1].data == rec.messages["/robot_description"][0][1].data


def test_both_decoders_agree(rec):
    """mcap-ros2-support (from the schema text) and rosbags (its Humble definitions) read the
    same values from every scene message."""
    for _t, m, r in rec.messages["/clock"]:
        assert (m.clock.sec, m.clock.nanosec) == (r.clock.sec, r.clock.nanosec)
    for _t, m, r in rec.messages["/tf"]:
        for a, b in zip(m.transforms, r.transforms, strict=True):
            assert (a.header.frame_id, a.child_frame_id) == (b.header.frame_id, b.child_frame_id)
            assert _stamp(a.header) == _stamp(b.header)
            for f in "xyz":
                assert getattr(a.transform.translation, f) == getattr(b.transform.translation, f)
            for f in "xyzw":
                assert getattr(a.transform.rotation, f) == getattr(b.transform.rotation, f)
    for _t, m, r in rec.messages["/biped/markers"]:
        for a, b in zip(m.markers, r.markers, strict=True):
            assert (a.ns, a.id, a.type, a.header.frame_id) == (b.ns, b.id, b.type,
                                                               b.header.frame_id)
            assert [(p.x, p.y, p.z) for p in a.points] == [(p.x, p.y, p.z) for p in b.points]
            assert [(c.r, c.g, c.b, c.a) for c in a.colors] == \
                [(c.r, c.g, c.b, c.a) for c in b.colors]
            assert (a.scale.x, a.scale.y, a.scale.z) == (b.scale.x, b.scale.y, b.scale.z)


# -- stamps and frames ---------------------------------------------------------------------------

def test_stamps_are_the_state_stamps_once_each(rec):
    stamps = sorted(rec.states)
    tf = rec.messages["/tf"]
    tf_stamps = [t for t, _m, _r in tf]
    assert len(set(tf_stamps)) == len(tf_stamps)  # no two /tf messages share a stamp
    assert tf_stamps == stamps  # in order, one per distinct state stamp: every shown sample
    for log_time, m, _r in tf:
        assert {_stamp(x.header) for x in m.transforms} == {log_time}
    for topic in ("/clock", "/biped/markers"):
        assert [t for t, _m, _r in rec.messages[topic]] == tf_stamps
    for log_time, m, _r in rec.messages["/clock"]:
        assert m.clock.sec * NS + m.clock.nanosec == log_time
    for log_time, m, _r in rec.messages["/biped/markers"]:
        assert {_stamp(x.header) for x in m.markers} == {log_time}


def test_frames_follow_rep_103_and_105_in_closed_form(rec, recordings):
    """world -> each declared frame; planar: y = 0 and a rotation about y only; the body at
    (x, 0, z) turned by -th about y: quaternion (0, -sin(th/2), 0, cos(th/2)); the biped's feet
    at (x_i, 0, z_i), unturned."""
    frames = FRAMES[rec.name]
    for log_time, m, _r in rec.messages["/tf"]:
        assert [x.header.frame_id for x in m.transforms] == ["world"] * len(frames)
        assert [x.child_frame_id for x in m.transforms] == frames
        q = rec.states[log_time][1:]
        x, z, th = q[0], q[1], q[2]
        expected = [((x, z), (0.0, -np.sin(th / 2), 0.0, np.cos(th / 2)))]
        if rec.name == "biped":
            expected += [((q[3], q[4]), (0.0, 0.0, 0.0, 1.0)), ((q[5], q[6]), (0.0, 0.0, 0.0, 1.0))]
        for tf, ((ex, ez), quat) in zip(m.transforms, expected, strict=True):
            tr, rot = tf.transform.translation, tf.transform.rotation
            assert tr.y == 0.0 and rot.x == 0.0 and rot.z == 0.0  # the x-z plane, exactly
            assert abs(tr.x - ex) <= TOL and abs(tr.z - ez) <= TOL
            got = np.array([rot.x, rot.y, rot.z, rot.w])
            np.testing.assert_allclose(got, quat, rtol=0, atol=TOL)


def test_robot_description_is_robot_state_publishers_urdf(rec):
    (_t, m, _r), = rec.messages["/robot_description"]
    root = ET.fromstring(m.data)
    frames = FRAMES[rec.name]
    assert root.tag == "robot" and root.get("name") == rec.name
    links = {link.get("name"): link for link in root.findall("link")}
    assert sorted(links) == sorted(["world", *frames])  # the fixed frame and one link per frame
    joints = root.findall("joint")
    assert len(joints) == len(frames)
    for joint in joints:
        assert joint.get("type") == "floating"
        assert joint.find("parent").get("link") == "world"
    assert sorted(j.find("child").get("link") for j in joints) == sorted(frames)
    assert links["world"].findall("visual") == []
    compiled = compiled_biped() if rec.name == "biped" else CompiledSystem(rec.name)
    w = compiled.parameters["w"]
    # the sizes in closed form from the parameters (SYSTEMS.md Sec. 6, the library's looks)
    if rec.name == "biped":
        want = {"base_link": ("box", [2 * w + BODY_THICKNESS, BODY_DEPTH, BODY_THICKNESS]),
                "left_foot": ("sphere", [FOOT_RADIUS]), "right_foot": ("sphere", [FOOT_RADIUS])}
    else:
        want = {"base_link": ("box", [2 * w, 0.08, 0.04])}
    for frame, (kind, size) in want.items():
        (visual,) = links[frame].findall("visual")
        (geometry,) = list(visual.find("geometry"))
        assert geometry.tag == kind
        got = geometry.get("size" if kind == "box" else "radius").split()
        np.testing.assert_allclose([float(v) for v in got], size, rtol=1e-9)  # (printed %.9g)
        rgba = [float(v) for v in visual.find("material/color").get("rgba").split()]
        assert len(rgba) == 4 and all(0 <= c <= 1 for c in rgba)


# -- markers ---------------------------------------------------------------------------------------

def _items(rec: Decoded) -> dict[str, tuple[int, str]]:
    """namespace item -> (marker type, frame) as ROS.md's table and the descriptions say."""
    if rec.name == "biped":
        return {"ground": (CUBE, "world"), "body": (CUBE, "base_link"),
                "left_foot": (SPHERE, "left_foot"), "left_leg": (LINE_STRIP, "world"),
                "right_foot": (SPHERE, "right_foot"), "right_leg": (LINE_STRIP, "world"),
                "contacts": (SPHERE_LIST, "world"), "left_force": (ARROW, "world"),
                "right_force": (ARROW, "world")}
    return {"ground": (CUBE, "world"), "bar": (CUBE, "base_link"),
            "contacts": (SPHERE_LIST, "world"), "left_force": (ARROW, "world"),
            "right_force": (ARROW, "world")}


def _is_red(c: Any) -> bool:
    return c.r >= 0.5 and c.g <= 0.2 * c.r and c.b <= 0.2 * c.r and c.a == 1.0


def _is_grey(c: Any) -> bool:
    return c.r == c.g == c.b and 0 < c.a


def test_markers_have_the_tables_types_ids_and_closed_form_geometry(rec):
    items = _items(rec)
    compiled = compiled_biped() if rec.name == "biped" else CompiledSystem(rec.name)
    w = compiled.parameters["w"]
    seen_modes = set()
    for k, (log_time, m, _r) in enumerate(rec.messages["/biped/markers"]):
        markers_ = list(m.markers)
        if k == 0:
            # a new scene's first array starts by clearing what an earlier system left
            # (ROS.md Sec. 6): one DELETEALL in every namespace, at the array's stamp
            clear = markers_.pop(0)
            assert (clear.action, clear.ns) == (DELETEALL, "")
            assert clear.header.stamp == markers_[0].header.stamp
        m = SimpleNamespace(markers=markers_)
        by_ns: dict[str, list[Any]] = defaultdict(list)
        for marker in m.markers:
            by_ns[marker.ns].append(marker)
        assert sorted(by_ns) == sorted(f"{rec.name}/{k}" for k in items)
        ids = [marker.id for marker in m.markers]
        assert len(set(ids)) == len(ids) and ids[0] == 0  # unique; the ground is 0
        for markers in by_ns.values():
            assert len({mk.id for mk in markers}) == len(markers)  # unique per namespace
        marker = {ns.split("/", 1)[1]: mks[0] for ns, mks in by_ns.items()}
        for item, (kind, frame) in items.items():
            assert marker[item].type == kind and marker[item].header.frame_id == frame, item
        for mk in m.markers:
            # what RViz needs to draw a marker: ADD, a unit quaternion (an all-zero one is the
            # classic invisible marker), a positive scale, kept until replaced (lifetime 0)
            o = mk.pose.orientation
            assert mk.action == 0 and abs(o.x**2 + o.y**2 + o.z**2 + o.w**2 - 1) <= TOL
            assert mk.scale.x > 0 and (mk.lifetime.sec, mk.lifetime.nanosec) == (0, 0)
            if mk.type != ARROW:  # (an arrow is transparent while its constraint is free)
                assert mk.color.a > 0
            if mk.type == ARROW:  # shaft diameter, head diameter wider than the shaft
                assert 0 < mk.scale.x < mk.scale.y
        ground = marker["ground"]
        assert (ground.scale.x, ground.scale.y, ground.scale.z) == (20.0, 2.0, 0.01)
        assert ground.pose.position.z + ground.scale.z / 2 == 0.0  # its top is z = 0
        row = rec.states[log_time]
        d = len(compiled.coordinates)
        q, mode, lam = row[1 : 1 + d], int(row[1 + 2 * d]), row[2 + 2 * d :]
        seen_modes.add(mode)
        x, z, th = q[:3]
        if rec.name == "biped":
            feet = [(q[3], q[4]), (q[5], q[6])]
            for k, (item, s) in enumerate((("left", -1), ("right", 1))):
                leg = marker[f"{item}_leg"]
                hip = (x + s * w * np.cos(th), 0.0, z + s * w * np.sin(th))
                pts = np.array([[p.x, p.y, p.z] for p in leg.points])
                np.testing.assert_allclose(pts, [hip, (feet[k][0], 0.0, feet[k][1])],
                                           rtol=0, atol=TOL)
                assert leg.scale.x == LEG_WIDTH
                ball = marker[f"{item}_foot"]
                assert ball.frame_locked and ball.scale.x == ball.scale.y == ball.scale.z \
                    == 2 * FOOT_RADIUS
            body = marker["body"]
            assert body.frame_locked and (body.scale.x, body.scale.y, body.scale.z) == \
                (2 * w + BODY_THICKNESS, BODY_DEPTH, BODY_THICKNESS)
        else:
            feet = [(x - w * np.cos(th), z - w * np.sin(th)), (x + w * np.cos(th),
                                                                z + w * np.sin(th))]
            bar = marker["bar"]
            assert bar.frame_locked and (bar.scale.x, bar.scale.y, bar.scale.z) == \
                (2 * w, 0.08, 0.04)
        contacts = marker["contacts"]
        assert len(contacts.points) == len(contacts.colors) == 2
        for j, ((fx, fz), name) in enumerate(zip(feet, ("left", "right"))):
            point = contacts.points[j]
            np.testing.assert_allclose([point.x, point.y, point.z], [fx, 0.0, fz], rtol=0,
                                       atol=TOL)
            active = (mode >> j) & 1 == 1
            # red exactly while the constraint is active, grey while it is free
            assert _is_red(contacts.colors[j]) == active and _is_grey(contacts.colors[j]) != active
            arrow = marker[f"{name}_force"]
            a, b = ([p.x, p.y, p.z] for p in arrow.points)
            np.testing.assert_allclose(a, [fx, 0.0, fz], rtol=0, atol=TOL)
            # 0.1 m per unit of lambda_j along the normal +z; nothing while free
            length = 0.1 * lam[j] if active else 0.0
            np.testing.assert_allclose(np.subtract(b, a), [0.0, 0.0, length], rtol=0, atol=TOL)
            assert (arrow.color.a > 0) == active
    if rec.name == "biped":
        # (the touchdowns visit the air, one foot and both: both colours and arrows are tested)
        assert {0, 3} <= seen_modes and seen_modes & {1, 2}


def test_the_biped_pushes_on_the_ground_while_in_contact(recordings):
    """The arrows above are not all zero: in stance the recorded lambda is positive and the
    arrows up to 0.1 lambda long (a check that the arrow test saw forces)."""
    rec = recordings["biped"][0]
    longest = 0.0
    for _t, m, _r in rec.messages["/biped/markers"]:
        for marker in m.markers:
            if marker.type == ARROW:
                longest = max(longest, marker.points[1].z - marker.points[0].z)
    assert longest > 0.1  # lambda > 1 (the body weighs 1 in units of mb g) at some sample


# -- live ----------------------------------------------------------------------------------------

def _qos(topic: str) -> Any:
    _type, depth, durability = TABLE[topic]
    return ros.QoSProfile(depth=depth, history=ros.HistoryPolicy.KEEP_LAST,
                          reliability=ros.ReliabilityPolicy.RELIABLE,
                          durability=ros.DurabilityPolicy.TRANSIENT_LOCAL
                          if durability == QosDurability.TRANSIENT_LOCAL
                          else ros.DurabilityPolicy.VOLATILE)


@pytest.fixture()
def live(domain_id):
    """A simulator (no autostart) and an executor in a context of their own."""
    from biped_opt.nodes.simulator import SimulatorNode

    context = ros.Context()
    ros.init(args=[], context=context, domain_id=domain_id)
    sim = SimulatorNode(context=context,
                        parameter_overrides=[ros.Parameter("autostart", value=False)])
    executor = ros.MultiThreadedExecutor(num_threads=3, context=context)
    executor.add_node(sim)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    nodes = [sim]

    def add(node: Any) -> Any:
        nodes.append(node)
        executor.add_node(node)
        return node

    yield context, add
    executor.shutdown(timeout_sec=10.0)
    thread.join(10.0)
    for node in reversed(nodes):
        node.destroy_node()
    ros.try_shutdown(context=context)


def _wait(condition: Any, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.02)
    return condition()


def test_live_topics_arrive_with_the_documented_qos(live):
    from tests.nodes.test_nodes import call

    context, add = live
    probe = add(ros.Node("probe", context=context))
    timed = add(ros.Node("timed", context=context,
                         parameter_overrides=[ros.Parameter("use_sim_time", value=True)]))
    got: dict[str, list[Any]] = defaultdict(list)
    for topic, (typename, _depth, _dur) in TABLE.items():
        if topic != "/robot_description":
            probe.create_subscription(ros.message_type(typename), topic, got[topic].append,
                                      _qos(topic))
    time.sleep(0.5)  # discovery
    assert timed.get_clock().now().nanoseconds == 0  # on simulated time, before any /clock
    # real time x4: a touchdown of ~1.6 time units plays in ~0.4 s, every sample shown
    reply = call(probe, ros.srvs.Simulate, "/biped/simulate", maneuver="touchdown", theta0=0.1,
                 inputs=[2.0, 0.5, 0.0], real_time_factor=4.0)
    assert reply.success
    end = round(reply.t_final * NS)  # the first run starts the simulated clock at 0
    assert _wait(lambda: got["/clock"] and _ns(got["/clock"][-1].clock) == end)
    assert _wait(lambda: timed.get_clock().now().nanoseconds == end)
    assert _wait(lambda: got["/tf"] and _stamp(got["/tf"][-1].transforms[0].header) == end)
    assert _wait(lambda: got["/biped/markers"]
                 and _stamp(got["/biped/markers"][-1].markers[0].header) == end)
    # a run shown at 4x real time: (nearly) every shown sample of the reply arrives, in order
    shown = len({s.t for s in reply.states})
    assert len(got["/tf"]) >= 0.9 * shown
    stamps = [_stamp(m.transforms[0].header) for m in got["/tf"]]
    assert stamps == sorted(set(stamps))
    for m in got["/tf"]:
        assert [t.child_frame_id for t in m.transforms] == FRAMES["biped"]
        assert {t.header.frame_id for t in m.transforms} == {"world"}
        assert all(t.transform.translation.y == 0.0 for t in m.transforms)
    last = got["/tf"][-1].transforms[0].transform
    final = reply.states[-1]
    assert abs(last.translation.x - final.q[0]) <= TOL
    assert abs(last.rotation.y + np.sin(final.q[2] / 2)) <= TOL
    assert len(got["/biped/markers"][-1].markers) == 9
    # a late subscriber still gets the description (transient local, as robot_state_publisher)
    late = add(ros.Node("late", context=context))
    urdf: list[Any] = []
    late.create_subscription(ros.message_type("std_msgs/msg/String"), "/robot_description",
                             urdf.append, _qos("/robot_description"))
    assert _wait(lambda: len(urdf) == 1)
    root = ET.fromstring(urdf[0].data)
    assert sorted(link.get("name") for link in root.findall("link")) == \
        sorted(["world", *FRAMES["biped"]])


def _ns(t: Any) -> int:
    return int(t.sec) * NS + int(t.nanosec)


def test_times_within_half_a_nanosecond_take_one_stamp():
    # a live step continued after an event sums its pieces' offsets in floating point: a
    # sample and the step's end can differ by 1e-12 s and round to the same nanosecond; /tf
    # takes no stamp twice (tf2 rejects a repeated one), so one row per stamp, the later one
    compiled = compiled_biped()
    tr = simulate("touchdown", 0.1, (2.0, 0.5, 0.0), sample_dt=0.01)
    samples = tr.samples[:6].copy()
    twin = samples[3].copy()
    twin[0] += 1e-12
    twin[2] += 1e-3  # (a distinguishable state)
    samples = np.insert(samples, 4, twin, axis=0)
    scene = SceneMessages(load_interfaces().typestore, compiled.scene,
                          list(compiled.parameters.values()), len(compiled.coordinates))
    stamps, data = scene.messages(samples, 0)
    assert len(set(stamps.tolist())) == len(stamps) == len(samples) - 1
    assert all(len(v) == len(stamps) for v in data.values())
    want = scene.messages(np.delete(samples, 3, axis=0), 0)[1]["/tf"]
    assert data["/tf"] == want  # (the later row of the two is the one shown)
