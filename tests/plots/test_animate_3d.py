"""The 3-D view of animations (biped_opt.plots.animate, ``biped-opt animate --view``): solo12's
drop (a library robot from its URDF, compiled once per session) is drawn in 3-D by default, its
contact points where Pinocchio (an independent implementation of the URDF's kinematics) puts
the feet at the frames' configurations, red while in contact, the force segments ending at the
feet, and the pictures change from frame to frame; a planar scene keeps the x-z view."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.colors import to_rgba_array

from biped_opt.plots.animate import Animation, panel, planar, rotation_matrices
from biped_opt.record.scene import ACTIVE_COLOR, FREE_COLOR
from biped_opt.simulation.compiled import compiled_with
from biped_opt.simulation.scene import SceneState, quaternions

#: the drawn contact points are the evaluated scene's, copied; the scene's kinematics and
#: Pinocchio's agree to a few ulps of numbers of order 1
EXACT = 1e-12


@pytest.fixture(scope="module")
def solo():
    return compiled_with("solo12")


def _q_at(trajectory, t):
    """The configuration at t, interpolated linearly between the run's samples (the
    animation's rule, restated: an event's pre-reset row dropped)."""
    rows = trajectory.samples
    keep = np.ones(rows.shape[0], dtype=bool)
    keep[:-1] = rows[:-1, 0] != rows[1:, 0]
    rows = rows[keep]
    d = len(trajectory.y_final) // 2
    return np.array([np.interp(t, rows[:, 0], rows[:, 1 + i]) for i in range(d)])


def test_solo12_is_drawn_in_3d_where_pinocchio_puts_its_feet(solo):
    pytest.importorskip("pinocchio", reason="Pinocchio (pin in requirements-dev.txt) is the "
                                            "independent reference of the feet's positions")
    from biped_opt.systems.library.robots import ROBOT_FILES
    from tests.systems import urdf_checks as checks

    feet = [(f"{leg}_FOOT", (0.0, 0.0, 0.0), 0.0) for leg in ("FL", "FR", "HL", "HR")]
    reference = checks.reference_for(solo.system, ROBOT_FILES["solo12"], feet)
    run = panel(solo, "drop", 0.05, fps=30)
    movie = Animation([run], fps=30)
    try:
        assert movie.view == "3d"  # (its legs stand side by side: no one x-z plane)
        assert movie.axes[0].name == "3d"
        art = movie._artists[0]
        pictures = []
        frames = [0, int(np.argmax(movie.clock.held >= 0)), movie.frames - 1]
        for k in frames:
            movie.draw(k)
            q = _q_at(run.trajectory, movie.times[k])
            y = np.concatenate([q, np.zeros_like(q)])
            drawn_points = np.stack(art["contacts"]._offsets3d, axis=1)
            assert np.abs(drawn_points - reference.points(y)).max() < EXACT
            # red where the frame's mode (or a held impact) has the foot, grey elsewhere
            _d, mode = movie._drawn[0]
            entered = movie._flashes[0].get(int(movie.clock.held[k]), ([], [], ""))[0]
            # (the colours as set: a 3-D scatter's get_facecolor sorts them by the last
            # rendering's depth order)
            colours = to_rgba_array(art["contacts"]._original_facecolor)
            for c, j in enumerate(run.scene.contacts):
                on = bool(mode[k] >> j & 1) or c in entered
                assert tuple(colours[c]) == pytest.approx(ACTIVE_COLOR if on else FREE_COLOR)
                segment = np.stack(art["arrows"][c].get_data_3d(), axis=1)
                # a force segment ends at its foot and runs straight down to it (normal +z)
                assert np.abs(segment[1] - drawn_points[c]).max() < EXACT
                assert np.abs(segment[0, :2] - segment[1, :2]).max() < EXACT
                assert art["arrows"][c].get_visible() == (bool(mode[k] >> j & 1)
                                                          and segment[1, 2] > segment[0, 2])
            movie.figure.canvas.draw()
            pictures.append(np.asarray(movie.figure.canvas.buffer_rgba()).copy())
        # the first frame in the air, a held landing, the end standing: three pictures
        assert frames[1] > 0 and len(set(frames)) == 3
        for a, b in zip(pictures, pictures[1:]):
            assert np.count_nonzero(np.any(a != b, axis=-1)) > 100
    finally:
        movie.close()


def test_a_planar_scene_keeps_the_x_z_view():
    """``planar``: one y for every frame, contact point and line point, and turns about y
    only; any y offset or any roll makes the scene 3-D."""
    n = 3
    positions = np.zeros((n, 2, 3))
    positions[:, 1, 0] = [0.0, 0.1, 0.2]
    rpy = np.zeros((n, 2, 3))
    rpy[:, 0, 1] = [0.0, 0.3, -0.4]  # (pitch: about y)
    contacts = np.zeros((n, 1, 3))
    state = SceneState(positions, quaternions(rpy), {}, {}, contacts, contacts + [0, 0, 1])
    assert planar(None, state)
    rolled = rpy.copy()
    rolled[1, 1, 0] = 0.01
    assert not planar(None, SceneState(positions, quaternions(rolled), {}, {}, contacts,
                                       contacts))
    beside = positions.copy()
    beside[:, 1, 1] = 0.15
    assert not planar(None, SceneState(beside, quaternions(rpy), {}, {}, contacts, contacts))
    # (the rotation matrices of the quaternions used above: y kept by a pitch)
    assert np.allclose(rotation_matrices(quaternions(rpy))[..., 1, 1], 1.0, atol=1e-15)


def test_panels_side_by_side_share_one_scale_of_force():
    """Alone, the hopper's drop at s = 0.03 would draw its forces at 0.02 length units per
    unit and at s = 0.07 (a harder landing) at 0.002; side by side both use 0.002, and the
    arrows are that scale times the force along the normal."""
    from pathlib import Path

    hopper = compiled_with(str(Path(__file__).resolve().parents[1] / "systems" / "urdf"
                               / "hopper.urdf"))
    runs = [panel(hopper, "drop", s, fps=10) for s in (0.03, 0.07)]
    alone = []
    for run in runs:
        movie = Animation([run], fps=10, hold=0, min_frames=0, view="3d")
        alone.append(movie._drawn[0][0].force_scale)
        movie.close()
    assert alone[0] != alone[1]
    movie = Animation(runs, fps=10, hold=0, min_frames=0, view="3d")
    try:
        for run, (d, mode) in zip(runs, movie._drawn):
            assert d.force_scale == min(alone)
            _state, _m, lam = run.state_at(movie.times)
            for c, j in enumerate(run.scene.contacts):
                on = (mode >> j) & 1 == 1
                length = d.arrows[:, c, 1, 2] - d.arrows[:, c, 0, 2]  # (normal +z)
                assert np.abs(length - np.where(on, min(alone) * lam[:, j], 0.0)).max() < EXACT
    finally:
        movie.close()
