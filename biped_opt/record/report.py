"""Offline analysis of recorded sweeps: the paper's figures and a nonsmoothness table.

Nothing runs but this code: the SweepPoints of one or more recordings (``/biped/sweep``: angle,
policy, value, outcome, final time, mode sequence, event times) and each file's ``biped_opt.sweep``
metadata record (maneuver, fixed-input or optimal, inputs, cost) are turned into the plain arrays
of the paper's figures by the helpers of :mod:`biped_opt.paper.figures` and drawn by
:mod:`biped_opt.plots.figures`:

- Fig. 2 (outcome and cost at fixed inputs) and Fig. 3 (contact mode over t and th0, drawn from
  the recorded mode sequences and event times) from fixed-input sweeps;
- Fig. 4 (optimal outcome, policy, value; Eqs. (5), (6) of [1]_) from optimal sweeps.

A maneuver no file holds leaves its column of the figure empty ("not in the data").

A recording of another system (``biped_opt.system`` metadata: its SystemState sweep over the
maneuver's s) gets the nonsmoothness table of its outcome over s, the contact modes named by the
system's constraints, and a plot of the outcome over s; a fixed-input sweep has no cost (no
value), an optimal one (its problem in the ``biped_opt.sweep`` record's ``problem``) adds the
value and the policy to the table and the plot. ``refine`` re-locates the biped's points only.

**Nonsmoothness at grid resolution.** The recorded angles are handed to the core as
:class:`~biped_opt.analysis.sampled.Samples` and :func:`biped_opt.analysis.sampled.grid_nonsmooth`
estimates the points they hold: every change of the mode order (for optima also of the bound
holding the policy, or a policy step much larger than its neighbours') between neighbouring
recorded angles brackets a point; cubics through the 4 nearest recorded points of each side give
one-sided limits and slopes, the quadratics through 3 their error estimates, and differences
beyond 3x the errors are a **jump** or a **kink**. These are estimates from the recording, as good
as its grid: the bracket width (the recorded spacing) bounds the location error, and the table
says so. ``refine=True`` re-locates every point to 1e-10 with the core's engine
(:mod:`biped_opt.paper.nonsmooth`, which simulates and optimises again) and prints both.

Everything also goes into one self-contained HTML page, ``report.html``
(:mod:`biped_opt.record.html_page`). Nothing is drawn here either: the figures are
:mod:`biped_opt.plots`' (Figs. 2-4 from
:mod:`biped_opt.paper.figures`' data, another system's sweep by
:func:`biped_opt.plots.recorded.sweep_figure`).

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from biped_opt.analysis.sampled import GridPoint, Samples, labels
from biped_opt.analysis.sampled import grid_nonsmooth as _grid_nonsmooth
from biped_opt.analysis.switches import NonsmoothReport
from biped_opt.errors import BipedOptError
from biped_opt.paper.biped import INPUT_NAMES, ContactMode
from biped_opt.paper.problems import OptimalControlProblem, get_problem
from biped_opt.paper.sweeps import FixedSweep, OptimalSweep
from biped_opt.record.html_page import write_page
from biped_opt.record.reader import (
    RawRecording,
    decode_messages,
    read_raw,
    recorded_system,
    undecodable_note,
)
from biped_opt.simulation.trajectory import mode_name

__all__ = [
    "ReportError",
    "RecordedSweep",
    "GridPoint",
    "samples",
    "Report",
    "load_sweep",
    "grid_nonsmooth",
    "grid_table",
    "report",
]

Array = npt.NDArray[np.float64]

class ReportError(BipedOptError, ValueError):
    """A recording holds no sweep that can be analysed."""


@dataclass(frozen=True, eq=False)
class RecordedSweep:
    """The SweepPoints of one recording as arrays, sorted by th0."""

    path: Path
    maneuver: str
    optimal: bool
    #: the cost (Eqs. (14), (15)) the recorder used; None for another system (no cost)
    problem: OptimalControlProblem | None
    inputs: Array  #: (u1, u2, u12) of a fixed-input sweep (NaN for optimal sweeps)
    theta0: Array
    outcome: Array
    value: Array
    t_final: Array
    policy: dict[str, Array]  #: decision -> values (optimal) or u1, u2, u12 (fixed)
    mode_sequences: tuple[tuple[int, ...], ...]
    event_times: tuple[tuple[float, ...], ...]
    metadata: dict[str, str]
    complete: bool
    note: str
    #: the recorded system: "biped", or another system's name (theta0 is then its s)
    system: str = "biped"
    #: another system's constraints in declaration order (the bits of its contact modes)
    constraints: tuple[str, ...] = ()
    #: the problem of an optimal sweep of another system (Problem.as_dict(), as recorded)
    system_problem: dict[str, Any] | None = None

    @property
    def decision_bounds(self) -> tuple[tuple[str, tuple[float, float]], ...]:
        """The decisions of an optimal sweep with their bounds, in the problem's order."""
        if not self.optimal:
            return ()
        if self.problem is not None:
            return tuple((d, self.problem.bound(d)) for d in self.problem.decisions)
        assert self.system_problem is not None
        return tuple((str(d), (float(b[0]), float(b[1])))
                     for d, b in self.system_problem["decisions"].items())

    @property
    def has_value(self) -> bool:
        """Whether a cost, hence a value, is defined (not for another system's fixed inputs)."""
        return self.problem is not None or self.system_problem is not None

    @property
    def branch(self) -> tuple[str, ...]:
        return tuple("->".join(self._mode_name(m) for m in s) if s else "FAILED"
                     for s in self.mode_sequences)

    def _mode_name(self, mask: int) -> str:
        if self.system == "biped":
            return ContactMode(mask).name
        return mode_name(mask, self.constraints)

    @property
    def kind(self) -> str:
        return "optimal" if self.optimal else "fixed"

    @property
    def label(self) -> str:
        """The maneuver, prefixed by the system's name for another system than the biped."""
        return self.maneuver if self.system == "biped" else f"{self.system}:{self.maneuver}"


