"""A maneuver as a moving picture: any system's scene in the x-z plane, drawn per frame.

The scene is the one the simulator publishes as markers (:mod:`biped_opt.record.scene`, ROS.md
Sec. 6), drawn with matplotlib instead of a ROS tool, so an animation and a live view agree:

- boxes as rectangles posed by their frame (a planar system's frames turn about y only, so the
  rectangle is the box's x-z face; a rotation out of the plane would show that face's
  projection), spheres as circles, lines as polylines, the ground as the line z = 0;
- the contact points, red while their constraint is active and grey while it is free, and each
  contact force lambda_j as an arrow from its point along the constraint's normal,
  :data:`~biped_opt.record.scene.FORCE_SCALE` m per unit of force (none while free);
- each panel's title: its s, the order of its contact events (``right↓ left↓``: touchdowns,
  ``↑``: liftoffs), its outcome, and at every frame the time t and the contact mode.

Frames are taken at a fixed rate in simulated time (``speed`` simulated seconds per second of
animation, ``fps`` frames per second): the configuration is interpolated between samples (it
is continuous across impacts, only velocities jump), the mode and the forces are the ones
holding at the frame's time. :func:`side_by_side` puts the same maneuver at s0 - delta and
s0 + delta into two panels of one animation: on either side of a simultaneous event (s0 = 0:
the biped's touchdown and liftoff, the rocking bar's drop) the order of the contacts flips,
and with it the outcome (SYSTEMS.md Sec. 2 and [1]_).

GIFs are written with matplotlib's Pillow writer, MP4 with its FFmpeg writer where ffmpeg is
installed; the suffix chooses. The file appears complete or not at all (written under a
temporary name, then renamed).

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402
from matplotlib import animation  # noqa: E402
from matplotlib.patches import Circle, FancyArrowPatch, Polygon  # noqa: E402

from biped_opt.errors import InvalidInputError  # noqa: E402
from biped_opt.record.scene import (  # noqa: E402
    ACTIVE_COLOR,
    ARROW_COLOR,
    CONTACT_DIAMETER,
    FORCE_SCALE,
    FREE_COLOR,
    GROUND_COLOR,
)
from biped_opt.simulation.compiled import CompiledSystem  # noqa: E402
from biped_opt.simulation.scene import Scene, SceneState  # noqa: E402
from biped_opt.simulation.trajectory import Trajectory, constraint_names  # noqa: E402

__all__ = ["Animation", "Drawn", "Panel", "animate", "check_output", "default_inputs",
           "drawn", "frame_times", "panel", "rotation_matrices", "side_by_side",
           "SUFFIXES", "contact_order"]

Array = npt.NDArray[np.float64]

#: output suffix -> matplotlib writer
SUFFIXES = {".gif": "pillow", ".mp4": "ffmpeg"}
#: a panel's size in pixels (width, height) unless given, and the resolution it is drawn at
PANEL_SIZE = (320, 240)
DPI = 80
#: the finest sampling of a run, in simulated seconds (frames are interpolated between samples)
MAX_SAMPLE_DT = 0.005
#: contact events named in a title before the rest is cut to "..."
SHOWN_EVENTS = 4


def check_output(path: Path) -> str:
    """The matplotlib writer for ``path`` by its suffix (.gif: Pillow, .mp4: FFmpeg); an
    unknown suffix, or .mp4 where no ffmpeg is installed, is an InvalidInputError."""
    suffix = Path(path).suffix.lower()
    writer = SUFFIXES.get(suffix)
    if writer is None:
        raise InvalidInputError(f"{path}: unknown animation format {suffix or '(no suffix)'!r} "
                                f"(write {' or '.join(SUFFIXES)})")
    if not animation.writers.is_available(writer):
        raise InvalidInputError(f"{path}: {suffix} needs {writer}, which is not installed here "
                                "(write a .gif instead)")
    return writer


def default_inputs(compiled: CompiledSystem, maneuver: str) -> dict[str, float]:
    """The inputs a maneuver is shown at unless given: the paper's fixed inputs for the biped
    (MODEL.md Sec. 5), zeros for any other system."""
    from biped_opt.paper.biped import FIXED_INPUTS, INPUT_NAMES

    if compiled.name == "biped" and maneuver in FIXED_INPUTS \
            and tuple(compiled.inputs) == tuple(INPUT_NAMES):
        return dict(zip(INPUT_NAMES, FIXED_INPUTS[maneuver]))
    return {}


# -- what is drawn, as numbers --------------------------------------------------------------

def rotation_matrices(quaternions: npt.ArrayLike) -> Array:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4) given as x, y, z, w."""
    qv = np.asarray(quaternions, dtype=np.float64)
    x, y, z, w = qv[..., 0], qv[..., 1], qv[..., 2], qv[..., 3]
    rows = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


