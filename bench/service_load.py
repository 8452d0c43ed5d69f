"""Reliability of the optimiser service under concurrent load.

Starts one optimiser node in its own process, then N client processes that each make M calls of
``/biped/optimal_policy`` one after another, every call with an angle no other call uses (so no
reply comes from the node's cache and every request costs a real optimisation; ``--cached``:
every client asks the same 10 angles over and over, so all but the first answers come from the
cache and replies follow each other as fast as the clients take them). Prints

- sent, answered, lost (no reply within ``--timeout``), late (answered after it), duplicated
  (a second reply to one request) and misrouted (a reply whose numbers are not those of its
  request: every answered call is checked afterwards against ``optimal_policy`` run in this
  process, which is deterministic, so they must agree to the last bit);
- p50/p99 latency of the answered calls;
- the node's resident memory (VmRSS) after its start-up and after the load.

With ``--rmw-reader`` every client's reply reader keeps the last 10 replies, as the reader
rmw_cyclonedds creates for rclpy's default service QoS (this package's own client keeps all,
README "ROS 2"); each client then also holds a second, keep-all reader on the reply topic that
it reads only at the end, to tell why a call was lost: its reply reached the process but was
pushed out of the 10-deep history by replies to other clients before it was taken
(``evicted``), or it never arrived (``never_arrived``: the reply was not written, or the
server's writer dropped it before this reader acknowledged it).

``--lossy PERMILLE`` makes the node drop that share of the packets it sends (Cyclone's
``Internal/Test/XmitLossiness``), so that replies reach the clients only through the reliable
protocol's repairs, from what the node's reply writer still holds.

    python bench/service_load.py [--clients 8] [--calls 200] [--runs 1] [--cache-size N]
                                 [--rmw-reader] [--cached] [--lossy PERMILLE] [--json]
    python bench/service_load.py --adversarial [--flood 2000] [--flood-seconds 5] [--deaf 40]

``--adversarial`` measures what one client's misbehaviour costs another (services module doc,
README "Who may ask what"): a second client (this process) asks the node for one answer it has
cached, again and again, and for a fresh one now and then, while

- *flood*: one client process sends ``--flood`` requests for angles nobody asked before (every
  one an optimisation) within ``--flood-seconds``, without waiting for replies;
- *deaf*: one client process whose reply reader is gone sends ``--deaf`` requests (for the
  cached angle: each costs the node only its reply).

It prints, per phase, the second client's latencies (cached and fresh: count, median, largest)
and what the misbehaving client got (answered, refused busy, unanswered).

The node runs on whichever backend ``biped_opt.ros`` selects; discovery is loopback only.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("ROS_LOCALHOST_ONLY", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

#: touchdown angles are drawn from this interval (inside the maneuver's |th0| <= 0.25)
SPAN = 0.24


def angles(client: int, clients: int, calls: int) -> list[float]:
    """Angles of one client: a slice of one grid of clients * calls distinct values."""
    grid = np.linspace(-SPAN, SPAN, clients * calls)
    return [float(v) for v in grid[client::clients]]


def rss_kib(pid: int, field: str = "VmRSS") -> int:
    """Resident set size of a process [KiB] (Linux /proc); ``field="VmHWM"``: its peak."""
    with open(f"/proc/{pid}/status", encoding="ascii") as fh:
        for line in fh:
            if line.startswith(f"{field}:"):
                return int(line.split()[1])
    raise RuntimeError(f"no {field} for process {pid}")


# -- one client process --------------------------------------------------------------------------

def rmw_style_client(node: Any, srv_type: Any, name: str) -> Any:
    """A client of the built-in backend whose reply reader keeps the last 10 replies, as
    rmw_cyclonedds' reader for rclpy's default service QoS does (endpoints, USER_DATA and
    header otherwise the backend's, which follow rmw_cyclonedds)."""
    from biped_opt.ros.dds import qos_profile_services_default
    from biped_opt.ros.dds.services import Client

    class RmwStyleClient(Client):
        reader_keeps_all = False

    return node._add(RmwStyleClient(node, srv_type, node._resolve(name),
                                    qos_profile_services_default, node.default_callback_group))


def optimiser_client(name: str, rmw_reader: bool = False) -> tuple[Any, Any, Any]:
    """(node, client of /biped/optimal_policy, executor spinning in a thread) in the default
    context, once the service is there; ``close_client`` ends them. ``rmw_reader``: the
    client's reply reader keeps the last 10 replies (built-in backend only)."""
    from biped_opt import ros

    ros.init(args=[])
    node = ros.Node(name)
    if rmw_reader:
        cli = rmw_style_client(node, ros.srvs.OptimalPolicy, "/biped/optimal_policy")
    else:
        cli = node.create_client(ros.srvs.OptimalPolicy, "/biped/optimal_policy")
    executor = ros.SingleThreadedExecutor()
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    if not cli.wait_for_service(timeout_sec=60.0):
        raise SystemExit(f"{name}: /biped/optimal_policy did not appear")
    return node, cli, executor


def close_client(node: Any, executor: Any) -> None:
    from biped_opt import ros

    executor.shutdown()
    node.destroy_node()
    ros.try_shutdown()


def witness_reader(node: Any) -> Any:
    """A keep-all reader of the optimiser's reply topic next to an rmw-style client, without
    USER_DATA (no server waits for it), read only at the end (``client_main``)."""
    from cyclonedds.sub import DataReader

    from biped_opt import ros
    from biped_opt.ros.dds.qos import HistoryPolicy, QoSProfile, to_dds_qos

    topic = node._topic("rr/biped/optimal_policyReply", ros.srvs.OptimalPolicy.ResponseWire)
    return DataReader(node.context.participant, topic,
                      qos=to_dds_qos(QoSProfile(history=HistoryPolicy.KEEP_ALL)))


def client_main(index: int, clients: int, calls: int, timeout: float,
                rmw_reader: bool = False, cached: bool = False) -> None:
    """Make the calls of client ``index``; print one JSON line with every outcome."""
    from biped_opt import ros
    from biped_opt.ros.dds import wire

    node, cli, executor = optimiser_client(f"load_client_{index}", rmw_reader)
    witness = witness_reader(node) if rmw_reader else None
    results = []
    late: list[float] = []
    lost_seqs: list[int] = []
    # cached: every client asks the same 10 angles over and over, answered from the node's
    # cache after the first few rounds
    few = angles(0, 1, 10)
    for th in ([few[k % 10] for k in range(calls)] if cached
               else angles(index, clients, calls)):
        done = threading.Event()
        t0 = time.perf_counter()
        future = cli.call_async(ros.srvs.OptimalPolicy.Request(maneuver="touchdown", theta0=th))
        seq = len(results) + 1  # the client numbers its requests 1, 2, ...
        future.add_done_callback(lambda _f, done=done: done.set())
        if not done.wait(timeout):
            results.append({"theta0": th, "answered": False})
            lost_seqs.append(seq)
            future.add_done_callback(lambda _f, th=th: late.append(th))
            continue
        reply = future.result()
        results.append({
            "theta0": th, "answered": True, "latency_ms": (time.perf_counter() - t0) * 1e3,
            "success": bool(reply.success), "value": float(reply.value),
            "policy": [float(v) for v in np.asarray(reply.policy)],
        })
    time.sleep(0.5)  # a reply still on its way counts as late, not lost
    duplicates = int(getattr(cli, "duplicate_replies", 0))
    evicted = 0
    if witness is not None:
        arrived: set[int] = set()
        while True:
            samples, _ = wire.take(witness)
            if not samples:
                break
            arrived.update(int(r.header.seq) for r in samples
                           if (int(r.header.guid) & ((1 << 64) - 1)) == cli.guid)
        evicted = sum(seq in arrived for seq in lost_seqs)
        witness.__del__()
    print(json.dumps({"client": index, "results": results, "late": late,
                      "duplicates": duplicates, "evicted": evicted}), flush=True)
    close_client(node, executor)


# -- adversarial: one client floods or never reads, another measures ---------------------------

#: the angle the measuring client keeps asking (its answer cached once asked), and where its
#: fresh angles and the flood's come from (no two requests of a run share an angle)
CACHED_ANGLE = 0.0123


def flood_main(count: int, seconds: float, deaf: bool) -> None:
    """The misbehaving client: once ``go`` arrives on stdin, ``count`` requests in ``seconds``
    without waiting (fresh angles; ``deaf``: the cached angle, the client's reply reader
    deleted first), then up to 60 s for the replies; one JSON line of what it got."""
    from biped_opt import ros

    node, cli, executor = optimiser_client("flooder")
    if deaf:
        with cli._lock:  # (built-in backend): requests still go out, replies reach nobody
            condition, reader = cli.condition, cli._reader
            cli.condition = cli._reader = None
        condition.__del__()
        reader.__del__()
        time.sleep(0.5)
    print("ready", flush=True)
    sys.stdin.readline()
    grid = np.linspace(-SPAN, SPAN, count + 1)[1:]
    futures = []
    t0 = time.monotonic()
    for k in range(count):
        th = CACHED_ANGLE if deaf else float(grid[k])
        futures.append(cli.call_async(
            ros.srvs.OptimalPolicy.Request(maneuver="touchdown", theta0=th)))
        pause = t0 + (k + 1) * seconds / count - time.monotonic()
        if pause > 0:
            time.sleep(pause)
    sent = time.monotonic() - t0
    deadline = time.monotonic() + (3.0 if deaf else 600.0)
    for future in futures:
        future.wait(max(0.0, deadline - time.monotonic()))
    done = [f.result() for f in futures if f.done() and not f.cancelled()]
    print(json.dumps({
        "sent": count, "sending_s": sent, "answered": sum(r.success for r in done),
        "busy": sum((not r.success) and r.message.startswith("busy") for r in done),
        "refused": sum((not r.success) and not r.message.startswith("busy") for r in done),
        "unanswered": count - len(done), "drain_s": time.monotonic() - t0}), flush=True)
    close_client(node, executor)


def measure_while(cli: Any, proc: subprocess.Popen, fresh: list[float], least: float,
                  timeout: float) -> dict:
    """The measuring client's calls while ``proc`` runs (at least ``least`` s): the cached
    angle every 0.2 s, a fresh angle every fifth call; latencies [s] by kind."""
    from biped_opt import ros

    out: dict[str, list[float]] = {"cached": [], "fresh": []}
    lost = 0
    start, k = time.monotonic(), 0
    while proc.poll() is None or time.monotonic() - start < least:
        kind = "fresh" if k % 5 == 4 and fresh else "cached"
        th = fresh.pop() if kind == "fresh" else CACHED_ANGLE
        t0 = time.monotonic()
        future = cli.call_async(ros.srvs.OptimalPolicy.Request(maneuver="touchdown", theta0=th))
        if future.wait(timeout) and future.result().success:
            out[kind].append(time.monotonic() - t0)
        else:
            lost += 1
        k += 1
        time.sleep(max(0.0, 0.2 - (time.monotonic() - t0)))
    return {**{f"{kind}_{what}": value for kind, times in out.items()
               for what, value in (("n", len(times)),
                                   ("p50_s", float(np.median(times)) if times else None),
                                   ("max_s", max(times) if times else None))},
            "unanswered": lost}


def adversarial(args: argparse.Namespace, domain_id: int) -> dict:
    node = start_node(domain_id, None)
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "PYTHONPATH": str(ROOT)}
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    out: dict[str, Any] = {"flood": args.flood, "flood_seconds": args.flood_seconds,
                           "deaf": args.deaf}
    client, cli, executor = optimiser_client("measuring")
    try:
        from biped_opt import ros

        first = cli.call_async(ros.srvs.OptimalPolicy.Request(maneuver="touchdown",
                                                             theta0=CACHED_ANGLE))
        assert first.wait(120.0) and first.result().success, "the node does not answer"
        fresh = [float(v) for v in np.linspace(-0.2, 0.2, 4001)[1::2]]  # (off the flood's grid)
        for phase, extra in (("flood", ["--flood", str(args.flood), "--flood-seconds",
                                        str(args.flood_seconds)]),
                             ("deaf", ["--flood", str(args.deaf), "--flood-seconds", "0.5",
                                       "--deaf-client"])):
            proc = subprocess.Popen([sys.executable, __file__, "--client", "-1", *extra],
                                    env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                    text=True)
            assert proc.stdin is not None and proc.stdout is not None
            assert proc.stdout.readline().strip() == "ready"
            proc.stdin.write("go\n")
            proc.stdin.flush()
            measured = measure_while(cli, proc, fresh, least=args.flood_seconds + 2.0,
                                     timeout=args.timeout)
            flooder = json.loads(proc.communicate()[0].strip().splitlines()[-1])
            out[phase] = {"second_client": measured, "misbehaving_client": flooder}
        out["node_rss_kib"] = rss_kib(node.pid)
    finally:
        close_client(client, executor)
        node.terminate()
        node.wait(30)
    return out


