"""The built-in backend on real Cyclone DDS: round trips, wire conventions, graph, CLI."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from biped_opt.ros import dds
from biped_opt.ros.dds import graph
from biped_opt.ros.interfaces import load_interfaces

IFC = load_interfaces()
STATE = IFC.message_class("biped_opt_interfaces/msg/BipedState")
POLICY = IFC.services["biped_opt_interfaces/srv/OptimalPolicy"]
ROOT = Path(__file__).resolve().parents[2]
XCDR1 = Policy.DataRepresentation(use_cdrv0_representation=True)


def _until(predicate, timeout=5.0, step=None):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        if step is not None:
            step()
        else:
            time.sleep(0.01)
    return predicate()


def _double(request, response):
    response.success = True
    response.message = request.maneuver
    response.value = 2.0 * request.theta0
    return response


def test_pub_sub_round_trip(context):
    node = dds.Node("talker", context=context, namespace="/biped")
    got = []
    node.create_subscription(STATE, "state", got.append, 10)
    pub = node.create_publisher(STATE, "state", dds.qos_profile_system_default)
    assert pub.topic_name == "/biped/state"
    ex = dds.SingleThreadedExecutor(context=context)
    ex.add_node(node)
    assert _until(lambda: pub.get_subscription_count() == 1)
    sent = STATE(maneuver="touchdown", theta0=0.1, q=[float(i) for i in range(7)],
                 contact_mode=3)
    sent.header.stamp = node.get_clock().now().to_msg()
    pub.publish(sent)
    assert _until(lambda: bool(got), step=lambda: ex.spin_once(timeout_sec=0.05))
    assert got[0] == sent
    with pytest.raises(TypeError, match="expected BipedState"):
        pub.publish(POLICY.Request())


def test_service_round_trip_and_timer(context):
    node = dds.Node("server", context=context)
    node.create_service(POLICY, "/biped/optimal_policy", _double)
    client = node.create_client(POLICY, "/biped/optimal_policy")
    ticks = []
    node.create_timer(0.01, lambda: ticks.append(time.monotonic()))
    assert client.wait_for_service(timeout_sec=5.0)
    future = client.call_async(POLICY.Request(maneuver="liftoff", theta0=0.25))
    dds.spin_until_future_complete(node, future, timeout_sec=5.0, executor=None)
    assert future.done()
    assert future.result() == POLICY.Response(success=True, message="liftoff", value=0.5)
    dds.spin_once(node, timeout_sec=0.05)
    assert _until(lambda: len(ticks) >= 3, step=lambda: dds.spin_once(node, timeout_sec=0.05))


def test_wait_for_service_times_out(context):
    node = dds.Node("lonely", context=context)
    client = node.create_client(POLICY, "/nobody_here")
    t0 = time.monotonic()
    assert not client.wait_for_service(timeout_sec=0.2)
    assert time.monotonic() - t0 >= 0.2


def test_thousand_calls_lose_none(context):
    node = dds.Node("busy", context=context)
    node.create_service(POLICY, "/busy", _double)
    client = node.create_client(POLICY, "/busy")
    assert client.wait_for_service(timeout_sec=5.0)
    ex = dds.SingleThreadedExecutor(context=context)
    ex.add_node(node)
    values = []
    for i in range(1000):  # back to back: each call right after the previous reply
        future = client.call_async(POLICY.Request(theta0=float(i)))
        ex.spin_until_future_complete(future, timeout_sec=5.0)
        assert future.done(), f"call {i} got no reply"
        values.append(future.result().value)
    assert values == [2.0 * i for i in range(1000)]


def test_replies_never_reach_the_wrong_client(context):
    node = dds.Node("shared", context=context)
    node.create_service(POLICY, "/shared", _double)
    clients = [node.create_client(POLICY, "/shared") for _ in range(2)]
    assert clients[0].guid != clients[1].guid
    assert all(c.wait_for_service(timeout_sec=5.0) for c in clients)
    ex = dds.MultiThreadedExecutor(num_threads=2, context=context)
    ex.add_node(node)
    futures = {0: [], 1: []}
    for i in range(50):
        # Both requests in flight at once: each reply reaches both clients' readers.
        pair = [client.call_async(POLICY.Request(maneuver=f"client{k}", theta0=float(i)))
                for k, client in enumerate(clients)]
        assert _until(lambda: all(f.done() for f in pair), timeout=5.0,  # noqa: B023
                      step=lambda: ex.spin_once(timeout_sec=0.05))
        for k in (0, 1):
            futures[k].append(pair[k])
    ex.shutdown()
    for k in (0, 1):
        assert [f.result().message for f in futures[k]] == [f"client{k}"] * 50
        assert [f.result().value for f in futures[k]] == [2.0 * i for i in range(50)]


def test_parameters(context):
    node = dds.Node("params", context=context,
                    parameter_overrides=[dds.Parameter("rate", value=50.0)],
                    cli_args=["--ros-args", "-p", "name:=walker", "-p", "n:=3",
                              "-p", "flag:=true", "-p", "xs:=[1.0, 2.0]"])
    assert node.declare_parameter("rate", 10.0).value == 50.0
    assert node.declare_parameter("name", "x").value == "walker"
    assert node.declare_parameter("n", 0).value == 3
    assert node.declare_parameter("flag", False).value is True
    assert node.declare_parameter("xs", []).value == [1.0, 2.0]
    assert node.declare_parameter("other", 1.5).value == 1.5
    assert node.get_parameter("rate").value == 50.0
    with pytest.raises(dds.ParameterNotDeclaredException, match="missing"):
        node.get_parameter("missing")
    with pytest.raises(ValueError, match="already been declared"):
        node.declare_parameter("rate", 1.0)


def test_parameters_are_statically_typed_as_in_rclpy(context):
    """An override of another type than the default's is refused when declared (rclpy's
    InvalidParameterTypeException, also a TypeError); an empty list fits any array type."""
    node = dds.Node("typed", context=context,
                    cli_args=["--ros-args", "-p", "rate:=fast", "-p", "n:=2.5", "-p", "xs:=[]",
                              "-p", "flag:=1", "-p", "ys:=[1, 2]"])
    with pytest.raises(dds.InvalidParameterTypeException,
                       match="'rate' to 'fast' of type 'STRING', expecting type 'DOUBLE'"):
        node.declare_parameter("rate", 10.0)
    with pytest.raises(TypeError, match="expecting type 'INTEGER'"):
        node.declare_parameter("n", 1)
    with pytest.raises(TypeError, match="of type 'INTEGER', expecting type 'BOOL'"):
        node.declare_parameter("flag", False)
    with pytest.raises(TypeError, match="'INTEGER_ARRAY', expecting type 'DOUBLE_ARRAY'"):
        node.declare_parameter("ys", [0.0])
    assert node.declare_parameter("xs", [0.0]).value == []
    assert node.declare_parameter("any", None).value is None  # no default: no type to keep


@pytest.mark.parametrize(("args", "match"), [
    (["-p", "noequals"], "couldn't parse parameter override rule -p 'noequals'"),
    (["-p", ":=1"], "couldn't parse parameter override rule"),
    (["-p"], "-p expects an argument"),
    (["--params-file"], "--params-file expects an argument"),
    (["-p", "xs:=[1, 'a']"], "an array parameter holds values of one type"),
])
def test_malformed_ros_args_are_one_clear_error(args, match):
    with pytest.raises(dds.RosArgumentError, match=match):
        dds.parse_ros_args(["--ros-args", *args])


def test_context_lifecycle(domain_id):
    ctx = dds.Context()
    assert not ctx.ok()
    with pytest.raises(dds.NotInitializedError):
        dds.Node("early", context=ctx)
    dds.init(context=ctx, domain_id=domain_id)
    assert dds.ok(context=ctx)
    node = dds.Node("n", context=ctx)
    stop = threading.Event()

    def spinner():
        dds.spin(node)
        stop.set()

    thread = threading.Thread(target=spinner, daemon=True)
    thread.start()
    time.sleep(0.1)
    dds.shutdown(context=ctx)  # wakes the spinning executor
    assert stop.wait(5.0)
    assert not ctx.ok()
    with pytest.raises(dds.NotInitializedError):
        dds.shutdown(context=ctx)
    dds.try_shutdown(context=ctx)


def _raw_participant(domain_id):
    return DomainParticipant(domain_id)


def test_wire_names_types_and_request_header(context, domain_id):
    """An independent raw-Cyclone client that knows only the conventions of ROS.md Sec. 2."""
    node = dds.Node("wire", context=context, namespace="/biped")
    node.create_service(POLICY, "optimal_policy", _double)
    dp = _raw_participant(domain_id)
    req_t = Topic(dp, "rq/biped/optimal_policyRequest", POLICY.RequestWire)
    rep_t = Topic(dp, "rr/biped/optimal_policyReply", POLICY.ResponseWire)
    assert req_t.get_type_name() == "biped_opt_interfaces::srv::dds_::OptimalPolicy_Request_"
    assert rep_t.get_type_name() == "biped_opt_interfaces::srv::dds_::OptimalPolicy_Response_"
    qos = Qos(XCDR1, Policy.Reliability.Reliable(duration(seconds=1)),
              Policy.Userdata(b"clientid=raw;"))
    writer = DataWriter(dp, req_t, qos=qos)
    reader = DataReader(dp, rep_t, qos=qos)
    ex = dds.SingleThreadedExecutor(context=context)
    ex.add_node(node)
    assert _until(lambda: writer.get_matched_subscriptions() and reader.get_matched_publications())
    # The server's endpoints carry serviceid= USER_DATA on both reader and writer.
    for data in (writer.get_matched_subscription_data(writer.get_matched_subscriptions()[0]),
                 reader.get_matched_publication_data(reader.get_matched_publications()[0])):
        assert bytes(data.qos[Policy.Userdata].data).startswith(b"serviceid=")
    wire = POLICY.RequestWire(body=POLICY.Request(maneuver="raw", theta0=1.5))
    wire.header.guid, wire.header.seq = 0xFEDCBA9876543210, 7
    writer.write(wire)
    replies = []

    def step():
        ex.spin_once(timeout_sec=0.05)
        replies.extend(reader.take(N=10))

    assert _until(lambda: bool(replies), step=step)
    assert replies[0].header.guid == 0xFEDCBA9876543210 and replies[0].header.seq == 7
    assert replies[0].body.value == 3.0 and replies[0].body.message == "raw"


def test_client_request_header_on_the_wire(context, domain_id):
    node = dds.Node("caller", context=context)
    client = node.create_client(POLICY, "/raw_service")
    dp = _raw_participant(domain_id)
    # Read the request as raw bytes through a type with only the header (+ opaque body).
    reader = DataReader(dp, Topic(dp, "rq/raw_serviceRequest", POLICY.RequestWire),
                        qos=Qos(XCDR1, Policy.Reliability.Reliable(duration(seconds=1)),
                                Policy.History.KeepLast(10)))
    assert _until(lambda: client._writer.get_matched_subscriptions()
                  and reader.get_matched_publications())
    client.call_async(POLICY.Request(maneuver="m", theta0=0.5))
    client.call_async(POLICY.Request(maneuver="m", theta0=0.5))
    got = []
    assert _until(lambda: got.extend(reader.take(N=10)) or len(got) == 2)
    assert [g.header.seq for g in got] == [1, 2]
    assert {g.header.guid for g in got} == {client.guid}
    assert client.guid == client._writer.get_instance_handle() & (2**64 - 1)
    raw = bytes(got[0].serialize(use_version_2=False))
    assert raw[:4] == b"\x00\x01\x00\x00"
    assert int.from_bytes(raw[4:12], "little") == client.guid
    assert int.from_bytes(raw[12:20], "little") == 1
    pub = node.create_publisher(STATE, "/raw_topic", 10)
    topic = Topic(dp, "rt/raw_topic", STATE)
    assert topic.get_type_name() == "biped_opt_interfaces::msg::dds_::BipedState_"
    sub = DataReader(dp, topic, qos=Qos(XCDR1))
    assert _until(lambda: pub.get_subscription_count() == 1 and sub.get_matched_publications())
    pub.publish(STATE(maneuver="seen"))
    seen = []
    assert _until(lambda: seen.extend(sub.take(N=5)) or bool(seen))
    assert seen[0].maneuver == "seen"


def test_graph_topic(context, domain_id):
    node = dds.Node("graph_node", context=context, namespace="/ns")
    pub = node.create_publisher(STATE, "s", 10)
    _, _, info_t = graph.graph_types("humble")
    dp = _raw_participant(domain_id)
    reader = DataReader(dp, Topic(dp, graph.GRAPH_TOPIC, info_t), qos=Qos(
        XCDR1, Policy.Reliability.Reliable(duration(seconds=1)),
        Policy.Durability.TransientLocal, Policy.History.KeepLast(1)))
    infos = []
    assert _until(lambda: infos.extend(reader.take(N=10)) or any(
        i.node_entities_info_seq for i in infos))
    info = [i for i in infos if i.node_entities_info_seq][-1]
    assert bytes(info.gid.data[:16]) == context.participant.get_guid().bytes
    assert bytes(info.gid.data[16:]) == bytes(8)  # Humble: zero-padded char[24]
    entry = info.node_entities_info_seq[0]
    assert (entry.node_namespace, entry.node_name) == ("/ns", "graph_node")
    writer_gids = [bytes(g.data[:16]) for g in entry.writer_gid_seq]
    assert pub._writer.get_guid().bytes in writer_gids


def test_jazzy_graph_layout(monkeypatch):
    monkeypatch.setenv("BIPED_OPT_GRAPH_LAYOUT", "jazzy")
    gid_t, _, info_t = graph.graph_types()
    assert len(gid_t().data) == 16
    sample = info_t(gid=gid_t(data=graph.gid_bytes(bytes(range(16)))))
    assert bytes(sample.serialize(use_version_2=False))[4:20] == bytes(range(16))
    monkeypatch.setenv("BIPED_OPT_GRAPH_LAYOUT", "iron")
    with pytest.raises(ValueError, match="humble"):
        graph.graph_layout()


def _env(domain_id):
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), ROS_LOCALHOST_ONLY="1",
               BIPED_OPT_BACKEND="dds", PYTHONPATH=str(ROOT))
    return env


def test_node_in_subprocess(context, domain_id):
    proc = subprocess.Popen(
        [sys.executable, "-m", "tests.ros._echo_node", "--ros-args", "-p", "prefix:=/far"],
        cwd=ROOT, env=_env(domain_id), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)
    try:
        node = dds.Node("near", context=context)
        states = []
        node.create_subscription(STATE, "/far/state", states.append, 10)
        client = node.create_client(POLICY, "/far/optimal_policy")
        assert client.wait_for_service(timeout_sec=15.0), proc.stderr.read() if proc.poll() else ""
        future = client.call_async(POLICY.Request(maneuver="across", theta0=0.75))
        dds.spin_until_future_complete(node, future, timeout_sec=5.0)
        assert future.result().message == "across" and future.result().value == 1.5
        assert future.result().mode_sequence == [1, 3]
        assert _until(lambda: bool(states), step=lambda: dds.spin_once(node, timeout_sec=0.05))
        assert states[0].maneuver == "across"
        executor = dds.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        values = []
        for i in range(1000):  # back to back across processes: none may be lost
            future = client.call_async(POLICY.Request(maneuver="n", theta0=float(i)))
            executor.spin_until_future_complete(future, timeout_sec=5.0)
            assert future.done(), f"cross-process call {i} got no reply"
            values.append(future.result().value)
        assert values == [2.0 * i for i in range(1000)]
    finally:
        proc.terminate()
        proc.wait(10)


def test_cyclonedds_cli_sees_ros_types(context, domain_id):
    cli = shutil.which("cyclonedds", path=str(Path(sys.executable).parent)) or shutil.which(
        "cyclonedds")
    if cli is None:
        pytest.skip("the cyclonedds CLI is not installed next to this interpreter")
    node = dds.Node("visible", context=context)
    node.create_publisher(STATE, "/biped/state", 10)
    node.create_service(POLICY, "/biped/optimal_policy", _double)
    # The CLI is plain Cyclone: give it the same loopback-only configuration.
    env = dict(_env(domain_id), CYCLONEDDS_URI=dds.loopback_config())
    out = subprocess.run([cli, "ls", "-i", str(domain_id), "-r", "2s",
                          "--suppress-progress-bar", "--color", "none"],
                         env=env, capture_output=True, text=True, timeout=30).stdout
    assert "rt/biped/state" in out
    assert "biped_opt_interfaces::msg::dds_::BipedState_" in out
    assert "rq/biped/optimal_policyRequest" in out and "rr/biped/optimal_policyReply" in out
    assert "ros_discovery_info" in out
    out = subprocess.run([cli, "typeof", "rt/biped/state", "-i", str(domain_id), "-r", "2s",
                          "--suppress-progress-bar", "--color", "none"],
                         env=env, capture_output=True, text=True, timeout=30).stdout
    assert "BipedState_" in out and "contact_force" in out


def test_endpoint_ids_follow_rmw_format(context):
    node = dds.Node("ids", context=context)
    client = node.create_client(POLICY, "/ids")
    service = node.create_service(POLICY, "/ids", _double)
    for text in (client.client_id, service.service_id):
        parts = text.split(".")
        assert len(parts) == 24  # Humble GID storage: 16-byte GUID + zero padding
        assert len(parts[0]) == 2 and all(1 <= len(p) <= 2 for p in parts)
        data = bytes(int(p, 16) for p in parts)
        assert data[:12] == context.participant.get_guid().bytes[:12]
        assert data[16:] == bytes(8)
    assert client.client_id != service.service_id


def test_jazzy_endpoints_carry_type_hash(monkeypatch, domain_id):
    monkeypatch.setenv("BIPED_OPT_GRAPH_LAYOUT", "jazzy")
    ctx = dds.Context()
    dds.init(context=ctx, domain_id=domain_id)
    try:
        node = dds.Node("jazzy", context=ctx)
        pub = node.create_publisher(STATE, "/jazzy_state", 10)
        service = node.create_service(POLICY, "/jazzy_srv", _double)
        assert len(service.service_id.split(".")) == 16
        dp = _raw_participant(domain_id)
        reader = DataReader(dp, Topic(dp, "rt/jazzy_state", STATE), qos=Qos(XCDR1))
        assert _until(lambda: reader.get_matched_publications())
        data = reader.get_matched_publication_data(reader.get_matched_publications()[0])
        expected = IFC.typestore.hash_rihs01("biped_opt_interfaces/msg/BipedState")
        assert bytes(data.qos[Policy.Userdata].data) == f"typehash={expected};".encode()
        assert pub.get_subscription_count() == 1
    finally:
        ctx.try_shutdown()


def test_localhost_environment(monkeypatch):
    for var in ("ROS_LOCALHOST_ONLY", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
        monkeypatch.delenv(var, raising=False)
    assert not dds.localhost_only()
    monkeypatch.setenv("ROS_LOCALHOST_ONLY", "1")
    assert dds.localhost_only()
    monkeypatch.setenv("ROS_LOCALHOST_ONLY", "0")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    assert dds.localhost_only()
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET")
    assert not dds.localhost_only()
    assert '<NetworkInterface address="127.0.0.1"/>' in dds.loopback_config()
    monkeypatch.setenv("ROS_DOMAIN_ID", "233")
    with pytest.raises(ValueError, match="0..232"):
        dds.Context().init()


def test_logger_prints_like_rclpy(context, capfd):
    node = dds.Node("chatty", context=context, namespace="/biped")
    node.get_logger().info("hello there")
    node.get_logger().debug("not shown at the default level")
    err = capfd.readouterr().err
    assert "[INFO]" in err and "[biped.chatty]: hello there" in err
    assert "not shown" not in err


def test_context_reinit_with_same_executor(domain_id):
    ctx = dds.Context()
    executor = dds.SingleThreadedExecutor(context=ctx)
    for round_ in range(2):
        dds.init(context=ctx, domain_id=domain_id)
        node = dds.Node("again", context=ctx)
        ticks = []
        node.create_timer(0.005, lambda: ticks.append(1))  # noqa: B023
        executor.add_node(node)
        assert _until(lambda: len(ticks) >= 2,  # noqa: B023
                      step=lambda: executor.spin_once(0.05)), round_
        executor.remove_node(node)
        dds.shutdown(context=ctx)