@dataclass(frozen=True)
class Drawn:
    """The drawn artists' coordinates in the x-z plane at n frames: ``boxes`` (n, 4, 2)
    corners (local (-x, -z), (+x, -z), (+x, +z), (-x, +z) in turn), ``circles`` (n, 2)
    centres with their radii (n,), ``lines`` (n, P, 2) points with their widths (n,) [m],
    ``contacts`` (n, C, 2), ``active`` (n, C), ``arrows`` (n, C, 2, 2): each force arrow's
    start and end (start = end while its constraint is free)."""

    boxes: dict[str, Array]
    circles: dict[str, tuple[Array, Array]]
    lines: dict[str, tuple[Array, Array]]
    contacts: Array
    active: npt.NDArray[np.bool_]
    arrows: Array

    def bounds(self) -> tuple[float, float, float, float]:
        """x min, x max, z min, z max of everything drawn at any frame (and of z = 0)."""
        xs: list[Array] = [np.zeros(1)]
        zs: list[Array] = [np.zeros(1)]
        for corners in self.boxes.values():
            xs.append(corners[..., 0].ravel())
            zs.append(corners[..., 1].ravel())
        for centre, radius in self.circles.values():
            for sign in (-1, 1):
                xs.append(centre[:, 0] + sign * radius)
                zs.append(centre[:, 1] + sign * radius)
        for points, _width in self.lines.values():
            xs.append(points[..., 0].ravel())
            zs.append(points[..., 1].ravel())
        xs += [self.contacts[..., 0].ravel(), self.arrows[..., 0].ravel()]
        zs += [self.contacts[..., 1].ravel(), self.arrows[..., 1].ravel()]
        x, z = np.concatenate(xs), np.concatenate(zs)
        return float(x.min()), float(x.max()), float(z.min()), float(z.max())


def drawn(scene: Scene, state: SceneState, mode: npt.ArrayLike, lam: npt.ArrayLike) -> Drawn:
    """What is drawn of ``scene`` in ``state`` (n frames) with contact modes ``mode`` (n,)
    (bit j: constraint j active) and contact forces ``lam`` (n, constraints)."""
    mode = np.asarray(mode, dtype=np.int64)
    lam = np.atleast_2d(np.asarray(lam, dtype=np.float64))
    n = state.positions.shape[0]
    rot = rotation_matrices(state.quaternions)  # (n, F, 3, 3)
    where = {name: k for k, name in enumerate(scene.frames)}
    boxes: dict[str, Array] = {}
    circles: dict[str, tuple[Array, Array]] = {}
    lines: dict[str, tuple[Array, Array]] = {}
    for s in scene.shapes:
        size = state.sizes[s.name]
        if s.kind == "line":
            lines[s.name] = (state.points[s.name][:, :, [0, 2]], size[:, 0])
            continue
        k = where[s.frame]
        origin = state.positions[:, k, :][:, [0, 2]]
        if s.kind == "sphere":
            circles[s.name] = (origin, size[:, 0])
            continue
        # the frame's x and z axes in the world's x-z plane, scaled to half the box's edges
        ex = rot[:, k, :, 0][:, [0, 2]] * (size[:, 0:1] / 2)
        ez = rot[:, k, :, 2][:, [0, 2]] * (size[:, 2:3] / 2)
        boxes[s.name] = np.stack([origin - ex - ez, origin + ex - ez, origin + ex + ez,
                                  origin - ex + ez], axis=1)
    contacts = state.contacts[:, :, [0, 2]]
    active = np.zeros((n, len(scene.contacts)), dtype=bool)
    arrows = np.repeat(contacts[:, :, None, :], 2, axis=2)
    for i, j in enumerate(scene.contacts):
        active[:, i] = (mode >> j) & 1 == 1
        force = np.where(active[:, i], lam[:, j] if j < lam.shape[1] else 0.0, 0.0)
        arrows[:, i, 1, :] += FORCE_SCALE * force[:, None] * state.normals[:, i][:, [0, 2]]
    return Drawn(boxes, circles, lines, contacts, active, arrows)


