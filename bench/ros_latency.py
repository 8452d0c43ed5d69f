"""Latency and throughput of biped_opt's ROS layer on loopback.

Measures the OptimalPolicy service round trip (p50/p99) with client and server in one process
and in two processes, and the BipedState publish rate to one matched subscriber.

    python bench/ros_latency.py [--calls 2000] [--domain-id 42]

Uses whichever backend ``biped_opt.ros`` selects (``BIPED_OPT_BACKEND``); loopback only.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("ROS_LOCALHOST_ONLY", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from biped_opt import ros  # noqa: E402


def _serve(request, response):
    response.success = True
    response.value = 2.0 * request.theta0
    response.policy = [1.0, 2.0]
    response.value_derivative = [0.5, -0.5]
    return response


def server_main() -> None:
    ros.init()
    node = ros.Node("bench_server")
    node.create_service(ros.srvs.OptimalPolicy, "/bench/optimal_policy", _serve)
    print("ready", flush=True)
    try:
        ros.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        ros.try_shutdown()


def _round_trips(node, executor, calls: int) -> np.ndarray:
    client = node.create_client(ros.srvs.OptimalPolicy, "/bench/optimal_policy")
    if not client.wait_for_service(timeout_sec=20.0):
        raise RuntimeError("service /bench/optimal_policy did not appear")
    request = ros.srvs.OptimalPolicy.Request(maneuver="touchdown", theta0=0.1)
    for _ in range(50):  # warm-up
        future = client.call_async(request)
        executor.spin_until_future_complete(future, timeout_sec=5.0)
    times = np.empty(calls)
    for i in range(calls):
        t0 = time.perf_counter()
        future = client.call_async(request)
        executor.spin_until_future_complete(future, timeout_sec=5.0)
        times[i] = time.perf_counter() - t0
        if not future.done():
            raise RuntimeError(f"call {i} lost")
    node.destroy_client(client)
    return times * 1e3


def _report(label: str, ms: np.ndarray) -> None:
    p50, p99 = np.percentile(ms, [50, 99])
    print(f"{label:<34} n={ms.size:5d}  p50={p50:.3f} ms  p99={p99:.3f} ms  max={ms.max():.3f} ms")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=2000)
    parser.add_argument("--domain-id", type=int, default=1 + os.getpid() % 200)
    parser.add_argument("--publish-seconds", type=float, default=2.0)
    parser.add_argument("--serve", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    os.environ["ROS_DOMAIN_ID"] = str(args.domain_id)
    if args.serve:
        server_main()
        return 0
    print(f"backend={ros.BACKEND} domain={args.domain_id} calls={args.calls}")
    ctx = ros.Context()
    ros.init(context=ctx, domain_id=args.domain_id)
    node = ros.Node("bench_client", context=ctx)
    executor = ros.SingleThreadedExecutor(context=ctx)
    executor.add_node(node)

    server = ros.Node("bench_server_local", context=ctx, namespace="/local")
    server.create_service(ros.srvs.OptimalPolicy, "/bench/optimal_policy", _serve)
    executor.add_node(server)
    _report("service round trip, one process", _round_trips(node, executor, args.calls))
    executor.remove_node(server)
    server.destroy_node()

    proc = subprocess.Popen([sys.executable, __file__, "--serve", "--domain-id",
                             str(args.domain_id)], stdout=subprocess.PIPE, text=True)
    try:
        proc.stdout.readline()
        _report("service round trip, two processes", _round_trips(node, executor, args.calls))
    finally:
        proc.terminate()
        proc.wait(10)

    received = []
    node.create_subscription(ros.msgs.BipedState, "/bench/state", received.append, 10)
    pub = node.create_publisher(ros.msgs.BipedState, "/bench/state", 10)
    deadline = time.monotonic() + 5.0
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    msg = ros.msgs.BipedState(maneuver="touchdown", q=[0.1] * 7, qdot=[0.2] * 7)
    sent, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < args.publish_seconds:
        msg.t = float(sent)
        pub.publish(msg)
        sent += 1
        executor.spin_once(timeout_sec=0.0)
    elapsed = time.perf_counter() - t0
    print(f"{'BipedState publish+take, one process':<34} {sent / elapsed:9.0f} msg/s, "
          f"{sent} sent "
          f"({len({m.t for m in received})} distinct of {len(received)} delivered to the "
          "subscription callback)")
    node.destroy_node()
    ros.try_shutdown(context=ctx)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
