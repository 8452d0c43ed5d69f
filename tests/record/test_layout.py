"""config/foxglove_layout.json: a Foxglove layout (the JSON Foxglove exports and imports) whose
every topic, frame and message path exists in a biped sweep recording and on the topics of a
live simulator serving the biped (so that no panel stays empty while watching one).

Message paths (``/topic.field[index].field``, Foxglove's syntax) are checked twice: against the
message definitions in the typestore (each field exists, an index goes into an array or a
sequence and within a fixed array's length, the leaf is a number Foxglove can plot), and on the
decoded messages of a real recording (each path gives exactly one number in every message of its
topic: a plot against a custom x-axis pairs its x and y values by their order, so one missing
value would shift every later point).
"""

from __future__ import annotations

import json
import re
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from biped_opt.ros.interfaces import load_interfaces

from .test_scene_conventions import record_biped_sweep

LAYOUT = Path(__file__).resolve().parents[2] / "config" / "foxglove_layout.json"
#: what Foxglove writes when it exports a layout
TOP_KEYS = {"configById", "globalVariables", "userNodes", "playbackConfig", "layout"}
PANEL_TYPES = {"3D", "Plot", "StateTransitions"}
X_AXES = {"timestamp", "index", "custom", "currentCustom"}
TIMESTAMP_METHODS = {"receiveTime", "headerStamp"}
#: ROS types Foxglove plots (its Plot panel's list, less time, duration and string)
PLOTTABLE = {"bool", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64",
             "float32", "float64"}
_PATH = re.compile(r"^(?P<topic>(?:/[A-Za-z_][A-Za-z0-9_]*)+)(?P<rest>(?:\.[A-Za-z_]\w*"
                   r"(?:\[\d+\])?)+)$")
_PART = re.compile(r"\.([A-Za-z_]\w*)(?:\[(\d+)\])?")


@pytest.fixture(scope="module")
def layout() -> dict[str, Any]:
    return json.loads(LAYOUT.read_text())


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> dict[str, Any]:
    """A small biped touchdown sweep as the recorder writes it: its topics' types, the frames of
    its /tf and every decoded message by topic."""
    path = tmp_path_factory.mktemp("layout") / "sweep.mcap"
    record_biped_sweep(path, num=5, dt=0.05)
    types: dict[str, str] = {}
    messages: dict[str, list[Any]] = defaultdict(list)
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, _message, msg in reader.iter_decoded_messages():
            types[channel.topic] = schema.name
            messages[channel.topic].append(msg)
    frames = {name for m in messages["/tf"] for t in m.transforms
              for name in (t.header.frame_id, t.child_frame_id)}
    return {"types": types, "messages": messages, "frames": frames}


def parse_path(path: str) -> tuple[str, list[tuple[str, int | None]]]:
    """``/topic.a[2].b`` -> (``/topic``, [(``a``, 2), (``b``, None)]); a ValueError if it is
    not of that form."""
    m = _PATH.match(path)
    if m is None:
        raise ValueError(f"not a message path: {path!r}")
    parts = [(name, int(index) if index else None)
             for name, index in _PART.findall(m.group("rest"))]
    return m.group("topic"), parts


def field_type(typestore: Any, typename: str, parts: list[tuple[str, int | None]]) -> str:
    """The ROS type at the end of ``parts`` in ``typename``; an AssertionError naming the
    part that the definitions do not have."""
    current = typename
    for k, (name, index) in enumerate(parts):
        _consts, fields = typestore.fielddefs[current]
        found = dict(fields)
        assert name in found, f"{current} has no field {name!r}"
        kind, spec = found[name]
        kind = getattr(kind, "name", kind)
        if index is not None:
            assert kind in ("ARRAY", "SEQUENCE"), f"{current}.{name} is not an array"
            (kind, spec), length = spec
            kind = getattr(kind, "name", kind)
            if length:  # a fixed array (or a bounded sequence): the index must be inside
                assert index < length, f"{current}.{name}[{index}]: it has {length}"
        else:
            assert kind in ("BASE", "NAME"), f"{current}.{name} is an array: give an index"
        if kind == "NAME":
            current = spec
        else:
            assert k == len(parts) - 1, f"{current}.{name} has no fields"
            return str(spec[0])
    return current


