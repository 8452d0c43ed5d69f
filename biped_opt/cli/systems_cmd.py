"""``biped-opt systems``: the library's systems (or a file's) with their d, n, inputs, maneuvers."""

from __future__ import annotations

import argparse

from biped_opt.cli.args import add_large_argument, check_size
from biped_opt.cli.output import emit_json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("systems", help="list the library's systems (d, n, inputs, maneuvers)",
                       description="The systems that `simulate --system` takes by name, or the "
                                   "ones given (names or files), with their coordinates, "
                                   "constraints, inputs, parameters and maneuvers.")
    p.add_argument("names", nargs="*", metavar="NAME|FILE.py",
                   help="systems to describe (default: the library)")
    p.add_argument("--json", action="store_true", help="print a JSON list")
    p.add_argument("--check", action="store_true",
                   help="integrate each maneuver of each system up to its first event with "
                        "every input at zero and report the drift of the energy it declares "
                        "(status 1 when a drift exceeds the tolerance: a force is wrong)")
    add_large_argument(p)
    p.set_defaults(func=run)


def describe(spec: str) -> dict:
    from biped_opt.system_spec import parse_file_spec
    from biped_opt.systems import derive, load_system

    system = load_system(spec)
    derived = derive(system)  # checks the description, so a broken file says so here
    return {
        "name": spec if spec != system.name and parse_file_spec(spec) is None else system.name,
        "d": derived.ndof, "n": derived.nconstraints,
        "coordinates": list(system.coordinate_names),
        "constraints": list(system.constraints),
        "inputs": list(system.u.names()),
        "parameters": dict(system.defaults),
        "maneuvers": {name: {"s": str(system.s), "s_range": list(m.s_range),
                             "description": m.description}
                      for name, m in system.maneuvers.items()},
    }


def check(spec: str) -> list[dict]:
    """The energy check of ``spec`` (:func:`biped_opt.simulation.energy.energy_drift`), a row
    per maneuver; a system that declares no energy says so."""
    from biped_opt.errors import InvalidInputError
    from biped_opt.simulation.compiled import compile_system
    from biped_opt.simulation.energy import energy_drift

    compiled = compile_system(spec)
    if compiled.system.energy is None and not compiled.derived.bodies:
        return [{"name": spec, "checked": False, "ok": True,
                 "reason": "declares no energy (system.energy)"}]
    rows = []
    for m in compiled.maneuvers:
        try:
            rows.append({"name": spec, "checked": True, **energy_drift(compiled, m).as_dict()})
        except InvalidInputError as exc:  # (bodies whose applied forces do work)
            return [{"name": spec, "checked": False, "ok": True, "reason": str(exc)}]
    return rows


def run(args: argparse.Namespace) -> int:
    from biped_opt.systems import LIBRARY

    names = args.names or [*LIBRARY, "walker2_decoupled"]
    for name in names:
        check_size(args, "NAME", name)
    if args.check:
        checks = [row for name in names for row in check(name)]
        if args.json:
            emit_json(checks)
        else:
            for c in checks:
                if not c["checked"]:
                    print(f"{c['name']}: not checked: {c['reason']}")
                    continue
                what = "" if c["source"] == "declared" else " (the bodies')"
                print(f"{c['name']}: {c['maneuver']} at s = {c['s']:.6g}, inputs 0, "
                      f"t in [0, {c['t_end']:.6g}] ({c['samples']} samples): energy"
                      f"{what} "
                      f"{c['energy']:.10g}, drift {c['drift']:.3g} ({c['relative']:.3g} of "
                      f"its scale, tolerance {c['tolerance']:.0e}): "
                      f"{'ok' if c['ok'] else 'FAILED, a force does not match the energy'}")
        return 0 if all(c["ok"] for c in checks) else 1
    rows = [describe(name) for name in names]
    if args.json:
        emit_json(rows)
        return 0
    print(f"{'system':<18} {'d':>2} {'n':>2}  {'inputs':<22} maneuvers (s range)")
    for r in rows:
        maneuvers = ", ".join(f"{k} ({m['s']} in [{m['s_range'][0]:g}, {m['s_range'][1]:g}])"
                              for k, m in r["maneuvers"].items())
        print(f"{r['name']:<18} {r['d']:>2} {r['n']:>2}  {', '.join(r['inputs']):<22} "
              f"{maneuvers}")
    print("\nwalkerN[_coupled|_decoupled] gives the walker with N legs (walker: 3, coupled); "
          "chain5|7|9|11 the planar chain with that many coordinates (chain: 5); "
          "quadruped (d = 20, n = 4) is built only when named (its description takes "
          "seconds), as are the gradient study's smoothed models biped_smooth and "
          "rocking_bar_soft; a path to a .py file gives your own system (README: Your own "
          "system).")
    return 0
