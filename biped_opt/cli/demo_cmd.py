"""``biped-opt demo``: the paper's fixed-input sweeps and the nonsmooth points they reveal."""

from __future__ import annotations

import argparse
import time

from biped_opt.fixed_sweep import FIXED_INPUTS, fixed_sweep, outcome_breaks, theta_grid
from biped_opt.maneuvers import spec


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the paper's fixed-input sweeps and locate kink and jump")
    p.add_argument("--num", type=int, default=401, help="grid points per sweep (default 401)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.num < 3:
        from biped_opt.errors import InvalidInputError

        raise InvalidInputError(f"--num must be at least 3, got {args.num}")
    print("Fixed-input sweeps of the outcome th(t_f) over th0 (MODEL.md Secs. 5-6)")
    for maneuver in ("touchdown", "liftoff"):
        limit = spec(maneuver).theta0_limit
        grid = theta_grid(-limit, limit, args.num)
        start = time.perf_counter()
        sweep = fixed_sweep(maneuver, grid)
        elapsed = time.perf_counter() - start
        u = FIXED_INPUTS[maneuver]
        print(
            f"\n{maneuver}: {grid.size} angles in [{-limit}, {limit}], inputs "
            f"(u1, u2, u12) = {u}, {int(sweep.success.sum())} ok, {elapsed * 1e3:.1f} ms"
        )
        for b in outcome_breaks(maneuver, sweep):
            print(f"  {b.kind} at th0 = {b.theta0:+.3e}")
            print(f"    sequences   {' -> '.join(b.sequence_left)}  |  "
                  f"{' -> '.join(b.sequence_right)}")
            print(f"    limits      left {b.left_limit:+.9f}   right {b.right_limit:+.9f}")
            print(f"    slopes      left {b.left_slope:+.9f}   right {b.right_slope:+.9f}")
    return 0
