"""The simulator node's ROS 2 Simulation Interfaces and its live simulation (ROS.md Sec. 8).

The services of the ``simulation_interfaces`` standard (2.1.0), under the node's private names
as Gazebo's ``gzserver`` offers them (``/simulator/get_simulation_state``...), and the
``SimulateSteps`` action, drive one *world* that holds at most one entity (the served system at
start-up, or one spawned later) with a state ``(y, contact mode)`` at the simulated time:

- **the entity**: the served system at start-up; ``SpawnEntity`` puts a library system or one
  in ``system_paths`` (by name, in ``uri``) or a robot's URDF text (``resource_string``, no
  file or mesh opened) into an empty world, compiled by the node's compiler thread (a first
  request answers ``busy: ...; retry``); ``DeleteEntity`` empties it.
- **states** (:data:`STOPPED`, :data:`PLAYING`, :data:`PAUSED`): the node starts stopped. Playing
  integrates at ``real_time_factor`` (0: as fast as the machine goes) with the last valid command
  of ``/biped/command``; paused holds; stopping resets (time, state, spawned entities), as the
  standard defines it. Setting the state it is in answers ``ALREADY_IN_TARGET_STATE``; quitting
  is not offered (``RESULT_FEATURE_UNSUPPORTED``); the world states (no world, loading) are not
  targets (``INCORRECT_TRANSITION``).
- **a step** is ``step_size`` (parameter) of simulated time integrated from the current state with
  the current command: the compiled kernel locates every contact event inside it exactly, as in
  ``/biped/simulate``, so N steps end where one simulation to the same time ends (to the
  integrator's tolerance). ``StepSimulation`` and ``SimulateSteps`` step only while paused.
- **the command** (``std_msgs/Float64MultiArray`` on ``/biped/command``): the entity's inputs in
  their declared order, as ros2_control's forward command controller takes them. A message of
  the wrong length or with a value that is not finite is dropped (a warning, one a second at
  most) and the last valid command is held; a reset or a new entity holds zeros.
- **publication**: the state topics of the node (``/biped/state`` or ``/biped/system_state``),
  ``/biped/contact_mode`` (the biped: every change, stamped with the event's exact time) and the
  scene (``/clock``, ``/tf``, markers: whatever :class:`SceneMessages` gives) for every step,
  thinned to ``publish_rate_hz`` samples per unit of simulated time (events always shown); a
  sample whose stamp was shown already (a step's first, equal to the previous step's last) is
  never shown again. ``/clock`` goes out ``clock_rate_hz`` times a second when nothing else
  publishes it (stopped, paused, idle), at the current time; it goes back only on a reset
  (to 0).
- **real time**: a playing world that falls behind ``real_time_factor`` by more than
  ``max_lag`` seconds of simulated time drops the backlog instead of bursting to catch up,
  says so (a warning at most every 5 s) and reports the factor achieved on ``/diagnostics``
  (``diagnostic_msgs/DiagnosticArray``, once a second while playing).
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import re
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from biped_opt import ros
from biped_opt.errors import BipedOptError, InvalidInputError, InvalidParameterError, quoted
from biped_opt.nodes import convert
from biped_opt.nodes.compiler import COMPILE_TIMEOUT_S, Busy, Compiler
from biped_opt.nodes.parameters import float_parameter, int_parameter
from biped_opt.nodes.refusals import LOG_THROTTLE_S, failure_message, public
from biped_opt.nodes.sources import check_name, declare_request_limits
from biped_opt.record.scene import SceneMessages

__all__ = ["SimControl", "Entity", "STOPPED", "PLAYING", "PAUSED", "COMMAND_TOPIC",
           "SERVICES", "base_pose", "set_base", "name_filter"]

NS = convert.NS
STOPPED, PLAYING, PAUSED = 0, 1, 2
_STATE_NAMES = {STOPPED: "stopped", PLAYING: "playing", PAUSED: "paused"}
COMMAND_TOPIC = "/biped/command"
#: service name (the node's private namespace, as Gazebo's gzserver) -> type name
SERVICES = {
    "get_simulator_features": "GetSimulatorFeatures",
    "get_simulation_state": "GetSimulationState",
    "set_simulation_state": "SetSimulationState",
    "reset_simulation": "ResetSimulation",
    "step_simulation": "StepSimulation",
    "get_entities": "GetEntities",
    "get_entity_state": "GetEntityState",
    "set_entity_state": "SetEntityState",
    "delete_entity": "DeleteEntity",
    "spawn_entity": "SpawnEntity",
}
#: a constraint of a state set is on its surface within SURFACE_TOL, at rest within REST_TOL
SURFACE_TOL, REST_TOL = 1e-9, 1e-6
#: a state set must be within this of a unit quaternion, of the x-z plane (planar systems)
QUATERNION_TOL, PLANE_TOL = 1e-6, 1e-9
#: the floating base's coordinates (biped_opt.systems.urdf.BASE) and a planar base's
FLOATING = ("base_x", "base_y", "base_z", "base_roll", "base_pitch", "base_yaw")
PLANAR = ("x", "z", "th")
#: the most steps of a SimulateSteps goal (a goal ends on a cancel, a stop or a reset too)
MAX_GOAL_STEPS = 1_000_000_000
#: a step's integration goes on after the maneuver's terminal event or event budget at most
#: this often
MAX_PIECES = 10_000
#: wall time a tick of a world playing as fast as possible integrates for [s] (then the node
#: serves what waits)
FAST_TICK_S = 0.004
#: at most one real-time warning this often [s]
LAG_LOG_S = 5.0


class Refused(BipedOptError, ValueError):
    """A request the standard answers with ``code`` (a Result or a service's own code)."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


#: the longest name filter, and the most ``.*`` in one (a pattern a peer sends is matched
#: here: these keep its backtracking to a few thousand steps on a 64-character name)
MAX_FILTER, MAX_WILDCARDS = 256, 2
_FILTER = re.compile(r"\^?(?:[A-Za-z0-9_/-]|\.\*|\.)*\$?")


def name_filter(text: str) -> re.Pattern[str] | None:
    """GetEntities' filter (a POSIX extended regular expression) if it keeps to the subset
    this node matches safely: name characters, ``.``, ``.*``, ``^`` first and ``$`` last;
    else None."""
    if len(text) > MAX_FILTER or not _FILTER.fullmatch(text) or \
            text.count(".*") > MAX_WILDCARDS:
        return None
    return re.compile(text)


# -- the base's pose and twist ------------------------------------------------------------------

def _quaternion_rpy(roll: float, pitch: float, yaw: float) -> tuple[float, ...]:
    """(x, y, z, w) of R = Rz(yaw) Ry(pitch) Rx(roll) (URDF's fixed-axis rpy)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def _rpy_quaternion(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def _rates_matrix(pitch: float, yaw: float) -> np.ndarray:
    """E with omega (world frame) = E @ (roll', pitch', yaw') for R = Rz Ry Rx."""
    cp, sp, cy, sy = math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    return np.array([[cy * cp, -sy, 0.0], [sy * cp, cy, 0.0], [-sp, 0.0, 1.0]])


def base_kind(coordinates: tuple[str, ...]) -> str:
    """``floating`` (base_x..base_yaw), ``planar`` (x, z, th: a base in the x-z plane whose
    frame has pitch -th) or ``none``."""
    if all(c in coordinates for c in FLOATING):
        return "floating"
    if all(c in coordinates for c in PLANAR):
        return "planar"
    return "none"


def base_pose(coordinates: tuple[str, ...], y: np.ndarray
              ) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...],
                         tuple[float, ...]]:
    """(position, quaternion xyzw, linear velocity, angular velocity), world frame, of the
    base of a state ``y`` = (q, q')."""
    d = len(coordinates)
    kind = base_kind(coordinates)
    if kind == "none":
        raise Refused(0, "the entity has no base (neither base_x..base_yaw nor x, z, th "
                         "coordinates): its state is its coordinates, on its state topic")
    i = {c: coordinates.index(c) for c in (FLOATING if kind == "floating" else PLANAR)}
    if kind == "planar":
        th, dth = y[i["th"]], y[d + i["th"]]
        return ((y[i["x"]], 0.0, y[i["z"]]), (0.0, math.sin(-th / 2), 0.0, math.cos(-th / 2)),
                (y[d + i["x"]], 0.0, y[d + i["z"]]), (0.0, -dth, 0.0))
    pos = tuple(float(y[i[c]]) for c in FLOATING[:3])
    roll, pitch, yaw = (float(y[i[c]]) for c in FLOATING[3:])
    rates = np.array([y[d + i[c]] for c in FLOATING[3:]])
    omega = _rates_matrix(pitch, yaw) @ rates
    return (pos, _quaternion_rpy(roll, pitch, yaw),
            tuple(float(y[d + i[c]]) for c in FLOATING[:3]), tuple(float(v) for v in omega))


