"""MCAP round trips through two independent readers, schema text, crash recovery."""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from biped_opt import simulate
from biped_opt.record import SweepWriter, read_recording
from biped_opt.record.cdr import compile_layout
from biped_opt.record.writer import TOPICS
from biped_opt.ros.interfaces import load_interfaces


def _sweep_point(tr, theta0):
    return {
        "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "biped"},
        "maneuver": tr.maneuver, "theta0": theta0, "optimal": False,
        "policy": list(tr.inputs[:2]), "value": 0.0, "outcome": tr.outcome,
        "t_final": tr.t_final, "mode_sequence": [int(m) for m in tr.mode_sequence],
        "event_times": tr.event_times,
    }


@pytest.fixture(scope="module")
def trajectories():
    return [simulate("touchdown", th, (2.0, 0.5), sample_dt=0.005) for th in (-0.1, 0.0, 0.1)]


def _write(target, trajectories, **kwargs):
    with SweepWriter(target, metadata={"maneuver": "touchdown", "num": "3"}, **kwargs) as w:
        for k, tr in enumerate(trajectories):
            offset = k * 10**10
            w.write_states(maneuver="touchdown", theta0=tr.theta0, samples=tr.samples,
                           stamp_offset_ns=offset)
            w.write("/biped/sweep", _sweep_point(tr, tr.theta0), offset + int(tr.t_final * 1e9))
    return w


def test_fast_layout_bytes_equal_rosbags():
    ts = load_interfaces().typestore
    layout = compile_layout(ts, "biped_opt_interfaces/msg/BipedState",
                            {"header.frame_id": "odd_len", "maneuver": "liftoff"})
    msgs = layout.empty(2)
    rng = np.random.default_rng(0)
    q = rng.normal(size=(2, 7))
    msgs["header.stamp.sec"] = [3, 4]
    msgs["q"], msgs["qdot"], msgs["contact_mode"] = q, -q, [2, 3]
    msgs["contact_force"], msgs["t"], msgs["theta0"] = [[1.5, 0.0], [0.0, 2.5]], [0.1, 0.2], -0.05
    cls = ts.types["biped_opt_interfaces/msg/BipedState"]
    header, stamp = ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    for k, data in enumerate(layout.serialize(msgs)):
        ref = cls(header=header(stamp=stamp(sec=3 + k, nanosec=0), frame_id="odd_len"),
                  maneuver="liftoff", theta0=-0.05, t=0.1 * (k + 1), q=q[k], qdot=-q[k],
                  contact_mode=2 + k, contact_force=np.array([[1.5, 0.0], [0.0, 2.5]][k]))
        assert bytes(ts.serialize_cdr(ref, cls.__msgtype__)) == data


def test_round_trip_two_independent_readers(tmp_path, trajectories):
    path = tmp_path / "sweep.mcap"
    w = _write(path, trajectories)
    assert w.counts["/biped/state"] == sum(len(tr.samples) for tr in trajectories)

    ours = read_recording(path)
    assert ours.complete and ours.counts["/biped/sweep"] == 3
    # reader 2: mcap + mcap-ros2-support decode from the schema text alone
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert reader.get_header().profile == "ros2"
        decoded = list(reader.iter_decoded_messages(log_time_order=True))
    assert len(decoded) == len(ours.messages)
    for (_schema, channel, message, msg), mine in zip(decoded, ours.messages):
        assert channel.topic == mine.topic and message.log_time == mine.log_time_ns
        if channel.topic == "/biped/state":
            np.testing.assert_array_equal(np.asarray(msg.q), np.asarray(mine.msg.q))
            assert msg.contact_mode == mine.msg.contact_mode and msg.t == mine.msg.t
    # values equal the simulation's samples exactly
    tr = trajectories[2]
    rows = ours.states_of(tr.theta0)
    np.testing.assert_array_equal(rows[:, 0], tr.samples[:, 0])
    np.testing.assert_array_equal(rows[:, 1:15], tr.samples[:, 1:15])
    # log times increase through the sweep
    times = [m.log_time_ns for m in ours.messages]
    assert times == sorted(times)
    # channel metadata and schemas per MCAP.md Secs. 1-2
    ts = load_interfaces().typestore
    for channel in summary.channels.values():
        typename = TOPICS[channel.topic][0]
        assert channel.message_encoding == "cdr"
        assert channel.metadata["topic_type_hash"] == ts.hash_rihs01(typename)
        assert "reliability: " in channel.metadata["offered_qos_profiles"]
        schema = summary.schemas[channel.schema_id]
        assert schema.encoding == "ros2msg" and schema.name == typename
        assert schema.data.decode() == ts.generate_msgdef(typename, ros_version=2)[0]
    assert "\nMSG: std_msgs/Header\n" in summary.schemas[1].data.decode()
    assert summary.statistics.message_count == len(ours.messages)
    assert ours.metadata["biped_opt.sweep"]["num"] == "3"


