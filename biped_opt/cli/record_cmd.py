"""``biped-opt record``: bring up the graph in-process and record one sweep to MCAP."""

from __future__ import annotations

import argparse
from pathlib import Path

from biped_opt.cli.args import (
    add_large_argument,
    check_size,
    finite_float,
    input_file,
    int_in_range,
    output_file,
    path_arg,
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("record", help="record a sweep through the ROS graph to an MCAP file")
    p.add_argument("--maneuver", required=True)
    p.add_argument("--theta0-min", required=True, type=finite_float("--theta0-min"))
    p.add_argument("--theta0-max", required=True, type=finite_float("--theta0-max"))
    p.add_argument("--num", required=True, type=int_in_range("--num", 2, 100_000),
                   help="angles (th0 = 0 is always added)")
    p.add_argument("--optimal", action="store_true", help="optimal policies (else fixed inputs)")
    p.add_argument("--out", required=True, type=path_arg(output_file, "--out", overwrite=False),
                   help="output .mcap file (its directory must exist; never overwritten)")
    p.add_argument("--params-file", type=path_arg(input_file, "--params-file"), default=None,
                   help="ROS 2 parameter file")
    p.add_argument("--system", default="",
                   help="record another system than the biped: a library name or a system "
                        "file (the --theta0 range is then the maneuver's s)")
    p.add_argument("--problem", default="",
                   help="with --system and --optimal: a problem the system declares or a "
                        "problem file (default: the one named like the maneuver)")
    p.add_argument("--inputs", nargs="+", type=finite_float("--inputs"), default=(),
                   metavar="U", help="fixed inputs: the biped's u1 u2 u12 (default: the "
                                     "paper's), another system's in its declared order "
                                     "(default zeros)")
    add_large_argument(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from biped_opt.cli.signals import stop_requested
    from biped_opt.nodes.graph import Graph
    from biped_opt.nodes.recorder import SweepRequest

    request = SweepRequest(maneuver=args.maneuver, theta0_min=args.theta0_min,
                           theta0_max=args.theta0_max, num=args.num, optimal=args.optimal,
                           output=args.out, system=args.system, problem=args.problem,
                           fixed_inputs=tuple(args.inputs)).validated()
    check_size(args, "--system", args.system)
    large = {"max_legs": 1 << 20, "max_coordinates": 1 << 20} if args.large else {}
    # Ctrl-C or SIGTERM while the graph starts abandons the start; once it records, either one
    # stops the sweep after the current point, the file is finished and the summary printed
    # (the optimiser serves the operator's problem file by name from its directory)
    problem_file = [args.problem] if Path(args.problem).suffix else []
    with stop_requested(interrupt=True) as stop:
        try:
            graph = Graph(params_file=args.params_file,
                          overrides={"simulator": {"autostart": False, "system": args.system},
                                     "optimiser": {"systems": [args.system, *problem_file]
                                                   if args.optimal else [], **large},
                                     "recorder": {"system": args.system}})
        except KeyboardInterrupt:
            return 0
        with graph:
            stop.defer(graph.recorder.stop)
            summary = graph.recorder.record(request)
    print(summary.path)
    for topic, count in summary.counts.items():
        print(f"  {topic:22s} {count:8d} messages")
    if summary.stopped:
        print(f"  stopped by a signal after {summary.recorded} of {summary.points} angles")
    if summary.failed:
        print(f"  {summary.failed} of {summary.recorded} sweep points did not reach their end")
    return 0 if not summary.failed else 1
