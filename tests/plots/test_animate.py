"""Animations (biped_opt.plots.animate, ``biped-opt animate``): what is drawn is where the
description puts it, the written GIF has the frames its duration, rate and speed ask for, the
side-by-side titles name the order of contacts each run really has, bad input writes nothing."""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp
from matplotlib import animation
from PIL import Image

from biped_opt.cli.main import main
from biped_opt.errors import InvalidInputError
from biped_opt.paper.biped import FIXED_INPUTS
from biped_opt.plots.animate import (
    Animation,
    drawn,
    frame_times,
    panel,
    side_by_side,
)
from biped_opt.simulation.compiled import CompiledSystem, compile_system
from biped_opt.systems.description import System
from biped_opt.systems.library.walker import FOOT_RADIUS, LEG_WIDTH

# (exact geometry: the drawn coordinates are a few products and sums of the evaluated scene,
# so they agree with the closed forms to a few ulps of numbers of order 1)
EXACT = 1e-12


@pytest.fixture(scope="module")
def bar() -> CompiledSystem:
    return CompiledSystem("rocking_bar")


@pytest.fixture(scope="module")
def biped() -> CompiledSystem:
    return CompiledSystem("biped")


def _names(mask: int, constraints: tuple[str, ...]) -> list[str]:
    return [c for j, c in enumerate(constraints) if mask >> j & 1]


# -- geometry ------------------------------------------------------------------------------

def test_rocking_bar_rectangle_is_the_closed_form(bar):
    """The bar (half-length w, thickness h = 0.04 as the library declares its box) at (x, z, th):
    its short edges' midpoints are (x -+ w cos th, z -+ w sin th), its corners those -+ h/2
    along the bar's normal (-sin th, cos th); its ends are the contact points."""
    w, h = bar.parameters["w"], 0.04
    rng = np.random.default_rng(3)
    q = np.column_stack([rng.uniform(-1, 1, 9), rng.uniform(0, 2, 9),
                         np.r_[rng.uniform(-3, 3, 7), 0.0, math.pi / 2]])
    state = bar.scene.evaluate(q, list(bar.parameters.values()))
    d = drawn(bar.scene, state, np.zeros(len(q), dtype=int), np.zeros((len(q), 2)))
    x, z, th = q.T
    c, s = np.cos(th), np.sin(th)
    expected = np.stack([
        np.column_stack([x - w * c + h / 2 * s, z - w * s - h / 2 * c]),
        np.column_stack([x + w * c + h / 2 * s, z + w * s - h / 2 * c]),
        np.column_stack([x + w * c - h / 2 * s, z + w * s + h / 2 * c]),
        np.column_stack([x - w * c - h / 2 * s, z - w * s + h / 2 * c])], axis=1)
    np.testing.assert_allclose(d.boxes["bar"], expected, rtol=0, atol=EXACT)
    ends = np.stack([np.column_stack([x - w * c, z - w * s]),
                     np.column_stack([x + w * c, z + w * s])], axis=1)
    np.testing.assert_allclose(0.5 * (d.boxes["bar"][:, [0, 1]] + d.boxes["bar"][:, [3, 2]]),
                               ends, rtol=0, atol=EXACT)
    np.testing.assert_allclose(d.contacts, ends, rtol=0, atol=EXACT)
    # free constraints: grey points, no arrows (start = end)
    assert not d.active.any()
    np.testing.assert_array_equal(d.arrows[:, :, 0], d.arrows[:, :, 1])


def test_biped_feet_legs_and_force_arrows(biped):
    """Feet are circles of the declared radius at (x_i, z_i); legs run from the hips
    (x -+ w cos th, z -+ w sin th) to the feet; an active foot's force arrow rises from the foot
    by 0.1 m per unit of lambda (the ground's normal is +z), a free foot has none."""
    p = biped.parameters
    w = p["w"]
    rng = np.random.default_rng(5)
    q = rng.uniform(-1, 1, (6, 7))
    mode = np.array([0, 1, 2, 3, 3, 1])
    lam = rng.uniform(0, 5, (6, 2))
    d = drawn(biped.scene, biped.scene.evaluate(q, list(p.values())), mode, lam)
    x, z, th = q[:, 0], q[:, 1], q[:, 2]
    for i, (foot, sign) in enumerate((("left", -1), ("right", 1))):
        feet = q[:, [3 + 2 * i, 4 + 2 * i]]
        centre, radius = d.circles[f"{foot}_foot"]
        np.testing.assert_allclose(centre, feet, rtol=0, atol=EXACT)
        np.testing.assert_allclose(radius, FOOT_RADIUS, rtol=0, atol=EXACT)
        hips = np.column_stack([x + sign * w * np.cos(th), z + sign * w * np.sin(th)])
        points, width = d.lines[f"{foot}_leg"]
        np.testing.assert_allclose(points, np.stack([hips, feet], axis=1), rtol=0, atol=EXACT)
        np.testing.assert_allclose(width, LEG_WIDTH, rtol=0, atol=EXACT)
        on = (mode >> i) & 1 == 1
        np.testing.assert_array_equal(d.active[:, i], on)
        rise = np.where(on, 0.1 * lam[:, i], 0.0)
        np.testing.assert_allclose(d.arrows[:, i, 0], feet, rtol=0, atol=EXACT)
        np.testing.assert_allclose(d.arrows[:, i, 1], feet + np.column_stack([0 * rise, rise]),
                                   rtol=0, atol=EXACT)