# -- runs and their frames ------------------------------------------------------------------

def frame_times(duration: float, fps: int, speed: float) -> Array:
    """The simulated times of the frames of a run lasting ``duration``: every ``speed / fps``
    from 0 up to the first at or past ``duration`` (ceil(duration fps / speed) + 1 frames),
    which shows the run's end."""
    step = speed / fps
    count = int(math.ceil(duration / step * (1 - 1e-12))) + 1
    return np.arange(count, dtype=np.float64) * float(step)


def contact_order(trajectory: Trajectory) -> str:
    """The run's contact events in order: each constraint entered with ``↓``, each left with
    ``↑`` (``right↓ left↓``); ``no contact`` if none; cut after :data:`SHOWN_EVENTS`."""
    rows = trajectory.event_rows[: trajectory.n_events]
    names = trajectory.constraints
    words = []
    for row in rows[:SHOWN_EVENTS]:
        entered = constraint_names(int(row[2]), names)
        left = constraint_names(int(row[3]), names)
        words.append(" ".join([f"{c}↓" for c in entered] + [f"{c}↑" for c in left]))
    if len(rows) > SHOWN_EVENTS:
        words.append("...")
    return " ".join(words) if words else "no contact"


@dataclass(frozen=True)
class Panel:
    """One run to draw: its label, its sampled trajectory, the system's scene and parameter
    values; :meth:`at` gives what is drawn at any times, :attr:`title` the fixed part of the
    panel's title."""

    label: str
    trajectory: Trajectory
    scene: Scene
    parameters: tuple[float, ...]

    @property
    def title(self) -> str:
        tr = self.trajectory
        end = (f"outcome {tr.outcome:+.4f}" if tr.success
               else f"{tr.status.name.lower()} (no outcome)")
        return f"{self.label}  s = {tr.s:+.4g}\ncontacts: {contact_order(tr)}, {end}"

    def at(self, times: Array) -> tuple[Drawn, npt.NDArray[np.int64]]:
        """What is drawn at ``times`` (past the run's end: its last state) and the mode."""
        tr = self.trajectory
        samples = tr.samples
        assert samples is not None
        d = len(tr.y_final) // 2
        t = samples[:, 0]
        keep = np.ones(t.size, dtype=bool)  # (an event's pre-reset row: the post-reset one)
        keep[:-1] = t[:-1] != t[1:]
        rows = samples[keep]
        t = rows[:, 0]
        times = np.minimum(np.asarray(times, dtype=np.float64), t[-1])
        q = np.stack([np.interp(times, t, rows[:, 1 + i]) for i in range(d)], axis=1)
        before = np.clip(np.searchsorted(t, times, side="right") - 1, 0, t.size - 1)
        after = np.minimum(before + 1, t.size - 1)
        mode = rows[before, 1 + 2 * d].astype(np.int64)
        lam = rows[before, 2 + 2 * d:]
        # forces move continuously within a mode: interpolated there, held across a switch
        span = t[after] - t[before]
        frac = np.where(span > 0, (times - t[before]) / np.where(span > 0, span, 1.0), 0.0)
        same = (rows[after, 1 + 2 * d] == rows[before, 1 + 2 * d])[:, None]
        lam = np.where(same, lam + frac[:, None] * (rows[after, 2 + 2 * d:] - lam), lam)
        state = self.scene.evaluate(q, np.asarray(self.parameters))
        return drawn(self.scene, state, mode, lam), mode


