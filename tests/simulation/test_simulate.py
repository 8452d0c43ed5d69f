"""The generated event-driven simulator on every library system and on a user's own system.

Reference numbers are SYSTEMS.md's and MODEL.md's (independent implementations, rtol 1e-11).
Tolerances: against SYSTEMS.md, whose numbers carry 10 digits, 1e-9; one-sided slopes,
extrapolated from ladders of simulations, 1e-6 (as MODEL.md's); the biped's API and the
generated biped are the same kernel, equal to the last bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from biped_opt.codegen.render import render
from biped_opt.codegen.runtime import Status
from biped_opt.paper.biped import BipedParams, simulate
from biped_opt.piecewise import locate_switch, one_sided
from biped_opt.simulation.compiled import cache_dir, compile_system
from biped_opt.systems import System, derive, walker
from biped_opt.systems.library import biped
from tests.conftest import REFERENCE


@pytest.fixture(scope="module")
def bar():
    return compile_system("rocking_bar")


def _impacts(tr):
    return [e.mask_entered for e in tr.contact_events]


def test_rocking_bar_jumps_at_zero(bar):
    """SYSTEMS.md Sec. 2: left, right, left for small th0 > 0 and th'(t_f) = -0.1988749738 at
    th0 = 1e-6; the mirror image below 0; one simultaneous impact and exactly 0 at th0 = 0,
    t_f = 1.5 sqrt(2)."""
    right = bar.simulate("drop", 1e-6)
    assert right.success and _impacts(right) == [1, 2, 1]
    assert right.outcome == pytest.approx(-0.1988749738, abs=1e-9)
    left = bar.simulate("drop", -1e-6)
    assert _impacts(left) == [2, 1, 2] and left.outcome == -right.outcome
    zero = bar.simulate("drop", 0.0)
    assert _impacts(zero) == [3] and zero.outcome == 0.0
    assert zero.t_final == pytest.approx(1.5 * math.sqrt(2.0), abs=1e-12)
    assert bar.simulate("drop", 0.2).outcome == pytest.approx(2.42070065442, abs=1e-10)


@pytest.mark.parametrize(("where", "below", "above"), [
    (0.0961485, -0.3007, 2.4098), (0.2646950, 2.4201, -0.4295)])
def test_rocking_bar_jumps_where_a_third_impact_meets_the_apex(bar, where, below, above):
    """The number of impacts changes where the third one coincides with the apex; located by
    bisection to 1e-12 and compared with SYSTEMS.md's 7 digits."""
    def count(th):
        return len(_impacts(bar.simulate("drop", th)))

    lo, hi = locate_switch(count, where - 1e-4, where + 1e-4, tol=1e-12)
    assert lo == pytest.approx(where, abs=1e-7)
    assert bar.simulate("drop", lo).outcome == pytest.approx(below, abs=1e-4)
    assert bar.simulate("drop", hi).outcome == pytest.approx(above, abs=1e-4)


def test_a_parameter_change_does_not_recompile(bar):
    before = sorted(cache_dir().glob("rocking_bar_*.py"))
    stiff = compile_system("rocking_bar", gamma=0.0)
    assert stiff.module is bar.module and sorted(cache_dir().glob("rocking_bar_*.py")) == before
    # plastic impact: the first end stays down, so the bar ends in contact or pivots
    assert stiff.simulate("drop", 0.2).outcome != bar.simulate("drop", 0.2).outcome


@pytest.fixture(scope="module")
def generated_biped():
    return compile_system(biped())


CASES = [("touchdown", (2.0, 0.5, 0.0)), ("liftoff", (1.5, 3.0, 0.0)),
         ("touchdown", (0.0, 0.0, 0.0)), ("liftoff", (0.3, 0.2, 0.1))]


@pytest.mark.parametrize(("maneuver", "u"), CASES)
def test_the_biped_api_runs_the_generated_biped(generated_biped, maneuver, u):
    """biped_opt.simulate (the paper's preset: BipedParams, maneuver names, th0) is the
    generated biped to the last bit, with the default parameters and with others (a parameter
    passed under a wrong name or to the wrong compiled system would show here)."""
    params = BipedParams(k=31.0, c=0.2, gamma=0.3, w=0.3, Ib=0.7)
    for kw in ({}, {field: getattr(params, field) for field in generated_biped.parameters}):
        generated_biped.set_parameters(**kw)
        for th in (-0.2, -1e-7, 0.0, 0.03, 0.2):
            gen = generated_biped.simulate(maneuver, th, u)
            api = simulate(maneuver, th, u, params=params if kw else None)
            assert type(gen) is type(api) and gen.status is api.status
            assert gen.mode_sequence == api.mode_sequence
            assert gen.outcome == api.outcome
            assert gen.event_times == api.event_times
            assert [(e.kind, e.entered, e.left) for e in gen.events] == \
                [(e.kind, e.entered, e.left) for e in api.events]
    generated_biped.set_parameters()


