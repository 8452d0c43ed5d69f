"""Recording sweeps to MCAP (ROS 2 profile) and reading them back (MCAP.md).

The names below are imported from their modules when first used: a command that only writes a
study's CSV table (:mod:`biped_opt.record.study_table`) does not pay for the writer's ROS
message types and DDS backend (a third of a second).
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = [
    "TOPICS",
    "RecordError",
    "RecordedMessage",
    "Recording",
    "SweepWriter",
    "read_recording",
]

_HOMES = {"TOPICS": "writer", "RecordError": "writer", "SweepWriter": "writer",
          "RecordedMessage": "reader", "Recording": "reader", "read_recording": "reader"}


def __getattr__(name: str) -> Any:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{home}"), name)