def panel(compiled: CompiledSystem, maneuver: str, s: float,
          inputs: Mapping[str, float] | None = None, *, fps: int = 30, speed: float = 1.0,
          label: str | None = None) -> Panel:
    """Simulate ``maneuver`` of ``compiled`` at s (inputs by name; unset ones at
    :func:`default_inputs`), sampled finely enough for frames every ``speed / fps``."""
    scene = compiled.scene
    if scene.empty:
        raise InvalidInputError(
            f"{compiled.name}: the system declares no looks (no frame, shape or contact point), "
            "so there is nothing to draw; see SYSTEMS.md Sec. 6")
    given = {**default_inputs(compiled, maneuver), **dict(inputs or {})}
    dt = min(MAX_SAMPLE_DT, speed / fps / 2)
    tr = compiled.simulate(maneuver, s, given, sample_dt=dt)
    return Panel(label or f"{compiled.name} {maneuver}", tr, scene,
                 tuple(compiled.parameters.values()))


# -- the figure -------------------------------------------------------------------------------

class Animation:
    """Panels drawn side by side, one frame per :func:`frame_times` of the longest run (a
    shorter run holds its last state). :meth:`draw` poses frame k, :meth:`save` writes all."""

    def __init__(self, panels: Sequence[Panel], *, fps: int = 30, speed: float = 1.0,
                 size: tuple[int, int] = PANEL_SIZE) -> None:
        if not panels:
            raise InvalidInputError("an animation needs at least one run")
        _check_rate(fps, speed)
        width, height = (int(v) for v in size)
        if width < 32 or height < 32 or width % 2 or height % 2:
            raise InvalidInputError(f"a panel's size must be even and at least 32 x 32 pixels, "
                                    f"got {width} x {height}")
        self.panels = tuple(panels)
        self.fps, self.speed = int(fps), float(speed)
        self.times = frame_times(max(p.trajectory.t_final for p in panels), fps, speed)
        self._drawn = [p.at(self.times) for p in self.panels]
        self.figure = plt.figure(figsize=(width * len(panels) / DPI, height / DPI), dpi=DPI)
        self.size = (width * len(panels), height)
        self.axes = [self.figure.add_subplot(1, len(panels), k + 1) for k in range(len(panels))]
        digits = max(2, int(math.ceil(-math.log10(self.speed / self.fps))) + 1)
        self._t_format = f"t = {{:.{digits}f}}"
        limits = self._limits()
        self._artists = [self._setup(ax, p, d, limits)
                         for ax, p, (d, _m) in zip(self.axes, self.panels, self._drawn)]
        self.figure.subplots_adjust(left=0.02, right=0.98, bottom=0.02, top=0.80,
                                    wspace=0.06)

    @property
    def frames(self) -> int:
        return int(self.times.size)

    def _limits(self) -> tuple[float, float, float, float]:
        """One view for every panel (so they compare): all that is drawn, padded, with the
        panel's aspect ratio at one metre per metre in x and z."""
        bounds = np.array([d.bounds() for d, _m in self._drawn])
        x0, x1 = bounds[:, 0].min(), bounds[:, 1].max()
        z0, z1 = bounds[:, 2].min(), bounds[:, 3].max()
        pad = 0.08 * max(x1 - x0, z1 - z0, 1e-3)
        x0, x1, z0, z1 = x0 - pad, x1 + pad, z0 - pad, z1 + pad
        aspect = (self.size[1] * 0.78) / (self.size[0] / len(self.panels) * 0.96)
        if (z1 - z0) < aspect * (x1 - x0):
            grow = aspect * (x1 - x0) - (z1 - z0)
            z0, z1 = z0 - grow / 2, z1 + grow / 2
        else:
            grow = (z1 - z0) / aspect - (x1 - x0)
            x0, x1 = x0 - grow / 2, x1 + grow / 2
        return x0, x1, z0, z1

    def _setup(self, ax: Any, p: Panel, d: Drawn,
               limits: tuple[float, float, float, float]) -> dict[str, Any]:
        x0, x1, z0, z1 = limits
        ax.set_xlim(x0, x1)
        ax.set_ylim(z0, z1)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.axhspan(z0, 0.0, color=GROUND_COLOR[:3], zorder=0)
        ax.axhline(0.0, color="0.35", linewidth=1.0, zorder=1)
        # points per metre, for line widths and marker sizes given in metres
        per_m = self.size[0] / len(self.panels) * 0.96 / (x1 - x0) * 72 / DPI
        shapes = {s.name: s for s in p.scene.shapes}
        artists: dict[str, Any] = {"boxes": {}, "circles": {}, "lines": {}, "arrows": []}
        for name, corners in d.boxes.items():
            artists["boxes"][name] = ax.add_patch(Polygon(corners[0], closed=True, zorder=3,
                                                          color=shapes[name].color))
        for name, (centre, radius) in d.circles.items():
            artists["circles"][name] = ax.add_patch(Circle(tuple(centre[0]), radius[0],
                                                           zorder=4, color=shapes[name].color))
        for name, (points, width) in d.lines.items():
            (line,) = ax.plot(points[0, :, 0], points[0, :, 1], color=shapes[name].color,
                              linewidth=max(0.5, float(width[0]) * per_m), zorder=2,
                              solid_capstyle="round")
            artists["lines"][name] = line
        if d.contacts.shape[1]:
            artists["contacts"] = ax.scatter(d.contacts[0, :, 0], d.contacts[0, :, 1],
                                             s=max(4.0, (CONTACT_DIAMETER * per_m) ** 2),
                                             zorder=5, edgecolors="none")
            for _ in range(d.contacts.shape[1]):
                arrow = FancyArrowPatch((0, 0), (0, 0), arrowstyle="-|>", mutation_scale=8,
                                        color=ARROW_COLOR[:3], linewidth=1.5, zorder=6)
                artists["arrows"].append(ax.add_patch(arrow))
        return artists

    def draw(self, k: int) -> None:
        """Pose every artist at frame ``k`` and write the titles."""
        t = float(self.times[k])
        for ax, p, (d, mode), art in zip(self.axes, self.panels, self._drawn, self._artists):
            for name, patch in art["boxes"].items():
                patch.set_xy(d.boxes[name][k])
            for name, patch in art["circles"].items():
                centre, radius = d.circles[name]
                patch.center = (float(centre[k, 0]), float(centre[k, 1]))
                patch.set_radius(float(radius[k]))
            for name, line in art["lines"].items():
                points = d.lines[name][0][k]
                line.set_data(points[:, 0], points[:, 1])
            if "contacts" in art:
                art["contacts"].set_offsets(d.contacts[k])
                art["contacts"].set_facecolor([ACTIVE_COLOR if on else FREE_COLOR
                                               for on in d.active[k]])
                for i, arrow in enumerate(art["arrows"]):
                    start, end = d.arrows[k, i]
                    shown = bool(d.active[k, i]) and float(np.hypot(*(end - start))) > 1e-9
                    arrow.set_visible(shown)
                    if shown:
                        arrow.set_positions(tuple(start), tuple(end))
            tr = p.trajectory
            names = ", ".join(constraint_names(int(mode[k]), tr.constraints)) or "air"
            clock = self._t_format.format(min(t, tr.t_final))
            ended = "  (end)" if t >= tr.t_final else ""
            ax.set_title(f"{p.title}\n{clock}  mode {{{names}}}{ended}", fontsize=7,
                         loc="left")

    def save(self, path: Path) -> Path:
        """Write every frame to ``path`` (.gif or .mp4, see :func:`check_output`)."""
        path = Path(path)
        writer_name = check_output(path)
        writer: Any = (animation.PillowWriter(fps=self.fps) if writer_name == "pillow"
                       else animation.FFMpegWriter(fps=self.fps))
        partial = path.with_name(f".{path.stem}.partial{path.suffix}")
        try:
            with writer.saving(self.figure, str(partial), DPI):
                for k in range(self.frames):
                    self.draw(k)
                    writer.grab_frame()
            os.replace(partial, path)
        finally:
            partial.unlink(missing_ok=True)
        return path

    def close(self) -> None:
        plt.close(self.figure)