@pytest.mark.parametrize("name", sorted(REFERENCE))
def test_the_generated_biped_reproduces_model_md(generated_biped, name):
    maneuver, th0, u, value = REFERENCE[name]
    assert generated_biped.simulate(maneuver, th0, u).outcome == pytest.approx(value, abs=1e-11)


def test_the_walker_with_two_legs_is_the_biped_line_for_line():
    """walker(2, coupled) renders to the biped's module once the names are the biped's: the
    same code, so the same numbers to the last bit."""
    two = render(derive(walker(2, "coupled", name="biped", feet=["left", "right"],
                               inputs=["u1", "u2", "u12"])))
    assert two == render(derive(biped()))
    plain = render(derive(walker(2, "coupled")))
    renamed = plain.replace("walker2_coupled", "biped").replace("u_body", "u12")
    assert renamed == render(derive(biped()))


def _slopes(system, maneuver, u):
    f = lambda th: system.simulate(maneuver, th, u).outcome  # noqa: E731
    return one_sided(f, 0.0, -1), one_sided(f, 0.0, +1), f(0.0)


def test_decoupled_two_legs_are_smooth_where_coupled_ones_are_not():
    """SYSTEMS.md Sec. 3, the paper's control experiment: with the decoupled input law the
    touchdown and liftoff outcomes are C^1 at th0 = 0 (one-sided slopes equal to 1e-6)."""
    w = compile_system(walker(2, "decoupled"))
    left, right, at = _slopes(w, "touchdown", (2.0, 0.5, 0.0))
    assert at == pytest.approx(-0.0127708483, abs=1e-9)
    assert left.derivative == pytest.approx(right.derivative, abs=1e-6)
    assert left.derivative == pytest.approx(0.8304310463, abs=1e-6)
    left, right, at = _slopes(w, "liftoff", (1.5, 3.0, 0.0))
    assert at == pytest.approx(0.0491117591, abs=1e-9)
    assert left.limit == pytest.approx(right.limit, abs=1e-9)
    assert left.derivative == pytest.approx(right.derivative, abs=1e-6)
    assert left.derivative == pytest.approx(0.4926096190, abs=1e-6)


@pytest.mark.parametrize(("law", "left", "right"), [
    ("coupled", 0.8732676633, 0.8395968313), ("decoupled", 0.8874799113, 0.8874799113)])
def test_three_legs_touchdown_slopes(law, left, right):
    w = compile_system(walker(3, law))
    lo, hi, _at = _slopes(w, "touchdown", (2.0, 1.0, 0.5, 0.0))
    assert lo.derivative == pytest.approx(left, abs=1e-6)
    assert hi.derivative == pytest.approx(right, abs=1e-6)


@pytest.fixture(scope="module")
def ball():
    """A system written here from scratch: a point mass bouncing on a floor with restitution
    gamma, thrown sideways at speed s from height h; it ends at the first apex after a bounce."""
    s = System("ball", ["x", "z"], parameters={"m": 2.0, "g": 1.0, "h": 1.0, "gamma": 0.6})
    x, z = s.q
    s.mass_matrix = sp.diag(s.p.m, s.p.m)
    s.forces = lambda J: [0, -s.p.m * s.p.g]
    s.constraint("floor", z)
    s.restitution = s.p.gamma
    s.maneuver("bounce", initial={z: s.p.h, s.dq[0]: s.s}, terminal=s.dq[1], outcome=z,
               armed_after="touchdown", final_mode=(), s_range=(0.0, 2.0))
    return compile_system(s)