def _problem(meta: dict[str, str], maneuver: str, path: Path) -> OptimalControlProblem:
    """The biped's problem the recording was costed with (its ``cost``, else the maneuver's
    default); a recorded problem that is no problem of the biped is a :class:`ReportError`."""
    text = meta.get("cost")
    try:
        if not text:
            return get_problem(maneuver)
        d = json.loads(text)
        decisions = tuple(d["decisions"])
        fixed = tuple(float(d.get("fixed_inputs", {}).get(n, 0.0)) for n in INPUT_NAMES)
        return OptimalControlProblem(
            name=str(d.get("name", maneuver)), maneuver=d.get("maneuver", maneuver),
            decisions=decisions, fixed_inputs=fixed,  # type: ignore[arg-type]
            bounds=tuple(tuple(d["bounds"][k]) for k in decisions),  # type: ignore[arg-type]
            theta_star=float(d["theta_star"]),
            alphas=tuple(float(d["alphas"][k]) for k in decisions))
    except (BipedOptError, KeyError, TypeError, ValueError) as exc:
        raise ReportError(f"{path}: the recorded sweep (maneuver {maneuver[:40]!r}) has no "
                          f"problem of the biped: {exc}") from None


#: the topics a report reads
SWEEP_TOPICS = ("/biped/sweep", "/biped/system_info")


