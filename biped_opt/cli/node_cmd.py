"""``biped-opt node NAME`` and ``biped-opt launch``: the ROS 2 nodes without ``ros2 run``."""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from typing import Any

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


#: how long ``launch`` lets its nodes stop after Ctrl-C or SIGTERM before it ends without
#: them [s]: a callback under way (a study's work item, a first compile in C) can take minutes
LAUNCH_STOP_S = 2.5
#: the backstop [s]: if the process has not ended this long after the signal (no Python thread
#: got to run: something held the interpreter), faulthandler's own thread prints every thread's
#: stack and ends it with status 1
LAUNCH_HARD_STOP_S = 12.5


def _end_after_stop(stop: Any) -> None:
    """Once a stop is asked, give the graph :data:`LAUNCH_STOP_S`, then end the process
    (status 0, one line saying what was left; the nodes write no file of their own); at the
    latest after :data:`LAUNCH_HARD_STOP_S`, with the stacks that held it (status 1)."""
    import faulthandler

    stop.event.wait()
    faulthandler.dump_traceback_later(LAUNCH_HARD_STOP_S, exit=True)
    time.sleep(LAUNCH_STOP_S)
    print(f"biped-opt launch: stopped {LAUNCH_STOP_S:g} s after the signal without waiting for "
          "the callbacks still under way", file=sys.stderr, flush=True)
    sys.stdout.flush()
    os._exit(0)


def run_launch(args: argparse.Namespace) -> int:
    from biped_opt.cli.signals import stop_requested
    from biped_opt.nodes.graph import Graph

    # a signal while the graph starts abandons the start; once it runs, a signal (even one that
    # arrives while the "running" line is printed) only ends the wait below; either way the
    # process ends within LAUNCH_STOP_S of it
    with stop_requested(interrupt=True) as stop:
        threading.Thread(target=_end_after_stop, args=(stop,), name="launch-stop",
                         daemon=True).start()
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
