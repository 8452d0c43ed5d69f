"""``--system`` and ``--problem`` on ``optimise``, ``sweep`` and ``nonsmooth``: any system.

The biped's own options (--theta0, --u1.., --theta-star, --alpha, --bounds, --fixed, --variant)
stay the biped's; with --system a maneuver is swept over its parameter s (--s, --s-min,
--s-max), fixed inputs are ``--input NAME=VALUE``, system parameters ``--param NAME=VALUE``, and
an optimal-control problem is one the system declares (``--problem NAME``, default: the one
named like --maneuver) or a problem file (``--problem FILE.yaml|FILE.py``, whose ``system`` key
may replace --system).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

from biped_opt import strict_json
from biped_opt.cli.args import assignment, finite_float
from biped_opt.errors import InvalidInputError

__all__ = ["add_system_arguments", "uses_system", "problem_from_system_args",
           "run_optimise", "run_sweep", "run_nonsmooth"]

#: the biped's options, refused alongside --system (name on the command line, attribute)
BIPED_ONLY = (("--theta0", "theta0"), ("--theta0-min", "theta0_min"),
              ("--theta0-max", "theta0_max"), ("--theta-star", "theta_star"),
              ("--alpha", "alpha"), ("--bounds", "bounds"), ("--fixed", "fixed"),
              ("--variant", "variant"), ("--u1", "u1"), ("--u2", "u2"), ("--u12", "u12"))


def add_system_arguments(p: argparse.ArgumentParser, *, point: bool = False,
                         sweep: bool = False, problem: bool = True) -> None:
    """The options of any system (see the module docstring)."""
    g = p.add_argument_group("any system (instead of the biped)")
    g.add_argument("--system", metavar="NAME|FILE.py",
                   help="a library system (biped, walkerN[_coupled|_decoupled], rocking_bar) or "
                        "a system file; see `biped-opt systems`")
    if problem:
        g.add_argument("--problem", metavar="NAME|FILE",
                       help="an optimal-control problem the system declares, or a problem file "
                            "(.yaml/.py; README 'Problems on any system')")
    if point:
        g.add_argument("--s", type=finite_float("--s"), help="the maneuver's parameter s")
    if sweep:
        g.add_argument("--s-min", type=finite_float("--s-min"), default=None,
                       help="smallest s (default: the maneuver's range)")
        g.add_argument("--s-max", type=finite_float("--s-max"), default=None,
                       help="largest s (default: the maneuver's range)")
    g.add_argument("--input", action="append", default=[], metavar="NAME=VALUE",
                   type=assignment("--input"), help="a fixed input of the system (repeatable)")
    g.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   type=assignment("--param"), help="a parameter of the system (repeatable)")


def uses_system(args: argparse.Namespace) -> bool:
    """Whether the command line selects a system (else it is the biped's)."""
    if getattr(args, "system", None) is not None or getattr(args, "problem", None) is not None:
        for flag, attr in BIPED_ONLY:
            value = getattr(args, attr, None)
            if value not in (None, False, []):
                raise InvalidInputError(
                    f"{flag}: the biped's option; with --system use --s, --s-min/--s-max, "
                    "--input NAME=VALUE, --param NAME=VALUE and --problem")
        return True
    for flag in ("s", "s_min", "s_max", "input", "param"):
        if getattr(args, flag, None) not in (None, []):
            raise InvalidInputError(f"--{flag.replace('_', '-')}: only with --system")
    return False


def problem_from_system_args(args: argparse.Namespace, *, required: bool = True):
    """The Problem of --system/--problem/--maneuver with --param overrides, or None."""
    from biped_opt.control.problems import describe, load_problem
    from biped_opt.errors import BipedOptError

    try:
        if args.problem is not None:
            problem = load_problem(args.problem, system=args.system)
        else:
            if args.maneuver is None:
                if not required:
                    return None
                raise InvalidInputError("--problem (or --maneuver naming one) is required")
            system = describe(args.system)
            if args.maneuver not in system.problems:
                if not required:
                    return None
                raise InvalidInputError(
                    f"--problem: {system.where()} declares no problem named like --maneuver "
                    f"{args.maneuver!r} (problems: {', '.join(system.problems) or 'none'}); "
                    "give --problem NAME or a problem file")
            problem = load_problem(args.maneuver, system=args.system)
        if args.system is not None and args.problem is not None and \
                Path(str(args.problem)).suffix in (".yaml", ".yml", ".py"):
            chosen = describe(args.system).name
            if problem.description.name != chosen:
                raise InvalidInputError(
                    f"--problem: {args.problem} is a problem on {problem.description.name}, "
                    f"not on --system {chosen}")
        if args.param:
            merged = {**dict(problem.parameters), **dict(args.param)}
            problem = dataclasses.replace(problem, parameters=tuple(merged.items()))
    except InvalidInputError:
        raise
    except BipedOptError as exc:
        raise InvalidInputError(f"--problem: {exc}") from None
    if args.maneuver is not None and args.maneuver != problem.maneuver:
        raise InvalidInputError(f"--maneuver {args.maneuver!r}: the problem {problem.name} is "
                                f"on maneuver {problem.maneuver!r}")
    return problem


def _compiled(args: argparse.Namespace):
    from biped_opt.simulation.compiled import CompiledSystem

    if args.system is None:
        raise InvalidInputError("--system is required")
    if args.maneuver is None:
        raise InvalidInputError("--maneuver is required")
    return CompiledSystem(args.system, **dict(args.param))


def _grid(args: argparse.Namespace, compiled: Any, maneuver: str, num: int):
    from biped_opt.analysis.nonsmooth import s_grid

    return s_grid(compiled, maneuver, args.num or num, args.s_min, args.s_max)


def _progress(args: argparse.Namespace) -> bool:
    from biped_opt.cli.sweep_cmd import progress_from_args

    return progress_from_args(args)


def run_optimise(args: argparse.Namespace) -> int:
    from biped_opt.control.solve import optimal_policy

    problem = problem_from_system_args(args)
    if args.s is None:
        raise InvalidInputError("--s is required with --system")
    from biped_opt.control.theorem1 import optimal_derivatives
    from biped_opt.errors import SimulationError

    r = optimal_policy(problem, args.s)
    derivatives = None
    if r.success:
        try:
            d = optimal_derivatives(problem, args.s)
        except SimulationError as exc:  # e.g. a grazing terminal event: say so, keep the optimum
            print(f"note: no one-sided derivatives at this s: {exc}", file=sys.stderr)
        else:  # the form of the biped's optimise --json
            derivatives = {"outcome": list(d.outcome), "value": list(d.value),
                           "policy": {k: list(v) for k, v in d.policy.items()},
                           "method": "variational (Theorem 1)"}
    if args.json:
        out = r.as_dict()
        out["problem"] = problem.as_dict()
        if derivatives is not None:
            out["derivatives"] = derivatives
        print(strict_json.dumps(out))
        return 0 if r.success else 1
    print(f"problem    {problem.name}  ({problem.description.name}, maneuver "
          f"{problem.maneuver})  s = {r.s:+.12g}")
    print(f"status     {'ok' if r.success else 'failed'}: {r.message}")
    print("policy     " + "  ".join(f"{k} = {v:+.12g}" for k, v in r.policy.items())
          + (f"  (bound: {r.bound})" if r.bound else ""))
    print(f"value      {r.value:.15g}")
    print(f"outcome    {r.outcome:+.15g}")
    print(f"branch     {r.branch}")
    if derivatives is not None:
        from biped_opt.cli.optimise_cmd import print_derivatives

        print_derivatives(str(problem.description.s), derivatives)
    print(f"work       simulations = {r.nsim}")
    return 0 if r.success else 1


def run_sweep(args: argparse.Namespace) -> int:
    if args.optimal or args.problem is not None:
        from biped_opt.control.solve import compiled_for, optimal_sweep
        from biped_opt.progress import bar as _bar

        problem = problem_from_system_args(args)
        grid = _grid(args, compiled_for(problem), problem.maneuver, 201)
        bar = _bar(_progress(args), grid.size, f"{problem.name} sweep")
        results = optimal_sweep(problem, grid, callback=bar.update)
        names = problem.decision_names
        rows = [{"s": r.s, "outcome": r.outcome, "value": r.value, "policy": r.policy,
                 "branch": r.branch, "success": r.success} for r in results]
        header = f"{'s':>14} {'outcome':>18} {'value':>18}  policy  branch"
        lines = [f"{r.s:>14.9g} {r.outcome:>18.12g} {r.value:>18.12g}  "
                 + "  ".join(f"{d}={r.policy[d]:+.10g}" for d in names) + f"  {r.branch}"
                 for r in results]
        data = {"problem": problem.as_dict(), "points": rows}
        ok = all(r.success for r in results)
    else:
        from biped_opt.control.solve import branch_of
        from biped_opt.simulation.compiled import STATUS_NAMES

        compiled = _compiled(args)
        maneuver = args.maneuver
        compiled.initial_mode(maneuver)
        grid = _grid(args, compiled, maneuver, 401)
        u = compiled._inputs(dict(args.input))
        out = compiled.simulate_batch(maneuver, grid, u)
        first = compiled.initial_mode(maneuver)
        branches = [branch_of(compiled, first, out["events"][k, : int(out["n_events"][k])],
                              STATUS_NAMES[int(out["status"][k])]) for k in range(grid.size)]
        header = f"{'s':>14} {'outcome':>18}  branch"
        lines = [f"{x:>14.9g} {out['outcome'][k]:>18.12g}  {branches[k]}"
                 for k, x in enumerate(grid)]
        data = {"system": compiled.name, "maneuver": maneuver,
                "inputs": dict(zip(compiled.inputs, u.tolist())),
                "parameters": compiled.parameters, "s": grid.tolist(),
                "outcome": out["outcome"].tolist(), "t_final": out["t_final"].tolist(),
                "branch": branches}
        ok = bool((out["status"] == 0).all())
    from biped_opt.cli.sweep_cmd import print_sweep

    return print_sweep(args, data, header, lines, ok)


def run_nonsmooth(args: argparse.Namespace) -> int:
    from biped_opt.analysis.nonsmooth import find_nonsmooth, find_nonsmooth_optimal

    progress = _progress(args)
    if args.optimal or args.problem is not None:
        problem = problem_from_system_args(args)
        from biped_opt.control.solve import compiled_for

        grid = _grid(args, compiled_for(problem), problem.maneuver, 201)
        report = find_nonsmooth_optimal(problem, grid, progress=progress)
    else:
        compiled = _compiled(args)
        compiled.initial_mode(args.maneuver)
        grid = _grid(args, compiled, args.maneuver, 401)
        report = find_nonsmooth(compiled, args.maneuver, dict(args.input), s=grid,
                                progress=progress)
    from biped_opt.cli.nonsmooth_cmd import print_report

    return print_report(report, args.json)