def test_frames_every_speed_over_fps_until_the_end():
    """A run of 1.23 s at 20 fps, real time: frames at 0, 0.05, ..., 1.25 (26 of them, the
    last past the end shows the end); at speed 0.5, twice as many steps."""
    t = frame_times(1.23, 20, 1.0)
    assert t.size == 26 and t[-1] == pytest.approx(1.25, abs=1e-15)
    np.testing.assert_allclose(np.diff(t), 0.05, rtol=1e-12)
    assert frame_times(1.23, 20, 0.5).size == 51  # ceil(1.23 / 0.025) + 1
    assert frame_times(1.0, 4, 1.0).size == 5  # an end on a frame: no extra one


# -- files ---------------------------------------------------------------------------------

def test_gif_has_the_frames_and_size_asked_for(tmp_path, bar):
    """One run of the bar at 5 fps, real time: ceil(t_f 5) + 1 frames of 96 x 64 pixels, each
    shown 1/5 s; t_f from a simulation of its own."""
    out = tmp_path / "bar.gif"
    movie = Animation([panel(bar, "drop", 0.1, fps=5)], fps=5, size=(96, 64))
    movie.save(out)
    movie.close()
    t_f = bar.simulate("drop", 0.1).t_final
    with Image.open(out) as im:
        assert im.format == "GIF" and im.size == (96, 64)
        assert im.n_frames == math.ceil(t_f * 5) + 1
        assert im.info["duration"] == 200
    assert [p.name for p in tmp_path.iterdir()] == ["bar.gif"]  # (no partial file left)


def test_side_by_side_names_each_runs_order_of_contacts(tmp_path, biped, capsys):
    """The biped's touchdown at th0 = -0.02 and +0.02 through the command line: a GIF of two
    panels whose titles name the order of touchdown and the outcome each run has, computed
    here from the mode sequences of runs of our own: the orders differ (one foot first on
    one side, the other on the other) and so do the outcomes' signs."""
    out = tmp_path / "pair.gif"
    assert main(["animate", "--system", "biped", "--maneuver", "touchdown", "--side-by-side",
                 "--delta", "0.02", "--fps", "4", "--width", "96", "--height", "64",
                 "-o", str(out)]) == 0
    printed = capsys.readouterr().out.splitlines()
    firsts, outcomes, t_f = [], [], []
    for s, line in zip((-0.02, 0.02), printed):
        tr = biped.simulate("touchdown", s, FIXED_INPUTS["touchdown"])
        modes = tr.mode_sequence
        order = [_names(after & ~before, tr.constraints)
                 for before, after in zip(modes, modes[1:])]
        assert all(len(o) == 1 for o in order)  # (one foot at a time, off s = 0)
        firsts.append(order[0][0])
        outcomes.append(tr.outcome)
        t_f.append(tr.t_final)
        assert f"s = {s:+.4g}" in line
        assert "contacts: " + " ".join(f"{o[0]}↓" for o in order) in line
        assert f"outcome {tr.outcome:+.4f}" in line
    assert firsts[0] != firsts[1]
    assert outcomes[0] * outcomes[1] < 0
    with Image.open(out) as im:
        assert im.size == (192, 64)
        assert im.n_frames == math.ceil(max(t_f) * 4) + 1


