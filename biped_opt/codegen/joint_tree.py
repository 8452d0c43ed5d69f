"""A system of bodies as a tree of standard joints, for ``/robot_description`` (ROS.md Sec. 6).

A description written with :meth:`~biped_opt.systems.description.System.body` gives each body's
pose in its parent's frame as expressions of q and the parameters. :func:`body_tree` finds, where
there is one, the tree of standard joints those expressions are: the root body on a floating
base whose position is three coordinates and whose axes are R = Rz(yaw) Ry(pitch) Rx(roll) of
three others, and every other body on a chain of hinges -- its origin fixed in its parent's frame
(an expression of the parameters only) and its axes R0 Rot(a1, +-q1) Rot(a2, +-q2) ..., R0 not
depending on q, each a_k a frame axis and each coordinate moving one hinge. A chain of several
hinges gets a massless link between two of them (``<coordinate>_link``). The check is numeric, at
the default parameters and a few random configurations, to 1e-12; a system that fails it (or
declares no bodies) has no tree, and keeps one transform per frame.

The URDF depends on the parameters (lengths, masses), which change at run time without a
recompile, so it is kept as a template (:attr:`JointTree.template`, numbers as ``{k}``) whose
numbers are the expressions :attr:`JointTree.values`, rendered into the scene module as
``tree_values(p)`` (:mod:`biped_opt.codegen.scene`).
"""

from __future__ import annotations

import itertools
import weakref
from dataclasses import dataclass, field
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np
import sympy as sp

from biped_opt.systems.description import System

__all__ = ["JointTree", "body_tree", "tree_of"]

#: how closely a pose must match a chain of standard joints (numbers of order 1)
TOL = 1e-12
#: random configurations the check uses
CHECKS = 3
_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


@dataclass
class JointTree:
    """A tree of standard joints found in a system of bodies (see the module docstring)."""

    base: str  #: the root body's link
    base_coordinates: list[int]  #: indices in q of x, y, z, roll, pitch, yaw
    joints: list[list[Any]]  #: per hinge: [coordinate name, its index in q, 0.0, -1]
    template: str = ""
    values: list[sp.Expr] = field(default_factory=list)

    def facts(self) -> dict[str, Any]:
        """As :func:`biped_opt.systems.urdf.tree_facts` gives them, with the URDF a template."""
        return {"urdf_template": self.template, "base": self.base,
                "base_coordinates": self.base_coordinates, "base_pose": None,
                "joints": self.joints}


_FOUND: weakref.WeakKeyDictionary[System, JointTree | None] = weakref.WeakKeyDictionary()


def tree_of(system: System) -> JointTree | None:
    """:func:`body_tree`, found once per system object (the scene's module and its facts both
    need it)."""
    if system not in _FOUND:
        _FOUND[system] = body_tree(system)
    return _FOUND[system]


def _turn(axis: str, sign: int, angle: float) -> np.ndarray:
    c, s = np.cos(sign * angle), np.sin(sign * angle)
    if axis == "x":
        return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    if axis == "y":
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    return _turn("z", 1, yaw) @ _turn("y", 1, pitch) @ _turn("x", 1, roll)


