"""Dependent contacts (docs/SYSTEMS.md, "Dependent contacts"): the kernel's rules where closed
forms check them, and what the tools that assume independent constraints say.

The system: a box resting flat on its four bottom corners (rank 3: dependent), with a slider
on its top face moving along the box's x axis at a fixed offset y0 from its centre line, and a
clock coordinate for a fixed end time. Nothing horizontal acts between them (the slider's
joint is frictionless, the ground too), so both move at constant horizontal velocities and the
box stays flat; the support's reactions are statics, in closed form: their sum is the total
weight and their moments about the box's centre are the slider's weight's,

    sum_j lambda_j = (m + ms) g,   sum_j lambda_j x_j = ms g xs,   sum_j lambda_j y_j = ms g y0,

with (x_j, y_j) = (+-a, +-b) the corners and xs the slider's position on the box. Four unknowns
and three equations: the reactions are not unique. The kernel's rule is a basic solution (one
corner held at zero, the other three pressing), and as the slider crosses a diagonal of the
face the held corner changes, without an event.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from biped_opt.control.derivatives import outcome_gradient
from biped_opt.simulation.compiled import CompiledSystem, compile_system
from biped_opt.simulation.contacts import DependentContactsError, dependent_modes

M, MS, A, B, C, G, Y0 = 1.0, 0.3, 0.4, 0.25, 0.15, 1.0, 0.05

SLIDER = textwrap.dedent(f"""
    # a box at rest on its face, a slider crossing its top face, a clock
    import sympy as sp
    from biped_opt.systems import System, rotation_rpy

    box = System("slidebox", ["x", "y", "z", "yaw", "pitch", "roll", "xs", "tau"], s="s",
                 parameters={{"m": {M}, "ms": {MS}, "a": {A}, "b": {B}, "c": {C}, "g": {G},
                             "y0": {Y0}, "T": 2.0, "v": 0.5}})
    x, y, z, yaw, pitch, roll, xs, tau = box.q
    m, ms, a, b, c, g, y0, T, v = (box.p[n] for n in box.p.names())
    R = rotation_rpy(roll, pitch, yaw)
    box.body("box", m, position=(x, y, z), rotation=R,
             inertia=(m * (b**2 + c**2) / 3, m * (a**2 + c**2) / 3, m * (a**2 + b**2) / 3))
    box.body("slider", ms, parent="box", position=(xs, y0, c), inertia=(1e-3, 1e-3, 1e-3))
    box.body("clock", 1, position=(tau, 0, 0))
    box.gravity = (0, 0, -g)
    for name, sx, sy in (("fl", 1, 1), ("fr", 1, -1), ("rl", -1, 1), ("rr", -1, -1)):
        box.constraint(name, z + (R * sp.Matrix([sx * a, sy * b, -c]))[2])
    # at rest on the face, the slider at s moving at v along the box; ends at T
    box.maneuver("slide", initial={{z: c, xs: box.s, box.dq[6]: v, box.dq[7]: 1}},
                 mode=("fl", "fr", "rl", "rr"), terminal=T - tau, outcome=box.dq[6],
                 s_range=(-0.5, 0.5))
    SYSTEM = box
