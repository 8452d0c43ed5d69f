"""Figures for any system, and the control experiment of the paper's claim (SYSTEMS.md Secs. 2-3).

The drawing functions take data (arrays and simple records), never a solver, so any analysis
can feed them; each writes one PNG and returns its path. What they show is computed in the core:
:mod:`biped_opt.analysis.figure_data` (sweeps, contact-mode bands, nonsmooth points of any
system) and :mod:`biped_opt.paper.figures` (the control experiment's data); the names defined
there are also importable from here.

- :func:`outcome_figure`: outcomes or costs over s, each curve broken at its jumps (never a
  vertical segment joining two branches), nonsmooth points marked per kind;
- :func:`draw_modes` (and :func:`modes_figure`, a compiled system's sweep): contact mode over
  time and s (Fig. 3 of [1]_ for any system), from
  :func:`~biped_opt.analysis.figure_data.mode_bands`;
- :func:`policy_value_figure`: an optimal policy (one curve per input) and value over s;
- :func:`fixed_input_figures` and :func:`optimal_figures` (``biped-opt figures --system``): a
  system's sweep at fixed inputs, or a problem's optimal sweep
  (:func:`~biped_opt.analysis.figure_data.fixed_input_curves`,
  :func:`~biped_opt.analysis.figure_data.optimal_curves`) drawn with the figures above into one
  directory, with captions.txt and data.json (what each figure shows);
- :func:`control_experiment_figure`: the paper's point in one picture. The two-leg walker under
  the coupled input law (the paper's biped) and under the decoupled law (each leg's input acts
  whenever its foot is down, Pace & Burden 2017): same mechanics, only the coupling differs; the
  coupled touchdown outcome is kinked and its liftoff outcome jumps at th0 = 0, the decoupled ones
  are C^1 there. Beside them the rocking bar, whose coupling is inertial: its outcome jumps
  without any input at all. Its data comes from
  :func:`biped_opt.paper.figures.control_experiment_data`.

A nonsmooth point ("point" below) is any record with attributes or keys ``s`` (or ``theta0``)
and ``kind`` ("kink", "jump", ...), and optionally ``cause``, ``left``/``right`` (one-sided
limits for a jump, slopes for a kink), ``at`` (the value at s), ``series`` (or ``input``: the
curve it belongs to; none: every curve) and ``quantity`` ("policy"/"value": the panel it belongs
to). :class:`~biped_opt.analysis.figure_data.Mark` is such a record, and so is
:class:`biped_opt.analysis.switches.NonsmoothPoint`.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402

from biped_opt.analysis.figure_data import (  # noqa: E402
    Mark,
    ModeBands,
    SweepCurves,
    fixed_input_curves,
    fixed_input_sweep,
    grid_one_sided,
    mode_bands,
    optimal_curves,
    system_marks,
)
from biped_opt.analysis.switches import NonsmoothReport  # noqa: E402
from biped_opt.control.problems import Problem  # noqa: E402
from biped_opt.errors import InvalidInputError  # noqa: E402
from biped_opt.paper.biped import ContactMode  # noqa: E402
from biped_opt.paper.figures import (  # noqa: E402
    LIFTOFF_INPUTS,
    TOUCHDOWN_INPUTS,
    ControlExperiment,
    control_experiment_data,
)
from biped_opt.plots.figures import MODE_COLOURS, _finish  # noqa: E402
from biped_opt.simulation.compiled import CompiledSystem  # noqa: E402
from biped_opt.simulation.trajectory import mode_name  # noqa: E402

__all__ = [
    "Mark",
    "ModeBands",
    "ControlExperiment",
    "outcome_figure",
    "mode_bands",
    "mode_name",
    "modes_figure",
    "draw_modes",
    "policy_value_figure",
    "system_marks",
    "fixed_input_sweep",
    "SystemFigures",
    "fixed_input_figures",
    "optimal_figures",
    "grid_one_sided",
    "control_experiment_data",
    "TOUCHDOWN_INPUTS",
    "LIFTOFF_INPUTS",
    "control_experiment_figure",
    "CONTROL_EXPERIMENT_CAPTION",
]

Array = npt.NDArray[np.float64]

#: how each kind of nonsmooth point is drawn: marker and its colour (never a curve's colour),
#: and the style of the faint vertical line at its s (faint: a jump must not look joined)
KIND_STYLES = {
    "jump": {"marker": "o", "colour": "#762a83", "ls": ":"},
    "kink": {"marker": "D", "colour": "#e08214", "ls": "--"},
    "second-derivative": {"marker": "s", "colour": "0.35", "ls": "-."},
}
#: curve colours in series order (coupled first, decoupled second in the control experiment)
SERIES_COLOURS = ("#b2182b", "#2166ac", "#1b7837", "#4d4d4d", "#8c510a", "#01665e")


def _get(point: Any, *names: str, default: Any = None) -> Any:
    for name in names:
        value = point.get(name) if isinstance(point, Mapping) else getattr(point, name, None)
        if value is not None:
            return value
    return default


def _point(point: Any) -> tuple[float, str]:
    """(s, kind) of a point record, or one clear error."""
    s = _get(point, "s", "theta0")
    kind = _get(point, "kind")
    if s is None or kind is None:
        raise InvalidInputError(
            f"a point needs 's' (or 'theta0') and 'kind', got {type(point).__name__} {point!r}")
    return float(s), str(kind)


def _base_kind(kind: str) -> str:
    """'u1: jump' (a policy component's) -> 'jump'."""
    return kind.rsplit(":", 1)[-1].strip()


def _curves(s: npt.ArrayLike, series: Mapping[str, npt.ArrayLike], what: str
            ) -> tuple[Array, dict[str, Array]]:
    grid = np.asarray(s, dtype=np.float64)
    if grid.ndim != 1 or grid.size < 2:
        raise InvalidInputError(f"s must be a 1-D array of at least 2 values, got {grid.shape}")
    if np.any(np.diff(grid) <= 0):
        raise InvalidInputError("s must be strictly increasing")
    out = {}
    for label, values in series.items():
        v = np.asarray(values, dtype=np.float64)
        if v.shape != grid.shape:
            raise InvalidInputError(
                f"{what} {label!r} has shape {v.shape}, s has {grid.shape}")
        out[str(label)] = v
    return grid, out


def _belongs(point: Any, label: str) -> bool:
    """Whether a point is on the curve ``label`` (a point naming no curve is on every one)."""
    owner = _get(point, "series", "input")
    return owner is None or owner == label


def _draw_curve(ax, s: Array, y: Array, breaks: Sequence[float], **style: Any) -> None:
    """A curve as lines between its breaks; a grid value lying exactly on a break (the
    simultaneous event itself) is an isolated dot."""
    cuts = np.sort(np.asarray(breaks, dtype=np.float64))
    piece = 2 * np.searchsorted(cuts, s, side="left") + np.isin(s, cuts)
    label = style.pop("label", None)
    colour = style.pop("color")
    starts = np.flatnonzero(np.r_[True, piece[1:] != piece[:-1]])
    ends = np.r_[starts[1:], s.size]
    for a, b in zip(starts, ends):
        if piece[a] % 2:  # exactly on a break
            ax.plot(s[a:b], y[a:b], "o", ms=3.5, color=colour, zorder=4)
            continue
        ax.plot(s[a:b], y[a:b], "-", color=colour, label=label, **style)
        label = None


def _draw_points(ax, s: Array, curves: Mapping[str, Array], points: Sequence[Any],
                 causes: bool = True) -> None:
    """A vertical line per point (style by kind), markers at the one-sided limits of a jump and
    at the value of a kink; the causes in a note under the axes (:func:`_cause_note`)."""
    seen: set[str] = set()
    why: list[tuple[float, str, str]] = []
    for p in points:
        x, kind = _point(p)
        base = _base_kind(kind)
        style = KIND_STYLES.get(base, KIND_STYLES["second-derivative"])
        ax.axvline(x, color="0.75", lw=0.7, ls=style["ls"], zorder=0)
        owners = [label for label in curves if _belongs(p, label)]
        for label in owners:
            y = curves[label]
            if base == "jump":
                limits = _get(p, "limits", default=(math.nan, math.nan))
                left = _get(p, "left", default=math.nan) if np.isnan(limits[0]) else limits[0]
                right = _get(p, "right", default=math.nan) if np.isnan(limits[1]) else limits[1]
                ys = [v for v in (left, right) if np.isfinite(v)]
            else:
                at = _get(p, "at", default=math.nan)
                ys = [at if np.isfinite(at) else float(np.interp(x, s, y))]
            ax.plot([x] * len(ys), ys, style["marker"], ms=6, mfc="none", mec=style["colour"],
                    mew=1.3, zorder=5, label=None if base in seen else base)
            seen.add(base)
        cause = _get(p, "cause", default="")
        if cause and causes:
            why.append((x, kind, str(cause)))
    if why:
        _cause_note(ax, why)


#: the longest line of a cause note, in characters (the captions and tables hold it whole)
CAUSE_CHARS = 110


def _cause_note(ax, why: Sequence[tuple[float, str, str]]) -> None:
    """Each point's cause, one line each ("kink at 0: mode order changes: ..."), in small grey
    type under the axes' x label: off the plotting area, so it never crosses a curve (written
    along the point's line, as it once was, it crossed every curve there)."""
    lines = []
    for x, kind, cause in why:
        line = f"{kind} at {x:.7g}: {cause}"
        lines.append(line if len(line) <= CAUSE_CHARS else line[:CAUSE_CHARS - 3] + "...")
    ax.annotate("\n".join(lines), xy=(0.5, 0.0), xycoords=ax.xaxis.label, xytext=(0, -3),
                textcoords="offset points", ha="center", va="top", fontsize=7, color="0.35")


def _panel(ax, s: Array, curves: Mapping[str, Array], points: Sequence[Any],
           causes: bool = True, legend: str = "best") -> None:
    for i, (label, y) in enumerate(curves.items()):
        breaks = [_point(p)[0] for p in points
                  if _base_kind(_point(p)[1]) == "jump" and _belongs(p, label)]
        _draw_curve(ax, s, y, breaks, color=SERIES_COLOURS[i % len(SERIES_COLOURS)], lw=1.3,
                    label=label)
    _draw_points(ax, s, curves, points, causes)
    ax.legend(fontsize=8, loc=legend)


def outcome_figure(path: str | Path, s: npt.ArrayLike, series: Mapping[str, npt.ArrayLike], *,
                   points: Sequence[Any] = (), ylabel: str = "outcome", xlabel: str = "s",
                   title: str = "", figsize: tuple[float, float] = (8.0, 5.0)) -> Path:
    """Outcome (or cost) over s, one curve per entry of ``series``, broken at the jumps among
    ``points`` and with every point marked by kind."""
    grid, curves = _curves(s, series, "series")
    fig, ax = plt.subplots(figsize=figsize, constrained_layout=True)
    _panel(ax, grid, curves, points)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    return _finish(fig, Path(path))


def policy_value_figure(path: str | Path, s: npt.ArrayLike, policy: Mapping[str, npt.ArrayLike],
                        value: npt.ArrayLike, *, points: Sequence[Any] = (), xlabel: str = "s",
                        title: str = "", figsize: tuple[float, float] = (8.0, 7.0)) -> Path:
    """Optimal policy (a) and value (b) over s. A point with a ``quantity`` goes on that panel
    only; one with an ``input``/``series`` goes on that policy curve."""
    grid, inputs = _curves(s, policy, "policy")
    _, values = _curves(grid, {"value": value}, "value")
    fig, axes = plt.subplots(2, 1, figsize=figsize, sharex=True, constrained_layout=True)
    for ax, quantity, curves in ((axes[0], "policy", inputs), (axes[1], "value", values)):
        mine = [p for p in points if _get(p, "quantity", default=quantity) == quantity]
        _panel(ax, grid, curves, mine)
    axes[0].set_ylabel(r"optimal policy $\pi(s)$")
    axes[0].set_title("(a) optimal policy", fontsize=10)
    axes[1].set_ylabel(r"optimal value $\nu(s)$")
    axes[1].set_title("(b) optimal value", fontsize=10)
    axes[1].set_xlabel(xlabel)
    fig.suptitle(title)
    return _finish(fig, Path(path))


# --- contact modes over time and s --------------------------------------------------------------
def _mode_colour(mode: int) -> Any:
    if mode in {m.value for m in ContactMode}:
        return MODE_COLOURS[ContactMode(mode)]  # the biped's colours for the biped's masks
    return plt.get_cmap("tab10")(mode % 10)


def modes_figure(path: str | Path, compiled: CompiledSystem, maneuver: str,
                 s_grid: npt.ArrayLike, inputs: Any = None, *, title: str = "",
                 figsize: tuple[float, float] = (9.0, 5.0),
                 bands: Sequence[ModeBands] | None = None) -> Path:
    """Contact mode over time t (x) and s (y) as coloured bands, contact events as ticks;
    ``bands`` are :func:`biped_opt.analysis.figure_data.mode_bands` of ``s_grid`` (computed
    there when not given)."""
    if bands is None:
        bands = mode_bands(compiled, maneuver, s_grid, inputs)
    return draw_modes(path, bands, compiled.constraints,
                      s_name=compiled.s_name,
                      title=title or f"{compiled.name} {maneuver}: contact mode over time and "
                      f"{compiled.s_name}", figsize=figsize)


def draw_modes(path: str | Path, bands: Sequence[ModeBands], constraint_names: Sequence[str],
               *, s_name: str = "s", title: str = "",
               figsize: tuple[float, float] = (9.0, 5.0)) -> Path:
    """The mode bands of a sweep (one row per s) drawn, modes named by the constraints."""
    if not bands:
        raise InvalidInputError("s_grid must hold at least one value")
    names = tuple(constraint_names)
    ss = np.array([b.s for b in bands])
    steps = np.diff(ss)
    height = float(np.min(np.abs(steps))) if steps.size else 1.0
    fig, ax = plt.subplots(figsize=figsize, constrained_layout=True)
    used: dict[int, None] = {}
    for b in bands:
        for mode, t0, t1 in zip(b.modes, b.starts, b.ends):
            ax.broken_barh([(t0, t1 - t0)], (b.s - height / 2, height), color=_mode_colour(mode),
                           lw=0)
            used[mode] = None
        if b.status != "OK":
            ax.plot([b.ends[-1]], [b.s], "x", color="k", ms=4)
    for mask in sorted({m for b in bands for m in b.switched}):
        hits = [(t, b.s) for b in bands for t, m in zip(b.events, b.switched) if m == mask]
        ts, ys = zip(*hits)
        ax.plot(ts, ys, ".", ms=2.5, mec="none", color=SERIES_COLOURS[mask % 6],
                label=f"event: {mode_name(mask, names)}")
    ax.plot([b.ends[-1] for b in bands], ss, ".", ms=2, color="k", label=r"end $t_f$")
    handles = [plt.Rectangle((0, 0), 1, 1, color=_mode_colour(m)) for m in sorted(used)]
    legend = ax.legend(handles, [mode_name(m, names) for m in sorted(used)], title="mode",
                       loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.add_artist(legend)
    ax.legend(loc="lower left", bbox_to_anchor=(1.01, 0.0), fontsize=8)
    ax.set_xlabel("time t")
    ax.set_ylabel(s_name)
    ax.set_ylim(ss[0] - height, ss[-1] + height)
    ax.set_title(title, fontsize=10)
    return _finish(fig, Path(path))


# --- every figure of one system's sweep, with captions and data ---------------------------------
@dataclass(frozen=True)
class SystemFigures:
    """What :func:`fixed_input_figures` or :func:`optimal_figures` drew: the curves over s (the
    outcome; optimal: also the value and one policy curve per decision), the nonsmooth report
    whose points are marked on them, and the files written (figures, captions, data)."""

    subject: str
    s: Array
    curves: dict[str, Array]
    report: NonsmoothReport
    figures: tuple[Path, ...]
    captions: Path
    data: Path


#: how the nonsmooth points are drawn, for the captions
MARKS_CAPTION = ("Circles: one-sided limits of a jump; diamonds: kinks; squares: second-"
                 "derivative jumps; the cause of each is written under the axes.")


def _caption(file: str | None, text: str) -> str:
    """A caption paragraph wrapped to 96 columns: a figure's under its file name with a hanging
    indent, any other one with its later lines indented by two."""
    import textwrap

    first = "" if file is None else f"{file:<18}"
    return textwrap.fill(text, 96, initial_indent=first,
                         subsequent_indent=" " * (2 if file is None else 18))


def _error(name: str, reference: float) -> str:
    """'(name - r)', or '(name + |r|)' for a negative r."""
    return f"({name} {'-' if reference >= 0 else '+'} {abs(reference):g})"


def _setting(compiled: CompiledSystem, maneuver: str, grid: Array) -> list[str]:
    """Caption lines naming the system, its parameters, the maneuver and the grid."""
    m = compiled.derived.maneuvers[maneuver].description
    where = f" ({compiled.system.source})" if compiled.system.source else ""
    return [_caption(None, text) for text in (
        f"System {compiled.name}{where}, parameters "
        + (", ".join(f"{k} = {v:g}" for k, v in compiled.parameters.items()) or "none") + ".",
        f"Maneuver {maneuver}" + (f": {m.description}" if m.description else "")
        + f"; outcome {m.outcome} at t_f.",
        f"Grid: {grid.size} values of {compiled.s_name} in [{grid[0]:g}, {grid[-1]:g}]"
        + (", 0 included." if 0.0 in grid else "."))]


def _write_outputs(out: Path, subject: str, grid: Array, curves: dict[str, Array],
                   report: NonsmoothReport, figures: Sequence[Path], lines: list[str],
                   about: Mapping[str, Any]) -> SystemFigures:
    """captions.txt (``lines`` and the nonsmooth table) and data.json (what the figures show)."""
    from biped_opt import strict_json

    captions = out / "captions.txt"
    captions.write_text("\n".join([
        *lines, "",
        "Nonsmooth points (left | right: limits for jumps, first derivatives for kinks, second",
        "derivatives for second-derivative jumps; located to 1e-10 in s):", "",
        report.table(), ""]))
    data = out / "data.json"
    data.write_text(strict_json.dumps({
        **about, "s": grid.tolist(), "curves": {k: v.tolist() for k, v in curves.items()},
        "points": [p.as_dict() for p in report.points],
        "figures": [f.name for f in figures]}) + "\n")
    return SystemFigures(subject=subject, s=grid, curves=curves, report=report,
                         figures=tuple(figures), captions=captions, data=data)


def fixed_input_figures(out: str | Path, compiled: CompiledSystem, maneuver: str,
                        grid: npt.ArrayLike, inputs: Any = None, *,
                        progress: bool = False, data: SweepCurves | None = None
                        ) -> SystemFigures:
    """``maneuver`` swept over ``grid`` at fixed ``inputs``: ``outcome.png`` (the outcome with
    its nonsmooth points marked), ``modes.png`` (contact modes over time and s), captions.txt
    and data.json in ``out``. ``data`` is what
    :func:`biped_opt.analysis.figure_data.fixed_input_curves` computes for these arguments
    (computed there when not given)."""
    out = Path(out)
    if data is None:
        data = fixed_input_curves(compiled, maneuver, grid, inputs, progress=progress)
    s, u, outcome, report = data.s, data.inputs, data.curves["outcome"], data.report
    shown = ", ".join(f"{k} = {v:g}" for k, v in zip(compiled.inputs, u)) or "none"
    subject = f"{compiled.name} {maneuver}"
    name = str(compiled.derived.maneuvers[maneuver].description.outcome)
    figures = (
        outcome_figure(out / "outcome.png", s, {f"outcome {name}(t_f)": outcome},
                       points=report.points, ylabel=f"outcome {name}(t_f)",
                       xlabel=compiled.s_name,
                       title=f"{subject}: outcome at inputs {shown}"),
        modes_figure(out / "modes.png", compiled, maneuver, s, u, bands=data.bands),
    )
    lines = [
        _caption(None, f"{subject} at fixed inputs {shown}."),
        *_setting(compiled, maneuver, s), "",
        _caption("outcome.png", f"Outcome {name}(t_f) over {compiled.s_name}, broken at its "
                 f"jumps (a dot: the value exactly at a jump). {MARKS_CAPTION}"),
        _caption("modes.png", f"Contact mode over time t and {compiled.s_name} as coloured "
                 "bands (named by the constraints in contact), contact events as dots (an "
                 "impact that separates at once changes no band but is a dot), t_f in black."),
    ]
    about = {"system": compiled.name, "maneuver": maneuver, "parameters": compiled.parameters,
             "inputs": dict(zip(compiled.inputs, map(float, u)))}
    return _write_outputs(out, subject, s, {"outcome": outcome}, report, figures, lines, about)


def optimal_figures(out: str | Path, problem: Problem, grid: npt.ArrayLike, *,
                    progress: bool = False, data: SweepCurves | None = None) -> SystemFigures:
    """The optimal control of ``problem`` over ``grid``: ``outcome.png`` (the optimal outcome)
    and ``policy_value.png`` (policy and value), each with the nonsmooth points of
    :func:`biped_opt.analysis.nonsmooth.find_nonsmooth_optimal` on its curves, captions.txt and
    data.json in ``out``. ``data`` is what :func:`biped_opt.analysis.figure_data.optimal_curves`
    computes for these arguments (computed there when not given)."""
    from biped_opt.control.solve import compiled_for

    out = Path(out)
    if data is None:
        data = optimal_curves(problem, grid, progress=progress)
    s, report = data.s, data.report
    table = {"outcome": data.curves["outcome"], "value": data.curves["value"],
             **{d: data.curves[f"policy:{d}"] for d in problem.decision_names}}
    compiled = compiled_for(problem)
    names = problem.decision_names
    name = str(compiled.derived.maneuvers[problem.maneuver].description.outcome)
    subject = f"problem {problem.name} on {compiled.name}"
    figures = (
        outcome_figure(out / "outcome.png", s, {f"optimal outcome {name}(t_f)": table["outcome"]},
                       points=[p for p in report.points if p.quantity == "outcome"],
                       ylabel=f"outcome {name}(t_f)", xlabel=compiled.s_name,
                       title=f"{subject}: outcome under the optimal policy"),
        policy_value_figure(out / "policy_value.png", s, {d: table[d] for d in names},
                            table["value"], points=report.points,
                            xlabel=compiled.s_name, title=subject),
    )
    spec = problem.as_dict()
    fixed = ", ".join(f"{k} = {v:g}" for k, v in zip(problem.facts.inputs, problem.inputs())
                      if k not in names) or "none"
    lines = [
        _caption(None, f"{subject}: minimise the cost over "
                 + ", ".join(f"{d} in [{lo:g}, {hi:g}]" for d, (lo, hi) in
                             spec["decisions"].items()) + f" (other inputs: {fixed})."),
        _caption(None, f"Cost: {spec['outcome_weight']:g} {_error('outcome', spec['target'])}^2"
                 + "".join(f" + {w:g} {_error(f'{k}(t_f)', r)}^2"
                           for k, (w, r) in spec["final_state"].items())
                 + "".join(f" + {a:g} {d}^2" for d, a in spec["weights"].items() if a) + "."),
        *_setting(compiled, problem.maneuver, s), "",
        _caption("outcome.png", f"Outcome {name}(t_f) under the optimal policy over "
                 f"{compiled.s_name}, broken at its jumps. {MARKS_CAPTION}"),
        _caption("policy_value.png", "(a) Optimal policy, one curve per decision, and (b) "
                 "optimal value (the minimal cost), each with its own nonsmooth points."),
    ]
    about = {"problem": spec, "system": compiled.name, "maneuver": problem.maneuver,
             "parameters": compiled.parameters}
    return _write_outputs(out, subject, s, data.curves, report, figures, lines, about)


# --- the control experiment ---------------------------------------------------------------------
#: what control_experiment.png shows, for the captions file next to it
CONTROL_EXPERIMENT_CAPTION = """\
control_experiment.png  The paper's claim as a controlled experiment (SYSTEMS.md Secs. 2-3).
          (a, b) The two-leg walker with the paper's coupled input law (u_i acts iff leg i
          alone is down: the biped) and the decoupled law (u_i acts iff foot i is down), same
          mechanics and inputs: touchdown u = (2, 0.5, 0), liftoff u = (1.5, 3, 0), 801
          angles in [-0.02, 0.02], 0 included. Coupled: touchdown kinked, liftoff jumping at
          th0 = 0 (the dot is the simultaneous liftoff itself); decoupled: C^1 (legend: one-
          sided slopes at 0 from the variational equation). Inset: outcome minus its chord
          (a V is a kink).
          (c) The rocking bar (no input; inertial coupling) dropped at pitch th0: its outcome
          th'(t_f) jumps at 0 and where a third impact meets the apex. Curves are broken at
          jumps; circles are one-sided limits, diamonds kinks, located to 1e-10."""


def _law_label(law: str, behaviour: tuple[str, tuple[float, float]]) -> str:
    """'coupled: kink, slopes 0.796 | 0.714' or 'decoupled: C^1, slopes 0.830 | 0.830' from
    :attr:`biped_opt.paper.figures.ControlExperiment.zero`."""
    kind, (left, right) = behaviour
    if kind == "jump":
        return f"{law}: jump, limits {left:+.4f} | {right:+.4f}"
    if kind == "kink":
        return f"{law}: kink, slopes {left:.4f} | {right:.4f}"
    return f"{law}: C$^1$, slopes {left:.4f} | {right:.4f}"


def _value_at(s: Array, y: Array, x: float) -> float:
    hit = np.flatnonzero(s == x)
    return float(y[hit[0]]) if hit.size else math.nan


def _chord_inset(ax, s: Array, curves: Mapping[str, Array]) -> None:
    """Each curve minus its chord through the window's ends: a kink of slopes a | b becomes a
    V of slopes +-(a - b) / 2, a C^1 curve a flat arc (its curvature only)."""
    inset = ax.inset_axes((0.08, 0.6, 0.36, 0.32))
    for i, y in enumerate(curves.values()):
        chord = y[0] + (y[-1] - y[0]) * (s - s[0]) / (s[-1] - s[0])
        inset.plot(s, 1e3 * (y - chord), color=SERIES_COLOURS[i], lw=1.0)
    inset.set_title("minus chord [mrad]", fontsize=7)
    inset.tick_params(labelsize=6)
    inset.axvline(0.0, color="0.75", lw=0.6, ls="--", zorder=0)


def control_experiment_figure(path: str | Path, data: ControlExperiment | None = None, *,
                              figsize: tuple[float, float] = (15.0, 5.0)) -> Path:
    """The paper's point in one picture (module docstring); ``data`` defaults to
    :func:`control_experiment_data` with its defaults."""
    data = control_experiment_data() if data is None else data
    fig, axes = plt.subplots(1, 3, figsize=figsize, constrained_layout=True)
    for ax, maneuver, u, outcome, marks in (
            (axes[0], "touchdown", TOUCHDOWN_INPUTS, data.touchdown, data.touchdown_marks),
            (axes[1], "liftoff", LIFTOFF_INPUTS, data.liftoff, data.liftoff_marks)):
        curves = {_law_label(law, data.zero[(maneuver, law)]): y for law, y in outcome.items()}
        relabel = dict(zip(outcome, curves))
        shown = [replace(m, series=relabel[m.series]) for m in marks
                 if m.kind in ("jump", "kink")]  # the C^1 law's second derivative: not the point
        _panel(ax, data.s, curves, shown,
               legend="lower right" if maneuver == "touchdown" else "upper left")
        if maneuver == "liftoff":
            low, high = ax.get_ylim()
            ax.set_ylim(low, high + 0.3 * (high - low))  # room for the legend above the curves
        letter = "a" if maneuver == "touchdown" else "b"
        ax.set_title(f"({letter}) two-leg walker, {maneuver}, u = "
                     f"({', '.join(f'{v:g}' for v in u)})", fontsize=10)
        ax.set_xlabel(r"initial pitch $\theta_0$ [rad]")
        ax.set_ylabel(r"outcome $\theta(t_f)$ [rad]")
    _chord_inset(axes[0], data.s, data.touchdown)
    ax = axes[2]
    _panel(ax, data.bar_s, {"rocking bar, no input": data.bar}, data.bar_marks, causes=False)
    jumps = ", ".join(f"{m.s:+.7f}" for m in data.bar_marks if m.kind == "jump")
    ax.text(0.02, 0.02, f"jumps at $\\theta_0$ = {jumps}\n(at 0: one simultaneous impact, "
            f"outcome {_value_at(data.bar_s, data.bar, 0.0):g})", transform=ax.transAxes,
            fontsize=7, va="bottom", ha="left",
            bbox={"boxstyle": "round", "fc": "white", "ec": "0.7", "alpha": 0.9})
    low, high = ax.get_ylim()
    ax.set_ylim(low - 0.25 * (high - low), high)  # room for the box under the curves
    ax.set_title("(c) rocking bar dropped at pitch $\\theta_0$: inertial coupling", fontsize=10)
    ax.set_xlabel(r"initial pitch $\theta_0$ [rad]")
    ax.set_ylabel(r"outcome $\dot\theta(t_f)$ at the first apex [rad / time]")
    fig.suptitle("Same mechanics, only the coupling differs: force-coupled inputs (coupled) make "
                 "the outcome kink or jump at simultaneous contact, decoupled inputs keep it "
                 "C$^1$; inertial coupling makes it jump without any input", fontsize=10)
    return _finish(fig, Path(path))
