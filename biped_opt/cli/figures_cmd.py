"""``biped-opt figures``: the paper's Figs. 2-4 as PNG, with captions and the nonsmooth table, and
the control experiment (coupled vs decoupled walker, rocking bar) in one more PNG.

With ``--system`` (or a problem file as ``--problem``) the figures of any system instead: a
maneuver swept over s at fixed inputs (``--maneuver M [--input N=V ...]``: outcome with its
nonsmooth points, contact modes over time and s) or an optimal-control problem (``--problem``:
optimal outcome, policy and value with theirs), with captions.txt and data.json.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from biped_opt.cli.args import (
    MAX_POINTS,
    add_system_arguments,
    check_physical_args,
    check_size,
    int_in_range,
    output_directory,
    path_arg,
    problem_from_system_args,
    s_grid_from_args,
    uses_system,
)
from biped_opt.cli.output import emit_paths
from biped_opt.errors import InvalidInputError

#: grid sizes with --system when --num is not given: fixed inputs, optimal
SYSTEM_NUM = {"fixed": 401, "optimal": 101}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("figures", help="reproduce the paper's figures (PNG) and nonsmooth table, "
                                       "or draw any system's (--system)")
    p.add_argument("--out", type=path_arg(output_directory, "--out", create=False),
                   default=Path("out/figures"), help="output directory")
    p.add_argument("--fixed-num", type=int_in_range("--fixed-num", 5, MAX_POINTS), default=None,
                   help="angles per fixed sweep (default 401; the biped's)")
    p.add_argument("--optimal-num", type=int_in_range("--optimal-num", 5, MAX_POINTS), default=None,
                   help="angles per optimal sweep (default 201; the biped's)")
    p.add_argument("--progress", action="store_true", help="progress bars on stderr")
    add_system_arguments(p, sweep=True)
    g = p.add_argument_group("any system: the maneuver and the grid")
    g.add_argument("--maneuver", default=None, metavar="M",
                   help="the maneuver swept at fixed inputs (--input NAME=VALUE)")
    g.add_argument("--num", type=int_in_range("--num", 5, MAX_POINTS), default=None,
                   help=f"values of s (default {SYSTEM_NUM['fixed']} fixed, "
                        f"{SYSTEM_NUM['optimal']} optimal; 0 included when inside)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if uses_system(args):
        return run_system(args)
    for flag in ("maneuver", "num"):
        if getattr(args, flag) is not None:
            raise InvalidInputError(f"--{flag}: only with --system")
    output_directory("--out", args.out)
    # matplotlib only when drawing
    from biped_opt.plots.reproduce import reproduce
    from biped_opt.plots.systems import CONTROL_EXPERIMENT_CAPTION, control_experiment_figure

    result = reproduce(args.out, fixed_num=args.fixed_num or 401,
                       optimal_num=args.optimal_num or 201, progress=args.progress)
    experiment = control_experiment_figure(args.out / "control_experiment.png")
    with result.captions.open("a") as fh:
        fh.write(f"\n{CONTROL_EXPERIMENT_CAPTION}\n")
    print(result.table())
    print()
    emit_paths((*result.figures, experiment, result.captions))
    print(f"reproduction took {result.seconds:.1f} s")
    return 0


def run_system(args: argparse.Namespace) -> int:
    """Any system's figures; every argument is checked before the output directory is made."""
    import time

    from biped_opt.control.solve import compiled_for
    from biped_opt.simulation.compiled import CompiledSystem

    for flag in ("fixed_num", "optimal_num"):
        if getattr(args, flag) is not None:
            raise InvalidInputError(f"--{flag.replace('_', '-')}: the biped's option; with "
                                    "--system the grid is --num, --s-min, --s-max")
    start = time.perf_counter()
    if args.problem is not None:
        if args.input:
            raise InvalidInputError("--input: fixed-input figures only (--maneuver without "
                                    "--problem); a problem fixes its other inputs itself")
        problem = problem_from_system_args(args)
        compiled, maneuver, kind = compiled_for(problem), problem.maneuver, "optimal"
    else:
        if args.system is None:
            raise InvalidInputError("--system is required")
        if args.maneuver is None:
            raise InvalidInputError("--maneuver (fixed inputs) or --problem (optimal) is "
                                    "required with --system")
        check_size(args, "--system", args.system)
        compiled, maneuver, kind = CompiledSystem(args.system, **dict(args.param)), \
            args.maneuver, "fixed"
        compiled.initial_mode(maneuver)  # an unknown maneuver: the system's message
        check_physical_args(args, compiled, maneuver)
        compiled.input_vector(dict(args.input))  # an unknown input: the system's message
    grid = s_grid_from_args(args, compiled, maneuver, SYSTEM_NUM[kind])
    output_directory("--out", args.out)
    # matplotlib only when drawing
    from biped_opt.plots.systems import fixed_input_figures, optimal_figures

    if kind == "optimal":
        result = optimal_figures(args.out, problem, grid, progress=args.progress)
    else:
        result = fixed_input_figures(args.out, compiled, maneuver, grid, dict(args.input),
                                     progress=args.progress)
    print(f"{result.subject}: {len(result.report.points)} nonsmooth points over "
          f"{grid.size} values of {result.report.parameter}")
    print(result.report.table())
    print()
    emit_paths((*result.figures, result.captions, result.data))
    print(f"figures took {time.perf_counter() - start:.1f} s")
    return 0
