"""What a Foxglove layout shows, drawn with matplotlib from a recording.

Foxglove is an application that does not run here; :func:`draw_layout` reads the layout file
(``config/foxglove_layout.json``: Foxglove's ``configById`` and ``layout`` mosaic) and draws each
of its panels, in the mosaic's proportions, from a recording read with
:func:`biped_opt.record.reader.read_raw`:

- ``3D``: the scene at one instant in the x-z plane (the layout's camera looks along +y from
  -y: x to the right, z up), from ``/tf`` and the markers: boxes and spheres in their frames,
  lines, the contact points (their colours: red while active), the force arrows, the ground;
  the URDF's visuals (``/robot_description``) as dashed outlines in their frames, the axes of
  the frames the layout shows, its grid layer;
- ``Plot``: every path over the time since the recording's start (``xAxisVal`` timestamp, with
  the instant of the 3D panel as the playback cursor) or against ``xAxisPath`` (``custom``: x
  and y values paired in order, as Foxglove pairs them);
- ``StateTransitions``: every path as a band over time, a colour per value, the values named in
  a legend (by the message's constants where it defines them, as Foxglove labels them); below,
  the same bands over the window the synced plots follow (``followingViewWidth``), since a
  sweep's hundreds of changes are only seen zoomed in.

Lengths and times are labelled in the recorded system's units (:mod:`biped_opt.plots.units`):
the biped's are gravity units (g = 1), so a length is in length units, not metres, and the log
time, simulated time, counts the model's time units (one per second of Foxglove's clock).

Message paths are Foxglove's ``/topic.field[index].field``. A topic the recording lacks leaves its
panel with a note. ``python -m biped_opt.plots.layout_preview RECORDING OUT.png --layout
config/foxglove_layout.json`` draws one.
"""

from __future__ import annotations

import argparse
import json
import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from matplotlib.patches import Circle, FancyArrowPatch, Patch, Polygon

from biped_opt.errors import BipedOptError
from biped_opt.plots.figures import plt  # (its import selects the file backend)
from biped_opt.plots.units import units_of
from biped_opt.record.reader import RawRecording, read_raw, recorded_system
from biped_opt.ros.interfaces import load_interfaces

__all__ = ["LayoutError", "draw_layout", "message_path", "mosaic", "FIGSIZE", "DPI"]

NS = 1_000_000_000
#: the picture: 16 x 9 inches at 100 dpi (1600 x 900 pixels)
FIGSIZE, DPI = (16.0, 9.0), 100
#: visualization_msgs/Marker types drawn here
ARROW, CUBE, SPHERE, LINE_STRIP, SPHERE_LIST = 0, 1, 2, 4, 7
_PATH = re.compile(r"^((?:/[A-Za-z_][A-Za-z0-9_]*)+)((?:\.[A-Za-z_]\w*(?:\[\d+\])?)+)$")
_PART = re.compile(r"\.([A-Za-z_]\w*)(?:\[(\d+)\])?")

Array = npt.NDArray[np.float64]
Rect = tuple[float, float, float, float]


class LayoutError(BipedOptError, ValueError):
    """A layout file this module cannot draw."""


def message_path(path: str) -> tuple[str, list[tuple[str, int | None]]]:
    """Foxglove's ``/topic.a[2].b`` as (``/topic``, [(``a``, 2), (``b``, None)])."""
    m = _PATH.match(path)
    if m is None:
        raise LayoutError(f"not a message path: {path!r}")
    return m.group(1), [(name, int(index) if index else None)
                        for name, index in _PART.findall(m.group(2))]


def _select(msg: Any, parts: Sequence[tuple[str, int | None]]) -> Any:
    """The value a path's ``parts`` select in a decoded message (None past a sequence's end)."""
    value = msg
    for name, index in parts:
        value = getattr(value, name)
        if index is not None:
            if index >= len(value):
                return None
            value = value[index]
    return value


