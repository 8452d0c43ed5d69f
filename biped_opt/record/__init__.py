"""Recording sweeps to MCAP (ROS 2 profile) and reading them back (MCAP.md)."""

from biped_opt.record.reader import RecordedMessage, Recording, read_recording
from biped_opt.record.writer import TOPICS, RecordError, SweepWriter

__all__ = [
    "TOPICS",
    "RecordError",
    "RecordedMessage",
    "Recording",
    "SweepWriter",
    "read_recording",
]
