"""``biped-opt nonsmooth``: where outcome, policy and value are not C^1, located and explained."""

from __future__ import annotations

import argparse

from biped_opt import strict_json
from biped_opt.cli.optimise_cmd import add_problem_arguments, problem_from_args
from biped_opt.cli.simulate_cmd import parse_maneuver_arg
from biped_opt.cli.sweep_cmd import add_range_arguments, grid_from_args, progress_from_args
from biped_opt.cli.system_cmds import add_system_arguments, run_nonsmooth, uses_system
from biped_opt.fixed_sweep import FIXED_INPUTS
from biped_opt.optimal.nonsmooth import (
    NonsmoothReport,
    find_nonsmooth_fixed,
    find_nonsmooth_optimal,
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "nonsmooth", help="find and classify the nonsmooth points along a th0 sweep"
    )
    add_problem_arguments(p)
    add_range_arguments(p, "sweep grid points (default 401 fixed, 201 optimal; 0 always included)")
    p.add_argument("--optimal", action="store_true",
                   help="analyse the optimal outcome, policy and value (default: the outcome "
                        "at the paper's fixed inputs)")
    add_system_arguments(p, sweep=True)
    p.add_argument("--json", action="store_true", help="print a JSON list of points")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if uses_system(args):
        return run_nonsmooth(args)
    maneuver = parse_maneuver_arg(args.maneuver).value
    progress = progress_from_args(args)
    if args.optimal or args.variant:
        problem = problem_from_args(args)
        grid = grid_from_args(args, maneuver, 201)
        report = find_nonsmooth_optimal(problem, grid, progress=progress)
    else:
        grid = grid_from_args(args, maneuver, 401)
        report = find_nonsmooth_fixed(maneuver, grid, FIXED_INPUTS[maneuver], progress=progress)
    return print_report(report, args.json)


def print_report(report: NonsmoothReport, as_json: bool) -> int:
    """A nonsmooth table as text, or as a JSON list of points."""
    if as_json:
        print(strict_json.dumps([p.as_dict() for p in report.points]))
    else:
        kind = "optimal" if report.optimal else "fixed-input"
        print(f"{report.subject} ({kind}), {report.parameter} in [{report.theta0_range[0]:g}, "
              f"{report.theta0_range[1]:g}], {report.grid_size} grid points, "
              f"{len(report.points)} nonsmooth findings")
        print(report.table())
    return 0
