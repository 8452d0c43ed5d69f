"""``biped-opt nonsmooth``: where outcome, policy and value are not C^1, located and explained."""

from __future__ import annotations

import argparse

from biped_opt.cli.args import (
    SWEEP_NUM,
    add_problem_arguments,
    add_range_arguments,
    add_system_arguments,
    compiled_from_args,
    grid_from_args,
    parse_maneuver_arg,
    problem_from_args,
    problem_from_system_args,
    progress_from_args,
    s_grid_from_args,
    uses_system,
)
from biped_opt.cli.output import show_report


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
    system = uses_system(args)
    progress = progress_from_args(args)
    kind = "optimal" if args.optimal or args.variant or args.problem is not None else "fixed"
    if system and kind == "optimal":
        from biped_opt.analysis.nonsmooth import find_nonsmooth_optimal
        from biped_opt.control.solve import compiled_for

        problem = problem_from_system_args(args)
        grid = s_grid_from_args(args, compiled_for(problem), problem.maneuver, SWEEP_NUM[kind])
        report = find_nonsmooth_optimal(problem, grid, progress=progress)
    elif system:
        from biped_opt.analysis.nonsmooth import find_nonsmooth

        compiled = compiled_from_args(args)
        compiled.initial_mode(args.maneuver)  # an unknown maneuver: the system's message
        grid = s_grid_from_args(args, compiled, args.maneuver, SWEEP_NUM[kind])
        report = find_nonsmooth(compiled, args.maneuver, dict(args.input), s=grid,
                                progress=progress)
    elif kind == "optimal":
        from biped_opt.paper.nonsmooth import find_nonsmooth_optimal as find_biped_optimal

        maneuver = parse_maneuver_arg(args.maneuver).value
        problem = problem_from_args(args)
        grid = grid_from_args(args, maneuver, SWEEP_NUM[kind])
        report = find_biped_optimal(problem, grid, progress=progress)
    else:
        from biped_opt.paper.biped import FIXED_INPUTS
        from biped_opt.paper.nonsmooth import find_nonsmooth_fixed

        maneuver = parse_maneuver_arg(args.maneuver).value
        grid = grid_from_args(args, maneuver, SWEEP_NUM[kind])
        report = find_nonsmooth_fixed(maneuver, grid, FIXED_INPUTS[maneuver], progress=progress)
    return show_report(report, args.json)