def load_sweep(path: str | Path | RawRecording) -> RecordedSweep:
    """Read the SweepPoints (and the system's description) of a recording; unfinished files are
    recovered. The ``biped_opt.sweep`` record says what kind of sweep it is; without it (lost to
    damage: :func:`~biped_opt.record.reader.checked_metadata`) the SweepPoints do, and a fixed
    sweep of the biped is costed with its maneuver's default problem."""
    raw = path if isinstance(path, RawRecording) else read_raw(path, topics=SWEEP_TOPICS)
    sweep = [m for m in raw.messages if m.topic == "/biped/sweep"]
    if not sweep:
        raise ReportError(f"{raw.path}: no /biped/sweep messages ({raw.note})")
    described = recorded_system(raw)
    decoded, bad = decode_messages(raw, sweep)
    msgs, odd = _usable_points([msg for _, msg in decoded],
                               len(described["constraints"]) if described else 2)
    lost = sum(bad.values()) + odd
    note = raw.note + undecodable_note(bad) + (
        f"; {odd} sweep points left out (a non-finite angle, a contact mode the system does "
        "not have, or a policy unlike the other points')" if odd else "")
    if not msgs:
        raise ReportError(f"{raw.path}: none of its {len(sweep)} /biped/sweep messages is a "
                          f"sweep point that can be used ({note})")
    meta = raw.metadata.get("biped_opt.sweep", {})
    maneuver = meta.get("maneuver") or msgs[0].maneuver
    pol = np.array([np.asarray(m.policy, dtype=float) for m in msgs]).reshape(len(msgs), -1)
    extra: dict[str, Any] = {}
    problem: OptimalControlProblem | None = None
    optimal = (meta["optimal"] == "True") if "optimal" in meta else bool(msgs[0].optimal)
    if described is not None:  # another system: a sweep over s, no cost at fixed inputs
        extra = {"system": str(described["system"]),
                 "constraints": tuple(described["constraints"])}
        if optimal:
            try:
                extra["system_problem"] = json.loads(meta["problem"])
                names: Sequence[str] = tuple(extra["system_problem"]["decisions"])
            except (KeyError, TypeError, ValueError):
                raise ReportError(f"{raw.path}: an optimal sweep of {described['system']} "
                                  "without its problem (biped_opt.sweep: problem)") from None
            inputs = np.full(len(described["inputs"]), np.nan)
        else:
            names = tuple(described["inputs"])
            inputs = pol[0]
    elif optimal:
        problem = _problem(meta, maneuver, raw.path)
        names = problem.decisions
        inputs = np.full(3, np.nan)
    else:
        problem = _problem(meta, maneuver, raw.path)
        names = INPUT_NAMES[: pol.shape[1]]
        text = meta.get("fixed_inputs")
        inputs = np.zeros(3)
        given = json.loads(text) if text else pol[0].tolist()
        if len(given) > inputs.size:
            raise ReportError(f"{raw.path}: {len(given)} fixed inputs recorded for the biped's "
                              f"{inputs.size}")
        inputs[: len(given)] = given
    if pol.shape[1] != len(names):
        raise ReportError(f"{raw.path}: policy has {pol.shape[1]} entries, expected "
                          f"{len(names)} ({', '.join(names) or 'no inputs'})")
    return RecordedSweep(
        path=raw.path, maneuver=maneuver, optimal=optimal, problem=problem, inputs=inputs,
        theta0=np.array([m.theta0 for m in msgs]), outcome=np.array([m.outcome for m in msgs]),
        value=np.array([m.value for m in msgs]), t_final=np.array([m.t_final for m in msgs]),
        policy={n: pol[:, k] for k, n in enumerate(names)},
        mode_sequences=tuple(tuple(int(v) for v in m.mode_sequence) for m in msgs),
        event_times=tuple(tuple(float(v) for v in m.event_times) for m in msgs),
        metadata=dict(meta), complete=raw.complete and not lost, note=note, **extra,
    )


def _usable_points(msgs: list[Any], constraints: int) -> tuple[list[Any], int]:
    """The sweep points a report can use, sorted by angle (a repeated angle: the later point
    wins), and how many it cannot: a non-finite angle, a contact mode beyond the system's
    ``constraints``, a policy of another length than most points'. (A file's CRCs say only that
    it holds what its writer wrote.)"""
    lengths = Counter(len(m.policy) for m in msgs)
    width = lengths.most_common(1)[0][0] if lengths else 0
    points: dict[float, Any] = {}
    odd = 0
    for msg in msgs:
        if (not math.isfinite(msg.theta0) or len(msg.policy) != width
                or any(not 0 <= int(v) < 1 << constraints for v in msg.mode_sequence)):
            odd += 1
            continue
        points[float(msg.theta0)] = msg
    return [points[k] for k in sorted(points)], odd


# --- nonsmoothness from the recorded grid ------------------------------------------------------
def samples(s: RecordedSweep) -> Samples:
    """The recorded sweep as the core's :class:`~biped_opt.analysis.sampled.Samples`: outcome,
    the decisions' policies of an optimal sweep, and the value where a cost defines one."""
    q = {"outcome": s.outcome}
    q.update({f"policy:{d}": s.policy[d] for d, _ in s.decision_bounds})
    if s.has_value:  # (another system's fixed inputs have no cost, hence no value)
        q["value"] = s.value
    return Samples(s=s.theta0, branch=s.branch, quantities=q, optimal=s.optimal,
                   bounds=s.decision_bounds)


def grid_nonsmooth(s: RecordedSweep) -> list[GridPoint]:
    """Nonsmooth points estimated from the recorded angles
    (:func:`biped_opt.analysis.sampled.grid_nonsmooth`)."""
    return _grid_nonsmooth(samples(s))


