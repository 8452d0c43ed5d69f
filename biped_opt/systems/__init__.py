"""Mechanical systems subject to unilateral constraints, described symbolically (SYSTEMS.md).

:class:`System` is what a user writes; :func:`derive` checks it and derives Da and
(d/dt Da) q'; :class:`NumericSystem` evaluates Eq. (1) for it with NumPy. The library holds the
paper's biped, the n-leg walker and the rocking bar, and robots from their URDFs
(:func:`system_from_urdf`, also ``System.from_urdf``).
"""

from __future__ import annotations

from biped_opt.systems.derive import DerivedSystem, NumericSystem, derive, mode_mask
from biped_opt.systems.description import ManeuverDescription, System, SystemDescriptionError
from biped_opt.systems.files import load_system
from biped_opt.systems.library import LIBRARY, biped, rocking_bar, walker
from biped_opt.systems.rotations import (
    rotation_rpy,
    rotation_x,
    rotation_xz,
    rotation_y,
    rotation_z,
)
from biped_opt.systems.urdf import system_from_urdf

__all__ = ["System", "ManeuverDescription", "SystemDescriptionError", "DerivedSystem",
           "NumericSystem", "derive", "mode_mask", "load_system", "LIBRARY", "biped",
           "rocking_bar", "walker", "rotation_x", "rotation_y", "rotation_z", "rotation_rpy",
           "rotation_xz", "system_from_urdf"]
