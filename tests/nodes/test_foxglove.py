"""The live Foxglove view: the simulator and the bridge in-process on real DDS, and a real client
of the Foxglove WebSocket protocol under Node.js (``foxglove_client/client.js``: Foxglove's own
``@foxglove/ws-protocol`` client, ``@foxglove/rosmsg`` and ``@foxglove/rosmsg2-serialization``)
that subscribes, decodes each message with the schema the server advertised and prints JSON.

The client's modules are installed by ``make test`` (``npm ci`` in ``foxglove_client/``); without
node, npm or those modules the client tests skip and say why.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
import types
from collections import deque
from pathlib import Path

import numpy as np
import pytest
from cyclonedds.idl import IdlMeta, IdlStruct
from cyclonedds.idl import types as idl_types

from biped_opt import ros
from biped_opt.nodes import foxglove as foxglove_node
from biped_opt.nodes.foxglove import (
    LATCHED_MESSAGES,
    FoxgloveNode,
    adapted_qos,
    cdr_bytes,
    ros2msg_schema,
)
from biped_opt.nodes.simulator import CONTACT_MODE_QOS, SimulatorNode
from biped_opt.paper.biped import simulate
from biped_opt.ros.interfaces import load_interfaces
from tests.conftest import unique_domain_id

NS = 1_000_000_000
CLIENT_DIR = Path(__file__).resolve().parent / "foxglove_client"
CLIENT = CLIENT_DIR / "client.js"
MODULES = ("@foxglove/ws-protocol", "@foxglove/rosmsg", "@foxglove/rosmsg2-serialization", "ws")

#: the topics a client subscribes to and decodes, with their types. /tf (tf2_msgs/msg/TFMessage)
#: and /biped/markers (visualization_msgs/msg/MarkerArray) join with one line each once the
#: simulator publishes them.
LIVE_TOPICS = {
    "/biped/state": "biped_opt_interfaces/msg/BipedState",
    "/biped/contact_mode": "biped_opt_interfaces/msg/ContactMode",
    "/clock": "rosgraph_msgs/msg/Clock",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/biped/markers": "visualization_msgs/msg/MarkerArray",
    "/robot_description": "std_msgs/msg/String",
}
#: the run the tests play: the simulator's default maneuver, its samples at 200 Hz
MANEUVER, THETA0, INPUTS, RATE_HZ = "touchdown", 0.1, (2.0, 0.5, 0.0), 200.0


def _client_missing() -> str | None:
    if shutil.which("node") is None:
        return "node is not installed (the Foxglove client runs under Node.js)"
    if shutil.which("npm") is None:
        return "npm is not installed (it installs the Foxglove client's modules)"
    missing = [m for m in MODULES if not (CLIENT_DIR / "node_modules" / m).is_dir()]
    if missing:
        return (f"the Foxglove client's modules are not installed ({', '.join(missing)}): "
                "`make test` installs them (npm ci in tests/nodes/foxglove_client)")
    return None


needs_client = pytest.mark.skipif(_client_missing() is not None,
                                  reason=_client_missing() or "")


class Client:
    """``client.js`` as a process; its JSON lines gathered by a thread as they come."""

    def __init__(self, url: str, counts: dict[str, int], timeout_s: float = 30.0,
                 try_publish: bool = False, subprotocol: str | None = None) -> None:
        argv = ["node", str(CLIENT), url, "1", str(timeout_s)]
        argv += ["--try-publish"] if try_publish else []
        argv += [f"--subprotocol={subprotocol}"] if subprotocol else []
        argv += [f"{topic}:{n}" for topic, n in counts.items()]
        self.proc = subprocess.Popen(argv, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        self.lines: list[dict] = []
        self._cond = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.timeout_s = timeout_s

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._cond:
                self.lines.append(json.loads(line))
                self._cond.notify_all()

    def wait_for(self, predicate, timeout: float = 20.0) -> None:
        with self._cond:
            assert self._cond.wait_for(lambda: predicate(self.lines), timeout), self.lines

    def finish(self) -> int:
        code = self.proc.wait(self.timeout_s + 10)
        self._reader.join(10)
        return code

    def of(self, op: str, topic: str | None = None) -> list[dict]:
        return [x for x in self.lines if x["op"] == op and (topic is None or
                                                            x.get("topic") == topic)]


# -- the graph: a simulator and a bridge, one process, one domain ------------------------------

class Bridged:
    def __init__(self) -> None:
        self.context = ros.Context()
        ros.init(args=[], context=self.context, domain_id=unique_domain_id())
        self.simulator = SimulatorNode(context=self.context, parameter_overrides=[
            ros.Parameter("autostart", value=False),
            ros.Parameter("publish_rate_hz", value=RATE_HZ)])
        self.bridge = FoxgloveNode(context=self.context, parameter_overrides=[
            ros.Parameter("port", value=0), ros.Parameter("discovery_period", value=0.2)])
        self.probe = ros.Node("probe", context=self.context)
        self.executor = ros.MultiThreadedExecutor(num_threads=3, context=self.context)
        for node in (self.simulator, self.probe):
            self.executor.add_node(node)
        # the bridge on an executor of its own with one thread, as run_node spins it: several
        # threads may run one subscription's callbacks in another order than its samples came
        self.bridge_executor = ros.SingleThreadedExecutor(context=self.context)
        self.bridge_executor.add_node(self.bridge)
        self.threads = [threading.Thread(target=e.spin, daemon=True)
                        for e in (self.executor, self.bridge_executor)]
        for thread in self.threads:
            thread.start()
        self.url = f"ws://127.0.0.1:{self.bridge.port}"

    def simulate(self, real_time_factor: float):
        client = self.probe.create_client(ros.srvs.Simulate, "/biped/simulate")
        assert client.wait_for_service(timeout_sec=10.0)
        done = threading.Event()
        future = client.call_async(ros.srvs.Simulate.Request(
            maneuver=MANEUVER, theta0=THETA0, inputs=list(INPUTS),
            real_time_factor=real_time_factor))
        future.add_done_callback(lambda _f: done.set())
        assert done.wait(30.0)
        self.probe.destroy_client(client)
        reply = future.result()
        assert reply.success, reply.message
        return reply

    def close(self) -> None:
        for executor, thread in zip((self.executor, self.bridge_executor), self.threads):
            executor.shutdown(timeout_sec=10.0)
            thread.join(10.0)
        for node in (self.probe, self.bridge, self.simulator):
            node.destroy_node()
        ros.try_shutdown(context=self.context)


@pytest.fixture(scope="module")
def bridged():
    graph = Bridged()
    yield graph
    graph.close()


@pytest.fixture(scope="module")
def live(bridged):
    """One run played before any client connects, then a client subscribed to LIVE_TOPICS, then
    a second run at real time: (client, its lines, the run's reply, the first run's wall time)."""
    if _client_missing():
        pytest.skip(_client_missing())
    deadline = time.monotonic() + 10.0
    while set(LIVE_TOPICS) - set(bridged.bridge.bridged()) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert LIVE_TOPICS.items() <= bridged.bridge.bridged().items()
    first = bridged.simulate(0.0)  # (as fast as possible: all of it before a client exists)
    n_modes = len(first.mode_sequence)
    # the bridge receives and keeps the transient-local contact modes
    kept = bridged.bridge._bridged["/biped/contact_mode"]
    deadline = time.monotonic() + 10.0
    while len(kept.kept()) < n_modes and time.monotonic() < deadline:
        time.sleep(0.02)
    assert len(kept.kept()) == n_modes
    before_client_ns = time.time_ns()
    expected = simulate(MANEUVER, THETA0, INPUTS, sample_dt=1.0 / RATE_HZ)
    # states: enough of the second run to see it unfold, fewer than it has (a best-effort topic
    # may drop a sample under load)
    n_states = min(100, len(expected.samples) // 2)
    # every topic at least one message; the states and both runs' contact modes as said
    counts = {topic: 1 for topic in LIVE_TOPICS}
    counts.update({"/biped/state": n_states, "/biped/contact_mode": 2 * n_modes})
    client = Client(bridged.url, counts)
    # the first run's modes come from the bridge's memory; then a second run, live
    client.wait_for(lambda lines: len([x for x in lines if x["op"] == "message"
                                       and x["topic"] == "/biped/contact_mode"]) >= n_modes)
    reply = bridged.simulate(1.0)
    code = client.finish()
    assert code == 0, (code, client.lines[-5:], client.proc.stderr.read())
    return client, reply, expected, before_client_ns


# -- the protocol as a client sees it -----------------------------------------------------------

@needs_client
def test_the_server_is_read_only(live):
    client = live[0]
    info = client.of("serverInfo")
    assert len(info) == 1 and info[0]["capabilities"] == []  # no publish, services, parameters


@needs_client
@pytest.mark.parametrize("topic", sorted(LIVE_TOPICS))
def test_every_topic_is_advertised_as_ros2_and_decodes_with_its_schema(live, topic):
    client = live[0]
    [channel] = client.of("advertise", topic)
    assert channel == {"op": "advertise", "topic": topic, "encoding": "cdr",
                       "schemaName": LIVE_TOPICS[topic], "schemaEncoding": "ros2msg"}
    messages = client.of("message", topic)
    assert messages, f"no message on {topic}"
    # Foxglove's decoder read each payload to its end: schema and bytes agree field for field
    assert not any(m["trailingBytes"] for m in messages)
    stamps = [int(m["logTime"]) for m in messages]
    assert stamps == sorted(stamps)


@needs_client
def test_states_are_the_simulators_samples(live):
    client, reply, expected, _ = live
    states = [m["data"] for m in client.of("message", "/biped/state")]
    samples = expected.samples
    at: dict[float, list[int]] = {}  # (an event's time has a sample before and one after it)
    for i, t in enumerate(samples[:, 0].tolist()):
        at.setdefault(t, []).append(i)
    assert len(states) == min(100, len(samples) // 2)
    for state in states:
        # the same kernel, the same doubles through CDR and JSON (shortest round-trip text):
        # every sample equals the direct simulate call's at its time, to the bit
        assert state["maneuver"] == MANEUVER and state["theta0"] == THETA0
        assert all(math.isfinite(v) for v in state["q"] + state["qdot"])
        assert any(np.array_equal(state["q"], samples[i, 1:8])
                   and np.array_equal(state["qdot"], samples[i, 8:15])
                   and state["contact_mode"] == int(samples[i, 15]) for i in at[state["t"]])
    times = [s["t"] for s in states]
    assert times == sorted(times)
    assert times[-1] - times[0] > 0.1  # (a stretch of the run, not one instant)
    assert reply.outcome == expected.outcome


@needs_client
def test_the_robot_moves_in_foxglove_as_simulated(live):
    # what Foxglove's 3D panel gets: the URDF, and the body frame of every /tf equal to the
    # closed form of a sample of the direct simulate call ((x, 0, z), a turn by -th about y;
    # 1e-12: the same doubles through the scene's NumPy code)
    client, _reply, expected, _ = live
    [urdf] = [m["data"]["data"] for m in client.of("message", "/robot_description")]
    assert '<robot name="biped">' in urdf and '<joint name="base_link_joint" type="floating">' \
        in urdf
    samples = expected.samples
    frames = [m["data"]["transforms"] for m in client.of("message", "/tf")]
    assert frames
    for tf in frames:
        assert [f["child_frame_id"] for f in tf] == ["base_link", "left_foot", "right_foot"]
        body = tf[0]["transform"]
        x, z = body["translation"]["x"], body["translation"]["z"]
        i = int(np.argmin(np.abs(samples[:, 1] - x) + np.abs(samples[:, 2] - z)))
        th = samples[i, 3]
        assert abs(samples[i, 1] - x) < 1e-12 and abs(samples[i, 2] - z) < 1e-12
        assert body["rotation"]["y"] == pytest.approx(-math.sin(th / 2), abs=1e-12)
        assert body["rotation"]["w"] == pytest.approx(math.cos(th / 2), abs=1e-12)
    markers = client.of("message", "/biped/markers")[-1]["data"]["markers"]
    assert [m["ns"] for m in markers][:2] == ["biped/ground", "biped/body"]


@needs_client
def test_a_late_client_gets_the_contact_modes_kept_before_it_connected(live):
    client, _reply, expected, before_client_ns = live
    modes = client.of("message", "/biped/contact_mode")
    n = len(expected.mode_sequence)
    kept = modes[:n]
    assert [m["data"]["mode"] for m in kept] == [int(k) for k in expected.mode_sequence]
    # received by the bridge before the client existed (log time = the bridge's receipt time)
    assert all(int(m["logTime"]) < before_client_ns for m in kept)
    # and stamped with the exact event times after the first (to the nanosecond)
    stamp = [m["data"]["header"]["stamp"] for m in kept]
    start = stamp[0]["sec"] * NS + stamp[0]["nanosec"]
    for s, t_event in zip(stamp[1:], expected.event_times):
        assert abs(s["sec"] * NS + s["nanosec"] - start - round(t_event * NS)) <= 1


@needs_client
def test_a_client_cannot_publish(bridged):
    client = Client(bridged.url, {}, timeout_s=20.0, try_publish=True)
    assert client.finish() == 0, client.lines
    errors = [s["message"] for s in client.of("status") if s["level"] == 2]  # 2 = error
    assert "Server does not support clientPublish capability" in errors
    # nothing reached the graph
    topics = dict(bridged.probe.get_topic_names_and_types())
    assert "/biped/simulate_from_client" not in topics


# -- the subprotocols: foxglove.sdk.v1 and its older name ----------------------------------------

def _handshake(port: int, protocols: list[str] | None) -> tuple[int, dict[str, str], bytes]:
    """A WebSocket upgrade request written by hand (RFC 6455 Sec. 4.1) offering ``protocols``
    (None: no Sec-WebSocket-Protocol header): the answer's status, headers and what follows
    them (a 400's body, or the first frames after a 101)."""
    lines = ["GET / HTTP/1.1", f"Host: 127.0.0.1:{port}", "Upgrade: websocket",
             "Connection: Upgrade", "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==",
             "Sec-WebSocket-Version: 13"]
    if protocols is not None:
        lines.append(f"Sec-WebSocket-Protocol: {', '.join(protocols)}")
    with socket.create_connection(("127.0.0.1", port), timeout=10.0) as sock:
        sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        data = b""
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            head, sep, rest = data.partition(b"\r\n\r\n")
            if sep and (not head.startswith(b"HTTP/1.1 101") or len(rest) >= 2):
                if not head.startswith(b"HTTP/1.1 101"):
                    length = int(dict(
                        ln.lower().split(": ", 1) for ln in head.decode().split("\r\n")[1:]
                    ).get("content-length", "0"))
                    if len(rest) >= length:
                        break
                else:
                    break
            chunk = sock.recv(65536)
            if not chunk:
                break
            data += chunk
    head, _sep, rest = data.partition(b"\r\n\r\n")
    status_line, *header_lines = head.decode("latin-1").split("\r\n")
    headers = {k.lower(): v for k, v in (ln.split(": ", 1) for ln in header_lines)}
    return int(status_line.split()[1]), headers, rest


@pytest.mark.parametrize("offered", [["foxglove.sdk.v1"], ["foxglove.websocket.v1"],
                                     ["other", "foxglove.websocket.v1"],
                                     ["foxglove.websocket.v1", "foxglove.sdk.v1"]])
def test_either_subprotocol_name_is_answered_with_the_one_offered(bridged, offered):
    status, headers, rest = _handshake(bridged.bridge.port, offered)
    assert status == 101, (status, headers, rest)
    # the answer names a subprotocol the client offered (else a WebSocket client drops it):
    # the SDK's own name when offered, else the older one
    want = "foxglove.sdk.v1" if "foxglove.sdk.v1" in offered else "foxglove.websocket.v1"
    assert headers["sec-websocket-protocol"] == want
    # then the server speaks: a text frame (opcode 1) whose JSON is serverInfo
    assert rest[0] & 0x0F == 1, rest[:4]


@pytest.mark.parametrize("offered", [None, ["foxglove.websocket.v2"], ["ros1"]])
def test_other_subprotocols_get_a_400_that_names_the_accepted_ones(bridged, offered):
    status, headers, body = _handshake(bridged.bridge.port, offered)
    assert status == 400
    text = body.decode()
    assert int(headers["content-length"]) == len(body)
    assert "foxglove.sdk.v1" in text and "foxglove.websocket.v1" in text
    assert f"offered: {', '.join(offered) if offered else 'none'}" in text


def test_a_request_head_without_end_is_cut_off_at_its_bound(bridged):
    """A peer that sends header lines for ever is dropped after HEAD_MAX bytes, unanswered."""
    from biped_opt.nodes.ws_front import HANDSHAKE_S, HEAD_MAX

    with socket.create_connection(("127.0.0.1", bridged.bridge.port), timeout=10.0) as sock:
        sock.sendall(b"GET / HTTP/1.1\r\n")
        sent = 0
        try:
            while sent <= 4 * HEAD_MAX:
                sock.sendall(b"X-Filler: " + b"a" * 1000 + b"\r\n")
                sent += 1012
        except OSError:
            pass  # (the front closed the connection while we were still sending)
        sock.settimeout(HANDSHAKE_S / 2)  # (a front without the bound would wait for more)
        try:
            answer = sock.recv(1024)
        except ConnectionResetError:  # (closed with our bytes unread: a reset)
            answer = b""
    assert answer == b""  # closed, nothing said


def test_connections_beyond_the_bound_are_closed_at_once(bridged, monkeypatch):
    """Peers that open connections and say nothing hold at most MAX_CONNECTIONS places (each
    for at most HANDSHAKE_S); one more is closed unanswered, and a place freed serves again."""
    from biped_opt.nodes import ws_front

    monkeypatch.setattr(ws_front, "MAX_CONNECTIONS", 2)
    front = bridged.bridge._front
    idle = [socket.create_connection(("127.0.0.1", bridged.bridge.port), timeout=10.0)
            for _ in range(4)]  # (2 x MAX_CONNECTIONS sockets: the bound counts both ends)
    try:
        deadline = time.monotonic() + 10.0
        while front.connections < 4 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert front.connections >= 4
        # (at once: well before the HANDSHAKE_S an admitted connection would be given)
        with socket.create_connection(("127.0.0.1", bridged.bridge.port), timeout=2.0) as extra:
            assert extra.recv(1024) == b""  # closed, nothing said
    finally:
        for sock in idle:
            sock.close()
    deadline = time.monotonic() + 10.0
    while front.connections and time.monotonic() < deadline:
        time.sleep(0.02)
    assert _handshake(bridged.bridge.port, ["foxglove.sdk.v1"])[0] == 101


@needs_client
def test_a_ws_protocol_client_on_the_older_name_gets_the_topics(bridged):
    """Foxglove's ws-protocol client offering only foxglove.websocket.v1: served as well."""
    client = Client(bridged.url, {"/robot_description": 1}, timeout_s=20.0,
                    subprotocol="foxglove.websocket.v1")
    assert client.finish() == 0, (client.lines[-5:], client.proc.stderr.read())
    (info,) = client.of("serverInfo")
    assert info["capabilities"] == []
    (urdf,) = client.of("message", "/robot_description")
    assert urdf["data"]["data"].startswith("<?xml") and not urdf["trailingBytes"]


# -- the bytes ----------------------------------------------------------------------------------

def _filled(typestore, ros_type: str, depth: int = 0):
    """A rosbags message of ``ros_type`` with a distinct value in every field (and two
    elements in every sequence), for byte-level comparisons."""
    counter = iter(range(1, 1_000_000))
    cls = typestore.types[ros_type]
    _consts, fields = typestore.fielddefs[ros_type]
    values = {}

    def base(kind: str):
        k = next(counter)
        if kind == "string":
            return f"s{k}"
        if kind == "bool":
            return bool(k % 2)
        if kind.startswith("float"):
            return k + 0.25
        return k % 100

    for name, (kind, spec) in fields:
        kind = int(kind)
        if kind == 1:
            values[name] = base(spec[0])
        elif kind == 2:
            values[name] = _filled(typestore, spec, depth + 1)
        else:
            (sub_kind, sub_spec), size = spec
            n = size or 2
            if int(sub_kind) == 2:
                values[name] = [_filled(typestore, sub_spec, depth + 1) for _ in range(n)]
            else:
                dtype = {"float64": np.float64, "float32": np.float32, "uint8": np.uint8,
                         "int8": np.int8, "int32": np.int32, "uint32": np.uint32,
                         "int64": np.int64, "uint64": np.uint64, "int16": np.int16,
                         "uint16": np.uint16, "byte": np.uint8, "char": np.uint8,
                         "bool": np.bool_}.get(sub_spec[0])
                items = [base(sub_spec[0]) for _ in range(n)]
                values[name] = np.array(items, dtype=dtype) if dtype is not None else items
    return cls(**values)


@pytest.mark.skipif(ros.BACKEND != "dds", reason="the built-in backend's messages")
@pytest.mark.parametrize("ros_type", [
    "biped_opt_interfaces/msg/BipedState", "biped_opt_interfaces/msg/ContactMode",
    "biped_opt_interfaces/msg/SystemInfo", "tf2_msgs/msg/TFMessage",
    "visualization_msgs/msg/MarkerArray", "rosgraph_msgs/msg/Clock"])
def test_cdr_bytes_are_rosbags_bytes(ros_type):
    """What the bridge sends is what rosbags (and so our MCAP files) would write for the same
    message, the 4-byte encapsulation header (little-endian CDR) included."""
    ifc = load_interfaces()
    typestore = ifc.typestore
    reference = _filled(typestore, ros_type)
    expected = bytes(typestore.serialize_cdr(reference, ros_type))
    msg = ifc.message_class(ros_type).deserialize(expected)
    data = cdr_bytes(msg)
    assert data[:4] == b"\x00\x01\x00\x00"
    assert data == expected
    # and the field values made it through the backend's class, not just the bytes
    again = typestore.deserialize_cdr(data, ros_type)
    assert bytes(typestore.serialize_cdr(again, ros_type)) == expected


def test_a_state_built_on_the_backend_serializes_as_rosbags_builds_it():
    """The same BipedState written field by field in both worlds: the same bytes."""
    if ros.BACKEND != "dds":
        pytest.skip("the built-in backend's messages")
    ifc = load_interfaces()
    typestore = ifc.typestore
    name = "biped_opt_interfaces/msg/BipedState"
    q = np.linspace(-1.0, 1.0, 7)
    fields = dict(maneuver="touchdown", theta0=0.1, t=0.25, contact_mode=3)
    header = dict(frame_id="biped")
    msg = ifc.message_class(name)(
        header=ifc.message_class("std_msgs/msg/Header")(
            stamp=ifc.message_class("builtin_interfaces/msg/Time")(sec=7, nanosec=9), **header),
        q=list(q), qdot=list(-q), contact_force=[1.5, 2.5], **fields)
    T = typestore.types
    ref = T[name](
        header=T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=7, nanosec=9), **header),
        q=q, qdot=-q, contact_force=np.array([1.5, 2.5]), **fields)
    assert cdr_bytes(msg) == bytes(typestore.serialize_cdr(ref, name))


