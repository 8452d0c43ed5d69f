"""The event rules of the hybrid simulator (docs/SYSTEMS.md, "Events") against references that
import nothing from biped_opt: closed forms of the flights between events (a rocking bar and a
ball fly ballistically and rotate at constant rate, a two-mass hopper's relative motion is a
harmonic oscillation), with event times as roots of those closed forms (scanned, then
``brentq`` to 1e-15).

Tolerances: outcomes and event times within 1e-9 (the kernel locates roots to ~1e-13 of a
step and integrates to rtol 1e-11; the references are exact up to rounding), impact sequences
exactly.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import sympy as sp
from scipy.optimize import brentq

from biped_opt.cli.main import main
from biped_opt.codegen.runtime import Status
from biped_opt.simulation.compiled import compile_system
from biped_opt.systems import System
from biped_opt.systems.description import SystemDescriptionError

# ----------------------------------------------------------------------------------------------
# independent references


def _first_root(g, t_max: float, t_min: float = 0.0) -> float | None:
    """The first t in (t_min, t_max] where g falls through 0, g vectorised: scanned on a grid
    that is geometric near t_min (a flight that starts at a root can be as short as 1e-8)
    then uniform, and refined by brentq."""
    near = t_min + np.geomspace(1e-9, 1e-2, 400)
    grid = np.concatenate([near, np.arange(t_min + 1e-2, t_max, 2e-4), [t_max]])
    values = g(grid)
    down = np.flatnonzero((values[:-1] > 0) & (values[1:] <= 0))
    if down.size == 0:
        return None
    k = down[0]
    return brentq(g, grid[k], grid[k + 1], xtol=1e-15, rtol=4 * np.finfo(float).eps)


def bar_reference(th0: float, *, w: float = 0.5, gamma: float = 0.5, m: float = 1.0,
                  g: float = 1.0, horizon: float = 10.0):
    """The rocking bar's drop (SYSTEMS.md Sec. 2) in closed form: between impacts z is a
    parabola, th linear in t, x constant; an impact of end j (a_j = z -+ w sin th) changes
    (z', th') by -(1 + gamma) M^-1 Da_j^T (Da_j q') / (Da_j M^-1 Da_j^T); the terminal event
    is the first z' = 0 falling after the first impact. Returns (impacts as 1 = left,
    2 = right, their times, th' at the end, t_end, z' just before each impact)."""
    inertia = m * (2 * w) ** 2 / 12
    t, z, th, vz, om = 0.0, 1.0, th0, 0.0, 0.0
    impacts, times, rising = [], [], []
    last = 0
    while t < horizon:
        def end(sign, t0=t, z0=z, th_0=th, vz0=vz, om0=om):
            return lambda tt: (z0 + vz0 * (tt - t0) - g * (tt - t0) ** 2 / 2
                               + sign * w * np.sin(th_0 + om0 * (tt - t0)))
        roots = {j: _first_root(end(sign), horizon, t) for j, sign in ((1, -1), (2, 1))}
        if impacts and vz > 0:
            roots[0] = t + vz / g  # the apex, z' = 0
        roots = {j: r for j, r in roots.items() if r is not None and not (j == last and r <= t)}
        j = min(roots, key=roots.get)
        t_next = roots[j]
        dt = t_next - t
        t, z, th, vz = t_next, z + vz * dt - g * dt * dt / 2, th + om * dt, vz - g * dt
        if j == 0:
            return impacts, times, om, t, rising
        rising.append(vz)
        sign = -1 if j == 1 else 1
        da = np.array([1.0, sign * w * math.cos(th)])  # (z, th) columns of Da_j
        minv = np.array([1 / m, 1 / inertia])
        v = np.array([vz, om])
        v = v - (1 + gamma) * minv * da * (da @ v) / (da @ (minv * da))
        vz, om = v
        impacts.append(j)
        times.append(t)
        last = j
    raise AssertionError("no apex before the horizon")


def _impacts(tr):
    return [e.mask_entered for e in tr.contact_events]


# ----------------------------------------------------------------------------------------------
# 1. every event found


@pytest.fixture(scope="module")
def bar():
    return compile_system("rocking_bar")


def test_a_bounce_and_return_within_one_step_is_an_event(bar):
    """The left end bounces at t = 1.6038 and lands again at t = 1.687456, within one step
    of the integrator (~0.1 here, 0.5 at most in flight): the return is an impact, and the
    apex that follows is the end (before, the end was 1.5e-4 under the ground there)."""
    bar.set_parameters(w=0.7, gamma=0.35)
    tr = bar.simulate("drop", -0.025)
    impacts, times, outcome, t_end, _ = bar_reference(-0.025, w=0.7, gamma=0.35)
    assert tr.success
    assert _impacts(tr) == impacts == [2, 1, 2, 1, 1]
    np.testing.assert_allclose(tr.event_times, times, rtol=0, atol=1e-9)
    assert times[-1] == pytest.approx(1.687456, abs=1e-6)  # (the number)
    assert tr.outcome == pytest.approx(outcome, abs=1e-9)
    assert tr.outcome == pytest.approx(0.0041943, abs=1e-7)
    assert tr.t_final == pytest.approx(t_end, abs=1e-9)


def test_status_ok_means_the_ends_stayed_above_the_ground(bar):
    """On every sample of an OK run (a grid of 1e-3 plus every event) both ends are at or
    above the ground, to the root locator's accuracy (1e-12 here: heights of O(1))."""
    bar.set_parameters(w=0.7, gamma=0.35)
    for th0 in (-0.025, 0.013, 0.2):
        tr = bar.simulate("drop", th0, sample_dt=1e-3)
        assert tr.success
        z, th = tr.samples[:, 2], tr.samples[:, 3]
        assert np.all(z - 0.7 * np.sin(th) >= -1e-12)
        assert np.all(z + 0.7 * np.sin(th) >= -1e-12)