def value_at(msg: Any, parts: list[tuple[str, int | None]]) -> list[Any]:
    """The values ``parts`` select in a decoded message (one, or none when an index is past a
    sequence's end)."""
    value = msg
    for name, index in parts:
        value = getattr(value, name)
        if index is not None:
            if index >= len(value):
                return []
            value = value[index]
    return [value]


def _panels(layout: dict[str, Any], kind: str) -> dict[str, dict[str, Any]]:
    return {pid: cfg for pid, cfg in layout["configById"].items() if pid.split("!")[0] == kind}


def _paths(layout: dict[str, Any]) -> list[str]:
    """Every message path the layout names."""
    out = []
    for cfg in layout["configById"].values():
        out += [p["value"] for p in cfg.get("paths", [])]
        if "xAxisPath" in cfg:
            out.append(cfg["xAxisPath"]["value"])
    return out


def _leaves(node: Any) -> list[str]:
    if isinstance(node, str):
        return [node]
    assert set(node) <= {"direction", "first", "second", "splitPercentage"}, node
    assert node["direction"] in ("row", "column")
    assert 0 < node.get("splitPercentage", 50) < 100
    return _leaves(node["first"]) + _leaves(node["second"])


# -- the shape of a Foxglove layout ---------------------------------------------------------------

def test_the_layout_has_the_shape_foxglove_exports(layout):
    assert set(layout) == TOP_KEYS
    assert layout["globalVariables"] == {} and layout["userNodes"] == {}
    assert layout["playbackConfig"]["speed"] > 0
    leaves = _leaves(layout["layout"])
    # every panel of the mosaic is configured, and every configured panel is in the mosaic once
    assert sorted(leaves) == sorted(layout["configById"])
    for pid, cfg in layout["configById"].items():
        kind, _, suffix = pid.partition("!")
        assert kind in PANEL_TYPES and suffix, pid
        assert isinstance(cfg.get("foxglovePanelTitle", ""), str)
    for pid, cfg in {**_panels(layout, "Plot"), **_panels(layout, "StateTransitions")}.items():
        assert cfg["paths"], pid
        for p in cfg["paths"]:
            assert isinstance(p["value"], str) and p["timestampMethod"] in TIMESTAMP_METHODS
            assert isinstance(p.get("enabled", True), bool)
    for pid, cfg in _panels(layout, "Plot").items():
        assert cfg["xAxisVal"] in X_AXES, pid
        assert (cfg["xAxisVal"] in ("custom", "currentCustom")) == ("xAxisPath" in cfg), pid


def test_the_layout_shows_the_four_views(layout):
    """The robot (URDF, frames and markers in the fixed frame world), the outcome against th0,
    the contact modes over time and the state over time."""
    (scene,) = _panels(layout, "3D").values()
    assert scene["followTf"] == "world"
    assert scene["followMode"] in ("follow-pose", "follow-position", "follow-none")
    for topic in ("/robot_description", "/tf", "/biped/markers"):
        assert scene["topics"][topic]["visible"] is True
    camera = scene["cameraState"]
    # a side view of the x-z plane: horizontal (phi 90 deg from +z), from -y (theta 0)
    assert camera["phi"] == 90 and camera["thetaOffset"] == 0
    plots = _panels(layout, "Plot")
    against_th0 = {p["value"]: cfg["xAxisPath"]["value"] for cfg in plots.values()
                   if cfg["xAxisVal"] == "custom" for p in cfg["paths"]}
    # every run's samples against its th0: a sweep recording and a live simulator alike
    assert against_th0["/biped/state.q[2]"] == "/biped/state.theta0"
    assert against_th0["/biped/state.contact_mode"] == "/biped/state.theta0"
    over_time = {p["value"] for cfg in plots.values() if cfg["xAxisVal"] == "timestamp"
                 for p in cfg["paths"]}
    assert {"/biped/state.q[2]", "/biped/state.q[1]"} <= over_time
    modes = {p["value"] for cfg in _panels(layout, "StateTransitions").values()
             for p in cfg["paths"]}
    assert "/biped/state.contact_mode" in modes


# -- against a recording ---------------------------------------------------------------------------

