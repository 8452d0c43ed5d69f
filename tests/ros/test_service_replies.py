"""Where a service's replies can be lost, and which side loses them (services module doc).

Every client of a service receives every reply on ``rr/...Reply``. A reader that keeps the last
10 replies, as rmw_cyclonedds creates it for rclpy's default service QoS, loses its own reply
when replies to other clients arrive before it takes it; the backend's own client (keep-all)
does not. The server's reply writer keeps unacknowledged replies deeper than the profile, so
that replies to other clients never make one unrecoverable on the writer's side."""

from __future__ import annotations

import time

from cyclonedds.core import Policy

from bench.service_load import rmw_style_client
from biped_opt.ros import dds
from biped_opt.ros.dds.services import REPLY_HISTORY
from biped_opt.ros.interfaces import load_interfaces

POLICY = load_interfaces().services["biped_opt_interfaces/srv/OptimalPolicy"]


def _double(request, response):
    response.success, response.message, response.value = True, request.maneuver, 2 * request.theta0
    return response


def _until(predicate, step, timeout=5.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not predicate():
        step()
    return predicate()


def test_other_clients_replies_push_a_reply_out_of_a_keep_last_10_reader(context):
    server = dds.Node("server", context=context)
    answered = []

    def serve(request, response):
        answered.append(request.maneuver)
        return _double(request, response)

    server.create_service(POLICY, "/shared", serve)
    busy = server.create_client(POLICY, "/shared")
    # the slow clients' node is spun by nobody until the busy client is done: as a client
    # whose process is descheduled while the others go on calling
    slow = dds.Node("slow", context=context)
    rmw_like = rmw_style_client(slow, POLICY, "/shared")
    keep_all = slow.create_client(POLICY, "/shared")
    assert all(c.wait_for_service(timeout_sec=5.0) for c in (busy, rmw_like, keep_all))
    ex = dds.SingleThreadedExecutor(context=context)
    ex.add_node(server)
    lost = rmw_like.call_async(POLICY.Request(maneuver="rmw", theta0=1.0))
    kept = keep_all.call_async(POLICY.Request(maneuver="all", theta0=2.0))
    assert _until(lambda: len(answered) == 2, lambda: ex.spin_once(timeout_sec=0.05))
    # replies to other clients, one after another: with the keep-all client's, 11 reach the
    # keep-last-10 reader after its own (the next test: 9 leave room for it)
    for i in range(10):
        future = busy.call_async(POLICY.Request(maneuver="busy", theta0=float(i)))
        ex.spin_until_future_complete(future, timeout_sec=5.0)
        assert future.done()
    slow_ex = dds.SingleThreadedExecutor(context=context)
    slow_ex.add_node(slow)
    assert _until(kept.done, lambda: slow_ex.spin_once(timeout_sec=0.05))
    assert kept.result().value == 4.0
    # 1 s of spinning: the reply would be taken in the first few ms if it were there
    assert not _until(lambda: lost.done(), lambda: slow_ex.spin_once(timeout_sec=0.05),
                      timeout=1.0)
    ex.shutdown()
    slow_ex.shutdown()


def test_nine_other_replies_do_not_push_it_out(context):
    """The same with 9 replies to another client: the keep-last-10 reader keeps its reply, so
    the loss above is the reader's depth and not something else."""
    server = dds.Node("server", context=context)
    server.create_service(POLICY, "/shared", _double)
    busy = server.create_client(POLICY, "/shared")
    slow = dds.Node("slow", context=context)
    rmw_like = rmw_style_client(slow, POLICY, "/shared")
    assert all(c.wait_for_service(timeout_sec=5.0) for c in (busy, rmw_like))
    ex = dds.SingleThreadedExecutor(context=context)
    ex.add_node(server)
    mine = rmw_like.call_async(POLICY.Request(maneuver="rmw", theta0=1.0))
    first = busy.call_async(POLICY.Request(maneuver="busy", theta0=0.0))
    ex.spin_until_future_complete(first, timeout_sec=5.0)  # the service answered both
    for i in range(1, 9):
        future = busy.call_async(POLICY.Request(maneuver="busy", theta0=float(i)))
        ex.spin_until_future_complete(future, timeout_sec=5.0)
    slow_ex = dds.SingleThreadedExecutor(context=context)
    slow_ex.add_node(slow)
    assert _until(mine.done, lambda: slow_ex.spin_once(timeout_sec=0.05))
    assert mine.result().value == 2.0
    ex.shutdown()
    slow_ex.shutdown()


def test_reply_writer_keeps_unacknowledged_replies_deeper_than_the_profile(context):
    node = dds.Node("server", context=context)
    service = node.create_service(POLICY, "/deep", _double)
    client = node.create_client(POLICY, "/deep")
    history = service._writer.get_qos()[Policy.History]
    assert history == Policy.History.KeepLast(REPLY_HISTORY)
    # the client's request writer and the service's request reader are as before
    assert client._writer.get_qos()[Policy.History] == Policy.History.KeepLast(10)
    assert service._reader.get_qos()[Policy.History] == Policy.History.KeepAll
    assert rmw_style_client(node, POLICY, "/deep")._reader.get_qos()[Policy.History] == \
        Policy.History.KeepLast(10)
