"""``simulator`` node: plays a maneuver's trajectory on ``/biped/state`` and its contact modes.

Parameters: ``maneuver``, ``theta0``, ``inputs`` ([u1, u2, u12]), ``publish_rate_hz`` (samples per
unit of simulation time, default 200), ``real_time_factor`` (default 1; 0 = as fast as possible),
``loop`` (replay the trajectory forever), ``autostart`` (play the parameters' run at start-up),
``scene`` (publish /clock, /tf, markers and /robot_description, below; default true).

- ``/biped/state`` (BipedState, sensor-data QoS): the dense trajectory, sampled every
  1 / publish_rate_hz of simulation time plus before and after each event;
- ``/biped/contact_mode`` (ContactMode, reliable + transient-local): the initial mode and every
  change, stamped with the exact event time (run start + t_event);
- ``/biped/simulate`` (Simulate.srv): simulate and start playing a new run; the reply carries the
  outcome, the mode sequence, the event times and every state sample (so a recorder loses nothing
  to the best-effort topic).

Any other system (parameter ``system``: a library name such as ``rocking_bar`` or
``walker3_coupled``, or the path of a system file; default ``""`` = the biped as above):

- ``/biped/system_info`` (SystemInfo, reliable + transient-local, published once): the names of
  the coordinates, constraints (the bits of a contact mode), inputs, parameters and maneuvers;
- ``/biped/system_state`` (SystemState, sensor-data QoS): the dense trajectory as above;
- ``/biped/simulate``: ``maneuver`` one of the system's, ``theta0`` the maneuver's s, ``inputs``
  in the system's declared order; the reply carries ``contact_modes`` and ``system_states``.

The default ``maneuver`` and ``inputs`` of such a system are its first maneuver and zeros. An
unknown system or a bad system file stops the node at start-up with one line saying why, as
does (with ``autostart``) a run the parameters cannot start.

**Simulated time and the scene** (ROS.md Sec. 6). The node keeps a simulated clock that starts at
0 and runs on through successive runs (a run starts 1 ns after the previous one ended). Every
message is stamped with it, and while a run plays the node publishes:

- ``/clock`` (rosgraph_msgs/Clock): the time of every shown sample, so nodes with
  ``use_sim_time`` run on simulated time;
- ``/tf`` (tf2_msgs/TFMessage): world -> each body frame the system declares;
- ``/biped/markers`` (visualization_msgs/MarkerArray): the ground, the shapes, the contact points
  (active ones red) and the contact forces as arrows;
- ``/robot_description`` (std_msgs/String, transient local, once): the URDF of the frames.

**A simulator a ROS stack drives** (ROS.md Sec. 8, :mod:`biped_opt.nodes.sim_control`): the ROS 2
Simulation Interfaces under ``/simulator/...`` (state, reset, step, entity state, delete), a
live world that plays at ``real_time_factor`` with the inputs of ``/biped/command``
(``std_msgs/Float64MultiArray``), ``/clock`` at the current time while nothing plays, and
``/diagnostics`` with the real-time factor achieved. A run starts 1 ns after the previous one's
last sample, so no stamp is shown twice; ``/biped/simulate`` is refused while the world plays.

A run played as fast as possible (``real_time_factor`` 0, as a sweep asks) publishes its states
and contact modes as before but ``/clock``, ``/tf`` and the markers of its last sample only: no
viewer follows a run played in a millisecond, and the recorder writes every sample to its file
from the reply.
"""

from __future__ import annotations

import threading
import time
import types
from dataclasses import dataclass
from typing import Any

import numpy as np

from biped_opt import ros
from biped_opt.errors import BipedOptError, InvalidInputError, InvalidParameterError
from biped_opt.nodes import convert
from biped_opt.nodes.refusals import refuse
from biped_opt.nodes.run import announce_ready, run_node, warm_up_kernels
from biped_opt.nodes.sim_control import COMMAND_TOPIC, PLAYING, SERVICES, Entity, SimControl
from biped_opt.paper.biped import compiled_biped, simulate
from biped_opt.record.scene import DELETEALL, MARKERS_TOPIC, SCENE_TOPICS, SceneMessages
from biped_opt.ros.interfaces import load_interfaces

