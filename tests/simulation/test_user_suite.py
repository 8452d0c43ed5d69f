"""User systems against independent references (issue 22, item 6).

The system files in ``tests/simulation/user/`` are written as the manual's "Your own system"
tutorial (docs/tutorials/own_system.md) tells a user to write them; the references next to
them import nothing from biped_opt:

- ``reference_flight``: closed-form flights with certified event isolation for the corner
  (a point mass between the floor and a wall leaning back, coupled normals, restitution), the
  stacked balls (coupled through the lower ball's mass), the plank (a rocking bar in other
  names and parameters) and the library's rocking bar;
- ``reference_chain``: SciPy's solve_ivp on the three-link chain's M(q) and f(q, q') derived
  there again from the links' Jacobians (the file derives them from the kinetic energy's
  Hessian), the chain's angles being relative (``sin(th + a1)``).

Outcomes, event times and the sequence of impacts are compared at 1e-9: the references locate
event times to ~1e-15 (closed form) and ~1e-11 (solve_ivp at rtol 1e-12), the simulator to
~1e-12, so 1e-9 leaves two orders of magnitude for the flights' rounding and no room for a wrong
event. Every coincidence of two events in the tested ranges is located from the reference by
bisection on the order of its events (merging switched off), and the simulator is checked at
s* +- 1e-9, 3e-10, 1e-10 against the reference there, where the model's simultaneity band
(contact guards within 1e-9 of zero flip together; the terminal event never merges) decides.
"""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from biped_opt.codegen.runtime import Status
from tests.simulation.user import reference_chain, reference_flight

USER = Path(__file__).with_name("user")
TOL = 1e-9  # outcomes and event times (see the module docstring)
OFFSETS = (-1e-9, -3e-10, -1e-10, 1e-10, 3e-10, 1e-9)
#: a guard this close (relative) to the band's edge at an event makes a case undecidable at
#: the references' and the simulator's accuracy (~1e-12 in a guard): such an offset is skipped
EDGE = 0.05


#: system file, maneuver, reference of s, tested ranges of s
FLIGHT = {
    "corner": ("toss", reference_flight.corner, [(0.1, 0.8)]),
    "stack": ("throw", reference_flight.stack, [(0.05, 0.5)]),
    # |s| < 0.06: re-impacts cascade (the ends' flights shrink toward a Zeno point at 0);
    # the part the simulator misses today is test_plank_reimpacts_within_a_step
    "plank": ("fall", reference_flight.plank, [(-0.4, -0.06), (0.06, 0.4)]),
}


@cache
def compiled(name: str):
    from biped_opt.simulation.compiled import compile_system

    return compile_system(name if name == "rocking_bar" else str(USER / f"{name}.py"))


def assert_agrees(tr, ref, where: str) -> None:
    """Same status, same impacts (which constraints, in which order), event times and outcome
    within TOL."""
    assert tr.status.name == ref.status, f"{where}: status {tr.status.name}, reference " \
        f"{ref.status}"
    impacts = [frozenset(j for j in range(8) if e.mask_entered >> j & 1)
               for e in tr.contact_events]
    assert impacts == [j for _, j in ref.events], f"{where}: impacts {impacts}, reference " \
        f"{[sorted(j) for _, j in ref.events]}"
    np.testing.assert_allclose(tr.event_times, ref.times, rtol=0, atol=TOL, err_msg=where)
    assert tr.outcome == pytest.approx(ref.outcome, rel=0, abs=TOL), where
    if ref.status == "OK":
        assert tr.t_final == pytest.approx(ref.t_final, rel=0, abs=TOL), where


# -- the references themselves ------------------------------------------------------------------

def test_the_flight_reference_reproduces_the_published_numbers():
    """The closed-form reference against SYSTEMS.md Sec. 2 and issue 22's bar case, numbers
    computed by other implementations (quoted to their printed digits)."""
    bar = reference_flight.rocking_bar
    assert reference_flight.simulate(bar(0.2)).outcome == pytest.approx(2.42070065442, abs=1e-11)
    assert reference_flight.simulate(bar(1e-6)).outcome == pytest.approx(-0.1988749738,
                                                                         abs=1e-10)
    level = reference_flight.simulate(bar(0.0))
    assert [sorted(j) for _, j in level.events] == [[0, 1]]
    assert level.t_final == pytest.approx(1.5 * math.sqrt(2), abs=1e-14)
    apex_first = reference_flight.simulate(bar(0.09614845291502618))
    assert len(apex_first.events) == 2
    assert apex_first.outcome == pytest.approx(2.4098311, abs=5e-8)
    reimpact = reference_flight.simulate(bar(-0.025, w=0.7, gamma=0.35))
    assert [sorted(j) for _, j in reimpact.events] == [[1], [0], [1], [0], [0]]
    assert reimpact.times[4] == pytest.approx(1.687456, abs=5e-7)
    assert reimpact.outcome == pytest.approx(0.0041943, abs=5e-8)


