"""rosbag2 directories holding a biped_opt recording (MCAP.md: "What ROS 2 tools need").

A rosbag2 directory is the MCAP file plus ``metadata.yaml``. Humble's rosbag2 reads metadata
versions up to 8 (``rosbags`` writes 9 by default, which Humble rejects), so this module writes
version 8 itself: ``storage_identifier: mcap``, the file list, duration, start time, message count
and ``topics_with_message_count`` with each topic's ``offered_qos_profiles`` (the YAML string with
integer enums that the channel metadata already holds) and ``type_description_hash``.

Two ways to get one:

- :func:`export_rosbag2` converts a recording (finished, or recovered from an unfinished file) into
  a new directory; the command line is ``biped-opt info FILE --to-rosbag2 DIR``;
- :class:`Rosbag2SweepWriter` is a :class:`~biped_opt.record.writer.SweepWriter` that writes into a
  directory and adds ``metadata.yaml`` when it finishes.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from biped_opt.record.reader import RawRecording, read_raw
from biped_opt.record.writer import RecordError, SweepWriter, sealed
from biped_opt.version import __version__

__all__ = ["METADATA_VERSION", "Rosbag2SweepWriter", "export_rosbag2", "metadata_yaml"]

#: the newest rosbag2 metadata version that ROS 2 Humble reads
METADATA_VERSION = 8


def metadata_yaml(
    file_name: str,
    topics: list[dict[str, Any]],
    *,
    start_ns: int,
    end_ns: int,
    ros_distro: str = "humble",
) -> str:
    """``metadata.yaml`` (version 8) for one MCAP file.

    ``topics`` holds one dict per topic: ``name``, ``type``, ``offered_qos_profiles`` (YAML text),
    ``type_description_hash`` and ``message_count``. ``end_ns`` is the last message's log time.
    """
    count = sum(int(t["message_count"]) for t in topics)
    duration = max(0, int(end_ns) - int(start_ns)) if count else 0
    start = int(start_ns) if count else 0
    info = {
        "version": METADATA_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": count,
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": t["name"],
                    "type": t["type"],
                    "serialization_format": "cdr",
                    "offered_qos_profiles": t["offered_qos_profiles"],
                    "type_description_hash": t["type_description_hash"],
                },
                "message_count": int(t["message_count"]),
            }
            for t in topics
        ],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [file_name],
        "files": [
            {
                "path": file_name,
                "starting_time": {"nanoseconds_since_epoch": start},
                "duration": {"nanoseconds": duration},
                "message_count": count,
            }
        ],
        "custom_data": None,
        "ros_distro": ros_distro,
    }
    return yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False,
                          default_flow_style=False)


def _write_metadata_from_summary(directory: Path, mcap_path: Path) -> Path:
    """``metadata.yaml`` from a finished MCAP file's summary (statistics, channels)."""
    with open(mcap_path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    if summary is None or summary.statistics is None:
        raise RecordError(f"{mcap_path}: no summary statistics (was the file finished?)")
    stats = summary.statistics
    topics = []
    for cid, channel in sorted(summary.channels.items()):
        schema = summary.schemas.get(channel.schema_id)
        topics.append({
            "name": channel.topic,
            "type": schema.name if schema is not None else "",
            "offered_qos_profiles": channel.metadata.get("offered_qos_profiles", ""),
            "type_description_hash": channel.metadata.get("topic_type_hash", ""),
            "message_count": stats.channel_message_counts.get(cid, 0),
        })
    path = directory / "metadata.yaml"
    path.write_text(metadata_yaml(mcap_path.name, topics, start_ns=stats.message_start_time,
                                  end_ns=stats.message_end_time))
    return path


def _prepare(directory: str | Path) -> Path:
    out = Path(directory)
    if out.exists() and any(out.iterdir()):
        raise RecordError(f"{out} exists and is not empty (rosbag2 needs a new directory)")
    out.mkdir(parents=True, exist_ok=True)
    return out


def export_rosbag2(recording: str | Path | RawRecording, directory: str | Path) -> Path:
    """Write ``directory`` (new or empty) as a rosbag2 bag: ``<name>_0.mcap`` + ``metadata.yaml``.

    The MCAP is rewritten from the recording's records (schemas, channels with their metadata,
    messages in log-time order, metadata records), so an unfinished file recovered by
    :func:`~biped_opt.record.reader.read_raw` comes out finished and indexed.
    Returns the directory.
    """
    raw = recording if isinstance(recording, RawRecording) else read_raw(recording)
    out = _prepare(directory)
    mcap_path = out / f"{out.name}_0.mcap"
    with open(mcap_path, "wb") as stream:
        writer = Writer(stream, compression=CompressionType.ZSTD)
        writer.start(profile="ros2", library=f"biped_opt {__version__}")
        ids: dict[str, int] = {}
        schema_ids: dict[str, int] = {}
        for topic, ch in raw.channels.items():
            if ch.type not in schema_ids:
                schema_ids[ch.type] = writer.register_schema(
                    name=ch.type, encoding=ch.schema_encoding, data=ch.schema_data)
            ids[topic] = writer.register_channel(
                topic=topic, message_encoding=ch.message_encoding,
                schema_id=schema_ids[ch.type], metadata=ch.metadata)
        for seq, m in enumerate(raw.messages):
            writer.add_message(ids[m.topic], log_time=m.log_time_ns, data=m.data,
                               publish_time=m.publish_time_ns, sequence=seq)
        for name, values in raw.metadata.items():
            writer.add_metadata(name, sealed(name, values))
        writer.finish()
    _write_metadata_from_summary(out, mcap_path)
    return out


class Rosbag2SweepWriter(SweepWriter):
    """A :class:`SweepWriter` that records into a rosbag2 directory (new or empty).

    The MCAP goes to ``directory/<directory name>_0.mcap``; :meth:`finish` (also run on exit of the
    ``with`` block and by :meth:`SweepWriter.finish_on_signals`) adds ``metadata.yaml``.
    A killed writer leaves the directory without it; :func:`export_rosbag2` of the MCAP inside then
    recovers the complete chunks into a new directory.
    """

    def __init__(self, directory: str | Path, *, metadata: Mapping[str, str] | None = None,
                 **kwargs: Any) -> None:
        self.directory = _prepare(directory)
        super().__init__(self.directory / f"{self.directory.name}_0.mcap", metadata=metadata,
                         **kwargs)

    def finish(self) -> None:
        with self._lock:
            if self.finished:
                return
            super().finish()
            assert self.path is not None
            _write_metadata_from_summary(self.directory, self.path)
