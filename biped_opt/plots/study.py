"""Figures of a parameter study's table (:mod:`biped_opt.studies.study`): where the
nonsmoothness persists.

- :func:`size_map`: over two varied parameters, the size of one kind of nonsmooth point of one
  quantity near a chosen s (the jump of the liftoff outcome at 0, the kink of the touchdown
  outcome ...) as a heat map; cells where the point is absent are drawn hatched, so "gone" is
  not confused with "small";
- :func:`location_plot`: the s where a kind of point of a quantity sits (the optimal liftoff
  policy's switch) against one parameter, one line per value of a second one.

Both read the rows as :func:`biped_opt.record.study_table.read_table` returns them (strings) or as
dictionaries of numbers.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from biped_opt.errors import InvalidInputError  # noqa: E402
from biped_opt.plots.figures import _finish  # noqa: E402

__all__ = ["size_map", "size_grid", "location_plot", "locations", "study_figures"]


def _num(value: Any) -> float:
    return math.nan if value in ("", None) else float(value)


def _select(rows: Iterable[Mapping[str, Any]], table: str, quantity: str, kind: str,
            s_near: float | None, window: float) -> list[Mapping[str, Any]]:
    out = []
    for r in rows:
        if r["table"] != table or r["quantity"] != quantity or r["kind"] != kind:
            continue
        if s_near is not None and not abs(_num(r["s"]) - s_near) <= window:
            continue
        out.append(r)
    return out


def size_grid(rows: Sequence[Mapping[str, Any]], x: str, y: str, *, table: str = "fixed",
              quantity: str = "outcome", kind: str = "jump", s_near: float | None = 0.0,
              window: float = 1e-6) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x values, y values, sizes[len(y), len(x)]) of the chosen points; NaN where a parameter
    point has none (several in the window: the largest in size)."""
    if not rows:
        raise InvalidInputError("the study table has no rows")
    for name in (x, y):
        if name not in rows[0]:
            raise InvalidInputError(f"the study did not vary {name!r}")
    xs = sorted({_num(r[x]) for r in rows})
    ys = sorted({_num(r[y]) for r in rows})
    sizes = np.full((len(ys), len(xs)), np.nan)
    for r in _select(rows, table, quantity, kind, s_near, window):
        i, j = ys.index(_num(r[y])), xs.index(_num(r[x]))
        size = _num(r["size"])
        if math.isnan(sizes[i, j]) or abs(size) > abs(sizes[i, j]):
            sizes[i, j] = size
    return np.array(xs), np.array(ys), sizes


def size_map(path: str | Path, rows: Sequence[Mapping[str, Any]], x: str, y: str, *,
             table: str = "fixed", quantity: str = "outcome", kind: str = "jump",
             s_near: float | None = 0.0, window: float = 1e-6, title: str | None = None) -> Path:
    """Heat map of the size (right - left: limits for a jump, slopes for a kink) of the chosen
    nonsmooth points over the parameters x and y (module docstring)."""
    xs, ys, sizes = size_grid(rows, x, y, table=table, quantity=quantity, kind=kind,
                              s_near=s_near, window=window)
    fig, ax = plt.subplots(figsize=(6.4, 4.8), constrained_layout=True)
    shown = np.ma.masked_invalid(sizes)
    mesh = ax.pcolormesh(np.arange(xs.size + 1) - 0.5, np.arange(ys.size + 1) - 0.5, shown,
                         cmap="viridis", shading="flat")
    for i, j in zip(*np.nonzero(np.isnan(sizes))):
        ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, hatch="///",
                                   ec="0.6", lw=0))
    for i in range(ys.size):
        for j in range(xs.size):
            text = "none" if np.isnan(sizes[i, j]) else f"{sizes[i, j]:.3g}"
            ax.text(j, i, text, ha="center", va="center", fontsize=7,
                    color="k" if np.isnan(sizes[i, j]) else "w")
    ax.set_xticks(range(xs.size), [f"{v:g}" for v in xs])
    ax.set_yticks(range(ys.size), [f"{v:g}" for v in ys])
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    what = "jump (right - left limit)" if kind == "jump" else f"{kind} (right - left slope)"
    fig.colorbar(mesh, ax=ax, label=what)
    where = "" if s_near is None else f" at s = {s_near:g}"
    ax.set_title(title or f"{table} {quantity}: {what}{where}; hatched: none", fontsize=9)
    return _finish(fig, Path(path))


def locations(rows: Sequence[Mapping[str, Any]], x: str, *, by: str | None = None,
              table: str = "optimal", quantity: str = "policy", kind: str = "jump"
              ) -> dict[float | None, tuple[np.ndarray, np.ndarray]]:
    """{value of ``by`` (None without): (x values, s of the chosen points)} sorted by x; a
    parameter point with several such points contributes each."""
    if rows and x not in rows[0]:
        raise InvalidInputError(f"the study did not vary {x!r}")
    groups: dict[float | None, list[tuple[float, float]]] = {}
    for r in _select(rows, table, quantity, kind, None, 0.0):
        key = None if by is None else _num(r[by])
        groups.setdefault(key, []).append((_num(r[x]), _num(r["s"])))
    return {k: tuple(np.array(v) for v in zip(*sorted(pts))) for k, pts in
            sorted(groups.items(), key=lambda kv: (kv[0] is None, kv[0]))}  # type: ignore


def location_plot(path: str | Path, rows: Sequence[Mapping[str, Any]], x: str, *,
                  by: str | None = None, table: str = "optimal", quantity: str = "policy",
                  kind: str = "jump", title: str | None = None) -> Path:
    """Where the chosen points sit in s against the parameter x (module docstring)."""
    found = locations(rows, x, by=by, table=table, quantity=quantity, kind=kind)
    fig, ax = plt.subplots(figsize=(6.4, 4.0), constrained_layout=True)
    for key, (xs, ss) in found.items():
        ax.plot(xs, ss, "o-", ms=4, label=None if key is None else f"{by} = {key:g}")
    if not found:
        ax.text(0.5, 0.5, f"no {kind} of the {table} {quantity} in this study",
                transform=ax.transAxes, ha="center")
    ax.axhline(0.0, color="0.8", lw=0.8, zorder=0)
    ax.set_xlabel(x)
    ax.set_ylabel("s of the point")
    if by is not None and found:
        ax.legend(fontsize=8)
    ax.set_title(title or f"where the {table} {quantity} has its {kind}", fontsize=9)
    return _finish(fig, Path(path))


def study_figures(folder: str | Path, rows: Sequence[Mapping[str, Any]],
                  parameters: Sequence[str]) -> list[Path]:
    """The figures a study's table supports: for the first two varied parameters, a heat map
    of every (table, quantity, kind) that occurs at s = 0; for the first parameter, where the
    optimal policy's jumps and kinks sit (one line per value of the second)."""
    folder = Path(folder)
    out: list[Path] = []
    x = parameters[0]
    y = parameters[1] if len(parameters) > 1 else None
    groups = sorted({(r["table"], r["quantity"], r["kind"]) for r in rows
                     if r["kind"] not in ("none", "second-derivative")
                     and abs(_num(r["s"])) <= 1e-6})
    if y is not None:
        for table, quantity, kind in groups:
            out.append(size_map(folder / f"map_{table}_{quantity}_{kind}.png", rows, x, y,
                                table=table, quantity=quantity, kind=kind))
    for kind in ("jump", "kink"):
        if any(r["table"] == "optimal" and r["quantity"] == "policy" and r["kind"] == kind
               for r in rows):
            out.append(location_plot(folder / f"policy_{kind}_location.png", rows, x, by=y,
                                     kind=kind))
    return out