def _finite(*values: float) -> bool:
    return all(isinstance(v, float | int) and math.isfinite(v) for v in values)


def set_base(coordinates: tuple[str, ...], y: np.ndarray, pose: Any = None, twist: Any = None
             ) -> np.ndarray:
    """``y`` with the base's pose (geometry_msgs/Pose) and/or twist (geometry_msgs/Twist, world
    frame) set; :class:`Refused` with SetEntityState's code for what cannot be set."""
    d = len(coordinates)
    kind = base_kind(coordinates)
    if kind == "none":
        base_pose(coordinates, y)  # (refuses with the reason)
    out = np.array(y, dtype=np.float64)
    i = {c: coordinates.index(c) for c in (FLOATING if kind == "floating" else PLANAR)}
    if pose is not None:
        p, q = pose.position, pose.orientation
        quat = (q.x, q.y, q.z, q.w)
        if not _finite(p.x, p.y, p.z, *quat):
            raise Refused(101, "pose: every number must be finite")
        norm = math.sqrt(sum(v * v for v in quat))
        if abs(norm - 1.0) > QUATERNION_TOL:
            raise Refused(101, f"pose: the orientation is not a unit quaternion (norm {norm:g})")
        qx, qy, qz, qw = (v / norm for v in quat)
        if kind == "planar":
            if abs(p.y) > PLANE_TOL or abs(qx) > PLANE_TOL or abs(qz) > PLANE_TOL:
                raise Refused(101, "pose: this entity moves in the x-z plane: position y must be "
                                   "0 and the orientation a rotation about y")
            out[i["x"]], out[i["z"]] = p.x, p.z
            out[i["th"]] = -2.0 * math.atan2(qy, qw)
        else:
            out[[i[c] for c in FLOATING[:3]]] = (p.x, p.y, p.z)
            out[[i[c] for c in FLOATING[3:]]] = _rpy_quaternion(qx, qy, qz, qw)
    if twist is not None:
        lin, ang = twist.linear, twist.angular
        if not _finite(lin.x, lin.y, lin.z, ang.x, ang.y, ang.z):
            raise Refused(4, "twist: every number must be finite")
        if kind == "planar":
            if abs(lin.y) > PLANE_TOL or abs(ang.x) > PLANE_TOL or abs(ang.z) > PLANE_TOL:
                raise Refused(4, "twist: this entity moves in the x-z plane: linear y and "
                                 "angular x, z must be 0")
            out[d + i["x"]], out[d + i["z"]], out[d + i["th"]] = lin.x, lin.z, -ang.y
        else:
            out[[d + i[c] for c in FLOATING[:3]]] = (lin.x, lin.y, lin.z)
            pitch, yaw = out[i["base_pitch"]], out[i["base_yaw"]]
            if abs(math.cos(pitch)) < 1e-6:
                raise Refused(4, "twist: the base's pitch is at +-90 degrees, where its roll-"
                                 "pitch-yaw rates do not follow from an angular velocity")
            out[[d + i[c] for c in FLOATING[3:]]] = np.linalg.solve(
                _rates_matrix(pitch, yaw), [ang.x, ang.y, ang.z])
    return out