@pytest.fixture(scope="module")
def ball():
    s = System("ball", ["x", "z"], parameters={"g": 1.0, "h": 1.5, "gamma": 0.5})
    x, z = s.q
    s.mass_matrix = sp.diag(1, 1)
    s.forces = lambda J: [0, -s.p.g]
    s.constraint("floor", z)
    s.restitution = s.p.gamma
    s.maneuver("bounce", initial={z: s.p.h, s.dq[0]: s.s}, terminal=s.p.h + 1 - x,
               outcome=z, s_range=(0.0, 2.0), max_events=22)
    # (for the horizon test: a fall whose terminal guard z + 1 > 0 is never reached; a
    # second maneuver rather than a second system, one compile)
    s.maneuver("fall", initial={z: s.s}, terminal=z + 1, outcome=z, horizon=0.5,
               s_range=(0.0, 1.0))
    return compile_system(s)


def test_bounces_much_shorter_than_a_step_are_all_found(ball):
    """A ball with restitution 1/2 from h = 1.5: the k-th flight lasts 2 sqrt(2 h) 2^-k, from
    2.4 down to 1.2e-6 for the 22nd, while the integrator's steps are 0.5 long (the flight
    is a polynomial it integrates exactly). Every bounce is found, at the closed-form times:
    flights are found however short while their apex (v^2 / 2g, 1e-13 for the 22nd) stays
    above the height's rounding (~1e-16), i.e. down to ~1e-7 time units here."""
    tr = ball.simulate("bounce", 0.0)
    assert tr.status is Status.MAX_EVENTS and tr.n_events == 22
    v0 = math.sqrt(2 * 1.5)
    flights = [2 * v0 * 0.5 ** k for k in range(1, 22)]
    expected = v0 + np.concatenate([[0.0], np.cumsum(flights)])
    np.testing.assert_allclose(tr.event_times, expected, rtol=0, atol=1e-9)
    assert min(np.diff(tr.event_times)) < 2e-6  # (the shortest flight checked)


# ----------------------------------------------------------------------------------------------
# 2. the terminal event ordered by time


def test_an_apex_just_before_an_impact_ends_the_run(bar):
    """At th0 = 0.09614845291502618 the apex comes first, with the left end still 2.5e-10
    above the ground: two impacts and th' = 2.4098311 (the end within the contact events'
    band of 1e-9 must not be applied with the apex)."""
    bar.set_parameters()  # (the defaults: m = 1, w = 0.5, g = 1, gamma = 0.5)
    th0 = 0.09614845291502618
    tr = bar.simulate("drop", th0)
    impacts, times, outcome, t_end, _ = bar_reference(th0)
    assert tr.success and _impacts(tr) == impacts == [1, 2]
    assert tr.outcome == pytest.approx(outcome, abs=1e-9)
    assert tr.outcome == pytest.approx(2.4098311, abs=1e-7)
    assert tr.t_final == pytest.approx(t_end, abs=1e-9)
    z, th = tr.y_final[1], tr.y_final[2]
    assert 0 < z - 0.5 * math.sin(th) < 1e-9


