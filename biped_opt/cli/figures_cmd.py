"""``biped-opt figures``: the paper's Figs. 2-4 as PNG, with captions and the nonsmooth table, and
the control experiment (coupled vs decoupled walker, rocking bar) in one more PNG."""

from __future__ import annotations

import argparse
from pathlib import Path

from biped_opt.cli.args import int_at_least, output_directory


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("figures", help="reproduce the paper's figures (PNG) and nonsmooth table")
    p.add_argument("--out", type=Path, default=Path("out/figures"), help="output directory")
    p.add_argument("--fixed-num", type=int_at_least("--fixed-num", 5), default=401,
                   help="angles per fixed sweep")
    p.add_argument("--optimal-num", type=int_at_least("--optimal-num", 5), default=201,
                   help="angles per optimal sweep")
    p.add_argument("--progress", action="store_true", help="progress bars on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    output_directory("--out", args.out)
    # matplotlib only when drawing
    from biped_opt.plots.reproduce import reproduce
    from biped_opt.plots.systems import CONTROL_EXPERIMENT_CAPTION, control_experiment_figure

    result = reproduce(args.out, fixed_num=args.fixed_num, optimal_num=args.optimal_num,
                       progress=args.progress)
    experiment = control_experiment_figure(args.out / "control_experiment.png")
    with result.captions.open("a") as fh:
        fh.write(f"\n{CONTROL_EXPERIMENT_CAPTION}\n")
    print(result.table())
    print()
    for path in (*result.figures, experiment, result.captions):
        print(f"wrote {path}")
    print(f"reproduction took {result.seconds:.1f} s")
    return 0
