"""``biped-opt animate``: a maneuver of any system as a GIF (or MP4 where ffmpeg exists), alone or
side by side at s0 - delta and s0 + delta (:mod:`biped_opt.plots.animate`)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from biped_opt.cli.args import (
    add_large_argument,
    assignment,
    check_physical_args,
    check_s,
    check_size,
    finite_float,
    int_in_range,
    output_file,
    path_arg,
    positive_float,
)
from biped_opt.errors import InvalidInputError

#: the most frames per second, simulated seconds per second, and pixels of a panel's side
MAX_FPS = 120
MAX_SPEED = 100.0
MAX_PIXELS = 1920


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "animate", help="draw a maneuver of any system as a GIF (or MP4), or two side by side",
        description=("Draws the system's scene (SYSTEMS.md Sec. 6) in the x-z plane, or in 3-D "
                     "where its bodies lie or move out of one (a robot from its URDF; --view), "
                     "at a fixed frame rate in simulated time: shapes, the ground, contact "
                     "points (red when active) and forces. With --side-by-side the same "
                     "maneuver at s - delta and s + delta, titled with each run's order of "
                     "contacts and outcome. The biped runs at the paper's fixed inputs unless "
                     "--input says otherwise."))
    p.add_argument("--system", default="biped", metavar="NAME|FILE.py",
                   help="a library system (biped, walkerN[_coupled|_decoupled], rocking_bar) or "
                        "a system file (default biped)")
    p.add_argument("--maneuver", required=True, help="a maneuver of the system")
    p.add_argument("--s", type=finite_float("--s"), default=0.0,
                   help="the maneuver's parameter s (the biped's th0); with --side-by-side the "
                        "centre s0 (default 0)")
    p.add_argument("--input", action="append", default=[], metavar="NAME=VALUE",
                   type=assignment("--input"), help="a fixed input of the system (repeatable)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   type=assignment("--param"), help="a parameter of the system (repeatable)")
    add_large_argument(p)
    p.add_argument("--side-by-side", action="store_true",
                   help="two panels: s - delta and s + delta")
    p.add_argument("--delta", type=positive_float("--delta", maximum=1.0), default=None,
                   help="the half distance of --side-by-side's two runs (default 0.02)")
    p.add_argument("--fps", type=int_in_range("--fps", 1, MAX_FPS), default=30,
                   help="frames per second (default 30)")
    p.add_argument("--speed", type=positive_float("--speed", maximum=MAX_SPEED), default=1.0,
                   help="simulated seconds per second of animation (default 1; 0.25: slow "
                        "motion)")
    p.add_argument("--width", type=int_in_range("--width", 32, MAX_PIXELS), default=320,
                   help="a panel's width in pixels, even (default 320)")
    p.add_argument("--height", type=int_in_range("--height", 32, MAX_PIXELS), default=240,
                   help="a panel's height in pixels, even (default 240)")
    p.add_argument("--view", choices=("auto", "xz", "3d"), default="auto",
                   help="the x-z plane, or 3-D (matplotlib's mplot3d); auto: 3-D when the "
                        "system's bodies lie or move out of one x-z plane (default)")
    p.add_argument("-o", "--output", required=True,
                   type=path_arg(output_file, "--output", overwrite=True),
                   help="the file to write: .gif, or .mp4 where ffmpeg is installed")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from biped_opt.plots.animate import animate, check_output, side_by_side
    from biped_opt.simulation.compiled import CompiledSystem

    output = Path(args.output)
    try:  # (the format, before anything is simulated)
        check_output(output)
    except InvalidInputError as exc:
        raise InvalidInputError(f"--output: {exc}") from None
    if args.delta is not None and not args.side_by_side:
        raise InvalidInputError("--delta: only with --side-by-side")
    for option, value in (("--width", args.width), ("--height", args.height)):
        if value % 2:
            raise InvalidInputError(f"{option} must be even (video encoders need it), "
                                    f"got {value}")
    start = time.perf_counter()
    check_size(args, "--system", args.system)
    compiled = CompiledSystem(args.system, **dict(args.param))
    compiled.code(args.maneuver)  # (an unknown maneuver: an error listing the system's)
    check_s(compiled, args.maneuver, "--s", args.s)
    check_physical_args(args, compiled, args.maneuver, args.s)
    unknown = [name for name, _ in args.input if name not in compiled.inputs]
    if unknown:
        raise InvalidInputError(f"--input: {compiled.name} has no input {unknown[0]!r} "
                                f"(inputs: {', '.join(compiled.inputs) or 'none'})")
    inputs, size = dict(args.input), (args.width, args.height)
    if args.side_by_side:
        delta = 0.02 if args.delta is None else args.delta
        movie = side_by_side(compiled, args.maneuver, output, s0=args.s, delta=delta,
                             inputs=inputs, fps=args.fps, speed=args.speed, size=size,
                             view=args.view)
    else:
        movie = animate(compiled, args.maneuver, args.s, output, inputs=inputs, fps=args.fps,
                        speed=args.speed, size=size, view=args.view)
    for p in movie.panels:
        print(p.title.replace("\n", "  "))
    print(f"{output}: {movie.frames} frames at {args.fps} fps, {movie.size[0]} x "
          f"{movie.size[1]} pixels, view {movie.view} ({time.perf_counter() - start:.1f} s)")
    return 0
