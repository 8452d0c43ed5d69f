"""The ``main`` of every node: init, spin until Ctrl-C or SIGTERM, clean up (rclpy's form)."""

from __future__ import annotations

import signal
from collections.abc import Callable
from typing import Any

from biped_opt import ros

__all__ = ["run_node", "stop_on_sigterm"]


def stop_on_sigterm() -> None:
    """Let SIGTERM (what ``ros2 launch`` sends after SIGINT) end a node like Ctrl-C: spin raises
    KeyboardInterrupt, the node is destroyed, open files are finished, the exit status is 0."""
    signal.signal(signal.SIGTERM, signal.default_int_handler)


def run_node(make_node: Callable[[], Any], args: list[str] | None, *, threads: int = 1) -> None:
    """Create the node after ``ros.init(args)`` and spin it (``threads`` > 1: a multi-threaded
    executor, for nodes whose callbacks wait on each other or serve concurrent clients)."""
    stop_on_sigterm()
    ros.init(args=args)
    node = make_node()
    executor = (ros.MultiThreadedExecutor(num_threads=threads) if threads > 1
                else ros.SingleThreadedExecutor())
    executor.add_node(node)
    try:
        executor.spin()
    except KeyboardInterrupt:
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        ros.try_shutdown()