""")
CORNERS = np.array([(A, B), (A, -B), (-A, B), (-A, -B)])  # fl, fr, rl, rr


@cache
def slider(folder: str) -> CompiledSystem:
    path = Path(folder) / "slidebox.py"
    path.write_text(SLIDER)
    return compile_system(str(path))


@pytest.fixture(scope="module")
def slidebox(tmp_path_factory: pytest.TempPathFactory) -> CompiledSystem:
    return slider(str(tmp_path_factory.mktemp("slidebox")))


def test_a_box_resting_on_four_corners_carries_the_slider_by_statics(slidebox):
    """From rest on its face (a dependent initial mode) the box stays flat while the slider
    crosses the face from xs = -0.3 to +0.7 at speed 0.5 (2 time units; its weight's moment
    crosses both diagonals at xs = +-Y0 A / B = +-0.08, and would tip the box past
    xs = (m + ms) A / ms = 1.73). No contact event, status OK, all four corners in contact at
    the end. The reactions sampled along the way: each >= 0 (to 1e-12: rounding of reactions
    of order 1), one of them 0 (a basic solution), their sum and moments the statics above to
    1e-12 (the reactions come from the same constrained accelerations the statics hold for,
    through one factorisation: rounding); and the corner held at zero changes as the slider
    crosses the diagonals."""
    tr = slidebox.simulate("slide", -0.3, sample_dt=0.01)
    assert tr.status.name == "OK", tr.message
    assert tr.n_events == 0
    assert tr.mode_names(tr.mode_final) == {"fl", "fr", "rl", "rr"}
    names = slidebox.coordinates
    d = len(names)
    q = tr.y_final[:d]
    for k in ("z", "roll", "pitch"):
        assert q[names.index(k)] == pytest.approx(C if k == "z" else 0.0, abs=1e-12)
    samples = tr.samples
    lam = samples[:, 2 + 2 * d:2 + 2 * d + 4]
    xs = samples[:, 1 + names.index("xs")]
    assert np.all(samples[:, 1 + 2 * d] == 0b1111)  # (every sample in the four-corner mode)
    assert lam.min() > -1e-12
    assert np.all(np.sort(lam, axis=1)[:, 0] < 1e-12)  # one corner held at zero
    weight = (M + MS) * G
    assert np.abs(lam.sum(axis=1) - weight).max() < 1e-12
    assert np.abs(lam @ CORNERS[:, 0] - MS * G * xs).max() < 1e-12
    assert np.abs(lam @ CORNERS[:, 1] - MS * G * Y0).max() < 1e-12
    held = {int(np.argmin(row)) for row in lam}
    assert len(held) >= 2, "the held corner should change as the slider crosses a diagonal"


def test_a_resting_box_with_dependent_corners_is_refused_by_the_b_derivatives(slidebox):
    """The B-derivative orders simultaneous events constraint by constraint and needs unique
    reactions: it stops with an error naming the mode and its rank instead of a number."""
    tr = slidebox.simulate("slide", -0.3)
    assert dependent_modes(slidebox, tr) == [(0.0, 0b1111, 3)]
    with pytest.raises(DependentContactsError, match=r"fl\+fr\+rl\+rr .*rank 3 of 4.*"
                                                     r"assumes independent constraints"):
        outcome_gradient(slidebox, "slide", -0.3)


def test_an_independent_run_is_not_refused():
    """The same check passes runs of independent contacts: the rocking bar's both ends at
    once (rank 2 of 2), whose B-derivatives exist (tests/control/test_derivatives.py)."""
    bar = compile_system("rocking_bar")
    tr = bar.simulate("drop", 0.0)
    assert tr.contact_events[0].mask_entered == 0b11
    assert dependent_modes(bar, tr) == []


def test_simulate_json_gives_each_events_states_and_modes(tmp_path):
    """``biped-opt simulate --json`` holds each event's modes and its states before and after
    the reset by coordinate name; the four-corner landing of the docs' box (SYSTEMS.md Sec.
    1a) has every corner entering and the velocities after it at 0 (plastic: the projection
    onto the velocities that keep the face on the ground, which for a level landing is 0)."""
    from tests.systems.test_bodies import _doc_example

    path = _doc_example("box.py", tmp_path)
    out = subprocess.run(
        [sys.executable, "-m", "biped_opt.cli.main", "simulate", "--system", str(path),
         "--maneuver", "drop", "--s", "0", "--json"], capture_output=True, text=True,
        timeout=300,
        env={**os.environ, "BIPED_OPT_AOT": "0"}, check=False)
    assert out.returncode == 0, out.stderr
    run = json.loads(out.stdout)
    (event,) = run["events"]
    assert event["touchdown"] == event["mode_after"] == ["fl", "fr", "rl", "rr"]
    assert event["mode_before"] == []
    before, after = event["state_before"], event["state_after"]
    assert set(before) == set(after) == {"q", "qdot"}
    assert before["q"] == after["q"]
    assert before["qdot"]["z"] == pytest.approx(-math.sqrt(2 * 0.3), abs=1e-12)
    assert all(abs(v) < 1e-15 for k, v in after["qdot"].items() if k != "tau")
    assert after["qdot"]["tau"] == 1.0


def test_sweeps_and_nonsmooth_tables_run_on_dependent_contacts(tmp_path):
    """The tools built on simulations alone work where the B-derivatives refuse: a batch over
    the docs' box's roll s (no inputs: the zero-padded input vector round-trips) gives the
    single runs' results to the bit, and the nonsmooth table of its outcome (the yaw rate,
    0 for every s by symmetry) finds nothing, though the mode sequence changes at s = 0 (one
    four-corner impact there, two edge impacts either side)."""
    from biped_opt.analysis.nonsmooth import find_nonsmooth
    from tests.systems.test_bodies import _doc_example

    box = compile_system(str(_doc_example("box.py", tmp_path)))
    grid = np.linspace(-0.3, 0.3, 7)
    batch = box.simulate_batch("drop", grid, box.input_vector(None))
    for k, s in enumerate(grid):
        one = box.simulate("drop", float(s))
        assert int(batch.status[k]) == 0 and batch.outcome[k] == one.outcome
        assert int(batch.n_events[k]) == (1 if s == 0.0 else 2)
    report = find_nonsmooth(box, "drop", num=21)
    assert report.points == ()


CUSP = textwrap.dedent("""
    # a point mass landing where a floor and a bowl (z + k x^2 >= 0) touch with one normal
    import sympy as sp
    from biped_opt.systems import System

    cusp = System("cusp", ["x", "z"], s="v", parameters={"k": 1.0})
    x, z = cusp.q
    cusp.mass_matrix = sp.eye(2)
    cusp.forces = lambda J: [0, -1]
    cusp.constraint("floor", z)
    cusp.constraint("bowl", z + cusp.p.k * x**2)
    cusp.maneuver("drop", initial={x: -1, z: 0.5, cusp.dq[0]: cusp.s}, terminal=2 - x,
                  outcome=cusp.dq[0], s_range=(0.5, 2.0))
    SYSTEM = cusp
