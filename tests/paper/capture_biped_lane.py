"""Record what the biped-only lane computes for docs/MODEL.md's maneuvers and problems.

Run once, by hand, from the repository root (about half a minute on two idle cores):

    python -m tests.paper.capture_biped_lane

It writes ``tests/paper/biped_lane.json``: the numbers the biped-only lane (``biped_opt.hybrid``,
``biped_opt.maneuvers``, ``biped_opt.optimal``) gives before that lane is retired, which
``tests/paper/test_same_numbers.py`` compares with the any-system lane. It uses the biped-only
lane alone, so it can run only while that lane exists: the file is the record afterwards.
(``biped_opt.optimal``'s solver, sweeps and derivatives became the presets of
``biped_opt.paper``, which run the one lane under the same names: run again, this would record
the one lane's own numbers. Do not.)

- ``trajectories``: both maneuvers at th0 on the ends of their ranges, at 0, within 1e-9 of 0
  and a few ordinary angles, with the paper's fixed inputs, zero, one more input vector each and
  two that make liftoff fail:
  status, outcome, final time and state, contact-event times and mode sequence;
- ``outcome_derivatives``: one-sided slopes and full branch gradients of the outcome at fixed
  inputs (the kink and the jump at 0, and an ordinary angle);
- ``optimal``: the three problems' optimal value, policy, outcome, branch, acting decision and
  bound at fixed angles and on both sides of every point of their nonsmooth tables;
- ``derivatives``: Theorem 1's one-sided derivatives at a few th0, kinks and jumps included;
- ``nonsmooth``: the tables (default grids) of the three problems and of the fixed-input sweeps.
"""

from __future__ import annotations

import json
import math
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from biped_opt.fixed_sweep import FIXED_INPUTS
from biped_opt.hybrid import simulate
from biped_opt.maneuvers import spec
from biped_opt.paper.derivatives import one_sided_derivatives, outcome_sensitivity
from biped_opt.paper.nonsmooth import find_nonsmooth_fixed, find_nonsmooth_optimal
from biped_opt.paper.problems import PROBLEMS, get_problem
from biped_opt.paper.solve import optimal_policy

OUT = Path(__file__).with_name("biped_lane.json")

#: angles of the trajectories, by maneuver: the range's ends, 0, within 1e-9 of 0, ordinary ones
TRAJECTORY_THETA0 = {
    "touchdown": [-0.25, -0.2, -0.1, -1e-9, -1e-10, 0.0, 1e-10, 1e-9, 1e-6, 0.05, 0.1, 0.25],
    "liftoff": [-0.3, -0.2, -0.05, -1e-9, -1e-10, 0.0, 1e-10, 1e-9, 1e-6, 0.03, 0.15, 0.3],
}
#: input vectors (u1, u2, u12) by maneuver: the paper's fixed inputs, zero, one more, and for
#: liftoff two that fail (apex reached in contact; an inconsistent contact)
TRAJECTORY_INPUTS = {
    "touchdown": [FIXED_INPUTS["touchdown"], (0.0, 0.0, 0.0), (-0.5, 1.5, 0.3)],
    "liftoff": [FIXED_INPUTS["liftoff"], (0.0, 0.0, 0.0), (1.5, 3.0, 0.2), (0.0, 0.0, -3.0),
                (-3.0, -3.0, 0.0)],
}
#: fixed-input outcome slopes: (maneuver, th0, inputs)
OUTCOME_DERIVATIVES = [
    ("touchdown", 0.0, FIXED_INPUTS["touchdown"]),
    ("touchdown", 0.0, (0.0, 0.0, 0.0)),
    ("touchdown", 0.1, FIXED_INPUTS["touchdown"]),
    ("liftoff", 0.0, FIXED_INPUTS["liftoff"]),
    ("liftoff", -0.05, FIXED_INPUTS["liftoff"]),
]
#: optimal solves at these angles, besides both sides of every nonsmooth point
OPTIMAL_THETA0 = {
    "touchdown": [-0.25, -0.1, -0.02, 0.0, 0.05, 0.2],
    "liftoff": [-0.3, -0.1, 0.0, 1e-4, 0.05, 0.3],
    "liftoff-variant": [-0.3, -0.1, 0.0, 0.05, 0.3],
}
#: offsets from a nonsmooth point at which the optimum is recorded
NEAR = (-1e-6, 1e-6)
#: Theorem 1 at these angles (plus each problem's policy jump, where it has one)
DERIVATIVE_THETA0 = {
    "touchdown": [-0.1, 0.0, 0.05],
    "liftoff": [0.0, 0.03],
    "liftoff-variant": [0.0, 0.1],
}


def _num(x: float) -> float | None:
    """A float for JSON (NaN, which a failing side of a table holds, as null)."""
    x = float(x)
    return x if math.isfinite(x) else None


def _floats(values: Any) -> list[float | None]:
    return [_num(v) for v in np.ravel(values)]


