"""``biped-opt optimise``: the optimal policy, value and one-sided derivatives at one th0.

Also holds the problem options shared by ``sweep`` and ``nonsmooth``: ``--variant``,
``--theta-star``, ``--alpha NAME=VALUE``, ``--bounds NAME=LO,HI`` and ``--fixed NAME=VALUE``
override MODEL.md Sec. 5's defaults.
"""

from __future__ import annotations

import argparse
import dataclasses
import math

from biped_opt import strict_json
from biped_opt.cli.args import finite_float
from biped_opt.cli.simulate_cmd import add_maneuver_argument, parse_maneuver_arg
from biped_opt.cli.system_cmds import add_system_arguments, run_optimise, uses_system
from biped_opt.errors import InvalidInputError, InvalidParameterError
from biped_opt.hybrid.simulate import INPUT_NAMES
from biped_opt.maneuvers import Maneuver, check_theta0
from biped_opt.optimal.problems import OptimalControlProblem, get_problem
from biped_opt.optimal.solve import OptimalResult, optimal_policy


def _assignment(name: str, pairs: bool):
    """argparse type for NAME=VALUE (or NAME=LO,HI when ``pairs``); errors name the option."""

    def convert(text: str) -> tuple[str, tuple[float, ...]]:
        key, sep, rest = text.partition("=")
        key = key.strip()
        if not sep or key not in INPUT_NAMES:
            form = "NAME=LO,HI" if pairs else "NAME=VALUE"
            raise argparse.ArgumentTypeError(
                f"{name} must look like {form} with NAME one of {', '.join(INPUT_NAMES)}, "
                f"got {text!r}"
            )
        parts = rest.replace(":", ",").split(",") if pairs else [rest]
        if len(parts) != (2 if pairs else 1):
            raise argparse.ArgumentTypeError(f"{name} {key}: expected LO,HI, got {rest!r}")
        values = []
        for part in parts:
            try:
                value = float(part)
            except ValueError:
                raise argparse.ArgumentTypeError(
                    f"{name} {key}: {part!r} is not a number"
                ) from None
            if not math.isfinite(value):
                raise argparse.ArgumentTypeError(f"{name} {key}: must be finite, got {part!r}")
            values.append(value)
        return key, tuple(values)

    convert.__name__ = name
    return convert


def add_problem_arguments(p: argparse.ArgumentParser, *, variant: bool = True) -> None:
    """The options that select and override the optimal-control problem."""
    add_maneuver_argument(p)
    if variant:
        p.add_argument("--variant", action="store_true",
                       help="liftoff only: decide the single-stance forces u1, u2 in [0, 3] "
                            "with u12 = 0 (MODEL.md Sec. 6)")
    p.add_argument("--theta-star", type=finite_float("--theta-star"), default=None,
                   help="target outcome th* [rad] (default per problem)")
    p.add_argument("--alpha", action="append", default=[], metavar="NAME=VALUE",
                   type=_assignment("--alpha", pairs=False),
                   help="input weight of a decision, e.g. --alpha u1=3e-4 (repeatable)")
    p.add_argument("--bounds", action="append", default=[], metavar="NAME=LO,HI",
                   type=_assignment("--bounds", pairs=True),
                   help="bounds of a decision, e.g. --bounds u12=-0.5,0.5 (repeatable)")
    p.add_argument("--fixed", action="append", default=[], metavar="NAME=VALUE",
                   type=_assignment("--fixed", pairs=False),
                   help="value of a non-decision input, e.g. --fixed u2=3 (repeatable)")


