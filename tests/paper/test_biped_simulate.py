"""The hybrid simulator against exact solutions, conservation laws, symmetry and MODEL.md."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from biped_opt.errors import InvalidInputError, InvalidParameterError
from biped_opt.paper.biped import BipedParams, simulate, simulate_batch
from biped_opt.paper.biped import ContactMode as M
from biped_opt.simulation.options import SimulatorOptions
from biped_opt.simulation.trajectory import Status
from tests.conftest import REFERENCE
from tests.paper.biped_physics import energy, initial_state, packed

AIR, LEFT, RIGHT, GROUND = M.AIR, M.LEFT, M.RIGHT, M.GROUND


def legs(mask: int) -> list[int]:
    """The legs (1 = left, 2 = right) of a mask over the biped's constraints."""
    return [j + 1 for j in M(mask).active]


@pytest.mark.parametrize("name", sorted(REFERENCE))
def test_reference_outcomes(name):
    """MODEL.md R1-R4; the table has 12 significant digits, we require 1e-9 absolute."""
    maneuver, theta0, u, expected = REFERENCE[name]
    tr = simulate(maneuver, theta0, u)
    assert tr.status is Status.OK
    assert abs(tr.outcome - expected) <= 1e-9


@pytest.mark.parametrize("theta0", [0.13, -0.07, 0.0])
def test_free_fall_is_the_exact_parabola_and_touchdown_time_is_exact(theta0):
    """Before the first touchdown every coordinate falls as z0 - g t^2 / 2 (legs at rest length,
    so no leg force acts). The first foot reaches z = 0 at t = sqrt(2 z_foot / g) exactly: the
    located event must agree to 1e-10 (MODEL.md Sec. 3)."""
    params = BipedParams(g=1.3)
    y0, _ = initial_state("touchdown", theta0, params)
    tr = simulate("touchdown", theta0, (0.4, 0.2), params=params, sample_dt=0.01)
    first = tr.contact_events[0]
    t_exact = math.sqrt(2 * min(y0[4], y0[6]) / params.g)
    assert abs(first.t - t_exact) <= 1e-10
    pre = tr.samples[tr.samples[:, 0] < first.t]
    assert len(pre) > 50
    t = pre[:, :1]
    expected_q = y0[:7] - 0.5 * params.g * t**2 * np.array([0, 1, 0, 0, 1, 0, 1])
    expected_dq = -params.g * t * np.array([0, 1, 0, 0, 1, 0, 1])
    np.testing.assert_allclose(pre[:, 1:8], expected_q, atol=1e-12)
    np.testing.assert_allclose(pre[:, 8:15], expected_dq, atol=1e-12)
    assert np.all(pre[:, 15] == AIR)


@pytest.mark.parametrize(("maneuver", "theta0"), [("touchdown", 0.08), ("touchdown", -0.15),
                                                  ("touchdown", 0.0), ("liftoff", 0.05)])
def test_energy_conserved_except_the_exact_impact_loss(maneuver, theta0):
    """c = 0, u = 0: energy is constant along the flow and each touchdown removes exactly
    0.5 mf z_j'^2 of the landing foot (to 1e-12). The drift grows like (steps x rtol x E): with
    rtol = 1e-12, ~20 steps and E ~ 1 it stays below 1e-10 (at the default 1e-11, ~2e-10)."""
    params = BipedParams(mf=0.7)
    tr = simulate(maneuver, theta0, (0.0, 0.0, 0.0), params=params, sample_dt=0.005,
                  options=SimulatorOptions(rtol=1e-12))
    assert tr.success
    e0 = energy(params, tr.samples[0, 1:15])
    lost = 0.0
    for e in tr.contact_events:
        before = energy(params, e.state_before)
        after = energy(params, e.state_after)
        expected_loss = sum(0.5 * params.mf * e.state_before[9 + 2 * j] ** 2
                            for j in legs(e.mask_entered))
        assert before - after == pytest.approx(expected_loss, abs=1e-12)
        assert abs(before - (e0 - lost)) < 1e-10
        lost += expected_loss
    # every sample between events sits on its segment's energy level (event rows checked above)
    event_times = {e.t for e in tr.contact_events}
    for row in tr.samples:
        if row[0] in event_times:
            continue
        level = e0 - sum(
            0.5 * params.mf * e.state_before[9 + 2 * j] ** 2
            for e in tr.contact_events for j in legs(e.mask_entered) if e.t < row[0]
        )
        assert abs(energy(params, row[1:15]) - level) < 1e-10
    if maneuver == "touchdown":
        assert lost > 0.01  # the feet land with real speed: the check above is not vacuous


