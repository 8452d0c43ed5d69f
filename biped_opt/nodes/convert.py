"""Conversions between the core's values and biped_opt_interfaces messages.

Array fields are read with ``np.asarray`` (rclpy gives ``array.array``/numpy, the built-in backend
lists) and written as plain float lists, which every backend accepts.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from biped_opt import ros
from biped_opt.errors import InvalidInputError
from biped_opt.hybrid.trajectory import Trajectory
from biped_opt.maneuvers import Maneuver, check_theta0, parse_maneuver

__all__ = [
    "NS",
    "stamp",
    "stamp_ns",
    "request_maneuver",
    "request_theta0",
    "state_messages",
    "contact_mode_messages",
]

NS = 1_000_000_000
FRAME_ID = "biped"


def stamp(ns: int) -> Any:
    """builtin_interfaces/Time from integer nanoseconds."""
    msg = ros.std_msgs.Header().stamp.__class__()
    msg.sec = int(ns // NS)
    msg.nanosec = int(ns % NS)
    return msg


def stamp_ns(t: Any) -> int:
    return int(t.sec) * NS + int(t.nanosec)


def header(ns: int) -> Any:
    h = ros.std_msgs.Header()
    h.stamp = stamp(ns)
    h.frame_id = FRAME_ID
    return h


def request_maneuver(text: str, allowed: tuple[Maneuver, ...] = tuple(Maneuver)) -> Maneuver:
    """The request's maneuver; the error names the field."""
    try:
        maneuver = parse_maneuver(text)
    except InvalidInputError as exc:
        raise InvalidInputError(f"maneuver: {exc}") from None
    if maneuver not in allowed:
        raise InvalidInputError(f"maneuver: {maneuver.value} is not served here")
    return maneuver


def request_theta0(maneuver: Maneuver, value: float) -> float:
    """The request's theta0, finite and in the maneuver's range; the error names the field."""
    try:
        return check_theta0(maneuver, value)
    except InvalidInputError as exc:
        raise InvalidInputError(f"theta0: {exc}") from None


def request_inputs(values: Any) -> npt.NDArray[np.float64]:
    arr = np.asarray(values, dtype=np.float64).ravel()
    if arr.size > 3:
        raise InvalidInputError(f"inputs: at most 3 values (u1, u2, u12), got {arr.size}")
    if not np.isfinite(arr).all():
        raise InvalidInputError(f"inputs: must be finite, got {arr.tolist()}")
    out = np.zeros(3)
    out[: arr.size] = arr
    return out


def state_messages(tr: Trajectory, start_ns: int) -> list[Any]:
    """One BipedState per dense sample of ``tr`` (two at each event: before and after)."""
    if tr.samples is None:
        raise ValueError("the trajectory has no samples; simulate with sample_dt")
    out = []
    for row in tr.samples:
        msg = ros.msgs.BipedState()
        msg.header = header(start_ns + round(row[0] * NS))
        msg.maneuver = tr.maneuver
        msg.theta0 = float(tr.theta0)
        msg.t = float(row[0])
        msg.q = [float(v) for v in row[1:8]]
        msg.qdot = [float(v) for v in row[8:15]]
        msg.contact_mode = int(row[15])
        msg.contact_force = [float(row[16]), float(row[17])]
        out.append(msg)
    return out


def contact_mode_messages(tr: Trajectory, start_ns: int) -> list[tuple[float, Any]]:
    """(t, ContactMode) for the initial mode and every change; the header stamp is the run's
    start plus the exact event time."""
    out = []
    for t, mode in tr.modes:
        msg = ros.msgs.ContactMode()
        msg.header = header(start_ns + round(t * NS))
        msg.mode = int(mode)
        out.append((t, msg))
    return out


def finite(value: float) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value)
