"""A maneuver as a moving picture: any system's scene in the x-z plane or in 3-D, drawn per frame.

The scene is the one the simulator publishes as markers (:mod:`biped_opt.record.scene`, ROS.md
Sec. 6), drawn with matplotlib instead of a ROS tool, so an animation and a live view agree:

- boxes as rectangles posed by their frame (a planar system's frames turn about y only, so the
  rectangle is the box's x-z face; a rotation out of the plane would show that face's
  projection), spheres as circles, lines as polylines, the ground as the line z = 0 (labelled);
- the contact points, red while their constraint is active and grey while it is free, and each
  contact force lambda_j as an arrow along the constraint's normal,
  :data:`~biped_opt.record.scene.FORCE_SCALE` length units per unit of force (none while
  free). The markers draw it from the contact point outwards, through the body; here it
  pushes on the body from the ground's side and ends where it meets the shapes drawn around
  the contact point (:data:`ARROW_GAP` short of them), so it never crosses the body;
- axes with a scale in the system's units (:mod:`biped_opt.plots.units`: gravity units for
  the biped, "model units" for a system that states none);
- each panel's title: its s, the order of its contact events (``right↓ left↓``: touchdowns,
  ``↑``: liftoffs), its outcome as the maneuver declares it with its value and unit
  (``th(t_f) = +0.0143 rad``), and at every frame the time t, how fast it runs, and the
  contact mode.

Frames are taken every ``speed / fps`` of simulated time (``speed`` simulated time units per
second of animation, ``fps`` frames per second), except around contact events
(:func:`frame_clock`): a mode between two events lasting less than ``min_frames + 1`` frame
steps (the biped's single stance near th0 = 0 lasts 10 ms) is slowed down until ``min_frames``
frames fall inside it, and every event is held for ``hold`` frames at its instant, with a ring
round each contact point it touches (red: an impact, grey: a liftoff). An impact that
separates at once (the rocking bar's, restitution 0.5) leaves no mode behind: its held frames,
with the point red and ringed, are where it shows. The title says when time runs slowed
(``t = 1.0006 (x0.022)``: 0.022 time units per second of animation) or is held (``held at
right↓ (impact)``). The configuration is interpolated between samples (it is continuous across
impacts, only velocities jump), the mode and the forces are the ones holding at the frame's
time (just after the event at a held frame). :func:`side_by_side` puts the same maneuver at
s0 - delta and s0 + delta into two panels of one animation on one clock: on either side of a
simultaneous event (s0 = 0: the biped's touchdown and liftoff, the rocking bar's drop) the
order of the contacts flips, and with it the outcome (SYSTEMS.md Sec. 2 and [1]_).

A system whose bodies lie or move out of one x-z plane (a robot from its URDF: legs side by
side, a base that rolls) is drawn in 3-D instead (``view="3d"``; ``"auto"``, the default, chooses
by :func:`planar`): matplotlib's mplot3d axes at one scale in x, y and z, the ground as the
plane z = 0, boxes as their six faces, spheres as round markers, lines, the contact points
(red while active) and the forces as segments ending at the contact point, from below the
ground. Forces that would reach further than half the bodies' extent are drawn at a smaller
scale of 1, 2 or 5 times a power of 10, which the ground's label gives. Holds, slowed stretches
and titles are those of the x-z view.

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
from matplotlib.ticker import MaxNLocator  # noqa: E402

from biped_opt.errors import InvalidInputError  # noqa: E402
from biped_opt.plots.units import MODEL, Units, units_of  # noqa: E402
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

__all__ = ["Animation", "Clock", "Drawn", "Drawn3d", "Panel", "drawn_3d", "planar", "VIEWS",
           "animate", "check_output", "default_inputs", "drawn", "frame_clock", "frame_times",
           "panel", "rotation_matrices", "side_by_side", "SUFFIXES", "contact_order",
           "HOLD_FRAMES", "MIN_MODE_FRAMES"]

Array = npt.NDArray[np.float64]

#: output suffix -> matplotlib writer
SUFFIXES = {".gif": "pillow", ".mp4": "ffmpeg"}
#: a panel's size in pixels (width, height) unless given, and the resolution it is drawn at;
#: a larger panel is the same picture enlarged (its resolution grows with its smaller ratio
#: to PANEL_SIZE), so its type is as legible
PANEL_SIZE = (320, 240)
DPI = 80
#: the finest sampling of a run, in simulated seconds (frames are interpolated between samples)
MAX_SAMPLE_DT = 0.005
#: contact events named in a title before the rest is cut to "..."
SHOWN_EVENTS = 4
#: what a force arrow leaves free between its head and the body it pushes on
ARROW_GAP = 0.01
#: frames each contact event is held for, and the fewest frames a mode between two events
#: is shown in (slowed down where the nominal rate gives it fewer), unless given
HOLD_FRAMES = 8
MIN_MODE_FRAMES = 8
#: the titles' font size [pt]; a held impact's ring, in areas of a contact point's marker
FONT = 7
FLASH_SIZE = 6.0
#: the ring round a contact point at a held liftoff
LIFTOFF_COLOR = (0.25, 0.25, 0.25, 1.0)
#: the views of an animation: the x-z plane, 3-D, or chosen by :func:`planar`
VIEWS = ("auto", "xz", "3d")
#: the 3-D view's elevation and azimuth [deg] (matplotlib's view_init)
VIEW_3D = (18.0, -58.0)
#: the axes' margins in a panel, in pixels: left (ticks and "z"), right, bottom (ticks and
#: the units), top (the three lines of the title)
MARGINS = (30, 6, 26, 40)


def _zoom(width: int, height: int) -> float:
    """How much larger than :data:`PANEL_SIZE` a panel of this size draws (type, lines)."""
    return min(width / PANEL_SIZE[0], height / PANEL_SIZE[1])


def _axes_box(width: int, height: int) -> tuple[float, float, float, float]:
    """A panel's axes (left, bottom, width, height) as fractions of the panel."""
    left, right, bottom, top = (m * _zoom(width, height) for m in MARGINS)
    return (left / width, bottom / height, 1 - (left + right) / width,
            1 - (bottom + top) / height)


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


