"""``biped-opt replay FILE``: republish a recording with its recorded timing (``ros2 bag play``)."""

from __future__ import annotations

import argparse
import sys

from biped_opt.cli.args import float_in_range, int_in_range

__all__ = ["register", "func"]

#: largest ROS_DOMAIN_ID Cyclone DDS accepts (DDS port arithmetic: 7400 + 250 * id < 65536)
MAX_DOMAIN_ID = 232


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "replay", help="republish a recorded sweep on ROS 2 with its recorded timing",
        description="Republish the topics of an MCAP recording with their recorded timing and "
                    "QoS on the ROS backend (rclpy or the built-in Cyclone DDS backend), like "
                    "'ros2 bag play'. Unfinished files (a killed recorder) are replayed from "
                    "their complete chunks. Ctrl-C or SIGTERM stops it (exit status 0).")
    p.add_argument("file", help="the .mcap recording")
    p.add_argument("--rate", type=float_in_range("--rate", 1e-3, 1e3), default=1.0,
                   help="speed factor, 0.001 to 1000 (default 1)")
    p.add_argument("--loop", action="store_true", help="start again after the last message")
    p.add_argument("--topics", nargs="+", metavar="T", help="replay only these topics")
    p.add_argument("--domain-id", type=int_in_range("--domain-id", 0, MAX_DOMAIN_ID), default=None,
                   help="DDS domain (default: $ROS_DOMAIN_ID, else 0)")
    p.add_argument("--delay", type=float_in_range("--delay", 0.0, 3600.0), default=0.5,
                   help="seconds to wait for subscribers to be discovered before the first "
                        "message (default 0.5)")
    p.set_defaults(func=func)


def func(args: argparse.Namespace) -> int:
    from biped_opt.cli.signals import stop_requested
    from biped_opt.record.reader import read_raw
    from biped_opt.record.replay import Player

    raw = read_raw(args.file, topics=args.topics)
    player = Player(raw, rate=args.rate, loop=args.loop, topics=args.topics,
                    domain_id=args.domain_id, delay=args.delay)
    # a signal at any moment from here on, while the player still sets up the graph too, stops
    # the replay where the player looks: no KeyboardInterrupt inside DDS set-up
    with stop_requested() as stop:
        stop.defer(player.stop)
        span = raw.time_range_ns
        seconds = (span[1] - span[0]) * 1e-9 if span else 0.0
        print(f"replaying {raw.path}: {len(raw.messages)} messages on {len(player.topics)} "
              f"topics, {seconds:.3f} s recorded, rate {args.rate:g}"
              f"{', looping' if args.loop else ''}", flush=True)
        if not raw.complete:
            print(f"note: {raw.note}", flush=True)
        stats = player.run()
    state = "stopped" if stats.interrupted else "finished"
    counts = ", ".join(f"{t} {n}" for t, n in stats.published.items())
    print(f"{state} after {stats.seconds:.2f} s, {stats.loops} complete pass(es): {counts}; "
          f"latest publish {stats.max_late * 1e3:.2f} ms behind its recorded time")
    if stats.cut_gaps:
        print(f"note: {stats.cut_gaps} gaps of more than an hour between recorded times were "
              "played as an hour", file=sys.stderr)
    if stats.undecodable:
        where = ", ".join(f"{t} {n}" for t, n in sorted(stats.undecodable.items()))
        print(f"note: {sum(stats.undecodable.values())} messages that do not decode were not "
              f"published ({where})", file=sys.stderr)
    if stats.skipped_types:
        print(f"skipped (type unknown to the backend): {', '.join(stats.skipped_types)}",
              file=sys.stderr)
    return 0