# -- the world ----------------------------------------------------------------------------------

@dataclass
class Entity:
    """The world's one entity: a compiled system, the maneuver whose guards and budget its
    steps use, its state and contact mode, and how it looks."""

    name: str
    compiled: Any  #: a CompiledSystem
    maneuver: str
    s: float
    y: np.ndarray
    mode: int
    spawned: bool
    scene: SceneMessages | None
    biped: bool  #: published as BipedState (the node's biped), else as SystemState

    def restart(self) -> None:
        self.y, self.mode = self.compiled.initial_state(self.maneuver, self.s)


class SimControl:
    """The services, the command topic and the live loop of one simulator node."""

    def __init__(self, node: Any, entity: Entity | None) -> None:
        self.node = node
        node.declare_parameter("step_size", 0.001)
        node.declare_parameter("clock_rate_hz", 20.0)
        node.declare_parameter("max_steps", 2000)
        node.declare_parameter("max_lag", 0.25)
        node.declare_parameter("max_resource_bytes", 1_000_000)
        node.declare_parameter("compile_queue", 2)
        node.declare_parameter("compile_timeout", COMPILE_TIMEOUT_S)
        self.sources, _, _ = declare_request_limits(node)
        node.private_paths = self.sources.system_paths
        self.max_resource_bytes = int_parameter(node, "max_resource_bytes", 1)
        self.compiler = Compiler(node.get_logger(),
                                 queue_size=int_parameter(node, "compile_queue", 0),
                                 timeout=float_parameter(node, "compile_timeout"))
        self.step_size = float_parameter(node, "step_size")
        if not 1e-6 <= self.step_size <= 1.0:
            raise InvalidParameterError(f"step_size must be in [1e-6, 1] (simulated time), "
                                        f"got {self.step_size}")
        self.max_steps = int_parameter(node, "max_steps", 1)
        self.max_lag = float_parameter(node, "max_lag")
        clock_rate = float_parameter(node, "clock_rate_hz")
        self.lock = threading.RLock()
        self.state = STOPPED
        self.initial = entity
        self.entity = entity
        self.command = self._zeros()
        self._wall0 = 0.0  # when play started (monotonic) and the simulated time then
        self._sim0_ns = 0
        self._lag_logged = -math.inf
        self._achieved: list[tuple[float, int]] = []
        self._last_mode: int | None = None
        msgs, srvs = ros.sim_msgs, ros.sim_srvs
        if msgs is None:
            raise InvalidParameterError(
                "the ROS 2 Simulation Interfaces need the simulation_interfaces package: "
                "install it (apt: ros-$ROS_DISTRO-simulation-interfaces) or use the built-in "
                "backend (BIPED_OPT_BACKEND=dds)")
        self.msgs, self.srvs = msgs, srvs
        self.services = [node.create_service(getattr(srvs, t), f"~/{name}",
                                             self._answer(getattr(self, f"_on_{name}")))
                         for name, t in SERVICES.items()]
        self._stepping = threading.Lock()  # one SimulateSteps goal at a time
        self.steps_action = ros.ActionServer(
            node, ros.sim_actions.SimulateSteps, "~/simulate_steps", self._simulate_steps,
            goal_callback=self._on_steps_goal,
            cancel_callback=lambda _handle: ros.CancelResponse.ACCEPT,
            callback_group=ros.ReentrantCallbackGroup())
        array = ros.message_type("std_msgs/msg/Float64MultiArray")
        self._command_sub = node.create_subscription(array, COMMAND_TOPIC, self._on_command, 10)
        self._clock_cls = ros.message_type("rosgraph_msgs/msg/Clock")
        self._clock_pub = node.scene_publisher("/clock")
        self._diag_cls = ros.message_type("diagnostic_msgs/msg/DiagnosticArray")
        self._diag_pub = None if self._diag_cls is None else node.create_publisher(
            self._diag_cls, "/diagnostics", 10)
        self._clock_timer = node.create_timer(1.0 / clock_rate, self._idle_clock)
        self._live_timer = node.create_timer(0.005, self._on_live_tick)
        self._diag_timer = node.create_timer(1.0, self._diagnostics)

    # -- helpers ---------------------------------------------------------------------------
    def _zeros(self) -> np.ndarray:
        n = len(self.entity.compiled.inputs) if self.entity is not None else 0
        return np.zeros(max(n, 1))

    def _answer(self, handler: Any) -> Any:
        """A service callback: the handler's answer; a refusal or a bug sets the Result."""
        def callback(request: Any, response: Any) -> Any:
            try:
                with self.lock:
                    handler(request, response)
                if hasattr(response, "result"):  # (GetSimulatorFeatures has none)
                    response.result.result = self.msgs.Result.RESULT_OK
            except Exception as exc:  # a refusal; or a bug, which costs one request
                if isinstance(exc, Refused):
                    code, message = exc.code, str(exc)
                    self.node.get_logger().warning(f"refused a simulation interface request: "
                                                   f"{message}",
                                                   throttle_duration_sec=LOG_THROTTLE_S)
                else:
                    code, message = (self.msgs.Result.RESULT_OPERATION_FAILED,
                                     f"internal error: {failure_message(exc)}")
                    self.node.get_logger().error(f"simulation interface request failed: "
                                                 f"{message}",
                                                 throttle_duration_sec=LOG_THROTTLE_S)
                if hasattr(response, "result"):
                    response.result.result = code
                    response.result.error_message = public(
                        message, getattr(self.node, "private_paths", ()))
            return response
        return callback

    def _need_entity(self, name: str | None = None) -> Entity:
        e = self.entity
        if e is None or (name is not None and name != e.name):
            have = f"the world holds {e.name!r}" if e is not None else "the world is empty"
            raise Refused(self.msgs.Result.RESULT_NOT_FOUND,
                          f"no entity {name!r} ({have})" if name is not None else have)
        return e

    # -- the services ----------------------------------------------------------------------
    def _on_get_simulator_features(self, _request: Any, response: Any) -> None:
        f = self.msgs.SimulatorFeatures
        response.features.features = [
            f.SPAWNING, f.SPAWNING_RESOURCE_STRING, f.DELETING, f.ENTITY_STATE_GETTING,
            f.ENTITY_STATE_SETTING,
            f.SIMULATION_RESET, f.SIMULATION_RESET_TIME, f.SIMULATION_RESET_STATE,
            f.SIMULATION_RESET_SPAWNED, f.SIMULATION_STATE_GETTING, f.SIMULATION_STATE_SETTING,
            f.SIMULATION_STATE_PAUSE, f.STEP_SIMULATION_SINGLE, f.STEP_SIMULATION_MULTIPLE,
            f.STEP_SIMULATION_ACTION]
        response.features.spawn_formats = ["urdf"]
        response.features.custom_info = (
            f"biped_opt simulator: one entity at a time; a step is step_size = "
            f"{self.step_size:g} of simulated time with contact events located exactly inside "
            f"it; command: std_msgs/Float64MultiArray on {COMMAND_TOPIC} (the inputs in "
            "declared order); spawn: entity_resource.uri names a library system or one in the "
            "node's system_paths")

    def _on_get_simulation_state(self, _request: Any, response: Any) -> None:
        response.state.state = self.state

    def _on_set_simulation_state(self, request: Any, response: Any) -> None:
        target = int(request.state.state)
        codes = self.srvs.SetSimulationState.Response
        if target == self.msgs.SimulationState.STATE_QUITTING:
            raise Refused(self.msgs.Result.RESULT_FEATURE_UNSUPPORTED,
                          "quitting is not offered: stop the node (Ctrl-C, SIGTERM) instead")
        if target not in _STATE_NAMES:
            raise Refused(codes.INCORRECT_TRANSITION,
                          f"state {target} is not one this simulator can be set to (0 stopped, "
                          "1 playing, 2 paused)")
        if target == self.state:
            raise Refused(codes.ALREADY_IN_TARGET_STATE,
                          f"the simulation is already {_STATE_NAMES[target]}")
        if target == STOPPED:
            self.reset(0xFF)
        elif target == PLAYING:
            self.node.end_playback()
            self._wall0, self._sim0_ns = time.monotonic(), self.node.sim_ns
            self._achieved = [(self._wall0, self._sim0_ns)]
        self.state = target
        self.node.get_logger().info(f"simulation {_STATE_NAMES[target]}")

    def _on_reset_simulation(self, request: Any, _response: Any) -> None:
        scope = int(request.scope) or 0xFF
        if not scope & 0x7:
            raise Refused(self.msgs.Result.RESULT_FEATURE_UNSUPPORTED,
                          f"scope {scope}: use 1 (time), 2 (state), 4 (spawned) or a sum")
        self.reset(scope)
        if self.state == PLAYING:  # (playing on from the reset time)
            self._wall0, self._sim0_ns = time.monotonic(), self.node.sim_ns
            self._achieved = [(self._wall0, self._sim0_ns)]

    def reset(self, scope: int) -> None:
        """ResetSimulation's scopes: time back to 0, the entity's initial state, the world of
        the start (the spawned entity removed, the served system back)."""
        if scope & 4 and (self.entity is None or self.entity.spawned):
            self._set_entity(self.initial)
        if scope & 2 and self.entity is not None:
            self.entity.restart()
            self.command = self._zeros()
        if scope & 1:
            self.node.end_playback()
            self.node.reset_clock()
        self._show_current()

    def _on_step_simulation(self, request: Any, _response: Any) -> None:
        steps = int(request.steps)
        self._check_steps(steps)
        self.step(steps)

    def _check_steps(self, steps: int, limit: int | None = None) -> None:
        """A request for ``steps`` steps: paused, an entity, at most ``limit`` steps (default
        ``max_steps``: StepSimulation holds the node until they are done)."""
        if self.state != PAUSED:
            raise Refused(self.msgs.Result.RESULT_OPERATION_FAILED,
                          f"the simulation is {_STATE_NAMES[self.state]}: it steps only while "
                          "paused")
        limit = self.max_steps if limit is None else limit
        if not 1 <= steps <= limit:
            what = "max_steps; SimulateSteps takes more" if limit == self.max_steps else "a goal"
            raise Refused(self.msgs.Result.RESULT_OPERATION_FAILED,
                          f"steps must be 1 to {limit} ({what}), got {steps}")
        self._need_entity()

    def _on_steps_goal(self, _goal: Any) -> Any:
        """One SimulateSteps goal at a time (another is rejected while one runs)."""
        return ros.GoalResponse.REJECT if self._stepping.locked() else ros.GoalResponse.ACCEPT

    def _simulate_steps(self, handle: Any) -> Any:
        """SimulateSteps: the steps one at a time, feedback after each; a cancel ends it after
        the step under way; a world that stops being paused aborts it."""
        action = ros.sim_actions.SimulateSteps
        result = action.Result()
        steps = int(handle.request.steps)
        done = 0
        # (goals accepted together past goal_callback's check: the later ones end at once
        # instead of holding an executor thread each until the first is done)
        if not self._stepping.acquire(blocking=False):
            result.result.result = self.msgs.Result.RESULT_OPERATION_FAILED
            result.result.error_message = "busy: another SimulateSteps goal is running; retry"
            handle.abort()
            return result
        with contextlib.ExitStack() as held:
            held.callback(self._stepping.release)
            try:
                while True:
                    with self.lock:
                        if done == 0:  # (one step at a time: the node serves in between)
                            self._check_steps(steps, MAX_GOAL_STEPS)
                        elif self.state != PAUSED:
                            raise Refused(self.msgs.Result.RESULT_OPERATION_FAILED,
                                          f"the simulation was {_STATE_NAMES[self.state]} "
                                          f"after {done} of {steps} steps")
                        self.step(1)
                    done += 1
                    handle.publish_feedback(action.Feedback(completed_steps=done,
                                                            remaining_steps=steps - done))
                    if done == steps or handle.is_cancel_requested:
                        break
            except Exception as exc:  # a refusal, or a bug: the goal aborts, says why
                result.result.result = exc.code if isinstance(exc, Refused) else \
                    self.msgs.Result.RESULT_OPERATION_FAILED
                result.result.error_message = public(failure_message(exc),
                                                     getattr(self.node, "private_paths", ()))
                handle.abort()
                return result
        result.result.result = self.msgs.Result.RESULT_OK
        if done < steps:
            result.result.error_message = f"canceled after {done} of {steps} steps"
            handle.canceled()
        else:
            handle.succeed()
        return result

    def _on_get_entities(self, request: Any, response: Any) -> None:
        f = request.filters
        if f.categories or f.tags.tags or int(f.bounds.type) != 0:
            raise Refused(self.msgs.Result.RESULT_FEATURE_UNSUPPORTED,
                          "only the name filter is supported (no categories, tags or bounds)")
        names = [] if self.entity is None else [self.entity.name]
        if f.filter:
            pattern = name_filter(f.filter)
            if pattern is None:
                raise Refused(self.msgs.Result.RESULT_FEATURE_UNSUPPORTED,
                              "filter: only the regular expressions of name characters, '.', "
                              f"at most {MAX_WILDCARDS} '.*', '^' and '$' are supported (at "
                              f"most {MAX_FILTER} characters)")
            names = [n for n in names if pattern.search(n)]
        response.entities = names

    def _on_get_entity_state(self, request: Any, response: Any) -> None:
        e = self._need_entity(request.entity)
        try:
            pos, quat, lin, ang = base_pose(e.compiled.coordinates, e.y)
        except Refused as exc:
            raise Refused(self.msgs.Result.RESULT_OPERATION_FAILED, str(exc)) from None
        st = response.state
        st.header = convert.header(self.node.sim_ns, "world")
        p, o = st.pose.position, st.pose.orientation
        p.x, p.y, p.z = (float(v) for v in pos)
        o.x, o.y, o.z, o.w = (float(v) for v in quat)
        tl, ta = st.twist.linear, st.twist.angular
        tl.x, tl.y, tl.z = (float(v) for v in lin)
        ta.x, ta.y, ta.z = (float(v) for v in ang)

    def _on_set_entity_state(self, request: Any, _response: Any) -> None:
        e = self._need_entity(request.entity)
        if request.set_acceleration:
            raise Refused(self.msgs.Result.RESULT_FEATURE_UNSUPPORTED,
                          "acceleration follows from the state and the command; it cannot be set")
        frame = request.state.header.frame_id
        if frame not in ("", "world"):
            raise Refused(self.msgs.Result.RESULT_OPERATION_FAILED,
                          f"frame {frame!r}: states are set in 'world' (or '')")
        try:
            y = set_base(e.compiled.coordinates, e.y,
                         request.state.pose if request.set_pose else None,
                         request.state.twist if request.set_twist else None)
        except Refused as exc:
            code = exc.code if exc.code in (101, 4) else self.msgs.Result.RESULT_OPERATION_FAILED
            raise Refused(code, str(exc)) from None
        e.y, e.mode = y, self._contacts_after_set(e, y, 101)

    def _contacts_after_set(self, e: Entity, y: np.ndarray, code: int) -> int:
        """The contact mode of a state set: the contacts of the mode before that are still on
        their surface (|a_j| <= SURFACE_TOL) and at rest on it (|a_j'| <= REST_TOL); the others
        go on free, found again as events. A constraint below its surface is refused
        (``code``)."""
        m = e.compiled.module
        d = len(e.compiled.coordinates)
        p = e.compiled.prepared
        h = 1e-7  # (a_j' by a central difference along q': error ~ h^2, far below REST_TOL)
        ahead, back = y.copy(), y.copy()
        ahead[:d] += h * y[d:]
        back[:d] -= h * y[d:]
        mode = 0
        for j, name in enumerate(e.compiled.constraints):
            a = float(m.constraint_value(j, p, y, 0))
            if a < -SURFACE_TOL:
                raise Refused(code, f"the state puts {name!r} below its surface "
                                    f"(a = {a:.3g})")
            rate = (float(m.constraint_value(j, p, ahead, 0))
                    - float(m.constraint_value(j, p, back, 0))) / (2 * h)
            if e.mode >> j & 1 and abs(a) <= SURFACE_TOL and abs(rate) <= REST_TOL:
                mode |= 1 << j
        return mode

    def _on_delete_entity(self, request: Any, _response: Any) -> None:
        self._need_entity(request.entity)
        self._set_entity(None)

    def _on_spawn_entity(self, request: Any, response: Any) -> None:
        self.spawn(request, response)

    def spawn(self, request: Any, response: Any) -> None:
        """SpawnEntity: a library system or one in ``system_paths`` named by
        ``entity_resource.uri``, or a robot's URDF text in ``resource_string``, compiled by
        the node's compiler thread (the first request for a system answers ``busy: ...;
        retry``); one entity at a time."""
        codes = self.srvs.SpawnEntity.Response
        failed = self.msgs.Result.RESULT_OPERATION_FAILED
        if self.entity is not None:
            if request.name == self.entity.name:
                raise Refused(codes.NAME_NOT_UNIQUE, f"{request.name!r} is in the world")
            raise Refused(failed, f"this simulator holds one entity at a time: delete "
                                  f"{self.entity.name!r} first")
        if request.entity_namespace:
            raise Refused(self.msgs.Result.RESULT_FEATURE_UNSUPPORTED,
                          "entity_namespace: entities have no interfaces of their own here")
        uri, text = request.entity_resource.uri, request.entity_resource.resource_string
        if request.name:
            try:
                check_name("name", request.name, "plain")
            except InvalidInputError as exc:
                raise Refused(codes.NAME_INVALID, str(exc)) from None
        if uri:
            if "/" in uri or ":" in uri:
                raise Refused(codes.UNSUPPORTED_FORMAT,
                              f"uri: {quoted(uri[:80])}: a uri names a library system or one "
                              "in the node's system_paths by name (no files, no package://)")
            try:
                check_name("uri", uri)
                self.sources.check_request(uri, "")
                job = self._job("study", system=uri, problem="")
                self.compiler.get(("study", uri, ""), f"system {uri}", job)
                source, _ = self.sources.study(uri, None)
            except Busy as exc:
                raise Refused(failed, str(exc)) from None
            except InvalidInputError as exc:
                raise Refused(codes.RESOURCE_PARSE_ERROR if "cannot" in str(exc) else
                              self.msgs.Result.RESULT_NOT_FOUND, str(exc)) from None
            from biped_opt.simulation.compiled import compiled_with

            compiled = compiled_with(source)
        elif text:
            if len(text.encode()) > self.max_resource_bytes:
                raise Refused(failed, f"resource_string: longer than {self.max_resource_bytes} "
                                      "bytes (max_resource_bytes)")
            if not text.lstrip("\ufeff \t\r\n").startswith("<"):
                raise Refused(codes.UNSUPPORTED_FORMAT,
                              "resource_string: a URDF text (XML) is the one format taken")
            from biped_opt.systems.urdf import MOVING, parse_urdf

            try:
                robot = parse_urdf(text, source="resource_string")
            except BipedOptError as exc:
                raise Refused(codes.RESOURCE_PARSE_ERROR, str(exc)) from None
            # (at least one coordinate per moving joint that follows none: a robot beyond
            # max_coordinates is refused here, before a compile process spends time on it)
            joints = sum(j.kind in MOVING and j.mimic is None for j in robot.joints)
            limit = self.sources.limits.max_coordinates
            if joints > limit:
                raise Refused(failed, f"resource_string: {joints} moving joints, more than "
                                      f"the {limit} coordinates a system may have here "
                                      "(max_coordinates)")
            digest = hashlib.sha256(text.encode()).hexdigest()
            try:
                compiled = self.compiler.get(("urdf", digest), f"the URDF robot {digest[:12]}",
                                             {**self._job("urdf"), "urdf": text})
            except Busy as exc:
                raise Refused(failed, str(exc)) from None
            except InvalidInputError as exc:
                raise Refused(codes.RESOURCE_PARSE_ERROR, str(exc)) from None
        else:
            raise Refused(codes.NO_RESOURCE, "entity_resource: both uri and resource_string "
                                             "are empty")
        name = request.name or compiled.name
        try:
            check_name("name", name, "plain")
        except InvalidInputError as exc:
            raise Refused(codes.NAME_INVALID, f"{exc} (give a name)") from None
        entity = Entity(name=name, compiled=compiled, maneuver=compiled.maneuvers[0],
                        s=0.0, y=np.zeros(0), mode=0, spawned=True,
                        scene=self.node.scene_for(compiled), biped=False)
        entity.restart()
        pose = request.initial_pose.pose
        q = pose.orientation
        if (pose.position.x, pose.position.y, pose.position.z) != (0.0, 0.0, 0.0) or \
                (q.x, q.y, q.z) != (0.0, 0.0, 0.0) or q.w not in (0.0, 1.0):
            if request.initial_pose.header.frame_id not in ("", "world"):
                raise Refused(codes.INVALID_POSE, "initial_pose: poses are in 'world' (or '')")
            try:
                y = set_base(compiled.coordinates, entity.y, pose)
                entity.y, entity.mode = y, self._contacts_after_set(entity, y, 109)
            except Refused as exc:
                raise Refused(codes.INVALID_POSE, f"initial_pose: {exc}") from None
        self._set_entity(entity)
        response.entity_name = name
        self.node.get_logger().info(f"spawned {name!r}")

    def _job(self, kind: str, **fields: Any) -> dict[str, Any]:
        return {"kind": kind, "system_paths": [str(p) for p in self.sources.system_paths],
                "max_legs": self.sources.limits.max_legs,
                "max_coordinates": self.sources.limits.max_coordinates, **fields}

    def close(self) -> None:
        self.compiler.close()
        self.steps_action.destroy()

    # -- the world's entity ----------------------------------------------------------------
    def _set_entity(self, entity: Entity | None) -> None:
        if entity is not None and entity is not self.entity:
            entity.scene = self.node.scene_for(entity.compiled)  # (a new scene: a new system)
        self.entity = entity
        if entity is not None and entity is self.initial:
            entity.restart()
        self.command = self._zeros()
        self._last_mode = None
        self.node.entity_changed(entity)
        self._show_current()

    def _show_current(self) -> None:
        """Publish the entity's current state at the current time (if not shown already)."""
        e = self.entity
        if e is None:
            return
        row = np.concatenate(([0.0], e.y, [e.mode], np.zeros(len(e.compiled.constraints))))
        self.node.show_live(e, row[None, :], [], self.node.sim_ns)

    # -- stepping --------------------------------------------------------------------------
    def step(self, steps: int, fast: bool = False) -> None:
        """``steps`` steps of ``step_size`` from the current state with the current command
        (held over them all: integrated as one span, the kernel's own steps and events
        independent of where ours begin), the samples and events shown once reached (``fast``:
        the state and scene of the last sample only, and the contact events)."""
        e = self._need_entity()
        self.node.end_playback()  # (its stamps would come after the steps': tf goes back)
        span = steps * self.step_size
        start_ns = self.node.sim_ns
        rate = float(self.node.get_parameter("publish_rate_hz").value)
        sample_dt = 1.0 / rate if math.isfinite(rate) and rate > 0 else self.step_size
        rows: list[np.ndarray] = []
        events: list[tuple[float, int]] = []
        t, pieces = 0.0, 0
        u = tuple(float(v) for v in self.command)
        try:
            while True:
                tr = e.compiled.advance(e.maneuver, e.y, e.mode, u, span - t,
                                        sample_dt=sample_dt)
                # (OK, APEX_IN_CONTACT: the maneuver's terminal event, which ends a maneuver
                # but not a world; MAX_EVENTS: the maneuver's event budget for one call, used
                # up after an event: go on from there)
                if tr.status.name not in ("OK", "HORIZON", "APEX_IN_CONTACT", "MAX_EVENTS"):
                    raise Refused(self.msgs.Result.RESULT_OPERATION_FAILED,
                                  f"the step from t = {start_ns / NS:.9g} failed at t = "
                                  f"{start_ns / NS + t + tr.t_final:.9g}: {tr.status.message}")
                if tr.samples is not None and len(tr.samples):
                    # (a piece's first row is the previous piece's last)
                    piece = tr.samples[1:] if rows else tr.samples.copy()
                    piece[:, 0] += t
                    rows.append(piece)
                events += [(t + ev.t, ev.mask_after) for ev in tr.contact_events]
                e.y, e.mode = tr.y_final, int(tr.mode_final)
                if tr.status.name == "HORIZON":
                    t = span
                    break
                pieces += 1
                if pieces > MAX_PIECES:
                    raise Refused(self.msgs.Result.RESULT_OPERATION_FAILED,
                                  f"the step from t = {start_ns / NS:.9g} met the maneuver's "
                                  f"terminal event or event budget {MAX_PIECES} times (a Zeno "
                                  "cascade of impacts?)")
                t += tr.t_final
        finally:
            self.node.advance_clock(start_ns + (steps * round(self.step_size * NS)
                                                if t >= span else round(t * NS)))
            if rows:
                self.node.show_live(e, np.concatenate(rows), events, start_ns, fast)

    def _on_live_tick(self) -> None:
        with self.lock:
            if self.state != PLAYING or self.entity is None:
                return
            now = time.monotonic()
            factor = float(self.node.get_parameter("real_time_factor").value)
            h_ns = round(self.step_size * NS)
            if factor > 0:
                due_ns = self._sim0_ns + round((now - self._wall0) * factor * NS)
                steps = (due_ns - self.node.sim_ns) // h_ns
                behind = (due_ns - self.node.sim_ns) / NS
                if behind > self.max_lag:  # drop the backlog, and say so
                    if now - self._lag_logged > LAG_LOG_S:
                        self._lag_logged = now
                        self.node.get_logger().warning(
                            f"cannot keep real_time_factor {factor:g}: {behind:.3f} s of "
                            "simulated time behind; playing slower (the factor achieved is "
                            "on /diagnostics)")
                    steps = max(1, round(self.max_lag * NS) // h_ns)  # (this tick: max_lag)
                    self._wall0, self._sim0_ns = now, self.node.sim_ns + steps * h_ns
            else:
                steps = max(1, round(0.05 * NS) // h_ns)
            if steps <= 0:
                return
            try:
                if factor > 0:
                    self.step(int(min(steps, self.max_steps)))
                else:  # as fast as it goes: 50 ms pieces for FAST_TICK_S of wall time
                    while time.monotonic() - now < FAST_TICK_S:
                        self.step(int(min(steps, self.max_steps)), fast=True)
            except Refused as exc:
                self.state = PAUSED
                self.node.get_logger().error(f"simulation paused: {exc}")
            self._achieved.append((time.monotonic(), self.node.sim_ns))
            del self._achieved[:-400]

    def achieved_factor(self) -> float:
        """Simulated seconds per wall-clock second over the last second or so of play."""
        if len(self._achieved) < 2:
            return 0.0
        (w0, s0), (w1, s1) = self._achieved[0], self._achieved[-1]
        for w, s in self._achieved:
            if w1 - w <= 2.0:
                w0, s0 = w, s
                break
        return (s1 - s0) / NS / (w1 - w0) if w1 > w0 else 0.0

    def _diagnostics(self) -> None:
        if self._diag_pub is None or self.state != PLAYING:
            return
        with self.lock:
            target = float(self.node.get_parameter("real_time_factor").value)
            achieved = self.achieved_factor()
        msg = self._diag_cls()
        status_cls = ros.message_type("diagnostic_msgs/msg/DiagnosticStatus")
        kv_cls = ros.message_type("diagnostic_msgs/msg/KeyValue")
        status = status_cls()
        level = 1 if target > 0 and achieved < 0.9 * target else 0  # (OK, WARN)
        status.level = bytes([level]) if ros.BACKEND == "rclpy" else level  # (a byte field)
        status.name = f"{self.node.get_name()}: real time"
        status.hardware_id = "biped_opt"
        status.message = (f"real_time_factor {achieved:.3f} of {target:g} requested"
                          if target > 0 else f"as fast as possible: {achieved:.3f}")
        status.values = [kv_cls(key="real_time_factor", value=f"{target:g}"),
                         kv_cls(key="achieved", value=f"{achieved:.4f}")]
        msg.header = convert.header(self.node.sim_ns, "")
        msg.status = [status]
        self._diag_pub.publish(msg)

    # -- the command and the idle clock ------------------------------------------------------
    def _on_command(self, msg: Any) -> None:
        data = msg.data
        with self.lock:
            e = self.entity
            n = len(e.compiled.inputs) if e is not None else 0
            try:
                if len(data) != n:
                    raise InvalidInputError(
                        f"{len(data)} values, the entity has {n} inputs"
                        + (f" ({', '.join(e.compiled.inputs)})" if e is not None else ""))
                values = np.array(data, dtype=np.float64)
                if not np.all(np.isfinite(values)):
                    raise InvalidInputError("a value is not finite")
            except (InvalidInputError, TypeError, ValueError) as exc:
                self.node.get_logger().warning(
                    f"dropped a command on {COMMAND_TOPIC} ({exc}); holding the last valid one",
                    throttle_duration_sec=LOG_THROTTLE_S)
                return
            self.command = values if n else self._zeros()

    def _idle_clock(self) -> None:
        if self._clock_pub is None or self.node.playing_back() or (
                self.state == PLAYING and self.entity is not None):  # (the steps publish it)
            return
        ns = self.node.clock_ns
        msg = self._clock_cls()
        msg.clock = convert.stamp(max(ns, 0))
        self._clock_pub.publish(msg)