def grid_table(s: RecordedSweep, points: Sequence[GridPoint]) -> str:
    """Plain-text table of grid-resolution estimates, headed by what they are."""
    spacing = np.diff(s.theta0)
    head = [
        f"== {s.label} ({'optimal' if s.optimal else 'fixed inputs'}) from {s.path.name}: "
        f"{s.theta0.size} recorded {'angles' if s.system == 'biped' else 's values'} in "
        f"[{s.theta0[0]:g}, {s.theta0[-1]:g}], "
        f"spacing {spacing.min():.3g}..{spacing.max():.3g} ==",
        "GRID-RESOLUTION ESTIMATES from the recording: each point lies in the recorded bracket "
        "[lo, hi]; left/right are one-sided",
        "limits (jump) or slopes (kink) of cubics through the 4 nearest recorded angles of each "
        "side, at theta0: the isolated",
        "angle inside the bracket, else where the cubics of a continuous quantity meet (its "
        "kink), else the bracket's centre;",
        "+- is the change from the quadratic through 3 (error estimate). --refine locates to "
        "1e-10.",
    ]
    if not s.complete:
        head.append(f"(recording RECOVERED: {s.note})")
    lines = [f"{'theta0':>12} {'bracket [lo, hi]':>25} {'width':>9} {'quantity':<12} "
             f"{'kind':<5} {'left':>12} {'+-':>8} {'right':>12} {'+-':>8}  cause"]
    for g in points:
        p = g.point
        err = g.limit_error if p.kind == "jump" else g.slope_error
        q = p.quantity if p.input is None else f"{p.quantity}:{p.input}"
        lines.append(
            f"{p.theta0:>12.6g} [{p.bracket[0]:>+11.6g}, {p.bracket[1]:>+11.6g}] "
            f"{g.width:>9.2g} {q:<12} {p.kind:<5} {p.left:>12.6g} {err[0]:>8.1g} "
            f"{p.right:>12.6g} {err[1]:>8.1g}  {p.cause}")
    if not points:
        lines.append("(no jump or kink resolved at this grid resolution)")
    return "\n".join(head + lines)


# --- figures and the report --------------------------------------------------------------------
@dataclass(frozen=True)
class Report:
    figures: tuple[Path, ...]
    table_path: Path
    table: str
    sweeps: tuple[RecordedSweep, ...]
    grid_points: dict[str, tuple[GridPoint, ...]]
    refined: tuple[NonsmoothReport, ...] = ()
    #: the whole report as one self-contained HTML page (biped_opt.record.html_page)
    page: Path | None = None


def _fixed_sweep(s: RecordedSweep) -> FixedSweep:
    n = s.theta0.size
    return FixedSweep(
        maneuver=s.maneuver, inputs=s.inputs, theta0=s.theta0, outcome=s.outcome,
        t_final=s.t_final, status=("OK",) * n, branch=s.branch, event_times=s.event_times,
        nfev=np.zeros(n, dtype=np.int64))


def _optimal_sweep(s: RecordedSweep) -> OptimalSweep:
    assert s.problem is not None  # (a sweep of the biped always has its problem)
    n = s.theta0.size
    bound = []
    for lab in labels(samples(s)):
        held = [h for h in lab[1] if h is not None]
        bound.append(held[0] if held else None)
    return OptimalSweep(
        problem=s.problem, theta0=s.theta0, policy=dict(s.policy), value=s.value,
        outcome=s.outcome, branch=s.branch, active=(None,) * n, bound=tuple(bound),
        success=np.ones(n, dtype=bool), nsim=np.zeros(n, dtype=np.int64),
        nfev=np.zeros(n, dtype=np.int64), results=())


