"""QoS profiles with rclpy's names, mapped to Cyclone DDS policies.

Profiles and defaults follow rmw (ROS.md Sec. 2): default and services KEEP_LAST 10 RELIABLE
VOLATILE, sensor data KEEP_LAST 5 BEST_EFFORT VOLATILE, parameters KEEP_LAST 1000.
Every DDS entity is XCDR1-only, as rmw_cyclonedds is.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace

from cyclonedds.core import Policy, Qos
from cyclonedds.util import duration

__all__ = [
    "HistoryPolicy", "ReliabilityPolicy", "DurabilityPolicy", "QoSProfile",
    "qos_profile_system_default", "qos_profile_sensor_data", "qos_profile_services_default",
    "qos_profile_parameters", "to_dds_qos", "as_profile",
]


class HistoryPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


class ReliabilityPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class DurabilityPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


@dataclass
class QoSProfile:
    """rclpy.qos.QoSProfile subset: ``QoSProfile(depth=10, reliability=...)``."""

    history: HistoryPolicy = HistoryPolicy.KEEP_LAST
    depth: int = 10
    reliability: ReliabilityPolicy = ReliabilityPolicy.RELIABLE
    durability: DurabilityPolicy = DurabilityPolicy.VOLATILE

    def __post_init__(self) -> None:
        self.history = HistoryPolicy(self.history)
        self.reliability = ReliabilityPolicy(self.reliability)
        self.durability = DurabilityPolicy(self.durability)
        if self.history == HistoryPolicy.KEEP_LAST and int(self.depth) < 1:
            raise ValueError("QoSProfile: depth must be >= 1 with KEEP_LAST history")


qos_profile_system_default = QoSProfile()
qos_profile_services_default = QoSProfile()
qos_profile_sensor_data = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
qos_profile_parameters = QoSProfile(depth=1000)


def as_profile(qos: QoSProfile | int) -> QoSProfile:
    """rclpy accepts a depth in place of a profile (KEEP_LAST depth, otherwise default)."""
    if isinstance(qos, QoSProfile):
        return replace(qos)
    if isinstance(qos, int) and not isinstance(qos, bool):
        return QoSProfile(depth=qos)
    raise TypeError(f"qos_profile must be a QoSProfile or an int depth, got {qos!r}")


def to_dds_qos(profile: QoSProfile, user_data: bytes | None = None) -> Qos:
    """Cyclone ``Qos`` of a profile (XCDR1, optional USER_DATA)."""
    policies = [Policy.DataRepresentation(use_cdrv0_representation=True)]
    if profile.history == HistoryPolicy.KEEP_ALL:
        policies.append(Policy.History.KeepAll)
    else:
        policies.append(Policy.History.KeepLast(depth=int(profile.depth)))
    if profile.reliability == ReliabilityPolicy.BEST_EFFORT:
        policies.append(Policy.Reliability.BestEffort)
    else:
        policies.append(Policy.Reliability.Reliable(max_blocking_time=duration(seconds=1)))
    if profile.durability == DurabilityPolicy.TRANSIENT_LOCAL:
        policies.append(Policy.Durability.TransientLocal)
    else:
        policies.append(Policy.Durability.Volatile)
    if user_data is not None:
        policies.append(Policy.Userdata(data=user_data))
    return Qos(*policies)
