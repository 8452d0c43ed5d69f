"""Fuzz the optimiser node with malformed requests and check it keeps serving.

Starts one optimiser node in its own process and writes N requests (default 10,000) straight
onto ``rq/biped/optimal_policyRequest`` with Cyclone's raw write, each a seeded random
corruption of a valid request: bit flips in the maneuver name or anywhere in the body, random
bytes of random length as the name (mostly not UTF-8), wrong string lengths. Cyclone refuses
the structurally invalid ones at the writer (its CDR check; a receiving Cyclone applies the
same check); every other one reaches the node. Prints how many were written, refused by
Cyclone, answered ``success = false``, answered otherwise and left unanswered, whether a valid
request is still answered correctly afterwards, the node's exit status on SIGINT and whether
its stderr holds a traceback.

    python bench/request_fuzz.py [--requests 10000] [--seed 1]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import struct
import sys
import time
from pathlib import Path

os.environ.setdefault("ROS_LOCALHOST_ONLY", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cyclonedds._clayer import ddspy_write  # noqa: E402

from bench.service_load import (  # noqa: E402
    close_client,
    optimiser_client,
    rss_kib,
    start_node,
)


def _string(text: bytes) -> bytes:
    raw = struct.pack("<I", len(text) + 1) + text + b"\x00"
    return raw + bytes(-len(raw) % 8)


#: the request's fields after theta0: system and problem, both "" (length 1, NUL, padding)
_TAIL = struct.pack("<I", 1) + bytes(4) + struct.pack("<I", 1) + bytes(1)


def corrupt(rng: random.Random, i: int) -> bytes:
    """The body (after the 16-byte header) of the i-th malformed OptimalPolicy request."""
    name = bytearray(rng.choice([b"touchdown", b"liftoff"]))
    kind = i % 4
    if kind == 0:  # bit flips in the name
        for _ in range(rng.randint(1, 4)):
            name[rng.randrange(len(name))] ^= 1 << rng.randrange(8)
        return _string(bytes(name)) + (struct.pack("<d", 0.05) + _TAIL)
    if kind == 1:  # random bytes as the name
        return _string(rng.randbytes(rng.randrange(1, 64))) + (struct.pack("<d", 0.05) + _TAIL)
    if kind == 2:  # bit flips anywhere in the body
        body = bytearray(_string(bytes(name)) + (struct.pack("<d", 0.05) + _TAIL))
        for _ in range(rng.randint(1, 4)):
            body[rng.randrange(len(body))] ^= 1 << rng.randrange(8)
        return bytes(body)
    body = _string(bytes(name)) + (struct.pack("<d", 0.05) + _TAIL)  # a wrong string length
    return struct.pack("<I", rng.randrange(1 << 16)) + body[4:]


def run(requests: int, seed: int, domain_id: int) -> dict:
    from biped_opt import ros

    node_proc = start_node(domain_id, None)
    rss_before = rss_kib(node_proc.pid)
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    node, cli, executor = optimiser_client("fuzzer")
    rng = random.Random(seed)
    futures, refused = [], 0
    t0 = time.perf_counter()
    for i in range(requests):
        future = ros.Future()
        with cli._pending_lock:
            seq = next(cli._seq)
            cli._pending[seq] = future
        data = b"\x00\x01\x00\x00" + struct.pack("<Qq", cli.guid, seq) + corrupt(rng, i)
        if ddspy_write(cli._writer._ref, data.ljust(-(-len(data) // 4) * 4, b"\x00")) < 0:
            cli.remove_pending_request(future)
            refused += 1
        else:
            futures.append(future)
    deadline = time.monotonic() + 120.0
    while not all(f.done() for f in futures) and time.monotonic() < deadline:
        time.sleep(0.05)
    elapsed = time.perf_counter() - t0
    done = [f.result() for f in futures if f.done()]
    probe = cli.call_async(ros.srvs.OptimalPolicy.Request(maneuver="touchdown", theta0=0.05))
    probe_ok = probe.wait(60.0) and probe.result().success and \
        abs(probe.result().value - 0.0194158739485) < 1e-12  # MODEL.md R5
    rss_after = rss_kib(node_proc.pid)
    close_client(node, executor)
    node_proc.send_signal(2)
    status = node_proc.wait(30)
    time.sleep(0.2)  # the collecting thread reads the last lines
    stderr_lines = [line.rstrip() for line in node_proc.log_lines]
    return {
        "requests": requests, "seed": seed, "refused_by_cyclone": refused,
        "reached_the_node": len(futures),
        "answered_success_false": sum(not r.success for r in done),
        "answered_success_true": sum(bool(r.success) for r in done),
        "unanswered": len(futures) - len(done), "seconds": elapsed,
        "valid_request_after": bool(probe_ok), "node_exit_status": status,
        "traceback_in_node_stderr": any("Traceback" in line for line in stderr_lines),
        "node_log_lines": len(stderr_lines),
        "node_log_sample": stderr_lines[1:3],
        "node_rss_kib_before": rss_before, "node_rss_kib_after": rss_after,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--domain-id", type=int, default=1 + os.getpid() % 200)
    args = parser.parse_args()
    result = run(args.requests, args.seed, args.domain_id)
    print(json.dumps(result, indent=2))
    ok = (result["unanswered"] == 0 and result["valid_request_after"]
          and result["node_exit_status"] == 0 and not result["traceback_in_node_stderr"])
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
