"""How well the live simulator keeps real time (ROS.md Sec. 8).

Starts the simulator node in this process on a domain of its own (the built-in backend, or
rclpy), plays the biped hopping from the touchdown maneuver's start with a constant command,
and measures, from the node's own clock against the wall clock:

- at ``real_time_factor`` 1: the factor achieved and the largest lag of the simulated time
  behind real time, sampled every 10 ms (what a ``use_sim_time`` controller sees);
- at ``real_time_factor`` 0 (as fast as the node goes): the factor achieved, i.e. how many times
  real time the live world can run with its publication;
- the reference in the same run: the same span integrated by the kernel alone
  (``CompiledSystem.advance`` in pieces of one tick, no ROS, no publication), as a factor of
  real time. The ratio of the two as-fast-as-possible factors is what the node's publication
  and bookkeeping cost.

    python bench/live_simulator.py [--seconds 3] [--domain-id 61]
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from pathlib import Path

os.environ.setdefault("ROS_LOCALHOST_ONLY", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from biped_opt import ros  # noqa: E402
from biped_opt.nodes.sim_control import PAUSED, PLAYING  # noqa: E402
from biped_opt.nodes.simulator import SimulatorNode  # noqa: E402
from biped_opt.paper.biped import compiled_biped  # noqa: E402

NS = 1_000_000_000
COMMAND = (2.0, 0.5, 0.0)


def kernel_factor(seconds: float, tick: float = 0.005) -> float:
    """Simulated seconds per wall second of the kernel alone over ``seconds`` of simulated
    time, in pieces of ``tick`` (the node's tick at factor 1), continuing after terminal
    events as the node does."""
    c = compiled_biped()
    y, mode = c.initial_state("touchdown", 0.1)
    start = time.perf_counter()
    for _ in range(round(seconds / tick)):
        rest = tick
        while True:
            tr = c.advance("touchdown", y, mode, COMMAND, rest, sample_dt=1 / 200)
            y, mode = tr.y_final, tr.mode_final
            if tr.status.name == "HORIZON":
                break
            if tr.status.name not in ("OK", "APEX_IN_CONTACT"):
                raise SystemExit(f"the reference failed: {tr.status.message}")
            rest -= tr.t_final
    return seconds / (time.perf_counter() - start)


def _start(node: SimulatorNode) -> None:
    """The world from its start, the command set, playing (under the node's lock)."""
    control = node.control
    with control.lock:
        control.reset(0xFF)
        control.command[:] = COMMAND
        control.state = PAUSED
        request = ros.sim_srvs.SetSimulationState.Request()
        request.state.state = PLAYING
        control._on_set_simulation_state(request, ros.sim_srvs.SetSimulationState.Response())


def play(node: SimulatorNode, factor: float, seconds: float) -> tuple[float, float, int]:
    """(factor achieved, largest lag [s of simulated time], restarts) over ``seconds`` of
    wall time. The hopping biped with a constant command meets a contact mode the model has no
    consistent continuation for after some seconds of simulated time (the world then pauses,
    saying why): the world starts again from its start, and the time simulated before counts."""
    control = node.control
    node.set_parameters([ros.Parameter("real_time_factor", value=factor)])
    _start(node)
    wall0, done_ns, restarts = time.monotonic(), 0, 0
    lag = 0.0
    while time.monotonic() - wall0 < seconds:
        time.sleep(0.01)
        with control.lock:
            if control.state != PLAYING:
                done_ns += node.sim_ns
                restarts += 1
                _start(node)
            elapsed = time.monotonic() - wall0
            simulated = (done_ns + node.sim_ns) / NS
        if factor > 0:
            lag = max(lag, elapsed * factor - simulated)
    with control.lock:
        achieved = (done_ns + node.sim_ns) / NS / (time.monotonic() - wall0)
        control.state = PAUSED
    return achieved, lag, restarts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--domain-id", type=int, default=61)
    args = parser.parse_args()
    context = ros.Context()
    ros.init(args=[], context=context, domain_id=args.domain_id)
    node = SimulatorNode(context=context, parameter_overrides=[
        ros.Parameter("autostart", value=False), ros.Parameter("maneuver", value="touchdown"),
        ros.Parameter("theta0", value=0.1)])
    executor = ros.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        reference = kernel_factor(args.seconds)
        real, lag, _ = play(node, 1.0, args.seconds)
        fast, _, restarts = play(node, 0.0, args.seconds)
    finally:
        executor.shutdown()
        node.destroy_node()
        ros.try_shutdown(context=context)
    print(f"backend {ros.BACKEND}, {args.seconds:g} s of wall time each")
    print(f"real_time_factor 1: achieved {real:.4f}, largest lag {lag * 1000:.1f} ms of "
          "simulated time")
    print(f"real_time_factor 0: achieved {fast:.2f} x real time (the node, publishing; "
          f"{restarts} restarts)")
    print(f"kernel alone, same ticks: {reference:.2f} x real time; the node's share: "
          f"{fast / reference:.3f} of the kernel's speed")


if __name__ == "__main__":
    main()