def trajectories() -> list[dict[str, Any]]:
    out = []
    for maneuver, angles in TRAJECTORY_THETA0.items():
        for u in TRAJECTORY_INPUTS[maneuver]:
            for th in angles:
                tr = simulate(maneuver, th, u)
                out.append({
                    "maneuver": maneuver, "theta0": th, "inputs": list(u),
                    "status": tr.status.name, "outcome": tr.outcome, "t_final": tr.t_final,
                    "state_final": _floats(tr.state_final),
                    "event_times": _floats(tr.event_times),
                    "modes": [m.name for m in tr.mode_sequence],
                })
    return out


def outcome_derivatives() -> list[dict[str, Any]]:
    out = []
    for maneuver, th, u in OUTCOME_DERIVATIVES:
        sides = {}
        for side in (-1, 1):
            s = outcome_sensitivity(maneuver, th, u, direction=(float(side), 0.0, 0.0, 0.0))
            sides[side] = {"outcome": s.outcome, "gradient": _floats(s.gradient),
                           "modes": [m.name for m in s.mode_sequence],
                           "continued": s.continued}
        out.append({"maneuver": maneuver, "theta0": th, "inputs": list(u),
                    "left": sides[-1], "right": sides[1]})
    return out


def _optimum(name: str, th: float) -> dict[str, Any]:
    r = optimal_policy(get_problem(name), th)
    return {"problem": name, "theta0": th, "value": r.value, "policy": dict(r.policy),
            "outcome": r.outcome, "branch": r.branch, "active": r.active, "bound": r.bound,
            "success": r.success, "event_times": _floats(r.event_times)}


def _point(p: Any) -> dict[str, Any]:
    return {"theta0": p.theta0, "quantity": p.quantity, "input": p.input, "kind": p.kind,
            "left": _num(p.left), "right": _num(p.right), "cause": p.cause,
            "limits": _floats(p.limits), "derivatives": _floats(p.derivatives),
            "second_derivatives": _floats(p.second_derivatives), "at": _num(p.at),
            "bracket": list(p.bracket), "labels": list(p.labels)}


def _table(report: Any, seconds: float) -> dict[str, Any]:
    return {"subject": report.subject, "grid_size": report.grid_size,
            "theta0_range": list(report.theta0_range), "seconds": round(seconds, 1),
            "points": [_point(p) for p in report.points]}


def nonsmooth() -> dict[str, Any]:
    tables: dict[str, Any] = {"fixed": [], "optimal": {}}
    for maneuver in ("touchdown", "liftoff"):
        for u in (FIXED_INPUTS[maneuver], (0.0, 0.0, 0.0)):
            t0 = time.perf_counter()
            report = find_nonsmooth_fixed(maneuver, None, u)
            tables["fixed"].append({"maneuver": maneuver, "inputs": list(u),
                                    **_table(report, time.perf_counter() - t0)})
    for name in PROBLEMS:
        t0 = time.perf_counter()
        report = find_nonsmooth_optimal(get_problem(name))
        tables["optimal"][name] = _table(report, time.perf_counter() - t0)
    return tables


def optimal(tables: dict[str, Any]) -> list[dict[str, Any]]:
    out = []
    for name, angles in OPTIMAL_THETA0.items():
        limit = spec(get_problem(name).maneuver).theta0_limit
        points = sorted({p["theta0"] for p in tables[name]["points"]})
        near = [x + d for x in points for d in NEAR if abs(x + d) <= limit]
        for th in sorted(set(angles) | set(near)):
            out.append(_optimum(name, th))
    return out


def derivatives(tables: dict[str, Any]) -> list[dict[str, Any]]:
    out = []
    for name, angles in DERIVATIVE_THETA0.items():
        jumps = sorted({p["theta0"] for p in tables[name]["points"]
                        if p["quantity"] == "policy" and p["kind"] == "jump"})
        for th in sorted(set(angles) | set(jumps)):
            d = one_sided_derivatives(get_problem(name), th)
            out.append({
                "problem": name, "theta0": th, "outcome": list(d.outcome),
                "value": list(d.value), "policy": {k: list(v) for k, v in d.policy.items()},
                "outcome_limits": list(d.outcome_limits), "value_limits": list(d.value_limits),
                "policy_limits": {k: list(v) for k, v in d.policy_limits.items()},
                "branches": list(d.branches), "at_bound": [list(b) for b in d.at_bound],
            })
    return out


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                              check=True, cwd=Path(__file__).parent).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main() -> None:
    t0 = time.perf_counter()
    tables = nonsmooth()
    record = {
        "about": "numbers of the biped-only lane, written by tests/paper/capture_biped_lane.py",
        "commit": _commit(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "trajectories": trajectories(),
        "outcome_derivatives": outcome_derivatives(),
        "optimal": optimal(tables["optimal"]),
        "derivatives": derivatives(tables["optimal"]),
        "nonsmooth": tables,
    }
    OUT.write_text(json.dumps(record, indent=1) + "\n")
    print(f"wrote {OUT} ({OUT.stat().st_size / 1e3:.0f} kB) in "
          f"{time.perf_counter() - t0:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
