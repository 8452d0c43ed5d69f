"""The matplotlib picture of the Foxglove layout: a PNG of the expected size, drawn from the
recording (the active contact point's red is there exactly when the instant shown has a foot
down), panels tiling the figure as the layout's mosaic says, bad input refused in one line."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from biped_opt.errors import BipedOptError
from biped_opt.paper.biped import simulate
from biped_opt.plots.layout_preview import (
    DPI,
    FIGSIZE,
    LayoutError,
    draw_layout,
    main,
    message_path,
    mosaic,
)
from biped_opt.record import SweepWriter
from tests.record.test_scene_conventions import record_biped_sweep

LAYOUT = Path(__file__).resolve().parents[2] / "config" / "foxglove_layout.json"
#: ROS.md Sec. 6's active contact point colour (0.85, 0.1, 0.1) as 8-bit RGB: the inside of a
#: drawn point has exactly this colour (an edge pixel is blended, but a disc has an inside)
RED = np.array([217, 26, 26])


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> tuple[Path, dict[float, object]]:
    path = tmp_path_factory.mktemp("preview") / "sweep.mcap"
    return path, record_biped_sweep(path, lo=-0.1, hi=0.1, num=5, dt=0.05)


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def _red_pixels(path: Path) -> int:
    rgb = np.round(imread(path)[:, :, :3] * 255).astype(int)
    return int(np.sum(np.all(np.abs(rgb - RED) <= 1, axis=-1)))


def test_the_preview_is_a_png_of_the_expected_size(recording, tmp_path):
    path, trs = recording
    out = draw_layout(path, tmp_path / "preview.png", layout=LAYOUT)
    assert out == tmp_path / "preview.png"
    assert _png_size(out) == (round(FIGSIZE[0] * DPI), round(FIGSIZE[1] * DPI))
    image = imread(out)[:, :, :3]
    # not blank: the panels draw many colours (bands, curves, the robot)
    assert len(np.unique(np.round(image * 255).astype(int).reshape(-1, 3), axis=0)) > 50
    # the default instant has one foot down: an active (red) contact point is drawn
    assert _red_pixels(out) > 20


def test_the_instant_shown_is_the_one_asked_for(recording, tmp_path):
    """At the start of a run both feet are in the air (no red point); at its end both are
    down (two red points: about twice the red of one)."""
    path, trs = recording
    th = min(trs, key=lambda v: abs(v - 0.05))  # (a sweep point with an event order)
    air = draw_layout(path, tmp_path / "air.png", layout=LAYOUT, at=(th, 0.0))
    assert _red_pixels(air) == 0
    one = draw_layout(path, tmp_path / "one.png", layout=LAYOUT)
    both = draw_layout(path, tmp_path / "both.png", layout=LAYOUT,
                          at=(th, trs[th].t_final))
    assert 1.5 < _red_pixels(both) / _red_pixels(one) < 2.5


def test_axes_are_labelled_in_the_models_units(recording, tmp_path, monkeypatch):
    """The biped is in gravity units (MODEL.md Sec. 2): the robot's axes say length units,
    the time axes time units; no axis says metres or seconds."""
    from matplotlib.figure import Figure

    saved = []
    savefig = Figure.savefig

    def keep(fig, *args, **kwargs):
        saved.append(fig)
        return savefig(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    path, _trs = recording
    draw_layout(path, tmp_path / "preview.png", layout=LAYOUT)
    (fig,) = saved
    labels = [label for ax in fig.axes for label in (ax.get_xlabel(), ax.get_ylabel())]
    assert "x [length units] (world; gravity units, g = 1)" in labels
    assert "z [length units]" in labels
    assert "time since the recording's start [time units]" in labels
    assert not [label for label in labels if "[m]" in label or "[s]" in label
                or label.endswith(" s") or " s," in label]
    titles = [ax.get_title() for ax in fig.axes]
    assert any("time units of the recording)" in t for t in titles)


def test_a_recording_without_the_scene_still_draws(tmp_path):
    """A recording of states only (older files): the panels whose topics it lacks say so, the
    state plots are drawn, no red contact point."""
    path = tmp_path / "states.mcap"
    with SweepWriter(path) as w:
        tr = simulate("touchdown", 0.1, (2.0, 0.5, 0.0), sample_dt=0.05)
        w.write_states(maneuver="touchdown", theta0=0.1, samples=tr.samples, stamp_offset_ns=0)
    out = draw_layout(path, tmp_path / "states.png", layout=LAYOUT)
    assert _png_size(out) == (round(FIGSIZE[0] * DPI), round(FIGSIZE[1] * DPI))
    assert _red_pixels(out) == 0


def test_the_panels_tile_the_figure_as_the_mosaic_says():
    spec = json.loads(LAYOUT.read_text())
    rects = mosaic(spec["layout"])
    assert sorted(rects) == sorted(spec["configById"])
    # the areas add up to the whole and no two rectangles overlap
    assert sum(w * h for _x, _y, w, h in rects.values()) == pytest.approx(1.0, abs=1e-12)
    boxes = list(rects.values())
    for i, (x0, y0, w0, h0) in enumerate(boxes):
        for x1, y1, w1, h1 in boxes[i + 1:]:
            overlap = max(0.0, min(x0 + w0, x1 + w1) - max(x0, x1)) * \
                max(0.0, min(y0 + h0, y1 + h1) - max(y0, y1))
            assert overlap < 1e-12
    # the 3D panel takes the left 45 %, whole height (the layout's first split)
    assert rects["3D!robot"] == pytest.approx((0.0, 0.0, 0.45, 1.0))


def test_message_paths_parse_as_foxglove_writes_them():
    assert message_path("/biped/state.q[2]") == ("/biped/state", [("q", 2)])
    assert message_path("/biped/sweep.header.stamp.sec") == \
        ("/biped/sweep", [("header", None), ("stamp", None), ("sec", None)])
    for bad in ("/biped/state", "biped.q", "/biped/state.q[", "/biped/state.q[x]"):
        with pytest.raises(LayoutError):
            message_path(bad)


def test_bad_input_is_refused_in_one_line(recording, tmp_path, capsys):
    path, _trs = recording
    not_layout = tmp_path / "x.json"
    not_layout.write_text("[1, 2]")
    with pytest.raises(LayoutError) as err:
        draw_layout(path, tmp_path / "x.png", layout=not_layout)
    assert "not a Foxglove layout" in str(err.value) and "\n" not in str(err.value)
    # a path to a field the message does not have: which panel, in one line
    spec = json.loads(LAYOUT.read_text())
    spec["configById"]["Plot!body"]["paths"][0]["value"] = "/biped/state.qq[2]"
    bad_path = tmp_path / "bad_path.json"
    bad_path.write_text(json.dumps(spec))
    with pytest.raises(LayoutError, match=r"panel 'Plot!body': cannot draw it") as err:
        draw_layout(path, tmp_path / "x.png", layout=bad_path)
    assert "qq" in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(BipedOptError):
        draw_layout(tmp_path / "missing.mcap", tmp_path / "x.png", layout=LAYOUT)
    assert not (tmp_path / "x.png").exists()
    with pytest.raises(SystemExit) as ex:
        main([str(tmp_path / "missing.mcap"), str(tmp_path / "y.png"), "--layout",
              str(LAYOUT)])
    assert ex.value.code == 2
    err_text = capsys.readouterr().err
    assert err_text.startswith("error: ") and err_text.count("\n") == 1
    assert main([str(path), str(tmp_path / "z.png"), "--layout", str(LAYOUT)]) == 0
    assert capsys.readouterr().out.strip() == str(tmp_path / "z.png")