def mosaic(node: Any, rect: Rect = (0.0, 0.0, 1.0, 1.0)) -> dict[str, Rect]:
    """Panel id -> (left, top, width, height) as fractions of the whole, for Foxglove's mosaic
    (a panel id, or ``direction`` row (first on the left) or column (first on top),
    ``first``, ``second`` and ``splitPercentage`` of the first, 50 by default)."""
    if isinstance(node, str):
        return {node: rect}
    try:
        split = float(node.get("splitPercentage", 50)) / 100
        first, second, direction = node["first"], node["second"], node["direction"]
    except (AttributeError, KeyError, TypeError, ValueError):
        raise LayoutError(f"not a mosaic node: {node!r:.80}") from None
    x, y, w, h = rect
    if direction == "row":
        a, b = (x, y, w * split, h), (x + w * split, y, w * (1 - split), h)
    elif direction == "column":
        a, b = (x, y, w, h * split), (x, y + h * split, w, h * (1 - split))
    else:
        raise LayoutError(f"mosaic direction must be row or column, got {direction!r}")
    return {**mosaic(first, a), **mosaic(second, b)}


@dataclass
class _Data:
    """A recording's messages by topic, decoded on first use, and the recorded system's units
    (a recording of the biped names no system: the biped's)."""

    raw: RawRecording
    typestore: Any

    def __post_init__(self) -> None:
        system = recorded_system(self.raw)
        self.units = units_of("biped") if system is None else \
            units_of(system.get("system"), system.get("source"))
        self._by_topic: dict[str, list[Any]] = {}
        self._decoded: dict[str, list[tuple[int, Any]]] = {}
        for m in self.raw.messages:
            self._by_topic.setdefault(m.topic, []).append(m)
        self.start_ns = self.raw.messages[0].log_time_ns if self.raw.messages else 0

    def has(self, topic: str) -> bool:
        return bool(self._by_topic.get(topic))

    def type(self, topic: str) -> str:
        return self.raw.channels[topic].type

    def messages(self, topic: str) -> list[tuple[int, Any]]:
        """(log time, message) of every message of ``topic``."""
        if topic not in self._decoded:
            typename = self.type(topic) if self.has(topic) else ""
            self._decoded[topic] = [
                (m.log_time_ns, self.typestore.deserialize_cdr(m.data, typename))
                for m in self._by_topic.get(topic, [])]
        return self._decoded[topic]

    def at(self, topic: str, log_time_ns: int) -> Any:
        """The last message of ``topic`` logged at or before ``log_time_ns`` (else the first)."""
        items = self._by_topic[topic]
        times = [m.log_time_ns for m in items]
        k = max(int(np.searchsorted(times, log_time_ns, side="right")) - 1, 0)
        return self.typestore.deserialize_cdr(items[k].data, self.type(topic))

    def series(self, path: str) -> tuple[Array, list[Any]]:
        """(times since the start [s], values) of a path, one per message that has it."""
        topic, parts = message_path(path)
        times, values = [], []
        for t, msg in self.messages(topic):
            v = _select(msg, parts)
            if v is not None:
                times.append((t - self.start_ns) / NS)
                values.append(v)
        return np.asarray(times, dtype=np.float64), values

    def constants(self, path: str) -> dict[Any, str]:
        """Value -> name of the constants of the message type holding a path's last field."""
        topic, parts = message_path(path)
        typename = self.type(topic)
        for name, _index in parts[:-1]:
            kind, spec = dict(self.typestore.fielddefs[typename][1])[name]
            typename = spec if getattr(kind, "name", kind) == "NAME" else spec[0][1]
        return {value: name for name, _t, value in self.typestore.fielddefs[typename][0]}


# -- the 3D panel ----------------------------------------------------------------------------------

def _rotate(q: Sequence[float], v: Array) -> Array:
    """Rows of ``v`` turned by the unit quaternion ``q`` (x, y, z, w)."""
    u, w = np.asarray(q[:3], dtype=np.float64), float(q[3])
    c = np.cross(u, v)
    return v + 2 * w * c + 2 * np.cross(u, c)