# -- the node and the run ------------------------------------------------------------------------

def start_node(domain_id: int, cache_size: int | None, *, kind: str = "optimiser",
               parameters: tuple[str, ...] = (), cwd: Path | None = None,
               memory_cap: int | None = None, lossiness: int = 0) -> subprocess.Popen:
    """A node (``biped-opt node <kind>``) in a process of its own, once it logged its ready
    line; what it logs goes on being collected in ``proc.log_lines``. ``parameters``: more
    ``name:=value``; ``memory_cap``: its address space limit [bytes]; ``lossiness``: per mille
    of the node's packets that Cyclone drops instead of sending (its test setting)."""
    args = [sys.executable, "-m", "biped_opt.cli.main", "node", kind, "--ros-args"]
    if cache_size is not None:
        args += ["-p", f"cache_size:={cache_size}"]
    for parameter in parameters:
        args += ["-p", parameter]
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "PYTHONPATH": str(ROOT)}
    if lossiness:
        from biped_opt.ros.dds.context import loopback_config

        env["CYCLONEDDS_URI"] = loopback_config().replace(
            "</Domain>", "<Internal><Test><XmitLossiness>"
            f"{lossiness}</XmitLossiness></Test></Internal></Domain>")

    def limit() -> None:
        import resource

        if memory_cap is not None:
            resource.setrlimit(resource.RLIMIT_AS, (memory_cap, memory_cap))

    proc = subprocess.Popen(args, env=env, stderr=subprocess.PIPE, text=True, cwd=cwd,
                            preexec_fn=limit if memory_cap is not None else None)
    deadline = time.monotonic() + 300.0
    assert proc.stderr is not None
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            raise RuntimeError(f"the {kind} node exited with status {proc.wait()}")
        if "ready" in line:
            lines = [line]
            proc.log_lines = lines  # type: ignore[attr-defined]
            threading.Thread(target=lines.extend, args=(proc.stderr,), daemon=True).start()
            return proc
    proc.kill()
    raise RuntimeError(f"the {kind} node did not report ready within 300 s")


