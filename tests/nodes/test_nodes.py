"""The three nodes launched in-process on real DDS: a fresh Context, unique domain and executor
thread per test (the Graph), clients in a separate test node of the same context."""

from __future__ import annotations

import contextlib
import math
import os
import signal
import struct
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from cyclonedds._clayer import ddspy_write

from biped_opt import ros
from biped_opt.nodes.graph import Graph
from biped_opt.nodes.recorder import SweepRequest
from biped_opt.nodes.sim_control import SERVICES
from biped_opt.paper.biped import simulate
from biped_opt.paper.problems import get_problem
from biped_opt.paper.solve import optimal_policy
from biped_opt.piecewise import theta_grid
from biped_opt.record import read_recording
from tests.conftest import signal_state

NS = 1_000_000_000


@pytest.fixture()
def graph(domain_id):
    g = Graph(domain_id=domain_id, overrides={"simulator": {"autostart": False}})
    yield g
    g.close()


@pytest.fixture()
def probe(graph):
    """A test node in the graph's context, spun by the graph's executor."""
    node = ros.Node("probe", context=graph.context)
    graph.executor.add_node(node)
    yield node
    graph.executor.remove_node(node)
    node.destroy_node()


@contextlib.contextmanager
def serving_simulator(domain_id, **parameters):
    """The graph in-process with the simulator's ``parameters`` (and autostart off), and a
    probe node of the test's own on its executor; everything closed on leaving."""
    with Graph(domain_id=domain_id,
               overrides={"simulator": {"autostart": False, **parameters}}) as g:
        node = ros.Node("probe", context=g.context)
        g.executor.add_node(node)
        try:
            yield g, node
        finally:
            g.executor.remove_node(node)
            node.destroy_node()


def call(node, srv, name, timeout=30.0, **fields):
    client = node.create_client(srv, name)
    assert client.wait_for_service(timeout_sec=10.0)
    request = srv.Request()
    for key, value in fields.items():
        setattr(request, key, value)
    done = threading.Event()
    future = client.call_async(request)
    future.add_done_callback(lambda _f: done.set())
    assert done.wait(timeout)
    return future.result()


def test_state_stream_has_the_modes_and_exact_event_stamps(graph, probe):
    states, modes = [], []
    # best effort as the publisher offers, but deep: the test is about stamps and order, and a
    # 5-deep reader drops samples whenever the loaded executor takes a burst late
    probe.create_subscription(ros.msgs.BipedState, "/biped/state", states.append,
                              ros.QoSProfile(depth=1000,
                                             reliability=ros.ReliabilityPolicy.BEST_EFFORT))
    probe.create_subscription(ros.msgs.ContactMode, "/biped/contact_mode", modes.append,
                              ros.QoSProfile(depth=10, reliability=ros.ReliabilityPolicy.RELIABLE,
                                             durability=ros.DurabilityPolicy.TRANSIENT_LOCAL))
    time.sleep(0.5)  # discovery
    reply = call(probe, ros.srvs.Simulate, "/biped/simulate", maneuver="touchdown", theta0=0.1,
                 inputs=[2.0, 0.5, 0.0], real_time_factor=2.0)
    assert reply.success
    tr = simulate("touchdown", 0.1, (2.0, 0.5), sample_dt=1 / 200)
    assert list(reply.mode_sequence) == [0, 1, 3]
    assert reply.outcome == tr.outcome  # same kernel, same numbers
    assert len(reply.states) == len(tr.samples)
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and (len(modes) < 3 or len(states) < len(tr.samples)):
        time.sleep(0.05)
    # contact modes: every change, stamped at start + exact event time (to the nanosecond)
    assert [m.mode for m in modes] == [0, 1, 3]
    start = modes[0].header.stamp.sec * NS + modes[0].header.stamp.nanosec
    for m, t_event in zip(modes[1:], tr.event_times):
        stamp = m.header.stamp.sec * NS + m.header.stamp.nanosec
        assert abs(stamp - start - round(t_event * NS)) <= 1
    # the state stream, in time order, with the modes switching at the events
    times = [s.t for s in states]
    assert times == sorted(times)
    seen = [s.contact_mode for s in states]
    assert [k for i, k in enumerate(seen) if i == 0 or seen[i - 1] != k] == [0, 1, 3]
    # loopback in one process at 2x real time: a best-effort stream still delivers (nearly) all
    assert len(states) >= 0.99 * len(tr.samples)


