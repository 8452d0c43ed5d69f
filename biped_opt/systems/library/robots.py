"""Robots from their URDFs (SYSTEMS.md Sec. 3c): vendored files in ``robots/<name>/`` (their
sources and licences beside them), imported by :mod:`biped_opt.systems.urdf` with the contacts,
locked joints and posture each one needs.

- ``solo12``: the quadruped of the Open Dynamic Robot Initiative, point feet at the
  ``*_FOOT`` frames (BSD-3-Clause);
- ``bolt``: the same initiative's biped, point feet (BSD-3-Clause);
- ``g1``: Unitree's G1 humanoid with its waist and arms locked, its feet the four collision
  spheres under each sole (flat feet: dependent contacts) (BSD-3-Clause).

The postures are the ``standing`` states of solo12's and bolt's SRDFs in example-robot-data
and, for g1, hips, knees and ankles pitched by -0.1, 0.3 and -0.2 (its soles level). PAL's
Talos, the issue's example, is not here: its URDF in example-robot-data carries a Creative
Commons NonCommercial-NoDerivs notice in the file itself, whatever the package's README says.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from biped_opt.systems.description import System

__all__ = ["solo12", "bolt", "g1", "ROBOTS", "ROBOT_SIZES", "ROBOT_FILES", "FOLDER"]

#: where the vendored URDFs are
FOLDER = Path(__file__).resolve().parent / "robots"
#: name -> the vendored URDF
ROBOT_FILES = {"solo12": FOLDER / "solo12" / "solo12.urdf", "bolt": FOLDER / "bolt" / "bolt.urdf",
               "g1": FOLDER / "g1" / "g1_29dof_rev_1_0.urdf"}

_LEGS4 = ("FL", "FR", "HL", "HR")


def solo12() -> System:
    """Solo-12: 18 coordinates (a floating base and three hinges per leg), four point feet."""
    from biped_opt.systems.urdf import system_from_urdf

    posture = {}
    for leg in _LEGS4:
        front = leg[0] == "F"
        posture[f"{leg}_HAA"] = 0.0
        posture[f"{leg}_HFE"] = 0.8 if front else -0.8
        posture[f"{leg}_KFE"] = -1.6 if front else 1.6
    return system_from_urdf(ROBOT_FILES["solo12"], name="solo12",
                            contacts=[f"{leg}_FOOT" for leg in _LEGS4], posture=posture)


def bolt() -> System:
    """Bolt: 12 coordinates (a floating base and three hinges per leg), two point feet."""
    from biped_opt.systems.urdf import system_from_urdf

    posture = {}
    for leg, side in (("FL", -1), ("FR", 1)):
        posture[f"{leg}_HAA"] = 0.3 * side
        posture[f"{leg}_HFE"] = 0.78539816
        posture[f"{leg}_KFE"] = -1.57079633
    return system_from_urdf(ROBOT_FILES["bolt"], name="bolt", contacts=["FL_FOOT", "FR_FOOT"],
                            posture=posture)


#: g1's standing posture (hips and ankles pitched so that the soles stay level)
G1_POSTURE = {f"{side}_{joint}": value for side in ("left", "right")
              for joint, value in (("hip_pitch_joint", -0.1), ("knee_joint", 0.3),
                                   ("ankle_pitch_joint", -0.2))}


def g1() -> System:
    """Unitree G1: 18 coordinates (a floating base and six hinges per leg; the waist and arms
    locked), eight contacts: the four collision spheres under each sole."""
    from biped_opt.systems.urdf import system_from_urdf

    return system_from_urdf(ROBOT_FILES["g1"], name="g1",
                            contacts=["left_ankle_roll_link", "right_ankle_roll_link"],
                            lock=["waist_*", "*_shoulder_*", "*_elbow_*", "*_wrist_*"],
                            posture=G1_POSTURE)


#: the robots by name, built only when named (importing takes about a second)
ROBOTS: dict[str, Callable[[], System]] = {"solo12": solo12, "bolt": bolt, "g1": g1}
#: (constraints, coordinates) of each, known without building it
ROBOT_SIZES: dict[str, tuple[int, int]] = {"solo12": (4, 18), "bolt": (2, 12), "g1": (8, 18)}