""")


@pytest.mark.parametrize("v", [1.0, 1.0 - 1e-9, 1.0 + 1e-9])
def test_contacts_whose_rows_coincide_at_one_configuration_only(v, tmp_path):
    """Thrown at speed v from x = -1, z = 1/2 under unit gravity, the mass lands at t = 1 at
    x = v - 1: at v = 1 on the floor and the bowl at once, whose rows of Da coincide there
    (and only there: the system is not flagged as dependent). Within 1e-9 of it the two land
    within the simultaneity band with rows 2e-9 apart, closer than the Schur complement can
    resolve. Either way the impact is Newton's on the floor alone (the bowl's row depends on
    it), the horizontal velocity is kept, the bowl is released (it curves away) and the mass
    slides to x = 2 at t = 1 + (3 - v) / v (closed form, to 1e-12: event times are located to
    ~1e-13 and the slide is exact). Before, the impact's singular Schur complement gave NaN
    and the run ended INCONSISTENT."""
    path = tmp_path / "cusp.py"
    path.write_text(CUSP)
    tr = compile_system(str(path)).simulate("drop", v)
    assert tr.status.name == "OK", tr.message
    (landing,) = tr.contact_events
    assert set(landing.entered) == {"floor", "bowl"}
    assert tr.mode_names(tr.mode_final) == {"floor"}
    assert tr.outcome == pytest.approx(v, abs=1e-12)
    assert tr.t_final == pytest.approx(1 + (3 - v) / v, abs=1e-12)
    assert np.all(np.isfinite(tr.y_final))
