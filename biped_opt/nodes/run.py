"""The ``main`` of every node: init, spin until Ctrl-C or SIGTERM, clean up (rclpy's form); the
kernels' warm-up the simulating nodes do before they serve, and the one "ready" line each node
logs once it serves."""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Callable
from typing import Any

from biped_opt import ros
from biped_opt.paper.biped import kernels_cached, warm_up

__all__ = ["announce_ready", "run_node", "stop_on_sigterm", "warm_up_kernels"]

#: what a first compile takes on a 2-core machine [s] (measured 27-63 s)
FIRST_COMPILE_S = (30, 60)
#: after SIGINT/SIGTERM, how long callbacks under way may take to return before the process
#: ends without them [s]
STOP_GRACE_S = 3.0
#: then how long the node's own clean-up (destroy_node, the middleware's) may take [s]
TEARDOWN_S = 10.0


def stop_on_sigterm() -> None:
    """Let SIGINT and SIGTERM (what ``ros2 launch`` sends after SIGINT) end a node like Ctrl-C:
    spin raises KeyboardInterrupt, the node is destroyed, open files are finished, the exit
    status is 0. Both are installed and unblocked here whatever the process inherited: a parent
    that ignores SIGINT (SIG_IGN survives exec, and Python then keeps it) or blocks it in the
    spawning thread (the mask survives exec too) would otherwise leave a node that no signal
    but SIGKILL stops."""
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})


def warm_up_kernels(node: Any) -> None:
    """Compile (or load) the simulator's kernels before ``node`` offers its services: in a fresh
    checkout that takes ~30 s, which a client's first request would otherwise wait out (and a
    30 s service timeout would not). A first compile says so before it starts, and how long
    it took once done."""
    if not kernels_cached():
        low, high = FIRST_COMPILE_S
        node.get_logger().info(
            f"compiling the simulator's kernels (first start in this checkout): about "
            f"{low}-{high} s on 2 cores; later starts load them in about a second")
    seconds = warm_up()
    if seconds > 1.0:
        node.get_logger().info(
            f"compiled the simulator's kernels in {seconds:.1f} s (cached for later runs)"
        )


def announce_ready(node: Any, *, serves: tuple[str, ...] = (), calls: tuple[str, ...] = (),
                   publishes: tuple[str, ...] = ()) -> None:
    """The node's one "ready" line: what it serves, calls and publishes (what a launch file or
    a test waits for)."""
    parts = [f"{verb} {', '.join(names)}" for verb, names in (
        ("serving", serves), ("calling", calls), ("publishing", publishes)) if names]
    node.get_logger().info("ready: " + "; ".join(parts))


def run_node(make_node: Callable[[], Any], args: list[str] | None, *, threads: int = 1) -> None:
    """Create the node after ``ros.init(args)`` and spin it (``threads`` > 1: a multi-threaded
    executor, for nodes whose callbacks wait on each other or serve concurrent clients).

    Ctrl-C or SIGTERM, also during the warm-up, ends it with status 0; a bad parameter ends it
    with one line on stderr and status 2, as a bad command-line argument would."""
    stop_on_sigterm()
    try:
        ros.init(args=args)
        node = make_node()
    except ros.STARTUP_ERRORS as exc:
        ros.try_shutdown()
        name = getattr(make_node, "__name__", "node").removesuffix("Node").lower()
        print(f"{name}: error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    except KeyboardInterrupt:
        ros.try_shutdown()
        return
    executor = (ros.MultiThreadedExecutor(num_threads=threads) if threads > 1
                else ros.SingleThreadedExecutor())
    executor.add_node(node)
    stopped = False
    try:
        executor.spin()
        stopped = True
    except KeyboardInterrupt:
        stopped = True
    finally:
        # callbacks under way get STOP_GRACE_S to return; a longer one (an optimisation, a
        # study's points) must not keep a stopped node alive: the process ends without it
        stopping = threading.Thread(target=executor.shutdown, daemon=True)
        stopping.start()
        stopping.join(STOP_GRACE_S)
        if stopping.is_alive():
            kill_work = getattr(node, "kill_work", None)
            if kill_work is not None:  # (the processes it started: a compile)
                kill_work()
            _exit_now()
        # the node's own clean-up (a recorder finishes its file) gets TEARDOWN_S; then, on a
        # stop (not an error, which must show), the process ends without the interpreter's
        # finalisation: the middleware's threads and objects met there could hold it up
        errors: list[BaseException] = []
        teardown = threading.Thread(target=_teardown, args=(node, errors), daemon=True)
        teardown.start()
        teardown.join(TEARDOWN_S)
        if stopped or teardown.is_alive():
            _exit_now(1 if errors else 0)  # (the thread printed an error's traceback)


def _teardown(node: Any, errors: list[BaseException]) -> None:
    try:
        node.destroy_node()
        ros.try_shutdown()
    except BaseException as exc:
        errors.append(exc)
        raise


def _exit_now(status: int = 0) -> None:
    """End the process with ``status`` at once, the standard streams flushed."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)
