"""Recordings of other systems than the biped (SystemState): CDR bytes, info, report, replay."""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest

from biped_opt import ros
from biped_opt.cli.info_cmd import describe
from biped_opt.cli.main import main
from biped_opt.nodes import convert
from biped_opt.nodes.simulator import SYSTEM_INFO_QOS
from biped_opt.piecewise import theta_grid
from biped_opt.record import SweepWriter, read_recording
from biped_opt.record.reader import read_raw
from biped_opt.record.replay import Player
from biped_opt.record.report import load_sweep, report
from biped_opt.simulation.compiled import CompiledSystem

NS = 1_000_000_000
#: same kernel, float64 all the way: the numbers come back to the last bit (1e-12 allows
#: for nothing else)
TOL = 1e-12


def write_system_sweep(path, name="walker3_coupled", maneuver="touchdown", inputs=(0.5, 0.2),
                       lo=-0.1, hi=0.1, num=5, dt=0.01):
    """A fixed-input sweep over s written as the recorder writes it, straight from the
    compiled system; returns {s: trajectory}."""
    compiled = CompiledSystem(name)
    u = [*inputs, *[0.0] * (len(compiled.inputs) - len(inputs))]
    info = convert.system_info_fields(compiled, name)
    meta = {"system": name, "maneuver": maneuver, "theta0_min": lo, "theta0_max": hi,
            "num": num, "optimal": False, "fixed_inputs": json.dumps(u)}
    out = {}
    offset = 0
    with SweepWriter(path, metadata={k: str(v) for k, v in meta.items()}, system=info) as w:
        for s in theta_grid(lo, hi, num):
            tr = compiled.simulate(maneuver, s, u, sample_dt=dt)
            w.write_system_states(maneuver=maneuver, s=s, samples=tr.samples,
                                  ndof=len(compiled.system.q), stamp_offset_ns=offset)
            w.write("/biped/sweep", {
                "header": {"frame_id": name}, "maneuver": maneuver, "theta0": s, "policy": u,
                "value": float("nan"), "outcome": tr.outcome, "t_final": tr.t_final,
                "mode_sequence": list(tr.modes), "event_times": list(tr.event_times)},
                offset + int(tr.t_final * NS))
            out[float(s)] = tr
            offset += int((tr.t_final + 0.5) * NS)
    return out


def test_batch_serialized_states_equal_rosbags(tmp_path):
    """The vectorised SystemState layout (sequences of known length) gives rosbags' bytes."""
    path = tmp_path / "w.mcap"
    trs = write_system_sweep(path, num=3)
    raw = read_raw(path, topics=["/biped/system_state"])
    ts = SweepWriter(tmp_path / "x.mcap").typestore
    typename = "biped_opt_interfaces/msg/SystemState"
    assert len(raw.messages) == sum(len(tr.samples) for tr in trs.values())
    for m in raw.messages[::7]:
        msg = ts.deserialize_cdr(m.data, typename)
        assert len(msg.q) == 9 and len(msg.contact_force) == 3
        assert bytes(ts.serialize_cdr(msg, typename)) == m.data


def test_read_back_equals_the_compiled_system(tmp_path):
    path = tmp_path / "w.mcap"
    trs = write_system_sweep(path)
    rec = read_recording(path)
    assert rec.system["constraints"] == ["foot1", "foot2", "foot3"]
    for s, tr in trs.items():
        np.testing.assert_allclose(rec.system_states_of(s), tr.samples, rtol=0, atol=TOL)
    assert rec.counts["/biped/system_info"] == 1 and "/biped/state" not in rec.counts