@dataclass(frozen=True)
class _Pose:
    position: Array
    rotation: tuple[float, float, float, float]

    def apply(self, points: Array) -> Array:
        return _rotate(self.rotation, np.atleast_2d(points)) + self.position

    @staticmethod
    def of(p: Any) -> _Pose:
        """From a geometry_msgs Pose or Transform."""
        t = getattr(p, "position", None) or p.translation
        r = getattr(p, "orientation", None) or p.rotation
        return _Pose(np.array([t.x, t.y, t.z]), (r.x, r.y, r.z, r.w))


IDENTITY = _Pose(np.zeros(3), (0.0, 0.0, 0.0, 1.0))


def _rgba(c: Any) -> tuple[float, float, float, float]:
    return (float(c.r), float(c.g), float(c.b), float(c.a))


def _box(ax: Any, pose: _Pose, size: Sequence[float], **style: Any) -> Array:
    """A box's outline in x-z (its corners projected; the convex hull of a planar view)."""
    sx, sy, sz = (float(v) / 2 for v in size)
    corners = np.array([[a * sx, b * sy, c * sz] for a in (-1, 1) for b in (-1, 1)
                        for c in (-1, 1)])
    xz = pose.apply(corners)[:, [0, 2]]
    hull = _hull(xz)
    ax.add_patch(Polygon(hull, closed=True, **style))
    return xz


def _hull(points: Array) -> Array:
    """Convex hull of 2-D points (monotone chain), counter-clockwise."""
    pts = sorted(set(map(tuple, np.round(points, 12))))
    if len(pts) < 3:
        return np.array(pts)

    def half(seq: list[tuple[float, float]]) -> list[tuple[float, float]]:
        out: list[tuple[float, float]] = []
        for p in seq:
            while len(out) >= 2 and _turn(out[-2], out[-1], p) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _turn(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
    """The z component of (a - o) x (b - o): > 0 for a left turn."""
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _frames(tf: Any) -> dict[str, _Pose]:
    """Frame -> pose in world of one TFMessage (world -> child transforms)."""
    out = {"world": IDENTITY}
    for t in tf.transforms:
        parent = out.get(t.header.frame_id, IDENTITY)
        child = _Pose.of(t.transform)
        out[t.child_frame_id] = _Pose(parent.apply(child.position)[0],
                                      _compose(parent.rotation, child.rotation))
    return out


def _compose(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float, float]:
    """The quaternion product a b (x, y, z, w)."""
    ax_, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax_ * bw + ay * bz - az * by, aw * by - ax_ * bz + ay * bw + az * bx,
            aw * bz + ax_ * by - ay * bx + az * bw, aw * bw - ax_ * bx - ay * by - az * bz)