def test_the_flight_reference_finds_the_corner_in_closed_form():
    """Thrown level from (1, h0) at speed 1.2 under g = 1, the mass reaches the corner when
    x = 0 and z = 0 together: t = 1/1.2, h0 = t^2 / 2 = 25/72; the stacked balls meet as the
    lower one lands at v0 = 0.2 / sqrt(2). Both are among the located coincidences."""
    corner = reference_flight.coincidences(reference_flight.corner, 0.1, 0.8, 41)
    assert min(abs(c - 25 / 72) for c in corner) < 1e-14
    stack = reference_flight.coincidences(reference_flight.stack, 0.05, 0.5, 41)
    assert min(abs(c - 0.2 / math.sqrt(2)) for c in stack) < 1e-14


# -- outcomes over the tested ranges -----------------------------------------------------------

@pytest.mark.parametrize("name", list(FLIGHT))
def test_outcomes_and_impacts_over_s(name):
    """41 values of s per range: the batch's outcomes, statuses and event counts and each
    trajectory's impacts and event times against the reference."""
    maneuver, make, ranges = FLIGHT[name]
    system = compiled(name)
    for lo, hi in ranges:
        grid = np.linspace(lo, hi, 41)
        batch = system.simulate_batch(maneuver, grid)
        for k, s in enumerate(grid):
            ref = reference_flight.simulate(make(s))
            where = f"{name} s = {s!r}"
            assert Status(batch.status[k]).name == ref.status, where
            assert batch["n_events"][k] == len(ref.events), where
            assert batch["outcome"][k] == pytest.approx(ref.outcome, rel=0, abs=TOL), where
            assert_agrees(system.simulate(maneuver, s), ref, where)


# -- every coincidence of two events, approached within 1e-9 -----------------------------------

def _coincidences(name: str, kind: str) -> list[float]:
    """The coincidences in the tested ranges whose two events are two contact events
    (``kind="contact"``) or the terminal event and a contact event (``"terminal"``)."""
    _maneuver, make, ranges = FLIGHT[name]
    found = []
    for lo, hi in ranges:
        for c in reference_flight.coincidences(make, lo, hi, 41):
            sides = [reference_flight.simulate(make(c + d), band=0.0) for d in (-1e-13, 1e-13)]
            gap = min((abs(a.t_final - t) for a in sides if a.status == "OK"
                       for b in sides for t in b.times), default=math.inf)
            if (gap < 1e-6) == (kind == "terminal"):
                found.append(c)
    return found


def _check_coincidences(name: str, kind: str, expected: int) -> None:
    maneuver, make, _ranges = FLIGHT[name]
    system = compiled(name)
    points = _coincidences(name, kind)
    assert len(points) == expected, f"{name}: {kind} coincidences at {points}"
    checked = 0
    for c in points:
        sides = set()
        for offset in OFFSETS:
            s = c + offset
            ref = reference_flight.simulate(make(s))
            if ref.band_margin < EDGE:
                continue
            assert_agrees(system.simulate(maneuver, s), ref, f"{name} s = s* {offset:+.0e}")
            sides.add(offset > 0)
            checked += 1
        assert sides == {False, True}, f"{name}: s* = {c!r} checked on one side only"
    assert checked >= 4 * expected


@pytest.mark.parametrize(("name", "expected"), [("corner", 1), ("stack", 1)])
def test_simultaneous_impacts(name, expected):
    """The mass hits floor and wall at once (25/72), the balls meet as the lower one lands:
    the impacts merge within the band and are one impact on both constraints, outside it
    they come in the reference's order."""
    _check_coincidences(name, "contact", expected)


@pytest.mark.parametrize(("name", "expected"), [
    ("corner", 1), ("plank", 2),
])
def test_apex_next_to_an_impact(name, expected):
    """The apex and an impact at once (the corner's wall impact at h0 = 0.1399, the plank's
    fourth impact at +-0.1976): the terminal event is ordered by time, never merged."""
    _check_coincidences(name, "terminal", expected)


