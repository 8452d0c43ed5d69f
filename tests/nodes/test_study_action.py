"""The study as the ROS 2 action ``/biped/study`` on the built-in backend: goal, feedback,
result, cancel, and the names and types rcl_action puts on the wire."""

from __future__ import annotations

import json
import time

import pytest
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.core import Policy

from biped_opt import ros
from biped_opt.ros.dds import GoalStatus
from tests.conftest import unique_domain_id

from .test_study_fanout import SPEC, Host, assert_same_table, coordinator, local_rows, optimiser

pytestmark = pytest.mark.skipif(ros.BACKEND != "dds", reason="the built-in backend's wire")


@pytest.fixture(scope="module")
def local_table(tmp_path_factory) -> list[dict[str, str]]:
    return local_rows(SPEC, tmp_path_factory.mktemp("local"))


@pytest.fixture()
def graph(tmp_path):
    domain = unique_domain_id()
    hosts = [optimiser(domain, "h1"), coordinator(domain, output_dir=str(tmp_path))]
    client = Host(lambda c: ros.Node("study_client", context=c), domain)
    hosts.append(client)
    action = ros.ActionClient(client.node, ros.actions.Study, "/biped/study",
                              callback_group=ros.ReentrantCallbackGroup())
    assert action.wait_for_server(timeout_sec=10)
    yield hosts, action
    action.destroy()
    for host in reversed(hosts):
        host.close()


def _send(action, study: dict, out: str, feedback: list):
    future = action.send_goal_async(
        ros.actions.Study.Goal(study=json.dumps(study), out=out),
        feedback_callback=lambda m: feedback.append(m.feedback))
    assert future.wait(10)
    return future.result()


def test_a_goal_runs_the_study_with_feedback_and_a_result(tmp_path, graph, local_table):
    _, action = graph
    feedback: list = []
    handle = _send(action, SPEC, "t.csv", feedback)
    assert handle.accepted
    done = handle.get_result_async()
    assert done.wait(120)
    reply = done.result()
    assert reply.status == GoalStatus.SUCCEEDED
    r = reply.result
    assert r.success and (r.points, r.computed, r.resumed, r.stopped) == (16, 16, 0, False)
    # named, not by path: where the node keeps its files is not the domain's business
    assert (r.table, r.spec) == ("t.csv", "t.csv.study.json")
    assert (tmp_path / "t.csv").is_file()
    assert_same_table(tmp_path / "t.csv", local_table)
    assert r.rows == len(local_table)
    time.sleep(0.2)  # the last feedback may trail the result
    assert [f.done for f in feedback] == list(range(1, 17))
    assert all(f.total == 16 for f in feedback)
    last = feedback[-1]
    assert json.loads(last.current) == {"gamma": SPEC["grid"]["gamma"][last.current_point]}
    assert handle.status == GoalStatus.SUCCEEDED  # from the status topic


def test_cancel_stops_the_study_and_a_new_goal_continues_it(tmp_path, graph, local_table):
    _, action = graph
    feedback: list = []
    handle = _send(action, SPEC, "t.csv", feedback)
    deadline = time.monotonic() + 60
    while len(feedback) < 3 and time.monotonic() < deadline:
        time.sleep(0.01)
    canceling = handle.cancel_goal_async()
    assert canceling.wait(10)
    reply = canceling.result()
    assert reply.return_code == 0 and len(reply.goals_canceling) == 1
    assert bytes(reply.goals_canceling[0].goal_id.uuid) == bytes(handle.goal_id.uuid)
    done = handle.get_result_async()
    assert done.wait(60)
    first = done.result()
    assert first.status == GoalStatus.CANCELED
    assert first.result.stopped and 3 <= first.result.computed < 16
    # a second cancel of the ended goal: terminated
    again = handle.cancel_goal_async()
    assert again.wait(10) and again.result().return_code == 3
    # the same goal again continues the table
    handle = _send(action, SPEC, "t.csv", [])
    done = handle.get_result_async()
    assert done.wait(120)
    second = done.result().result
    assert second.resumed == first.result.computed
    assert second.resumed + second.computed == 16 and not second.stopped
    assert_same_table(tmp_path / "t.csv", local_table)


def test_a_bad_goal_is_aborted_with_the_reason(tmp_path, graph):
    _, action = graph
    handle = _send(action, {**SPEC, "grid": {"mass": [1.0]}}, "t.csv", [])
    done = handle.get_result_async()
    assert done.wait(30)
    reply = done.result()
    assert reply.status == GoalStatus.ABORTED and not reply.result.success
    assert "cannot vary 'mass'" in reply.result.message


def test_wire_names_and_types_are_rcl_actions(graph):
    hosts, _ = graph
    node = hosts[-1].node
    services = dict(node.get_service_names_and_types())
    assert services["/biped/study/_action/send_goal"] == [
        "biped_opt_interfaces/action/Study_SendGoal"]
    assert services["/biped/study/_action/get_result"] == [
        "biped_opt_interfaces/action/Study_GetResult"]
    assert services["/biped/study/_action/cancel_goal"] == ["action_msgs/srv/CancelGoal"]
    reader = BuiltinDataReader(hosts[-1].context.participant, BuiltinTopicDcpsPublication)
    time.sleep(0.2)
    writers = {s.topic_name: s for s in reader.read(N=10_000)}
    status = writers["rt/biped/study/_action/status"]
    assert status.type_name == "action_msgs::msg::dds_::GoalStatusArray_"
    assert status.qos[Policy.Durability] == Policy.Durability.TransientLocal
    feedback = writers["rt/biped/study/_action/feedback"]
    assert feedback.type_name == "biped_opt_interfaces::action::dds_::Study_FeedbackMessage_"
    assert writers["rq/biped/study/_action/send_goalRequest"].type_name == \
        "biped_opt_interfaces::action::dds_::Study_SendGoal_Request_"
    reader.__del__()


def test_a_study_of_a_urdf_named_by_its_stem(tmp_path):
    """A goal naming ``hopper``: the coordinator and the optimiser find ``hopper.urdf`` in their
    system_paths (the optimiser's through its ``systems`` parameter, which names the file and
    adds its directory) and write the table a local run of the same file writes."""
    import shutil
    from pathlib import Path

    robots = tmp_path / "robots"
    robots.mkdir()
    urdf = robots / "hopper.urdf"
    shutil.copy(Path(__file__).resolve().parents[1] / "systems" / "urdf" / "hopper.urdf", urdf)
    spec = {"system": "hopper", "maneuver": "drop", "grid": {"kp": [5.0, 10.0]},
            "s_range": [0.02, 0.1], "num": 9}
    local = local_rows({**spec, "system": str(urdf)}, tmp_path)
    domain = unique_domain_id()
    hosts = [optimiser(domain, "h1", systems=[str(urdf)]),
             coordinator(domain, output_dir=str(tmp_path), system_paths=[str(robots)])]
    client = Host(lambda c: ros.Node("study_client", context=c), domain)
    hosts.append(client)
    action = ros.ActionClient(client.node, ros.actions.Study, "/biped/study",
                              callback_group=ros.ReentrantCallbackGroup())
    try:
        assert action.wait_for_server(timeout_sec=10)
        handle = _send(action, spec, "hop.csv", [])
        assert handle.accepted
        done = handle.get_result_async()
        assert done.wait(300)
        reply = done.result()
        assert reply.status == GoalStatus.SUCCEEDED, reply.result.message
        assert reply.result.points == 2
        assert_same_table(tmp_path / "hop.csv", local)
    finally:
        action.destroy()
        for host in reversed(hosts):
            host.close()