def test_the_schema_is_the_recordings_schema():
    """ROS 2's concatenated .msg text, each nested type after a line of '=' and 'MSG: pkg/Name'
    (what our MCAP files carry, so a live view and a recording decode alike)."""
    text = ros2msg_schema("biped_opt_interfaces/msg/BipedState").decode()
    assert text.startswith("std_msgs/Header header")
    assert f"{'=' * 80}\nMSG: std_msgs/Header\n" in text
    assert f"{'=' * 80}\nMSG: builtin_interfaces/Time\n" in text


# -- QoS -----------------------------------------------------------------------------------------

def _qos(reliable: bool, latched: bool, depth: int = 10):
    return ros.QoSProfile(
        depth=depth,
        reliability=ros.ReliabilityPolicy.RELIABLE if reliable else
        ros.ReliabilityPolicy.BEST_EFFORT,
        durability=ros.DurabilityPolicy.TRANSIENT_LOCAL if latched else
        ros.DurabilityPolicy.VOLATILE)


@pytest.mark.parametrize(("offered", "reliable", "latched", "depth"), [
    ([(True, True, 10)], True, True, 10),  # /biped/contact_mode: all of its history
    ([(True, True, 1)], True, True, 1),  # /biped/system_info, /robot_description
    ([(False, False, 5)], False, False, 100),  # /biped/state
    ([(True, False, 10), (False, False, 5)], False, False, 100),  # best effort hears both
    ([(True, True, 10), (True, False, 10)], True, False, 100),  # volatile matches both
    ([(True, True, 100_000)], True, True, LATCHED_MESSAGES),  # bounded
])
def test_the_subscription_matches_every_publisher(offered, reliable, latched, depth):
    profile = adapted_qos([_qos(*o) for o in offered])
    assert (profile.reliability == ros.ReliabilityPolicy.RELIABLE) == reliable
    assert (profile.durability == ros.DurabilityPolicy.TRANSIENT_LOCAL) == latched
    assert profile.depth == depth


