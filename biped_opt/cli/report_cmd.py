"""``biped-opt report FILE... --out DIR``: figures, a nonsmoothness table and one HTML page of
them from recordings."""

from __future__ import annotations

import argparse

from biped_opt.cli.args import int_in_range, output_directory, path_arg
from biped_opt.cli.output import emit_paths

__all__ = ["register", "func"]

#: the most figure processes --jobs asks for (a report has a handful of figures)
MAX_JOBS = 64


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "report", help="rebuild the paper's figures and a nonsmooth table from recordings",
        description="Offline analysis of recorded sweeps (no node runs): Fig. 2 and 3 from "
                    "fixed-input sweeps, Fig. 4 from optimal sweeps, and a table of nonsmooth "
                    "points estimated at the recording's grid resolution (one-sided limits and "
                    "slopes extrapolated from the recorded angles on each side). --refine also "
                    "locates every point to 1e-10 with the core and prints both. All of it "
                    "also goes into one self-contained page, DIR/report.html.")
    p.add_argument("files", nargs="+", metavar="FILE", help=".mcap recordings")
    p.add_argument("--out", type=path_arg(output_directory, "--out", create=False),
                   required=True, help="output directory (made once the recordings are read)")
    p.add_argument("--refine", action="store_true",
                   help="re-locate the points with the core (simulates/optimises again)")
    p.add_argument("--jobs", type=int_in_range("--jobs", 1, MAX_JOBS), default=None,
                   metavar="N",
                   help="draw up to N figures at once, in forked processes (default: the CPUs "
                        "this process may use; 1: one after the other in this process)")
    p.set_defaults(func=func)


def func(args: argparse.Namespace) -> int:
    from biped_opt.record.reader import read_raw

    # every file read first, before the analysis and plotting modules load: a file that is
    # no recording is refused in a fraction of a second and of the memory
    raws = [read_raw(path, topics=("/biped/sweep", "/biped/system_info"))
            for path in args.files]
    from biped_opt.plots.parallel import usable_processes
    from biped_opt.record.report import report

    result = report(raws, args.out, refine=args.refine,
                    processes=args.jobs or usable_processes())
    for s in result.sweeps:
        state = "complete" if s.complete else f"RECOVERED ({s.note})"
        print(f"{s.path}: {s.kind} {s.label} sweep, {s.theta0.size} points, {state}")
    print()
    print(result.table)
    emit_paths((*result.figures, result.table_path, *([result.page] if result.page else [])))
    return 0