def problem_from_args(args: argparse.Namespace) -> OptimalControlProblem:
    """The problem named by --maneuver/--variant with the command line's overrides."""
    maneuver = parse_maneuver_arg(args.maneuver)
    name = maneuver.value
    if getattr(args, "variant", False):
        if maneuver is not Maneuver.LIFTOFF:
            raise InvalidInputError("--variant: only the liftoff maneuver has a variant problem")
        name = "liftoff-variant"
    problem = get_problem(name)
    try:
        if args.theta_star is not None:
            problem = dataclasses.replace(problem, theta_star=args.theta_star)
        fixed = list(problem.fixed_inputs)
        for key, (value,) in args.fixed:
            if key in problem.decisions:
                raise InvalidInputError(
                    f"--fixed: {key} is a decision of the {problem.name} problem, not fixed"
                )
            fixed[INPUT_NAMES.index(key)] = value
        problem = dataclasses.replace(problem, fixed_inputs=tuple(fixed))
    except InvalidParameterError as exc:
        raise InvalidInputError(f"--theta-star/--fixed: {exc}") from None
    for option, items, apply in (
        ("--alpha", args.alpha, lambda pr, k, v: pr.with_alpha(k, v[0])),
        ("--bounds", args.bounds, lambda pr, k, v: pr.with_bounds(k, v[0], v[1])),
    ):
        for key, values in items:
            try:
                problem = apply(problem, key, values)
            except (InvalidInputError, InvalidParameterError) as exc:
                raise InvalidInputError(f"{option}: {exc}") from None
    return problem


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("optimise", help="optimal policy, value and one-sided derivatives at th0")
    add_problem_arguments(p)
    p.add_argument("--theta0", type=finite_float("--theta0"), help="initial body pitch [rad]")
    add_system_arguments(p, point=True)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def derivatives_json(problem: OptimalControlProblem, theta0: float) -> dict:
    """One-sided derivatives (left, right) of outcome, value and policy at theta0.

    From the variational equations (Theorem 1, Eqs. (12)-(13)) when
    :mod:`biped_opt.optimal.derivatives` is available, else from extrapolated one-sided
    finite differences of the optimal solution.
    """
    try:
        from biped_opt.optimal.derivatives import one_sided_derivatives
    except ImportError:
        return _finite_difference_derivatives(problem, theta0)
    d = one_sided_derivatives(problem, theta0)
    return {
        "outcome": list(d.outcome),
        "value": list(d.value),
        "policy": {k: list(v) for k, v in d.policy.items()},
        "method": "variational",
    }


def _finite_difference_derivatives(problem: OptimalControlProblem, theta0: float) -> dict:
    from biped_opt.maneuvers import spec
    from biped_opt.piecewise import one_sided

    cache: dict[float, OptimalResult] = {}

    def at(th: float) -> OptimalResult:
        if th not in cache:
            cache[th] = optimal_policy(problem, th)
        return cache[th]

    limit = spec(problem.maneuver).theta0_limit
    out: dict = {"policy": {}, "method": "finite-difference"}
    quantities = [("outcome", lambda r: r.outcome), ("value", lambda r: r.value)]
    quantities += [(f"policy:{d}", (lambda name: lambda r: r.policy[name])(d))
                   for d in problem.decisions]
    for key, get in quantities:
        pair = []

        def f(th: float, get=get) -> float:
            return get(at(th))

        for side in (-1, 1):
            h = min(1e-3, limit - side * theta0) if limit - side * theta0 > 0 else 0.0
            # None (JSON null) where the side lies outside the valid range
            pair.append(one_sided(f, theta0, side, h0=h).derivative if h > 0 else None)
        if key.startswith("policy:"):
            out["policy"][key.split(":")[1]] = pair
        else:
            out[key] = pair
    return out


def print_derivatives(parameter: str, derivatives: dict) -> None:
    """The one-sided derivatives of :func:`derivatives_json`'s form as text lines."""
    print(f"{'d/d' + parameter:<10} ({derivatives['method']}; left, right)")
    print(f"  outcome  {derivatives['outcome'][0]:+.10g}  {derivatives['outcome'][1]:+.10g}")
    print(f"  value    {derivatives['value'][0]:+.10g}  {derivatives['value'][1]:+.10g}")
    for k, (lft, rgt) in derivatives["policy"].items():
        print(f"  {k:<8} {lft:+.10g}  {rgt:+.10g}")


def result_json(result: OptimalResult, derivatives: dict | None) -> dict:
    out = result.as_dict()
    out["problem"] = result.problem.describe()
    if derivatives is not None:
        out["derivatives"] = derivatives
    return out


def run(args: argparse.Namespace) -> int:
    if uses_system(args):
        return run_optimise(args)
    if args.theta0 is None:
        raise InvalidInputError("--theta0 is required (or --system with --s)")
    problem = problem_from_args(args)
    try:
        check_theta0(problem.maneuver, args.theta0)
    except InvalidInputError as exc:
        raise InvalidInputError(f"--theta0: {exc}") from None
    result = optimal_policy(problem, args.theta0)
    derivatives = derivatives_json(problem, args.theta0) if result.success else None
    if args.json:
        print(strict_json.dumps(result_json(result, derivatives)))
        return 0 if result.success else 1
    print(f"problem    {problem.name}  theta0 = {result.theta0:+.12g}")
    print(f"status     {result.status}: {result.message}")
    print("policy     " + "  ".join(f"{k} = {v:+.12g}" for k, v in result.policy.items())
          + (f"  ({result.active} at its {result.bound} bound)" if result.bound else ""))
    print(f"value      {result.value:.15g}")
    print(f"outcome    th(t_f) = {result.outcome:+.15g}")
    print(f"branch     {result.branch}")
    if derivatives is not None:
        print_derivatives("th0", derivatives)
    print(f"work       simulations = {result.nsim}, nfev = {result.nfev}")
    return 0 if result.success else 1
