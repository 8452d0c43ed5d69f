"""Figures for any system: PNG files of the stated size, mode bands, and the control experiment's
numbers against SYSTEMS.md Secs. 2-3 (MODEL.md Sec. 6 for the coupled walker, which is the biped).
"""

from __future__ import annotations

import struct

import matplotlib.pyplot as plt
import numpy as np
import pytest

from biped_opt.errors import InvalidInputError
from biped_opt.plots.systems import (
    Mark,
    _panel,
    control_experiment_data,
    control_experiment_figure,
    grid_one_sided,
    mode_bands,
    modes_figure,
    outcome_figure,
    policy_value_figure,
)
from biped_opt.simulation.compiled import CompiledSystem

DPI = 150  # what every figure is saved at


def png_size(path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def check_png(path, figsize: tuple[float, float]) -> None:
    assert png_size(path) == (round(figsize[0] * DPI), round(figsize[1] * DPI))
    assert path.stat().st_size > 15_000  # something drawn, not a blank canvas (~5 kB)


@pytest.fixture(scope="module")
def experiment():
    return control_experiment_data()


@pytest.fixture(scope="module")
def walker():
    return CompiledSystem("walker2_coupled")


# --- the drawing functions --------------------------------------------------------------------
def test_outcome_figure_writes_png_of_its_size(tmp_path):
    s = np.linspace(-1.0, 1.0, 201)
    points = [{"s": 0.0, "kind": "kink", "series": "|s|", "cause": "order flips"},
              Mark(s=0.5, kind="jump", series="step", limits=(0.0, 1.0))]
    path = outcome_figure(tmp_path / "a" / "outcome.png", s,
                          {"|s|": np.abs(s), "step": (s > 0.5).astype(float)}, points=points,
                          ylabel="cost", title="test", figsize=(6.0, 4.0))
    check_png(path, (6.0, 4.0))


def test_policy_value_figure_writes_png_of_its_size(tmp_path):
    s = np.linspace(-1.0, 1.0, 101)
    points = [{"theta0": 0.0, "kind": "u2: jump", "input": "u2", "quantity": "policy",
               "left": -1.0, "right": 1.0},
              {"s": 0.0, "kind": "kink", "quantity": "value", "at": 0.0}]
    path = policy_value_figure(tmp_path / "pv.png", s,
                               {"u1": np.maximum(s, 0.0), "u2": np.sign(s)}, np.abs(s),
                               points=points)
    check_png(path, (8.0, 7.0))


def test_modes_figure_writes_png_of_its_size(tmp_path, walker):
    path = modes_figure(tmp_path / "modes.png", walker, "touchdown",
                        np.linspace(-0.1, 0.1, 21), (2.0, 0.5, 0.0), figsize=(7.0, 4.0))
    check_png(path, (7.0, 4.0))


def test_control_experiment_figure_writes_png_of_its_size(tmp_path, experiment):
    check_png(control_experiment_figure(tmp_path / "ce.png", experiment), (15.0, 5.0))


def test_control_experiment_labels_cross_no_curve(tmp_path, experiment, monkeypatch):
    """Every text of every panel (the causes of the points, the jump list of (c)) as drawn:
    its box, measured with the renderer, meets no curve's path (each segment sampled at one
    pixel) and no marker. Written along the point's line, the causes crossed the curves."""
    import biped_opt.plots.systems as systems

    kept = []
    finish = systems._finish

    def keep(fig, path):
        kept.append(fig)
        return finish(fig, path)

    monkeypatch.setattr(systems, "_finish", keep)
    control_experiment_figure(tmp_path / "ce.png", experiment)
    (fig,) = kept
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    texts = 0
    for ax in fig.axes[:3]:
        points = []
        for line in ax.lines:
            if line.get_transform() != ax.transData:  # (the faint lines at the points' s)
                continue
            xy = ax.transData.transform(np.asarray(line.get_xydata(), dtype=float))
            points.append(xy)
            for a, b in zip(xy[:-1], xy[1:]):
                n = int(np.ceil(np.hypot(*(b - a)))) + 1
                points.append(a + np.linspace(0, 1, n)[:, None] * (b - a))
        pts = np.vstack(points)
        for text in ax.texts:
            patch = text.get_bbox_patch()
            box = (patch if patch is not None else text).get_window_extent(renderer)
            hit = ((pts[:, 0] >= box.x0) & (pts[:, 0] <= box.x1)
                   & (pts[:, 1] >= box.y0) & (pts[:, 1] <= box.y1))
            assert not hit.any(), (ax.get_title(), text.get_text())
            texts += 1
    assert texts == 3  # (the causes of (a) and (b), the jumps of (c))
    plt.close(fig)


def test_bad_data_is_one_clear_error(tmp_path):
    s = np.linspace(0.0, 1.0, 5)
    with pytest.raises(InvalidInputError, match=r"series 'y' has shape \(4,\), s has \(5,\)"):
        outcome_figure(tmp_path / "x.png", s, {"y": np.zeros(4)})
    with pytest.raises(InvalidInputError, match="s must be strictly increasing"):
        outcome_figure(tmp_path / "x.png", s[::-1], {"y": s})
    with pytest.raises(InvalidInputError, match="a point needs 's'"):
        outcome_figure(tmp_path / "x.png", s, {"y": s}, points=[{"kind": "jump"}])
    with pytest.raises(InvalidInputError, match="num must be an integer >= 5"):
        control_experiment_data(num=3)


def test_a_jump_is_never_bridged_by_a_line():
    """Every drawn line lies on one side of the jump; the value at the jump itself is a dot."""
    s = np.linspace(-1.0, 1.0, 21)
    y = np.where(s < 0, -1.0, 1.0)
    y[10] = 0.0  # s = 0: the simultaneous event's own value
    fig, ax = plt.subplots()
    _panel(ax, s, {"y": y}, [Mark(s=0.0, kind="jump", limits=(-1.0, 1.0))])
    lines = [ln for ln in ax.lines if ln.get_linestyle() == "-"]
    assert len(lines) == 2
    for ln in lines:
        x = np.asarray(ln.get_xdata())
        assert np.all(x < 0) or np.all(x > 0)
    dots = [ln for ln in ax.lines if ln.get_marker() == "o" and ln.get_linestyle() == "None"
            and list(ln.get_xdata()) == [0.0] and list(ln.get_ydata()) == [0.0]]
    assert len(dots) == 1
    plt.close(fig)


# --- mode bands -------------------------------------------------------------------------------
def test_mode_bands_walker_order_flips_at_zero(walker):
    """Tilted right (th0 > 0) foot1 lands first, tilted left foot2, level both at once."""
    right, level, left = mode_bands(walker, "touchdown", [0.01, 0.0, -0.01], (2.0, 0.5, 0.0))
    assert right.modes == (0, 0b01, 0b11) and left.modes == (0, 0b10, 0b11)
    assert level.modes == (0, 0b11) and level.switched == (0b11,)
    for b in (right, level, left):
        assert b.status == "OK"
        assert b.starts[0] == 0.0 and b.starts[1:] == b.ends[:-1] == b.events
    # the bands are the trajectory's own event times
    tr = walker.simulate("touchdown", 0.01, (2.0, 0.5, 0.0))
    assert right.ends == (*tr.event_times, tr.t_final)


def test_mode_bands_rocking_bar_impacts_without_mode_change():
    """Restitution 0.5: every impact separates at once, so one air band holds all the impacts
    (SYSTEMS.md Sec. 2: left, right, left for small th0 > 0; left, right at th0 = 0.2; one
    simultaneous impact at 0, ending at t_f = 1.5 sqrt(2))."""
    bar = CompiledSystem("rocking_bar")
    small, mid, level = mode_bands(bar, "drop", [0.05, 0.2, 0.0])
    assert small.modes == mid.modes == level.modes == (0,)
    assert small.switched == (0b01, 0b10, 0b01) and mid.switched == (0b01, 0b10)
    assert level.switched == (0b11,)
    assert level.ends[0] == pytest.approx(1.5 * np.sqrt(2.0), abs=1e-9)  # event-located t_f


# --- the control experiment's numbers ---------------------------------------------------------
def test_grid_holds_zero_and_is_symmetric(experiment):
    assert 0.0 in experiment.s and 0.0 in experiment.bar_s
    # symmetric up to linspace's rounding (1 ulp of 0.02 ~ 3.5e-18)
    np.testing.assert_allclose(experiment.s, -experiment.s[::-1], rtol=0, atol=1e-17)


def sides(experiment, maneuver, law):
    y = getattr(experiment, maneuver)[law]
    return (grid_one_sided(experiment.s, y, 0.0, -1), grid_one_sided(experiment.s, y, 0.0, 1),
            float(y[experiment.s == 0.0][0]))


# The slopes below come from the plotted grid alone (spacing 5e-5, a five-point ladder up to
# 8e-4 extrapolated to 0): measured within 2e-9 of the references, whose own two sides differ by
# 2e-10 for the decoupled walker; 1e-8 leaves room for the integrator's 1e-12 noise amplified by
# the extrapolation and still tells 0.8304 from 0.7962 by seven orders of magnitude.
SLOPE_TOL = 1e-8


def test_decoupled_outcomes_are_c1_with_systems_md_slopes(experiment):
    left, right, at = sides(experiment, "touchdown", "decoupled")
    assert left.derivative == pytest.approx(0.8304310463, abs=SLOPE_TOL)
    assert right.derivative == pytest.approx(0.8304310461, abs=SLOPE_TOL)
    assert at == pytest.approx(-0.0127708483, abs=1e-10)  # SYSTEMS.md gives 10 decimals
    left, right, at = sides(experiment, "liftoff", "decoupled")
    assert left.derivative == pytest.approx(0.4926096190, abs=SLOPE_TOL)
    assert right.derivative == pytest.approx(0.4926096191, abs=SLOPE_TOL)
    assert at == pytest.approx(0.0491117591, abs=1e-10)
    # continuous: both one-sided limits are the value at 0 (to the extrapolation's 1e-11)
    assert abs(left.limit - at) < 1e-10 and abs(right.limit - at) < 1e-10


def test_coupled_touchdown_kinks_with_the_bipeds_slopes(experiment):
    left, right, at = sides(experiment, "touchdown", "coupled")
    assert left.derivative == pytest.approx(0.7962438835, abs=SLOPE_TOL)  # MODEL.md Sec. 6
    assert right.derivative == pytest.approx(0.7143664519, abs=SLOPE_TOL)
    assert abs(left.limit - at) < 1e-10 and abs(right.limit - at) < 1e-10  # continuous


def test_coupled_liftoff_jumps_decoupled_does_not(experiment):
    left, right, at = sides(experiment, "liftoff", "coupled")
    # MODEL.md Sec. 6 limits, 9 decimals; the simultaneous liftoff itself is symmetric: 0
    assert left.limit == pytest.approx(0.026283950, abs=1e-9)
    assert right.limit == pytest.approx(-0.006532702, abs=1e-9)
    assert abs(at) < 1e-12
    # the grid shows the jump: neighbours of 0 differ by ~0.033, 1000 times the decoupled step
    y = experiment.liftoff["coupled"]
    k = int(np.flatnonzero(experiment.s == 0.0)[0])
    assert y[k - 1] - y[k + 1] > 0.03
    smooth = experiment.liftoff["decoupled"]
    assert abs(smooth[k - 1] - smooth[k + 1]) < 1e-4  # 2 x 5e-5 x slope 0.49


def test_marks_name_only_the_coupled_law(experiment):
    kinds = {(m.series, m.kind, m.s) for m in experiment.touchdown_marks}
    assert kinds == {("coupled", "kink", 0.0)}
    kinds = {(m.series, m.kind, m.s) for m in experiment.liftoff_marks}
    assert kinds == {("coupled", "jump", 0.0)}


def test_rocking_bar_jumps_where_systems_md_says(experiment):
    """Five jumps, located by bisection to 1e-10 (SYSTEMS.md gives 7 digits: 1e-7)."""
    marks = experiment.bar_marks
    assert [m.kind for m in marks] == ["jump"] * 5
    expected = [-0.2646950, -0.0961485, 0.0, 0.0961485, 0.2646950]
    np.testing.assert_allclose([m.s for m in marks], expected, atol=1e-7)
    (zero,) = [m for m in marks if m.s == 0.0]
    # left, right limits at 0: +0.1988738 | -0.1988738 (7 decimals), 0 exactly at 0
    assert zero.limits == pytest.approx((0.1988738, -0.1988738), abs=1e-7)
    assert experiment.bar[experiment.bar_s == 0.0][0] == 0.0
    at_02 = experiment.bar[np.argmin(np.abs(experiment.bar_s - 0.2))]
    assert abs(experiment.bar_s[np.argmin(np.abs(experiment.bar_s - 0.2))] - 0.2) < 1e-12
    assert at_02 == pytest.approx(2.42070065442, abs=1e-10)  # SYSTEMS.md, 11 decimals
