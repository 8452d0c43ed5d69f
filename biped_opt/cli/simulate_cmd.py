"""``biped-opt simulate``: one maneuver, printed as text or one JSON object."""

from __future__ import annotations

import argparse
import dataclasses

from biped_opt.cli.args import (
    add_maneuver_argument,
    add_system_arguments,
    check_physical_args,
    check_s,
    check_size,
    checked_theta0,
    finite_float,
    int_in_range,
    parse_maneuver_arg,
    positive_float,
)
from biped_opt.cli.output import show_system_trajectory, show_trajectory
from biped_opt.errors import InvalidInputError
from biped_opt.simulation.options import SimulatorOptions

#: bounds of one run's budget on the command line (a run's events and samples grow with them)
MAX_EVENTS = 10_000
MAX_HORIZON = 1e4


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate", help="simulate one maneuver at fixed inputs",
        description="The biped's maneuvers (--theta0, --u1, --u2, --u12), or any system's with "
                    "--system NAME|FILE.py (--s, --input NAME=VALUE, --param NAME=VALUE).")
    add_maneuver_argument(p)
    p.add_argument("--theta0", type=finite_float("--theta0"),
                   help="initial body pitch [rad] (the biped)")
    add_system_arguments(p, point=True, problem=False)
    p.add_argument("--u1", type=finite_float("--u1"), default=0.0,
                   help="left leg force in left single stance (default 0)")
    p.add_argument("--u2", type=finite_float("--u2"), default=0.0,
                   help="right leg force in right single stance (default 0)")
    p.add_argument("--u12", type=finite_float("--u12"), default=0.0,
                   help="body torque in double stance (default 0)")
    p.add_argument("--max-events", type=int_in_range("--max-events", 1, MAX_EVENTS),
                   default=None,
                   help="contact events allowed before giving up (default: the maneuver's, 16)")
    p.add_argument("--horizon", type=positive_float("--horizon", maximum=MAX_HORIZON),
                   default=None,
                   help="time allowed before giving up (default: the maneuver's, 10)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def budget(args: argparse.Namespace, options: SimulatorOptions) -> SimulatorOptions:
    """``options`` with --max-events and --horizon applied."""
    changes = {"max_events": args.max_events, "t_end": args.horizon}
    changes = {k: v for k, v in changes.items() if v is not None}
    return dataclasses.replace(options, **changes) if changes else options


def _check_lane(args: argparse.Namespace) -> None:
    """Options of the other lane are refused (the biped's with --system, and the reverse)."""
    if args.system is not None:
        if args.theta0 is not None or any(getattr(args, n) for n in ("u1", "u2", "u12")):
            raise InvalidInputError("--theta0/--u1/--u2/--u12: the biped's options; with "
                                    "--system give --s and --input NAME=VALUE")
        if args.s is None:
            raise InvalidInputError("--s is required with --system")
        if args.maneuver is None:
            raise InvalidInputError("--maneuver is required")
        return
    for option in ("s", "input", "param"):
        if getattr(args, option) not in (None, []):
            raise InvalidInputError(f"--{option}: only with --system (the biped takes --theta0, "
                                    "--u1, --u2, --u12)")
    parse_maneuver_arg(args.maneuver)
    if args.theta0 is None:
        raise InvalidInputError("--theta0 is required (or --system with --s)")


def run(args: argparse.Namespace) -> int:
    _check_lane(args)
    if args.system is not None:  # any system, through its compiled simulator
        from biped_opt.simulation.compiled import compile_system

        check_size(args, "--system", args.system)
        compiled = compile_system(args.system, **dict(args.param))
        compiled.code(args.maneuver)  # (an unknown maneuver: the system's message)
        check_s(compiled, args.maneuver, "--s", args.s)
        check_physical_args(args, compiled, args.maneuver, args.s)
        tr = compiled.simulate(args.maneuver, args.s, dict(args.input),
                               options=budget(args, compiled.maneuver_options(args.maneuver)))
        return show_system_trajectory(compiled, tr, args.json)
    from biped_opt.paper.biped import simulate
    from biped_opt.simulation.options import DEFAULT_OPTIONS

    maneuver = parse_maneuver_arg(args.maneuver)
    theta0 = checked_theta0(maneuver, args.theta0)
    tr = simulate(maneuver, theta0, (args.u1, args.u2, args.u12),
                  options=budget(args, DEFAULT_OPTIONS))
    return show_trajectory(tr, args.json)
