"""The issue-3 benchmark: biped_opt against solve_ivp and a relaxation simulator, same cases.

:func:`run_benchmark` builds one list of (maneuver, theta0, inputs) cases, runs every method on
it and returns a JSON-ready dict:

- ``per_trajectory_s``: median wall time of one trajectory per method (each case timed
  ``rounds`` times, the fastest kept to shed scheduler noise, then the median over cases);
  biped_opt is timed through its public :func:`biped_opt.simulate`, one call per trajectory,
  after a warm-up call per maneuver;
- ``biped_opt_after_other_method_s``: biped_opt timed right after each call of another method,
  when the CPU caches hold that method's code and data (an isolated call's cost);
- ``batch_per_trajectory_s``: :func:`biped_opt.simulate_batch` on the same cases, per case;
- ``speedup_vs_solve_ivp``: ratio of the ``per_trajectory_s`` medians;
- ``max_abs_error``: each method's largest |outcome - outcome of the most accurate method|; the
  most accurate is biped_opt at its default tolerance (checked against itself at rtol 1e-14 in
  ``reference_self_check``), and biped_opt's own entry is its error against solve_ivp;
- ``sweep_s``: a 401-point fixed-input sweep per maneuver through the batch path
  (:func:`biped_opt.paper.sweeps.sweep_fixed`, one batch), median of a few repeats after warm-up;
- ``compile_s``: a fresh interpreter importing biped_opt and simulating once, with
  ``NUMBA_CACHE_DIR`` an empty directory (cold compile) and then the same directory (cached).
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable

import numpy as np

from bench import relaxation, solve_ivp_reference

__all__ = ["make_cases", "run_benchmark", "SWEEP_POINTS"]

SWEEP_POINTS = 401
DEFAULT_SEED = 20200401
#: input ranges of the cases (MODEL.md Sec. 5)
TOUCHDOWN_U = (-0.5, 1.5)
LIFTOFF_U12 = (-0.5, 0.5)
LIFTOFF_U = (1.5, 3.0)
THETA_LIMIT = {"touchdown": 0.25, "liftoff": 0.3}

Case = tuple[str, float, tuple[float, float, float]]

_COMPILE_SCRIPT = """
import time
t0 = time.perf_counter()
import biped_opt
t1 = time.perf_counter()
tr = biped_opt.simulate("touchdown", 0.1, (2.0, 0.5, 0.0))
t2 = time.perf_counter()
assert tr.success, tr.message
print(t1 - t0, t2 - t1)
"""


def make_cases(n_cases: int = 200, seed: int = DEFAULT_SEED) -> list[Case]:
    """Half touchdown (u1, u2 in [-0.5, 1.5], |th0| <= 0.25), half liftoff (u = (1.5, 3, u12),
    u12 in [-0.5, 0.5], |th0| <= 0.3); the first case of each maneuver has th0 = 0 exactly."""
    if n_cases < 2:
        raise ValueError(f"n_cases must be at least 2, got {n_cases}")
    rng = np.random.default_rng(seed)
    n_td = n_cases // 2
    cases: list[Case] = []
    for k in range(n_td):
        th = 0.0 if k == 0 else float(rng.uniform(-1.0, 1.0) * THETA_LIMIT["touchdown"])
        u1, u2 = (float(v) for v in rng.uniform(*TOUCHDOWN_U, size=2))
        cases.append(("touchdown", th, (u1, u2, 0.0)))
    for k in range(n_cases - n_td):
        th = 0.0 if k == 0 else float(rng.uniform(-1.0, 1.0) * THETA_LIMIT["liftoff"])
        cases.append(("liftoff", th, (*LIFTOFF_U, float(rng.uniform(*LIFTOFF_U12)))))
    return cases


class _Timing:
    """Best-of-rounds wall time per case of one method, and what its results say."""

    def __init__(self, n: int) -> None:
        self.best = np.full(n, np.inf)
        self.outcome = np.full(n, np.nan)
        self.nfev = np.full(n, np.nan)
        self.seqs: list = [None] * n


def _time_blocks(
    methods: dict[str, tuple[Callable[[Case], object], Callable, int]],
    cases: list[Case],
    rounds: int,
    chaser: str,
) -> dict[str, _Timing]:
    """Time every method on every case in blocks (one method over all cases, as a sweep or an
    optimiser calls it), alternating the blocks round by round so that drifting machine load
    hits all methods alike.

    ``methods[name] = (call, extract, stride)``: the method runs on every ``stride``-th case, and
    in the first round only if ``stride`` is negative (slow methods); ``extract`` turns a result
    into (outcome, mode names, nfev) outside the timed region. Besides, method ``chaser`` is
    timed once more right after each call of every other method (key ``chaser + "_chased"``): its
    time when the CPU caches hold the other method's code and data instead of its own.
    """
    out = {name: _Timing(len(cases)) for name in methods}
    chased = out[chaser + "_chased"] = _Timing(len(cases))
    chase_call = methods[chaser][0]
    for r in range(rounds):
        for name, (call, extract, stride) in methods.items():
            if stride < 0 and r > 0:
                continue
            res = out[name]
            for k, case in enumerate(cases):
                if k % abs(stride):
                    continue
                t0 = time.perf_counter()
                result = call(case)
                dt = time.perf_counter() - t0
                res.best[k] = min(res.best[k], dt)
                res.outcome[k], res.seqs[k], res.nfev[k] = extract(result)
                if name != chaser:
                    t0 = time.perf_counter()
                    chase_call(case)
                    chased.best[k] = min(chased.best[k], time.perf_counter() - t0)
    return out


def _compile_cost() -> dict[str, float]:
    """Import + first simulate in fresh interpreters: empty numba cache, then the filled one."""
    out = {}
    with tempfile.TemporaryDirectory(prefix="biped_opt_numba_cache_") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        for label in ("cold", "cached"):
            t0 = time.perf_counter()
            proc = subprocess.run(
                [sys.executable, "-c", _COMPILE_SCRIPT], env=env, cwd=cache,
                capture_output=True, text=True, timeout=900, check=False,
            )
            wall = time.perf_counter() - t0
            if proc.returncode != 0:
                tail = proc.stderr.strip().splitlines()[-1:] or ["(no output)"]
                raise RuntimeError(f"compile-cost subprocess failed: {tail[0]}")
            import_s, first_s = (float(v) for v in proc.stdout.split())
            out[label] = import_s + first_s
            out[f"{label}_first_call"] = first_s
            out[f"{label}_process_wall"] = wall
        out["import"] = import_s
    return out


def _machine() -> dict:
    import numba
    import scipy

    from biped_opt.simulation.compiled import batch_threads

    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        usable = os.cpu_count() or 1
    return {
        "cpu_count": os.cpu_count(),
        "usable_cpus": usable,
        "batch_threads": batch_threads(1 << 20),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
    }


def run_benchmark(
    n_cases: int = 200,
    seed: int = DEFAULT_SEED,
    quick: bool = False,
    *,
    compile_cost: bool = True,
) -> dict:
    """Time and compare the three simulators on the same cases; returns a JSON-ready dict.

    ``quick`` uses one timing round, 41-point sweeps and relaxation on a subset (for tests and a
    first look; not for the acceptance figures). ``compile_cost=False`` skips the two fresh
    interpreters and reports their entries as None.
    """
    import biped_opt
    from biped_opt.paper.biped import ContactMode
    from biped_opt.paper.sweeps import sweep_fixed
    from biped_opt.piecewise import theta_grid

    cases = make_cases(n_cases, seed)
    rounds = 1 if quick else 5
    relax_every = 4 if quick else 1  # relaxation is pure Python: a subset in quick mode
    sweep_points = 41 if quick else SWEEP_POINTS
    sweep_repeats = 1 if quick else 5

    def call_biped_opt(case: Case, options=None):
        m, th, u = case
        if options is None:
            return biped_opt.simulate(m, th, u)
        return biped_opt.simulate(m, th, u, options=options)

    def from_biped_opt(tr) -> tuple[float, tuple[str, ...], int]:
        if not tr.success:
            raise RuntimeError(f"biped_opt failed at th0 = {tr.theta0}: {tr.message}")
        return tr.outcome, tuple(ContactMode(mode).name for mode in tr.mode_sequence), tr.nfev

    def from_comparator(r) -> tuple[float, tuple[str, ...], int]:
        return r.outcome, r.mode_sequence, r.nfev

    def call_solve_ivp(case: Case):
        return solve_ivp_reference.simulate(*case)

    def call_relaxation(case: Case):
        return relaxation.simulate(*case)

    for m in THETA_LIMIT:  # warm-up: compile or load the cache, fault in code paths
        from_biped_opt(call_biped_opt((m, 0.01, (0.5, 0.5, 0.1))))
        call_solve_ivp((m, 0.01, (0.5, 0.5, 0.1)))
    timed = _time_blocks(
        {
            "biped_opt": (call_biped_opt, from_biped_opt, 1),
            "solve_ivp": (call_solve_ivp, from_comparator, 1),
            "relaxation": (call_relaxation, from_comparator, -relax_every),
        },
        cases,
        rounds,
        chaser="biped_opt",
    )
    bo, iv, rx = timed["biped_opt"], timed["solve_ivp"], timed["relaxation"]
    relax_idx = np.arange(0, len(cases), relax_every)
    t_bo, out_bo, seq_bo, nfev_bo = bo.best, bo.outcome, bo.seqs, bo.nfev
    t_iv, out_iv, seq_iv, nfev_iv = iv.best, iv.outcome, iv.seqs, iv.nfev
    t_rx, out_rx, nfev_rx = rx.best[relax_idx], rx.outcome[relax_idx], rx.nfev[relax_idx]
    seq_rx = [rx.seqs[k] for k in relax_idx]

    tight = biped_opt.SimulatorOptions(rtol=1e-14, atol=1e-14)
    out_tight = np.array([from_biped_opt(call_biped_opt(c, tight))[0] for c in cases])

    # the parallel batch path (all cores) on the same cases: wall time per trajectory
    batch_times = []
    for m in THETA_LIMIT:
        idx = [k for k, c in enumerate(cases) if c[0] == m]
        th = np.array([cases[k][1] for k in idx])
        u = np.array([cases[k][2] for k in idx])
        biped_opt.simulate_batch(m, th, u)
        best = float("inf")
        for _ in range(5):  # fastest of a few repeats, as for the per-call timings
            t0 = time.perf_counter()
            batch = biped_opt.simulate_batch(m, th, u)
            best = min(best, time.perf_counter() - t0)
        batch_times.append(best)
        if np.max(np.abs(batch.outcome - out_bo[idx])) > 1e-12:
            raise RuntimeError(f"simulate_batch and simulate disagree on the {m} cases")

    sweep = {}
    for m in THETA_LIMIT:
        grid = theta_grid(-THETA_LIMIT[m], THETA_LIMIT[m], sweep_points)
        sweep_fixed(m, grid, chunks=1)
        times = []
        for _ in range(sweep_repeats):
            t0 = time.perf_counter()
            result = sweep_fixed(m, grid, chunks=1)
            times.append(time.perf_counter() - t0)
        if not np.all(result.success):
            raise RuntimeError(f"the {m} sweep has failed trajectories")
        sweep[m] = float(np.median(times))

    med = {
        "biped_opt": float(np.median(t_bo)),
        "solve_ivp": float(np.median(t_iv)),
        "relaxation": float(np.median(t_rx)),
    }
    err_bo_iv = float(np.max(np.abs(out_bo - out_iv)))
    err_rx = np.abs(out_rx - out_bo[relax_idx])
    result = {
        "n_cases": len(cases),
        "seed": seed,
        "quick": quick,
        "timing": f"per case best of {rounds} round(s) (relaxation: 1), one method at a time "
        "over all cases, median over cases",
        "relaxation_cases": int(relax_idx.size),
        "per_trajectory_s": med,
        "biped_opt_after_other_method_s": float(np.median(timed["biped_opt_chased"].best)),
        "batch_per_trajectory_s": float(sum(batch_times) / len(cases)),
        "speedup_vs_solve_ivp": {
            "biped_opt": med["solve_ivp"] / med["biped_opt"],
            "relaxation": med["solve_ivp"] / med["relaxation"],
        },
        "error_reference": "biped_opt (default tolerance); its own entry is vs solve_ivp",
        "max_abs_error": {
            "biped_opt": err_bo_iv,
            "solve_ivp": err_bo_iv,
            "relaxation": float(np.max(err_rx)),
        },
        "median_abs_error": {
            "solve_ivp": float(np.median(np.abs(out_bo - out_iv))),
            "relaxation": float(np.median(err_rx)),
        },
        "reference_self_check": float(np.max(np.abs(out_bo - out_tight))),
        "mode_sequence_mismatches": {
            "solve_ivp": sum(a != b for a, b in zip(seq_bo, seq_iv)),
            "relaxation": sum(seq_bo[k] != s for k, s in zip(relax_idx, seq_rx)),
        },
        "median_nfev": {
            "biped_opt": float(np.median(nfev_bo)),
            "solve_ivp": float(np.median(nfev_iv)),
            "relaxation": float(np.median(nfev_rx)),
        },
        "sweep_points": int(theta_grid(-0.25, 0.25, sweep_points).size),
        "sweep_s": sweep,
        "compile_s": _compile_cost() if compile_cost else {"cold": None, "cached": None},
        "machine": _machine(),
    }
    return result


if __name__ == "__main__":
    print(json.dumps(run_benchmark(quick="--quick" in sys.argv), indent=2))