@pytest.mark.skipif(ros.BACKEND != "dds", reason="the built-in backend's graph queries")
def test_the_graph_lists_topics_and_what_their_publishers_offer(domain_id):
    ctx = ros.Context()
    ros.init(args=[], context=ctx, domain_id=domain_id)
    try:
        node = ros.Node("lister", context=ctx)
        node.create_publisher(ros.msgs.ContactMode, "/biped/contact_mode", CONTACT_MODE_QOS)
        node.create_publisher(ros.msgs.BipedState, "state", ros.qos_profile_sensor_data)
        node.create_subscription(ros.std_msgs.Header, "/only_read", lambda _m: None, 10)
        deadline = time.monotonic() + 5.0
        while len(node.get_topic_names_and_types()) < 3 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert node.get_topic_names_and_types() == [
            ("/biped/contact_mode", ["biped_opt_interfaces/msg/ContactMode"]),
            ("/only_read", ["std_msgs/msg/Header"]),
            ("/state", ["biped_opt_interfaces/msg/BipedState"])]
        [mode] = node.get_publishers_info_by_topic("/biped/contact_mode")
        assert mode.topic_type == "biped_opt_interfaces/msg/ContactMode"
        assert (mode.qos_profile.reliability, mode.qos_profile.durability,
                mode.qos_profile.depth) == (ros.ReliabilityPolicy.RELIABLE,
                                            ros.DurabilityPolicy.TRANSIENT_LOCAL, 10)
        [state] = node.get_publishers_info_by_topic("state")  # (resolved as rclpy does)
        assert (state.qos_profile.reliability, state.qos_profile.durability,
                state.qos_profile.depth) == (ros.ReliabilityPolicy.BEST_EFFORT,
                                             ros.DurabilityPolicy.VOLATILE, 5)
        assert node.get_publishers_info_by_topic("/only_read") == []
    finally:
        ros.try_shutdown(context=ctx)