def test_info_names_the_system(tmp_path, capsys):
    path = tmp_path / "w.mcap"
    write_system_sweep(path)
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "system:       walker3_coupled (from walker3_coupled)" in out
    assert "constraints: foot1, foot2, foot3" in out and "sweep points: 5" in out
    assert "biped_opt_interfaces/msg/SystemState" in out
    info = describe(path)
    assert info["system"]["inputs"] == ["u1", "u2", "u3", "u_body"]
    assert main(["info", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["system"]["coordinates"][:3] == ["x", "z", "th"]


def test_report_of_a_system_sweep(tmp_path):
    """The walker's touchdown changes mode order at s = 0 (foot 3 first for s < 0, foot 1
    first for s > 0, all three at once at 0): the table names the masks by their constraints
    and brackets the change by the recorded s values around 0."""
    path = tmp_path / "w.mcap"
    write_system_sweep(path, lo=-0.1, hi=0.1, num=21)
    sweep = load_sweep(path)
    assert sweep.system == "walker3_coupled" and sweep.problem is None
    assert sweep.branch[10] == "air->foot1+foot2+foot3"
    assert sweep.branch[0] == "air->foot3->foot2+foot3->foot1+foot2+foot3"
    result = report([path], tmp_path / "rep")
    assert "== walker3_coupled:touchdown (fixed inputs)" in result.table
    points = result.grid_points["fixed:walker3_coupled:touchdown"]
    assert points and all(p.point.bracket == (-0.01, 0.01) or p.point.theta0 == 0.0
                          for p in points)
    assert [f.name for f in result.figures] == ["walker3_coupled_touchdown.png"]
    assert result.figures[0].stat().st_size > 10_000


def test_replay_of_a_system_recording(tmp_path, domain_id):
    """Replay publishes the description latched and every SystemState with its numbers."""
    path = tmp_path / "w.mcap"
    trs = write_system_sweep(path, num=3, dt=0.02)
    total = sum(len(tr.samples) for tr in trs.values())
    context = ros.Context()
    ros.init(args=[], context=context, domain_id=domain_id)
    node = ros.Node("listener", context=context)
    states, infos = [], []
    lock = threading.Lock()

    def keep(box):
        def callback(msg):
            with lock:
                box.append(msg)
        return callback

    # best effort, as recorded (a reliable reader would not match the player's writer)
    node.create_subscription(ros.msgs.SystemState, "/biped/system_state", keep(states),
                             ros.QoSProfile(depth=1000,
                                            reliability=ros.ReliabilityPolicy.BEST_EFFORT))
    node.create_subscription(ros.msgs.SystemInfo, "/biped/system_info", keep(infos),
                             SYSTEM_INFO_QOS)
    executor = ros.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    try:
        stats = Player(path, domain_id=domain_id, delay=1.0, rate=20.0).run()
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and len(states) < total:
            time.sleep(0.02)
    finally:
        executor.shutdown()
        node.destroy_node()
        ros.try_shutdown(context=context)
        thread.join(5.0)
    assert stats.skipped_types == ()
    assert stats.published["/biped/system_state"] == total
    assert len(infos) == 1 and list(infos[0].maneuvers) == ["touchdown", "liftoff"]
    assert len(states) == total
    got = {}
    for m in states:
        got.setdefault(m.s, []).append([m.t, *m.q, *m.qdot, m.contact_mode, *m.contact_force])
    for s, tr in trs.items():
        np.testing.assert_allclose(np.array(got[s]), tr.samples, rtol=0, atol=TOL)


def test_writer_refuses_system_states_in_a_biped_recording(tmp_path):
    from biped_opt.record.writer import RecordError

    with SweepWriter(tmp_path / "b.mcap") as w, pytest.raises(RecordError, match="biped"):
        w.write_system_states(maneuver="drop", s=0.0, samples=np.zeros((1, 10)), ndof=3,
                              stamp_offset_ns=0)


def test_optimal_sweep_of_a_system_through_the_cli(tmp_path, capsys, monkeypatch, domain_id):
    """``record --system walker3_coupled --optimal`` (the graph in-process): every SweepPoint
    equals the core's optimum at its s, ``info`` shows the problem, ``report`` finds the
    policy's kinks where the foot order changes at s = 0 (foot 3 first below, foot 1 above)."""
    from biped_opt.control.problems import get_problem
    from biped_opt.control.solve import optimal_policy

    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain_id))
    path = tmp_path / "w.mcap"
    assert main(["record", "--system", "walker3_coupled", "--maneuver", "touchdown",
                 "--optimal", "--problem", "touchdown", "--theta0-min", "-0.1",
                 "--theta0-max", "0.1", "--num", "11", "--out", str(path)]) == 0
    capsys.readouterr()
    sweep = load_sweep(path)
    problem = get_problem("walker3_coupled", "touchdown")
    assert sweep.optimal and list(sweep.policy) == ["u1", "u2", "u3"]
    assert sweep.system_problem == json.loads(json.dumps(problem.as_dict()))
    for k, s in enumerate(sweep.theta0):
        core = optimal_policy(problem, s)
        assert abs(sweep.value[k] - core.value) <= TOL
        assert all(abs(sweep.policy[d][k] - core.policy[d]) <= TOL for d in sweep.policy)
        assert sweep.mode_sequences[k] == core.modes
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "optimal: True" in out and '"decisions": {"u1": [-0.5, 1.5]' in out
    result = report([path], tmp_path / "rep")
    assert "== walker3_coupled:touchdown (optimal)" in result.table
    # the bracket is the recorded grid's neighbours of s = 0 (0.02 apart, to rounding)
    kinks = {(p.point.quantity, p.point.input, p.point.kind, round(p.point.theta0, 12),
              tuple(round(v, 12) for v in p.point.bracket))
             for p in result.grid_points["optimal:walker3_coupled:touchdown"]}
    assert {("policy", d, "kink", 0.0, (-0.02, 0.02)) for d in ("u1", "u3")} <= kinks
    assert [f.name for f in result.figures] == ["walker3_coupled_touchdown_optimal.png"]