@pytest.mark.parametrize("theta0", [0.01, 0.1, 0.2])
def test_mirror_symmetry(theta0):
    """outcome(-th0) with (u1, u2) swapped = -outcome(th0) (u12 = 0); 1e-12 covers rounding."""
    for maneuver, u in (("touchdown", (2.0, 0.5)), ("liftoff", (1.5, 3.0))):
        a = simulate(maneuver, theta0, u)
        b = simulate(maneuver, -theta0, u[::-1])
        assert abs(a.outcome + b.outcome) < 1e-12
        assert abs(a.t_final - b.t_final) < 1e-12
        mirrored = [{LEFT: RIGHT, RIGHT: LEFT}.get(m, m) for m in a.mode_sequence]
        assert list(b.mode_sequence) == mirrored


@pytest.mark.parametrize(
    ("maneuver", "theta0", "u", "sequence"),
    [
        ("touchdown", 0.1, (2.0, 0.5), (AIR, LEFT, GROUND)),
        ("touchdown", 1e-6, (2.0, 0.5), (AIR, LEFT, GROUND)),
        ("touchdown", -0.2, (2.0, 0.5), (AIR, RIGHT, GROUND)),
        ("touchdown", 0.0, (2.0, 0.5), (AIR, GROUND)),
        ("liftoff", -1e-6, (1.5, 3.0), (GROUND, RIGHT, AIR)),
        ("liftoff", 0.1, (1.5, 3.0), (GROUND, LEFT, AIR)),
        ("liftoff", 0.0, (1.5, 3.0), (GROUND, AIR)),
    ],
)
def test_mode_sequences(maneuver, theta0, u, sequence):
    tr = simulate(maneuver, theta0, u)
    assert tr.success
    assert tr.mode_sequence == sequence
    assert tr.segments[0].t_start == 0.0 and tr.segments[-1].t_end == tr.t_final
    assert tuple(seg.mask for seg in tr.segments) == sequence
    if len(sequence) == 2:  # th0 = 0 exactly: both feet flip in one simultaneous event
        (event,) = tr.contact_events
        assert event.simultaneous
        assert tr.outcome == 0.0  # the motion stays exactly symmetric


def test_liftoff_events_are_roots_of_the_reaction_force():
    """Each liftoff happens where lambda_j = 0: |lambda_j| / |dlambda_j/dt| <= 1e-10."""
    from tests.paper.biped_physics import dynamics

    params = BipedParams()
    tr = simulate("liftoff", 0.07, (1.5, 3.0, 0.1), sample_dt=0.001)
    for e in tr.contact_events:
        (leg,) = legs(e.mask_left)
        assert e.liftoff == (("left", "right")[leg - 1],)  # the constraint's name
        j = leg - 1
        dy, lam = np.empty(14), np.empty(2)
        dynamics(packed(params), e.mask_before, e.state_before, np.array(tr.inputs), dy, lam)
        # rate of lambda_j from the samples just before the event
        before = tr.samples[(tr.samples[:, 0] < e.t) & (tr.samples[:, 15] == e.mask_before)]
        rate = (before[-1, 16 + j] - before[-2, 16 + j]) / (before[-1, 0] - before[-2, 0])
        assert abs(lam[j] / rate) <= 1e-10
        # no reset at liftoff: the state is continuous
        np.testing.assert_array_equal(e.state_before, e.state_after)


def test_liftoff_does_not_retrigger_touchdown():
    """A foot that just lifted sits at z = 0: the disarmed guard must not fire again."""
    for theta0 in (-0.2, -0.01, 0.03, 0.25):
        tr = simulate("liftoff", theta0, (1.5, 3.0, 0.0))
        assert tr.success
        assert all(e.kind == "liftoff" for e in tr.contact_events)
        assert tr.nevents == 2


def test_touchdown_impact_stops_only_the_landing_foot():
    tr = simulate("touchdown", 0.1, (2.0, 0.5))
    first = tr.contact_events[0]
    assert first.touchdown == first.entered == ("left",) and legs(first.mask_entered) == [1]
    assert first.mode_before == frozenset() and first.mode_after == frozenset({"left"})
    changed = np.flatnonzero(first.state_before != first.state_after)
    assert changed.tolist() == [11]  # z1' only (gamma = 0: plastic)
    assert first.state_after[11] == 0.0


def test_inconsistent_contact_is_reported():
    """A pulling leg (u1 = -3 < -mf g / cos th) would need lambda_1 < 0 right at touchdown."""
    tr = simulate("touchdown", 0.1, (-3.0, 0.0))
    assert tr.status is Status.INCONSISTENT
    assert not tr.success
    assert "negative reaction" in tr.message