def _draw_scene(ax: Any, data: _Data, cfg: dict[str, Any], log_time_ns: int,
                what: str) -> None:
    ax.set_aspect("equal")
    ax.set_facecolor("#f7f7f7")
    if not data.has("/tf"):
        _note(ax, "no /tf in the recording")
        return
    frames = _frames(data.at("/tf", log_time_ns))
    drawn: list[Array] = []
    topics = cfg.get("topics", {})
    if data.has("/biped/markers") and topics.get("/biped/markers", {}).get("visible", True):
        drawn += _draw_markers(ax, data.at("/biped/markers", log_time_ns), frames)
    if data.has("/robot_description") and \
            topics.get("/robot_description", {}).get("visible", True):
        _draw_urdf(ax, data.messages("/robot_description")[0][1].data, frames)
    scene = cfg.get("scene", {}).get("transforms", {})
    scale = float(scene.get("axisScale", 0.1))
    for key, settings in cfg.get("transforms", {}).items():
        name = key.removeprefix("frame:")
        if name in frames and settings.get("visible", True):
            pose = frames[name]
            o, ex, ez = pose.apply(np.array([[0, 0, 0], [scale, 0, 0], [0, 0, scale]]))
            ax.plot([o[0], ex[0]], [o[2], ex[2]], color="#e41a1c", lw=1.5, zorder=6)
            ax.plot([o[0], ez[0]], [o[2], ez[2]], color="#377eb8", lw=1.5, zorder=6)
            if scene.get("showLabel", True):
                ax.annotate(name, (o[0], o[2]), xytext=(4, -10), textcoords="offset points",
                            fontsize=7, color="0.25", zorder=7)
    if drawn:
        pts = np.vstack(drawn)
        (x0, z0), (x1, z1) = pts.min(axis=0), pts.max(axis=0)
        pad = 0.15 * max(x1 - x0, z1 - z0, 0.5)
        ax.set_xlim(x0 - pad, x1 + pad)
        ax.set_ylim(min(z0, 0.0) - pad, z1 + pad)
    for layer in cfg.get("layers", {}).values():
        if layer.get("layerId") == "foxglove.Grid" and layer.get("visible", True):
            _draw_grid(ax, layer)
    ax.set_xlabel(f"x [{data.units.length}] (world; {data.units.name})")
    ax.set_ylabel(f"z [{data.units.length}]")
    ax.set_title(f"{ax.get_title()}\n{what} (at {(log_time_ns - data.start_ns) / NS:.3f} "
                 f"{data.units.time} of the recording)", fontsize=9)


def _draw_markers(ax: Any, array: Any, frames: dict[str, _Pose]) -> list[Array]:
    """Every marker of a MarkerArray in x-z; the points drawn, for the view's limits (the
    ground's far ends left out)."""
    drawn: list[Array] = []
    for m in array.markers:
        frame = frames.get(m.header.frame_id, IDENTITY)
        pose = _Pose(frame.apply(_Pose.of(m.pose).position)[0],
                     _compose(frame.rotation, _Pose.of(m.pose).rotation))
        color = _rgba(m.color)
        points = np.array([[p.x, p.y, p.z] for p in m.points]).reshape(-1, 3)
        if m.type == CUBE:
            xz = _box(ax, pose, (m.scale.x, m.scale.y, m.scale.z), fc=color, ec="none",
                      zorder=2 if m.id else 1)
            if m.id:  # (the ground spans 20 m: the view follows the robot)
                drawn.append(xz)
        elif m.type == SPHERE:
            o = pose.position
            ax.add_patch(Circle((o[0], o[2]), m.scale.x / 2, fc=color, ec="none", zorder=4))
            drawn.append(np.array([[o[0] - m.scale.x, o[2] - m.scale.x],
                                   [o[0] + m.scale.x, o[2] + m.scale.x]]))
        elif m.type == LINE_STRIP and len(points):
            xz = pose.apply(points)[:, [0, 2]]
            ax.plot(xz[:, 0], xz[:, 1], color=color, lw=3, solid_capstyle="round", zorder=3)
            drawn.append(xz)
        elif m.type == SPHERE_LIST and len(points):
            xz = pose.apply(points)[:, [0, 2]]
            colours = [_rgba(c) for c in m.colors] or [color] * len(xz)
            for (px, pz), c in zip(xz, colours):
                ax.add_patch(Circle((px, pz), m.scale.x / 2, fc=c, ec="k", lw=0.4, zorder=5))
        elif m.type == ARROW and len(points) == 2 and color[3] > 0:
            (a, b) = pose.apply(points)[:, [0, 2]]
            if np.hypot(*(b - a)) > 0:
                ax.add_patch(FancyArrowPatch(tuple(a), tuple(b), arrowstyle="-|>",
                                             mutation_scale=12, color=color, lw=2, zorder=6))
                drawn.append(np.array([a, b]))
    return drawn


