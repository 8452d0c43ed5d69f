"""rosbag2 directories (metadata.yaml version 8) read back with rosbags' Reader."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import Reader

from biped_opt.cli.main import main
from biped_opt.record import read_recording
from biped_opt.record.reader import read_raw
from biped_opt.record.rosbag2 import Rosbag2SweepWriter, export_rosbag2
from biped_opt.record.writer import RecordError
from biped_opt.ros.interfaces import load_interfaces
from tests.record.test_report import write_fixed_sweep


def _check_bag(directory, raw):
    meta = yaml.safe_load((directory / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 8 and meta["storage_identifier"] == "mcap"
    assert meta["message_count"] == len(raw.messages)
    first, last = raw.time_range_ns
    assert meta["starting_time"]["nanoseconds_since_epoch"] == first
    assert meta["duration"]["nanoseconds"] == last - first
    ts = load_interfaces().typestore
    with Reader(directory) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert counts == {t: n for t, n in raw.counts.items()}
        qos = {c.topic: c.ext.offered_qos_profiles[0] for c in reader.connections}
        assert qos["/biped/state"].reliability.value == 2  # best effort, as recorded
        assert qos["/biped/contact_mode"].durability.value == 1  # transient local
        got = [(c.topic, t, ts.deserialize_cdr(data, c.msgtype))
               for c, t, data in reader.messages()]
    assert [(t, ns) for t, ns, _ in got] == [(m.topic, m.log_time_ns) for m in raw.messages]
    states = [m for topic, _, m in got if topic == "/biped/state"]
    return states


def test_export_reads_back_with_rosbags(tmp_path):
    path = write_fixed_sweep(tmp_path / "s.mcap", num=5)
    raw = read_raw(path)
    out = export_rosbag2(path, tmp_path / "bag")
    assert (out / "bag_0.mcap").is_file()
    states = _check_bag(out, raw)
    ref = read_recording(path).topic("/biped/state")
    np.testing.assert_array_equal([s.q for s in states], [m.msg.q for m in ref])
    with pytest.raises(RecordError, match="not empty"):
        export_rosbag2(path, tmp_path / "bag")


def test_export_of_a_recovered_file_is_finished(tmp_path):
    path = write_fixed_sweep(tmp_path / "k.mcap", num=5, chunk_size=3000)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    raw = read_raw(path)
    assert not raw.complete
    out = export_rosbag2(raw, tmp_path / "bag")
    _check_bag(out, raw)
    assert read_raw(out / "bag_0.mcap").complete


def test_rosbag2_sweep_writer_and_cli(tmp_path, capsys):
    d = tmp_path / "direct"
    tr_samples = np.zeros((3, 18))
    tr_samples[:, 0] = [0.0, 0.01, 0.02]
    with Rosbag2SweepWriter(d, metadata={"maneuver": "touchdown"}) as w:
        w.write_states(maneuver="touchdown", theta0=0.1, samples=tr_samples, stamp_offset_ns=5)
    _check_bag(d, read_raw(d / "direct_0.mcap"))
    path = write_fixed_sweep(tmp_path / "s.mcap", num=3)
    assert main(["info", str(path), "--to-rosbag2", str(tmp_path / "cli")]) == 0
    assert "metadata.yaml version 8" in capsys.readouterr().out
    _check_bag(tmp_path / "cli", read_raw(path))
