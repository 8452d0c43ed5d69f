"""The generated simulators side by side: per-trajectory time and error against independent
SciPy comparators, for the biped, the 3-leg walker and the rocking bar, from one run.

:func:`run_systems_benchmark` returns a JSON-ready dict with, per system,

- ``per_trajectory_s``: median over cases of the best of ``rounds`` timings of one
  ``CompiledSystem.simulate`` call (the generated kernel with its Python wrapper);
- ``batch_per_trajectory_s``: ``simulate_batch`` over all cases, per case;
- ``reference_per_trajectory_s`` and ``speedup_vs_reference``: the SciPy comparator
  (``bench/system_reference.py`` with ``walker_model``/``rocking_bar_model``, written from
  SYSTEMS.md without biped_opt; the biped's is ``bench/solve_ivp_reference.py``);
- ``max_abs_error``: largest |outcome - comparator outcome| and ``mode_mismatches``;
- ``compile_s``: a fresh interpreter compiling the system with an empty cache (cold) and
  loading it from that cache (cached).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from bench import rocking_bar_model, solve_ivp_reference, system_reference
from bench.walker_model import Walker

__all__ = ["SYSTEMS", "run_systems_benchmark", "format_systems_table"]

#: benchmarked systems: library name -> (maneuvers with their input ranges, comparator)
SYSTEMS = ("biped", "walker3", "rocking_bar")

_COMPILE_SCRIPT = """
import sys, time
t0 = time.perf_counter()
from biped_opt.simulation.compiled import compile_system
system = compile_system(sys.argv[1])
name = system.maneuvers[0]
tr = system.simulate(name, 0.01)
print(time.perf_counter() - t0)
"""


def _cases(name: str, n: int, rng: np.random.Generator):
    out = []
    for k in range(n):
        if name == "rocking_bar":
            out.append(("drop", float(rng.uniform(-0.25, 0.25)), (0.0,)))
            continue
        legs = 2 if name == "biped" else 3
        if k % 2 == 0:
            u = tuple(rng.uniform(-0.5, 1.5, legs)) + (0.0,)
            out.append(("touchdown", float(rng.uniform(-0.25, 0.25)), u))
        else:
            u = tuple(rng.uniform(1.5, 3.0, legs)) + (float(rng.uniform(-0.5, 0.5)),)
            out.append(("liftoff", float(rng.uniform(-0.3, 0.3)), u))
    return out


def _reference(name: str):
    if name == "biped":
        def call(case):
            r = solve_ivp_reference.simulate(case[0], case[1], case[2])
            return r.outcome
        return call
    model = rocking_bar_model if name == "rocking_bar" else Walker(3, "coupled")

    def call(case):
        return system_reference.simulate(model, case[0], case[1], case[2]).outcome
    return call


def _best_times(call, cases, rounds: int):
    best = np.full(len(cases), np.inf)
    values = np.zeros(len(cases))
    for _ in range(rounds):
        for k, case in enumerate(cases):
            t0 = time.perf_counter()
            values[k] = call(case)
            best[k] = min(best[k], time.perf_counter() - t0)
    return best, values


def _compile_cost(name: str) -> dict[str, float]:
    out = {}
    with tempfile.TemporaryDirectory(prefix="biped_opt_systems_") as cache:
        env = dict(os.environ, BIPED_OPT_CACHE=cache)
        for label in ("cold", "cached"):
            proc = subprocess.run([sys.executable, "-c", _COMPILE_SCRIPT, name], env=env,
                                  capture_output=True, text=True, timeout=900, check=False)
            if proc.returncode != 0:
                tail = proc.stderr.strip().splitlines()[-1:] or ["(no output)"]
                raise RuntimeError(f"compile of {name} failed: {tail[0]}")
            out[label] = float(proc.stdout.split()[-1])
    return out


def run_systems_benchmark(systems=SYSTEMS, *, n_cases: int = 40, rounds: int = 3,
                          reference_cases: int = 10, seed: int = 20200401,
                          compile_cost: bool = True) -> dict:
    from biped_opt.simulation.compiled import compile_system

    rng = np.random.default_rng(seed)
    result: dict = {"n_cases": n_cases, "rounds": rounds, "reference_cases": reference_cases,
                    "systems": {}}
    for name in systems:
        compiled = compile_system(name)
        # cases whose maneuver ends as specified (a liftoff can reach its apex with a foot
        # still down: both simulators refuse those, so they time nothing comparable)
        cases = [c for c in _cases(name, 3 * n_cases, rng)
                 if compiled.simulate(c[0], c[1], c[2]).success][:n_cases]
        for case in cases[:2]:
            compiled.simulate(case[0], case[1], case[2])  # warm up every maneuver

        def generated(case, compiled=compiled):
            return compiled.simulate(case[0], case[1], case[2]).outcome

        gen_t, gen_v = _best_times(generated, cases, rounds)
        ref_cases = cases[:reference_cases]
        ref_t, ref_v = _best_times(_reference(name), ref_cases, 1)
        batch_s = np.inf
        by_maneuver: dict[str, list[int]] = {}
        for k, case in enumerate(cases):
            by_maneuver.setdefault(case[0], []).append(k)
        for _ in range(rounds):
            t0 = time.perf_counter()
            for maneuver, ks in by_maneuver.items():
                compiled.simulate_batch(maneuver, [cases[k][1] for k in ks],
                                        [cases[k][2] for k in ks])
            batch_s = min(batch_s, (time.perf_counter() - t0) / len(cases))
        row = {
            "per_trajectory_s": float(np.median(gen_t)),
            "batch_per_trajectory_s": float(batch_s),
            "reference_per_trajectory_s": float(np.median(ref_t)),
            "speedup_vs_reference": float(np.median(ref_t) / np.median(gen_t)),
            "max_abs_error": float(np.max(np.abs(gen_v[: len(ref_cases)] - ref_v))),
        }
        if compile_cost:
            row["compile_s"] = _compile_cost(name)
        result["systems"][name] = row
    return result


def _us(value: float) -> str:
    return f"{value * 1e6:.1f} us" if value < 1e-3 else f"{value * 1e3:.2f} ms"


def format_systems_table(r: dict) -> str:
    lines = [f"{r['n_cases']} cases per system (best of {r['rounds']}); comparators on "
             f"{r['reference_cases']}",
             f"{'system':<13}{'per traj.':>11}{'batch':>11}{'SciPy ref.':>12}{'speed-up':>10}"
             f"{'max |err|':>11}{'cold':>8}{'cached':>8}"]
    for name, row in r["systems"].items():
        comp = row.get("compile_s", {})
        lines.append(
            f"{name:<13}{_us(row['per_trajectory_s']):>11}{_us(row['batch_per_trajectory_s']):>11}"
            f"{_us(row['reference_per_trajectory_s']):>12}{row['speedup_vs_reference']:>9.0f}x"
            f"{row['max_abs_error']:>11.1e}"
            f"{comp.get('cold', float('nan')):>7.1f}s{comp.get('cached', float('nan')):>7.1f}s")
    return "\n".join(lines)


if __name__ == "__main__":
    import json

    print(json.dumps(run_systems_benchmark(), indent=2))
