"""config/biped_opt.rviz: an RViz2 view of what the simulator publishes (ROS.md Sec. 6).

RViz2 reads the file as YAML; each display subscribes with the topic and QoS written in it. So:
the file parses, its fixed frame is the scene's world frame, each display is one of RViz2's
default plugins and its topic is one the simulator offers (:data:`SCENE_TOPICS`, the scene
topics it creates a publisher for) with the type that plugin takes, and the QoS it asks for is
one the offered QoS satisfies (a transient-local or reliable request matches only a publisher
that offers as much: otherwise RViz2 gets nothing and says only "no messages received").
"""

from __future__ import annotations

from pathlib import Path

import yaml

from biped_opt.record.scene import MARKERS_TOPIC, SCENE_TOPICS
from biped_opt.systems.description import WORLD

RVIZ = Path(__file__).resolve().parents[2] / "config" / "biped_opt.rviz"
#: RViz2's display plugins used here -> the message type each subscribes to (None: no topic)
PLUGINS = {"rviz_default_plugins/Grid": None, "rviz_default_plugins/TF": None,
           "rviz_default_plugins/RobotModel": "std_msgs/msg/String",
           "rviz_default_plugins/MarkerArray": "visualization_msgs/msg/MarkerArray"}
#: rosbag2's integer enums (as SCENE_TOPICS gives them) of RViz2's QoS names
RELIABILITY = {"Reliable": 1, "Best Effort": 2}
DURABILITY = {"Transient Local": 1, "Volatile": 2}


def _config() -> dict:
    return yaml.safe_load(RVIZ.read_text())


def test_the_view_is_in_the_world_frame_with_the_four_displays():
    manager = _config()["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == WORLD
    displays = manager["Displays"]
    assert sorted(d["Class"] for d in displays) == sorted(PLUGINS)
    assert all(d["Enabled"] and d["Value"] for d in displays)


def test_each_display_subscribes_to_a_topic_the_simulator_offers():
    topics = {}
    for display in _config()["Visualization Manager"]["Displays"]:
        want = PLUGINS[display["Class"]]
        key = "Description Topic" if "Description Topic" in display else "Topic"
        if want is None:
            assert key not in display
            continue
        if display["Class"].endswith("RobotModel"):
            assert display["Description Source"] == "Topic"
        sub = display[key]
        topic = sub["Value"]
        typename, offered = SCENE_TOPICS[topic]
        assert typename == want, topic
        # a request is met when the offer is at least as strong (RMW's QoS compatibility)
        assert RELIABILITY[sub["Reliability Policy"]] >= offered["reliability"], topic
        assert DURABILITY[sub["Durability Policy"]] >= offered["durability"], topic
        assert sub["History Policy"] == "Keep Last" and sub["Depth"] >= 1
        topics[topic] = display["Class"]
    assert set(topics) == {"/robot_description", MARKERS_TOPIC}


def test_a_topic_the_simulator_does_not_offer_is_caught():
    """The check above fails on a misspelt topic or a request stronger than the offer."""
    config = _config()
    markers = next(d for d in config["Visualization Manager"]["Displays"]
                   if d["Class"].endswith("MarkerArray"))
    assert "/biped/marker" not in SCENE_TOPICS
    offered = SCENE_TOPICS[markers["Topic"]["Value"]][1]
    # the markers are offered volatile: a transient-local request would get nothing
    assert DURABILITY["Transient Local"] < offered["durability"]