def _contact_forces(scene: Scene, mode: npt.ArrayLike, lam: npt.ArrayLike
                    ) -> tuple[npt.NDArray[np.bool_], Array]:
    """Whether each of the scene's contact points is active (n, C) in the modes (n,), and its
    force (n, C) from the constraints' ``lam`` (n, constraints); 0 while free."""
    mode = np.asarray(mode, dtype=np.int64)
    lam = np.atleast_2d(np.asarray(lam, dtype=np.float64))
    active = np.zeros((mode.size, len(scene.contacts)), dtype=bool)
    force = np.zeros(active.shape)
    for i, j in enumerate(scene.contacts):
        active[:, i] = (mode >> j) & 1 == 1
        force[:, i] = np.where(active[:, i], lam[:, j] if j < lam.shape[1] else 0.0, 0.0)
    return active, force


def _shapes(scene: Scene, state: SceneState) -> tuple[
        dict[str, tuple[Array, Array, Array]], dict[str, tuple[Array, Array]],
        dict[str, tuple[Array, Array]]]:
    """The scene's shapes in 3-D at every sample: boxes as their frame's origin (n, 3),
    rotation (n, 3, 3) and edges (n, 3); spheres as centre (n, 3) and radius (n,); lines as
    points (n, P, 3) and width (n,)."""
    rot = rotation_matrices(state.quaternions)  # (n, F, 3, 3)
    where = {name: k for k, name in enumerate(scene.frames)}
    boxes: dict[str, tuple[Array, Array, Array]] = {}
    circles: dict[str, tuple[Array, Array]] = {}
    lines: dict[str, tuple[Array, Array]] = {}
    for s in scene.shapes:
        size = state.sizes[s.name]
        if s.kind == "line":
            lines[s.name] = (state.points[s.name], size[:, 0])
            continue
        k = where[s.frame]
        if s.kind == "sphere":
            circles[s.name] = (state.positions[:, k, :], size[:, 0])
        else:
            boxes[s.name] = (state.positions[:, k, :], rot[:, k], size)
    return boxes, circles, lines


def drawn(scene: Scene, state: SceneState, mode: npt.ArrayLike, lam: npt.ArrayLike) -> Drawn:
    """What is drawn of ``scene`` in ``state`` (n frames) with contact modes ``mode`` (n,)
    (bit j: constraint j active) and contact forces ``lam`` (n, constraints)."""
    active, force = _contact_forces(scene, mode, lam)
    posed, circles3, lines3 = _shapes(scene, state)
    circles = {name: (c[:, [0, 2]], r) for name, (c, r) in circles3.items()}
    lines = {name: (pts[:, :, [0, 2]], w) for name, (pts, w) in lines3.items()}
    boxes: dict[str, Array] = {}
    for name, (origin3, rot, size) in posed.items():
        origin = origin3[:, [0, 2]]
        # the frame's x and z axes in the world's x-z plane, scaled to half the box's edges
        ex = rot[:, :, 0][:, [0, 2]] * (size[:, 0:1] / 2)
        ez = rot[:, :, 2][:, [0, 2]] * (size[:, 2:3] / 2)
        boxes[name] = np.stack([origin - ex - ez, origin + ex - ez, origin + ex + ez,
                                origin - ex + ez], axis=1)
    contacts = state.contacts[:, :, [0, 2]]
    arrows = np.repeat(contacts[:, :, None, :], 2, axis=2)
    for i in range(len(scene.contacts)):
        normal = state.normals[:, i][:, [0, 2]]
        unit = normal / np.maximum(np.hypot(normal[:, 0], normal[:, 1]), 1e-300)[:, None]
        # the force pushes on the body from the ground's side: the arrow ends where it leaves
        # the shapes around the contact point, seen from below, so it never crosses the body
        gap = _clearance(contacts[:, i], -unit, boxes, circles, lines) + ARROW_GAP
        end = contacts[:, i] - gap[:, None] * unit
        arrows[:, i, 1, :] = np.where(active[:, i, None], end, contacts[:, i])
        arrows[:, i, 0, :] = arrows[:, i, 1, :] - FORCE_SCALE * force[:, i, None] * normal
    return Drawn(boxes, circles, lines, contacts, active, arrows)