# -- re-impacts closer together than a step ----------------------------------------------------

def test_plank_reimpacts_within_a_step():
    """0.04 <= s <= 0.058: an end lands again after a flight shorter than the simulator's
    step (5 or 6 impacts), and every coincidence there."""
    system = compiled("plank")
    points = list(np.linspace(0.04, 0.057, 9))
    coincidences = reference_flight.coincidences(reference_flight.plank, 0.039, 0.058, 20)
    for c in coincidences:
        points += [c + offset for offset in OFFSETS]
    checked = 0
    for s in points:
        ref = reference_flight.simulate(reference_flight.plank(s))
        if ref.band_margin >= EDGE:
            assert_agrees(system.simulate("fall", s), ref, f"plank s = {s!r}")
            checked += 1
    # (not skipped away: as for the other coincidences, at least 4 of the 6 offsets of each;
    # measured: all 27 points of the 3 coincidences and the grid are decidable)
    assert coincidences and checked >= len(points) - 2 * len(coincidences)


def test_library_bar_reimpact():
    """`biped-opt simulate --system rocking_bar --maneuver drop --s=-0.025 --param w=0.7
    --param gamma=0.35`: five impacts, the last of the left end at t = 1.687456."""
    bar = compiled("rocking_bar")
    bar.set_parameters(w=0.7, gamma=0.35)
    try:
        tr = bar.simulate("drop", -0.025)
    finally:
        bar.set_parameters()
    ref = reference_flight.simulate(reference_flight.rocking_bar(-0.025, w=0.7, gamma=0.35))
    assert_agrees(tr, ref, "rocking_bar s = -0.025")


def test_library_bar_apex_first():
    """th0 = 0.09614845291502618: the apex comes first, an end 2.5e-10 above the ground."""
    bar = compiled("rocking_bar")
    bar.set_parameters()
    s = 0.09614845291502618
    assert_agrees(bar.simulate("drop", s), reference_flight.simulate(
        reference_flight.rocking_bar(s)), f"rocking_bar s = {s!r}")


# -- the chain: relative joint angles, a full configuration-dependent mass matrix -------------

CHAIN_TILTS = (-0.15, -0.05, 0.1)


def test_chain_conserves_energy_in_flight():
    """No damping and no input: before the first impact the energy (the reference's own T + V)
    of every sampled state is the initial one to 1e-9 (DOP853 at rtol 1e-11 drifts ~1e-12)."""
    chain = reference_chain.Chain()
    for tilt in CHAIN_TILTS:
        tr = compiled("chain").simulate("drop", tilt, sample_dt=0.01)
        flight = tr.samples[tr.samples[:, 0] < tr.event_times[0]]
        assert len(flight) > 50
        energy = np.array([chain.energy(row[1:11]) for row in flight])
        assert np.ptp(energy) < 1e-9, f"tilt {tilt}: energy drifts by {np.ptp(energy)}"


def test_chain_against_solve_ivp():
    """The drop at three tilts: impacts, event times and outcome against solve_ivp."""
    chain = reference_chain.Chain()
    for tilt in CHAIN_TILTS:
        ref = reference_chain.simulate(chain, tilt)
        assert_agrees(compiled("chain").simulate("drop", tilt), ref, f"chain tilt {tilt}")


def test_chain_feet_landing_together():
    """The chain is mirror-symmetric at tilt 0, so both feet land at once there (s* = 0, also
    where the reference's event order swaps); within 1e-9 of it the simulator follows the
    reference's merged or ordered impacts."""
    chain = reference_chain.Chain()
    left = reference_chain.simulate(chain, -1e-3, band=0.0)
    right = reference_chain.simulate(chain, 1e-3, band=0.0)
    assert sorted(left.events[0][1]) != sorted(right.events[0][1])
    level = reference_chain.simulate(chain, 0.0)
    assert sorted(level.events[0][1]) == [0, 1]
    assert_agrees(compiled("chain").simulate("drop", 0.0), level, "chain tilt 0")
    sides = set()
    for offset in (-1e-9, -1e-10, 1e-10, 1e-9):
        ref = reference_chain.simulate(chain, offset)
        if ref.band_margin < EDGE:
            continue
        assert_agrees(compiled("chain").simulate("drop", offset), ref, f"chain tilt {offset}")
        sides.add(offset > 0)
    assert sides == {False, True}
