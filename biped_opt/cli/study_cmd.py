"""``biped-opt study``: a parameter study of the nonsmoothness, resumable, on local processes
or on the optimiser nodes of a ROS 2 domain.

``biped-opt study STUDY.yaml --out TABLE.csv [--workers N | --ros]``: the study file holds the
keys of :meth:`~biped_opt.studies.study.Study.from_spec` (system, maneuver and inputs and/or
problem, grid and/or sample with samples and seed, s_range, num, num_optimal, name). With
``--ros`` a coordinator (:mod:`biped_opt.nodes.coordinator`) hands the points to every optimiser
node on the domain (``ROS_DOMAIN_ID``), on any machine. Run again with the same arguments to
continue an interrupted study; SIGINT/SIGTERM stop it after the points under way (exit status
130, as a shell gives an interrupted command). A table damaged since (a row that is not UTF-8,
holds a NUL byte, names a point the study does not have or other parameter values) loses those
rows and their points are computed again, which the run says in one line. """

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from biped_opt.cli.args import (
    add_progress_arguments,
    int_in_range,
    output_directory,
    output_file,
    path_arg,
    positive_float,
    progress_from_args,
)
from biped_opt.errors import BipedOptError, InvalidInputError

#: local processes at most: each holds a compiled system (~200 MB); more is a typo
MAX_WORKERS = 256


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("study", help="parameter study: where kinks and jumps persist (CSV)")
    p.add_argument("spec", metavar="STUDY.yaml", type=Path,
                   help="the study (system, maneuver/problem, grid/sample, ...)")
    p.add_argument("--out", required=True, type=path_arg(output_file, "--out", overwrite=True),
                   metavar="TABLE.csv",
                   help="the table; if it exists with the same study, the run continues it")
    p.add_argument("--workers", type=int_in_range("--workers", 1, MAX_WORKERS), default=1,
                   help=f"local processes (default 1, at most {MAX_WORKERS})")
    p.add_argument("--mcap", type=path_arg(output_file, "--mcap", overwrite=True), default=None,
                   metavar="FILE.mcap",
                   help="also write the table as /biped/study StudyRow messages to an MCAP file")
    p.add_argument("--figures", type=path_arg(output_directory, "--figures", create=False),
                   default=None, metavar="DIR",
                   help="draw the table's figures (heat maps over the first two parameters, "
                        "policy switch locations) into DIR")
    p.add_argument("--ros", action="store_true",
                   help="compute on the optimiser nodes of the ROS 2 domain (start `biped-opt "
                        "node optimiser` on each machine with the same ROS_DOMAIN_ID)")
    p.add_argument("--item-timeout", type=positive_float("--item-timeout", maximum=86400.0),
                   default=None,
                   metavar="S", help="with --ros: a point a node has not answered in S seconds "
                                     "goes to another node (default 300)")
    add_progress_arguments(p)
    p.set_defaults(func=run)


def load_study(path: Path):
    """A Study from a YAML file; errors name the file."""
    from biped_opt.control.problems import read_yaml
    from biped_opt.studies.study import Study

    if not path.exists() or path.is_dir():  # (a device or a FIFO: read_yaml says what it is)
        raise InvalidInputError(f"{path}: no such study file")
    try:
        return Study.from_spec(read_yaml(path), where=str(path))
    except BipedOptError as exc:
        raise InvalidInputError(str(exc)) from None


def run(args: argparse.Namespace) -> int:
    from biped_opt.cli.signals import stop_requested
    from biped_opt.progress import Progress
    from biped_opt.record.study_table import run_study

    study = load_study(args.spec)
    bar = Progress(1, f"{study.name}", enabled=progress_from_args(args))
    if args.ros and args.workers > 1:
        raise InvalidInputError("--workers: not with --ros (the optimiser nodes do the work)")
    if args.item_timeout is not None and not args.ros:
        raise InvalidInputError("--item-timeout: only with --ros")
    with stop_requested() as stop:
        if args.ros:
            from biped_opt.nodes.coordinator import run_on_domain

            parameters = {} if args.item_timeout is None else {"item_timeout": args.item_timeout}
            summary = run_on_domain(study, args.out, parameters=parameters,
                                    progress=lambda done, total, _: bar.update(done, total),
                                    stop=stop.is_set)
        else:
            summary = run_study(study, args.out, workers=args.workers, progress=bar.update,
                                stop=stop.is_set)
    if summary.repaired:
        print(f"biped-opt study: {args.out}: {summary.repaired}", file=sys.stderr)
    print(f"{summary.path}: {summary.points} parameter points, {summary.computed} computed now, "
          f"{summary.resumed} resumed, {summary.rows} rows"
          + ("; stopped early, run again to continue" if summary.stopped else ""))
    if stop.is_set():
        return 130  # (the table as far as it got; no file or figure of a part of it)
    if args.mcap is not None:
        from biped_opt.record.study_table import write_study_mcap

        print(f"  {args.mcap}: {write_study_mcap(study, args.out, args.mcap)} /biped/study rows")
    if args.figures is not None:
        from biped_opt.plots.study import study_figures
        from biped_opt.record.study_table import read_table

        output_directory("--figures", args.figures)
        for path in study_figures(args.figures, read_table(args.out, study),
                                  study.parameter_names):
            print(f"  {path}")
    return 0
