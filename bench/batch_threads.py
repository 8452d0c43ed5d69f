"""A batch never loses to single calls in a loop, also with another process busy on one core.

For each system, times one trajectory per case three ways -- single calls in a loop, one batch
(``CompiledSystem.simulate_batch``: its threads take pieces of the cases as they finish, see
docs/SYSTEMS.md Sec. 1), and one batch forced to a single thread -- on an idle machine and
again while a second process spins on one core. Prints per-trajectory times and the ratio
batch / loop (below 1: the batch is faster) for each; the cases are the same in every column.

    python bench/batch_threads.py [--cases 400] [--rounds 5] [--system biped ...] [--json]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from biped_opt.simulation import compiled as compiled_systems  # noqa: E402

#: each system's maneuver, its s range for the cases, and inputs
SYSTEMS = {
    "biped": ("touchdown", 0.25, (2.0, 0.5, 0.0)),
    "walker2_coupled": ("touchdown", 0.25, None),
    "rocking_bar": ("drop", 0.3, None),
}


def _best(fn, rounds: int) -> float:
    best = float("inf")
    for _ in range(rounds):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def measure(name: str, cases: int, rounds: int) -> dict[str, float]:
    maneuver, span, inputs = SYSTEMS[name]
    c = compiled_systems.compile_system(name)
    s = np.linspace(-span, span, cases)
    u = c.input_vector(inputs)
    c.simulate(maneuver, 0.0, u)
    c.simulate_batch(maneuver, s[:2], u)  # (compiled or loaded before timing)
    shared, sv = c.shared_kernel()
    kernel = shared.simulate_batch_kernel

    given = tuple(u.tolist())  # (a tuple: the single call's quick input check)

    def loop() -> None:
        for v in s:
            c.simulate(maneuver, float(v), given)

    def batch() -> None:
        c.simulate_batch(maneuver, s, u)

    def one_thread() -> None:  # the batch's arrays, then the kernel in this thread alone
        m = c.module
        n = s.size
        opts = c.maneuver_options(maneuver)
        compiled_systems.run_batch(
            kernel, n, (c.prepared, sv, c.code(maneuver), s, np.tile(u, (n, 1)), c._cfg(opts, 0.0),
                        np.zeros((n, opts.max_events + 1, m.EVENT_WIDTH)),
                        np.zeros((n, m.NSTATE)), np.zeros(n), np.zeros((n, 8))), threads=1)

    out = {}
    for label, fn in (("loop", loop), ("batch", batch), ("batch_1_thread", one_thread)):
        out[f"{label}_us"] = _best(fn, rounds) / cases * 1e6
    out["batch_over_loop"] = out["batch_us"] / out["loop_us"]
    out["threads"] = compiled_systems.batch_threads(cases)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=400)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--system", action="append", choices=sorted(SYSTEMS))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    names = args.system or list(SYSTEMS)
    results: dict[str, dict[str, dict[str, float]]] = {}
    for condition in ("idle", "one_core_busy"):
        spinner = None
        if condition == "one_core_busy":
            spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
            time.sleep(0.5)
        try:
            results[condition] = {n: measure(n, args.cases, args.rounds) for n in names}
        finally:
            if spinner is not None:
                spinner.kill()
                spinner.wait()
    if args.json:
        print(json.dumps({"cores": compiled_systems.available_cores(), "cases": args.cases,
                          "results": results}, indent=1))
        return 0
    print(f"{args.cases} cases, {compiled_systems.available_cores()} cores; per trajectory, best "
          f"of {args.rounds}")
    print(f"{'condition':15s} {'system':16s} {'loop':>9s} {'batch':>9s} {'1 thread':>9s} "
          f"{'threads':>7s} {'batch/loop':>10s}")
    for condition, by_system in results.items():
        for n, r in by_system.items():
            print(f"{condition:15s} {n:16s} {r['loop_us']:8.1f}u {r['batch_us']:8.1f}u "
                  f"{r['batch_1_thread_us']:8.1f}u {r['threads']:7d} {r['batch_over_loop']:10.2f}")
    worst = max(r["batch_over_loop"] for by in results.values() for r in by.values())
    print(f"worst batch/loop: {worst:.2f} ({'never slower' if worst <= 1.0 else 'SLOWER'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
