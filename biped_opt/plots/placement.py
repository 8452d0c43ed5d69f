"""Where a figure's notes go: in a part of the axes the data leaves free, never over it.

A note is an annotation with a box (the one-sided numbers of a nonsmooth point, say) tagged
with :data:`NOTE`. :func:`place_notes` moves every note of a figure, once its layout is final,
to the free spot of its axes nearest to the point it annotates: a spot whose box holds no point
of the plotted data (each line's vertices, the segments between them sampled every
:data:`STEP` pixels, each marker's radius) and meets no other note, legend or inset. Where no
spot is free it raises the axes' upper limit by :data:`HEADROOM` of the range (up to
:data:`ROUNDS` times), which frees a band above the data; failing that the note goes outside
the axes, right of them. Lines drawn in axes coordinates in either direction (``axvline``,
``axhline``: the faint lines that mark a point's s or an input's bound) are guides, not data.

matplotlib's own ``loc="best"`` for legends only lessens the overlap; :func:`overlaps` says
whether a box holds any data point, so a test can check a figure as a reader sees it.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
import numpy.typing as npt
from matplotlib.legend import Legend
from matplotlib.lines import Line2D
from matplotlib.transforms import Bbox

__all__ = ["NOTE", "data_points", "overlaps", "place_notes", "notes_of", "STEP", "HEADROOM",
           "ROUNDS", "MARGIN", "LEADER"]

Array = npt.NDArray[np.float64]

#: the gid of a note that :func:`place_notes` places
NOTE = "biped_opt.note"
#: pixels between samples of a drawn segment; pixels kept clear around a note's box; the
#: least distance of a box from the point it annotates, so that its leader line shows
STEP, MARGIN, LEADER = 2.0, 3.0, 10.0
#: the fraction of the y range added above the data per round, and the rounds tried
HEADROOM, ROUNDS = 0.3, 3
#: candidate spots per axis direction
GRID = 24


def _is_data(line: Line2D, ax: Any) -> bool:
    return line.get_visible() and line.get_transform() == ax.transData


def data_points(ax: Any) -> tuple[Array, Array]:
    """The display coordinates (k, 2) of every plotted data point of ``ax`` (line vertices,
    the segments between them every :data:`STEP` pixels, scatter offsets) and each one's
    radius in pixels (a marker's half size, else 0)."""
    points: list[Array] = []
    radii: list[Array] = []
    dpi = ax.figure.dpi
    for line in ax.lines:
        if not _is_data(line, ax):
            continue
        xy = np.asarray(line.get_xydata(), dtype=np.float64)
        xy = xy[np.all(np.isfinite(xy), axis=1)]
        if not xy.size:
            continue
        disp = ax.transData.transform(xy)
        marker = line.get_marker()
        radius = 0.0 if marker in (None, "", " ", "None", "none") else \
            line.get_markersize() * dpi / 72 / 2
        points.append(disp)
        radii.append(np.full(len(disp), radius))
        if line.get_linestyle() not in ("None", "", " ", "none") and len(disp) > 1:
            a, b = disp[:-1], disp[1:]
            pieces = np.maximum(1, np.ceil(np.hypot(*(b - a).T) / STEP)).astype(int)
            k = np.repeat(np.arange(len(a)), pieces)
            frac = (np.arange(pieces.sum()) - np.repeat(np.cumsum(pieces) - pieces, pieces)) \
                / np.repeat(pieces, pieces)
            points.append(a[k] + frac[:, None] * (b[k] - a[k]))
            radii.append(np.full(len(k), line.get_linewidth() * dpi / 72 / 2))
    for coll in ax.collections:
        offsets = np.asarray(coll.get_offsets(), dtype=np.float64).reshape(-1, 2)
        if coll.get_visible() and offsets.size:
            disp = coll.get_offset_transform().transform(offsets)
            sizes = np.asarray(coll.get_sizes(), dtype=np.float64)
            r = np.sqrt(sizes) * dpi / 72 / 2 if sizes.size else np.zeros(1)
            points.append(disp)
            radii.append(np.resize(r, len(disp)))
    if not points:
        return np.zeros((0, 2)), np.zeros(0)
    return np.vstack(points), np.concatenate(radii)


def overlaps(box: Bbox, points: Array, radii: Array, margin: float = 0.0) -> bool:
    """Whether any point (grown by its radius and ``margin`` pixels) meets ``box``."""
    if not len(points):
        return False
    grow = radii + margin
    inside = ((points[:, 0] + grow >= box.x0) & (points[:, 0] - grow <= box.x1)
              & (points[:, 1] + grow >= box.y0) & (points[:, 1] - grow <= box.y1))
    return bool(inside.any())


def notes_of(ax: Any) -> list[Any]:
    """The notes of ``ax`` (its texts tagged :data:`NOTE`), in the order they were made."""
    return [t for t in ax.texts if t.get_gid() == NOTE]


def _patch(note: Any, renderer: Any) -> Bbox:
    """The display box of a note's frame (its text where it has none)."""
    note.update_positions(renderer)
    patch = note.get_bbox_patch()
    if patch is None:
        return note.get_window_extent(renderer)
    note.update_bbox_position_size(renderer)
    return patch.get_window_extent(renderer)


def _obstacles(ax: Any, renderer: Any) -> list[Bbox]:
    """Boxes a note must not meet: the legends and insets of ``ax``."""
    out = [c.get_window_extent(renderer) for c in ax.get_children()
           if isinstance(c, Legend) and c.get_visible()]
    out += [c.get_window_extent(renderer) for c in ax.child_axes if c.get_visible()]
    return out


def _spot(ax: Any, size: tuple[float, float], target: tuple[float, float], points: Array,
          radii: Array, taken: list[Bbox]) -> Bbox | None:
    """The free box of ``size`` nearest to ``target`` inside ``ax``, or None."""
    frame = ax.get_window_extent()
    w, h = size
    lefts = np.linspace(frame.x0 + MARGIN, frame.x1 - MARGIN - w, GRID)
    bottoms = np.linspace(frame.y0 + MARGIN, frame.y1 - MARGIN - h, GRID)
    if lefts[0] > lefts[-1] or bottoms[0] > bottoms[-1]:
        return None
    best, best_d = None, np.inf
    for x0 in lefts:
        for y0 in bottoms:
            box = Bbox.from_bounds(x0, y0, w, h)
            # distance from the target to the box (0 inside)
            dx = max(box.x0 - target[0], 0.0, target[0] - box.x1)
            dy = max(box.y0 - target[1], 0.0, target[1] - box.y1)
            d = float(np.hypot(dx, dy))
            if d >= best_d or d < LEADER or overlaps(box, points, radii, MARGIN):
                continue
            if any(box.overlaps(o.expanded(1.0, 1.0).padded(2 * MARGIN)) for o in taken):
                continue
            best, best_d = box, d
    return best


def _move(note: Any, renderer: Any, box: Bbox) -> None:
    """Put a note's frame at ``box`` (display), keeping its text where it is in the frame."""
    now = _patch(note, renderer)
    ax = note.axes
    anchor = ax.transAxes.transform(note.xyann)
    new = ax.transAxes.inverted().transform(anchor + np.array([box.x0 - now.x0,
                                                               box.y0 - now.y0]))
    note.set_annotation_clip(False)
    note.xyann = (float(new[0]), float(new[1]))


def _place_axes(ax: Any, notes: list[Any], renderer: Any) -> bool:
    """Place the notes of one axes inside it; False where one found no free spot."""
    points, radii = data_points(ax)
    taken = _obstacles(ax, renderer)
    for note in notes:
        size = _patch(note, renderer)
        target = ax.transData.transform(note.xy) if note.xycoords == "data" else \
            np.array([size.x0, size.y0])
        box = _spot(ax, (size.width, size.height), (float(target[0]), float(target[1])),
                    points, radii, taken)
        if box is None:
            return False
        _move(note, renderer, box)
        taken.append(box)
    return True


def _outside(ax: Any, notes: list[Any], renderer: Any) -> None:
    """Stack the notes right of the axes, top down (the layout makes room for them)."""
    top = 1.0
    for note in notes:
        note.set_annotation_clip(False)
        note.set_in_layout(True)
        note.xyann = (1.03, top)
        note.set_horizontalalignment("left")
        note.set_verticalalignment("top")
        size = _patch(note, renderer)
        top -= size.height / ax.get_window_extent().height + 0.03


def place_notes(fig: Any, axes: Iterable[Any] | None = None) -> bool:
    """Place every note of ``axes`` (default: all of ``fig``'s) as the module docstring says.
    Notes must use ``textcoords="axes fraction"``; call it after everything else is drawn.
    True when it drew the figure: its layout as last drawn is then final."""
    chosen = [ax for ax in (fig.axes if axes is None else axes) if notes_of(ax)]
    if not chosen:
        return False
    for ax in chosen:  # (a note inside its axes never moves the layout, wherever it goes)
        for note in notes_of(ax):
            note.set_in_layout(False)
    fig.canvas.draw()  # (the final layout: the data's pixels and the notes' sizes)
    renderer = fig.canvas.get_renderer()
    moved = False
    for ax in list(chosen):
        notes = notes_of(ax)
        for _round in range(ROUNDS + 1):
            if _place_axes(ax, notes, renderer):
                break
            moved = True
            if _round < ROUNDS:
                low, high = ax.get_ylim()
                ax.set_ylim(low, high + HEADROOM * (high - low))
                fig.canvas.draw()
        else:
            _outside(ax, notes, renderer)
            chosen.remove(ax)
    if not moved:  # every note found a spot in the first layout, which is then final
        return True
    # a raised limit or a note outside may have moved the layout by a few pixels: place once
    # more in the layout they give
    fig.canvas.draw()
    for ax in chosen:
        _place_axes(ax, notes_of(ax), renderer)
    return True