def body_tree(system: System) -> JointTree | None:
    """The tree of standard joints of ``system``'s bodies, or None (see the module docstring)."""
    if not system.bodies or system.robot is not None:
        return None
    q = list(system.q)
    index = {sym: k for k, sym in enumerate(q)}
    params = list(system.p)
    defaults = np.array([system.defaults[str(p)] for p in params])
    rng = np.random.default_rng(0)
    samples = rng.uniform(-1.0, 1.0, (CHECKS, len(q)))
    used: set[int] = set()
    bodies = list(system.bodies.values())
    roots = [b for b in bodies if b.parent is None]
    if len(roots) != 1:
        return None

    def numeric(expr: Any) -> Any:
        f = sp.lambdify([q, params], sp.Matrix(expr), "numpy")
        return lambda qv: np.asarray(f(qv, defaults), dtype=float)

    def rotation(body: Any) -> sp.Matrix:
        return sp.eye(3) if body.rotation is None else sp.Matrix(body.rotation)

    values: list[sp.Expr] = []

    def number(expr: Any) -> str:
        values.append(sp.sympify(expr))
        return "{" + str(len(values) - 1) + "}"

    def origin(p: Any, R0: sp.Matrix) -> str:
        roll = sp.atan2(R0[2, 1], R0[2, 2])
        pitch = sp.asin(-R0[2, 0])
        yaw = sp.atan2(R0[1, 0], R0[0, 0])
        xyz = " ".join(number(v) for v in p)
        rpy = " ".join(number(sp.simplify(v)) for v in (roll, pitch, yaw))
        return f'<origin xyz="{xyz}" rpy="{rpy}"/>'

    links: list[str] = []

    def link(name: str, body: Any | None) -> None:
        if body is None or sp.sympify(body.mass) == 0:
            links.append(f"  <link name={quoteattr(name)}/>")
            return
        inertia = sp.Matrix(body.inertia)
        xx, xy, xz, yy, yz, zz = (number(inertia[i, j]) for i, j in
                                  ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)))
        centre = " ".join(number(v) for v in body.centre)
        links.append("\n".join([
            f"  <link name={quoteattr(name)}>", "    <inertial>",
            f'      <origin xyz="{centre}" rpy="0 0 0"/>',
            f'      <mass value="{number(body.mass)}"/>',
            f'      <inertia ixx="{xx}" ixy="{xy}" ixz="{xz}" iyy="{yy}" iyz="{yz}" '
            f'izz="{zz}"/>', "    </inertial>", "  </link>"]))

    # the root: a floating base
    root = roots[0]
    position = [sp.sympify(v) for v in root.position]
    if not all(v in index for v in position) or len(set(position)) != 3:
        return None
    base = [index[v] for v in position]
    R = rotation(root)
    rest = sorted({index[s] for s in R.free_symbols if s in index} - set(base))
    if len(rest) != 3:
        return None
    f = numeric(R)
    for roll, pitch, yaw in itertools.permutations(rest):
        if all(np.abs(f(qv) - _rpy(qv[roll], qv[pitch], qv[yaw])).max() <= TOL
               for qv in samples):
            base += [roll, pitch, yaw]
            break
    else:
        return None
    used.update(base)
    link(root.name, root)
    joints_xml: list[str] = []
    joints: list[list[Any]] = []
    for body in bodies:
        if body is root:
            continue
        if body.parent is None or body.parent not in system.bodies:
            return None
        p = sp.Matrix([sp.sympify(v) for v in body.position])
        if p.free_symbols & set(q):
            return None  # (a slider, or a point that moves: not a hinge chain)
        R = rotation(body)
        coords = sorted({index[s] for s in R.free_symbols if s in index})
        if any(c in used for c in coords) or len(coords) > 3:
            return None
        f = numeric(R)
        zero = {q[c]: 0 for c in coords}
        R0 = R.xreplace(zero)
        g = numeric(R0)
        chain = None
        for order in itertools.permutations(coords):
            for axes in itertools.product("xyz", repeat=len(order)):
                for signs in itertools.product((1, -1), repeat=len(order)):
                    ok = True
                    for qv in samples:
                        want = g(qv)
                        for c, a, s in zip(order, axes, signs):
                            want = want @ _turn(a, s, qv[c])
                        if np.abs(f(qv) - want).max() > TOL:
                            ok = False
                            break
                    if ok:
                        chain = list(zip(order, axes, signs))
                        break
                if chain is not None:
                    break
            if chain is not None:
                break
        if chain is None:
            return None
        used.update(coords)
        parent = body.parent
        if not chain:  # (fixed to its parent)
            joints_xml.append("\n".join([
                f"  <joint name={quoteattr(body.name + '_fixed')} type=\"fixed\">",
                f"    {origin(p, R0)}", f"    <parent link={quoteattr(parent)}/>",
                f"    <child link={quoteattr(body.name)}/>", "  </joint>"]))
        for k, (c, a, s) in enumerate(chain):
            name = str(q[c])
            child = body.name if k == len(chain) - 1 else f"{name}_link"
            placed = origin(p, R0) if k == 0 else '<origin xyz="0 0 0" rpy="0 0 0"/>'
            axis = " ".join(repr(s * v + 0.0) for v in _AXES[a])
            joints_xml.append("\n".join([
                f"  <joint name={quoteattr(name)} type=\"continuous\">", f"    {placed}",
                f"    <parent link={quoteattr(parent)}/>", f"    <child link={quoteattr(child)}/>",
                f'    <axis xyz="{axis}"/>', "  </joint>"]))
            joints.append([name, c, 0.0, -1])
            if child != body.name:
                link(child, None)
            parent = child
        link(body.name, body)
    if used != set(range(len(q))):
        return None  # (a coordinate that moves no joint)
    template = "\n".join(['<?xml version="1.0"?>', f"<robot name={quoteattr(system.name)}>",
                          *links, *joints_xml, "</robot>"]) + "\n"
    return JointTree(base=root.name, base_coordinates=base, joints=joints, template=template,
                    values=values)
