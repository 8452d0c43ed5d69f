"""The paper's figures as a reader sees them: the boxes with a nonsmooth point's one-sided
numbers (Figs. 2 and 4) cover no plotted point, measured in pixels with matplotlib's renderer
on the figure as it is saved; and the notes' placement on its own (biped_opt.plots.placement).
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pytest

from biped_opt.paper.figures import optimal_data
from biped_opt.paper.nonsmooth import find_nonsmooth_optimal
from biped_opt.paper.problems import get_problem
from biped_opt.paper.sweeps import sweep_grid, sweep_optimal
from biped_opt.plots import figures
from biped_opt.plots.placement import NOTE, place_notes


def pixels_of_data(ax) -> tuple[np.ndarray, np.ndarray]:
    """Display coordinates of every point of the lines plotted in data coordinates (not the
    axvline/axhline guides), with each one's marker radius in pixels; a solid line also
    every pixel along its segments. Written here, apart from the placement's own."""
    points, radii = [], []
    for line in ax.lines:
        if line.get_transform() != ax.transData:
            continue
        xy = ax.transData.transform(np.asarray(line.get_xydata(), dtype=float))
        xy = xy[np.all(np.isfinite(xy), axis=1)]
        r = 0.0 if line.get_marker() in ("None", "", None, " ") else \
            line.get_markersize() * ax.figure.dpi / 72 / 2
        points.append(xy)
        radii.append(np.full(len(xy), r))
        if line.get_linestyle() not in ("None", "", " ") and len(xy) > 1:
            for a, b in zip(xy[:-1], xy[1:]):
                n = int(np.ceil(np.hypot(*(b - a)))) + 1
                points.append(a + np.linspace(0, 1, n)[:, None] * (b - a))
                radii.append(np.zeros(n))
    if not points:
        return np.zeros((0, 2)), np.zeros(0)
    return np.vstack(points), np.concatenate(radii)


def covered(box, points: np.ndarray, radii: np.ndarray) -> int:
    """How many points (each a disc of its radius) meet the box."""
    return int(np.sum((points[:, 0] + radii > box.x0) & (points[:, 0] - radii < box.x1)
                      & (points[:, 1] + radii > box.y0) & (points[:, 1] - radii < box.y1)))


def boxes(ax, renderer) -> list:
    """The drawn frames of the annotations that have one (their text where they have none)."""
    out = []
    for t in ax.texts:
        patch = t.get_bbox_patch()
        out.append(patch.get_window_extent(renderer) if patch is not None
                   else t.get_window_extent(renderer))
    return out


@pytest.fixture(scope="module")
def touchdown_optimal():
    """Fig. 4's touchdown column on 41 angles: three notes on the policy panel (c), u1's two
    kinks and u2's, next to u2* rising to the left of th0 = 0."""
    problem = get_problem("touchdown")
    grid = sweep_grid("touchdown", num=41)
    report = find_nonsmooth_optimal(problem, grid)
    return optimal_data(sweep_optimal(problem, grid), report.points)


def drawn_figure(monkeypatch, draw, *args):
    """The figure a drawing function saves, kept open to be measured (its ``_finish``
    wrapped: it saves as usual, then the figure is drawn once more as saved)."""
    kept = []
    finish = figures._finish

    def keep(fig, path):
        kept.append(fig)
        finish(fig, path)
        return path

    monkeypatch.setattr(figures, "_finish", keep)
    draw(*args)
    (fig,) = kept
    fig.canvas.draw()
    return fig


def test_fig4_notes_cover_no_data(tmp_path, monkeypatch, touchdown_optimal):
    fig = drawn_figure(monkeypatch, figures.figure4, touchdown_optimal, None,
                       tmp_path / "fig4.png")
    renderer = fig.canvas.get_renderer()
    policy = fig.axes[2]
    assert policy.get_title().startswith("(c)")
    assert len(policy.texts) == 3  # (u1's kinks at 0 and at its bound, u2's kink at 0)
    checked = 0
    for ax in fig.axes[::2]:  # (the touchdown column; the liftoff one says "not in the data")
        points, radii = pixels_of_data(ax)
        legends = [ax.get_legend().get_window_extent(renderer)] if ax.get_legend() else []
        mine = boxes(ax, renderer)
        for i, box in enumerate(mine):
            assert covered(box, points, radii) == 0, (ax.get_title(), ax.texts[i].get_text())
            assert not any(box.overlaps(other) for other in mine[i + 1:] + legends)
            assert ax.bbox.contains(box.x0, box.y0) and ax.bbox.contains(box.x1, box.y1)
            checked += 1
    assert checked == 7  # outcome 2, policy 3, value 2
    plt.close(fig)


