"""``biped-opt sweep``: outcomes at fixed inputs, or optimal policies and values, over th0 (the
biped) or s (any system)."""

from __future__ import annotations

import argparse

from biped_opt.cli.args import (
    SWEEP_NUM,
    add_problem_arguments,
    add_range_arguments,
    add_system_arguments,
    compiled_from_args,
    finite_float,
    grid_from_args,
    output_file,
    parse_maneuver_arg,
    path_arg,
    problem_from_args,
    problem_from_system_args,
    progress_from_args,
    s_grid_from_args,
    uses_system,
)
from biped_opt.cli.output import emit_sweep, fixed_sweep_table, optimal_sweep_table


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
    system = uses_system(args)
    if args.optimal or args.variant or args.problem is not None:
        return (_optimal_system if system else _optimal_biped)(args)
    return (_fixed_system if system else _fixed_biped)(args)


def _optimal_biped(args: argparse.Namespace) -> int:
    from biped_opt.paper.sweeps import sweep_optimal

    maneuver = parse_maneuver_arg(args.maneuver).value
    problem = problem_from_args(args)
    grid = grid_from_args(args, maneuver, SWEEP_NUM["optimal"])
    result = sweep_optimal(problem, grid, progress=progress_from_args(args))
    policy = [{d: result.policy[d][k] for d in problem.decisions}
              for k in range(len(result.theta0))]
    header, lines = optimal_sweep_table("theta0", result.theta0, result.outcome, result.value,
                                        policy, result.branch)
    return emit_sweep(args.out, result.as_dict(), header, lines, bool(result.success.all()))


def _fixed_biped(args: argparse.Namespace) -> int:
    from biped_opt.paper.biped import FIXED_INPUTS
    from biped_opt.paper.sweeps import sweep_fixed

    maneuver = parse_maneuver_arg(args.maneuver).value
    u = [value if value is not None else default
         for value, default in zip((args.u1, args.u2, args.u12), FIXED_INPUTS[maneuver])]
    grid = grid_from_args(args, maneuver, SWEEP_NUM["fixed"])
    result = sweep_fixed(maneuver, grid, u, progress=progress_from_args(args))
    header, lines = fixed_sweep_table("theta0", result.theta0, result.outcome, result.branch)
    return emit_sweep(args.out, result.as_dict(), header, lines, bool(result.success.all()))


def _optimal_system(args: argparse.Namespace) -> int:
    from biped_opt.control.solve import compiled_for, optimal_sweep
    from biped_opt.progress import bar

    problem = problem_from_system_args(args)
    grid = s_grid_from_args(args, compiled_for(problem), problem.maneuver, SWEEP_NUM["optimal"])
    progress = bar(progress_from_args(args), grid.size, f"{problem.name} sweep")
    results = optimal_sweep(problem, grid, callback=progress.update)
    policy = [{d: r.policy[d] for d in problem.decision_names} for r in results]
    header, lines = optimal_sweep_table("s", [r.s for r in results],
                                        [r.outcome for r in results],
                                        [r.value for r in results], policy,
                                        [r.branch for r in results])
    data = {"problem": problem.as_dict(),
            "points": [{"s": r.s, "outcome": r.outcome, "value": r.value, "policy": r.policy,
                        "branch": r.branch, "success": r.success} for r in results]}
    return emit_sweep(args.out, data, header, lines, all(r.success for r in results))


def _fixed_system(args: argparse.Namespace) -> int:
    from biped_opt.control.solve import branch_of

    compiled = compiled_from_args(args)
    maneuver = args.maneuver
    first = compiled.initial_mode(maneuver)
    grid = s_grid_from_args(args, compiled, maneuver, SWEEP_NUM["fixed"])
    u = compiled.input_vector(dict(args.input))
    out = compiled.simulate_batch(maneuver, grid, u)
    branches = [branch_of(compiled, first, out["events"][k, : int(out["n_events"][k])], status)
                for k, status in enumerate(out.statuses())]
    header, lines = fixed_sweep_table("s", grid, out["outcome"], branches)
    data = {"system": compiled.name, "maneuver": maneuver,
            "inputs": dict(zip(compiled.inputs, u.tolist())),
            "parameters": compiled.parameters, "s": grid.tolist(),
            "outcome": out["outcome"].tolist(), "t_final": out["t_final"].tolist(),
            "branch": branches}
    return emit_sweep(args.out, data, header, lines, bool((out["status"] == 0).all()))
