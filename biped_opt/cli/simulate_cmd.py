"""``biped-opt simulate``: one maneuver, printed as text or one JSON object."""

from __future__ import annotations

import argparse

from biped_opt import strict_json
from biped_opt.cli.args import finite_float
from biped_opt.errors import InvalidInputError
from biped_opt.hybrid import simulate
from biped_opt.hybrid.trajectory import Trajectory
from biped_opt.maneuvers import Maneuver, check_theta0, parse_maneuver


def add_maneuver_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--maneuver",
        required=True,
        type=str,
        metavar="{" + ",".join(m.value for m in Maneuver) + "}",
        help="which maneuver of the paper (Sec. IV)",
    )


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="simulate one maneuver at fixed inputs")
    add_maneuver_argument(p)
    p.add_argument("--theta0", required=True, type=finite_float("--theta0"),
                   help="initial body pitch [rad]")
    p.add_argument("--u1", type=finite_float("--u1"), default=0.0,
                   help="left leg force in left single stance (default 0)")
    p.add_argument("--u2", type=finite_float("--u2"), default=0.0,
                   help="right leg force in right single stance (default 0)")
    p.add_argument("--u12", type=finite_float("--u12"), default=0.0,
                   help="body torque in double stance (default 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def trajectory_json(tr: Trajectory) -> dict:
    """The JSON form of a trajectory (the ``--json`` output)."""
    return {
        "maneuver": tr.maneuver,
        "theta0": tr.theta0,
        "inputs": {"u1": tr.inputs[0], "u2": tr.inputs[1], "u12": tr.inputs[2]},
        "outcome": tr.outcome,
        "t_final": tr.t_final,
        "status": "ok" if tr.success else tr.status.name.lower(),
        "message": tr.message,
        "modes": [{"t": t, "mode": m.name} for t, m in tr.modes],
        "events": [
            {"t": e.t, "kind": e.kind, "touchdown": list(e.touchdown),
             "liftoff": list(e.liftoff), "mode_after": e.mode_after.name}
            for e in tr.contact_events
        ],
        "state": {"q": tr.q_final.tolist(), "qdot": tr.qdot_final.tolist()},
        "nfev": tr.nfev,
        "nsteps": tr.nsteps,
    }


def parse_maneuver_arg(text: str) -> Maneuver:
    """--maneuver as a Maneuver; the error names the argument."""
    try:
        return parse_maneuver(text)
    except InvalidInputError as exc:
        raise InvalidInputError(f"--maneuver: {exc}") from None


def run(args: argparse.Namespace) -> int:
    maneuver = parse_maneuver_arg(args.maneuver)
    try:
        check_theta0(maneuver, args.theta0)
    except InvalidInputError as exc:
        raise InvalidInputError(f"--theta0: {exc}") from None
    tr = simulate(maneuver, args.theta0, (args.u1, args.u2, args.u12))
    if args.json:
        print(strict_json.dumps(trajectory_json(tr)))
    else:
        print(f"maneuver   {tr.maneuver}  theta0 = {tr.theta0:+.12g}")
        print(f"status     {tr.status.name}: {tr.message}")
        print(f"outcome    th(t_f) = {tr.outcome:+.15g}")
        print(f"t_final    {tr.t_final:.15g}")
        print("modes      " + " -> ".join(f"{m.name}@{t:.12g}" for t, m in tr.modes))
        print(f"work       nfev = {tr.nfev}, steps = {tr.nsteps}")
    return 0 if tr.success else 1