def _check_rate(fps: int, speed: float) -> None:
    if isinstance(fps, bool) or not isinstance(fps, (int, np.integer)) or not 1 <= fps <= 120:
        raise InvalidInputError(f"fps must be an integer from 1 to 120, got {fps!r}")
    if not (isinstance(speed, (int, float)) and math.isfinite(speed) and 0 < speed <= 100):
        raise InvalidInputError(f"speed must be a number in (0, 100], got {speed!r}")


def _write(panels: Sequence[Panel], out: Path, fps: int, speed: float,
           size: tuple[int, int]) -> Animation:
    movie = Animation(panels, fps=fps, speed=speed, size=size)
    try:
        movie.save(out)
    finally:
        movie.close()
    return movie


def animate(system: CompiledSystem | str, maneuver: str, s: float, out: Path, *,
            inputs: Mapping[str, float] | None = None, fps: int = 30, speed: float = 1.0,
            size: tuple[int, int] = PANEL_SIZE) -> Animation:
    """Write ``maneuver`` of ``system`` (compiled, a library name or a system file) at s to
    ``out`` (.gif, or .mp4 with ffmpeg); returns the (closed) animation: its frames, times
    and panels. Every argument is checked before anything is simulated or written."""
    out = Path(out)
    check_output(out)
    _check_rate(fps, speed)
    _check_s("s", s)
    compiled = system if isinstance(system, CompiledSystem) else CompiledSystem(system)
    compiled.code(maneuver)
    return _write([panel(compiled, maneuver, s, inputs, fps=fps, speed=speed)], out, fps,
                  speed, size)