__all__ = ["SimulatorNode", "main", "CONTACT_MODE_QOS", "SYSTEM_INFO_QOS", "BIPED"]

#: values of the ``system`` parameter that mean the biped of the paper (BipedState messages)
BIPED = ("", "biped")

CONTACT_MODE_QOS = ros.QoSProfile(
    depth=10,
    reliability=ros.ReliabilityPolicy.RELIABLE,
    durability=ros.DurabilityPolicy.TRANSIENT_LOCAL,
    history=ros.HistoryPolicy.KEEP_LAST,
)

#: the system description: published once, kept for late subscribers
SYSTEM_INFO_QOS = ros.QoSProfile(
    depth=1,
    reliability=ros.ReliabilityPolicy.RELIABLE,
    durability=ros.DurabilityPolicy.TRANSIENT_LOCAL,
    history=ros.HistoryPolicy.KEEP_LAST,
)


def compile_served_system(spec: str) -> Any:
    """The :class:`~biped_opt.simulation.compiled.CompiledSystem` of the ``system`` parameter, its
    kernel compiled (a first start compiles for a while; later ones load it). Any failure is
    one :class:`BipedOptError` naming the parameter."""
    from biped_opt.simulation.compiled import CompiledSystem

    try:
        compiled = CompiledSystem(spec)
        maneuver = compiled.maneuvers[0]
        compiled.simulate(maneuver, 0.0, sample_dt=0.1)  # compile before serving
    except BipedOptError as exc:
        raise InvalidParameterError(f"system: {exc}") from None
    except IndexError:
        raise InvalidParameterError(f"system: {spec!r} has no maneuver to simulate") from None
    except Exception as exc:  # the generated code failed to build: say so, not a traceback
        raise InvalidParameterError(
            f"system: cannot compile {spec!r}: {type(exc).__name__}: {exc}") from None
    return compiled


def scene_qos(topic: str) -> Any:
    """The QoS a scene topic is offered with (:data:`SCENE_TOPICS`, rosbag2's enums)."""
    q = SCENE_TOPICS[topic][1]
    return ros.QoSProfile(depth=q["depth"], history=ros.HistoryPolicy.KEEP_LAST,
                          reliability=ros.ReliabilityPolicy(q["reliability"]),
                          durability=ros.DurabilityPolicy(q["durability"]))


@dataclass
class _Playback:
    trajectory: Any  #: a Trajectory (biped) or a SystemTrajectory
    states: list[Any]
    modes: list[tuple[float, Any]]
    #: (t, {topic: CDR}) of the shown samples' /clock, /tf and markers, decoded when due
    scene: list[tuple[float, dict[str, bytes]]]
    rate: float  # real-time factor; 0 = everything at once
    wall_start: float
    start_ns: int = 0  #: the run's start on the simulated clock
    #: (maneuver, theta0, inputs) of the run, to play it again on the clock when looping
    request: tuple[str, float, Any] = ("", 0.0, ())
    next_state: int = 0
    next_mode: int = 0
    next_scene: int = 0


