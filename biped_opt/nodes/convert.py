"""Conversions between the core's values and biped_opt_interfaces messages.

Array fields are read with ``np.asarray`` (rclpy gives ``array.array``/numpy, the built-in backend
lists) and written as plain float lists, which every backend accepts.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from biped_opt import ros
from biped_opt.errors import BipedOptError, InvalidInputError, quoted
from biped_opt.nodes.sources import PROBLEM_SUFFIXES, check_maneuver_of, check_problem_on
from biped_opt.paper.biped import Maneuver, check_theta0, parse_maneuver
from biped_opt.simulation.trajectory import Trajectory

if TYPE_CHECKING:  # the systems' modules (SymPy) load only where a system is used
    from biped_opt.control.problems import Problem
    from biped_opt.simulation.compiled import CompiledSystem, SystemTrajectory

__all__ = [
    "NS",
    "stamp",
    "stamp_ns",
    "request_maneuver",
    "request_theta0",
    "state_messages",
    "contact_mode_messages",
    "SYSTEM_INFO_FIELDS",
    "system_info_fields",
    "message_fields",
    "request_system_maneuver",
    "request_s",
    "request_system_inputs",
    "system_state_messages",
    "request_problem",
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


def header(ns: int, frame_id: str = FRAME_ID) -> Any:
    h = ros.std_msgs.Header()
    h.stamp = stamp(ns)
    h.frame_id = frame_id
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
    for segment in tr.segments:
        t = segment.t_start
        msg = ros.msgs.ContactMode()
        msg.header = header(start_ns + round(t * NS))
        msg.mode = segment.mask
        out.append((t, msg))
    return out


# -- any system (biped_opt.systems) ----------------------------------------------------------

#: the fields of SystemInfo, in its order
SYSTEM_INFO_FIELDS = ("system", "source", "coordinates", "constraints", "inputs",
                      "parameter_names", "parameter_values", "maneuvers", "s_min", "s_max")


def system_info_fields(compiled: CompiledSystem, source: str) -> dict[str, Any]:
    """SystemInfo's fields (plain str, list and float values) for ``compiled``, loaded from
    ``source`` (a library name or a file path)."""
    ranges = [compiled.s_range(m) for m in compiled.maneuvers]
    return {
        "system": compiled.name, "source": source,
        "coordinates": list(compiled.coordinates), "constraints": list(compiled.constraints),
        "inputs": list(compiled.inputs), "parameter_names": list(compiled.parameters),
        "parameter_values": [float(v) for v in compiled.parameters.values()],
        "maneuvers": list(compiled.maneuvers), "s_min": [float(lo) for lo, _ in ranges],
        "s_max": [float(hi) for _, hi in ranges],
    }


def message_fields(msg: Any, names: tuple[str, ...]) -> dict[str, Any]:
    """``names`` of a message as plain values (arrays as lists), from any backend."""
    out: dict[str, Any] = {}
    for name in names:
        value = getattr(msg, name)
        out[name] = value if isinstance(value, (str, int, float)) else [
            v if isinstance(v, str) else float(v) for v in value]
    return out


def request_system_maneuver(compiled: CompiledSystem, text: str) -> str:
    """The request's maneuver, one of the system's; the error names the field."""
    if text not in compiled.maneuvers:
        raise InvalidInputError(
            f"maneuver: {compiled.name} has no maneuver {quoted(text)} "
            f"(maneuvers: {', '.join(compiled.maneuvers) or 'none'})")
    return text


def request_s(value: float) -> float:
    """The request's s (Simulate.theta0 for a non-biped system): finite; the error names the
    field. The maneuver's s range is advice, not a limit (outside it other mode sequences
    appear), so it is not enforced."""
    if not finite(value):
        raise InvalidInputError(f"theta0: the maneuver's s must be finite, got {value}")
    return float(value)


def request_system_inputs(compiled: CompiledSystem, values: Any) -> list[float]:
    """The request's inputs for ``compiled`` in its declared order, padded with zeros."""
    arr = np.asarray(values, dtype=np.float64).ravel()
    names = compiled.inputs
    if arr.size > len(names) and not arr[len(names):].any():
        arr = arr[: len(names)]  # trailing zeros say nothing (a system without inputs: [0.0])
    if arr.size > len(names):
        raise InvalidInputError(
            f"inputs: at most {len(names)} values ({', '.join(names) or 'none'}) for "
            f"{compiled.name}, got {arr.size}")
    if not np.isfinite(arr).all():
        raise InvalidInputError(f"inputs: must be finite, got {arr.tolist()}")
    out = [0.0] * len(names)
    out[: arr.size] = arr.tolist()
    return out


def system_state_messages(tr: SystemTrajectory, ndof: int, start_ns: int) -> list[Any]:
    """One SystemState per dense sample of ``tr`` (rows [t, q, qdot, mode, lambda]; two at
    each event: before and after); the frame id is the system's name."""
    d = ndof
    out = []
    for row in tr.samples:
        msg = ros.msgs.SystemState()
        msg.header = header(start_ns + round(row[0] * NS), tr.system)
        msg.system = tr.system
        msg.maneuver = tr.maneuver
        msg.s = float(tr.s)
        msg.t = float(row[0])
        msg.q = [float(v) for v in row[1 : 1 + d]]
        msg.qdot = [float(v) for v in row[1 + d : 1 + 2 * d]]
        msg.contact_mode = int(row[1 + 2 * d])
        msg.contact_force = [float(v) for v in row[2 + 2 * d :]]
        out.append(msg)
    return out


def finite(value: float) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value)


def _is_file(text: str) -> bool:
    return Path(text).suffix in PROBLEM_SUFFIXES


def request_problem(system: str, problem: str, maneuver: str) -> Problem:
    """The :class:`~biped_opt.control.problems.Problem` of an operator's parameters on any
    system (the recorder's): ``system`` a library name or a system file (``""``: the biped, or
    the system a problem file names), ``problem`` one the system declares or a problem file
    (``""``: the one named like ``maneuver``), which must be on ``maneuver``. Each error names
    the field. (A request from the domain names files only through
    :mod:`biped_opt.nodes.sources`.)"""
    from biped_opt.control.problems import load_problem
    from biped_opt.simulation.facts import describe

    described = None
    if system or not _is_file(problem):
        try:
            described = describe(system or "biped")
        except BipedOptError as exc:
            raise InvalidInputError(f"system: {exc}") from None
        if not problem:
            check_maneuver_of(described, maneuver)
    try:
        found = load_problem(problem or maneuver, system=system or "biped")
    except BipedOptError as exc:
        raise InvalidInputError(f"problem: {exc}") from None
    return check_problem_on(found, described, maneuver)
