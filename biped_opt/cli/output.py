"""The command line's output side, shared by the sub-commands: each result kind has one
conversion to its text form and one to its JSON form, and the forms of delivery (one JSON object
on stdout, a JSON file, a table, the paths written).

Nothing here computes: a command hands over what the core returned, these functions print it.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from biped_opt import strict_json
from biped_opt.errors import InvalidInputError

if TYPE_CHECKING:
    from biped_opt.analysis.switches import NonsmoothReport
    from biped_opt.control.solve import OptimalResult
    from biped_opt.simulation.compiled import CompiledSystem
    from biped_opt.simulation.trajectory import Trajectory

__all__ = ["derivatives_json", "emit_json", "emit_paths", "emit_sweep", "fixed_sweep_table",
           "optimal_json", "optimal_sweep_table", "show_derivatives", "show_optimal",
           "show_report", "show_system_trajectory", "show_trajectory",
           "system_trajectory_json", "trajectory_json"]


# -- forms of delivery --------------------------------------------------------------------------

def emit_json(value: Any, *, indent: int | None = None) -> None:
    """``value`` as strict JSON on stdout (no NaN or infinity): one line, or indented."""
    print(strict_json.dumps(value, indent=indent))


def emit_paths(paths: Iterable[Path | str], *, to_stderr: bool = False) -> None:
    """One ``wrote PATH`` line per file written."""
    for path in paths:
        print(f"wrote {path}", file=sys.stderr if to_stderr else sys.stdout)


def emit_sweep(out: Path | None, data: Mapping[str, Any], header: str, lines: Sequence[str],
               ok: bool) -> int:
    """A sweep as JSON to the --out file (and a line saying so), else as a table on stdout;
    the exit status (1 when a point failed)."""
    if out:
        try:
            with open(out, "w", encoding="utf-8") as fh:
                fh.write(strict_json.dumps(data))
        except OSError as exc:
            raise InvalidInputError(f"--out: cannot write {str(out)!r}: {exc.strerror}"
                                    ) from None
        print(f"wrote {len(lines)} points to {out}")
    else:
        print(header)
        print("\n".join(lines))
    return 0 if ok else 1


# -- sweeps: one row per grid point -------------------------------------------------------------

def fixed_sweep_table(parameter: str, grid: Iterable[float], outcome: Sequence[float],
                      branch: Sequence[str]) -> tuple[str, list[str]]:
    """Header and rows of a fixed-input sweep: the parameter, the outcome, the branch."""
    header = f"{parameter:>14} {'outcome':>18}  branch"
    return header, [f"{x:>14.9g} {outcome[k]:>18.12g}  {branch[k]}"
                    for k, x in enumerate(grid)]


def optimal_sweep_table(parameter: str, grid: Iterable[float], outcome: Sequence[float],
                        value: Sequence[float], policy: Sequence[Mapping[str, float]],
                        branch: Sequence[str]) -> tuple[str, list[str]]:
    """Header and rows of an optimal sweep: the parameter, the optimal outcome and value, the
    policy (one NAME=VALUE per decision) and the branch."""
    header = f"{parameter:>14} {'outcome':>18} {'value':>18}  policy  branch"
    return header, [f"{x:>14.9g} {outcome[k]:>18.12g} {value[k]:>18.12g}  "
                    + "  ".join(f"{d}={u:+.10g}" for d, u in policy[k].items())
                    + f"  {branch[k]}" for k, x in enumerate(grid)]


# -- nonsmooth tables ---------------------------------------------------------------------------

def show_report(report: NonsmoothReport, as_json: bool) -> int:
    """A nonsmooth table as text, or as a JSON list of points; the exit status."""
    if as_json:
        emit_json([p.as_dict() for p in report.points])
    else:
        kind = "optimal" if report.optimal else "fixed-input"
        print(f"{report.subject} ({kind}), {report.parameter} in [{report.theta0_range[0]:g}, "
              f"{report.theta0_range[1]:g}], {report.grid_size} grid points, "
              f"{len(report.points)} nonsmooth findings")
        print(report.table())
    return 0


# -- trajectories -------------------------------------------------------------------------------

def _legs(mask: int) -> list[int]:
    """The biped's legs (1 = left, 2 = right) of a mask over its constraints."""
    from biped_opt.paper.biped import ContactMode

    return [j + 1 for j in ContactMode(mask).active]


