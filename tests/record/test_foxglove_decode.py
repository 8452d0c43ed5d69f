"""Foxglove's own decoders read every topic of a recording (issue 24 part 6; docs/ROS.md Sec. 6).

A sweep recorded through the nodes, read with the MCAP library, and every message of every
topic (the scene's /clock, /tf, markers and URDF among them) handed with its channel's schema to
``@foxglove/rosmsg`` and ``@foxglove/rosmsg2-serialization`` under Node.js, as Foxglove's app
decodes an MCAP file: each decodes to its end (no trailing bytes) and the decoded fields equal
what rosbags reads from the same bytes (exactly: the same doubles; JSON keeps them).
"""

from __future__ import annotations

import base64
import json
import subprocess

import pytest
from mcap.reader import make_reader

from biped_opt.nodes.graph import Graph
from biped_opt.nodes.recorder import SweepRequest
from biped_opt.ros.interfaces import load_interfaces
from tests.conftest import unique_domain_id
from tests.nodes.test_foxglove import CLIENT_DIR, needs_client


@pytest.fixture()
def recording(tmp_path):
    out, domain_id = tmp_path / "sweep.mcap", unique_domain_id()
    with Graph(overrides={"simulator": {"autostart": False}}, domain_id=domain_id) as graph:
        graph.recorder.record(SweepRequest(maneuver="touchdown", theta0_min=-0.02,
                                           theta0_max=0.02, num=3, optimal=False, output=out))
    return out


@needs_client
def test_foxglove_decodes_every_recorded_topic_as_rosbags_does(recording):
    ts = load_interfaces().typestore
    items, expected = [], []
    with open(recording, "rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            items.append(json.dumps({"topic": channel.topic, "schemaName": schema.name,
                                     "schema": schema.data.decode(),
                                     "data": base64.b64encode(message.data).decode()}))
            expected.append((channel.topic, ts.deserialize_cdr(message.data, schema.name)))
    proc = subprocess.run(["node", str(CLIENT_DIR / "decode.js")], input="\n".join(items),
                          capture_output=True, text=True, timeout=300, check=True)
    decoded = [json.loads(line) for line in proc.stdout.splitlines()]
    assert len(decoded) == len(expected)
    topics = {topic for topic, _ in expected}
    assert {"/clock", "/tf", "/biped/markers", "/robot_description", "/biped/state",
            "/biped/contact_mode", "/biped/sweep"} <= topics
    for got, (topic, ref) in zip(decoded, expected):
        assert got["topic"] == topic and "error" not in got, got
        assert not got["trailingBytes"], topic
        _same(ts, got["data"], ref, topic)


def _same(ts, got, ref, where: str) -> None:
    """Foxglove's decoded JSON against rosbags' message object, field for field (the fields of
    the type's definition, constants aside)."""
    msgtype = getattr(ref, "__msgtype__", None)
    if msgtype is not None:
        for name, _spec in ts.fielddefs[msgtype][1]:
            _same(ts, got[name], getattr(ref, name), f"{where}.{name}")
    elif isinstance(ref, (list, tuple)) or hasattr(ref, "tolist"):
        items = ref.tolist() if hasattr(ref, "tolist") else list(ref)
        assert len(got) == len(items), where
        for k, (g, r) in enumerate(zip(got, items)):
            _same(ts, g, r, f"{where}[{k}]")
    else:
        assert got == ref, (where, got, ref)
