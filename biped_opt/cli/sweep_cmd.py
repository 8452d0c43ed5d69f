"""``biped-opt sweep``: outcomes at fixed inputs, or optimal policies and values, over th0."""

from __future__ import annotations

import argparse
import sys

from biped_opt import strict_json
from biped_opt.cli.args import MAX_POINTS, finite_float, int_in_range, output_file, path_arg
from biped_opt.cli.optimise_cmd import add_problem_arguments, problem_from_args
from biped_opt.cli.simulate_cmd import parse_maneuver_arg
from biped_opt.cli.system_cmds import add_system_arguments, run_sweep, uses_system
from biped_opt.errors import InvalidInputError
from biped_opt.fixed_sweep import FIXED_INPUTS
from biped_opt.maneuvers import check_theta0
from biped_opt.optimal.sweep import sweep_fixed, sweep_grid, sweep_optimal


def add_range_arguments(p: argparse.ArgumentParser, num_help: str) -> None:
    p.add_argument("--theta0-min", type=finite_float("--theta0-min"), default=None,
                   help="smallest th0 [rad] (default: -limit of the maneuver)")
    p.add_argument("--theta0-max", type=finite_float("--theta0-max"), default=None,
                   help="largest th0 [rad] (default: +limit of the maneuver)")
    p.add_argument("--num", type=int_in_range("--num", 2, MAX_POINTS), default=None,
                   help=num_help)
    p.add_argument("--progress", dest="progress", action="store_true", default=None,
                   help="draw a progress bar on stderr (default: when stderr is a terminal)")
    p.add_argument("--no-progress", dest="progress", action="store_false")


def grid_from_args(args: argparse.Namespace, maneuver: str, default_num: int):
    for option, value in (("--theta0-min", args.theta0_min), ("--theta0-max", args.theta0_max)):
        if value is not None:
            try:
                check_theta0(maneuver, value)
            except InvalidInputError as exc:
                raise InvalidInputError(f"{option}: {exc}") from None
    if (args.theta0_min is not None and args.theta0_max is not None
            and not args.theta0_min < args.theta0_max):
        raise InvalidInputError(
            f"--theta0-min must be below --theta0-max, got {args.theta0_min} >= {args.theta0_max}"
        )
    return sweep_grid(maneuver, args.theta0_min, args.theta0_max,
                      args.num if args.num is not None else default_num)


def progress_from_args(args: argparse.Namespace) -> bool:
    return sys.stderr.isatty() if args.progress is None else bool(args.progress)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sweep", help="sweep th0: fixed-input outcomes or optimal solutions")
    add_problem_arguments(p)
    add_range_arguments(p, "grid points (default 401 fixed, 201 optimal; 0 always included)")
    p.add_argument("--optimal", action="store_true",
                   help="optimal policy and value instead of fixed inputs")
    for name in ("u1", "u2", "u12"):
        p.add_argument(f"--{name}", type=finite_float(f"--{name}"), default=None,
                       help=f"fixed-input sweep: {name} (default: the paper's figure input)")
    add_system_arguments(p, sweep=True)
    p.add_argument("--out", type=path_arg(output_file, "--out", overwrite=True), default=None,
                   metavar="F.json",
                   help="write the sweep as JSON to this file (default: a table on stdout)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if uses_system(args):
        return run_sweep(args)
    maneuver = parse_maneuver_arg(args.maneuver).value
    optimal = args.optimal or args.variant
    if optimal:
        problem = problem_from_args(args)
        grid = grid_from_args(args, maneuver, 201)
        result = sweep_optimal(problem, grid, progress=progress_from_args(args))
        rows = [
            (th, result.outcome[k], result.value[k],
             "  ".join(f"{d}={result.policy[d][k]:+.10g}" for d in problem.decisions),
             result.branch[k])
            for k, th in enumerate(result.theta0)
        ]
        header = f"{'theta0':>14} {'outcome':>18} {'value':>18}  policy  branch"
        lines = [f"{r[0]:>14.9g} {r[1]:>18.12g} {r[2]:>18.12g}  {r[3]}  {r[4]}" for r in rows]
        ok = bool(result.success.all())
    else:
        u = list(FIXED_INPUTS[maneuver])
        for j, name in enumerate(("u1", "u2", "u12")):
            if getattr(args, name) is not None:
                u[j] = getattr(args, name)
        grid = grid_from_args(args, maneuver, 401)
        result = sweep_fixed(maneuver, grid, u, progress=progress_from_args(args))
        header = f"{'theta0':>14} {'outcome':>18}  branch"
        lines = [f"{th:>14.9g} {result.outcome[k]:>18.12g}  {result.branch[k]}"
                 for k, th in enumerate(result.theta0)]
        ok = bool(result.success.all())
    return print_sweep(args, result.as_dict(), header, lines, ok)


def print_sweep(args: argparse.Namespace, data: dict, header: str, lines: list[str],
                ok: bool) -> int:
    """The sweep as JSON to --out, else as a table on stdout; the exit status."""
    if args.out:
        try:
            with open(args.out, "w", encoding="utf-8") as fh:
                fh.write(strict_json.dumps(data))
        except OSError as exc:
            raise InvalidInputError(f"--out: cannot write {str(args.out)!r}: {exc.strerror}"
                                    ) from None
        print(f"wrote {len(lines)} points to {args.out}")
    else:
        print(header)
        print("\n".join(lines))
    return 0 if ok else 1