@dataclass(frozen=True)
class Drawn3d:
    """The drawn artists' coordinates in 3-D at n frames: ``boxes`` (n, 8, 3) corners (local
    signs (x, y, z) in the order of :data:`BOX_SIGNS`), ``circles`` (n, 3) sphere centres with
    their radii (n,), ``lines`` (n, P, 3) points with their widths (n,), ``contacts`` (n, C, 3),
    ``active`` (n, C), ``arrows`` (n, C, 2, 3): each force's segment, from its tail below the
    ground to the contact point (start = end while its constraint is free), drawn at
    ``force_scale`` lengths per unit of force."""

    boxes: dict[str, Array]
    circles: dict[str, tuple[Array, Array]]
    lines: dict[str, tuple[Array, Array]]
    contacts: Array
    active: npt.NDArray[np.bool_]
    arrows: Array
    force_scale: float

    def bounds(self) -> Array:
        """(3, 2): the least and greatest x, y, z of everything drawn at any frame (and of the
        origin, on the ground)."""
        points = [np.zeros((1, 3)), self.contacts.reshape(-1, 3), self.arrows.reshape(-1, 3)]
        points += [c.reshape(-1, 3) for c in self.boxes.values()]
        for centre, radius in self.circles.values():
            points += [centre - radius[:, None], centre + radius[:, None]]
        points += [pts.reshape(-1, 3) for pts, _w in self.lines.values()]
        allp = np.concatenate(points)
        return np.stack([allp.min(axis=0), allp.max(axis=0)], axis=1)