@pytest.mark.parametrize("gamma", [1.0, 0.6, 0.0])
def test_a_bouncing_ball_keeps_the_energy_its_restitution_says(ball, gamma):
    """Apex after one bounce at gamma^2 h (the normal speed scales by gamma, kinetic energy of
    the vertical motion by gamma^2); gamma = 1 conserves energy, gamma = 0 keeps the ball on
    the floor (it never rises again: the maneuver runs to its horizon)."""
    ball.set_parameters(gamma=gamma, h=1.5)
    tr = ball.simulate("bounce", 0.7)
    if gamma == 0.0:
        assert tr.status is Status.HORIZON and tr.modes == (0, 1)
        return
    assert tr.success and tr.modes == (0, 0)
    assert tr.outcome == pytest.approx(gamma**2 * 1.5, abs=1e-10)
    fall = math.sqrt(2 * 1.5)
    assert tr.t_final == pytest.approx(fall + gamma * fall, abs=1e-10)
    assert tr.y_final[0] == pytest.approx(0.7 * tr.t_final, abs=1e-10)


def test_batches_equal_single_runs(bar):
    ths = np.linspace(-0.25, 0.25, 41)
    batch = bar.simulate_batch("drop", ths)
    single = [bar.simulate("drop", th).outcome for th in ths]
    np.testing.assert_array_equal(batch["outcome"], single)
    assert np.all(batch["status"] == 0)


def test_bad_calls_name_what_is_wrong(bar):
    from biped_opt.errors import InvalidInputError, InvalidParameterError

    with pytest.raises(InvalidInputError, match="unknown maneuver 'hop' \\(maneuvers: drop\\)"):
        bar.simulate("hop", 0.0)
    with pytest.raises(InvalidInputError, match="unknown input 'u1' \\(inputs: u_th\\)"):
        bar.simulate("drop", 0.0, {"u1": 1.0})
    with pytest.raises(InvalidInputError, match="s must be finite"):
        bar.simulate("drop", math.nan)
    with pytest.raises(InvalidParameterError, match="unknown parameter 'k'"):
        compile_system("rocking_bar", k=1.0)
    with pytest.raises(InvalidParameterError, match="parameter 'm' must be a finite number"):
        compile_system("rocking_bar", m=math.inf)


def test_the_quick_checks_of_inputs_and_parameters(generated_biped):
    """The wrapper's one-call input check and the parameters' precomputation take what the
    full checks took and refuse what they refused."""
    from biped_opt.errors import InvalidInputError, InvalidParameterError

    floats = generated_biped.simulate("touchdown", 0.1, (0.5, 1.0, 0.0))
    # NumPy and integer inputs are the same numbers: the same simulation, bit for bit
    for same in ((np.float64(0.5), np.float64(1.0), 0.0), (0.5, 1, 0), [0.5, 1.0, 0.0]):
        tr = generated_biped.simulate("touchdown", 0.1, same)
        assert tr.outcome == floats.outcome and tr.inputs == (0.5, 1.0, 0.0)
    assert floats.modes == (0, *floats.event_rows[: floats.n_events, 5].astype(int))
    for bad, name in (((0.5, math.nan, 0.0), "u2"), ((math.inf, -math.inf, 0.0), "u1"),
                      ((math.inf, 0.0, 0.0), "u1"), ((0.0, 0.0, "x"), None)):
        # the error names the first offending input
        match = f"biped: {name} must be finite" if name else "inputs must be numbers"
        with pytest.raises(InvalidInputError, match=match):
            generated_biped.simulate("touchdown", 0.1, bad)
    # finite inputs whose sum overflows are inputs like any other (taken as given)
    big = generated_biped.simulate("touchdown", 0.1, (1e308, 1e308, 1e308))
    assert big.inputs == (1e308, 1e308, 1e308)
    with pytest.raises(InvalidParameterError, match="no invertible mass matrix"):
        compile_system("biped", mf=0.0)


def test_module_level_simulate_for_any_system(bar):
    """simulate(system, maneuver, s, inputs, parameters=...) and simulate_batch: the same numbers
    as the compiled system's methods, parameters per call, one compiled system per process."""
    from biped_opt.simulation.compiled import simulate as simulate_system
    from biped_opt.simulation.compiled import simulate_batch as simulate_system_batch

    one = simulate_system("rocking_bar", "drop", 0.2)
    assert one.outcome == bar.simulate("drop", 0.2).outcome
    soft = simulate_system("rocking_bar", "drop", 0.2, parameters={"gamma": 0.2})
    assert soft.outcome != one.outcome
    again = simulate_system("rocking_bar", "drop", 0.2)  # defaults again: no parameter lingers
    assert again.outcome == one.outcome
    batch = simulate_system_batch("rocking_bar", "drop", [0.2, -0.2])
    np.testing.assert_array_equal(batch["outcome"], [one.outcome, -one.outcome])
