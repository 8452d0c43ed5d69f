"""What drawing costs a recorded sweep: ``/clock``, ``/tf``, markers and the URDF (issue 24).

Records the same fixed-input sweep of the biped's touchdown through the nodes (simulator and
recorder in one process on the built-in backend, as ``biped-opt launch`` runs them) with the
nodes' ``scene`` parameter on and off, alternating, and prints the best time of each, the ratio
on/off (target <= 1.10: drawing costs at most 10% of the sweep) and the file sizes.

    python bench/scene_cost.py [--num 401] [--rounds 3] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from biped_opt.nodes.graph import Graph  # noqa: E402
from biped_opt.nodes.recorder import SweepRequest  # noqa: E402

TARGET = 1.10


def _sweep(graph: Graph, out: Path, num: int) -> tuple[float, int, dict[str, int]]:
    t0 = time.perf_counter()
    summary = graph.recorder.record(SweepRequest(
        maneuver="touchdown", theta0_min=-0.25, theta0_max=0.25, num=num, optimal=False,
        output=out))
    seconds = time.perf_counter() - t0
    return seconds, out.stat().st_size, dict(summary.counts)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--num", type=int, default=401)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    best = {True: float("inf"), False: float("inf")}
    sizes: dict[bool, int] = {}
    counts: dict[bool, dict[str, int]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        # (each graph on a domain of its own: the recorders must reach their own simulator)
        base = 100 + os.getpid() % 60
        graphs = {on: Graph(overrides={n: {"scene": on, "autostart": False}
                                       for n in ("simulator", "recorder")},
                            domain_id=base + 60 * on)
                  for on in (True, False)}
        try:
            for on in (True, False):  # warm: kernels loaded, layouts built
                _sweep(graphs[on], Path(tmp) / "warm.mcap", 5)
            for r in range(args.rounds):
                for on in (True, False):
                    s, size, n = _sweep(graphs[on], Path(tmp) / f"{on}_{r}.mcap", args.num)
                    best[on] = min(best[on], s)
                    sizes[on], counts[on] = size, n
        finally:
            for g in graphs.values():
                g.close()
    ratio = best[True] / best[False]
    result = {"num": args.num, "rounds": args.rounds, "seconds_with_scene": best[True],
              "seconds_without_scene": best[False], "ratio": ratio, "target": TARGET,
              "meets_target": ratio <= TARGET, "file_MB_with_scene": sizes[True] / 1e6,
              "file_MB_without_scene": sizes[False] / 1e6, "messages_with_scene": counts[True]}
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(f"sweep of {args.num} points, best of {args.rounds}: with scene "
              f"{best[True]:.2f} s, without {best[False]:.2f} s, ratio {ratio:.3f} "
              f"(target <= {TARGET}); file {sizes[True] / 1e6:.1f} MB vs "
              f"{sizes[False] / 1e6:.1f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
