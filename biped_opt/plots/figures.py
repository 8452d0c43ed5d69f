"""The paper's figures as PNG files.

- Fig. 2 (a-d): outcome th(t_f) and cost over th0 at fixed inputs, touchdown and liftoff;
- Fig. 3 (a, b): contact mode over time and th0 at fixed inputs (where the mode order flips);
- Fig. 4 (a-f): optimal outcome, policy and value over th0, touchdown and liftoff.

Plotting takes plain arrays (:class:`~biped_opt.paper.figures.FixedSweepData`,
:class:`~biped_opt.paper.figures.OptimalSweepData`, computed by :mod:`biped_opt.paper.figures`)
so the same functions draw live sweeps and sweeps read back from a recording. Nonsmooth points
are marked and annotated with their one-sided limits or slopes.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402

from biped_opt.paper.biped import ContactMode  # noqa: E402
from biped_opt.paper.figures import (  # noqa: E402
    FixedSweepData,
    NonsmoothMark,
    OptimalSweepData,
)
from biped_opt.plots.placement import NOTE, place_notes  # noqa: E402

__all__ = [
    "FixedSweepData",
    "OptimalSweepData",
    "NonsmoothMark",
    "figure2",
    "figure3",
    "figure4",
    "MODE_COLOURS",
]

Array = npt.NDArray[np.float64]

#: one colour per contact mode, shared by every figure
MODE_COLOURS = {
    ContactMode.AIR: "#dbe9f6",
    ContactMode.LEFT: "#e6550d",
    ContactMode.RIGHT: "#3182bd",
    ContactMode.GROUND: "#636363",
}
MANEUVER_TITLES = {"touchdown": "touchdown", "liftoff": "liftoff"}


def _annotate(ax, marks: Sequence[NonsmoothMark], fmt: str = "{:+.4g}") -> None:
    """Marker at each nonsmooth point, with its one-sided numbers in a small box that
    :func:`~biped_opt.plots.placement.place_notes` puts where the data leaves room."""
    for m in marks:
        ax.axvline(m.theta0, color="0.6", lw=0.6, ls=":", zorder=0)
        ax.plot([m.theta0], [m.value], "o", ms=6, mfc="none", mec="crimson", mew=1.4, zorder=5)
        what = f" {m.label}" if m.label else ""
        text = (f"{m.kind} at $\\theta_0$={m.theta0:.3g}\nleft{what} {fmt.format(m.left)}\n"
                f"right{what} {fmt.format(m.right)}")
        ax.annotate(
            text, xy=(m.theta0, m.value), xytext=(0.03, 0.97), textcoords="axes fraction",
            va="top", ha="left", fontsize=7, gid=NOTE, zorder=6,
            bbox={"boxstyle": "round", "fc": "white", "ec": "crimson", "alpha": 0.9},
            arrowprops={"arrowstyle": "-", "color": "crimson", "lw": 0.6},
        )


def _finish(fig, path: Path) -> Path:
    """Place the notes and write the figure. Placing them draws it with its final layout
    (:func:`~biped_opt.plots.placement.place_notes`); writing it keeps that layout instead of
    laying it out a third time (0.05 s of a four-panel figure). The layout is kept in fractions
    of the figure, so it holds at the written resolution as at the drawn one (to a pixel's
    rounding of the text's extents)."""
    if place_notes(fig):
        fig.set_layout_engine("none")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=150)
    plt.close(fig)
    return path


def _not_recorded(axes: Sequence, maneuver: str) -> None:
    """An empty column for a maneuver the data does not hold (e.g. a report of one file)."""
    for ax in axes:
        ax.text(0.5, 0.5, f"{maneuver}: not in the data", ha="center", va="center",
                transform=ax.transAxes, color="0.5")
        ax.set_xticks([])
        ax.set_yticks([])


def figure2(touchdown: FixedSweepData | None, liftoff: FixedSweepData | None, path: Path) -> Path:
    """Fig. 2: outcomes (a, b) and costs (c, d) over th0 at fixed inputs (None: not drawn)."""
    fig, axes = plt.subplots(2, 2, figsize=(10, 7), constrained_layout=True)
    for col, data in enumerate((touchdown, liftoff)):
        if data is None:
            _not_recorded(axes[:, col], ("touchdown", "liftoff")[col])
            continue
        u = ", ".join(f"{v:g}" for v in data.inputs)
        ax = axes[0, col]
        ax.plot(data.theta0, data.outcome, ".", ms=2.5, color="k")
        ax.set_title(f"({'ab'[col]}) {data.maneuver} outcome, u = ({u})", fontsize=10)
        ax.set_xlabel(r"initial pitch $\theta_0$ [rad]")
        ax.set_ylabel(r"outcome $\theta(t_f)$ [rad]")
        _annotate(ax, data.marks)
        ax = axes[1, col]
        ax.plot(data.theta0, data.cost, ".", ms=2.5, color="k")
        ax.set_title(f"({'cd'[col]}) {data.maneuver} cost at fixed inputs", fontsize=10)
        ax.set_xlabel(r"initial pitch $\theta_0$ [rad]")
        ax.set_ylabel(r"cost $c(\theta_0, u)$ [rad$^2$]")
        _annotate(ax, data.cost_marks)
    fig.suptitle("Fig. 2: outcomes and costs at fixed inputs")
    return _finish(fig, path)


