"""How the costs grow with the system (issue 25 part 5): legs, coordinates, contact modes.

For each system, in one run:

- ``cold``: a new interpreter with an empty cache compiling the system and simulating once (the
  event-driven kernel every system shares is compiled once per installation, by ``make venv``,
  and is loaded from Numba's cache beside it: the script loads or compiles it first and prints
  how long that took);
- ``cached``: a new process running ``biped-opt simulate`` of it from that cache, once the kernel
  compiled ahead of time is there (what a user waits for at every later start; best of 2);
- ``per traj.``: single ``simulate`` calls over all cases in a loop, per case (best of
  ``--rounds`` loops);
- ``batch``: one ``simulate_batch`` of all cases, per case (best of ``--rounds``), timed the same
  way as the loop;
- the SciPy comparator of the same system in the same run (``bench/system_reference.py`` with
  ``bench/walker_model.py`` for the walkers; ``tests/simulation/user/reference_chain.py``, an
  independent derivation of the chains' equations, for the chains),
  its per-trajectory time and its start (a new interpreter importing SciPy and the model and
  simulating once), and each figure above as a ratio to the comparator's (below 1: faster);
- ``max |err|``: the largest outcome difference from the comparator over its cases.

Systems: the walker with n = 2, 3, 4, 6, 8, 10 legs (d = 3 + 2n, a diagonal M, 2^n contact
modes; ``--legs``, none with a bare ``--legs``) and the library's planar chains ``chain5``,
``chain7``, ``chain9``, ``chain11`` (d = 3 + 2 links per leg, a dense configuration-dependent M,
two feet; ``--chains``, default 5; ``--no-chain`` leaves them out) and, with ``--quadruped``,
the library's 3-D quadruped (d = 20, four feet, 16 modes; its comparator
``tests/simulation/user/reference_quadruped.py``, recursive Newton-Euler, its cases over its
maneuver's range [-0.1, 0.1]). Cold compiles of the larger walkers and chains take minutes;
``--legs 2 3 4`` gives a quick table.

    python bench/scaling.py [--legs 2 3 4 6 8 10] [--chains 5 7 9] [--no-chain] [--quadruped]
                            [--cases 20] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from bench.systems_bench import _best_times  # noqa: E402

#: the library's chains by their number of coordinates
CHAINS = (5, 7, 9, 11)

_COLD = """
import sys, time
t0 = time.perf_counter()
from biped_opt.simulation.compiled import CompiledSystem
system = CompiledSystem(sys.argv[1])
system.simulate(system.maneuvers[0], 0.01)
print(time.perf_counter() - t0)
"""

_REFERENCE_START = """
import sys, time
t0 = time.perf_counter()
sys.path.insert(0, sys.argv[1])
kind, n = sys.argv[2], int(sys.argv[3])
if kind == "walker":
    from bench import system_reference
    from bench.walker_model import Walker
    system_reference.simulate(Walker(n, "coupled"), "touchdown", 0.01, [0.0] * (n + 1))
elif kind == "quadruped":
    from tests.simulation.user import reference_quadruped
    reference_quadruped.simulate(reference_quadruped.Quadruped(), 0.01)
else:
    from tests.simulation.user import reference_chain
    reference_chain.simulate(reference_chain.Chain(n), 0.01)
