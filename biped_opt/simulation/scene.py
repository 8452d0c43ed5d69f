"""Where a system's bodies are: frames, shapes and contact points at every sample of a run.

:class:`Scene` reads the generated ``scene_values`` (:mod:`biped_opt.codegen.scene`) of a compiled
system and turns its columns into poses (positions and unit quaternions in the world frame),
shape sizes, line points and contact points, for a whole trajectory in one call
(:meth:`Scene.evaluate`). :meth:`Scene.urdf` writes the description as a URDF (SYSTEMS.md
Sec. 6), which is what ``/robot_description`` carries: for a system that is a tree of standard
joints (:attr:`Scene.tree`: one imported from a URDF) the robot itself, its joints, inertias and
collision shapes (:func:`biped_opt.systems.urdf.description_urdf`), whose joint values
(:meth:`Scene.joint_states`) and base pose (:meth:`Scene.base_pose`) place every link as
robot_state_publisher does; for any other the world link and one link per frame on a floating
joint, with the frame's boxes and spheres as visuals. Nothing here imports ROS.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np
import numpy.typing as npt

__all__ = ["Scene", "SceneState", "ShapeInfo", "quaternions"]

Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class ShapeInfo:
    """A shape of the scene (see :class:`biped_opt.systems.description.Shape`)."""

    name: str
    kind: str  #: "box", "sphere" or "line"
    frame: str  #: the frame it is fixed in ("world" for a line)
    color: tuple[float, float, float, float]
    npoints: int  #: a line's number of points (0 otherwise)

    @property
    def nsize(self) -> int:
        return 3 if self.kind == "box" else 1


@dataclass(frozen=True)
class SceneState:
    """The scene at n samples: ``positions`` (n, F, 3) and ``quaternions`` (n, F, 4, as x, y,
    z, w) of the frames; ``sizes`` and ``points`` of each shape by name ((n, 3) or (n, 1) and
    (n, P, 3)); ``contacts`` and ``normals`` (n, C, 3) of the contact points."""

    positions: Array
    quaternions: Array
    sizes: dict[str, Array]
    points: dict[str, Array]
    contacts: Array
    normals: Array


def quaternions(rpy: Array) -> Array:
    """Unit quaternions (x, y, z, w) of fixed-axis roll, pitch, yaw rotations (URDF's rpy:
    R = Rz(yaw) Ry(pitch) Rx(roll)); ``rpy`` has the angles in its last axis."""
    half = 0.5 * np.asarray(rpy, dtype=np.float64)
    cr, cp, cy = np.cos(half[..., 0]), np.cos(half[..., 1]), np.cos(half[..., 2])
    sr, sp, sy = np.sin(half[..., 0]), np.sin(half[..., 1]), np.sin(half[..., 2])
    return np.stack([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy], axis=-1)


class Scene:
    """The drawable parts of a compiled system (see the module docstring)."""

    def __init__(self, system: str, facts: dict[str, Any],
                 values: Callable[[Array, Array], Array], constraints: tuple[str, ...],
                 tree_values: Callable[[Array], Array] | None = None) -> None:
        self.system = system
        #: the fixed frame (the description's name for it, kept in the facts: reading it from
        #: the description would import SymPy on a cached start)
        self.world: str = facts["world"]
        self.frames: tuple[str, ...] = tuple(facts["frames"])
        self.shapes: tuple[ShapeInfo, ...] = tuple(
            ShapeInfo(s["name"], s["kind"], s["frame"], tuple(s["color"]),
                      int(s["points"])) for s in facts["shapes"])
        #: the constraints with a contact point, by index (bit j of a contact mode)
        self.contacts: tuple[int, ...] = tuple(int(j) for j in facts["contacts"])
        self.contact_names = tuple(constraints[j] for j in self.contacts)
        #: the tree of joints (:func:`biped_opt.systems.urdf.tree_facts`), None for a system
        #: that is not one
        self.tree: dict[str, Any] | None = facts.get("tree")
        self._values = values
        #: a tree of bodies' URDF numbers at given parameters (codegen/joint_tree.py)
        self._tree_values = tree_values
        if self.tree is not None and "urdf" not in self.tree and tree_values is None:
            self.tree = None  # (a template without its numbers: shown as frames instead)
        if self.tree is not None:
            joints = self.tree["joints"]
            #: the joints on ``/joint_states``, their coordinates' indices (-1: locked), their
            #: locked values and their efforts' indices among the inputs (-1: none)
            self.joint_names: tuple[str, ...] = tuple(str(j[0]) for j in joints)
            self._joint_q = np.array([int(j[1]) for j in joints], dtype=np.intp)
            self._joint_locked = np.array([float(j[2]) for j in joints])
            self.joint_inputs = np.array([int(j[3]) for j in joints], dtype=np.intp)

    @property
    def empty(self) -> bool:
        """Nothing declared: no frame, no shape, no contact point."""
        return not (self.frames or self.shapes or self.contacts)

    def evaluate(self, q: npt.ArrayLike, parameters: npt.ArrayLike) -> SceneState:
        """The scene at the rows of ``q`` ((n, d) coordinates) for the parameter values
        ``parameters`` (their declared order)."""
        q = np.atleast_2d(np.asarray(q, dtype=np.float64))
        cols = self._values(q, np.asarray(parameters, dtype=np.float64))
        cols = np.broadcast_to(cols, (q.shape[0], cols.shape[1]))
        n, k = q.shape[0], 0
        nf = len(self.frames)
        frames = cols[:, : 6 * nf].reshape(n, nf, 6)
        k = 6 * nf
        sizes: dict[str, Array] = {}
        points: dict[str, Array] = {}
        for s in self.shapes:
            sizes[s.name] = cols[:, k : k + s.nsize]
            k += s.nsize
            points[s.name] = cols[:, k : k + 3 * s.npoints].reshape(n, s.npoints, 3)
            k += 3 * s.npoints
        contact = cols[:, k:].reshape(n, len(self.contacts), 2, 3)
        return SceneState(positions=frames[:, :, :3], quaternions=quaternions(frames[:, :, 3:]),
                          sizes=sizes, points=points, contacts=contact[:, :, 0],
                          normals=contact[:, :, 1])

    @property
    def base(self) -> str | None:
        """The link whose pose in :attr:`world` goes on ``/tf`` (None: not a tree)."""
        return None if self.tree is None else str(self.tree["base"])

    def base_pose(self, q: npt.ArrayLike) -> tuple[Array, Array]:
        """The position (n, 3) and unit quaternion (n, 4, x y z w) of :attr:`base` in the world
        at the rows of ``q``: the floating base's coordinates or the fixed base's pose."""
        assert self.tree is not None
        q = np.atleast_2d(np.asarray(q, dtype=np.float64))
        index = self.tree["base_coordinates"]
        pose = (q[:, index] if index is not None else
                np.broadcast_to(np.asarray(self.tree["base_pose"], dtype=np.float64),
                                (q.shape[0], 6)))
        return pose[:, :3], quaternions(pose[:, 3:])

    def joint_states(self, q: npt.ArrayLike, dq: npt.ArrayLike) -> tuple[Array, Array]:
        """Positions and velocities (n, J) of the joints :attr:`joint_names` at the rows of
        ``q`` and ``dq`` (a locked joint: its value, at rest)."""
        q = np.atleast_2d(np.asarray(q, dtype=np.float64))
        dq = np.atleast_2d(np.asarray(dq, dtype=np.float64))
        free = self._joint_q >= 0
        at = np.where(free, self._joint_q, 0)
        positions = np.where(free, q[:, at], self._joint_locked)
        velocities = np.where(free, dq[:, at], 0.0)
        return positions, velocities

    def urdf(self, parameters: npt.ArrayLike, q: npt.ArrayLike) -> str:
        """The URDF of the system (see the module docstring); shape sizes for ``parameters``,
        ``q`` any configuration (sizes do not depend on it)."""
        if self.tree is not None:
            if "urdf" in self.tree:
                return str(self.tree["urdf"])
            assert self._tree_values is not None
            numbers = self._tree_values(np.asarray(parameters, dtype=np.float64))
            return str(self.tree["urdf_template"]).format(*(repr(float(v)) for v in numbers))
        state = self.evaluate(q, parameters)
        out = ['<?xml version="1.0"?>', f"<robot name={quoteattr(self.system)}>",
               f"  <link name={quoteattr(self.world)}/>"]
        for frame in self.frames:
            out.append(f"  <link name={quoteattr(frame)}>")
            for s in self.shapes:
                if s.frame != frame:
                    continue
                size = state.sizes[s.name][0]
                geometry = (f'<box size="{size[0]:.9g} {size[1]:.9g} {size[2]:.9g}"/>'
                            if s.kind == "box" else f'<sphere radius="{size[0]:.9g}"/>')
                rgba = " ".join(f"{c:.9g}" for c in s.color)
                out += [f"    <visual name={quoteattr(s.name)}>",
                        f"      <geometry>{geometry}</geometry>",
                        f'      <material name={quoteattr(s.name)}><color rgba="{rgba}"/>'
                        "</material>", "    </visual>"]
            out.append("  </link>")
        for frame in self.frames:
            out += [f"  <joint name={quoteattr(frame + '_joint')} type=\"floating\">",
                    f"    <parent link={quoteattr(self.world)}/>",
                    f"    <child link={quoteattr(frame)}/>", "  </joint>"]
        out.append("</robot>")
        return "\n".join(out) + "\n"
