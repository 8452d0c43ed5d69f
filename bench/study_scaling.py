"""Throughput of a parameter study fanned out over optimiser nodes (issue 15's performance).

A 20 x 20 grid (gamma x w) of the rocking bar's drop at fixed inputs, ``num`` s values a point:
computed in this process (``evaluate_point`` in a loop: the reference), then by one and by two
optimiser nodes (separate processes, ``biped-opt node optimiser``) through a coordinator in this
process. Reports points/s, the speed-up of two nodes over one, and the coordination overhead per
work item with one node: (wall time - time in-process) / points, and (wall time - the compute
time the node reports) / points, which other load on the machine disturbs less.

    python bench/study_scaling.py [--side 20] [--num 21] [--domain-id 77]

Loopback only (``ROS_LOCALHOST_ONLY=1``). Each node is warmed up first (the bar's kernel loaded,
a first point computed), so the timings are of the study alone.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("ROS_LOCALHOST_ONLY", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from biped_opt.nodes.coordinator import coordinator_on_domain  # noqa: E402
from biped_opt.studies.study import Study, evaluate_point  # noqa: E402


def study(side: int, num: int, name: str = "scaling") -> Study:
    return Study.from_spec({
        "name": name, "system": "rocking_bar", "maneuver": "drop", "num": num,
        "grid": {"gamma": [0.3 + 0.5 * i / (side - 1) for i in range(side)],
                 "w": [0.4 + 0.2 * i / (side - 1) for i in range(side)]}})


def in_process(st: Study) -> float:
    points = st.points()
    evaluate_point(st, 0, points[0])  # kernel loaded
    start = time.perf_counter()
    for i, values in enumerate(points):
        evaluate_point(st, i, values)
    return time.perf_counter() - start


EXTRA_ENV: dict[str, str] = {}


def start_nodes(count: int, domain: int) -> list[subprocess.Popen]:
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "PYTHONPATH": str(ROOT), **EXTRA_ENV}
    return [subprocess.Popen(
        [sys.executable, "-m", "biped_opt.cli.main", "node", "optimiser", "--ros-args",
         "-p", "warm_up:=false", "-p", f"worker:=bench{k}"],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for k in range(count)]


def on_nodes(st: Study, count: int, domain: int, work: Path) -> tuple[float, float]:
    """(wall time, compute time the nodes reported) of the study on ``count`` nodes."""
    nodes = start_nodes(count, domain)
    try:
        with coordinator_on_domain(domain) as coordinator:
            deadline = time.monotonic() + 60
            while len(coordinator.workers()) < count:
                if time.monotonic() > deadline:
                    raise RuntimeError(f"{count} optimiser nodes did not appear in 60 s")
                time.sleep(0.1)
            # warm-up: every node loads the kernel and computes points before the timing
            coordinator.run_study(study(3, st.num, name=f"warm{count}"),
                                  work / f"warm{count}.csv")
            assert len(coordinator.served) == count
            start = time.perf_counter()
            summary = coordinator.run_study(st, work / f"nodes{count}.csv")
            seconds = time.perf_counter() - start
            assert summary.computed == len(st.points()) and not summary.stopped
            return seconds, coordinator.node_seconds
    finally:
        for proc in nodes:
            proc.terminate()
        for proc in nodes:
            proc.wait(30)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--side", type=int, default=20, help="grid side (points: side^2)")
    parser.add_argument("--num", type=int, default=21, help="s values per point")
    parser.add_argument("--domain-id", type=int, default=77)
    args = parser.parse_args()
    load = os.getloadavg()
    st = study(args.side, args.num)
    n = len(st.points())
    t_in = in_process(st)
    with tempfile.TemporaryDirectory() as tmp:
        t1, busy1 = on_nodes(st, 1, args.domain_id, Path(tmp))
        t2, _ = on_nodes(st, 2, args.domain_id, Path(tmp))
    print(f"study: {n} points (rocking bar, drop, num={args.num}); load average before: "
          f"{load[0]:.2f} (other work on the machine takes cores from the nodes)")
    print(f"in-process   : {t_in:7.2f} s  {n / t_in:7.1f} points/s")
    print(f"1 node       : {t1:7.2f} s  {n / t1:7.1f} points/s")
    print(f"2 nodes      : {t2:7.2f} s  {n / t2:7.1f} points/s")
    print(f"speed-up 2 nodes / 1 node: {t1 / t2:.2f}x (target >= 1.8x)")
    print(f"coordination overhead per item: {1e3 * (t1 - t_in) / n:.2f} ms vs in-process, "
          f"{1e3 * (t1 - busy1) / n:.2f} ms vs the node's own compute time (target <= 1 ms)")


if __name__ == "__main__":
    main()