def test_an_impact_just_before_the_apex_does_not_end_the_run(bar):
    """Just below the coincidence the third impact comes first, with z' = +3e-10 (the apex
    3e-10 later, within the band): the impact is applied, z' jumps to +0.452, and the run
    goes on to the next apex (three impacts, th' near -0.3007)."""
    def count(th):
        return len(bar_reference(th)[0])

    coincidence = brentq(lambda th: count(th) - 2.5, 0.09614, 0.09615, xtol=1e-16)
    assert count(coincidence - 1e-12) == 3  # (three impacts below it)

    def rising(th):  # z' just before the third impact, less 3e-10
        return bar_reference(th)[4][2] - 3e-10

    th0 = brentq(rising, coincidence - 1e-6, coincidence - 1e-14, xtol=1e-18)
    impacts, times, outcome, t_end, vz = bar_reference(th0)
    assert impacts == [1, 2, 1] and 0 < vz[2] < 1e-9
    bar.set_parameters()
    tr = bar.simulate("drop", th0)
    assert tr.success and _impacts(tr) == impacts
    np.testing.assert_allclose(tr.event_times, times, rtol=0, atol=1e-9)
    third = tr.events[2]
    # y = (x, z, th, x', z', th'): z' just before the impact (the apex was near), and after it
    assert third.kind == "touchdown" and third.entered == ("left",)
    assert 0 < third.state_before[4] < 1e-9
    assert third.state_after[4] == pytest.approx(0.452, abs=1e-3)  # (not an apex)
    assert tr.outcome == pytest.approx(outcome, abs=1e-9)
    assert tr.outcome == pytest.approx(-0.3007288, abs=1e-7)  # (SYSTEMS.md's number)
    assert tr.t_final == pytest.approx(t_end, abs=1e-9) and t_end - times[-1] > 0.05


# ----------------------------------------------------------------------------------------------
# 5. the next mode by complementarity, and the budget


def hopper_reference(v_foot: float, *, mb=1.0, mf=0.1, k=10.0, length=1.0, g=1.0):
    """A body and a foot joined by a spring (rest length ``length``), the foot landing
    plastically while the stretched spring pulls it up harder than its weight: in contact it
    would need a pulling ground force, so it leaves the ground at once with zero velocity. In
    flight the centre of mass falls freely and the stretch r = zb - zf - length oscillates at
    omega^2 = k (1/mb + 1/mf). Returns (landing time, zb at the body's apex, t_apex)."""
    mt = mb + mf
    omega = math.sqrt(k * (1 / mb + 1 / mf))

    def flight(t0, zb, zf, vb, vf):
        Z, V = (mb * zb + mf * zf) / mt, (mb * vb + mf * vf) / mt
        r, vr = zb - zf - length, vb - vf

        def state(t):
            dt = t - t0
            zc, vc = Z + V * dt - g * dt * dt / 2, V - g * dt
            rr = r * np.cos(omega * dt) + vr / omega * np.sin(omega * dt)
            vrr = -r * omega * np.sin(omega * dt) + vr * np.cos(omega * dt)
            return (zc + mf / mt * (rr + length), zc - mb / mt * (rr + length),
                    vc + mf / mt * vrr, vc - mb / mt * vrr)
        return state

    state = flight(0.0, 1.6, 0.2, 1.0, v_foot)
    t_land = _first_root(lambda t: state(t)[1], 5.0)
    zb, zf, vb, vf = state(t_land)
    stretch_force = k * (zb - zf - length)
    assert stretch_force > mf * g  # the landing foot would pull on the ground
    state = flight(t_land, zb, 0.0, vb, 0.0)  # plastic: vf = 0, and off the ground at once
    t_apex = _first_root(lambda t: state(t)[2], 5.0, t_land)
    foot = _first_root(lambda t: state(t)[1], t_apex, t_land + 1e-6)
    assert foot is None  # (no second landing before the apex)
    return t_land, state(t_apex)[0], t_apex


