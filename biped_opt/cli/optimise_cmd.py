"""``biped-opt optimise``: the optimal policy, value and one-sided derivatives at one th0 (the
biped; MODEL.md Sec. 5's defaults overridden by --variant, --theta-star, --alpha NAME=VALUE,
--bounds NAME=LO,HI and --fixed NAME=VALUE), or at one s of any system's problem (--system,
--problem)."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from biped_opt.cli.args import (
    add_problem_arguments,
    add_system_arguments,
    checked_theta0,
    finite_float,
    problem_from_args,
    problem_from_system_args,
    uses_system,
)
from biped_opt.cli.output import derivatives_json, optimal_json, show_optimal
from biped_opt.errors import InvalidInputError

if TYPE_CHECKING:
    from biped_opt.control.solve import OptimalResult
    from biped_opt.paper.problems import OptimalControlProblem


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("optimise", help="optimal policy, value and one-sided derivatives at th0")
    add_problem_arguments(p)
    p.add_argument("--theta0", type=finite_float("--theta0"), help="initial body pitch [rad]")
    add_system_arguments(p, point=True)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    return run_system(args) if uses_system(args) else run_biped(args)


def run_biped(args: argparse.Namespace) -> int:
    """The biped's problem at --theta0: the derivatives from its variational equations."""
    from biped_opt.paper.solve import optimal_policy

    if args.theta0 is None:
        raise InvalidInputError("--theta0 is required (or --system with --s)")
    problem = problem_from_args(args)
    theta0 = checked_theta0(problem.maneuver, args.theta0)
    r = optimal_policy(problem, theta0)
    derivatives = _biped_derivatives(problem, theta0) if r.success else None
    return show_optimal(
        args.json, optimal_json(r, problem.describe()),
        problem=f"{problem.name}  theta0 = {r.theta0:+.12g}", status=f"{r.status}: {r.message}",
        policy=r.policy, bound=f"{r.active} at its {r.bound} bound" if r.bound else "",
        value=r.value, outcome=f"th(t_f) = {r.outcome:+.15g}", branch=r.branch,
        parameter="th0", derivatives=derivatives,
        work=f"simulations = {r.nsim}, nfev = {r.nfev}", success=r.success)


def run_system(args: argparse.Namespace) -> int:
    """Any system's problem at --s: the derivatives of Theorem 1."""
    from biped_opt.control.solve import optimal_policy
    from biped_opt.control.theorem1 import optimal_derivatives
    from biped_opt.errors import SimulationError

    problem = problem_from_system_args(args)
    if args.s is None:
        raise InvalidInputError("--s is required with --system")
    r = optimal_policy(problem, args.s)
    derivatives = None
    if r.success:
        try:
            d = optimal_derivatives(problem, args.s)
        except SimulationError as exc:  # e.g. a grazing terminal event: say so, keep the optimum
            print(f"note: no one-sided derivatives at this s: {exc}", file=sys.stderr)
        else:
            derivatives = derivatives_json(d, "variational (Theorem 1)")
    return show_optimal(
        args.json, optimal_json(r, problem.as_dict()),
        problem=f"{problem.name}  ({problem.facts.name}, maneuver {problem.maneuver})  "
                f"s = {r.s:+.12g}",
        status=f"{'ok' if r.success else 'failed'}: {r.message}", policy=r.policy,
        bound=f"bound: {r.bound}" if r.bound else "", value=r.value,
        outcome=f"{r.outcome:+.15g}", branch=r.branch, parameter=problem.facts.s,
        derivatives=derivatives, work=f"simulations = {r.nsim}", success=r.success)


def _biped_derivatives(problem: OptimalControlProblem, theta0: float) -> dict[str, Any]:
    """One-sided derivatives (left, right) of the biped's optimal outcome, value and policy at
    theta0: from the variational equations (Theorem 1, Eqs. (12)-(13)) when
    :mod:`biped_opt.paper.derivatives` imports, else from extrapolated one-sided finite
    differences of the optimal solution."""
    try:
        from biped_opt.paper.derivatives import one_sided_derivatives
    except ImportError:
        return _finite_difference_derivatives(problem, theta0)
    return derivatives_json(one_sided_derivatives(problem, theta0), "variational")


def _finite_difference_derivatives(problem: OptimalControlProblem,
                                   theta0: float) -> dict[str, Any]:
    from biped_opt.paper.biped import theta0_limit
    from biped_opt.paper.solve import optimal_policy
    from biped_opt.piecewise import one_sided

    cache: dict[float, OptimalResult] = {}

    def at(th: float) -> OptimalResult:
        if th not in cache:
            cache[th] = optimal_policy(problem, th)
        return cache[th]

    limit = theta0_limit(problem.maneuver)
    out: dict[str, Any] = {"policy": {}, "method": "finite-difference"}
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