def report(paths: Sequence[str | Path | RawRecording], out_dir: str | Path, *,
           refine: bool = False, processes: int = 1) -> Report:
    """Figures (whichever the recordings allow) and the nonsmoothness table into ``out_dir``;
    ``processes`` > 1 draws up to that many figures at once in forked processes
    (:func:`biped_opt.plots.parallel.draw_all`: only in a process with no other thread)."""
    from biped_opt.paper.figures import fixed_data, optimal_data
    from biped_opt.plots.figures import figure2, figure3, figure4
    from biped_opt.plots.parallel import draw_all
    from biped_opt.plots.reproduce import nonsmooth_table

    if not paths:
        raise ReportError("no recordings given")
    out = Path(out_dir)
    sweeps = [load_sweep(p) for p in paths]
    try:  # only now: a bad recording leaves no empty output directory behind
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ReportError(f"cannot create directory {str(out)!r}: {exc.strerror}") from None
    by_key: dict[tuple[str, str], RecordedSweep] = {}
    for s in sweeps:
        by_key[(s.kind, s.label)] = s  # a later file of the same kind and maneuver wins
    grid: dict[str, tuple[GridPoint, ...]] = {}
    blocks = []
    fixed, optimal = {}, {}
    drawings: list[Callable[[], Path]] = []
    for (kind, label), s in by_key.items():
        pts = grid_nonsmooth(s)
        grid[f"{kind}:{label}"] = tuple(pts)
        blocks.append(grid_table(s, pts))
        core = [g.point for g in pts]
        if s.system != "biped":
            drawings.append(functools.partial(
                _system_figure, s, pts,
                out / f"{s.system}_{s.maneuver}{'_optimal' if s.optimal else ''}.png"))
        elif kind == "fixed":
            assert s.problem is not None  # (a sweep of the biped always has its problem)
            fixed[label] = fixed_data(_fixed_sweep(s), s.problem, core)
        else:
            optimal[label] = optimal_data(_optimal_sweep(s), core)
    if fixed:
        td, lo = fixed.get("touchdown"), fixed.get("liftoff")
        drawings += [functools.partial(figure2, td, lo, out / "fig2.png"),
                     functools.partial(figure3, td, lo, out / "fig3.png")]
    if optimal:
        drawings.append(functools.partial(figure4, optimal.get("touchdown"),
                                          optimal.get("liftoff"), out / "fig4.png"))
    figures = draw_all(drawings, processes)
    refined: list[NonsmoothReport] = []
    biped = [s for s in by_key.values() if s.system == "biped"]
    if refine and biped:
        from biped_opt.paper.nonsmooth import find_nonsmooth_fixed, find_nonsmooth_optimal

        for s in biped:
            if s.kind == "fixed":
                refined.append(find_nonsmooth_fixed(s.maneuver, s.theta0, s.inputs))
            else:
                assert s.problem is not None
                refined.append(find_nonsmooth_optimal(s.problem, s.theta0))
        blocks.append("REFINED with the core (simulated/optimised again, located to 1e-10):\n\n"
                      + nonsmooth_table(refined))
        blocks.append(_comparison(grid, biped, refined))
    if refine and len(biped) < len(by_key):
        blocks.append("(--refine re-locates the biped's points only; the other systems' are "
                      "grid estimates)")
    table = "\n\n".join(blocks) + "\n"
    table_path = out / "nonsmooth_recorded.txt"
    table_path.write_text(table)
    result = Report(figures=tuple(figures), table_path=table_path, table=table,
                    sweeps=tuple(by_key.values()), grid_points=grid, refined=tuple(refined))
    return dataclasses.replace(result, page=write_page(result, out))


def _system_figure(s: RecordedSweep, points: Sequence[GridPoint], path: Path) -> Path:
    """Outcome over s of another system's recorded sweep, coloured by mode sequence, with the
    grid-resolution nonsmooth points marked; an optimal sweep adds its value and policy
    (:func:`biped_opt.plots.recorded.sweep_figure`)."""
    from biped_opt.plots.recorded import sweep_figure

    return sweep_figure(
        path, s.theta0, s.branch, s.outcome, value=s.value if s.optimal else None,
        policy={d: s.policy[d] for d, _ in s.decision_bounds} if s.optimal else None,
        points=[g.point.theta0 for g in points],
        title=f"{s.system}: {s.maneuver} ({'optimal' if s.optimal else 'fixed inputs'})")


def _comparison(grid: dict[str, tuple[GridPoint, ...]], sweeps: list[RecordedSweep],
                refined: list[NonsmoothReport]) -> str:
    lines = ["Grid estimate vs refined (same quantity and kind, nearest refined point):",
             f"{'sweep':<22} {'quantity':<12} {'kind':<5} {'theta0 grid':>12} "
             f"{'theta0 refined':>16} {'left grid':>12} {'left refined':>13} {'right grid':>12} "
             f"{'right refined':>14}"]
    for s, rep in zip(sweeps, refined):
        for g in grid[f"{s.kind}:{s.label}"]:
            p = g.point
            same = [r for r in rep.points
                    if (r.quantity, r.input, r.kind) == (p.quantity, p.input, p.kind)]
            q = p.quantity if p.input is None else f"{p.quantity}:{p.input}"
            if not same:
                lines.append(f"{s.kind + ':' + s.maneuver:<22} {q:<12} {p.kind:<5} "
                             f"{p.theta0:>12.6g} {'(not confirmed)':>16}")
                continue
            r = min(same, key=lambda r: abs(r.theta0 - p.theta0))
            lines.append(
                f"{s.kind + ':' + s.maneuver:<22} {q:<12} {p.kind:<5} {p.theta0:>12.6g} "
                f"{r.theta0:>16.10g} {p.left:>12.6g} {r.left:>13.9g} {p.right:>12.6g} "
                f"{r.right:>14.9g}")
    return "\n".join(lines)
