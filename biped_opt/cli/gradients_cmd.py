"""``biped-opt gradients``: gradient methods at kinks and jumps, measured (paper Sec. V-A)."""

from __future__ import annotations

import argparse
import dataclasses
import functools
import sys
from pathlib import Path
from typing import Any

from biped_opt.cli.args import (
    GRADIENT_EPS_VALUES,
    GRADIENT_SAMPLE_COUNTS,
    GRADIENT_SIGMAS,
    MAX_SEED,
    LazyChoices,
    int_in_range,
    output_directory,
    path_arg,
)
from biped_opt.cli.output import emit_json, emit_paths


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "gradients", help="descent and policy-gradient estimators at kinks and jumps, measured")
    p.add_argument("--seed", type=int_in_range("--seed", 0, MAX_SEED), default=0,
                   help="seed of every random draw (default 0)")
    p.add_argument("--quick", action="store_true",
                   help="small grids and samples (seconds per problem once compiled)")
    sizes = p.add_argument_group(
        "sizes", "each overrides the full study's size, or --quick's (a trial run: --starts 1 "
                 "--samples 64 --iterations 3 --quadrature 41, under a second per problem)")
    for flag, what in (("starts", "starting decisions per axis of each descent grid "
                                  "(default 7 for one decision, 4 for two; --quick 3 and 2)"),
                       ("samples", "draws of each estimator's bias and spread (default 20000; "
                                   "--quick 2000)"),
                       ("iterations", "iteration budget of every descent (default 60; "
                                      "--quick 30)"),
                       ("quadrature", "grid points per axis of the reference D J_sigma "
                                      "(default 8001 for one decision, 241 for two)")):
        sizes.add_argument(f"--{flag}", metavar="N", default=None, help=what,
                           type=int_in_range(f"--{flag}", _LOW[flag],
                                             functools.partial(_high, flag)))
    p.add_argument("--problem", action="append", metavar="NAME",
                   choices=LazyChoices(_problem_names),
                   help="study only this problem (repeatable; default all four)")
    p.add_argument("--figures", type=path_arg(output_directory, "--figures", create=False),
                   metavar="DIR", default=None,
                   help="write one figure per problem, gradients_<problem>.png, into DIR")
    p.add_argument("--json", action="store_true", help="print the tables' numbers as JSON")
    p.add_argument("--verbose", action="store_true", help="report each stage on stderr")
    p.set_defaults(func=run)


#: the smallest value of each size (the largest is the study's own limit, read when used)
_LOW = {"starts": 1, "samples": 2, "iterations": 1, "quadrature": 3}


def _high(flag: str) -> int:
    from biped_opt.analysis.gradients import GradientSizes

    return GradientSizes.LIMITS[flag][1]


def _sizes(args: argparse.Namespace) -> Any:
    """The preset (--quick or the full study) with the sizes given on the command line."""
    from biped_opt.analysis.gradients import FULL, QUICK

    chosen: dict[str, Any] = {}
    for flag in ("starts", "quadrature"):
        if getattr(args, flag) is not None:
            chosen[flag] = (getattr(args, flag),) * 2
    for flag in ("samples", "iterations"):
        if getattr(args, flag) is not None:
            chosen[flag] = getattr(args, flag)
    return dataclasses.replace(QUICK if args.quick else FULL, **chosen)


def _problem_names() -> list[str]:
    from biped_opt.analysis.gradients import PROBLEMS

    return [name for _, name, _, _ in PROBLEMS]


def run(args: argparse.Namespace) -> int:
    from biped_opt.analysis.gradients import report, run_gradient_study

    def say(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    study = run_gradient_study(seed=args.seed, quick=args.quick, problems=args.problem,
                               sigmas=GRADIENT_SIGMAS, sample_counts=GRADIENT_SAMPLE_COUNTS,
                               eps_values=GRADIENT_EPS_VALUES, sizes=_sizes(args),
                               progress=say if args.verbose else None)
    if args.json:
        emit_json(study.as_dict())
    else:
        print(report(study, GRADIENT_SAMPLE_COUNTS))
    if args.figures:
        from biped_opt.plots.gradients import gradient_figure

        output_directory("--figures", args.figures)
        emit_paths((gradient_figure(study, name, Path(args.figures) / f"gradients_{name}.png")
                    for name in study.curves), to_stderr=True)
    return 0