def test_optimiser_replies_equal_the_core(graph, probe):
    for maneuver, theta0 in (("touchdown", 0.05), ("touchdown", -0.03), ("liftoff", 0.01)):
        reply = call(probe, ros.srvs.OptimalPolicy, "/biped/optimal_policy", maneuver=maneuver,
                     theta0=theta0)
        core = optimal_policy(get_problem(maneuver), theta0)
        assert reply.success, reply.message
        np.testing.assert_array_equal(np.asarray(reply.policy), core.x)
        assert reply.value == core.value and reply.outcome == core.outcome
        assert list(reply.mode_sequence) == [int(m) for m in core.modes]
        left, right = np.asarray(reply.value_derivative)
        assert math.isfinite(left) and left == pytest.approx(right, rel=1e-9)  # smooth here
    # R5 through the service
    reply = call(probe, ros.srvs.OptimalPolicy, "/biped/optimal_policy", maneuver="touchdown",
                 theta0=0.05)
    assert abs(reply.value - 0.0194158739483) < 1e-8
    assert abs(reply.policy[0] - 1.2776719) < 1e-6


@pytest.mark.parametrize(
    ("maneuver", "theta0", "field"),
    [("touchdown", math.nan, "theta0"), ("liftoff", 0.5, "theta0"), ("hop", 0.1, "maneuver"),
     ("", 0.0, "maneuver"), ("touchdown", math.inf, "theta0")],
)
def test_bad_requests_are_refused_and_the_node_keeps_serving(graph, probe, maneuver, theta0,
                                                             field):
    reply = call(probe, ros.srvs.OptimalPolicy, "/biped/optimal_policy", maneuver=maneuver,
                 theta0=theta0)
    assert not reply.success and reply.message.startswith(f"{field}:")
    good = call(probe, ros.srvs.OptimalPolicy, "/biped/optimal_policy", maneuver="touchdown",
                theta0=0.02)
    assert good.success
    bad_sim = call(probe, ros.srvs.Simulate, "/biped/simulate", maneuver="touchdown",
                   theta0=0.1, inputs=[math.nan], real_time_factor=0.0)
    assert not bad_sim.success and bad_sim.message.startswith("inputs:")


#: the request fields after theta0 of each service: Simulate's empty inputs and
#: real_time_factor 0, OptimalPolicy's system and problem "" (length 1, the NUL, padding)
_TAILS = {"Simulate": bytes(24),
          "OptimalPolicy": struct.pack("<I", 1) + bytes(4) + struct.pack("<I", 1) + bytes(4)}


def _not_utf8_request(client, maneuver: bytes, theta0: float, srv: str):
    """A request whose maneuver is not UTF-8, written raw behind ``client``'s header (what a
    broken or hostile peer can send); the reply comes to ``client``'s future."""
    future = ros.Future()
    with client._pending_lock:
        seq = next(client._seq)
        client._pending[seq] = future
    text = struct.pack("<I", len(maneuver) + 1) + maneuver + b"\x00"
    text += bytes(-len(text) % 8)
    data = b"\x00\x01\x00\x00" + struct.pack("<Qq", client.guid, seq) + text
    data += struct.pack("<d", theta0) + _TAILS[srv]
    assert ddspy_write(client._writer._ref, data) >= 0
    return future


@pytest.mark.skipif(ros.BACKEND != "dds", reason="raw bytes are written through Cyclone")
@pytest.mark.parametrize(("service", "srv"), [("/biped/optimal_policy", "OptimalPolicy"),
                                               ("/biped/simulate", "Simulate")])
def test_no_request_can_take_a_node_down(graph, probe, capfd, service, srv):
    """Undecodable bytes, a megabyte-long maneuver name, absurd numbers: each is refused with a
    short message naming the field, the node logs a line and answers the next request."""
    srv_type = getattr(ros.srvs, srv)
    client = probe.create_client(srv_type, service)
    assert client.wait_for_service(timeout_sec=10.0)
    future = _not_utf8_request(client, b"touch\xffdown", 0.1, srv)
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    assert done.wait(30.0)
    assert not future.result().success
    assert future.result().message.startswith("malformed request: UnicodeDecodeError")
    huge = "x" * 1_000_000
    reply = call(probe, srv_type, service, maneuver=huge, theta0=0.1)
    assert not reply.success and reply.message.startswith("maneuver:")
    assert len(reply.message) < 200 and "(1000000 characters)" in reply.message
    for theta0 in (math.nan, -math.inf, 1e308, 5.0):
        reply = call(probe, srv_type, service, maneuver="touchdown", theta0=theta0)
        assert not reply.success and reply.message.startswith("theta0:")
    reply = call(probe, srv_type, service, maneuver="touchdown", theta0=-1e-6)
    assert reply.success
    err = capfd.readouterr().err
    assert "Traceback" not in err and "x" * 100 not in err