#: a box's corners as signs of its half edges along its frame's x, y, z
BOX_SIGNS = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                      [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=np.float64)
#: a box's six faces as indices into its corners
BOX_FACES = ((0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (1, 2, 6, 5), (0, 3, 7, 4))


def _nice_below(value: float) -> float:
    """The largest 1, 2 or 5 times a power of 10 that is at most ``value`` (> 0)."""
    power = 10.0 ** math.floor(math.log10(value))
    return max(m * power for m in (1.0, 2.0, 5.0) if m * power <= value * (1 + 1e-12))


def drawn_3d(scene: Scene, state: SceneState, mode: npt.ArrayLike, lam: npt.ArrayLike,
             force_scale: float | None = None) -> Drawn3d:
    """What is drawn of ``scene`` in 3-D in ``state`` (n frames) with contact modes ``mode``
    (n,) and contact forces ``lam`` (n, constraints); see :class:`Drawn3d`. ``force_scale``:
    the arrows' (default: :data:`FORCE_SCALE`, or less where the forces would reach further
    than half the bodies' extent)."""
    active, force = _contact_forces(scene, mode, lam)
    posed, circles, lines = _shapes(scene, state)
    boxes = {name: origin[:, None, :] + np.einsum(
                 "nij,nkj->nki", rot, BOX_SIGNS[None, :, :] * (size[:, None, :] / 2))
             for name, (origin, rot, size) in posed.items()}
    contacts = state.contacts
    # the bodies' extent (not the forces'): what the arrows are scaled to
    body = Drawn3d(boxes, circles, lines, contacts, active,
                   np.repeat(contacts[:, :, None, :], 2, axis=2), FORCE_SCALE).bounds()
    extent = float(np.max(body[:, 1] - body[:, 0]))
    largest = float(np.max(np.abs(force), initial=0.0))
    scale = FORCE_SCALE if force_scale is None else float(force_scale)
    if force_scale is None and largest > 0 and FORCE_SCALE * largest > 0.5 * extent > 0:
        scale = _nice_below(0.5 * extent / largest)
    arrows = np.repeat(contacts[:, :, None, :], 2, axis=2)
    arrows[:, :, 0, :] = contacts - scale * force[:, :, None] * state.normals
    return Drawn3d(boxes, circles, lines, contacts, active, arrows, scale)


def planar(scene: Scene, state: SceneState, tol: float = 1e-9) -> bool:
    """Whether everything of ``scene`` stays in one plane y = const at every sample of
    ``state``: the frames' origins, the lines' points and the contact points share one y and
    every frame turns about y only (then the x-z view shows it all)."""
    ys = [state.positions[..., 1].ravel(), state.contacts[..., 1].ravel()]
    ys += [pts[..., 1].ravel() for pts in state.points.values()]
    y = np.concatenate(ys)
    if y.size and float(np.ptp(y)) > tol:
        return False
    rot = rotation_matrices(state.quaternions)
    # a rotation about y alone keeps y: its (1, 1) entry is 1, and (0, 1), (2, 1), (1, 0),
    # (1, 2) are 0
    return bool(np.all(np.abs(rot[..., 1, 1] - 1.0) <= tol)) if rot.size else True



def _clearance(point: Array, direction: Array, boxes: dict[str, Array],
               circles: dict[str, tuple[Array, Array]],
               lines: dict[str, tuple[Array, Array]]) -> Array:
    """How far (n,) the rays from ``point`` (n, 2) along the unit ``direction`` (n, 2) run
    inside the drawn shapes that hold their start: circles, boxes (convex: the rectangle
    of each), and the round ends of lines; 0 where no shape holds the point."""
    out = np.zeros(point.shape[0])
    discs = [(c, r) for c, r in circles.values()]
    for pts, width in lines.values():
        discs += [(pts[:, k], width / 2) for k in range(pts.shape[1])]
    for centre, radius in discs:
        rel = point - centre
        b = np.einsum("ij,ij->i", rel, direction)
        c = np.einsum("ij,ij->i", rel, rel) - radius ** 2
        inside = c < 0
        exit_ = -b + np.sqrt(np.maximum(b * b - c, 0.0))
        out = np.where(inside, np.maximum(out, exit_), out)
    for corners in boxes.values():
        # the corners run counter-clockwise or clockwise: take the edges' outward normals
        # from the sign of the polygon's area
        edge = np.roll(corners, -1, axis=1) - corners  # (n, 4, 2)
        area = np.sum(corners[:, :, 0] * np.roll(corners, -1, axis=1)[:, :, 1]
                      - np.roll(corners, -1, axis=1)[:, :, 0] * corners[:, :, 1], axis=1)
        sign = np.where(area >= 0, 1.0, -1.0)[:, None]
        outward = np.stack([edge[:, :, 1], -edge[:, :, 0]], axis=-1) * sign[..., None]
        depth = np.einsum("ikj,ikj->ik", outward, point[:, None, :] - corners)  # <= 0 inside
        inside = np.all(depth < 0, axis=1)
        rate = np.einsum("ikj,ij->ik", outward, direction)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(rate > 0, -depth / rate, np.inf)
        exit_ = np.min(t, axis=1)
        out = np.where(inside & np.isfinite(exit_), np.maximum(out, exit_), out)
    return out


# -- runs and their frames ------------------------------------------------------------------

def frame_times(duration: float, fps: int, speed: float) -> Array:
    """The simulated times of the frames of a run lasting ``duration``: every ``speed / fps``
    from 0 up to the first at or past ``duration`` (ceil(duration fps / speed) + 1 frames),
    which shows the run's end."""
    step = speed / fps
    count = int(math.ceil(duration / step * (1 - 1e-12))) + 1
    return np.arange(count, dtype=np.float64) * float(step)


@dataclass(frozen=True)
class Clock:
    """The frames of an animation in simulated time: frame k shows ``times[k]``; ``pace[k]``
    is the simulated time it stands for over the nominal ``speed / fps`` (1: the nominal rate,
    below 1: slowed, 0: held); ``held[k]`` is the index into ``holds`` of the events it holds
    (-1: none). ``holds[c]`` is (t, ((panel, event index), ...)): the contact events of the
    panels held together at time t, each panel's event of that instant."""

    times: Array
    pace: Array
    held: npt.NDArray[np.int64]
    holds: tuple[tuple[float, tuple[tuple[int, int], ...]], ...]

    @property
    def frames(self) -> int:
        return int(self.times.size)


def frame_clock(events: Sequence[Sequence[float]], ends: Sequence[float], fps: int,
                speed: float, *, hold: int = 0, min_frames: int = 0) -> Clock:
    """The frames of panels whose contact events are at ``events[p]`` and which end at
    ``ends[p]``: every ``speed / fps`` of simulated time (:func:`frame_times` up to the latest
    end), except that

    - each mode between two contact events of a panel that lasts less than ``min_frames +
      1`` frame steps is slowed down so that at least ``min_frames`` frames fall strictly
      inside it (a single stance of 10 ms, or the 5 ms between two impacts of the rocking
      bar, which the nominal rate shows in one frame or none);
    - each event is held for ``hold`` frames at its instant, showing the state just after it.
      Events of different panels less than a thousandth of a frame apart (the two mirrored runs
      of a side-by-side pair) are held together, at the later of their times.
    """
    step = speed / fps
    t_end = max(ends)
    regular = frame_times(t_end, fps, speed)
    # the slowed stretches: (start, end, the longest step that puts min_frames inside)
    slowed: list[tuple[float, float, float]] = []
    if min_frames > 0:
        for ts in events:
            for a, b in zip(ts, ts[1:]):
                if 0 < b - a < (min_frames + 1) * step:
                    slowed.append((a, b, (b - a) / (min_frames + 1)))
    times: list[float] = []
    pace: list[float] = []
    cuts = sorted({v for a, b, _ in slowed for v in (a, b)})
    for a, b in zip(cuts, cuts[1:]):
        cover = [h for lo, hi, h in slowed if lo <= a and b <= hi]
        if not cover:
            continue
        n = max(1, math.ceil((b - a) / min(cover) * (1 - 1e-12)))
        times += [a + k * (b - a) / n for k in range(n)]
        pace += [(b - a) / n / step] * n
    inside = np.zeros(regular.size, dtype=bool)
    for lo, hi, _ in slowed:
        inside |= (regular >= lo) & (regular < hi)
    times += regular[~inside].tolist()
    pace += [1.0] * int(np.sum(~inside))
    held = [-1] * len(times)
    holds: list[tuple[float, tuple[tuple[int, int], ...]]] = []
    if hold > 0:
        tol = 1e-3 * step
        order = sorted((t, p, k) for p, ts in enumerate(events) for k, t in enumerate(ts))
        groups: list[list[tuple[float, int, int]]] = []
        for item in order:
            group = groups[-1] if groups else None
            if group and item[0] - group[0][0] <= tol and item[1] not in {g[1] for g in group}:
                group.append(item)
            else:
                groups.append([item])
        for c, group in enumerate(groups):
            first, at = group[0][0], group[-1][0]
            holds.append((at, tuple((p, k) for _t, p, k in group)))
            # (a frame between the grouped events, or on them, would show one panel's event
            # before the other's: the hold shows both)
            keep = [i for i, t in enumerate(times) if held[i] >= 0 or not first <= t <= at]
            times, pace, held = ([times[i] for i in keep], [pace[i] for i in keep],
                                 [held[i] for i in keep])
            times += [at] * hold
            pace += [0.0] * hold
            held += [c] * hold
    # in time order; at one instant the held frames first (they show the event itself)
    order_ = sorted(range(len(times)), key=lambda i: (times[i], held[i] < 0))
    return Clock(times=np.array([times[i] for i in order_], dtype=np.float64),
                 pace=np.array([pace[i] for i in order_], dtype=np.float64),
                 held=np.array([held[i] for i in order_], dtype=np.int64),
                 holds=tuple(holds))


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
    values, the maneuver's outcome expression and the system's units; :meth:`at` gives what
    is drawn at any times, :attr:`title` the fixed part of the panel's title."""

    label: str
    trajectory: Trajectory
    scene: Scene
    parameters: tuple[float, ...]
    outcome: str = "outcome"
    units: Units = MODEL

    @property
    def outcome_text(self) -> str:
        """The outcome as the maneuver declares it, its value and unit: ``th(t_f) = +0.0143
        rad`` (the unit where :class:`~biped_opt.plots.units.Units` knows it)."""
        tr = self.trajectory
        if not tr.success:
            return f"{tr.status.name.lower()} (no outcome)"
        unit = self.units.outcome(self.outcome)
        return f"{self.outcome}(t_f) = {tr.outcome:+.4f}" + (f" {unit}" if unit else "")

    @property
    def title(self) -> str:
        tr = self.trajectory
        return f"{self.label}  s = {tr.s:+.4g}\ncontacts: {contact_order(tr)}, " \
            f"{self.outcome_text}"

    def event_words(self, k: int) -> str:
        """Contact event k of the run as a title says it: ``right↓ (impact)``,
        ``left↑ (liftoff)``, ``left↓ right↓ (impact)`` for a simultaneous one."""
        row = self.trajectory.event_rows[k]
        names = self.trajectory.constraints
        entered = constraint_names(int(row[2]), names)
        left = constraint_names(int(row[3]), names)
        what = " + ".join(w for w, c in (("impact", entered), ("liftoff", left)) if c)
        return " ".join([f"{c}↓" for c in entered] + [f"{c}↑" for c in left]) + f" ({what})"

    def at(self, times: Array) -> tuple[Drawn, npt.NDArray[np.int64]]:
        """What is drawn at ``times`` (past the run's end: its last state) and the mode."""
        state, mode, lam = self.state_at(times)
        return drawn(self.scene, state, mode, lam), mode

    def state_at(self, times: Array) -> tuple[SceneState, npt.NDArray[np.int64], Array]:
        """The scene's state at ``times`` (past the run's end: its last state), the contact
        mode and the contact forces there."""
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
        return self.scene.evaluate(q, np.asarray(self.parameters)), mode, lam


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
    outcome = str(compiled.system.maneuvers[maneuver].outcome)
    return Panel(label or f"{compiled.name} {maneuver}", tr, scene,
                 tuple(compiled.parameters.values()), outcome,
                 units_of(compiled.name, compiled.system.source))


# -- the figure -------------------------------------------------------------------------------

class Animation:
    """Panels drawn side by side on one :func:`frame_clock` (a shorter run holds its last
    state): every ``speed / fps`` of simulated time, slowed where a mode lasts fewer than
    ``min_frames`` frames, each contact event held for ``hold`` frames. :meth:`draw` poses
    frame k, :meth:`save` writes all. ``view``: ``xz``, ``3d`` or ``auto`` (3-D unless every
    panel's scene stays in one x-z plane, :func:`planar`); :attr:`view` is the one drawn."""

    def __init__(self, panels: Sequence[Panel], *, fps: int = 30, speed: float = 1.0,
                 size: tuple[int, int] = PANEL_SIZE, hold: int = HOLD_FRAMES,
                 min_frames: int = MIN_MODE_FRAMES, view: str = "auto") -> None:
        if not panels:
            raise InvalidInputError("an animation needs at least one run")
        _check_view(view)
        _check_rate(fps, speed)
        _check_frames(hold, min_frames)
        width, height = (int(v) for v in size)
        if width < 32 or height < 32 or width % 2 or height % 2:
            raise InvalidInputError(f"a panel's size must be even and at least 32 x 32 pixels, "
                                    f"got {width} x {height}")
        self.panels = tuple(panels)
        self.fps, self.speed = int(fps), float(speed)
        self.clock = frame_clock([p.trajectory.event_times for p in self.panels],
                                 [p.trajectory.t_final for p in self.panels], fps, speed,
                                 hold=hold, min_frames=min_frames)
        self.times = self.clock.times
        states = [p.state_at(self.times) for p in self.panels]
        if view == "auto":
            view = "xz" if all(planar(p.scene, st) for p, (st, _m, _l) in
                               zip(self.panels, states)) else "3d"
        self.view = view
        make = drawn if view == "xz" else drawn_3d
        self._drawn: list[tuple[Any, npt.NDArray[np.int64]]] = [
            (make(p.scene, st, m, lam), m) for p, (st, m, lam) in zip(self.panels, states)]
        if view == "3d" and len({d.force_scale for d, _m in self._drawn}) > 1:
            # (panels that compare share one scale of force: the smallest)
            scale = min(d.force_scale for d, _m in self._drawn)
            self._drawn = [(drawn_3d(p.scene, st, m, lam, scale), m)
                           for p, (st, m, lam) in zip(self.panels, states)]
        self._flashes = [self._flash(i) for i in range(len(self.panels))]
        self.dpi = DPI * _zoom(width, height)
        self.figure = plt.figure(figsize=(width * len(panels) / self.dpi, height / self.dpi),
                                 dpi=self.dpi)
        self.size = (width * len(panels), height)
        self._box = _axes_box(width, height)
        self.axes = []
        for k in range(len(panels)):
            left, bottom, w, h = self._box
            self.axes.append(self.figure.add_axes(
                ((k + left) / len(panels), bottom, w / len(panels), h),
                **({"projection": "3d"} if view == "3d" else {})))
        shortest = float(np.min(self.clock.pace[self.clock.pace > 0], initial=1.0))
        digits = max(2, int(math.ceil(-math.log10(shortest * self.speed / self.fps))) + 1)
        self._t_format = f"t = {{:.{digits}f}}"
        if view == "3d":
            box = self._limits_3d()
            self._artists = [self._setup_3d(ax, p, d, box)
                             for ax, p, (d, _m) in zip(self.axes, self.panels, self._drawn)]
        else:
            limits = self._limits()
            self._artists = [self._setup(ax, p, d, limits)
                             for ax, p, (d, _m) in zip(self.axes, self.panels, self._drawn)]

    @property
    def frames(self) -> int:
        return self.clock.frames

    def _flash(self, i: int) -> dict[int, tuple[list[int], list[int], str]]:
        """Panel i's held events by hold: the contact points (indices into the scene's
        contacts) that an impact entered and those a liftoff left, and the caption's words."""
        p = self.panels[i]
        rows = p.trajectory.event_rows
        out = {}
        for c, (_t, members) in enumerate(self.clock.holds):
            mine = [k for panel_, k in members if panel_ == i]
            if not mine:
                continue
            entered = [pos for k in mine for pos, j in enumerate(p.scene.contacts)
                       if int(rows[k, 2]) >> j & 1]
            left = [pos for k in mine for pos, j in enumerate(p.scene.contacts)
                    if int(rows[k, 3]) >> j & 1]
            out[c] = (entered, left, ", ".join(p.event_words(k) for k in mine))
        return out

    def _limits(self) -> tuple[float, float, float, float]:
        """One view for every panel (so they compare): all that is drawn, padded, with the
        axes' aspect ratio at one unit of length per unit in x and z."""
        bounds = np.array([d.bounds() for d, _m in self._drawn])
        x0, x1 = bounds[:, 0].min(), bounds[:, 1].max()
        z0, z1 = bounds[:, 2].min(), bounds[:, 3].max()
        pad = 0.08 * max(x1 - x0, z1 - z0, 1e-3)
        x0, x1, z0, z1 = x0 - pad, x1 + pad, z0 - pad, z1 + pad
        _left, _bottom, w, h = self._box
        aspect = (h * self.size[1]) / (w * self.size[0] / len(self.panels))
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
        for axis in (ax.xaxis, ax.yaxis):
            axis.set_major_locator(MaxNLocator(5))
        ax.tick_params(labelsize=FONT - 1, length=2, pad=1)
        ax.set_xlabel(p.units.axes_note, fontsize=FONT - 1, labelpad=1)
        ax.set_ylabel("z", fontsize=FONT - 1, labelpad=1, rotation=0)
        ax.axhspan(z0, 0.0, color=GROUND_COLOR[:3], zorder=0)
        ax.axhline(0.0, color="0.35", linewidth=1.0, zorder=1)
        # (at the foot of the ground, where nothing is drawn but force arrows' tails)
        forces = bool(np.any(d.arrows[:, :, 0] != d.arrows[:, :, 1]))
        ax.text(x0 + 0.01 * (x1 - x0), z0 + 0.01 * (z1 - z0), "ground, z = 0"
                + (f"; arrows: contact force, {FORCE_SCALE:g} {p.units.length} per unit"
                   if forces else ""), fontsize=FONT - 1, color="0.3", va="bottom",
                ha="left", zorder=1)
        # points per unit of length, for line widths and marker sizes given in lengths
        _left, _bottom, w, _h = self._box
        per_m = self.size[0] / len(self.panels) * w / (x1 - x0) * 72 / self.dpi
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
            size = max(4.0, (CONTACT_DIAMETER * per_m) ** 2)
            artists["contacts"] = ax.scatter(d.contacts[0, :, 0], d.contacts[0, :, 1],
                                             s=size, zorder=5, edgecolors="none")
            # the held frames' rings: red round an impact's point, grey round a liftoff's
            artists["flash"] = ax.scatter(np.zeros(0), np.zeros(0), s=FLASH_SIZE * size,
                                          facecolors="none", linewidths=1.6, zorder=7)
            for _ in range(d.contacts.shape[1]):
                arrow = FancyArrowPatch((0, 0), (0, 0), arrowstyle="-|>", mutation_scale=8,
                                        color=ARROW_COLOR[:3], linewidth=1.5, zorder=6)
                artists["arrows"].append(ax.add_patch(arrow))
        return artists

    def caption(self, k: int, i: int) -> str:
        """The last line of panel i's title at frame k: the time, how fast it runs (or that
        it is held, and at which event), the contact mode."""
        p = self.panels[i]
        tr = p.trajectory
        _d, mode = self._drawn[i]
        t = float(self.times[k])
        names = ", ".join(constraint_names(int(mode[k]), tr.constraints)) or "air"
        clock = self._t_format.format(min(t, tr.t_final))
        held = int(self.clock.held[k])
        if t >= tr.t_final and held < 0:
            pace = " (end)"
        elif held >= 0:
            flash = self._flashes[i].get(held)
            pace = f" held at {flash[2]}" if flash else " (held)"
        else:
            rate = float(self.clock.pace[k]) * self.speed
            pace = f" (x{rate:.2g})" if abs(rate - 1) > 1e-9 else ""
        return f"{clock}{pace}  mode {{{names}}}"

    def _limits_3d(self) -> Array:
        """(3, 2): one box for every panel, all that is drawn, padded (the axes draw it at one
        scale in x, y and z)."""
        bounds = np.stack([d.bounds() for d, _m in self._drawn])
        box = np.stack([bounds[:, :, 0].min(axis=0), bounds[:, :, 1].max(axis=0)], axis=1)
        pad = 0.08 * max(float(np.max(box[:, 1] - box[:, 0])), 1e-3)
        return box + np.array([-pad, pad])

    def _setup_3d(self, ax: Any, p: Panel, d: Drawn3d, box: Array) -> dict[str, Any]:
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        (x0, x1), (y0, y1), (z0, z1) = box
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_zlim(z0, z1)
        ax.set_box_aspect((x1 - x0, y1 - y0, z1 - z0))  # (one scale in x, y and z)
        ax.view_init(*VIEW_3D)
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.set_major_locator(MaxNLocator(4))
        ax.tick_params(labelsize=FONT - 2, pad=0)
        for name, label in (("x", ax.set_xlabel), ("y", ax.set_ylabel), ("z", ax.set_zlabel)):
            label(name, fontsize=FONT - 1, labelpad=-8)
        ax.add_collection3d(Poly3DCollection(
            [[(x0, y0, 0.0), (x1, y0, 0.0), (x1, y1, 0.0), (x0, y1, 0.0)]],
            facecolors=[(*GROUND_COLOR[:3], 0.45)], edgecolors=["0.35"], linewidths=0.8))
        forces = bool(np.any(d.arrows[:, :, 0] != d.arrows[:, :, 1]))
        ax.text2D(0.0, 1.0, "ground, z = 0"
                  + (f"; arrows: contact force,\n{d.force_scale:g} {p.units.length} per unit"
                     if forces else ""), transform=ax.transAxes, fontsize=FONT - 2,
                  color="0.3", va="top", ha="left")
        shapes = {s.name: s for s in p.scene.shapes}
        artists: dict[str, Any] = {"boxes": {}, "circles": {}, "lines": {}, "arrows": []}
        for name, corners in d.boxes.items():
            poly = Poly3DCollection([corners[0][list(f)] for f in BOX_FACES],
                                    facecolors=[shapes[name].color], edgecolors=["0.2"],
                                    linewidths=0.3)
            artists["boxes"][name] = ax.add_collection3d(poly)
        for name, (centre, _radius) in d.circles.items():
            artists["circles"][name] = ax.scatter(*centre[0][:, None], s=16,
                                                  color=[shapes[name].color],
                                                  depthshade=False)
        for name, (points, _width) in d.lines.items():
            (line,) = ax.plot(*points[0].T, color=shapes[name].color, linewidth=1.5)
            artists["lines"][name] = line
        if d.contacts.shape[1]:
            artists["contacts"] = ax.scatter(*d.contacts[0].T, s=12, depthshade=False,
                                             edgecolors="none")
            artists["flash"] = ax.scatter(*np.zeros((3, 0)), s=12 * FLASH_SIZE,
                                          facecolors="none", linewidths=1.2,
                                          depthshade=False)
            for _ in range(d.contacts.shape[1]):
                (seg,) = ax.plot([], [], [], color=ARROW_COLOR[:3], linewidth=1.5)
                artists["arrows"].append(seg)
        return artists

    def _draw_3d(self, k: int, i: int, d: Drawn3d, art: dict[str, Any]) -> None:
        """Pose panel i's 3-D artists at frame ``k``."""
        held = int(self.clock.held[k])
        for name, poly in art["boxes"].items():
            poly.set_verts([d.boxes[name][k][list(f)] for f in BOX_FACES])
        for name, dots in art["circles"].items():
            dots._offsets3d = tuple(d.circles[name][0][k][:, None])
        for name, line in art["lines"].items():
            line.set_data_3d(*d.lines[name][0][k].T)
        if "contacts" in art:
            entered, left, _words = self._flashes[i].get(held, ([], [], ""))
            art["contacts"]._offsets3d = tuple(d.contacts[k].T)
            art["contacts"].set_facecolor([ACTIVE_COLOR if on or c in entered else FREE_COLOR
                                           for c, on in enumerate(d.active[k])])
            rings = entered + left
            art["flash"]._offsets3d = tuple(d.contacts[k][rings].T if rings
                                            else np.zeros((3, 0)))
            art["flash"].set_edgecolor([ACTIVE_COLOR] * len(entered)
                                       + [LIFTOFF_COLOR] * len(left))
            for c, seg in enumerate(art["arrows"]):
                start, end = d.arrows[k, c]
                shown = bool(d.active[k, c]) and float(np.linalg.norm(end - start)) > 1e-9
                seg.set_visible(shown)
                seg.set_data_3d(*np.stack([start, end]).T)

    def draw(self, k: int) -> None:
        """Pose every artist at frame ``k`` and write the titles."""
        held = int(self.clock.held[k])
        if self.view == "3d":
            for i, (ax, p, (d, _mode), art) in enumerate(zip(
                    self.axes, self.panels, self._drawn, self._artists)):
                self._draw_3d(k, i, d, art)
                ax.set_title(f"{p.title}\n{self.caption(k, i)}", fontsize=FONT, loc="left")
            return
        for i, (ax, p, (d, _mode), art) in enumerate(zip(self.axes, self.panels, self._drawn,
                                                          self._artists)):
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
                entered, left, _words = self._flashes[i].get(held, ([], [], ""))
                art["contacts"].set_offsets(d.contacts[k])
                art["contacts"].set_facecolor([ACTIVE_COLOR if on or c in entered
                                               else FREE_COLOR
                                               for c, on in enumerate(d.active[k])])
                rings = entered + left
                art["flash"].set_offsets(d.contacts[k][rings] if rings else np.zeros((0, 2)))
                art["flash"].set_edgecolor([ACTIVE_COLOR] * len(entered)
                                           + [LIFTOFF_COLOR] * len(left))
                for c, arrow in enumerate(art["arrows"]):
                    start, end = d.arrows[k, c]
                    shown = bool(d.active[k, c]) and float(np.hypot(*(end - start))) > 1e-9
                    arrow.set_visible(shown)
                    if shown:
                        arrow.set_positions(tuple(start), tuple(end))
            ax.set_title(f"{p.title}\n{self.caption(k, i)}", fontsize=FONT, loc="left")

    def save(self, path: Path) -> Path:
        """Write every frame to ``path`` (.gif or .mp4, see :func:`check_output`)."""
        path = Path(path)
        writer_name = check_output(path)
        writer: Any = (animation.PillowWriter(fps=self.fps) if writer_name == "pillow"
                       else animation.FFMpegWriter(fps=self.fps))
        partial = path.with_name(f".{path.stem}.partial{path.suffix}")
        try:
            with writer.saving(self.figure, str(partial), self.dpi):
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


def _check_frames(hold: int, min_frames: int) -> None:
    for name, value in (("hold", hold), ("min_frames", min_frames)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
                or not 0 <= value <= 100:
            raise InvalidInputError(f"{name} must be an integer from 0 to 100, got {value!r}")


def _check_view(view: str) -> None:
    if view not in VIEWS:
        raise InvalidInputError(f"view must be one of {', '.join(VIEWS)}, got {view!r}")


def _write(panels: Sequence[Panel], out: Path, fps: int, speed: float,
           size: tuple[int, int], hold: int, min_frames: int, view: str) -> Animation:
    movie = Animation(panels, fps=fps, speed=speed, size=size, hold=hold,
                      min_frames=min_frames, view=view)
    try:
        movie.save(out)
    finally:
        movie.close()
    return movie


def animate(system: CompiledSystem | str, maneuver: str, s: float, out: Path, *,
            inputs: Mapping[str, float] | None = None, fps: int = 30, speed: float = 1.0,
            size: tuple[int, int] = PANEL_SIZE, hold: int = HOLD_FRAMES,
            min_frames: int = MIN_MODE_FRAMES, view: str = "auto") -> Animation:
    """Write ``maneuver`` of ``system`` (compiled, a library name or a system file) at s to
    ``out`` (.gif, or .mp4 with ffmpeg) in ``view`` (:data:`VIEWS`); returns the (closed)
    animation: its frames, times and panels. Every argument is checked before anything is
    simulated or written."""
    out = Path(out)
    check_output(out)
    _check_view(view)
    _check_rate(fps, speed)
    _check_frames(hold, min_frames)
    _check_s("s", s)
    compiled = system if isinstance(system, CompiledSystem) else CompiledSystem(system)
    compiled.code(maneuver)
    return _write([panel(compiled, maneuver, s, inputs, fps=fps, speed=speed)], out, fps,
                  speed, size, hold, min_frames, view)


def side_by_side(system: CompiledSystem | str, maneuver: str, out: Path, *, s0: float = 0.0,
                 delta: float = 0.02, inputs: Mapping[str, float] | None = None, fps: int = 30,
                 speed: float = 1.0, size: tuple[int, int] = PANEL_SIZE,
                 hold: int = HOLD_FRAMES, min_frames: int = MIN_MODE_FRAMES,
                 view: str = "auto") -> Animation:
    """Write ``maneuver`` at s0 - delta (left panel) and s0 + delta (right panel) into one
    animation (see the module docstring; s0 = 0 is the simultaneous event of the biped's
    touchdown and liftoff and of the rocking bar's drop)."""
    out = Path(out)
    check_output(out)
    _check_view(view)
    _check_rate(fps, speed)
    _check_frames(hold, min_frames)
    _check_s("s0", s0)
    if not (isinstance(delta, (int, float)) and math.isfinite(delta) and 0 < delta <= 1):
        raise InvalidInputError(f"delta must be a number in (0, 1], got {delta!r}")
    compiled = system if isinstance(system, CompiledSystem) else CompiledSystem(system)
    compiled.code(maneuver)
    panels = [panel(compiled, maneuver, s0 + sign * delta, inputs, fps=fps, speed=speed)
              for sign in (-1, 1)]
    return _write(panels, out, fps, speed, size, hold, min_frames, view)


def _check_s(name: str, value: float) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value):
        raise InvalidInputError(f"{name} must be a finite number, got {value!r}")