def test_writer_accepts_a_stream_and_refuses_after_finish(trajectories):
    buf = io.BytesIO()
    w = _write(buf, trajectories[:1])
    assert buf.getvalue()[:8] == b"\x89MCAP0\r\n"
    with pytest.raises(OSError, match="already finished"):
        w.write("/biped/contact_mode", {"mode": 1}, 0)


_KILLED_WRITER = textwrap.dedent("""
    import sys, time
    import numpy as np
    from biped_opt import simulate
    from biped_opt.record import SweepWriter
    tr = simulate("touchdown", 0.1, (2.0, 0.5), sample_dt=0.001)
    w = SweepWriter(sys.argv[1], chunk_size=4096)
    w.finish_on_signals()
    k = 0
    while True:
        w.write_states(maneuver="touchdown", theta0=0.1, samples=tr.samples,
                       stamp_offset_ns=k * 10**10)
        k += 1
        if k == 4:
            print("ready", flush=True)
        time.sleep(0.01)
""")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_killed_writer(tmp_path, sig):
    """SIGTERM: the file is finished and valid. SIGKILL: complete chunks are recovered."""
    path = tmp_path / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-c", _KILLED_WRITER, str(path)],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(0.1)
        os.kill(proc.pid, sig)
        proc.wait(timeout=60)
    finally:
        proc.kill()
    rec = read_recording(path)
    n = rec.counts.get("/biped/state", 0)
    per_trajectory = len(simulate("touchdown", 0.1, (2.0, 0.5), sample_dt=0.001).samples)
    if sig == signal.SIGTERM:
        assert proc.returncode == 128 + signal.SIGTERM
        assert rec.complete and rec.note == "indexed"
        # the signal waited for the batch under way: only whole trajectories are in the file
        assert n >= 4 * per_trajectory and n % per_trajectory == 0
    else:
        assert not rec.complete and "recovered" in rec.note
        # 4 trajectories were written before "ready"; 4 KiB chunks keep all but the last
        assert n >= 3 * per_trajectory


_NO_BACKEND = textwrap.dedent("""
    import json, sys
    from biped_opt.record import SweepWriter, read_recording
    point = {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "biped"},
             "maneuver": "touchdown", "theta0": 0.1, "optimal": False, "policy": [2.0, 0.5],
             "value": 0.0, "outcome": 0.07, "t_final": 0.5, "mode_sequence": [0, 1],
             "event_times": [0.2]}
    with SweepWriter(sys.argv[1], metadata={"maneuver": "touchdown", "num": "1"}) as w:
        w.write("/biped/sweep", point, 500_000_000)
    rec = read_recording(sys.argv[1])
    loaded = sorted(m for m in sys.modules if m.split(".")[0] in ("cyclonedds", "rclpy")
                    or m.startswith("biped_opt.ros"))
    print(json.dumps({"points": len(rec.sweep_points()), "loaded": loaded}))
""")


def test_a_recording_is_written_and_read_without_a_ros_backend(tmp_path):
    """The typestore comes from biped_opt.interface_defs: neither the DDS backend nor rclpy
    is brought up to write or read a file (report and replay's reader start faster)."""
    done = subprocess.run([sys.executable, "-c", _NO_BACKEND, str(tmp_path / "one.mcap")],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert out == {"points": 1, "loaded": []}
