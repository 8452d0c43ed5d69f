"""Animations (biped_opt.plots.animate, ``biped-opt animate``): what is drawn is where the
description puts it, force arrows stay off the body, the frames slow down and hold around
contact events as the module says (a 10 ms single stance gets its frames, every impact is held
and ringed in red, also the rocking bar's that leave no mode behind), the axes have a scale in
the system's units, the written GIF has the frames its clock asks for, the side-by-side titles
name the order of contacts and the outcome each run really has, bad input writes nothing."""

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
    ARROW_GAP,
    HOLD_FRAMES,
    MIN_MODE_FRAMES,
    Animation,
    drawn,
    frame_clock,
    frame_times,
    panel,
    side_by_side,
)
from biped_opt.record.scene import ACTIVE_COLOR
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
    (x -+ w cos th, z -+ w sin th) to the feet; an active foot's force arrow, 0.1 per unit of
    lambda along the ground's normal +z, pushes up from below the ground and ends the foot's
    radius and ARROW_GAP under the contact point (the foot's centre); a free foot has none."""
    p = biped.parameters
    w = p["w"]
    rng = np.random.default_rng(5)
    q = rng.uniform(-1, 1, (6, 7))
    q[:, 1] = rng.uniform(0.3, 1, 6)  # (the body above its feet: no other shape round them)
    q[:, 2] = rng.uniform(-0.3, 0.3, 6)
    q[:, [4, 6]] = rng.uniform(-0.2, 0.1, (6, 2))
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
        below = np.where(on, FOOT_RADIUS + ARROW_GAP, 0.0)
        rise = np.where(on, 0.1 * lam[:, i], 0.0)
        end = feet - np.column_stack([0 * below, below])
        np.testing.assert_allclose(d.arrows[:, i, 1], end, rtol=0, atol=EXACT)
        np.testing.assert_allclose(d.arrows[:, i, 0], end - np.column_stack([0 * rise, rise]),
                                   rtol=0, atol=EXACT)


def _inside_body(point: np.ndarray, d, k: int) -> list[str]:
    """The drawn shapes of frame k that hold ``point`` (circles, boxes as convex polygons,
    lines as segments of their width): geometry of its own, not the module's."""
    names = []
    for name, (centre, radius) in d.circles.items():
        if np.hypot(*(point - centre[k])) < radius[k]:
            names.append(name)
    for name, corners in d.boxes.items():
        c = corners[k]
        cross = [(c[j + 1 - 4][0] - c[j][0]) * (point[1] - c[j][1])
                 - (c[j + 1 - 4][1] - c[j][1]) * (point[0] - c[j][0]) for j in range(4)]
        if all(v > 0 for v in cross) or all(v < 0 for v in cross):
            names.append(name)
    for name, (pts, width) in d.lines.items():
        for a, b in zip(pts[k][:-1], pts[k][1:]):
            u = np.clip(np.dot(point - a, b - a) / max(np.dot(b - a, b - a), 1e-300), 0, 1)
            if np.hypot(*(point - a - u * (b - a))) < width[k] / 2:
                names.append(name)
    return names


@pytest.mark.parametrize("maneuver", ["touchdown", "liftoff"])
def test_force_arrows_never_cross_the_body(biped, maneuver):
    """Every frame of the README's biped pairs: each shown arrow, sampled every 1e-3 along
    its length, lies outside every shape drawn (feet, legs, body)."""
    movie = Animation([panel(biped, maneuver, s, fps=20, speed=0.5) for s in (-0.02, 0.02)],
                      fps=20, speed=0.5)
    shown = 0
    for d, _mode in movie._drawn:
        for k in range(movie.frames):
            for c in np.flatnonzero(d.active[k]):
                start, end = d.arrows[k, c]
                length = float(np.hypot(*(end - start)))
                if length < 1e-9:
                    continue
                shown += 1
                for u in np.linspace(0, 1, int(length / 1e-3) + 2):
                    point = start + u * (end - start)
                    assert not _inside_body(point, d, k), (maneuver, k, c, u)
    movie.close()
    assert shown > 50


def test_frames_every_speed_over_fps_until_the_end():
    """A run of 1.23 s at 20 fps, real time: frames at 0, 0.05, ..., 1.25 (26 of them, the
    last past the end shows the end); at speed 0.5, twice as many steps."""
    t = frame_times(1.23, 20, 1.0)
    assert t.size == 26 and t[-1] == pytest.approx(1.25, abs=1e-15)
    np.testing.assert_allclose(np.diff(t), 0.05, rtol=1e-12)
    assert frame_times(1.23, 20, 0.5).size == 51  # ceil(1.23 / 0.025) + 1
    assert frame_times(1.0, 4, 1.0).size == 5  # an end on a frame: no extra one


def test_clock_slows_a_short_mode_and_holds_each_event():
    """Events at 1.0 and 1.003 (a 3 ms mode) at 20 fps, real time: 8 frames strictly inside
    it, 9 equal steps of 3 ms / 9 from the first event to the second; each event held for 5
    frames at its instant; everywhere else the frames of frame_times (every 0.05), the one
    at 1.0 held. Nothing slowed or held: frame_times itself."""
    clock = frame_clock([[1.0, 1.003]], [2.0], 20, 1.0, hold=5, min_frames=8)
    t = clock.times
    inside = (t > 1.0) & (t < 1.003)
    assert inside.sum() == 8
    np.testing.assert_allclose(t[inside], 1.0 + 0.003 / 9 * np.arange(1, 9), rtol=0,
                               atol=1e-15)
    np.testing.assert_allclose(clock.pace[inside], 0.003 / 9 / 0.05, rtol=1e-12)
    for c, at in enumerate((1.0, 1.003)):
        assert np.sum(clock.held == c) == 5 and np.all(t[clock.held == c] == at)
        assert np.all(clock.pace[clock.held == c] == 0)
        assert clock.holds[c] == (at, ((0, c),))
    rest = t[~inside & (clock.held < 0)]
    np.testing.assert_allclose(rest, [v for v in frame_times(2.0, 20, 1.0) if v != 1.0],
                               rtol=0, atol=1e-12)
    assert np.all(np.diff(t) >= 0)
    plain = frame_clock([[1.0, 1.003]], [2.0], 20, 1.0)
    np.testing.assert_array_equal(plain.times, frame_times(2.0, 20, 1.0))
    assert np.all(plain.held == -1) and np.all(plain.pace == 1)


def test_clock_holds_mirrored_events_together():
    """Two panels whose events lie 1e-8 apart (the mirrored runs of a pair) are held once, at
    the later time, for both; 0.01 apart (a fifth of a frame) they are held apart."""
    clock = frame_clock([[1.0], [1.0 + 1e-8]], [2.0, 2.0], 20, 1.0, hold=4)
    assert clock.holds == ((1.0 + 1e-8, ((0, 0), (1, 0))),)
    assert np.sum(clock.held == 0) == 4
    clock = frame_clock([[1.0], [1.01]], [2.0, 2.0], 20, 1.0, hold=4)
    assert [h[0] for h in clock.holds] == [1.0, 1.01]
    assert np.sum(clock.held >= 0) == 8


def test_a_10_ms_single_stance_gets_its_frames(biped):
    """The README's touchdown pair (20 fps, half speed: a frame every 25 ms): each run's single
    stance (10 ms between its two touchdowns) has at least MIN_MODE_FRAMES frames strictly
    inside it, drawn in its single-stance mode, and each touchdown HOLD_FRAMES frames at its
    instant, its title saying so."""
    movie = Animation([panel(biped, "touchdown", s, fps=20, speed=0.5) for s in (-0.02, 0.02)],
                      fps=20, speed=0.5)
    for i, p in enumerate(movie.panels):
        t1, t2 = p.trajectory.event_times
        single = p.trajectory.mode_sequence[1]
        inside = np.flatnonzero((movie.times > t1) & (movie.times < t2))
        assert inside.size >= MIN_MODE_FRAMES
        assert np.all(movie._drawn[i][1][inside] == single)
        for t_e in (t1, t2):
            at = np.flatnonzero(np.abs(movie.times - t_e) < 1e-6)
            assert at.size >= HOLD_FRAMES
            movie.draw(int(at[0]))
            assert "held at" in movie.axes[i].get_title(loc="left")
        movie.draw(int(inside[0]))
        assert "(x0.0" in movie.axes[i].get_title(loc="left")  # (slowed, and saying it)
    movie.close()


def _red_pixels(movie: Animation, k: int, i: int) -> int:
    """Pixels of ROS.md's active contact colour in panel i of frame k as drawn."""
    movie.draw(k)
    movie.figure.canvas.draw()
    rgb = np.asarray(movie.figure.canvas.buffer_rgba())[:, :, :3].astype(int)
    width = rgb.shape[1] // len(movie.panels)
    red = np.round(np.array(ACTIVE_COLOR[:3]) * 255).astype(int)
    part = rgb[:, i * width:(i + 1) * width]
    return int(np.sum(np.all(np.abs(part - red) <= 2, axis=-1)))


def test_rocking_bar_impacts_are_held_and_marked_red(bar):
    """The bar's impacts separate at once (restitution 0.5): no frame is ever in contact. At
    each impact the frames hold its instant for HOLD_FRAMES frames, red is drawn there (the
    point and its ring) and the title names the end that struck; before the first impact, and
    between the held frames, no red at all."""
    movie = Animation([panel(bar, "drop", 0.02, fps=20, speed=0.5)], fps=20, speed=0.5)
    tr = movie.panels[0].trajectory
    assert set(tr.mode_sequence) == {0}
    names = ("left", "right", "left")  # (SYSTEMS.md Sec. 2: small th0 > 0)
    for t_e, end in zip(tr.event_times, names):
        at = np.flatnonzero(movie.times == t_e)
        assert at.size == HOLD_FRAMES and np.all(movie.clock.held[at] >= 0)
        assert _red_pixels(movie, int(at[-1]), 0) > 20
        assert f"held at {end}↓ (impact)" in movie.axes[0].get_title(loc="left")
        after = int(at[-1]) + 1
        assert _red_pixels(movie, after, 0) == 0
    before = int(np.flatnonzero(movie.times < tr.event_times[0])[-1])
    assert _red_pixels(movie, before, 0) == 0
    movie.close()


def test_axes_have_a_scale_and_the_units_the_system_states(biped, bar):
    """Ticks with numbers on both axes, the ground labelled, the units named: gravity units
    for the biped and the bar (MODEL.md Sec. 2, SYSTEMS.md Sec. 2), and the outcome as the
    maneuver declares it with its unit (th in rad, th_dot in rad per time unit)."""
    for compiled, maneuver, s, outcome, unit in (
            (biped, "touchdown", 0.02, "th", "rad"),
            (bar, "drop", 0.02, "th_dot", "rad/time unit")):
        movie = Animation([panel(compiled, maneuver, s, fps=4)], fps=4)
        movie.draw(0)
        ax = movie.axes[0]
        movie.figure.canvas.draw()
        for labels in (ax.get_xticklabels(), ax.get_yticklabels()):
            assert len([t for t in labels if t.get_text()]) >= 3
        assert ax.get_xlabel() == "x, z in length units, t in time units (gravity units, g = 1)"
        assert any(t.get_text().startswith("ground, z = 0") for t in ax.texts)
        tr = movie.panels[0].trajectory
        assert f"{outcome}(t_f) = {tr.outcome:+.4f} {unit}" in ax.get_title(loc="left")
        movie.close()


def test_a_system_that_states_no_units_is_drawn_in_model_units():
    """A ball built here (its looks: a sphere and a contact point) is in model units, and its
    outcome, the height z, has no unit to name."""
    s = System("ball_with_looks", ["x", "z"], parameters={"m": 1.0, "g": 1.0},
               restitution=0.5)
    x, z = s.q
    s.mass_matrix = sp.diag(s.p.m, s.p.m)
    s.forces = lambda J: [0, -s.p.m * s.p.g]
    s.constraint("floor", z, at=(x, 0, z))
    s.frame("ball", x=x, z=z)
    s.sphere("ball", "ball", 0.05)
    s.maneuver("bounce", initial={z: 1, s.dq[0]: s.s}, terminal=s.dq[1], outcome=z,
               armed_after="touchdown", final_mode=())
    movie = Animation([panel(compile_system(s), "bounce", 0.1, fps=4)], fps=4)
    movie.draw(0)
    ax = movie.axes[0]
    assert ax.get_xlabel() == "x, z and t in model units (the system states none)"
    title = ax.get_title(loc="left")
    assert "z(t_f) = " in title and "rad" not in title
    movie.close()


# -- files ---------------------------------------------------------------------------------

def _durations(path) -> list[int]:
    """Each GIF frame's duration [ms] (Pillow writes a run of equal frames, a hold, as one
    frame lasting as long as the run)."""
    with Image.open(path) as im:
        out = []
        for k in range(im.n_frames):
            im.seek(k)
            out.append(im.info["duration"])
    return out


def test_gif_has_the_frames_and_size_asked_for(tmp_path, bar):
    """One run of the bar at 5 fps, real time, nothing held or slowed: ceil(t_f 5) + 1 frames
    of 96 x 64 pixels, each shown 1/5 s; t_f from a simulation of its own. Held and slowed
    (the defaults): the GIF lasts the clock's frames times 1/5 s, each impact's hold one
    frame of HOLD_FRAMES / 5 s."""
    out = tmp_path / "bar.gif"
    movie = Animation([panel(bar, "drop", 0.1, fps=5)], fps=5, size=(96, 64), hold=0,
                      min_frames=0)
    movie.save(out)
    movie.close()
    t_f = bar.simulate("drop", 0.1).t_final
    with Image.open(out) as im:
        assert im.format == "GIF" and im.size == (96, 64)
        assert im.n_frames == math.ceil(t_f * 5) + 1
        assert im.info["duration"] == 200
    assert [p.name for p in tmp_path.iterdir()] == ["bar.gif"]  # (no partial file left)
    movie = Animation([panel(bar, "drop", 0.1, fps=5)], fps=5, size=(96, 64))
    movie.save(out)
    movie.close()
    durations = _durations(out)
    assert sum(durations) == 200 * movie.frames
    impacts = len(bar.simulate("drop", 0.1).event_times)
    assert durations.count(200 * HOLD_FRAMES) == impacts


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
        assert f"th(t_f) = {tr.outcome:+.4f} rad" in line
    assert firsts[0] != firsts[1]
    assert outcomes[0] * outcomes[1] < 0
    frames = int(printed[2].split(": ")[1].split()[0])
    assert frames > math.ceil(max(t_f) * 4) + 1  # (the holds and the slowed stance)
    with Image.open(out) as im:
        assert im.size == (192, 64)
    assert sum(_durations(out)) == 250 * frames


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
        assert f"th(t_f) = {tr.outcome:+.4f} rad" in title
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
