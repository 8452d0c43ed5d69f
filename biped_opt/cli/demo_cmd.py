"""``biped-opt demo``: the paper's full reproduction (figures and the nonsmooth table)."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="reproduce the paper: sweeps, nonsmooth table, figures")
    p.add_argument("--out", type=Path, default=Path("out"), help="output directory (default out/)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from biped_opt.plots.reproduce import reproduce

    result = reproduce(args.out / "figures", progress=False)
    print("Nonsmooth points of outcomes, optimal policies and values (left | right)\n")
    print(result.table())
    print()
    for path in (*result.figures, result.captions):
        print(f"wrote {path}")
    print(f"reproduction took {result.seconds:.1f} s")
    return 0