def mode_image(data: FixedSweepData, times: Array) -> Array:
    """Mode at each (th0, t) on the grid ``times``; NaN after the maneuver ended."""
    img = np.full((data.theta0.size, times.size), np.nan)
    for k in range(data.theta0.size):
        starts = np.concatenate([[0.0], np.asarray(data.event_times[k], dtype=float)])
        idx = np.searchsorted(starts, times, side="right") - 1
        row = np.asarray(data.modes[k], dtype=float)[np.clip(idx, 0, len(starts) - 1)]
        row[times > data.t_final[k]] = np.nan
        img[k] = row
    return img


def figure3(touchdown: FixedSweepData | None, liftoff: FixedSweepData | None, path: Path) -> Path:
    """Fig. 3: contact mode over time t and initial pitch th0, at fixed inputs."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), constrained_layout=True)
    cmap = ListedColormap([MODE_COLOURS[m] for m in ContactMode])
    for col, data in enumerate((touchdown, liftoff)):
        ax = axes[col]
        if data is None:
            _not_recorded([ax], ("touchdown", "liftoff")[col])
            continue
        t_max = float(np.max(data.t_final))
        times = np.linspace(0.0, t_max, 800)
        img = mode_image(data, times)
        ax.imshow(
            img.T, origin="lower", aspect="auto", cmap=cmap, vmin=-0.5, vmax=3.5,
            extent=(data.theta0[0], data.theta0[-1], 0.0, t_max), interpolation="nearest",
        )
        ax.plot(data.theta0, data.t_final, color="k", lw=0.8, label=r"$t_f$")
        ax.axvline(0.0, color="crimson", lw=0.6, ls=":")
        ax.set_title(f"({'ab'[col]}) {data.maneuver}: contact mode", fontsize=10)
        ax.set_xlabel(r"initial pitch $\theta_0$ [rad]")
        ax.set_ylabel("time t [time units, g = 1]")
        if data.maneuver == "touchdown":
            # the interesting part is the landing: zoom on the stance phases
            first = min(float(np.min(np.asarray(e, dtype=float)[:1], initial=t_max))
                        for e in data.event_times)
            ax.set_ylim(max(0.0, first - 0.1), t_max)
    handles = [plt.Rectangle((0, 0), 1, 1, color=MODE_COLOURS[m]) for m in ContactMode]
    fig.legend(handles, [m.name for m in ContactMode], loc="outside right center")
    fig.suptitle("Fig. 3: contact mode vs time and initial pitch (mode order flips at 0)")
    return _finish(fig, path)


def figure4(touchdown: OptimalSweepData | None, liftoff: OptimalSweepData | None,
            path: Path) -> Path:
    """Fig. 4: optimal outcome (a, b), policy (c, d) and value (e, f) over th0."""
    fig, axes = plt.subplots(3, 2, figsize=(10, 10), constrained_layout=True)
    for col, data in enumerate((touchdown, liftoff)):
        if data is None:
            _not_recorded(axes[:, col], ("touchdown", "liftoff")[col])
            continue
        ax = axes[0, col]
        ax.plot(data.theta0, data.outcome, ".", ms=2.5, color="k")
        ax.set_title(f"({'ab'[col]}) {data.maneuver}: optimal outcome", fontsize=10)
        ax.set_ylabel(r"$\theta(t_f)$ at $\pi(\theta_0)$ [rad]")
        _annotate(ax, data.marks.get("outcome", ()))
        ax = axes[1, col]
        for name, values in data.policy.items():
            ax.plot(data.theta0, values, ".", ms=2.5, label=f"${_tex(name)}^*$")
            if name in data.bounds:
                for b in data.bounds[name]:
                    ax.axhline(b, color="0.7", lw=0.6, ls="--")
        ax.set_title(f"({'cd'[col]}) {data.maneuver}: optimal policy", fontsize=10)
        ax.set_ylabel(r"policy $\pi(\theta_0)$ [force / torque units]")
        ax.legend(fontsize=8, loc="lower right")
        _annotate(ax, data.marks.get("policy", ()))
        ax = axes[2, col]
        ax.plot(data.theta0, data.value, ".", ms=2.5, color="k")
        ax.set_title(f"({'ef'[col]}) {data.maneuver}: optimal value", fontsize=10)
        ax.set_ylabel(r"value $\nu(\theta_0)$ [rad$^2$]")
        _annotate(ax, data.marks.get("value", ()))
        for row in range(3):
            axes[row, col].set_xlabel(r"initial pitch $\theta_0$ [rad]")
    fig.suptitle("Fig. 4: optimal outcomes, policies and values")
    return _finish(fig, path)


def _tex(name: str) -> str:
    return {"u1": "u_1", "u2": "u_2", "u12": "u_{12}"}.get(name, name)