def _mode_name(mask: int) -> str:
    """The paper's name of a biped contact mode (air, left, right, ground)."""
    from biped_opt.paper.biped import ContactMode

    return ContactMode(mask).name


def _names(mask: int, constraints: tuple[str, ...]) -> list[str]:
    """The constraints of a mode mask, in their declared order."""
    from biped_opt.simulation.trajectory import constraint_names

    return list(constraint_names(mask, constraints))


def trajectory_json(tr: Trajectory) -> dict[str, Any]:
    """The JSON form of a biped trajectory, in the paper's words."""
    return {
        "maneuver": tr.maneuver,
        "theta0": tr.theta0,
        "inputs": {"u1": tr.inputs[0], "u2": tr.inputs[1], "u12": tr.inputs[2]},
        "outcome": tr.outcome,
        "t_final": tr.t_final,
        "status": "ok" if tr.success else tr.status.name.lower(),
        "message": tr.message,
        "modes": [{"t": seg.t_start, "mode": _mode_name(seg.mask)}
                  for seg in tr.segments],
        "events": [
            {"t": e.t, "kind": e.kind, "touchdown": _legs(e.mask_entered),
             "liftoff": _legs(e.mask_left), "mode_before": _mode_name(e.mask_before),
             "mode_after": _mode_name(e.mask_after),
             "state_before": e.state_before.tolist(), "state_after": e.state_after.tolist()}
            for e in tr.contact_events
        ],
        "state": {"q": tr.q_final.tolist(), "qdot": tr.qdot_final.tolist()},
        "nfev": tr.nfev,
        "nsteps": tr.nsteps,
    }


def show_trajectory(tr: Trajectory, as_json: bool) -> int:
    """A biped trajectory as text or one JSON object; the exit status."""
    if as_json:
        emit_json(trajectory_json(tr))
    else:
        print(f"maneuver   {tr.maneuver}  theta0 = {tr.theta0:+.12g}")
        print(f"status     {tr.status.name}: {tr.message}")
        print(f"outcome    th(t_f) = {tr.outcome:+.15g}")
        print(f"t_final    {tr.t_final:.15g}")
        print("modes      " + " -> ".join(f"{_mode_name(seg.mask)}@{seg.t_start:.12g}"
                                          for seg in tr.segments))
        print(f"work       nfev = {tr.nfev}, steps = {tr.nsteps}")
    return 0 if tr.success else 1


def _state(names: tuple[str, ...], y: Any) -> dict[str, dict[str, float]]:
    """A state y = (q, q') by coordinate name."""
    d = len(names)
    return {"q": dict(zip(names, map(float, y[:d]))), "qdot": dict(zip(names, map(float, y[d:])))}


def system_trajectory_json(compiled: CompiledSystem, tr: Trajectory) -> dict[str, Any]:
    """The JSON form of any system's trajectory (coordinates and constraints by name)."""
    names = compiled.coordinates
    return {
        "system": tr.system, "maneuver": tr.maneuver, "s": tr.s,
        "inputs": dict(zip(compiled.inputs, tr.inputs)),
        "parameters": compiled.parameters, "status": tr.status.name.lower(),
        "message": tr.message,
        "outcome": tr.outcome, "t_final": tr.t_final,
        "modes": [_names(seg.mask, tr.constraints) for seg in tr.segments],
        "event_times": list(tr.event_times),
        "events": [{"t": e.t, "touchdown": list(e.entered), "liftoff": list(e.left),
                    "mode_before": _names(e.mask_before, tr.constraints),
                    "mode_after": _names(e.mask_after, tr.constraints),
                    "state_before": _state(names, e.state_before),
                    "state_after": _state(names, e.state_after)}
                   for e in tr.contact_events],
        "state": _state(names, tr.y_final),
        "nfev": tr.nfev, "nsteps": tr.nsteps}