def test_fig2_notes_cover_no_data(tmp_path, monkeypatch):
    """Fig. 2 on a coarse grid with a made-up kink and jump: each note off its curve."""
    from biped_opt.paper.figures import FixedSweepData, NonsmoothMark

    th = np.linspace(-0.25, 0.25, 41)
    data = FixedSweepData(
        maneuver="touchdown", inputs=(2.0, 0.5, 0.0), theta0=th, outcome=np.abs(th) - 0.1,
        cost=th ** 2, event_times=[np.array([1.0])] * th.size, modes=[[0, 3]] * th.size,
        t_final=np.full(th.size, 1.2),
        marks=(NonsmoothMark(0.0, "kink", -1.0, 1.0, -0.1, "slope"),),
        cost_marks=(NonsmoothMark(0.0, "jump", 0.0, 0.01, 0.0, "limit"),))
    fig = drawn_figure(monkeypatch, figures.figure2, data, None, tmp_path / "fig2.png")
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes[::2]:  # (the touchdown column)
        points, radii = pixels_of_data(ax)
        (box,) = boxes(ax, renderer)
        assert covered(box, points, radii) == 0
    plt.close(fig)


def test_a_note_moves_off_the_data_and_points_at_its_mark():
    """A box that starts over the data (top left, where a curve runs) ends where none is,
    its leader still ending at the marked point; with data everywhere, the axes grow a band
    above it (the y upper limit rises) rather than the box covering a point."""
    fig, ax = plt.subplots(figsize=(4, 3), dpi=100)
    x = np.linspace(0, 1, 201)
    ax.plot(x, 1 - x, ".", ms=3)
    note = ax.annotate("kink at 0.5\nleft slope -1\nright slope -1", xy=(0.5, 0.5),
                       xytext=(0.02, 0.98), textcoords="axes fraction", va="top", fontsize=7,
                       gid=NOTE, bbox={"boxstyle": "round"}, arrowprops={"arrowstyle": "-"})
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    points, radii = pixels_of_data(ax)
    assert covered(boxes(ax, renderer)[0], points, radii) > 0  # (where it was made)
    place_notes(fig)
    fig.canvas.draw()  # (the figure as it is then written)
    assert covered(boxes(ax, renderer)[0], *pixels_of_data(ax)) == 0
    assert note.xy == (0.5, 0.5)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(4, 3), dpi=100)
    grid = np.linspace(0, 1, 60)
    gx, gy = np.meshgrid(grid, grid)
    ax.plot(gx.ravel(), gy.ravel(), ".", ms=2)  # (data all over the axes)
    ax.annotate("a note", xy=(0.5, 0.5), xytext=(0.5, 0.5), textcoords="axes fraction",
                gid=NOTE, bbox={"boxstyle": "round"})
    high = ax.get_ylim()[1]
    place_notes(fig)
    fig.canvas.draw()
    assert ax.get_ylim()[1] > high
    assert covered(boxes(ax, fig.canvas.get_renderer())[0], *pixels_of_data(ax)) == 0
    plt.close(fig)


def test_a_layout_in_which_every_note_found_a_spot_is_final():
    """place_notes draws once when every note fits where the data leaves room: the notes are
    out of the layout, so laying the figure out again, as writing it did, moves no axes."""
    fig, axes = plt.subplots(1, 2, figsize=(6, 3), dpi=100, constrained_layout=True)
    for ax in axes:
        x = np.linspace(0, 1, 101)
        ax.plot(x, x ** 2, ".", ms=2)
        ax.set_title("a title long enough to matter")
        # (made straddling the axes' top edge: in the layout, it would take room there)
        ax.annotate("kink at 0.5\nleft slope 1\nright slope 1", xy=(0.5, 0.25),
                    xytext=(0.03, 1.1), textcoords="axes fraction", va="top", fontsize=7,
                    gid=NOTE, bbox={"boxstyle": "round"}, arrowprops={"arrowstyle": "-"})
    draws = []
    fig.canvas.mpl_connect("draw_event", lambda _event: draws.append(1))
    assert place_notes(fig) is True
    assert len(draws) == 1
    placed = [ax.get_position().bounds for ax in axes]
    fig.canvas.draw()
    assert [ax.get_position().bounds for ax in axes] == placed
    for ax in axes:
        assert covered(boxes(ax, fig.canvas.get_renderer())[0], *pixels_of_data(ax)) == 0
    plt.close(fig)