def test_budgets_end_with_a_clear_status():
    tr = simulate("touchdown", 0.1, (2.0, 0.5), options=SimulatorOptions(max_events=1))
    assert tr.status is Status.MAX_EVENTS and tr.nevents == 1
    tr = simulate("touchdown", 0.1, (2.0, 0.5), options=SimulatorOptions(t_end=0.5))
    assert tr.status is Status.HORIZON and tr.t_final == pytest.approx(0.5, abs=1e-15)


def test_weak_push_reports_apex_in_contact():
    """With a soft spring the body peaks while both feet are still down."""
    tr = simulate("liftoff", 0.05, (0.0, 0.0, 0.0), params=BipedParams(k=8.0))
    assert tr.status is Status.APEX_IN_CONTACT
    assert tr.mode_final != AIR


def test_samples_have_events_twice_and_end_at_t_final():
    tr = simulate("touchdown", 0.1, (2.0, 0.5), sample_dt=0.01)
    times = tr.samples[:, 0]
    assert np.all(np.diff(times) >= 0)
    for e in tr.contact_events:
        rows = tr.samples[times == e.t]
        assert [int(r[15]) for r in rows] == [e.mask_before, e.mask_after]
    assert times[-1] == tr.t_final
    np.testing.assert_array_equal(tr.samples[-1, 1:15], tr.state_final)


def test_batch_equals_single_calls():
    """The parallel batch path runs the same kernel: results agree bit for bit."""
    grid = np.array([-0.2, -1e-3, 0.0, 1e-3, 0.17])
    batch = simulate_batch("touchdown", grid, (2.0, 0.5))
    for k, th in enumerate(grid):
        tr = simulate("touchdown", th, (2.0, 0.5))
        assert batch.outcome[k] == tr.outcome
        assert batch.t_final[k] == tr.t_final
        assert batch.mode_sequence(k) == tr.mode_sequence
        np.testing.assert_array_equal(batch.event_times(k), tr.event_times)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"maneuver": "hop", "theta0": 0.1}, InvalidInputError, "maneuver must be one of"),
        ({"maneuver": "touchdown", "theta0": math.nan}, InvalidInputError, "theta0 must be finite"),
        ({"maneuver": "touchdown", "theta0": 0.26}, InvalidInputError, "outside the valid range"),
        ({"maneuver": "liftoff", "theta0": -0.31}, InvalidInputError, "outside the valid range"),
        ({"maneuver": "touchdown", "theta0": 0.1, "inputs": (1.0, math.inf)}, InvalidInputError,
         "u2 must be finite"),
        ({"maneuver": "touchdown", "theta0": 0.1, "inputs": (1, 2, 3, 4)}, InvalidInputError,
         "4 inputs given, the system has 3"),
        ({"maneuver": "touchdown", "theta0": 0.1, "sample_dt": -1.0}, InvalidInputError,
         "sample_dt"),
    ],
)
def test_bad_arguments_raise_naming_the_argument(kwargs, error, match):
    with pytest.raises(error, match=match):
        simulate(**kwargs)


def test_batch_validates_every_case():
    with pytest.raises(InvalidInputError, match="u12 of case 1 must be finite"):
        simulate_batch("liftoff", [0.1, 0.2], [[1.5, 3.0, 0.0], [1.5, 3.0, math.nan]])
    with pytest.raises(InvalidInputError, match="outside the valid range"):
        simulate_batch("touchdown", [0.1, 0.3], (2.0, 0.5))
    with pytest.raises(InvalidInputError, match="inputs must have shape"):
        simulate_batch("touchdown", [0.1, 0.2], np.zeros((3, 2)))


def test_bad_options():
    with pytest.raises(InvalidParameterError, match="rtol"):
        SimulatorOptions(rtol=0.0)
    with pytest.raises(InvalidParameterError, match="max_events"):
        SimulatorOptions(max_events=0)


def test_warm_up_compiles_both_kernels():
    """In a fresh interpreter, warm_up leaves the single-call and the batch kernels compiled (or
    loaded from the cache) before any simulation asked for them, so a node that calls it before
    serving never compiles inside a request."""
    script = (
        "from biped_opt.codegen import kernel\n"
        "from biped_opt.paper.biped import compiled_biped, warm_up\n"
        "m = compiled_biped().module\n"
        "assert not kernel.simulate_maneuver.signatures and not m._CFUNCS\n"
        "assert not kernel.simulate_batch_kernel.signatures\n"
        "assert warm_up() > 0.0\n"
        "assert kernel.simulate_maneuver.signatures and len(m._CFUNCS) == 10\n"
        "assert kernel.simulate_batch_kernel.signatures\n"
    )
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