def test_every_topic_and_frame_is_in_a_biped_sweep_recording(layout, recording):
    (scene,) = _panels(layout, "3D").values()
    named = set(scene["topics"]) | {parse_path(p)[0] for p in _paths(layout)}
    assert named <= set(recording["types"]), named - set(recording["types"])
    frames = {key.removeprefix("frame:") for key in scene["transforms"]}
    frames |= {scene["followTf"]}
    frames |= {layer["frameId"] for layer in scene["layers"].values() if "frameId" in layer}
    assert frames <= recording["frames"], frames - recording["frames"]


def test_every_path_is_a_plottable_field_of_its_type(layout, recording):
    typestore = load_interfaces().typestore
    for path in _paths(layout):
        topic, parts = parse_path(path)
        leaf = field_type(typestore, recording["types"][topic], parts)
        assert leaf in PLOTTABLE, f"{path}: {leaf} is not plottable"


def test_every_path_gives_one_number_per_message(layout, recording):
    for path in _paths(layout):
        topic, parts = parse_path(path)
        messages = recording["messages"][topic]
        assert messages, topic
        for msg in messages:
            (value,) = value_at(msg, parts)  # exactly one: x and y pair up by order
            assert isinstance(value, (int, float)), (path, value)


def test_the_checks_catch_a_wrong_path(recording):
    """The parser and the definitions' walk refuse what Foxglove would show as empty."""
    typestore = load_interfaces().typestore
    sweep, state = recording["types"]["/biped/sweep"], recording["types"]["/biped/state"]
    for bad in ("/biped/sweep", "biped/sweep.outcome", "/biped/sweep.outcome[", "/a..b"):
        with pytest.raises(ValueError):
            parse_path(bad)
    for path, typename in (("/biped/sweep.outcomes", sweep), ("/biped/state.q[7]", state),
                           ("/biped/state.q", state), ("/biped/sweep.theta0[0]", sweep),
                           ("/biped/state.t.x", state)):
        with pytest.raises(AssertionError):
            field_type(typestore, typename, parse_path(path)[1])
    assert field_type(typestore, state, parse_path("/biped/state.header.stamp.sec")[1]) == \
        "int32"
    # a sequence index past the end gives no value: the one-value check would fail on it
    point = recording["messages"]["/biped/sweep"][0]
    assert value_at(point, parse_path("/biped/sweep.event_times[5]")[1]) == []


# -- against a live simulator ----------------------------------------------------------------------

def test_every_path_gives_one_number_per_message_of_a_live_simulator(layout, domain_id):
    """A simulator in-process on DDS plays one run; every topic a panel names is one it
    publishes, and every path gives one number in each message that arrives."""
    from biped_opt import ros
    from tests.nodes.test_nodes import call, serving_simulator

    topics = {parse_path(p)[0] for p in _paths(layout)}
    (scene,) = _panels(layout, "3D").values()
    got: dict[str, list[Any]] = defaultdict(list)
    with serving_simulator(domain_id) as (_graph, probe):
        offered = dict(probe.get_topic_names_and_types())
        # (the simulator's publishers exist once it is constructed: nothing to wait for on
        # the backend's own graph cache beyond discovery)
        deadline = time.monotonic() + 10.0
        while not (topics | set(scene["topics"])) <= set(offered) and \
                time.monotonic() < deadline:
            time.sleep(0.05)
            offered = dict(probe.get_topic_names_and_types())
        assert (topics | set(scene["topics"])) <= set(offered), \
            (topics | set(scene["topics"])) - set(offered)
        for topic in topics:
            (typename,) = offered[topic]
            probe.create_subscription(
                ros.message_type(typename), topic, got[topic].append,
                ros.QoSProfile(depth=1000, reliability=ros.ReliabilityPolicy.BEST_EFFORT))
        time.sleep(0.5)  # discovery
        # real time x4: a touchdown of ~1.6 time units plays in ~0.4 s, every sample shown
        reply = call(probe, ros.srvs.Simulate, "/biped/simulate", maneuver="touchdown",
                     theta0=0.1, inputs=[2.0, 0.5, 0.0], real_time_factor=4.0)
        assert reply.success, reply.message
        deadline = time.monotonic() + 10.0
        while not all(got[t] for t in topics) and time.monotonic() < deadline:
            time.sleep(0.05)
    for path in _paths(layout):
        topic, parts = parse_path(path)
        assert got[topic], f"{path}: no message on {topic} from a live simulator"
        for msg in got[topic]:
            (value,) = value_at(msg, parts)
            assert isinstance(value, (int, float)), (path, value)
