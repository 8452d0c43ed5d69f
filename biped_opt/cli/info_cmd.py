"""``biped-opt info FILE``: what a recording holds; ``--to-rosbag2 DIR`` exports a rosbag2 bag."""

from __future__ import annotations

import argparse
from pathlib import Path

from biped_opt.cli.args import new_directory, path_arg
from biped_opt.cli.output import emit_json

__all__ = ["register", "func", "describe"]


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "info", help="summarise a recording (topics, counts, time range, sweep parameters)",
        description="Topics with types, QoS and message counts, the log-time range, the number "
                    "of sweep points, the sweep's parameters (the biped_opt.sweep metadata "
                    "record), the system of a recording of another system than the biped "
                    "(the biped_opt.system record) and whether the file is complete or was "
                    "recovered from an unfinished write. --to-rosbag2 DIR also writes a "
                    "rosbag2 directory (metadata.yaml version 8, which ROS 2 Humble reads, "
                    "and the MCAP).")
    p.add_argument("file", help="the .mcap recording")
    p.add_argument("--to-rosbag2", type=path_arg(new_directory, "--to-rosbag2"), metavar="DIR",
                   help="write the recording as a rosbag2 directory DIR (new or empty)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=func)


def describe(path: str | Path) -> dict:
    """Plain-data summary of a recording (what ``info`` prints)."""
    from biped_opt.record.reader import read_raw, recorded_system
    from biped_opt.record.replay import qos_from_metadata
    from biped_opt.record.writer import RecordError

    raw = read_raw(path)
    try:
        system = recorded_system(raw)
        lost = ""
    except RecordError as exc:  # (the description's record and message both damaged)
        system, lost = None, str(exc).split(": ", 1)[-1]
    counts = raw.counts
    span = raw.time_range_ns
    topics = []
    for topic, ch in raw.channels.items():
        q = qos_from_metadata(ch.metadata.get("offered_qos_profiles"))
        topics.append({
            "topic": topic, "type": ch.type, "count": counts[topic],
            "qos": {"history": "keep_last" if q.history == 1 else "keep_all", "depth": q.depth,
                    "reliability": "reliable" if q.reliability == 1 else "best_effort",
                    "durability": "transient_local" if q.durability == 1 else "volatile"},
        })
    return {
        "path": str(raw.path),
        "bytes": raw.file_size,
        "complete": raw.complete,
        "read": raw.note,
        "messages": len(raw.messages),
        "topics": topics,
        "start_ns": span[0] if span else None,
        "end_ns": span[1] if span else None,
        "duration_s": (span[1] - span[0]) * 1e-9 if span else 0.0,
        "sweep_points": counts.get("/biped/sweep", 0),
        "sweep": raw.metadata.get("biped_opt.sweep", {}),
        "system": system,
        "system_lost": lost,
        "metadata_records": sorted(raw.metadata),
    }


def _text(info: dict) -> str:
    status = ("complete (finished, indexed)" if info["complete"]
              else f"RECOVERED: {info['read']}")
    lines = [
        f"file:         {info['path']} ({info['bytes'] / 1e6:.3f} MB)",
        f"status:       {status}",
        f"messages:     {info['messages']}",
    ]
    if info["start_ns"] is not None:
        lines.append(f"log time:     {info['start_ns'] * 1e-9:.9f} .. {info['end_ns'] * 1e-9:.9f}"
                     f" s ({info['duration_s']:.3f} s)")
    lines.append(f"sweep points: {info['sweep_points']}")
    lines.append("topics:")
    width = max((len(t["topic"]) for t in info["topics"]), default=0)
    for t in info["topics"]:
        q = t["qos"]
        lines.append(f"  {t['topic']:<{width}}  {t['count']:>8}  {t['type']}  "
                     f"[{q['reliability']}, {q['durability']}, {q['history']} {q['depth']}]")
    system = info["system"]
    if info["system_lost"]:
        lines.append(f"system:       unknown ({info['system_lost']})")
    if system is not None:
        lines.append(f"system:       {system['system']} (from {system['source']})")
        for key in ("coordinates", "constraints", "inputs", "maneuvers"):
            lines.append(f"  {key + ':':<13}{', '.join(system[key]) or 'none'}")
        params = ", ".join(f"{k} = {v:g}" for k, v in zip(system["parameter_names"],
                                                         system["parameter_values"]))
        lines.append(f"  {'parameters:':<13}{params or 'none'}")
    if info["sweep"]:
        lines.append("sweep parameters (biped_opt.sweep):")
        for key, value in info["sweep"].items():
            lines.append(f"  {key}: {value}")
    else:
        lines.append("sweep parameters: none recorded (no biped_opt.sweep metadata record)")
    return "\n".join(lines)


def func(args: argparse.Namespace) -> int:
    info = describe(args.file)
    if args.json:
        emit_json(info, indent=2)
    else:
        print(_text(info))
    if args.to_rosbag2 is not None:
        from biped_opt.record.rosbag2 import export_rosbag2

        out = export_rosbag2(args.file, args.to_rosbag2)
        print(f"wrote rosbag2 directory {out} (metadata.yaml version 8, storage mcap)")
    return 0