class SimulatorNode(ros.Node):
    """Simulates maneuvers and publishes them as they would unfold (see the module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("simulator", **kwargs)
        self.declare_parameter("system", "")
        self.source = str(self.get_parameter("system").value).strip()
        #: the served system's CompiledSystem; None for the biped
        self.system: Any = None
        if self.source not in BIPED:
            self.get_logger().info(f"loading system {self.source!r} (a first start compiles "
                                   "its simulator, which takes a while; later ones load it)")
            self.system = compile_served_system(self.source)
        biped = self.system is None
        self.declare_parameter("warm_up", True)
        self.declare_parameter("maneuver", "touchdown" if biped else self.system.maneuvers[0])
        self.declare_parameter("theta0", 0.1)
        self.declare_parameter("inputs", [2.0, 0.5, 0.0] if biped else
                               [0.0] * max(len(self.system.inputs), 1))
        self.declare_parameter("publish_rate_hz", 200.0)
        self.declare_parameter("real_time_factor", 1.0)
        self.declare_parameter("loop", False)
        self.declare_parameter("autostart", True)
        if biped and self.get_parameter("warm_up").value:
            warm_up_kernels(self)
        if biped:
            self._state_pub = self.create_publisher(
                ros.msgs.BipedState, "/biped/state", ros.qos_profile_sensor_data
            )
            self._mode_pub = self.create_publisher(
                ros.msgs.ContactMode, "/biped/contact_mode", CONTACT_MODE_QOS
            )
            topics = ("/biped/state", "/biped/contact_mode")
        else:
            self._state_pub = self.create_publisher(
                ros.msgs.SystemState, "/biped/system_state", ros.qos_profile_sensor_data
            )
            self._info_pub = self.create_publisher(
                ros.msgs.SystemInfo, "/biped/system_info", SYSTEM_INFO_QOS
            )
            self._info_pub.publish(ros.msgs.SystemInfo(
                **convert.system_info_fields(self.system, self.source)))
            topics = ("/biped/system_state", "/biped/system_info")
        self.declare_parameter("scene", True)
        compiled = compiled_biped() if biped else self.system
        #: the scene's messages (None: turned off, or the system declares no looks)
        self.scene: SceneMessages | None = self.scene_for(compiled)
        self._scene_pubs: dict[str, tuple[Any, type]] = {}
        if self.scene is not None:
            for topic, (typename, _) in self.scene.topics.items():
                cls = ros.message_type(typename)
                assert cls is not None, typename
                self._scene_pubs[topic] = (
                    self.create_publisher(cls, topic, scene_qos(topic)), cls)
            topics += tuple(self.scene.topics)
            pub, cls = self._scene_pubs["/robot_description"]
            pub.publish(ros.from_cdr(cls, self.scene.robot_description()))
        #: the simulated clock: the time reached (the end of the last run or step) [ns],
        #: whether a sample is stamped with it, the last /clock and /tf stamps published
        self._sim_ns = 0
        self._stamped = False
        self.clock_ns = 0
        self._shown_ns = -1
        self._service = self.create_service(
            ros.srvs.Simulate, "/biped/simulate", self._on_simulate
        )
        self._lock = threading.RLock()
        self._playback: _Playback | None = None
        self._timer = self.create_timer(0.005, self._on_tick)
        self._system_state_pub: Any = self._state_pub if not biped else None
        # (the world starts as the parameters' run would; a maneuver the system lacks, left
        # in a shared parameter file with autostart off, gives way to the system's first)
        maneuver = str(self.get_parameter("maneuver").value)
        entity = Entity(name=compiled.name, compiled=compiled,
                        maneuver=maneuver if maneuver in compiled.maneuvers
                        else compiled.maneuvers[0],
                        s=float(self.get_parameter("theta0").value), y=np.zeros(0), mode=0,
                        spawned=False, scene=self.scene, biped=biped)
        try:
            entity.restart()
        except BipedOptError as exc:
            raise InvalidParameterError(f"maneuver, theta0: {exc}") from None
        #: the ROS 2 Simulation Interfaces and the live simulation (sim_control)
        self.control = SimControl(self, entity)
        serves = ("/biped/simulate", *(f"{self.get_fully_qualified_name()}/{name}"
                                       for name in SERVICES),
                  f"{self.get_fully_qualified_name()}/simulate_steps (action)")
        if self.get_parameter("autostart").value:
            try:
                self.start(
                    str(self.get_parameter("maneuver").value),
                    float(self.get_parameter("theta0").value),
                    list(self.get_parameter("inputs").value),
                    float(self.get_parameter("real_time_factor").value),
                    publish_now=False,  # (the timer publishes once the ready line is out)
                )
            except BipedOptError as exc:  # a bad parameter: the node stops (status 2)
                raise InvalidParameterError(f"cannot start from the parameters: {exc}") \
                    from None
        announce_ready(self, serves=serves, publishes=(
            *topics, *(() if "/clock" in topics else ("/clock",)), "/diagnostics",
            COMMAND_TOPIC + " (subscribed)"))

    # -- running --------------------------------------------------------------------------
    def run(self, maneuver: str, theta0: float, inputs: Any) -> Any:
        """Validate a request and simulate it with the node's sampling rate: a Trajectory of the
        biped, else a SystemTrajectory of the served system (theta0 is its maneuver's s)."""
        rate = float(self.get_parameter("publish_rate_hz").value)
        if not (convert.finite(rate) and rate > 0):
            raise InvalidInputError(f"publish_rate_hz must be positive, got {rate}")
        if self.system is not None:
            name = convert.request_system_maneuver(self.system, maneuver)
            s = convert.request_s(theta0)
            u = convert.request_system_inputs(self.system, inputs)
            return self.system.simulate(name, s, u or None, sample_dt=1.0 / rate)
        m = convert.request_maneuver(maneuver)
        th = convert.request_theta0(m, theta0)
        u = convert.request_inputs(inputs)
        return simulate(m, th, u, sample_dt=1.0 / rate)

    def start(
        self, maneuver: str, theta0: float, inputs: Any, real_time_factor: float,
        publish_now: bool = True,
    ) -> tuple[Any, list[Any]]:
        """Simulate a request and play it from the simulated clock's current time: the
        trajectory and its state messages as stamped."""
        if not (convert.finite(real_time_factor) and real_time_factor >= 0):
            raise InvalidInputError(
                f"real_time_factor must be >= 0 (0: as fast as possible), got {real_time_factor}"
            )
        tr = self.run(maneuver, theta0, inputs)
        with self._lock:
            # (a run starts after the last stamp shown: one nanosecond after the previous
            # run's last sample, so no stamp carries two states)
            start_ns = self._sim_ns + self._stamped
            self._sim_ns = start_ns + max(round(tr.t_final * convert.NS), 1)
            self._stamped = True
        if self.system is not None:
            states = convert.system_state_messages(tr, len(self.system.coordinates), start_ns)
            modes: list[tuple[float, Any]] = []
        else:
            states = convert.state_messages(tr, start_ns)
            modes = convert.contact_mode_messages(tr, start_ns)
        scene: list[tuple[float, dict[str, bytes]]] = []
        if self.scene is not None and tr.samples is not None and len(tr.samples):
            shown = tr.samples if real_time_factor > 0 else tr.samples[-1:]
            stamps, data = self.scene.messages(shown, start_ns)
            scene = [((int(ns) - start_ns) / convert.NS, {k: v[i] for k, v in data.items()})
                     for i, ns in enumerate(stamps)]
        playback = _Playback(
            trajectory=tr,
            states=states,
            modes=modes,
            scene=scene,
            rate=real_time_factor,
            wall_start=time.monotonic(),
            start_ns=start_ns,
            request=(maneuver, theta0, inputs),
        )
        with self._lock:
            self._playback = playback
        if publish_now:
            self._on_tick()
        return tr, states

    def _on_tick(self) -> None:
        again = None
        with self._lock:
            pb = self._playback
            if pb is None:
                return
            sim_now = float("inf") if pb.rate == 0 else (time.monotonic() - pb.wall_start) * pb.rate
            while pb.next_mode < len(pb.modes) and pb.modes[pb.next_mode][0] <= sim_now:
                self._mode_pub.publish(pb.modes[pb.next_mode][1])
                pb.next_mode += 1
            while pb.next_scene < len(pb.scene) and pb.scene[pb.next_scene][0] <= sim_now:
                t, data = pb.scene[pb.next_scene]
                self._publish_scene(data, pb.start_ns + round(t * convert.NS))
                pb.next_scene += 1
            while pb.next_state < len(pb.states) and pb.states[pb.next_state].t <= sim_now:
                self._state_pub.publish(pb.states[pb.next_state])
                pb.next_state += 1
            done = pb.next_state == len(pb.states) and pb.next_mode == len(pb.modes) \
                and pb.next_scene == len(pb.scene)
            if done:
                self._playback = None
                if self.get_parameter("loop").value and pb.rate > 0:
                    again = pb
        if again is not None:  # the same run once more, later on the simulated clock
            self.start(*again.request, again.rate, publish_now=False)

    # -- the clock, the scene and the live world (used by sim_control) ------------------------
    @property
    def sim_ns(self) -> int:
        """The simulated time reached [ns]."""
        return self._sim_ns

    def advance_clock(self, ns: int) -> None:
        """The live world reached ``ns`` (its sample there is shown)."""
        with self._lock:
            self._sim_ns, self._stamped = max(ns, self._sim_ns), True

    def reset_clock(self) -> None:
        """Simulated time back to 0 (a reset: the one time the clock goes back)."""
        with self._lock:
            self._sim_ns, self._stamped, self._shown_ns = 0, False, -1
            self.clock_ns = 0
            self._publish_clock(0)

    def end_playback(self) -> None:
        """Drop what is left of a run being played (live play or a step takes over; the
        clock is at the run's end already)."""
        with self._lock:
            self._playback = None

    def playing_back(self) -> bool:
        return self._playback is not None

    def scene_publisher(self, topic: str) -> Any:
        """The publisher of a scene topic (made on first use)."""
        if topic not in self._scene_pubs:
            cls = ros.message_type(SCENE_TOPICS[topic][0])
            assert cls is not None, topic
            self._scene_pubs[topic] = (self.create_publisher(cls, topic, scene_qos(topic)), cls)
        return self._scene_pubs[topic][0]

    def _publish_scene(self, data: dict[str, bytes], ns: int) -> None:
        for topic, cdr in data.items():
            self.scene_publisher(topic)
            pub, cls = self._scene_pubs[topic]
            pub.publish(ros.from_cdr(cls, cdr))
        self._shown_ns = max(self._shown_ns, ns)
        if "/clock" in data:
            self.clock_ns = max(self.clock_ns, ns)

    def _publish_clock(self, ns: int) -> None:
        cls = ros.message_type(SCENE_TOPICS["/clock"][0])
        msg = cls()  # type: ignore[misc]
        msg.clock = convert.stamp(ns)
        self.scene_publisher("/clock").publish(msg)

    def scene_for(self, compiled: Any) -> SceneMessages | None:
        """The scene messages of a system spawned in the live world (None: the node's scene
        is turned off, or the system declares no looks)."""
        if compiled.scene.empty or self.get_parameter("scene").value is not True:
            return None
        return SceneMessages(load_interfaces().typestore, compiled.scene,
                             list(compiled.parameters.values()), len(compiled.coordinates))

    def destroy_node(self) -> None:
        control = getattr(self, "control", None)
        if control is not None:
            control.close()
        super().destroy_node()

    def entity_changed(self, entity: Entity | None) -> None:
        """A new entity in the live world (spawned, or the served system back): its
        description and looks; none (deleted): the viewers' markers cleared."""
        if entity is not None and entity.scene is not None:
            self.scene_publisher("/robot_description").publish(ros.from_cdr(
                self._scene_pubs["/robot_description"][1], entity.scene.robot_description()))
        elif entity is None and self.get_parameter("scene").value is True:
            self._clear_markers()

    def _clear_markers(self) -> None:
        """One DELETEALL marker at the current time (ROS.md Sec. 6): an empty world shows
        nothing of the entity deleted from it."""
        cls = ros.message_type(SCENE_TOPICS[MARKERS_TOPIC][0])
        marker = ros.message_type("visualization_msgs/msg/Marker")()  # type: ignore[misc]
        marker.action = DELETEALL
        marker.header.frame_id = "world"
        marker.header.stamp = convert.stamp(self.clock_ns)
        markers = cls()  # type: ignore[misc]
        markers.markers = [marker]
        self.scene_publisher(MARKERS_TOPIC).publish(markers)

    def show_live(self, entity: Entity, rows: Any, events: list[tuple[float, int]],
                  start_ns: int, fast: bool = False) -> None:
        """Publish the live world's samples (rows [t, y, mode, lambda], t from ``start_ns``)
        whose stamps are later than anything shown, and its contact events (``fast``: the
        last sample only)."""
        stamps = start_ns + np.round(rows[:, 0] * convert.NS).astype(np.int64)
        fresh = stamps > self._shown_ns
        if not fresh.any():
            return
        rows = rows[fresh][-1:] if fast else rows[fresh]
        # publish_rate_hz samples per unit of simulated time, every event's rows, the last
        rate = float(self.get_parameter("publish_rate_hz").value)
        t = rows[:, 0]
        keep = np.zeros(len(rows), dtype=bool)
        keep[SceneMessages.shown(rows, rate if convert.finite(rate) and rate > 0 else 0.0)] = True
        keep[:-1] |= t[:-1] == t[1:]  # (the state topic has an event's row before it too)
        rows = rows[keep]
        run = types.SimpleNamespace(samples=rows, maneuver=entity.maneuver, theta0=entity.s,
                                    s=entity.s, system=entity.compiled.name)
        if entity.biped and self.system is None:
            for msg in convert.state_messages(run, start_ns):
                self._state_pub.publish(msg)
        else:
            if self._system_state_pub is None:
                self._system_state_pub = self.create_publisher(
                    ros.msgs.SystemState, "/biped/system_state", ros.qos_profile_sensor_data)
            for msg in convert.system_state_messages(run, len(entity.compiled.coordinates),
                                                     start_ns):
                self._system_state_pub.publish(msg)
        if self.system is None and entity.biped:
            mode = self.control._last_mode
            first = int(rows[0, 1 + len(entity.y)])
            for t, mask in [(float(rows[0, 0]), first), *events]:
                ns = start_ns + round(t * convert.NS)
                if mask != mode and ns > self._shown_ns:
                    msg = ros.msgs.ContactMode()
                    msg.header = convert.header(ns)
                    msg.mode = int(mask)
                    self._mode_pub.publish(msg)
                    mode = mask
            self.control._last_mode = mode
        last = int(stamps[fresh][-1])
        if entity.scene is not None:
            shown, data = entity.scene.messages(rows, start_ns)  # (one row per stamp)
            for i, ns in enumerate(shown):
                self._publish_scene({k: v[i] for k, v in data.items()}, int(ns))
        else:
            self._publish_clock(last)
            self.clock_ns = max(self.clock_ns, last)
        self._shown_ns = max(self._shown_ns, last)

    # -- service --------------------------------------------------------------------------
    def _on_simulate(self, request: Any, response: Any) -> Any:
        if self.control.state == PLAYING:
            return refuse(self, "/biped/simulate", response, InvalidInputError(
                "the simulation is playing (ROS 2 Simulation Interfaces): pause or stop it "
                "first"))
        try:
            # (the states as stamped: the reply carries what the topic carried)
            tr, states = self.start(request.maneuver, request.theta0, request.inputs,
                                    request.real_time_factor)
        except Exception as exc:  # bad request, or a bug: one refused request either way
            return refuse(self, "/biped/simulate", response, exc)
        if self.system is not None:
            response.success = tr.success
            response.message = "" if tr.success else \
                f"simulation ended with status {tr.status.name}"
            response.contact_modes = [int(m) for m in tr.modes]
            response.system_states = states
        else:
            response.success = tr.success
            response.message = tr.message
            response.mode_sequence = [int(m) for m in tr.mode_sequence]
            response.contact_modes = list(response.mode_sequence)
            response.states = states
        response.outcome = tr.outcome
        response.t_final = tr.t_final
        response.event_times = [float(t) for t in tr.event_times]
        return response


def main(args: list[str] | None = None) -> None:
    run_node(SimulatorNode, args)


if __name__ == "__main__":
    main()