def _draw_urdf(ax: Any, urdf: str, frames: dict[str, _Pose]) -> None:
    """The URDF's box and sphere visuals (at their links' origins) as dashed outlines."""
    try:
        root = ET.fromstring(urdf)
    except ET.ParseError:
        return
    style = {"fill": False, "ec": "0.15", "lw": 0.8, "ls": "--", "zorder": 7}
    for link in root.findall("link"):
        pose = frames.get(link.get("name", ""))
        if pose is None:
            continue
        for geometry in link.findall("visual/geometry/*"):
            if geometry.tag == "box":
                _box(ax, pose, [float(v) for v in geometry.get("size", "0 0 0").split()],
                     **style)
            elif geometry.tag == "sphere":
                r = float(geometry.get("radius", "0"))
                ax.add_patch(Circle((pose.position[0], pose.position[2]), r, **style))


def _draw_grid(ax: Any, layer: dict[str, Any]) -> None:
    """A foxglove.Grid layer: lines in x-z when it is turned 90 degrees about x (as the layout
    places it), else its plane seen edge-on."""
    size, divisions = float(layer.get("size", 10)), int(layer.get("divisions", 10))
    x, _y, z = (float(v) for v in layer.get("position", (0, 0, 0)))
    roll = float(layer.get("rotation", (0, 0, 0))[0])
    color = layer.get("color", "#248eff")[:7]
    if abs(abs(roll) - 90) > 1e-9:
        ax.axhline(z, color=color, lw=0.5, zorder=0)
        return
    for v in np.linspace(-size / 2, size / 2, divisions + 1):
        ax.plot([x + v, x + v], [z - size / 2, z + size / 2], color=color, lw=0.4, zorder=0,
                alpha=0.5)
        ax.plot([x - size / 2, x + size / 2], [z + v, z + v], color=color, lw=0.4, zorder=0,
                alpha=0.5)


# -- plots -----------------------------------------------------------------------------------------

def _note(ax: Any, text: str) -> None:
    """An empty panel saying why."""
    ax.set_xticks([])
    ax.set_yticks([])
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, fontsize=9,
            color="0.4")


def _missing(data: _Data, paths: Sequence[str]) -> list[str]:
    """The topics of ``paths`` that the recording lacks."""
    return sorted({topic for topic, _parts in map(message_path, paths) if not data.has(topic)})


def _draw_plot(ax: Any, data: _Data, cfg: dict[str, Any], cursor_s: float) -> None:
    paths = [p for p in cfg.get("paths", []) if p.get("enabled", True)]
    custom = cfg.get("xAxisVal") in ("custom", "currentCustom")
    wanted = [p["value"] for p in paths] + ([cfg["xAxisPath"]["value"]] if custom else [])
    missing = _missing(data, wanted)
    if missing:
        _note(ax, f"no {', '.join(missing)} in the recording")
        return
    if custom:
        _t, xs = data.series(cfg["xAxisPath"]["value"])
        x = np.asarray(xs, dtype=np.float64)
        ax.set_xlabel(cfg["xAxisPath"]["value"])
    else:
        ax.axvline(cursor_s, color="0.3", lw=0.8, ls=":")
        ax.set_xlabel(f"time since the recording's start [{data.units.time}]")
    width = cfg.get("followingViewWidth")
    window = (cursor_s - float(width), cursor_s) if width and not custom else None
    shown: list[Array] = []
    for k, p in enumerate(paths):
        t, values = data.series(p["value"])
        y = np.asarray(values, dtype=np.float64)
        xs_ = x[: len(y)] if custom else t
        n = min(len(xs_), len(y))
        ax.plot(xs_[:n], y[:n], ls="-" if p.get("showLine", True) else "none",
                marker="." if custom else None, ms=3, lw=1.0, color=p.get("color", f"C{k}"),
                label=p.get("label") or p["value"])
        if window is not None:
            shown.append(y[:n][(xs_[:n] >= window[0]) & (xs_[:n] <= window[1])])
    if window is not None:  # Foxglove then shows the last ``width`` seconds of playback
        ax.set_xlim(*window)
        visible = np.concatenate(shown) if shown else np.zeros(0)
        if visible.size:
            lo, hi = float(visible.min()), float(visible.max())
            pad = 0.08 * max(hi - lo, 1e-9)
            ax.set_ylim(lo - pad, hi + pad)
    if cfg.get("showLegend", True):
        ax.legend(fontsize=7, loc="best", framealpha=0.8)