print(time.perf_counter() - t0)
"""


def _process_seconds(args: list[str], env: dict[str, str]) -> float:
    """Wall time of a command (its own figure when it prints one on its last line)."""
    t0 = time.perf_counter()
    proc = subprocess.run(args, env=env, capture_output=True, text=True, timeout=1800,
                          check=False, cwd=ROOT)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or ["(no output)"])[-1]
        raise RuntimeError(f"{' '.join(args[:3])}...: {tail}")
    try:
        return float(proc.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        return wall


def _wait_for_ahead_of_time(folder: Path, timeout: float = 600.0) -> None:
    """Wait for the kernel compiled ahead of time that the cold compile's second process builds
    (biped_opt/codegen/aot.py): the start a user sees from the second time on."""
    from biped_opt.codegen import aot

    if not aot.enabled():
        return
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if any(p.name.endswith(aot.extension_path(folder, "").name) for p in folder.iterdir()
               if not p.name.startswith(".")):
            return
        time.sleep(0.5)
    print(f"(no kernel compiled ahead of time in {folder} after {timeout:.0f} s)", file=sys.stderr)


def measure(spec: str, kind: str, n: int, *, cases: int, rounds: int,
            reference_cases: int) -> dict[str, Any]:
    """One row of the table (see the module docstring)."""
    from biped_opt.simulation.compiled import CompiledSystem

    with tempfile.TemporaryDirectory(prefix="biped_opt_scaling_") as cache:
        env = dict(os.environ, BIPED_OPT_CACHE=cache)
        cold = _process_seconds([sys.executable, "-c", _COLD, spec], env)
        maneuver = "touchdown" if kind == "walker" else "drop"
        _wait_for_ahead_of_time(Path(cache) / "systems")
        cached = min(_process_seconds([sys.executable, "-m", "biped_opt.cli.main", "simulate",
                                       "--system", spec, "--maneuver", maneuver, "--s", "0.01"],
                                      env) for _ in range(2))
        # (this process loads what the first one compiled)
        before = os.environ.get("BIPED_OPT_CACHE")
        os.environ["BIPED_OPT_CACHE"] = cache
        try:
            compiled = CompiledSystem(spec)
            warm = np.zeros((2, len(compiled.inputs)))
            compiled.simulate_batch(maneuver, [0.0, 0.01], warm)  # (loaded while it is there)
            compiled.simulate(maneuver, 0.0, warm[0])
        finally:
            if before is None:
                del os.environ["BIPED_OPT_CACHE"]
            else:
                os.environ["BIPED_OPT_CACHE"] = before
    d, ninputs = len(compiled.coordinates), len(compiled.inputs)
    lo, hi = (-0.1, 0.1) if kind == "quadruped" else (-0.2, 0.2)  # (its maneuver's range)
    s_values = np.linspace(lo, hi, cases)
    zero = np.zeros(ninputs)
    compiled.simulate(maneuver, 0.0, zero)  # (loaded and warm)
    loop = np.inf
    for _ in range(rounds):
        t0 = time.perf_counter()
        for s in s_values:
            compiled.simulate(maneuver, s, zero)
        loop = min(loop, (time.perf_counter() - t0) / cases)
    batch = np.inf
    for _ in range(rounds):
        t0 = time.perf_counter()
        compiled.simulate_batch(maneuver, s_values, np.tile(zero, (cases, 1)))
        batch = min(batch, (time.perf_counter() - t0) / cases)
    if kind == "walker":
        from bench import system_reference
        from bench.walker_model import Walker

        model = Walker(n, "coupled")

        def reference(s: float) -> float:
            return system_reference.simulate(model, "touchdown", s, [0.0] * (n + 1)).outcome
    elif kind == "quadruped":
        from tests.simulation.user import reference_quadruped

        robot = reference_quadruped.Quadruped()

        def reference(s: float) -> float:
            return reference_quadruped.simulate(robot, s).outcome
    else:
        from tests.simulation.user import reference_chain

        chain = reference_chain.Chain(n)

        def reference(s: float) -> float:
            return reference_chain.simulate(chain, s).outcome
    picks = list(s_values[:: max(1, cases // reference_cases)])[:reference_cases]
    ref_t, ref_v = _best_times(reference, picks, 1)
    own = np.array([compiled.simulate(maneuver, s, zero).outcome for s in picks])
    ref_start = _process_seconds([sys.executable, "-c", _REFERENCE_START, str(ROOT), kind,
                                  str(n)], dict(os.environ))
    per, ref = float(loop), float(np.median(ref_t))
    return {"system": spec, "d": d,
            "modes": 2 ** len(compiled.constraints), "cold_s": cold, "cached_s": cached,
            "per_trajectory_s": per, "batch_per_trajectory_s": float(batch),
            "reference_per_trajectory_s": ref, "reference_start_s": ref_start,
            "ratio_per_trajectory": per / ref, "ratio_batch": float(batch) / ref,
            "ratio_cold": cold / ref_start, "ratio_cached": cached / ref_start,
            "max_abs_error": float(np.max(np.abs(own - ref_v)))}


def _time(v: float) -> str:
    return f"{v * 1e6:.1f} us" if v < 1e-3 else f"{v * 1e3:.2f} ms" if v < 1 else f"{v:.1f} s"


def table(rows: list[dict[str, Any]]) -> str:
    head = (f"{'system':<20}{'d':>3}{'modes':>6}{'cold':>9}{'cached':>11}{'per traj.':>11}"
            f"{'batch':>11}{'SciPy':>11}{'SciPy start':>12}  ratios cold/cached/traj/batch"
            f"{'max |err|':>11}")
    lines = [head]
    for r in rows:
        lines.append(
            f"{r['system']:<20}{r['d']:>3}{r['modes']:>6}{_time(r['cold_s']):>9}"
            f"{_time(r['cached_s']):>11}{_time(r['per_trajectory_s']):>11}"
            f"{_time(r['batch_per_trajectory_s']):>11}{_time(r['reference_per_trajectory_s']):>11}"
            f"{_time(r['reference_start_s']):>12}  {r['ratio_cold']:.2f} / {r['ratio_cached']:.2f}"
            f" / {r['ratio_per_trajectory']:.3f} / {r['ratio_batch']:.3f}"
            f"{r['max_abs_error']:>11.1e}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--legs", type=int, nargs="*", default=[2, 3, 4, 6, 8, 10])
    ap.add_argument("--chains", type=int, nargs="*", default=[5], choices=CHAINS,
                    metavar="D", help=f"chains by d ({', '.join(map(str, CHAINS))})")
    ap.add_argument("--no-chain", action="store_true")
    ap.add_argument("--quadruped", action="store_true",
                    help="also the quadruped (d = 20; a cold compile of about a minute)")
    ap.add_argument("--cases", type=int, default=20)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--reference-cases", type=int, default=4)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    plan = [(f"walker{n}", "walker", n) for n in args.legs]
    if not args.no_chain:  # (n: links per leg)
        plan += [(f"chain{d}", "chain", (d - 3) // 2) for d in args.chains]
    if args.quadruped:
        plan.append(("quadruped", "quadruped", 4))
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "biped_opt.codegen.kernel"], check=True, cwd=ROOT,
                   capture_output=True)
    shared = time.perf_counter() - t0
    if not args.json:
        print(f"the shared kernel, compiled once per installation (here loaded or compiled in a "
              f"new interpreter): {shared:.1f} s", flush=True)
    rows = []
    for spec, kind, n in plan:
        rows.append(measure(spec, kind, n, cases=args.cases, rounds=args.rounds,
                            reference_cases=args.reference_cases))
        if not args.json:
            print(table(rows[-1:]).splitlines()[-1], flush=True)
    print(json.dumps(rows, indent=2) if args.json else table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