def test_eight_concurrent_clients_get_their_own_replies(graph, probe):
    """8 clients x 100 calls in flight together: every call is answered, once, with the answer
    to its own request. No request is ever sent twice: a reply not there within 30 s is lost.

    One client's first call once went unanswered now and then (in loaded runs): the service's
    reply step listed its writer's matched readers through cyclonedds' binding, which raises
    IndexError when a reader matches between its two calls (here: another client being
    created), and the pool thread's exception went unseen. Fixed in
    ``biped_opt.ros.dds.entities.matched_handles`` (tests/ros/test_robustness.py); the test
    runs beside the others again."""
    angles = np.linspace(-0.2, 0.2, 9)
    expected = {}
    for th in angles:  # fill the cache, and know each angle's answer
        r = call(probe, ros.srvs.OptimalPolicy, "/biped/optimal_policy", maneuver="touchdown",
                 theta0=float(th))
        expected[float(th)] = (r.value, tuple(np.asarray(r.policy)))
    errors: list[str] = []

    def client_loop(k: int) -> None:
        client = probe.create_client(ros.srvs.OptimalPolicy, "/biped/optimal_policy")
        assert client.wait_for_service(timeout_sec=10.0)
        for i in range(100):
            th = float(angles[(k + i) % len(angles)])
            request = ros.srvs.OptimalPolicy.Request()
            request.maneuver, request.theta0 = "touchdown", th
            done = threading.Event()
            future = client.call_async(request)
            future.add_done_callback(lambda _f, done=done: done.set())
            if not done.wait(30.0):
                with client._pending_lock:
                    pending = sorted(client._pending)
                errors.append(f"client {k} call {i}: no reply within 30 s (still pending: "
                              f"{pending}, matched server: {client.service_is_ready()})")
                return
            r = future.result()
            if (r.value, tuple(np.asarray(r.policy))) != expected[th]:
                errors.append(f"client {k} call {i}: reply for another request")
        if client.duplicate_replies:
            errors.append(f"client {k}: {client.duplicate_replies} duplicate replies")

    threads = [threading.Thread(target=client_loop, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(300.0)
    assert errors == []


def test_recorder_records_every_sample_through_the_graph(graph, tmp_path):
    """The file holds every sample of every trajectory: counts equal the trajectories' sample
    counts (the recorder takes them from the Simulate reply, not the best-effort topic)."""
    out = tmp_path / "sweep.mcap"
    summary = graph.recorder.record(SweepRequest(
        maneuver="liftoff", theta0_min=-0.1, theta0_max=0.1, num=5, optimal=True, output=out))
    rec = read_recording(out)
    assert rec.complete and summary.failed == 0
    points = rec.sweep_points()
    np.testing.assert_array_equal([p.theta0 for p in points], theta_grid(-0.1, 0.1, 5))
    assert 0.0 in [p.theta0 for p in points]
    total = 0
    for p in points:
        core = optimal_policy(get_problem("liftoff"), p.theta0)
        assert p.value == core.value and p.optimal
        tr = simulate("liftoff", p.theta0, core.inputs, sample_dt=1 / 200)
        assert len(rec.states_of(p.theta0)) == len(tr.samples)
        total += len(tr.samples)
    assert rec.counts["/biped/state"] == total
    assert rec.counts["/biped/contact_mode"] == sum(len(p.mode_sequence) for p in points)


def _node_process(domain_id, module, *ros_args):
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen(
        [sys.executable, "-m", f"biped_opt.nodes.{module}", "--ros-args", *ros_args],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )


@contextlib.contextmanager
def _outside_probe(domain_id):
    """A node in a context of its own (as another process would have), spun on demand."""
    ctx = ros.Context()
    ros.init(args=[], context=ctx, domain_id=domain_id)
    node = ros.Node("probe", context=ctx)
    executor = ros.SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    try:
        yield node, executor
    finally:
        executor.shutdown()
        node.destroy_node()
        ros.try_shutdown(context=ctx)


def _stop(proc, sig, ready):
    """Send ``sig``; the node must exit 0 promptly, having logged one ``ready`` line and no
    warning, error or traceback."""
    proc.send_signal(sig)
    try:
        _out, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        state = signal_state(proc.pid)
        proc.kill()
        raise AssertionError(f"no exit 30 s after signal {sig}: {state}") from None
    assert proc.returncode == 0, err
    assert "Traceback" not in err and "[ERROR]" not in err and "[WARN]" not in err, err
    assert [line.split("]: ", 1)[1] for line in err.splitlines() if "]: ready" in line] \
        == [ready], err


def test_node_in_a_subprocess_exits_cleanly_on_sigint(domain_id):
    proc = _node_process(domain_id, "optimiser", "-p", "touchdown.theta_star:=-0.05",
                         "-p", "worker:=w1")
    try:
        with _outside_probe(domain_id) as (node, executor):
            client = node.create_client(ros.srvs.OptimalPolicy, "/biped/optimal_policy")
            assert client.wait_for_service(timeout_sec=30.0)
            request = ros.srvs.OptimalPolicy.Request()
            request.maneuver, request.theta0 = "touchdown", 0.05
            future = client.call_async(request)
            executor.spin_until_future_complete(future, timeout_sec=60.0)
            reply = future.result()
        # the parameter given on the command line reached the node
        expected = optimal_policy(get_problem("touchdown", theta_star=-0.05), 0.05)
        assert reply.success and reply.value == expected.value
        _stop(proc, signal.SIGINT, "ready: serving /biped/optimal_policy, /optimiser/study/w1")
    finally:
        proc.kill()


def test_simulator_in_a_subprocess_exits_cleanly_on_sigterm(domain_id):
    """ros2 launch follows SIGINT with SIGTERM: a node must end cleanly on either."""
    proc = _node_process(domain_id, "simulator", "-p", "loop:=true")
    try:
        with _outside_probe(domain_id) as (node, executor):
            modes = []
            node.create_subscription(
                ros.msgs.ContactMode, "/biped/contact_mode", modes.append,
                ros.QoSProfile(depth=10, reliability=ros.ReliabilityPolicy.RELIABLE,
                               durability=ros.DurabilityPolicy.TRANSIENT_LOCAL))
            deadline = time.monotonic() + 30.0
            while not modes and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.1)
            assert modes, "the simulator never published its contact mode"
        _stop(proc, signal.SIGTERM,
              "ready: serving /biped/simulate, "
              + ", ".join(f"/simulator/{name}" for name in SERVICES)
              + ", /simulator/simulate_steps (action); publishing /biped/state, "
              "/biped/contact_mode, /clock, /tf, /biped/markers, /robot_description, "
              "/diagnostics, /biped/command (subscribed)")
    finally:
        proc.kill()


def test_the_simulated_clock_runs_on_across_runs(graph, probe):
    # ROS.md Sec. 6: each run starts where the previous one ended on the simulated clock, so
    # stamps never go back; a run's samples are stamped start + t to the nanosecond
    ends = []
    for th in (0.1, -0.05, 0.1):
        reply = call(probe, ros.srvs.Simulate, "/biped/simulate", maneuver="touchdown",
                     theta0=th, inputs=[2.0, 0.5, 0.0], real_time_factor=0.0)
        assert reply.success
        stamps = [s.header.stamp.sec * NS + s.header.stamp.nanosec for s in reply.states]
        start = stamps[0] - round(reply.states[0].t * NS)
        assert all(abs(ns - start - round(s.t * NS)) <= 1 for ns, s in zip(stamps, reply.states))
        if ends:
            assert start >= ends[-1]  # (not before the previous run's end)
            assert start - ends[-1] <= 1
        ends.append(start + round(reply.t_final * NS))
    assert ends[0] < ends[1] < ends[2]


def test_an_answer_asked_before_is_the_quick_reply(graph, probe):
    """The optimiser gives its service the answers it has by the request's own fields: the
    service sends them as requests arrive, never behind computations (tests/ros/
    test_fairness.py). The quick reply is the computed one field for field; a request not
    asked before, or asked with -0.0 for 0.0, has none."""
    first = call(probe, ros.srvs.OptimalPolicy, "/biped/optimal_policy", maneuver="touchdown",
                 theta0=0.0)
    assert first.success
    request = ros.srvs.OptimalPolicy.Request(maneuver="touchdown", theta0=0.0)
    quick = graph.optimiser._quick_reply(request)
    assert quick is not None
    for field in ("success", "message", "value", "outcome", "t_final"):
        assert getattr(quick, field) == getattr(first, field)
    for field in ("policy", "mode_sequence", "event_times", "value_derivative", "inputs"):
        np.testing.assert_array_equal(np.asarray(getattr(quick, field)),
                                      np.asarray(getattr(first, field)))
    assert graph.optimiser._quick_reply(
        ros.srvs.OptimalPolicy.Request(maneuver="touchdown", theta0=-0.0)) is None
    assert graph.optimiser._quick_reply(
        ros.srvs.OptimalPolicy.Request(maneuver="touchdown", theta0=0.01)) is None
    assert graph.optimiser._service.quick_reply == graph.optimiser._quick_reply