def show_system_trajectory(compiled: CompiledSystem, tr: Trajectory, as_json: bool) -> int:
    """Any system's trajectory as text or one JSON object; the exit status."""
    if as_json:
        emit_json(system_trajectory_json(compiled, tr))
    else:
        print(f"system     {tr.system}  maneuver {tr.maneuver}  s = {tr.s:+.12g}")
        print(f"status     {tr.status.name}: {tr.message}")
        print(f"outcome    {tr.outcome:+.15g}")
        print(f"t_final    {tr.t_final:.15g}")
        print("modes      " + " -> ".join(
            f"{{{', '.join(_names(seg.mask, tr.constraints))}}}@{seg.t_start:.12g}"
            for seg in tr.segments))
        for e in tr.contact_events:
            what = [f"{kind} {{{', '.join(found)}}}"
                    for kind, found in (("touchdown", e.entered), ("liftoff", e.left)) if found]
            print(f"event      t = {e.t:.12g}: {'; '.join(what)}")
        print(f"work       nfev = {tr.nfev}, steps = {tr.nsteps}")
    return 0 if tr.success else 1


# -- optimal solutions --------------------------------------------------------------------------

def derivatives_json(d: Any, method: str) -> dict[str, Any]:
    """One-sided derivatives (left, right) of the optimal outcome, value and policy, as JSON."""
    return {"outcome": list(d.outcome), "value": list(d.value),
            "policy": {k: list(v) for k, v in d.policy.items()}, "method": method}


def show_derivatives(parameter: str, derivatives: Mapping[str, Any]) -> None:
    """The one-sided derivatives of :func:`derivatives_json`'s form as text lines."""
    print(f"{'d/d' + parameter:<10} ({derivatives['method']}; left, right)")
    print(f"  outcome  {derivatives['outcome'][0]:+.10g}  {derivatives['outcome'][1]:+.10g}")
    print(f"  value    {derivatives['value'][0]:+.10g}  {derivatives['value'][1]:+.10g}")
    for k, (lft, rgt) in derivatives["policy"].items():
        print(f"  {k:<8} {lft:+.10g}  {rgt:+.10g}")


def optimal_json(result: OptimalResult, problem: Mapping[str, Any]) -> dict[str, Any]:
    """The JSON form of an optimal solution: the result's plain data with ``problem`` (its
    description) in place of its name. Each candidate keeps, beside its policy, ``decision``: its
    value of the acting decision (null when none or several act), the form the biped's candidates
    had before every problem ran on one solver."""
    out = {**result.as_dict(), "problem": dict(problem)}
    acting = result.active if result.active in result.policy else None
    out["candidates"] = [{**c, "decision": c["policy"][acting] if acting else None}
                         for c in out["candidates"]]
    return out


def show_optimal(as_json: bool, data: Mapping[str, Any], *, problem: str, status: str,
                 policy: Mapping[str, float], bound: str, value: float, outcome: str,
                 branch: str, parameter: str, derivatives: Mapping[str, Any] | None,
                 work: str, success: bool) -> int:
    """An optimal solution: ``data`` as one JSON object (with the derivatives), or the text
    form from the labelled parts (the problem line, status, policy with the bound it sits on,
    value, outcome, branch, the derivatives with respect to ``parameter``, the work done);
    the exit status (1 when the optimiser failed)."""
    if as_json:
        out = dict(data)
        if derivatives is not None:
            out["derivatives"] = derivatives
        emit_json(out)
        return 0 if success else 1
    print(f"problem    {problem}")
    print(f"status     {status}")
    print("policy     " + "  ".join(f"{k} = {v:+.12g}" for k, v in policy.items())
          + (f"  ({bound})" if bound else ""))
    print(f"value      {value:.15g}")
    print(f"outcome    {outcome}")
    print(f"branch     {branch}")
    if derivatives is not None:
        show_derivatives(parameter, derivatives)
    print(f"work       {work}")
    return 0 if success else 1
