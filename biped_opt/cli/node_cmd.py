"""``biped-opt node NAME`` and ``biped-opt launch``: the ROS 2 nodes without ``ros2 run``."""

from __future__ import annotations

import argparse

from biped_opt.cli.args import input_file, path_arg

NODES = ("simulator", "optimiser", "recorder", "coordinator", "foxglove")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "node", help="run one node (as `ros2 run biped_opt NAME`)",
        description="Arguments after NAME go to the node, e.g. --ros-args -p theta0:=0.05 "
                    "or --ros-args --params-file config/biped.yaml",
    )
    p.add_argument("name", choices=NODES)
    p.add_argument("ros_args", nargs=argparse.REMAINDER, help="--ros-args ...")
    p.set_defaults(func=run_node)
    p = sub.add_parser("launch", help="run all three nodes in one process (as the launch file)")
    p.add_argument("--params-file", type=path_arg(input_file, "--params-file"), default=None,
                   help="ROS 2 parameter file (default: config/biped.yaml)")
    p.set_defaults(func=run_launch)


def run_node(args: argparse.Namespace) -> int:
    import importlib

    module = importlib.import_module(f"biped_opt.nodes.{args.name}")
    module.main(args=["biped-opt-node", *args.ros_args])
    return 0


def run_launch(args: argparse.Namespace) -> int:
    from biped_opt.cli.signals import stop_requested
    from biped_opt.nodes.graph import Graph

    # a signal while the graph starts abandons the start; once it runs, a signal (even one that
    # arrives while the "running" line is printed) only ends the wait below
    with stop_requested(interrupt=True) as stop:
        try:
            graph = Graph(params_file=args.params_file)
        except KeyboardInterrupt:
            return 0
        with graph:
            stop.defer()
            names = ", ".join(n.get_name() for n in (graph.simulator, graph.optimiser,
                                                     graph.recorder))
            print(f"running {names}; Ctrl-C to stop", flush=True)
            stop.wait()
    return 0