def _value_colour(value: Any) -> Any:
    return plt.get_cmap("tab10")(int(value) % 10)


def _draw_transitions(axes: Sequence[Any], data: _Data, cfg: dict[str, Any], cursor_s: float,
                      width: float | None) -> None:
    """The bands on ``axes[0]`` over the whole recording; on ``axes[1]``, when given, the last
    ``width`` seconds before the cursor (what the synced plots show: a zoom in Foxglove)."""
    ax = axes[0]
    paths = cfg.get("paths", [])
    missing = _missing(data, [p["value"] for p in paths])
    if missing:
        _note(ax, f"no {', '.join(missing)} in the recording")
        for a in axes[1:]:
            a.set_visible(False)
        return
    end = (data.raw.messages[-1].log_time_ns - data.start_ns) / NS
    labels, names = [], {}
    for k, p in enumerate(paths):
        t, values = data.series(p["value"])
        names.update(data.constants(p["value"]))
        changes = [i for i in range(len(values)) if i == 0 or values[i] != values[i - 1]]
        for n, i in enumerate(changes):
            stop = t[changes[n + 1]] if n + 1 < len(changes) else end
            for a in axes:
                a.plot([t[i], stop], [-(k + 1)] * 2, lw=9, solid_capstyle="butt",
                       color=_value_colour(values[i]))
        labels.append(p.get("label") or p["value"])
        names.update({v: names.get(v, "") for v in set(values)})
    # one colour per value, as Foxglove colours the bands; a sweep has hundreds of changes, so
    # the values' names (the message's constants, as Foxglove labels them) go in a legend
    handles = [Patch(color=_value_colour(v), label=f"{names[v]} ({v})" if names[v] else str(v))
               for v in sorted(names)]
    ax.legend(handles=handles, fontsize=7, ncols=len(handles), loc="upper center",
              bbox_to_anchor=(0.5, 1.02), frameon=False)
    for a in axes:
        a.set_yticks([-(k + 1) for k in range(len(paths))], labels, fontsize=7)
        a.set_ylim(-len(paths) - 0.7, 0.9 if a is ax else -0.3)  # (room for the legend)
        a.axvline(cursor_s, color="0.3", lw=0.8, ls=":")
        a.tick_params(labelsize=7)
    if len(axes) > 1 and width:
        axes[1].set_xlim(cursor_s - width, cursor_s)
        axes[1].set_xlabel(f"the last {width:g} {data.units.time}, as the synced plots show "
                           "them (zoomed in)", fontsize=7)
    else:
        ax.set_xlabel(f"time since the recording's start [{data.units.time}]")


# -- the picture -----------------------------------------------------------------------------------

def _instant(data: _Data, at: tuple[float, float] | None) -> tuple[int, str]:
    """The log time shown in the 3D panel: ``at`` = (th0, t) of a sweep point, else the sweep
    point nearest half its largest |th0|, midway between its first two contact events (one
    foot down, one in the air), or at its end when it has fewer; without sweep points, the
    last /tf. Returns the log time and what it is, for the panel's title."""
    points = data.messages("/biped/sweep") if data.has("/biped/sweep") else []
    if not points:
        return (data.raw.messages[-1].log_time_ns if data.raw.messages else 0), "last sample"
    th = np.array([p.theta0 for _t, p in points])
    target = at[0] if at is not None else 0.5 * float(np.max(np.abs(th)))
    point = points[int(np.argmin(np.abs(th - target)))][1]
    start = int(point.header.stamp.sec) * NS + int(point.header.stamp.nanosec)
    if at is not None:
        t = at[1]
    elif len(point.event_times) >= 2:
        t = 0.5 * (point.event_times[0] + point.event_times[1])
    else:
        t = point.t_final
    return start + round(t * NS), f"th0 = {point.theta0:+.3g}, t = {t:.3f} of its run"