def run_once(args: argparse.Namespace, domain_id: int) -> dict:
    node = start_node(domain_id, args.cache_size, lossiness=args.lossy)
    try:
        rss_before = rss_kib(node.pid)
        env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "PYTHONPATH": str(ROOT)}
        t0 = time.perf_counter()
        procs = [subprocess.Popen(
            [sys.executable, __file__, "--client", str(k), "--clients", str(args.clients),
             "--calls", str(args.calls), "--timeout", str(args.timeout)]
            + (["--rmw-reader"] if args.rmw_reader else [])
            + (["--cached"] if args.cached else []),
            env=env, stdout=subprocess.PIPE, text=True) for k in range(args.clients)]
        outputs = [json.loads(p.communicate()[0].strip().splitlines()[-1]) for p in procs]
        wall = time.perf_counter() - t0
        rss_after = rss_kib(node.pid)
    finally:
        node.terminate()
        node.wait(30)
    return summarise(outputs, wall, rss_before, rss_after, args)


def summarise(outputs: list[dict], wall: float, rss_before: int, rss_after: int,
              args: argparse.Namespace) -> dict:
    from biped_opt.paper.problems import get_problem
    from biped_opt.paper.solve import optimal_policy

    problem = get_problem("touchdown")
    rows = [r for out in outputs for r in out["results"]]
    answered = [r for r in rows if r["answered"]]
    misrouted = 0
    if args.verify:
        for r in answered:
            expected = optimal_policy(problem, r["theta0"])
            if (r["value"] != float(expected.value)
                    or r["policy"] != [float(v) for v in expected.x]):
                misrouted += 1
    latency = np.array([r["latency_ms"] for r in answered]) if answered else np.zeros(1)
    lost = len(rows) - len(answered)
    evicted = sum(out["evicted"] for out in outputs)
    return {
        "clients": args.clients, "calls_per_client": args.calls,
        "reply_reader": "keep-last-10 (rmw)" if args.rmw_reader else "keep-all",
        "cached": args.cached, "lossy_permille": args.lossy,
        "sent": len(rows), "answered": len(answered), "lost": lost,
        "lost_evicted": evicted if args.rmw_reader else None,
        "lost_never_arrived": lost - evicted if args.rmw_reader else None,
        "late": sum(len(out["late"]) for out in outputs),
        "duplicated": sum(out["duplicates"] for out in outputs),
        "misrouted": misrouted if args.verify else None,
        "failed_replies": sum(not r["success"] for r in answered),
        "p50_ms": float(np.percentile(latency, 50)), "p99_ms": float(np.percentile(latency, 99)),
        "wall_s": wall, "calls_per_s": len(answered) / wall,
        "node_rss_kib_before": rss_before, "node_rss_kib_after": rss_after,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, default=8)
    parser.add_argument("--calls", type=int, default=200, help="calls per client")
    parser.add_argument("--timeout", type=float, default=30.0, help="per call [s]")
    parser.add_argument("--runs", type=int, default=1)
    parser.add_argument("--cache-size", type=int, default=None,
                        help="the optimiser's cache_size parameter (default: the node's)")
    parser.add_argument("--no-verify", dest="verify", action="store_false",
                        help="skip the misrouting check (recomputing every answer)")
    parser.add_argument("--rmw-reader", action="store_true",
                        help="clients' reply readers keep the last 10 replies, as rmw's do")
    parser.add_argument("--cached", action="store_true",
                        help="every client asks the same angles: replies at the rate of the "
                             "node's cache, not of the optimisation")
    parser.add_argument("--lossy", type=int, default=0, metavar="PERMILLE",
                        help="the node drops this per mille of the packets it sends (Cyclone's "
                             "test setting): replies must be repaired from its writer's history")
    parser.add_argument("--domain-id", type=int, default=1 + os.getpid() % 200)
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--adversarial", action="store_true",
                        help="a second client's latency while one floods, then while one "
                             "never reads its replies (see the module docstring)")
    parser.add_argument("--flood", type=int, default=2000,
                        help="--adversarial: requests the flooding client sends")
    parser.add_argument("--flood-seconds", type=float, default=5.0,
                        help="--adversarial: within this many seconds")
    parser.add_argument("--deaf", type=int, default=40,
                        help="--adversarial: requests of the client without a reply reader")
    parser.add_argument("--deaf-client", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--client", type=int, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.client == -1:
        flood_main(args.flood, args.flood_seconds, args.deaf_client)
        return 0
    if args.adversarial:
        result = adversarial(args, args.domain_id)
        if args.json:
            print(json.dumps(result), flush=True)
            return 0
        for phase in ("flood", "deaf"):
            m, f = result[phase]["second_client"], result[phase]["misbehaving_client"]
            what = (f"one client sent {f['sent']} fresh requests in {f['sending_s']:.1f} s"
                    if phase == "flood" else
                    f"one client without a reply reader sent {f['sent']} requests")

            def sec(v: float | None) -> str:
                return "-" if v is None else f"{v:.3f} s"

            print(f"{phase}: {what}: it got {f['answered']} answers, {f['busy']} busy, "
                  f"{f['refused']} refused, {f['unanswered']} unanswered ({f['drain_s']:.1f} s);"
                  f" the second client's cached requests: {m['cached_n']}, median "
                  f"{sec(m['cached_p50_s'])}, largest {sec(m['cached_max_s'])}; fresh: "
                  f"{m['fresh_n']}, median {sec(m['fresh_p50_s'])}, largest "
                  f"{sec(m['fresh_max_s'])}; unanswered {m['unanswered']}", flush=True)
        print(f"node RSS {result['node_rss_kib'] / 1024:.1f} MiB")
        return 0
    if args.client is not None:
        client_main(args.client, args.clients, args.calls, args.timeout, args.rmw_reader,
                    args.cached)
        return 0
    summaries = []
    for run in range(args.runs):
        summary = run_once(args, args.domain_id)
        summaries.append(summary)
        if args.json:
            print(json.dumps(summary), flush=True)
        else:
            why = ("" if summary["lost_evicted"] is None else
                   f" ({summary['lost_evicted']} evicted from the reader's history, "
                   f"{summary['lost_never_arrived']} never arrived)")
            print(f"run {run + 1}: {summary['clients']} clients x {summary['calls_per_client']} "
                  f"calls, {summary['reply_reader']} reply readers: sent {summary['sent']}, "
                  f"answered {summary['answered']}, lost {summary['lost']}{why}, late "
                  f"{summary['late']}, duplicated "
                  f"{summary['duplicated']}, misrouted {summary['misrouted']}, failed replies "
                  f"{summary['failed_replies']}; p50 {summary['p50_ms']:.1f} ms, p99 "
                  f"{summary['p99_ms']:.1f} ms; {summary['calls_per_s']:.1f} calls/s; node RSS "
                  f"{summary['node_rss_kib_before'] / 1024:.1f} -> "
                  f"{summary['node_rss_kib_after'] / 1024:.1f} MiB", flush=True)
    return 0 if all(s["lost"] == 0 and not s["misrouted"] for s in summaries) else 1


if __name__ == "__main__":
    raise SystemExit(main())