def side_by_side(system: CompiledSystem | str, maneuver: str, out: Path, *, s0: float = 0.0,
                 delta: float = 0.02, inputs: Mapping[str, float] | None = None, fps: int = 30,
                 speed: float = 1.0, size: tuple[int, int] = PANEL_SIZE) -> Animation:
    """Write ``maneuver`` at s0 - delta (left panel) and s0 + delta (right panel) into one
    animation (see the module docstring; s0 = 0 is the simultaneous event of the biped's
    touchdown and liftoff and of the rocking bar's drop)."""
    out = Path(out)
    check_output(out)
    _check_rate(fps, speed)
    _check_s("s0", s0)
    if not (isinstance(delta, (int, float)) and math.isfinite(delta) and 0 < delta <= 1):
        raise InvalidInputError(f"delta must be a number in (0, 1], got {delta!r}")
    compiled = system if isinstance(system, CompiledSystem) else CompiledSystem(system)
    compiled.code(maneuver)
    panels = [panel(compiled, maneuver, s0 + sign * delta, inputs, fps=fps, speed=speed)
              for sign in (-1, 1)]
    return _write(panels, out, fps, speed, size)


def _check_s(name: str, value: float) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value):
        raise InvalidInputError(f"{name} must be a finite number, got {value!r}")