def _draw_panel(fig: Any, rect: Rect, pid: str, panels: dict[str, Any], data: _Data,
                instant: int, what: str) -> None:
    """One panel of the layout in its rectangle of the figure (see the module docstring)."""
    x, y, w, h = rect
    cfg = panels.get(pid, {})
    kind = pid.split("!")[0]
    cursor = (instant - data.start_ns) / NS
    # the panel's rectangle, less room for its axis labels and title
    ax = fig.add_axes((x + 0.045 * min(w * 4, 1), 1 - y - h + 0.06 * min(h * 2.5, 1),
                       w - 0.06 * min(w * 4, 1), h - 0.1 * min(h * 2.5, 1)))
    ax.set_title(cfg.get("foxglovePanelTitle", kind), fontsize=9)
    ax.tick_params(labelsize=7)
    if kind == "3D":
        _draw_scene(ax, data, cfg, instant, what)
    elif kind == "Plot":
        _draw_plot(ax, data, cfg, cursor)
    elif kind == "StateTransitions":
        width = max((float(c.get("followingViewWidth", 0)) for c in panels.values()
                     if c.get("isSynced")), default=0.0)
        axes = [ax]
        if width and cfg.get("isSynced"):  # (room for the zoom below the whole)
            box = ax.get_position()
            ax.set_position((box.x0, box.y0 + 0.5 * box.height, box.width, 0.5 * box.height))
            axes.append(fig.add_axes((box.x0, box.y0, box.width, 0.33 * box.height)))
        _draw_transitions(axes, data, cfg, cursor, width)
    else:
        _note(ax, f"{kind} panel (not drawn here)")
    ax.xaxis.label.set_fontsize(7)
    ax.yaxis.label.set_fontsize(7)


def draw_layout(recording: str | Path, out: str | Path, *, layout: str | Path,
                   at: tuple[float, float] | None = None) -> Path:
    """Draw the panels of ``layout`` (a Foxglove layout file) from ``recording`` into the PNG
    ``out`` (:data:`FIGSIZE` at :data:`DPI`); ``at`` = (th0, t): the sweep point and time of
    the 3D panel's instant (see :func:`_instant` for the default)."""
    try:
        spec = json.loads(Path(layout).read_text())
        panels, tree = spec["configById"], spec["layout"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise LayoutError(f"{layout}: not a Foxglove layout ({type(exc).__name__}: {exc})") \
            from None
    data = _Data(read_raw(recording), load_interfaces().typestore)
    instant, what = _instant(data, at)
    fig = plt.figure(figsize=FIGSIZE, dpi=DPI)
    try:
        for pid, rect in mosaic(tree).items():
            try:
                _draw_panel(fig, rect, pid, panels, data, instant, what)
            except (AttributeError, KeyError, IndexError, TypeError, ValueError) as exc:
                raise LayoutError(f"{layout}: panel {pid!r}: cannot draw it "
                                  f"({type(exc).__name__}: {exc})") from None
    except BaseException:
        plt.close(fig)
        raise
    fig.text(0.995, 0.003, f"matplotlib rendering of {Path(layout).name} from "
             f"{Path(recording).name} (Foxglove itself draws the same panels)",
             ha="right", va="bottom", fontsize=7, color="0.4")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=DPI)
    plt.close(fig)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m biped_opt.plots.layout_preview",
                                description="draw a Foxglove layout's panels from a recording")
    p.add_argument("recording")
    p.add_argument("out")
    p.add_argument("--layout", required=True, help="the Foxglove layout file (JSON)")
    p.add_argument("--at", nargs=2, type=float, metavar=("TH0", "T"), default=None,
                   help="the 3D panel's instant: a sweep point's th0 and a time in it")
    args = p.parse_args(argv)
    try:
        path = draw_layout(args.recording, args.out, layout=args.layout,
                              at=tuple(args.at) if args.at else None)
    except BipedOptError as exc:
        p.exit(2, f"error: {exc}\n")
    print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
