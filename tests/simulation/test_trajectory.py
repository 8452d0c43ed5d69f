"""The one result type of every simulation: typed status and events by constraint name, derived
from the kernel's rows, the same for the biped's API and any compiled system."""

from __future__ import annotations

import numpy as np
import pytest

import biped_opt
from biped_opt.codegen.runtime import EVENT_CONTACT, EVENT_TERMINAL, Status
from biped_opt.paper.biped import ContactMode
from biped_opt.simulation.compiled import SystemTrajectory, compile_system
from biped_opt.simulation.trajectory import BatchResult, Trajectory, constraint_names


@pytest.fixture(scope="module")
def bar():
    return compile_system("rocking_bar")


def test_one_type_for_the_biped_and_any_system(bar):
    biped = biped_opt.simulate("touchdown", 0.1, (2.0, 0.5, 0.0))
    system = bar.simulate("drop", 0.1)
    assert type(biped) is type(system) is Trajectory is SystemTrajectory is biped_opt.Trajectory
    assert biped.status is Status.OK and system.status is Status.OK
    assert biped.system == "biped" and system.system == "rocking_bar"
    batch = biped_opt.simulate_batch("touchdown", [0.1], (2.0, 0.5))
    assert type(batch) is type(bar.simulate_batch("drop", [0.1])) is BatchResult


def test_events_are_the_rows_by_constraint_name(bar):
    """Every typed field is the kernel's row read by its layout; names follow the declared
    constraint order (the bar: left, right)."""
    tr = bar.simulate("drop", 0.1)
    assert tr.constraints == ("left", "right")
    assert len(tr.events) == len(tr.event_rows) == tr.n_events + 1  # the terminal row last
    n = len(tr.y_final)
    for e, row in zip(tr.events, tr.event_rows):
        assert e.t == row[0]
        assert (e.kind == "terminal") == (row[1] == EVENT_TERMINAL)
        assert (e.mask_entered, e.mask_left, e.mask_before, e.mask_after) == tuple(
            int(v) for v in row[2:6])
        assert e.entered == constraint_names(int(row[2]), tr.constraints)
        assert e.mode_after == frozenset(constraint_names(int(row[5]), tr.constraints))
        np.testing.assert_array_equal(e.state_before, row[6:6 + n])
        np.testing.assert_array_equal(e.state_after, row[6 + n:6 + 2 * n])
    assert [e.entered for e in tr.contact_events] == [("left",), ("right",)]
    assert all(row[1] == EVENT_CONTACT for row in tr.event_rows[: tr.n_events])
    assert tr.event_times == tuple(e.t for e in tr.contact_events)
    assert tr.mode_sequence == tr.modes == (0, 0, 0)  # each impact bounces: back in the air
    segments = tr.segments
    assert [s.t_start for s in segments] == [0.0, *tr.event_times]
    assert [s.t_end for s in segments] == [*tr.event_times, tr.t_final]
    assert all(s.mode == frozenset() for s in segments)


def test_the_biped_words_are_one_conversion_away():
    """Masks over the biped's constraints (left = bit 0 = leg 1) are ContactMode values."""
    tr = biped_opt.simulate("liftoff", 0.1, (1.5, 3.0, 0.0))
    assert tr.constraints == ("left", "right")
    assert [ContactMode(m) for m in tr.mode_sequence] == [ContactMode.GROUND, ContactMode.LEFT,
                                                          ContactMode.AIR]
    first, second = tr.contact_events
    assert first.kind == second.kind == "liftoff"
    assert first.left == first.liftoff == ("right",) and ContactMode(first.mask_left).active == (1,)
    assert first.mode_before == frozenset({"left", "right"}) and first.mode_after == {"left"}
    assert not first.simultaneous
    at_zero = biped_opt.simulate("liftoff", 0.0, (1.5, 3.0, 0.0))
    (both,) = at_zero.contact_events
    assert both.simultaneous and both.left == ("left", "right")
    # the biped's names for the same values
    assert tr.theta0 == tr.s == 0.1 and tr.state_final is tr.y_final
    assert tr.outcome == tr.q_final[2] and tr.nevents == tr.n_events == 2
    np.testing.assert_array_equal(np.concatenate([tr.q_final, tr.qdot_final]), tr.y_final)


def test_messages_name_the_budget_where_the_system_sets_one(bar):
    """A run that used up its budget says so, naming the budget and the last events: the
    biped's the same as every system's (one simulator)."""
    tr = bar.simulate("drop", 0.1, options=biped_opt.SimulatorOptions(max_events=1))
    assert tr.status is Status.MAX_EVENTS and not tr.success
    assert tr.message.startswith("1 contact events, the maneuver's event budget, were used up")
    assert tr.message.endswith("last events: t = 1.3784653 touchdown left -> mode air")
    biped = biped_opt.simulate("touchdown", 0.1, (2.0, 0.5),
                               options=biped_opt.SimulatorOptions(max_events=1))
    assert biped.status is Status.MAX_EVENTS
    assert biped.message.startswith("1 contact events, the maneuver's event budget, were used up")
    assert biped.message.endswith("touchdown left -> mode left")
    assert len(biped.event_rows) == biped.n_events == 1  # no terminal row without the end


def test_batches_read_as_single_runs(bar):
    grid = np.array([-0.1, 0.0, 0.1])
    batch = bar.simulate_batch("drop", grid)
    assert len(batch) == 3 and batch.success.all()
    for k, s in enumerate(grid):
        tr = bar.simulate("drop", s)
        assert batch.outcome[k] == tr.outcome and batch.mode_sequence(k) == tr.mode_sequence
        np.testing.assert_array_equal(batch.event_times(k), tr.event_times)
        assert batch.statuses()[k] is tr.status and batch.nfev[k] == tr.nfev
    # the dictionary this type replaced: the same arrays under the same keys
    assert batch["outcome"] is batch.outcome and batch["events"] is batch.event_rows
    with pytest.raises(KeyError):
        batch["success"]  # (a method's result, not a field)
    biped = biped_opt.simulate_batch("touchdown", [0.1, -0.1], (2.0, 0.5))
    assert biped.theta0 is biped.s and biped.state_final is biped.y_final
    np.testing.assert_array_equal(biped.outcome, biped.y_final[:, 2])  # th(t_f)
