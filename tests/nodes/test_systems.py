"""The ROS graph serving other systems than the biped (rocking bar, 3-leg walker) in-process on
real DDS: SystemInfo on the latched topic, SystemState samples equal to the compiled system's,
sweeps recorded to MCAP and read back by mcap-ros2-support, bad systems refused clearly."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from biped_opt import ros
from biped_opt.errors import BipedOptError
from biped_opt.nodes import convert
from biped_opt.nodes.graph import Graph
from biped_opt.nodes.recorder import SweepRequest
from biped_opt.nodes.simulator import SYSTEM_INFO_QOS
from biped_opt.piecewise import theta_grid
from biped_opt.simulation.compiled import CompiledSystem

from .test_nodes import call

NS = convert.NS


def _ns(stamp) -> int:
    return stamp.sec * NS + stamp.nanosec

#: the node and the test run the same compiled kernel on the same inputs, and the messages
#: carry float64: the numbers agree to the last bit; 1e-12 allows for nothing but that
TOL = 1e-12

#: (system, maneuver, s, inputs) of each served system; the walker's touchdown at s = 0.1
#: visits four contact modes (masks 0, 1, 3, 7), the bar's drop has impacts without contact
CASES = {
    "rocking_bar": ("drop", 0.1, [0.2]),
    "walker3_coupled": ("touchdown", 0.1, [0.5, 0.2]),
}


@pytest.fixture(params=sorted(CASES))
def served(request, domain_id):
    name = request.param
    g = Graph(domain_id=domain_id, overrides={
        "simulator": {"autostart": False, "system": name}, "recorder": {"system": name}})
    probe = ros.Node("probe", context=g.context)
    g.executor.add_node(probe)
    yield name, g, probe
    g.executor.remove_node(probe)
    probe.destroy_node()
    g.close()


def _core(name, maneuver, s, inputs):
    compiled = CompiledSystem(name)
    return compiled, compiled.simulate(maneuver, s, inputs, sample_dt=1 / 200)


def test_simulator_serves_the_system(served):
    name, _graph, probe = served
    maneuver, s, inputs = CASES[name]
    infos, states = [], []
    probe.create_subscription(ros.msgs.SystemInfo, "/biped/system_info", infos.append,
                              SYSTEM_INFO_QOS)
    probe.create_subscription(ros.msgs.SystemState, "/biped/system_state", states.append,
                              ros.QoSProfile(depth=5000,
                                             reliability=ros.ReliabilityPolicy.BEST_EFFORT))
    time.sleep(0.5)  # discovery
    reply = call(probe, ros.srvs.Simulate, "/biped/simulate", maneuver=maneuver, theta0=s,
                 inputs=inputs, real_time_factor=0.0)
    compiled, tr = _core(name, maneuver, s, inputs)
    d, n = len(compiled.system.q), len(compiled.system.constraints)
    assert reply.success, reply.message
    assert list(reply.contact_modes) == list(tr.modes)
    assert list(reply.mode_sequence) == [] and list(reply.states) == []  # the biped's fields
    np.testing.assert_allclose(reply.event_times, tr.event_times, rtol=0, atol=TOL)
    assert abs(reply.outcome - tr.outcome) <= TOL and abs(reply.t_final - tr.t_final) <= TOL
    got = np.array([[m.t, *m.q, *m.qdot, m.contact_mode, *m.contact_force]
                    for m in reply.system_states])
    assert all(len(m.q) == len(m.qdot) == d and len(m.contact_force) == n
               for m in reply.system_states)
    assert got.shape == tr.samples.shape
    np.testing.assert_allclose(got, tr.samples, rtol=0, atol=TOL)
    assert {m.system for m in reply.system_states} == {tr.system}
    # the latched description, and the live stream (best effort, loopback: nearly all of it)
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and (not infos or len(states) < len(tr.samples)):
        time.sleep(0.05)
    assert len(infos) == 1
    assert convert.message_fields(infos[0], convert.SYSTEM_INFO_FIELDS) == \
        convert.system_info_fields(compiled, name)
    assert len(states) >= 0.99 * len(tr.samples)
    by_t: dict[float, list] = {}  # (an event has two samples at its time: before and after)
    for row in tr.samples:
        by_t.setdefault(row[0], []).append(row)
    for m in states:
        row = np.array([m.t, *m.q, *m.qdot, m.contact_mode, *m.contact_force])
        assert min(np.max(np.abs(row - ref)) for ref in by_t[m.t]) <= TOL


def test_bad_requests_are_refused_and_the_system_keeps_serving(served):
    name, _graph, probe = served
    maneuver, s, inputs = CASES[name]
    compiled = CompiledSystem(name)
    for fields, start in (
        ({"maneuver": "hop", "theta0": s}, "maneuver:"),
        ({"maneuver": "x" * 100_000, "theta0": s}, "maneuver:"),
        ({"maneuver": maneuver, "theta0": math.nan}, "theta0:"),
        ({"maneuver": maneuver, "theta0": s, "inputs": [1.0] * 9}, "inputs:"),
        ({"maneuver": maneuver, "theta0": s, "inputs": [math.inf]}, "inputs:"),
    ):
        reply = call(probe, ros.srvs.Simulate, "/biped/simulate", **fields)
        assert not reply.success and reply.message.startswith(start), reply.message
        assert len(reply.message) < 300
    reply = call(probe, ros.srvs.Simulate, "/biped/simulate", maneuver="touchdown" if
                 name == "rocking_bar" else "drop", theta0=s)
    assert not reply.success and ", ".join(compiled.maneuvers) in reply.message
    good = call(probe, ros.srvs.Simulate, "/biped/simulate", maneuver=maneuver, theta0=s,
                inputs=inputs)
    assert good.success


def test_recorder_records_the_system_and_mcap_ros2_reads_it(served, tmp_path):
    """A fixed-input sweep over s through the graph: mcap-ros2-support decodes every
    SystemState of the file, equal to the compiled system's samples."""
    name, graph, _probe = served
    maneuver, _s, inputs = CASES[name]
    out = tmp_path / f"{name}.mcap"
    summary = graph.recorder.record(SweepRequest(
        maneuver=maneuver, theta0_min=-0.1, theta0_max=0.1, num=5, optimal=False, output=out,
        fixed_inputs=tuple(inputs), system=name))
    assert summary.failed == 0 and summary.recorded == 5
    compiled = CompiledSystem(name)
    full = [*inputs, *[0.0] * (len(compiled.inputs) - len(inputs))]
    by_s: dict[float, list] = {}
    points, infos = [], []
    scene: dict[str, list] = {}
    state_msgs: list = []
    with open(out, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        for _schema, channel, _message, msg in reader.iter_decoded_messages():
            if channel.topic == "/biped/system_state":
                state_msgs.append(msg)
                by_s.setdefault(msg.s, []).append(
                    [msg.t, *msg.q, *msg.qdot, msg.contact_mode, *msg.contact_force])
            elif channel.topic == "/biped/sweep":
                points.append(msg)
            elif channel.topic == "/biped/system_info":
                infos.append(msg)
            else:
                scene.setdefault(channel.topic, []).append(msg)
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert sorted(by_s) == list(theta_grid(-0.1, 0.1, 5))
    for s, rows in by_s.items():
        tr = compiled.simulate(maneuver, s, full, sample_dt=1 / 200)
        np.testing.assert_allclose(np.array(rows), tr.samples, rtol=0, atol=TOL)
        point = next(p for p in points if p.theta0 == s)
        assert list(point.mode_sequence) == list(tr.modes)
        assert abs(point.outcome - tr.outcome) <= TOL and list(point.policy) == full
    assert len(infos) == 1 and list(infos[0].constraints) == list(compiled.system.constraints)
    # the scene: one URDF; /clock, /tf and markers at 50 samples per unit of time (the
    # recorder's default), every event and the last sample, at stamps of state samples; the
    # body frame is (x, 0, z) turned by -th about y, in closed form from the recorded state
    assert len(scene["/robot_description"]) == 1
    assert "<robot name=" in scene["/robot_description"][0].data
    assert len(scene["/clock"]) == len(scene["/tf"]) == len(scene["/biped/markers"])
    states = {_ns(m.header.stamp): m for m in state_msgs}
    stamps = [_ns(tf.transforms[0].header.stamp) for tf in scene["/tf"]]
    assert len(set(stamps)) == len(stamps)  # no stamp twice
    assert [c.clock.sec * NS + c.clock.nanosec for c in scene["/clock"]] == stamps
    for point in points:  # each run's last sample is shown
        assert _ns(point.header.stamp) + round(point.t_final * NS) in stamps
    for tf in scene["/tf"]:
        body = tf.transforms[0]
        assert body.header.frame_id == "world" and body.child_frame_id == "base_link"
        state = states[_ns(body.header.stamp)]
        x, z, th = state.q[0], state.q[1], state.q[2]
        move = body.transform
        assert (move.translation.x, move.translation.y, move.translation.z) == \
            pytest.approx((x, 0.0, z), abs=1e-12)
        # (the quaternion of a rotation by -th about y: (0, -sin(th/2), 0, cos(th/2)))
        assert (move.rotation.x, move.rotation.y, move.rotation.z, move.rotation.w) == \
            pytest.approx((0.0, -np.sin(th / 2), 0.0, np.cos(th / 2)), abs=1e-12)
    assert metadata["biped_opt.system"]["system"] == name
    assert metadata["biped_opt.sweep"]["maneuver"] == maneuver


def test_recorder_refuses_what_the_system_cannot_do(served, tmp_path):
    name, graph, _probe = served
    maneuver = CASES[name][0]
    base = {"maneuver": maneuver, "theta0_min": -0.1, "theta0_max": 0.1, "num": 3,
            "optimal": False, "output": tmp_path / "x.mcap", "system": name}
    for change, start in (({"maneuver": "hop"}, "maneuver:"),
                          ({"fixed_inputs": (1.0,) * 9}, "fixed_inputs:"),
                          ({"system": "walker5"}, "system:"),
                          ({"problem": maneuver}, "problem: given for a fixed-input sweep")):
        with pytest.raises(BipedOptError) as err:
            graph.recorder.record(SweepRequest(**{**base, **change}))
        assert str(err.value).startswith(start), err.value
    assert not (tmp_path / "x.mcap").exists()


@pytest.mark.parametrize(("system", "message"), [
    ("no_such_system", "system: unknown system 'no_such_system'"),
    ("missing/file.py", "system: missing/file.py: no such system file"),
])
def test_bad_system_parameter_is_refused_at_start(domain_id, system, message):
    with pytest.raises(BipedOptError, match="^" + message):
        Graph(domain_id=domain_id, overrides={"simulator": {"system": system}})


def test_bad_system_file_is_one_line_from_the_node_process(domain_id, tmp_path):
    """``--ros-args -p system:=FILE`` with a broken file: exit status 2, one line naming the
    file and the line, no traceback."""
    bad = tmp_path / "bad_system.py"
    bad.write_text("from biped_opt.systems import System\nSYSTEM = System('b', [])\n")
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    proc = subprocess.run(
        [sys.executable, "-m", "biped_opt.nodes.simulator", "--ros-args", "-p",
         f"system:={bad}"], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    lines = [line for line in proc.stderr.splitlines() if "error:" in line]
    assert lines == [f"simulator: error: system: {bad}: line 2: b: coordinates: at least one "
                     "is needed"], proc.stderr


def test_a_biped_sweep_from_a_system_simulator_is_refused(served, tmp_path):
    """The recorder asked for a biped sweep while the simulator serves another system: the
    error says to give both nodes the same system, and no file is left."""
    name, graph, _probe = served
    assert graph.recorder.served_system(10.0)["system"] == name  # the latched info is in
    with pytest.raises(BipedOptError, match=f"the simulator serves {name}: give the recorder "
                                            "the same system parameter"):
        graph.recorder.record(SweepRequest(
            maneuver="touchdown", theta0_min=-0.1, theta0_max=0.1, num=3, optimal=False,
            output=tmp_path / "b.mcap"))
    assert not (tmp_path / "b.mcap").exists()
