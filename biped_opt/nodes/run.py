"""The ``main`` of every node: init, spin until Ctrl-C or SIGTERM, clean up (rclpy's form); and
the kernels' warm-up the simulating nodes do before they serve."""

from __future__ import annotations

import signal
from collections.abc import Callable
from typing import Any

from biped_opt import ros
from biped_opt.hybrid import warm_up

__all__ = ["run_node", "stop_on_sigterm", "warm_up_kernels"]


def stop_on_sigterm() -> None:
    """Let SIGTERM (what ``ros2 launch`` sends after SIGINT) end a node like Ctrl-C: spin raises
    KeyboardInterrupt, the node is destroyed, open files are finished, the exit status is 0."""
    signal.signal(signal.SIGTERM, signal.default_int_handler)


def warm_up_kernels(node: Any) -> None:
    """Compile (or load) the simulator's kernels before ``node`` offers its services: in a fresh
    checkout that takes ~30 s, which a client's first request would otherwise wait out (and a
    30 s service timeout would not). Logged when it took noticeably long."""
    seconds = warm_up()
    if seconds > 1.0:
        node.get_logger().info(
            f"compiled the simulator's kernels in {seconds:.1f} s (cached for later runs)"
        )


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
