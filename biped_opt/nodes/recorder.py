"""``recorder`` node: records sweeps through the graph into MCAP files.

A sweep is (maneuver, theta0 range, count, fixed-input or optimal, output path). For every angle of
the grid (which always holds th0 = 0) the recorder

1. asks the optimiser (``/biped/optimal_policy``) for the optimal policy, when ``optimal``;
2. asks the simulator (``/biped/simulate``, real_time_factor 0) to run the maneuver with those
   inputs (the paper's fixed inputs otherwise); the reply carries every state sample;
3. writes the samples on ``/biped/state``, the contact modes on ``/biped/contact_mode`` (stamped at
   the exact event times) and a SweepPoint on ``/biped/sweep`` to the MCAP file, and publishes the
   SweepPoint live on ``/biped/sweep``.

Samples come from the service reply, not the best-effort state topic, so a slow or lossy
subscription never costs the file a sample. Log times are simulation times offset by each sweep
point's start, so the file replays in order. The file is finished when the sweep ends, when the
node is destroyed and on SIGINT/SIGTERM (see :func:`main`).

Parameters: ``maneuver``, ``theta0_min``, ``theta0_max``, ``num``, ``optimal``, ``output``
(path of the .mcap), ``fixed_inputs`` ([u1, u2, u12] for fixed-input sweeps; empty: the paper's),
``autostart`` (record the parameters' sweep at start-up), ``service_timeout`` [s], ``system``,
``problem``, ``scene`` (also write ``/clock``, ``/tf``, the markers and ``/robot_description``,
ROS.md Sec. 6; default true) and ``scene_rate_hz`` (how many of a trajectory's samples per unit
of simulation time carry them, besides every event and the last sample: default 50, a smooth
view at a quarter of the state samples' cost; 0: every sample).

**Other systems.** With ``system`` set (as the simulator's: a library name or a system file;
``""`` = the biped) the recorder takes the system's description from the simulator's latched
``/biped/system_info``, sweeps the maneuver's s over [theta0_min, theta0_max] with fixed inputs
(the system's declared order; zeros by default) and writes ``/biped/system_state``, the
description (``/biped/system_info`` and the ``biped_opt.system`` metadata record) and one
SweepPoint per s (theta0 = s, policy = the inputs, value NaN: no cost is defined, the contact
modes as bit masks, which SweepPoint holds for systems of up to 8 constraints). An optimal sweep
of such a system asks the optimiser for ``problem`` (one the system declares or a problem file;
``""``: the one named like the maneuver) at every s and simulates its optimal inputs; its
SweepPoints hold the decisions (policy), the optimal value and ``optimal = true``, and the
``biped_opt.sweep`` metadata record the problem (``problem``: the problem file's mapping as
JSON, :meth:`~biped_opt.control.problems.Problem.as_dict`).
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from biped_opt import ros
from biped_opt.errors import (
    BipedOptError,
    InvalidInputError,
    InvalidParameterError,
    SimulationError,
)
from biped_opt.nodes import convert
from biped_opt.nodes.compiler import BUSY, COMPILE_TIMEOUT_S
from biped_opt.nodes.run import announce_ready, run_node
from biped_opt.nodes.simulator import BIPED, SYSTEM_INFO_QOS
from biped_opt.nodes.sources import name_of
from biped_opt.paper.biped import FIXED_INPUTS, parse_maneuver
from biped_opt.paper.problems import OptimalControlProblem, get_problem
from biped_opt.piecewise import theta_grid
from biped_opt.record import SweepWriter
from biped_opt.record.scene import SceneMessages
from biped_opt.record.writer import BIPED_TOPICS, SYSTEM_TOPICS
from biped_opt.ros.interfaces import load_interfaces

if TYPE_CHECKING:  # the systems' modules (SymPy) load only where a system is used
    from biped_opt.control.problems import Problem

__all__ = ["RecorderNode", "SweepRequest", "SweepSummary", "main"]

#: pause between two sweep points on the log-time axis [s]
GAP = 0.5
#: SweepPoint.mode_sequence is uint8[]: the masks of at most this many constraints fit
MAX_RECORDED_CONSTRAINTS = 8


#: samples per unit of simulation time that carry the scene in a recording (the parameter's
#: default; each scene message costs the recording about as much as a state message)
SCENE_RATE_HZ = 50.0


@dataclass(frozen=True)
class SweepRequest:
    maneuver: str
    theta0_min: float
    theta0_max: float
    num: int
    optimal: bool
    output: Path
    fixed_inputs: tuple[float, ...] = ()
    #: the system the simulator serves: "" (or "biped") the biped, else its library name or
    #: file (theta0_min/theta0_max then bound the maneuver's s)
    system: str = ""
    #: an optimal sweep's problem on another system: one it declares or a problem file ("":
    #: the one named like the maneuver)
    problem: str = ""

    @property
    def biped(self) -> bool:
        return self.system.strip() in BIPED

    def validated(self) -> SweepRequest:
        """Checks what can be checked without the system's description (all of it for the
        biped; :meth:`validated_for` checks the rest for another system)."""
        if self.biped:
            maneuver = convert.request_maneuver(self.maneuver)
            for name in ("theta0_min", "theta0_max"):
                convert.request_theta0(maneuver, getattr(self, name))
            if len(self.fixed_inputs) > 3:
                raise InvalidInputError(
                    f"fixed_inputs: at most 3 values (u1, u2, u12), got {len(self.fixed_inputs)}")
            if self.problem.strip():
                raise InvalidInputError(
                    "problem: the biped's optimal sweeps solve the optimiser's problems (its "
                    "parameters); a problem is given for another system")
        else:
            for name in ("theta0_min", "theta0_max"):
                if not convert.finite(getattr(self, name)):
                    raise InvalidInputError(f"{name} must be finite, got {getattr(self, name)}")
        if self.problem.strip() and not self.optimal:
            raise InvalidInputError("problem: given for a fixed-input sweep (optimal is false)")
        if not self.theta0_min < self.theta0_max:
            raise InvalidInputError("theta0_min must be below theta0_max")
        if not 2 <= int(self.num) <= 100_000:
            raise InvalidInputError(f"num must be between 2 and 100000, got {self.num}")
        return self

    def validated_for(self, info: dict[str, Any]) -> SweepRequest:
        """The checks that need the served system's description (SystemInfo's fields)."""
        self.validated()
        if self.system.strip() not in (info["system"], info["source"]):
            raise InvalidInputError(
                f"system: the simulator serves {info['source']!r}, not {self.system!r}")
        if self.maneuver not in info["maneuvers"]:
            raise InvalidInputError(
                f"maneuver: {info['system']} has no maneuver {self.maneuver!r} (maneuvers: "
                f"{', '.join(info['maneuvers']) or 'none'})")
        if len(self.fixed_inputs) > len(info["inputs"]):
            raise InvalidInputError(
                f"fixed_inputs: at most {len(info['inputs'])} values "
                f"({', '.join(info['inputs']) or 'none'}), got {len(self.fixed_inputs)}")
        if len(info["constraints"]) > MAX_RECORDED_CONSTRAINTS:
            raise InvalidInputError(
                f"system: {info['system']} has {len(info['constraints'])} constraints; a "
                f"recording's SweepPoint holds the contact modes of at most "
                f"{MAX_RECORDED_CONSTRAINTS}")
        return self

    def system_problem(self, info: dict[str, Any]) -> Problem:
        """An optimal sweep's problem on the served system (SystemInfo's fields)."""
        problem = convert.request_problem(self.system.strip(), self.problem.strip(),
                                          self.maneuver)
        if problem.facts.name != info["system"]:
            raise InvalidInputError(f"problem: {problem.name} is a problem on "
                                    f"{problem.facts.name}, not on {info['system']}")
        return problem


@dataclass(frozen=True)
class SweepSummary:
    path: Path
    points: int  #: angles in the sweep's grid
    failed: int
    counts: dict[str, int]
    #: angles recorded: ``points`` unless :meth:`RecorderNode.stop` ended the sweep early
    recorded: int = 0

    @property
    def stopped(self) -> bool:
        return self.recorded < self.points


class RecorderNode(ros.Node):
    """Records sweeps (see the module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        # what close() needs exists first: a bad parameter below fails the construction and
        # the context then destroys the half-made node
        self._stop = threading.Event()
        self._writer: SweepWriter | None = None
        self._writer_lock = threading.Lock()
        super().__init__("recorder", **kwargs)
        self.declare_parameter("maneuver", "touchdown")
        self.declare_parameter("theta0_min", -0.2)
        self.declare_parameter("theta0_max", 0.2)
        self.declare_parameter("num", 41)
        self.declare_parameter("optimal", False)
        self.declare_parameter("output", "out/sweep.mcap")
        self.declare_parameter("fixed_inputs", [0.0])
        self.declare_parameter("autostart", False)
        self.declare_parameter("service_timeout", 30.0)
        self.declare_parameter("scene", True)
        self.declare_parameter("scene_rate_hz", SCENE_RATE_HZ)
        self.declare_parameter("system", "")
        self.declare_parameter("problem", "")
        group = ros.ReentrantCallbackGroup()
        self._optimiser = self.create_client(
            ros.srvs.OptimalPolicy, "/biped/optimal_policy", callback_group=group)
        self._simulator = self.create_client(
            ros.srvs.Simulate, "/biped/simulate", callback_group=group)
        self._sweep_pub = self.create_publisher(ros.msgs.SweepPoint, "/biped/sweep", 10)
        self._system_info: Any = None
        self._system_info_seen = threading.Condition()
        self.create_subscription(ros.msgs.SystemInfo, "/biped/system_info",
                                 self._on_system_info, SYSTEM_INFO_QOS, callback_group=group)
        self.finished = threading.Event()
        self.last_summary: SweepSummary | None = None
        self.error: BaseException | None = None
        autostart = bool(self.get_parameter("autostart").value)
        try:  # (a sweep the parameters cannot give stops the node, autostart or not: status 2)
            self.request_from_parameters().validated()
        except BipedOptError as exc:
            raise InvalidParameterError(f"cannot record from the parameters: {exc}") from None
        announce_ready(self, calls=("/biped/optimal_policy", "/biped/simulate"),
                       publishes=("/biped/sweep",))
        if autostart:
            threading.Thread(target=self._record_from_parameters, daemon=True).start()

    # -- parameters -> request ----------------------------------------------------------
    def request_from_parameters(self) -> SweepRequest:
        g = self.get_parameter
        fixed = tuple(float(v) for v in g("fixed_inputs").value)
        return SweepRequest(
            maneuver=str(g("maneuver").value),
            theta0_min=float(g("theta0_min").value),
            theta0_max=float(g("theta0_max").value),
            num=int(g("num").value),
            optimal=bool(g("optimal").value),
            output=Path(str(g("output").value)),
            fixed_inputs=fixed if any(fixed) else (),
            system=str(g("system").value),
            problem=str(g("problem").value),
        )

    def _on_system_info(self, msg: Any) -> None:
        with self._system_info_seen:
            self._system_info = convert.message_fields(msg, convert.SYSTEM_INFO_FIELDS)
            self._system_info_seen.notify_all()

    def served_system(self, timeout: float) -> dict[str, Any]:
        """The simulator's SystemInfo (latched), waiting up to ``timeout`` [s] for it."""
        with self._system_info_seen:
            if not self._system_info_seen.wait_for(lambda: self._system_info is not None,
                                                   timeout):
                raise SimulationError(
                    f"no /biped/system_info within {timeout} s: is a simulator serving a "
                    "system (its parameter system) running?")
            return dict(self._system_info)

    def _record_from_parameters(self) -> None:
        try:
            self.record(self.request_from_parameters())
        except BaseException as exc:  # reported through .error and the log
            self.error = exc
            self.get_logger().error(f"sweep failed: {exc}")
        finally:
            self.finished.set()

    # -- service calls from a worker thread ------------------------------------------------
    def _call(self, client: Any, request: Any) -> Any:
        """Call and wait up to ``service_timeout``; no answer fails the sweep with a clear error.

        A request is sent once: requests and replies travel on reliable DDS and neither side's
        reader drops one (:mod:`biped_opt.ros.dds.services`), so a missing reply means the
        server is gone or stuck, which a second request would not mend."""
        timeout = float(self.get_parameter("service_timeout").value)
        if not client.wait_for_service(timeout_sec=timeout):
            raise SimulationError(f"service {client.srv_name} is not available")
        done = threading.Event()
        future = client.call_async(request)
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(timeout):
            client.remove_pending_request(future)
            raise SimulationError(f"no reply from {client.srv_name} within {timeout} s")
        return future.result()

    # -- the sweep --------------------------------------------------------------------------
    def record(self, req: SweepRequest) -> SweepSummary:
        """Record one sweep to ``req.output`` (blocking; call from a thread other than the one
        spinning this node)."""
        if not req.biped:
            return self._record_system(req)
        req = req.validated()
        with self._system_info_seen:
            served = self._system_info
        if served is not None:
            raise SimulationError(f"the simulator serves {served['system']}: give the recorder "
                                  "the same system parameter")
        maneuver = parse_maneuver(req.maneuver).value
        grid = theta_grid(req.theta0_min, req.theta0_max, int(req.num))
        fixed = req.fixed_inputs or FIXED_INPUTS[maneuver]
        # a fixed-input point's value is the cost of the maneuver's default problem (Eqs. (14),
        # (15)) at those inputs; an optimal point's comes from the optimiser
        problem = get_problem(maneuver)
        metadata = {
            "maneuver": maneuver, "theta0_min": req.theta0_min, "theta0_max": req.theta0_max,
            "num": grid.size, "optimal": req.optimal,
            "fixed_inputs": "" if req.optimal else json.dumps(list(fixed)),
            "cost": json.dumps(problem.describe()),
        }
        scene = self._scene("biped")
        writer = SweepWriter(req.output, metadata={k: str(v) for k, v in metadata.items()},
                             topics=BIPED_TOPICS + (tuple(scene.topics) if scene else ()))
        return self._sweep(writer, req, grid, lambda th, offset: self._record_point(
            writer, maneuver, th, req.optimal, fixed, problem, offset, scene), scene)

    def _record_system(self, req: SweepRequest) -> SweepSummary:
        """A fixed-input or optimal sweep over s of the non-biped system the simulator
        serves."""
        req.validated()
        info = self.served_system(float(self.get_parameter("service_timeout").value))
        req.validated_for(info)
        grid = theta_grid(req.theta0_min, req.theta0_max, int(req.num))
        inputs = [0.0] * len(info["inputs"])
        inputs[: len(req.fixed_inputs)] = req.fixed_inputs
        metadata = {
            "system": info["system"], "maneuver": req.maneuver, "theta0_min": req.theta0_min,
            "theta0_max": req.theta0_max, "num": grid.size, "optimal": req.optimal,
            "fixed_inputs": "" if req.optimal else json.dumps(inputs),
        }
        if req.optimal:
            metadata["problem"] = json.dumps(req.system_problem(info).as_dict())
        scene = self._scene(req.system.strip())
        writer = SweepWriter(req.output, metadata={k: str(v) for k, v in metadata.items()},
                             system=info,
                             topics=SYSTEM_TOPICS + (tuple(scene.topics) if scene else ()))
        ndof = len(info["coordinates"])
        return self._sweep(writer, req, grid, lambda s, offset: self._record_system_point(
            writer, req, s, inputs, ndof, offset, scene), scene)

    def _scene(self, spec: str) -> SceneMessages | None:
        """What draws the recorded system (its compiled scene, loaded from the cache the
        simulator filled), or None when it declares no looks or cannot be loaded (then the
        recording has no scene topics, and the log says why)."""
        from biped_opt.simulation.compiled import compiled_with

        if self.get_parameter("scene").value is not True:
            return None
        rate = self.get_parameter("scene_rate_hz").value
        if isinstance(rate, bool) or not isinstance(rate, (int, float)) \
                or not convert.finite(rate) or rate < 0:
            raise InvalidParameterError(
                f"scene_rate_hz must be a number >= 0 (0: every sample), got {rate!r}")
        try:
            compiled = compiled_with(spec)
            scene = compiled.scene
        except Exception as exc:  # the recording goes on without /tf and markers
            self.get_logger().warning(f"no /tf and markers for {spec!r}: "
                                      f"{type(exc).__name__}: {exc}")
            return None
        if scene.empty:
            return None
        return SceneMessages(load_interfaces().typestore, scene,
                             list(compiled.parameters.values()), len(compiled.coordinates),
                             float(rate))

    def _sweep(self, writer: SweepWriter, req: SweepRequest, grid: Any,
               record_point: Callable[[float, int], tuple[bool, float]],
               scene: SceneMessages | None = None) -> SweepSummary:
        """Record every point of ``grid`` (``record_point(angle, log-time offset)`` -> (reached
        its end, final time)) into ``writer`` and finish it; the system's URDF first when it
        is drawn (``scene``)."""
        if scene is not None:
            writer.write_robot_description(scene)
        with self._writer_lock:
            self._writer = writer
        failed = 0
        offset = 0
        recorded = 0
        try:
            for k, th in enumerate(grid):
                if self._stop.is_set():
                    break
                ok, t_final = record_point(float(th), offset)
                failed += not ok
                recorded += 1
                offset += int(round((t_final + GAP) * convert.NS))
                self.get_logger().debug(f"{req.maneuver} {k + 1}/{grid.size} at {th:+.4f}")
        finally:
            writer.finish()
            with self._writer_lock:
                self._writer = None
        summary = SweepSummary(path=req.output, points=grid.size, failed=failed,
                               counts=dict(writer.counts), recorded=recorded)
        what = req.maneuver if req.biped else f"{req.system} {req.maneuver}"
        self.get_logger().info(
            f"recorded {recorded} of {grid.size} {what} points to {req.output}: "
            + ", ".join(f"{topic} {n}" for topic, n in summary.counts.items()))
        self.last_summary = summary
        return summary

    def _record_point(self, writer: SweepWriter, maneuver: str, th: float, optimal: bool,
                      fixed: tuple[float, ...], problem: OptimalControlProblem, offset: int,
                      scene: SceneMessages | None = None) -> tuple[bool, float]:
        if optimal:
            q = ros.srvs.OptimalPolicy.Request()
            q.maneuver, q.theta0 = maneuver, th
            reply = self._call(self._optimiser, q)
            if not reply.success:
                raise SimulationError(f"optimiser failed at th0 = {th}: {reply.message}")
            policy = [float(v) for v in np.asarray(reply.policy)]
            value = float(reply.value)
            inputs = np.asarray(reply.inputs, dtype=float)
        else:
            inputs = np.zeros(3)
            inputs[: len(fixed)] = fixed
            policy = [float(v) for v in inputs]
        q = ros.srvs.Simulate.Request()
        q.maneuver, q.theta0, q.inputs, q.real_time_factor = maneuver, th, inputs.tolist(), 0.0
        reply = self._call(self._simulator, q)
        if not reply.states and not reply.success:
            raise SimulationError(f"simulator failed at th0 = {th}: {reply.message}")
        if reply.system_states:
            raise SimulationError("the simulator serves another system than the biped: give "
                                  "the recorder the same system parameter")
        samples = np.array(
            [[s.t, *np.asarray(s.q), *np.asarray(s.qdot), s.contact_mode,
              *np.asarray(s.contact_force)] for s in reply.states], dtype=float,
        )
        writer.write_states(maneuver=maneuver, theta0=th, samples=samples, stamp_offset_ns=offset)
        if scene is not None:
            writer.write_scene(scene, samples=samples, stamp_offset_ns=offset)
        modes = [int(m) for m in np.asarray(reply.mode_sequence)]
        times = [0.0, *[float(t) for t in np.asarray(reply.event_times)]]
        for t, mode in zip(times, modes):
            ns = offset + int(round(t * convert.NS))
            writer.write("/biped/contact_mode", {"header": _header_fields(ns), "mode": mode}, ns)
        if not optimal:
            value = float(problem.cost(reply.outcome, inputs))
        point = {
            "header": _header_fields(offset), "maneuver": maneuver, "theta0": th,
            "optimal": optimal, "policy": policy, "value": value,
            "outcome": float(reply.outcome), "t_final": float(reply.t_final),
            "mode_sequence": modes, "event_times": times[1:],
        }
        return self._write_point(writer, point, offset, reply)

    def _record_system_point(self, writer: SweepWriter, req: SweepRequest, s: float,
                             inputs: list[float], ndof: int, offset: int,
                             scene: SceneMessages | None = None) -> tuple[bool, float]:
        maneuver = req.maneuver
        policy, value = list(inputs), float("nan")
        if req.optimal:
            ask = ros.srvs.OptimalPolicy.Request()
            ask.maneuver, ask.theta0 = maneuver, s
            # names, as any request gives them (a file: its stem, in the optimiser's
            # system_paths); a system being compiled there is asked for again
            ask.system, ask.problem = name_of(req.system.strip()), name_of(req.problem.strip())
            deadline = time.monotonic() + COMPILE_TIMEOUT_S
            answer = self._call(self._optimiser, ask)
            while not answer.success and answer.message.startswith(BUSY) \
                    and time.monotonic() < deadline:
                time.sleep(1.0)
                answer = self._call(self._optimiser, ask)
            if not answer.success:
                raise SimulationError(f"optimiser failed at s = {s}: {answer.message}")
            inputs = [float(v) for v in np.asarray(answer.system_inputs)]
            policy = [float(v) for v in np.asarray(answer.policy)]
            value = float(answer.value)
        q = ros.srvs.Simulate.Request()
        q.maneuver, q.theta0, q.inputs, q.real_time_factor = maneuver, s, list(inputs), 0.0
        reply = self._call(self._simulator, q)
        if not reply.system_states:
            raise SimulationError(f"simulator failed at s = {s}: {reply.message}" if
                                  not reply.success else "the simulator serves the biped, not "
                                  "another system: give it the recorder's system parameter")
        samples = np.array(
            [[m.t, *np.asarray(m.q), *np.asarray(m.qdot), m.contact_mode,
              *np.asarray(m.contact_force)] for m in reply.system_states], dtype=float)
        writer.write_system_states(maneuver=maneuver, s=s, samples=samples, ndof=ndof,
                                   stamp_offset_ns=offset)
        if scene is not None:
            writer.write_scene(scene, samples=samples, stamp_offset_ns=offset)
        point = {
            "header": _header_fields(offset, writer.system["system"]), "maneuver": maneuver,
            "theta0": s, "optimal": req.optimal, "policy": policy, "value": value,
            "outcome": float(reply.outcome), "t_final": float(reply.t_final),
            "mode_sequence": [int(m) for m in np.asarray(reply.contact_modes)],
            "event_times": [float(t) for t in np.asarray(reply.event_times)],
        }
        return self._write_point(writer, point, offset, reply)

    def _write_point(self, writer: SweepWriter, point: dict[str, Any], offset: int,
                     reply: Any) -> tuple[bool, float]:
        """The SweepPoint of one simulated point into the file, stamped at its end, and live."""
        end = offset + int(round(reply.t_final * convert.NS))
        writer.write("/biped/sweep", point, end)
        msg = ros.msgs.SweepPoint()
        msg.header = convert.header(offset, point["header"]["frame_id"])
        for name in ("maneuver", "theta0", "optimal", "policy", "value", "outcome", "t_final",
                     "mode_sequence", "event_times"):
            setattr(msg, name, point[name])
        self._sweep_pub.publish(msg)
        return bool(reply.success), float(reply.t_final)

    def stop(self) -> None:
        """Let a running :meth:`record` return after the point it is recording (safe to call
        from a signal handler: it only sets a flag; the recording thread finishes the file)."""
        self._stop.set()

    def close(self) -> None:
        """Stop after the current point and finish any open file."""
        self._stop.set()
        with self._writer_lock:
            writer = self._writer
        if writer is not None:
            writer.finish()

    def destroy_node(self) -> None:
        self.close()
        super().destroy_node()


def _header_fields(ns: int, frame_id: str = convert.FRAME_ID) -> dict[str, Any]:
    return {"stamp": {"sec": ns // convert.NS, "nanosec": ns % convert.NS},
            "frame_id": frame_id}


def main(args: list[str] | None = None) -> None:
    run_node(RecorderNode, args, threads=2)


if __name__ == "__main__":
    main()