# -- parameters ---------------------------------------------------------------------------------

def _busy_port() -> socket.socket:
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen(1)
    return sock


@pytest.mark.parametrize(("param", "message"), [
    ("port:=70000", "foxglove: error: port must be an integer in 0..65535, got 70000"),
    ("port:=-1", "foxglove: error: port must be an integer >= 0, got -1"),
    ("host:=' '", "foxglove: error: host must be a host name or address, got ' '"),
    ("topics:=[biped/state]", "foxglove: error: topics: 'biped/state' is not an absolute "
                              "topic name (/a/b)"),
    ("discovery_period:=0.0", "foxglove: error: discovery_period must be a number > 0, got 0.0"),
    ("max_message_bytes:=100", "foxglove: error: max_message_bytes must be an integer >= 1024"),
    ("client_queue_bytes:=2048", "foxglove: error: client_queue_bytes (2048) must hold at least "
                                 "one message of max_message_bytes (65536)"),
    ("port:=BUSY", "foxglove: error: host, port: cannot listen on 127.0.0.1:BUSY: Address "
                   "already in use"),
])
def test_a_bad_parameter_ends_the_node_with_status_2_and_one_line(domain_id, param, message):
    sock = _busy_port()
    busy = str(sock.getsockname()[1])
    try:
        env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
        out = subprocess.run([sys.executable, "-m", "biped_opt.nodes.foxglove", "--ros-args",
                              "-p", param.replace("BUSY", busy)], env=env, capture_output=True,
                             text=True, timeout=60)
    finally:
        sock.close()
    assert out.returncode == 2, out.stderr
    assert out.stderr.strip().splitlines() == [out.stderr.strip()]
    assert out.stderr.startswith(message.replace("BUSY", busy)), out.stderr