def test_side_by_side_panel_titles_at_liftoff(biped):
    """The drawn titles themselves (not only what is printed): at liftoff the feet leave in
    opposite orders on the two sides of th0 = 0, each title says which left first, and the
    last frame says each run's end."""
    movie = Animation([panel(biped, "liftoff", s, fps=4) for s in (-0.02, 0.02)], fps=4,
                      size=(96, 64))
    movie.draw(movie.frames - 1)
    titles = [ax.get_title(loc="left") for ax in movie.axes]
    movie.close()
    firsts = []
    for s, title in zip((-0.02, 0.02), titles):
        tr = biped.simulate("liftoff", s, FIXED_INPUTS["liftoff"])
        modes = tr.mode_sequence
        order = [_names(before & ~after, tr.constraints)
                 for before, after in zip(modes, modes[1:])]
        firsts.append(order[0][0])
        assert "contacts: " + " ".join(f"{o[0]}↑" for o in order) in title
        assert f"outcome {tr.outcome:+.4f}" in title
    assert firsts[0] != firsts[1]
    assert all("(end)" in t and "mode {air}" in t for t in titles)


# -- bad input -----------------------------------------------------------------------------

def _status(argv: list[str]) -> int:
    """The exit status of ``biped-opt ARGV``: what main returns, or argparse's exit (an
    argument refused while the command line is parsed)."""
    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)


@pytest.mark.parametrize("argv, message", [
    (["--maneuver", "touchdown", "--s", "nan"], "--s must be finite"),
    (["--maneuver", "jump"], "unknown maneuver 'jump'"),
    (["--system", "no_such_system", "--maneuver", "drop"], "unknown system"),
    (["--maneuver", "touchdown", "--delta", "0.1"], "--delta: only with --side-by-side"),
    (["--maneuver", "touchdown", "--side-by-side", "--delta", "inf"], "--delta must be"),
    (["--maneuver", "touchdown", "--input", "u9=1"], "no input 'u9'"),
    (["--maneuver", "touchdown", "--fps", "0"], "--fps must be between 1 and"),
    (["--maneuver", "touchdown", "--width", "97"], "--width must be even"),
    (["--maneuver", "touchdown", "--speed", "-1"], "--speed must be positive"),
])
def test_bad_arguments_are_one_line_and_write_nothing(tmp_path, capsys, argv, message):
    assert _status(["animate", *argv, "-o", str(tmp_path / "x.gif")]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name, message", [
    ("x.png", "unknown animation format '.png'"),
    ("x", "unknown animation format '(no suffix)'"),
    ("x.mp4", ".mp4 needs ffmpeg"),
])
def test_bad_output_formats_are_refused_before_any_work(tmp_path, capsys, monkeypatch, name,
                                                        message):
    # (no ffmpeg: as on this machine; forced, so the test means the same where one exists)
    real = animation.writers.is_available
    monkeypatch.setattr(animation.writers, "is_available",
                        lambda writer: writer != "ffmpeg" and real(writer))
    assert _status(["animate", "--maneuver", "touchdown", "-o", str(tmp_path / name)]) == 2
    err = capsys.readouterr().err
    assert f"--output: {tmp_path / name}: {message}" in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_library_checks_its_arguments_before_writing(tmp_path, bar):
    for kwargs, message in (({"delta": float("nan")}, "delta must be"),
                            ({"s0": float("inf")}, "s0 must be a finite number"),
                            ({"fps": 2.5}, "fps must be an integer"),
                            ({"speed": 0.0}, "speed must be")):
        with pytest.raises(InvalidInputError, match=message):
            side_by_side(bar, "drop", tmp_path / "x.gif", **kwargs)
    with pytest.raises(InvalidInputError, match="unknown maneuver"):
        side_by_side(bar, "fall", tmp_path / "x.gif")
    assert list(tmp_path.iterdir()) == []


def test_a_system_without_looks_is_a_clear_error(tmp_path):
    """A bouncing point mass that declares no frame, shape or contact point."""
    s = System("plain_ball", ["x", "z"], parameters={"m": 1.0, "g": 1.0})
    x, z = s.q
    s.mass_matrix = sp.diag(s.p.m, s.p.m)
    s.forces = lambda J: [0, -s.p.m * s.p.g]
    s.constraint("floor", z)
    s.maneuver("bounce", initial={z: 1, s.dq[0]: s.s}, terminal=s.dq[1], outcome=z,
               armed_after="touchdown", final_mode=())
    ball = compile_system(s)
    with pytest.raises(InvalidInputError, match="plain_ball: the system declares no looks"):
        side_by_side(ball, "bounce", tmp_path / "x.gif")
    assert list(tmp_path.iterdir()) == []