@pytest.fixture(scope="module")
def hopper():
    s = System("hopper", ["zb", "zf"],
               parameters={"mb": 1.0, "mf": 0.1, "k": 10.0, "L": 1.0, "g": 1.0})
    zb, zf = s.q
    p = s.p
    spring = p.k * (zb - zf - p.L)
    s.mass_matrix = sp.diag(p.mb, p.mf)
    s.forces = lambda J: [-spring - p.mb * p.g, spring - p.mf * p.g]
    s.constraint("foot", zf)
    s.maneuver("land", initial={zb: 1.6, zf: 0.2, s.dq[0]: 1, s.dq[1]: s.s}, terminal=s.dq[0],
               outcome=zb, armed_after="touchdown", s_range=(-9.0, -5.0))
    return compile_system(s)


@pytest.mark.parametrize("v_foot", [-6.0, -8.0])
def test_a_landing_that_would_pull_leaves_the_ground_at_once(hopper, v_foot):
    """The complementarity rule after a plastic impact: the contact mode would need
    lambda < 0, the air mode has the foot accelerating up (a'' > 0), so the air mode it is
    (before: status INCONSISTENT)."""
    t_land, zb_apex, t_apex = hopper_reference(v_foot)
    tr = hopper.simulate("land", v_foot)
    assert tr.success, tr.message
    assert tr.modes == (0, 0)  # a touchdown whose next mode is the air
    assert _impacts(tr) == [1]
    assert tr.event_times[0] == pytest.approx(t_land, abs=1e-9)
    assert abs(tr.events[0].state_after[3]) < 1e-14  # the foot's velocity after the impact
    assert tr.t_final == pytest.approx(t_apex, abs=1e-9)
    assert tr.outcome == pytest.approx(zb_apex, abs=1e-9)


def test_the_budget_is_the_maneuvers_and_named_when_used_up(ball):
    """max_events and horizon are fields of the maneuver; a run that uses one up says which,
    where to raise it and its last events."""
    tr = ball.simulate("bounce", 0.0)
    assert tr.status is Status.MAX_EVENTS
    assert tr.message.startswith("22 contact events, the maneuver's event budget, were used up")
    assert "max_events" in tr.message and "--max-events" in tr.message
    assert tr.message.count("touchdown floor -> mode air") == 3  # the last three events
    assert ball.maneuver_options("bounce").max_events == 22
    assert ball.maneuver_options("bounce").t_end == 10.0

    tr = ball.simulate("fall", 1.0)
    assert tr.status is Status.HORIZON and tr.t_final == pytest.approx(0.5, abs=1e-15)
    assert "the horizon t = 0.5" in tr.message and "--horizon" in tr.message


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"max_events": 0}, "max_events must be a positive integer, got 0"),
    ({"max_events": 2.5}, "max_events must be a positive integer, got 2.5"),
    ({"horizon": -1.0}, "horizon must be a positive number, got -1.0"),
    ({"horizon": math.inf}, "horizon must be a positive number, got inf"),
])
def test_a_bad_budget_is_refused_by_name(kwargs, match):
    s = System("slow", ["z"])
    with pytest.raises(SystemDescriptionError, match=f"slow: maneuver 'fall': {match}"):
        s.maneuver("fall", initial={}, terminal=s.q[0], outcome=s.q[0], **kwargs)


def test_the_command_line_sets_the_budget(capsys):
    code = main(["simulate", "--system", "rocking_bar", "--maneuver", "drop", "--s=1e-6",
                 "--max-events", "2", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 1 and out["status"] == "max_events" and len(out["events"]) == 2
    assert out["message"].startswith("2 contact events")
    code = main(["simulate", "--system", "rocking_bar", "--maneuver", "drop", "--s=1e-6",
                 "--horizon", "1.2", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 1 and out["status"] == "horizon" and out["t_final"] == 1.2
    with pytest.raises(SystemExit):
        main(["simulate", "--system", "rocking_bar", "--maneuver", "drop", "--s=0",
              "--max-events", "0"])
    assert "--max-events must be between 1 and 10000, got 0" in capsys.readouterr().err