@pytest.mark.parametrize("signum", [2, 15])  # SIGINT, SIGTERM
def test_a_signal_stops_the_bridge_cleanly_while_it_queries_the_graph(domain_id, signum):
    """A discovery every 10 ms: the signal lands during a graph query more often than not, and
    still ends the node with status 0 and nothing on stderr but its log lines."""
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    proc = subprocess.Popen([sys.executable, "-m", "biped_opt.nodes.foxglove", "--ros-args",
                             "-p", "port:=0", "-p", "discovery_period:=0.01"], env=env,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    try:  # (the bridge is killed whatever fails: a leftover one would serve a later test)
        lines = [proc.stderr.readline()]
        assert "ready: serving ws://127.0.0.1:" in lines[0], lines
        time.sleep(1.0)
        proc.send_signal(signum)
        code = proc.wait(30)
    finally:
        proc.kill()
    lines += proc.stderr.read().splitlines()
    assert code == 0, lines
    assert not any("Traceback" in line or "rror" in line for line in lines), lines


# -- bounds ---------------------------------------------------------------------------------------

def _bridge_of(domain_id, **params):
    """A context with a publisher on /a and /b (std_msgs/msg/Header) and a bridge with
    ``params``."""
    ctx = ros.Context()
    ros.init(args=[], context=ctx, domain_id=domain_id)
    node = ros.Node("publishers", context=ctx)
    for topic in ("/a", "/b"):
        node.create_publisher(ros.std_msgs.Header, topic, 10)
    bridge = FoxgloveNode(context=ctx, parameter_overrides=[
        ros.Parameter("port", value=0), ros.Parameter("discovery_period", value=0.05),
        *(ros.Parameter(k, value=v) for k, v in params.items())])
    return ctx, bridge


def _discovered(ctx, bridge, count: int) -> dict[str, str]:
    executor = ros.SingleThreadedExecutor(context=ctx)
    executor.add_node(bridge)
    deadline = time.monotonic() + 5.0
    while len(bridge.bridged()) < count and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    for _ in range(10):  # a few more discoveries: nothing beyond ``count`` comes
        executor.spin_once(timeout_sec=0.05)
    executor.shutdown()
    return bridge.bridged()


def test_only_the_topics_asked_for_are_served(domain_id):
    ctx, bridge = _bridge_of(domain_id, topics=["/b"])
    try:
        assert _discovered(ctx, bridge, 1) == {"/b": "std_msgs/msg/Header"}
    finally:
        ros.try_shutdown(context=ctx)


def test_at_most_max_channels_topics_are_served(domain_id, monkeypatch, capfd):
    monkeypatch.setattr(foxglove_node, "MAX_CHANNELS", 1)
    ctx, bridge = _bridge_of(domain_id)
    try:
        served = _discovered(ctx, bridge, 1)
        assert len(served) == 1 and set(served) <= {"/a", "/b"}
        [other] = {"/a", "/b"} - set(served)
        assert f"not serving {other}: already serving 1 topics" in capfd.readouterr().err
    finally:
        ros.try_shutdown(context=ctx)


def test_what_a_latched_topic_keeps_is_bounded(monkeypatch):
    monkeypatch.setattr(foxglove_node, "LATCHED_BYTES", 250)
    entry = foxglove_node._Bridged(ros_type="std_msgs/msg/Header", channel=None,
                                   encode=bytes, latched=deque(maxlen=3))
    for k in range(5):
        entry.keep(bytes([k]) * 100, k)
    # three fit the count, two the bytes: the newest two
    assert entry.kept() == [(bytes([3]) * 100, 3), (bytes([4]) * 100, 4)]
    assert entry.latched_bytes == 200


def _unknown_type() -> type:
    """A DDS type that no interface defines, named as rmw names ROS types."""
    typename = "nosuch_pkg::msg::dds_::Thing_"
    namespace = IdlMeta.__prepare__("Thing", (IdlStruct,), typename=typename)
    namespace["__annotations__"]["x"] = idl_types.int32
    namespace.update({"x": 0, "__module__": __name__})
    return dataclasses.dataclass(IdlMeta("Thing", (IdlStruct,), namespace, typename=typename))


@pytest.mark.skipif(ros.BACKEND != "dds", reason="raw DDS writers")
def test_topics_a_peer_names_or_types_badly_are_left_out(domain_id, capfd):
    """Any peer on the domain names topics and types: a name rcl would refuse, and a type no
    interface defines, are not served (one log line each) and the good topics are."""
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic

    ctx, bridge = _bridge_of(domain_id)
    try:
        participant = ctx.participant
        writers = [DataWriter(participant, Topic(participant, "rt/9lives",
                                                 ros.msgs.ContactMode)),
                   DataWriter(participant, Topic(participant, "rt/thing", _unknown_type()))]
        assert _discovered(ctx, bridge, 2) == {"/a": "std_msgs/msg/Header",
                                               "/b": "std_msgs/msg/Header"}
        err = capfd.readouterr().err
        assert "not serving '/9lives': not a topic name" in err
        assert "not serving /thing: type 'nosuch_pkg/msg/Thing' is not known" in err
        del writers
    finally:
        ros.try_shutdown(context=ctx)


class _Recorded:
    """A channel that records what is logged on it."""

    def __init__(self) -> None:
        self.logged: list[tuple[bytes, int]] = []

    def id(self) -> int:
        return 4242

    def log(self, data: bytes, *, log_time: int) -> None:
        self.logged.append((data, log_time))

    def close(self) -> None:
        pass


def test_kept_messages_go_out_again_at_most_once_a_replay_interval(domain_id, monkeypatch):
    """A client that subscribes over and over makes the bridge resend a transient-local topic's
    kept messages once per interval, not once per subscription."""
    monkeypatch.setattr(foxglove_node, "REPLAY_MIN_INTERVAL_S", 0.3)
    ctx, bridge = _bridge_of(domain_id, topics=["/none"])
    try:
        channel = _Recorded()
        entry = foxglove_node._Bridged(ros_type="std_msgs/msg/Header", channel=channel,
                                       encode=bytes, latched=deque(maxlen=1))
        entry.keep(b"kept", 7)
        with bridge._lock:
            bridge._bridged["/latched"] = entry
        view = types.SimpleNamespace(id=channel.id(), topic="/latched")  # (as the SDK's)
        for _ in range(5):  # five subscriptions within the interval: one replay
            bridge._listener.on_subscribe(None, view)
            bridge._replay()
        assert channel.logged == [(b"kept", 7)]
        time.sleep(0.35)  # then the subscriptions that waited get theirs, once
        bridge._replay()
        bridge._replay()
        assert channel.logged == [(b"kept", 7)] * 2
        with bridge._lock:
            del bridge._bridged["/latched"]
    finally:
        ros.try_shutdown(context=ctx)


def test_a_clients_queue_holds_at_most_its_budget_in_messages_of_the_largest_size():
    assert foxglove_node.backlog(foxglove_node.CLIENT_QUEUE_BYTES,
                                 foxglove_node.MAX_MESSAGE_BYTES) == 256
    assert foxglove_node.backlog(1 << 20, 100_000) == 10
    assert foxglove_node.backlog(1 << 40, 1024) == foxglove_node.BACKLOG  # (the SDK's most)


def test_a_message_larger_than_the_limit_is_not_forwarded(domain_id, capfd):
    ctx, bridge = _bridge_of(domain_id, topics=["/none"], max_message_bytes=2048)
    try:
        channel = _Recorded()
        entry = foxglove_node._Bridged(ros_type="std_msgs/msg/String", channel=channel,
                                       encode=bytes)
        for size in (10, 2048, 2049, 100_000, 20):
            bridge._forward(entry, b"x" * size, "/big")
        assert [len(d) for d, _ in channel.logged] == [10, 2048, 20]
        assert bridge.oversized == {"/big": 2}
        assert capfd.readouterr().err.count("not forwarding messages of /big larger than "
                                            "max_message_bytes = 2048") == 1
    finally:
        ros.try_shutdown(context=ctx)


def test_clients_that_never_read_cost_the_bridge_at_most_their_budget(domain_id):
    """Two raw WebSocket clients subscribe and never read while a peer publishes 400 messages
    of 100 KB (bench/foxglove_backlog.py): with a budget of 1 MiB a client (10 messages of at
    most 100,000 bytes) the bridge grows by a few MB, not by the 80 MB those messages are; the
    clients stay connected (the SDK drops their oldest messages)."""
    from bench.foxglove_backlog import measure

    result = measure(domain_id, clients=2, messages=400, size=99_000,
                     parameters=["max_message_bytes:=100000", "client_queue_bytes:=1048576"])
    assert result["still_connected"] == 2
    assert result["rss_after_mib"] - result["rss_before_mib"] < 30, result
