"""A run as a ROS tool shows it: ``/clock``, ``/tf``, markers and ``/robot_description`` (ROS.md
Sec. 6), serialized to CDR for a whole trajectory in one vectorised pass.

:class:`SceneMessages` turns the samples of a run (the columns of
:attr:`biped_opt.simulation.trajectory.Trajectory.samples`) and the system's
:class:`~biped_opt.simulation.scene.Scene` into, per sample:

- ``rosgraph_msgs/msg/Clock`` on ``/clock``: the sample's time;
- ``tf2_msgs/msg/TFMessage`` on ``/tf``: world -> every body frame; for a system that is a tree
  of standard joints (:attr:`Scene.tree <biped_opt.simulation.scene.Scene.tree>`: one imported
  from a URDF) world -> its base link only, the rest being robot_state_publisher's work from
  ``/robot_description`` and ``/joint_states``;
- ``sensor_msgs/msg/JointState`` on ``/joint_states`` (trees only): every joint's name, position
  and velocity, and its effort when the run's inputs are given and each joint has one;
- ``visualization_msgs/msg/MarkerArray`` on ``/biped/markers``: the ground, every shape (boxes and
  spheres in their frames, or for a tree in the world frame at their frames' poses; lines
  through their world points), the contact points (red when the constraint is active, grey when
  not) and each contact force lambda_j as an arrow along its direction, :data:`FORCE_SCALE` m
  per unit of force (invisible while the constraint is free). The first array of a
  :class:`SceneMessages` (a new system) starts with a DELETEALL marker, so that a viewer drops
  what an earlier system left.

A sample repeated at an event (the rows before and after the reset share their time and
configuration) is shown once, after the reset, so no frame is sent twice for one stamp. A rate
thins the rows out (the recorder's ``scene_rate_hz``): the first row of each interval, every
event's post-reset row and the last row are kept. The
messages' layouts are fixed once the scene is known (:func:`biped_opt.record.cdr.compile_layout`),
so a trajectory costs a few NumPy assignments per field, whatever its length. The same bytes go
into MCAP files and, deserialized, onto the live topics: one definition of what is shown.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from biped_opt.record.cdr import CDR_LE_HEADER, FixedLayout, compile_layout
from biped_opt.simulation.scene import Scene, SceneState

__all__ = ["SceneMessages", "SCENE_TOPICS", "FORCE_SCALE", "MARKERS_TOPIC", "NS",
           "JOINT_STATES_TOPIC"]

NS = 1_000_000_000
MARKERS_TOPIC = "/biped/markers"
JOINT_STATES_TOPIC = "/joint_states"
#: topic -> (ROS type, offered QoS as rosbag2 integer enums: history 1 = KEEP_LAST, reliability
#: 1 = RELIABLE, durability 1 = TRANSIENT_LOCAL / 2 = VOLATILE): tf2_ros' broadcaster (depth 100,
#: reliable, volatile), robot_state_publisher's description (depth 1, transient local), a clock
#: every subscriber matches (reliable, depth 1), joint states as joint_state_publisher offers
#: them (depth 10, reliable, volatile)
SCENE_TOPICS: dict[str, tuple[str, dict[str, int]]] = {
    "/clock": ("rosgraph_msgs/msg/Clock",
               {"history": 1, "depth": 1, "reliability": 1, "durability": 2}),
    "/tf": ("tf2_msgs/msg/TFMessage",
            {"history": 1, "depth": 100, "reliability": 1, "durability": 2}),
    MARKERS_TOPIC: ("visualization_msgs/msg/MarkerArray",
                    {"history": 1, "depth": 10, "reliability": 1, "durability": 2}),
    "/robot_description": ("std_msgs/msg/String",
                           {"history": 1, "depth": 1, "reliability": 1, "durability": 1}),
    JOINT_STATES_TOPIC: ("sensor_msgs/msg/JointState",
                         {"history": 1, "depth": 10, "reliability": 1, "durability": 2}),
}
#: metres of arrow per unit of contact force
FORCE_SCALE = 0.1
#: visualization_msgs/Marker types used here
ARROW, CUBE, SPHERE, LINE_STRIP, SPHERE_LIST = 0, 1, 2, 4, 7
#: visualization_msgs/Marker action that removes every marker
DELETEALL = 3
#: the ground: a thin slab whose top is z = 0, and the contact points' and arrows' looks
GROUND_SIZE = (20.0, 2.0, 0.01)
GROUND_COLOR = (0.75, 0.75, 0.72, 1.0)
CONTACT_DIAMETER = 0.05
ACTIVE_COLOR, FREE_COLOR = (0.85, 0.1, 0.1, 1.0), (0.5, 0.5, 0.5, 0.6)
ARROW_COLOR = (0.1, 0.7, 0.2, 1.0)
ARROW_SCALE = (0.015, 0.035, 0.04)  # shaft diameter, head diameter, head length


class SceneMessages:
    """CDR of the scene topics for the samples of runs of one system (see the module
    docstring); ``parameters``: the parameter values, in their declared order; ``rate``: how
    many samples per unit of simulation time are shown (:meth:`shown`; 0: every one)."""

    def __init__(self, typestore: Any, scene: Scene, parameters: npt.ArrayLike,
                 ndof: int, rate: float = 0.0) -> None:
        self.typestore = typestore
        self.rate = float(rate)
        self.scene = scene
        self.parameters = np.asarray(parameters, dtype=np.float64)
        self.ndof = int(ndof)
        self.world = scene.world
        #: a tree of standard joints: /tf carries world -> base, /joint_states the joints, and
        #: the shapes' markers are placed in the world frame
        self.tree = scene.tree is not None
        #: the next array is the scene's first (it starts with a DELETEALL marker)
        self._fresh = True
        # one marker per item, in this order: ground, shapes, contact points, force arrows
        self._markers: list[tuple[str, int, str, int]] = [("ground", CUBE, self.world, 0)]
        for s in scene.shapes:
            kind = {"box": CUBE, "sphere": SPHERE, "line": LINE_STRIP}[s.kind]
            self._markers.append((s.name, kind, self.world if self.tree else s.frame,
                                  s.npoints))
        if scene.contacts:
            self._markers.append(("contacts", SPHERE_LIST, self.world, len(scene.contacts)))
            for name in scene.contact_names:
                self._markers.append((f"{name}_force", ARROW, self.world, 2))
        self._clock = compile_layout(typestore, SCENE_TOPICS["/clock"][0], {})
        #: the topics this scene publishes (:data:`SCENE_TOPICS`; /joint_states for a tree
        #: only), as ``SCENE_TOPICS`` maps them
        self.topics: dict[str, tuple[str, dict[str, int]]] = {
            t: v for t, v in SCENE_TOPICS.items() if self.tree or t != JOINT_STATES_TOPIC}
        #: the frames on /tf
        self.tf_frames: tuple[str, ...] = (str(scene.base),) if self.tree else scene.frames
        tf_strings = {}
        for k, frame in enumerate(self.tf_frames):
            tf_strings[f"transforms.{k}.header.frame_id"] = self.world
            tf_strings[f"transforms.{k}.child_frame_id"] = frame
        self._tf = compile_layout(typestore, SCENE_TOPICS["/tf"][0], tf_strings,
                                  {"transforms": len(self.tf_frames)})
        self._joints: dict[bool, FixedLayout] = {}
        if self.tree:
            names = scene.joint_names
            strings = {f"name.{k}": name for k, name in enumerate(names)}
            strings["header.frame_id"] = ""
            for efforts in (False, True):
                self._joints[efforts] = compile_layout(
                    typestore, SCENE_TOPICS[JOINT_STATES_TOPIC][0], strings,
                    {"name": len(names), "position": len(names), "velocity": len(names),
                     "effort": len(names) if efforts else 0})
        strings, lengths = {}, {"markers": len(self._markers)}
        for k, (name, kind, frame, npoints) in enumerate(self._markers):
            strings[f"markers.{k}.ns"] = f"{scene.system}/{name}"
            strings[f"markers.{k}.header.frame_id"] = frame
            lengths[f"markers.{k}.points"] = npoints
            lengths[f"markers.{k}.colors"] = npoints if kind == SPHERE_LIST else 0
        self._marker_layout = compile_layout(typestore, SCENE_TOPICS[MARKERS_TOPIC][0],
                                             strings, lengths, empty_rest=True)
        self._marker_template = self._constant_markers()

    # -- the constant parts ----------------------------------------------------------------
    def _constant_markers(self) -> npt.NDArray[Any]:
        """One MarkerArray with everything that does not change from sample to sample."""
        m = self._marker_layout.empty(1)
        for k, (_name, kind, _frame, _npoints) in enumerate(self._markers):
            f = f"markers.{k}."
            m[f + "id"] = k
            m[f + "type"] = kind
            m[f + "pose.orientation.w"] = 1.0
            m[f + "frame_locked"] = kind in (CUBE, SPHERE) and k > 0 and not self.tree
            color = {SPHERE_LIST: (1.0, 1.0, 1.0, 1.0), ARROW: ARROW_COLOR}.get(kind)
            for c, v in zip("rgba", color or (GROUND_COLOR if k == 0 else (0, 0, 0, 0))):
                m[f + "color." + c] = v
        m["markers.0.pose.position.z"] = -GROUND_SIZE[2] / 2
        for c, v in zip("xyz", GROUND_SIZE):
            m["markers.0.scale." + c] = v
        for k, s in enumerate(self.scene.shapes, start=1):
            for c, v in zip("rgba", s.color):
                m[f"markers.{k}.color.{c}"] = v
        if self.scene.contacts:
            k = 1 + len(self.scene.shapes)
            for c in "xyz":
                m[f"markers.{k}.scale.{c}"] = CONTACT_DIAMETER
            for j in range(len(self.scene.contacts)):
                for c, v in zip("xyz", ARROW_SCALE):
                    m[f"markers.{k + 1 + j}.scale.{c}"] = v
        return m

    def robot_description(self) -> bytes:
        """The ``std_msgs/msg/String`` CDR of the system's URDF (:meth:`Scene.urdf`)."""
        urdf = self.scene.urdf(self.parameters, np.zeros((1, self.ndof)))
        typename = SCENE_TOPICS["/robot_description"][0]
        msg = self.typestore.types[typename](data=urdf)
        data = bytes(self.typestore.serialize_cdr(msg, typename))
        assert data[:4] == CDR_LE_HEADER
        return data

    # -- per trajectory ----------------------------------------------------------------------
    @staticmethod
    def shown(samples: npt.NDArray[np.float64], rate: float = 0.0) -> npt.NDArray[np.intp]:
        """The rows shown: all but the first of rows with equal time (an event's pre-reset
        row); with ``rate`` > 0 (per unit of simulation time) only the first row of each
        1 / rate interval, every post-reset row and the last row."""
        t = samples[:, 0]
        keep = np.ones(t.size, dtype=bool)
        keep[:-1] = t[:-1] != t[1:]
        if rate > 0 and t.size > 1:
            tick = np.floor(t * rate)
            fresh = np.ones(t.size, dtype=bool)
            fresh[1:] = (tick[1:] != tick[:-1]) | (t[1:] == t[:-1])
            fresh[-1] = True
            keep &= fresh
        return np.flatnonzero(keep)

    def messages(self, samples: npt.NDArray[np.float64], stamp_offset_ns: int,
                 inputs: npt.ArrayLike | None = None
                 ) -> tuple[npt.NDArray[np.int64], dict[str, list[bytes]]]:
        """The stamps (``stamp_offset_ns`` + t) of the shown rows of ``samples``
        (:meth:`shown` at :attr:`rate`) and the CDR of ``/clock``, ``/tf``, the markers and,
        for a tree, ``/joint_states`` at each of them; ``inputs``: the run's inputs (in the
        system's order), the joints' efforts where each joint has one."""
        rows = samples[self.shown(samples, self.rate)]
        d = self.ndof
        stamps = stamp_offset_ns + np.round(rows[:, 0] * NS).astype(np.int64)
        # one row per stamp: distinct times less than half a nanosecond apart (a sample and
        # the end of a step continued after an event, the offsets summed in floating point)
        # round to the same stamp, and /tf takes no stamp twice (the last row: the later state)
        last = np.ones(stamps.size, dtype=bool)
        last[:-1] = stamps[:-1] != stamps[1:]
        rows, stamps = rows[last], stamps[last]
        sec, nsec = stamps // NS, stamps % NS
        state = self.scene.evaluate(rows[:, 1 : 1 + d], self.parameters)
        mode = rows[:, 1 + 2 * d].astype(np.int64)
        lam = rows[:, 2 + 2 * d :]
        out = {"/clock": self._fill_clock(sec, nsec),
               "/tf": self._fill_tf(sec, nsec, state, rows[:, 1 : 1 + d]),
               MARKERS_TOPIC: self._fill_markers(sec, nsec, state, mode, lam)}
        if self.tree:
            out[JOINT_STATES_TOPIC] = self._fill_joints(sec, nsec, rows[:, 1 : 1 + d],
                                                        rows[:, 1 + d : 1 + 2 * d], inputs)
        if self._fresh and len(rows):
            out[MARKERS_TOPIC][0] = self._cleared(out[MARKERS_TOPIC][0])
            self._fresh = False
        return stamps, out

    def _cleared(self, data: bytes) -> bytes:
        """The MarkerArray ``data`` with a DELETEALL marker before its own (same stamp)."""
        typename = SCENE_TOPICS[MARKERS_TOPIC][0]
        msg = self.typestore.deserialize_cdr(data, typename)
        first = msg.markers[0]
        marker_type = self.typestore.types["visualization_msgs/msg/Marker"]
        clear = marker_type(**{**{f: getattr(first, f) for f in first.__dataclass_fields__},
                               "ns": "", "id": 0, "action": DELETEALL,
                               "points": [], "colors": [], "frame_locked": False})
        msg.markers.insert(0, clear)
        return bytes(self.typestore.serialize_cdr(msg, typename))

    def _fill_joints(self, sec: npt.NDArray[np.int64], nsec: npt.NDArray[np.int64],
                     q: npt.NDArray[np.float64], dq: npt.NDArray[np.float64],
                     inputs: npt.ArrayLike | None) -> list[bytes]:
        index = self.scene.joint_inputs
        efforts = inputs is not None and bool(index.size) and bool((index >= 0).all())
        layout = self._joints[efforts]
        m = layout.empty(sec.size)
        m["header.stamp.sec"], m["header.stamp.nanosec"] = sec, nsec
        if index.size:
            m["position"], m["velocity"] = self.scene.joint_states(q, dq)
            if efforts:
                m["effort"] = np.asarray(inputs, dtype=np.float64)[index]
        return layout.serialize(m)

    def _fill_clock(self, sec: npt.NDArray[np.int64], nsec: npt.NDArray[np.int64]
                    ) -> list[bytes]:
        m = self._clock.empty(sec.size)
        m["clock.sec"], m["clock.nanosec"] = sec, nsec
        return self._clock.serialize(m)

    def _fill_tf(self, sec: npt.NDArray[np.int64], nsec: npt.NDArray[np.int64],
                 state: SceneState, q: npt.NDArray[np.float64]) -> list[bytes]:
        layout: FixedLayout = self._tf
        m = layout.empty(sec.size)
        if self.tree:
            position, quaternion = self.scene.base_pose(q)
            positions, quaternions = position[:, None, :], quaternion[:, None, :]
        else:
            positions, quaternions = state.positions, state.quaternions
        for k in range(len(self.tf_frames)):
            f = f"transforms.{k}."
            m[f + "header.stamp.sec"], m[f + "header.stamp.nanosec"] = sec, nsec
            for j, c in enumerate("xyz"):
                m[f + "transform.translation." + c] = positions[:, k, j]
            for j, c in enumerate("xyzw"):
                m[f + "transform.rotation." + c] = quaternions[:, k, j]
        return layout.serialize(m)

    def _fill_markers(self, sec: npt.NDArray[np.int64], nsec: npt.NDArray[np.int64],
                      state: SceneState, mode: npt.NDArray[np.int64],
                      lam: npt.NDArray[np.float64]) -> list[bytes]:
        n = sec.size
        m = np.repeat(self._marker_template, n)
        for k in range(len(self._markers)):
            m[f"markers.{k}.header.stamp.sec"] = sec
            m[f"markers.{k}.header.stamp.nanosec"] = nsec
        where = {frame: i for i, frame in enumerate(self.scene.frames)}
        for k, s in enumerate(self.scene.shapes, start=1):
            f = f"markers.{k}."
            size = state.sizes[s.name]
            if self.tree and s.kind != "line":  # (placed in the world at its frame's pose)
                i = where[s.frame]
                for j, c in enumerate("xyz"):
                    m[f + "pose.position." + c] = state.positions[:, i, j]
                for j, c in enumerate("xyzw"):
                    m[f + "pose.orientation." + c] = state.quaternions[:, i, j]
            if s.kind == "box":
                for j, c in enumerate("xyz"):
                    m[f + "scale." + c] = size[:, j]
            elif s.kind == "sphere":
                for c in "xyz":
                    m[f + "scale." + c] = 2 * size[:, 0]
            else:
                m[f + "scale.x"] = size[:, 0]
                for p in range(s.npoints):
                    for j, c in enumerate("xyz"):
                        m[f"{f}points.{p}.{c}"] = state.points[s.name][:, p, j]
        if self.scene.contacts:
            k = 1 + len(self.scene.shapes)
            for i, j in enumerate(self.scene.contacts):
                active = (mode >> j) & 1 == 1
                for c, (on, off) in zip("rgba", zip(ACTIVE_COLOR, FREE_COLOR)):
                    m[f"markers.{k}.colors.{i}.{c}"] = np.where(active, on, off)
                force = np.where(active, lam[:, j] if j < lam.shape[1] else 0.0, 0.0)
                f = f"markers.{k + 1 + i}."
                for a, c in enumerate("xyz"):
                    at = state.contacts[:, i, a]
                    m[f"markers.{k}.points.{i}.{c}"] = at
                    m[f + f"points.0.{c}"] = at
                    m[f + f"points.1.{c}"] = at + FORCE_SCALE * force * state.normals[:, i, a]
                m[f + "color.a"] = np.where(active, ARROW_COLOR[3], 0.0)
        return self._marker_layout.serialize(m)
