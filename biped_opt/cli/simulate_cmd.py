"""``biped-opt simulate``: one maneuver, printed as text or one JSON object."""

from __future__ import annotations

import argparse
import dataclasses

from biped_opt import strict_json
from biped_opt.cli.args import finite_float, int_in_range, positive_float
from biped_opt.cli.system_cmds import add_system_arguments
from biped_opt.errors import InvalidInputError
from biped_opt.hybrid import simulate
from biped_opt.hybrid.simulate import DEFAULT_OPTIONS, SimulatorOptions
from biped_opt.maneuvers import Maneuver, check_theta0, parse_maneuver
from biped_opt.model.modes import ContactMode
from biped_opt.simulation.trajectory import Trajectory, constraint_names

#: bounds of one run's budget on the command line (a run's events and samples grow with them)
MAX_EVENTS = 10_000
MAX_HORIZON = 1e4


def add_maneuver_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--maneuver",
        type=str,
        metavar="{" + ",".join(m.value for m in Maneuver) + "}",
        help="which maneuver of the paper (Sec. IV), or of --system",
    )


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


def _legs(mask: int) -> list[int]:
    """The biped's legs (1 = left, 2 = right) of a mask over its constraints."""
    return [j + 1 for j in ContactMode(mask).active]


def trajectory_json(tr: Trajectory) -> dict:
    """The JSON form of a biped's trajectory (the ``--json`` output), in the paper's words."""
    return {
        "maneuver": tr.maneuver,
        "theta0": tr.theta0,
        "inputs": {"u1": tr.inputs[0], "u2": tr.inputs[1], "u12": tr.inputs[2]},
        "outcome": tr.outcome,
        "t_final": tr.t_final,
        "status": "ok" if tr.success else tr.status.name.lower(),
        "message": tr.message,
        "modes": [{"t": seg.t_start, "mode": ContactMode(seg.mask).name}
                  for seg in tr.segments],
        "events": [
            {"t": e.t, "kind": e.kind, "touchdown": _legs(e.mask_entered),
             "liftoff": _legs(e.mask_left), "mode_after": ContactMode(e.mask_after).name}
            for e in tr.contact_events
        ],
        "state": {"q": tr.q_final.tolist(), "qdot": tr.qdot_final.tolist()},
        "nfev": tr.nfev,
        "nsteps": tr.nsteps,
    }


def parse_maneuver_arg(text: str | None) -> Maneuver:
    """--maneuver as a Maneuver; the error names the argument."""
    if text is None:
        raise InvalidInputError("--maneuver is required")
    try:
        return parse_maneuver(text)
    except InvalidInputError as exc:
        raise InvalidInputError(f"--maneuver: {exc}") from None


def run(args: argparse.Namespace) -> int:
    if args.system is not None:
        return run_system(args)
    for option in ("s", "input", "param"):
        if getattr(args, option) not in (None, []):
            raise InvalidInputError(f"--{option}: only with --system (the biped takes --theta0, "
                                    "--u1, --u2, --u12)")
    parse_maneuver_arg(args.maneuver)
    if args.theta0 is None:
        raise InvalidInputError("--theta0 is required (or --system with --s)")
    maneuver = parse_maneuver_arg(args.maneuver)
    try:
        check_theta0(maneuver, args.theta0)
    except InvalidInputError as exc:
        raise InvalidInputError(f"--theta0: {exc}") from None
    tr = simulate(maneuver, args.theta0, (args.u1, args.u2, args.u12),
                  options=budget(args, DEFAULT_OPTIONS))
    if args.json:
        print(strict_json.dumps(trajectory_json(tr)))
    else:
        print(f"maneuver   {tr.maneuver}  theta0 = {tr.theta0:+.12g}")
        print(f"status     {tr.status.name}: {tr.message}")
        print(f"outcome    th(t_f) = {tr.outcome:+.15g}")
        print(f"t_final    {tr.t_final:.15g}")
        print("modes      " + " -> ".join(f"{ContactMode(seg.mask).name}@{seg.t_start:.12g}"
                                          for seg in tr.segments))
        print(f"work       nfev = {tr.nfev}, steps = {tr.nsteps}")
    return 0 if tr.success else 1


def run_system(args: argparse.Namespace) -> int:
    """``simulate --system``: any system's maneuver through its compiled simulator."""
    from biped_opt.simulation.compiled import compile_system

    if args.theta0 is not None or any(getattr(args, n) for n in ("u1", "u2", "u12")):
        raise InvalidInputError("--theta0/--u1/--u2/--u12: the biped's options; with --system "
                                "give --s and --input NAME=VALUE")
    if args.s is None:
        raise InvalidInputError("--s is required with --system")
    if args.maneuver is None:
        raise InvalidInputError("--maneuver is required")
    compiled = compile_system(args.system, **dict(args.param))
    tr = compiled.simulate(args.maneuver, args.s, dict(args.input),
                           options=budget(args, compiled.maneuver_options(args.maneuver)))
    names = compiled.system.coordinate_names
    d = len(names)

    def active(mask: int) -> list[str]:  # a mode's constraints, in their declared order
        return list(constraint_names(mask, tr.constraints))

    if args.json:
        print(strict_json.dumps({
            "system": tr.system, "maneuver": tr.maneuver, "s": tr.s,
            "inputs": dict(zip(compiled.inputs, tr.inputs)),
            "parameters": compiled.parameters, "status": tr.status.name.lower(),
            "message": tr.message,
            "outcome": tr.outcome, "t_final": tr.t_final,
            "modes": [active(seg.mask) for seg in tr.segments],
            "event_times": list(tr.event_times),
            "events": [{"t": e.t, "touchdown": list(e.entered), "liftoff": list(e.left),
                        "mode_after": active(e.mask_after)}
                       for e in tr.contact_events],
            "state": {"q": dict(zip(names, tr.y_final[:d])),
                      "qdot": dict(zip(names, tr.y_final[d:]))},
            "nfev": tr.nfev, "nsteps": tr.nsteps}))
    else:
        print(f"system     {tr.system}  maneuver {tr.maneuver}  s = {tr.s:+.12g}")
        print(f"status     {tr.status.name}: {tr.message}")
        print(f"outcome    {tr.outcome:+.15g}")
        print(f"t_final    {tr.t_final:.15g}")
        print("modes      " + " -> ".join(
            f"{{{', '.join(active(seg.mask))}}}@{seg.t_start:.12g}" for seg in tr.segments))
        for e in tr.contact_events:
            what = [f"{kind} {{{', '.join(found)}}}"
                    for kind, found in (("touchdown", e.entered), ("liftoff", e.left)) if found]
            print(f"event      t = {e.t:.12g}: {'; '.join(what)}")
        print(f"work       nfev = {tr.nfev}, steps = {tr.nsteps}")
    return 0 if tr.success else 1
