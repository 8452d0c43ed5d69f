"""Rotation matrices for the bodies of a description (SYSTEMS.md Sec. 1a), as SymPy matrices.

A body's ``rotation`` is R with its axes' components as columns, in its parent's frame, so
that a point p of the body is at ``position + R p`` in the parent. The elementary rotations
turn by ``angle`` about one axis of the parent, right-handed (counterclockwise looking down the
axis toward the origin):

- :func:`rotation_x`, :func:`rotation_y`, :func:`rotation_z`;
- :func:`rotation_rpy`: URDF's fixed-axis roll, pitch and yaw, R = Rz(yaw) Ry(pitch) Rx(roll)
  (the same as body-fixed yaw, then pitch, then roll: a free base's usual Euler angles, as the
  looks' ``frame(roll=, pitch=, yaw=)`` of Sec. 6);
- :func:`rotation_xz`: a planar body in the x-z plane turned by ``angle`` from x toward +z,
  which is ``rotation_y(-angle)`` (a right-handed turn about y takes z toward x).
"""

from __future__ import annotations

from typing import Any

import sympy as sp

__all__ = ["rotation_x", "rotation_y", "rotation_z", "rotation_rpy", "rotation_xz"]


def rotation_x(angle: Any) -> sp.Matrix:
    """The rotation by ``angle`` about x: y turns toward z."""
    c, s = sp.cos(angle), sp.sin(angle)
    return sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])


def rotation_y(angle: Any) -> sp.Matrix:
    """The rotation by ``angle`` about y: z turns toward x."""
    c, s = sp.cos(angle), sp.sin(angle)
    return sp.Matrix([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rotation_z(angle: Any) -> sp.Matrix:
    """The rotation by ``angle`` about z: x turns toward y."""
    c, s = sp.cos(angle), sp.sin(angle)
    return sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rotation_rpy(roll: Any, pitch: Any, yaw: Any) -> sp.Matrix:
    """URDF's roll, pitch and yaw: Rz(yaw) Ry(pitch) Rx(roll)."""
    return rotation_z(yaw) * rotation_y(pitch) * rotation_x(roll)


def rotation_xz(angle: Any) -> sp.Matrix:
    """A planar body's rotation in the x-z plane, x turned toward +z by ``angle``."""
    return rotation_y(-angle)
