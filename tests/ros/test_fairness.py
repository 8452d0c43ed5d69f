"""A service shared by clients that do not play fair (services module doc): one that floods,
one that never reads its replies. Each client is a participant of its own (a Context), as a
process on the domain would be. The checks are on order and counts, not on times: what the
other client gets is measured by ``bench/service_load.py --adversarial``."""

from __future__ import annotations

import threading
import time

import pytest

from biped_opt.ros import dds
from biped_opt.ros.dds.lifetime import delete_dds
from biped_opt.ros.dds.services import MAX_QUEUED_PER_CLIENT, TOO_MANY
from biped_opt.ros.interfaces import load_interfaces

POLICY = load_interfaces().services["biped_opt_interfaces/srv/OptimalPolicy"]


@pytest.fixture()
def other(domain_id):
    """A second participant on the same domain (another process's)."""
    ctx = dds.Context()
    dds.init(context=ctx, domain_id=domain_id)
    yield ctx
    ctx.try_shutdown()


def _spun(context, node, threads=2):
    executor = dds.MultiThreadedExecutor(num_threads=threads, context=context)
    executor.add_node(node)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    return executor, thread


def _stop(executor, thread):
    assert executor.shutdown(timeout_sec=10.0)
    thread.join(10.0)


def _request(name, theta0=0.0):
    return POLICY.Request(maneuver=name, theta0=theta0)


def test_a_flooding_client_is_served_in_turn_with_the_others(context, other):
    """Client A sends 40 requests at once to a service that takes 20 ms a request, one at a
    time; client B then sends one. B's is served next but one (A's request under way, then in
    turn), not after A's 32 queued ones; A's requests beyond 32 waiting are answered busy at
    once."""
    server = dds.Node("server", context=context)
    order: list[str] = []
    release = threading.Event()

    def slow(request, response):
        release.wait(10.0)
        order.append(request.maneuver)
        time.sleep(0.02)
        response.success, response.message = True, request.maneuver
        return response

    service = server.create_service(POLICY, "/fair", slow,
                                    callback_group=dds.MutuallyExclusiveCallbackGroup())
    flooder = server.create_client(POLICY, "/fair")  # A: the server's own participant
    second_node = dds.Node("second", context=other)
    second = second_node.create_client(POLICY, "/fair")  # B: another participant
    executors = [_spun(context, server), _spun(other, second_node)]
    try:
        assert flooder.wait_for_service(10.0) and second.wait_for_service(10.0)
        floods = [flooder.call_async(_request(f"a{i}")) for i in range(40)]
        deadline = time.monotonic() + 10.0
        while sum(f.done() for f in floods) < 7 and time.monotonic() < deadline:
            time.sleep(0.005)
        time.sleep(0.2)  # (no more of them come: the rest wait for the slow callback)
        busy = [f for f in floods if f.done() and TOO_MANY in f.result().message]
        # (one may be taken to be served before the others queue: 32 or 33 wait or run)
        assert len(busy) in (40 - MAX_QUEUED_PER_CLIENT, 40 - MAX_QUEUED_PER_CLIENT - 1)
        assert sum(f.done() for f in floods) == len(busy)
        mine = second.call_async(_request("b"))
        deadline = time.monotonic() + 10.0
        while len(service._queue._queues) < 2 and time.monotonic() < deadline:
            time.sleep(0.005)  # B's request is queued beside A's (one of A's is under way)
        release.set()
        assert mine.wait(30.0) and mine.result().success
        assert all(f.wait(30.0) for f in floods)
        assert order.index("b") <= 2, order
        assert len(order) == 40 - len(busy) + 1
    finally:
        release.set()
        for executor, thread in executors:
            _stop(executor, thread)


def test_a_quick_reply_never_waits_behind_the_queue(context, other):
    """A service busy with one client's slow requests answers another client's cached request
    from its quick_reply as it arrives, while the slow ones still wait."""
    server = dds.Node("server", context=context)
    release = threading.Event()
    served: list[str] = []

    def slow(request, response):
        release.wait(10.0)
        served.append(request.maneuver)
        response.success, response.message = True, "computed"
        return response

    def cached(request):
        if request.maneuver != "cached":
            return None
        return POLICY.Response(success=True, message="from the cache")

    service = server.create_service(POLICY, "/quick", slow)
    service.quick_reply = cached
    flooder = server.create_client(POLICY, "/quick")
    second_node = dds.Node("second", context=other)
    second = second_node.create_client(POLICY, "/quick")
    executors = [_spun(context, server), _spun(other, second_node)]
    try:
        assert flooder.wait_for_service(10.0) and second.wait_for_service(10.0)
        floods = [flooder.call_async(_request("slow")) for _ in range(10)]
        mine = second.call_async(_request("cached"))
        assert mine.wait(10.0), "the cached request waited behind the slow ones"
        assert mine.result().message == "from the cache"
        assert served == [] and not any(f.done() for f in floods)
        release.set()
        assert all(f.wait(30.0) for f in floods)
        assert len(served) == 10
    finally:
        release.set()
        for executor, thread in executors:
            _stop(executor, thread)


def test_a_client_that_never_reads_its_replies_costs_the_others_nothing(context, other, capfd):
    """30 requests of a client whose reply reader is gone: their replies wait off the serving
    threads, so another client's request is answered while they wait; they are dropped after
    reply_wait_s with one warning line a second, and the client is remembered: its next 30
    replies are dropped after one look, not after another wait."""
    server = dds.Node("server", context=context)

    def echo(request, response):
        response.success, response.message = True, request.maneuver
        return response

    service = server.create_service(POLICY, "/deaf", echo)
    deaf_node = dds.Node("deaf", context=other)
    deaf = deaf_node.create_client(POLICY, "/deaf")
    listener = dds.Node("listener", context=context)
    good = listener.create_client(POLICY, "/deaf")
    executors = [_spun(context, server), _spun(context, listener)]
    try:
        assert deaf.wait_for_service(10.0) and good.wait_for_service(10.0)
        reader, deaf._reader = deaf._reader, None
        delete_dds(reader)  # the client's requests still come, its replies reach nobody
        time.sleep(0.3)  # (the service's writer sees the reader go)
        for i in range(30):
            deaf.call_async(_request(f"deaf{i}"))
        answer = good.call_async(_request("heard"))
        assert answer.wait(10.0) and answer.result().message == "heard"
        assert service.dropped_replies == 0  # answered while the 30 still waited
        deadline = time.monotonic() + service.reply_wait_s + 10.0
        while service.dropped_replies < 30 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert service.dropped_replies == 30
        service.reply_wait_s = 20.0  # a new wait would now take 20 s per reply
        start = time.monotonic()
        for i in range(30):
            deaf.call_async(_request(f"again{i}"))
        while service.dropped_replies < 60 and time.monotonic() < start + 10.0:
            time.sleep(0.01)
        assert service.dropped_replies == 60
        assert time.monotonic() - start < 2.5  # one look each: no 20 s wait
        warnings = [line for line in capfd.readouterr().err.splitlines()
                    if "reply dropped" in line]
        assert 1 <= len(warnings) <= 4, warnings
    finally:
        for executor, thread in executors:
            _stop(executor, thread)
        deaf_node.destroy_node()
