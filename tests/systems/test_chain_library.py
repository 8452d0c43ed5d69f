"""The library's planar chains (SYSTEMS.md Sec. 3a) against the user-system suite's chain and
against ``tests/simulation/user/reference_chain``, SciPy's solve_ivp on equations derived there
again from the links' velocity Jacobians and Christoffel symbols (it imports nothing from
biped_opt).

Each compiled system is built once per session (module-scoped fixtures); chain9, whose cold
compile is the longest (about 15 s), is checked in one test. The compiled chains with knees
(d = 7, 9) take about 35 s of compiling and comparing in all.
"""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from biped_opt.errors import InvalidInputError
from biped_opt.simulation.compiled import compile_system
from biped_opt.simulation.energy import DRIFT_TOLERANCE, energy_drift
from biped_opt.systems import load_system
from biped_opt.systems.description import SystemDescriptionError
from biped_opt.systems.files import library_size
from biped_opt.systems.library.chain import chain
from tests.simulation.test_user_suite import EDGE, USER, assert_agrees
from tests.simulation.user import reference_chain

#: near the simultaneous touchdown at s = 0: within the model's 1e-9 band the two impacts merge
#: (or not, by the guards' values there), as the reference decides with the same rule
OFFSETS = (-1e-9, -3e-10, -1e-10, 1e-10, 3e-10, 1e-9)


@pytest.fixture(scope="module")
def chain7():
    return compile_system("chain7")


@pytest.fixture(scope="module")
def reference7():
    return reference_chain.Chain(2)


# -- names, sizes, the description --------------------------------------------------------------

@pytest.mark.parametrize(("name", "d"), [("chain", 5), ("chain5", 5), ("chain7", 7),
                                         ("chain9", 9)])
def test_library_names_give_chains_of_d_coordinates(name, d):
    # (chain11 too, but its description alone costs ~10 s of the suite: its size by name only)
    assert library_size(name) == (2, d) and library_size("chain11") == (2, 11)
    system = load_system(name)
    assert len(system.q) == d
    assert system.coordinate_names[:5] == ("x", "z", "th", "a1", "a2")
    assert list(system.constraints) == ["foot1", "foot2"]
    assert list(system.maneuvers) == ["drop"]
    assert system.maneuvers["drop"].s_range == (-0.2, 0.2)


def test_bad_chain_sizes_are_refused():
    for segments in (0, 5, 1.5, True):
        with pytest.raises(SystemDescriptionError, match="segments must be an integer in 1..4"):
            chain(segments)
    with pytest.raises(SystemDescriptionError, match=r"chain5\|7\|9\|11"):
        load_system("chain6")


def test_nodes_take_the_chain_names():
    """A request's system field: chainD is a library name like walkerN, an unknown one is
    refused with the library's names listed."""
    from biped_opt.nodes.sources import Sources

    assert Sources().system("system", "chain9") == "chain9"
    with pytest.raises(InvalidInputError, match=r"unknown system 'chain8'.*chain5\|7\|9\|11"):
        Sources().system("system", "chain8")


@pytest.mark.parametrize("segments", [1, 2, 3])
def test_mass_matrix_and_energy_match_the_reference(segments):
    """The library's M (the kinetic energy's Hessian) and declared energy against the
    reference's (sums of m Jv^T Jv + I Jw^T Jw) at random states: equal to rounding (1e-12 on
    entries and energies of order 1)."""
    system = chain(segments)
    ref = reference_chain.Chain(segments)
    assert system.coordinate_names == tuple(reference_chain.coordinate_names(segments))
    assert system.defaults == {k: v for k, v in ref.values.items()}
    args = [*system.q, *system.dq, *system.p]
    mass = sp.lambdify(args, system.mass_matrix, "numpy")
    energy = sp.lambdify(args, system.energy, "numpy")
    p = list(system.defaults.values())
    rng = np.random.default_rng(segments)
    for _ in range(5):
        y = rng.uniform(-1.5, 1.5, 2 * ref.d)
        np.testing.assert_allclose(np.array(mass(*y, *p), dtype=float), ref.mass(y),
                                   rtol=0, atol=1e-12)
        assert energy(*y, *p) == pytest.approx(ref.energy(y), rel=0, abs=1e-12)


# -- d = 5: the user file's chain ----------------------------------------------------------------

def test_chain_is_the_user_files_chain():
    """chain() builds the user suite's chain: same names, parameters and maneuver, and the same
    trajectories (the same expressions, so the same generated code: 1e-12 leaves room for
    nothing but rounding)."""
    mine, theirs = compile_system("chain"), compile_system(str(USER / "chain.py"))
    assert mine.coordinates == theirs.coordinates
    assert mine.parameters == theirs.parameters
    assert mine.maneuvers == theirs.maneuvers
    assert mine.s_range("drop") == theirs.s_range("drop")
    a, b = mine.system.maneuvers["drop"], theirs.system.maneuvers["drop"]
    assert a.description == b.description
    for tilt in (-0.2, -0.05, 0.0, 1e-10, 0.1, 0.17):
        x, y = mine.simulate("drop", tilt), theirs.simulate("drop", tilt)
        assert x.status == y.status, tilt
        assert [e.mask_entered for e in x.contact_events] == \
            [e.mask_entered for e in y.contact_events], tilt
        np.testing.assert_allclose(x.event_times, y.event_times, rtol=0, atol=1e-12)
        assert x.outcome == pytest.approx(y.outcome, rel=0, abs=1e-12), tilt
        assert x.t_final == pytest.approx(y.t_final, rel=0, abs=1e-12), tilt


# -- d = 7 --------------------------------------------------------------------------------------

def test_chain7_against_solve_ivp(chain7, reference7):
    """Impacts, event times and outcome at 1e-9 (assert_agrees: the reference locates events to
    ~1e-11, the simulator to ~1e-12; the flights here last ~1 time unit with 1-4 impacts)."""
    for tilt in (-0.15, 0.05, 0.2):
        ref = reference_chain.simulate(reference7, tilt)
        assert ref.status == "OK"
        assert_agrees(chain7.simulate("drop", tilt), ref, f"chain7 tilt {tilt}")


def test_chain7_feet_landing_together(chain7, reference7):
    """Mirror-symmetric at s = 0: both feet land at once there, in one impact, and the middle
    link comes back level (th' = 0 at the apex). On either side one foot lands first, the left
    (foot1) for s > 0 (the tilt lowers it); within 1e-9 of 0 the simulator follows the
    reference's merged or ordered impacts on both sides."""
    level = reference_chain.simulate(reference7, 0.0)
    assert [sorted(j) for _, j in level.events][:1] == [[0, 1]]
    assert_agrees(chain7.simulate("drop", 0.0), level, "chain7 tilt 0")
    assert chain7.simulate("drop", 0.0).outcome == pytest.approx(0.0, abs=1e-12)
    _across_level(chain7, reference7, OFFSETS)


def test_chain7_keeps_its_energy_in_flight(chain7, reference7):
    """The energy check (``biped-opt systems chain7 --check``): no damping, no inputs, so the
    declared energy is constant up to the first impact to the integrator's accuracy
    (DRIFT_TOLERANCE: 1e-7 of its scale; a wrong Coriolis term drifts by 1e-3 and more), and
    the reference's own energy of the sampled states agrees (1e-9: the step's rtol 1e-11 over
    ~1 time unit)."""
    drift = energy_drift(chain7, "drop")
    assert drift.ok and drift.relative <= DRIFT_TOLERANCE, drift
    assert drift.samples > 100
    tr = chain7.simulate("drop", 0.13, sample_dt=0.01)
    flight = tr.samples[tr.samples[:, 0] < tr.event_times[0]]
    energy = np.array([reference7.energy(row[1:15]) for row in flight])
    assert np.ptp(energy) < 1e-9, np.ptp(energy)


# -- d = 9, in one test (its compile is the longest) ---------------------------------------------

def test_chain9_against_solve_ivp_and_its_energy():
    """chain9: the energy check; the drop at two tilts and at s = 0 against the reference at
    1e-9 (as chain7); and on each side of s = 0, 1e-9 away, the reference's first impact (one
    foot, the lower one, with merging off) and the simulator agreeing with the reference."""
    chain9, reference9 = compile_system("chain9"), reference_chain.Chain(3)
    drift = energy_drift(chain9, "drop")
    assert drift.ok and drift.relative <= DRIFT_TOLERANCE, drift
    for tilt in (-0.1, 0.0, 0.15):
        ref = reference_chain.simulate(reference9, tilt)
        assert ref.status == "OK"
        assert_agrees(chain9.simulate("drop", tilt), ref, f"chain9 tilt {tilt}")
    _across_level(chain9, reference9, (-3e-10, 3e-10, -1e-9, 1e-9))


def _across_level(compiled, reference, offsets) -> None:
    """Either side of s = 0, 1e-9 away, with merging off the reference's first impact is the
    lower foot's alone (foot1 for s > 0, foot2 for s < 0); at each offset the simulator has the
    reference's impacts (merged or ordered by the 1e-9 band), event times and outcome, on both
    sides (an offset that puts a guard near the band's edge is skipped)."""
    for offset, first in ((-1e-9, {1}), (1e-9, {0})):
        ordered = reference_chain.simulate(reference, offset, band=0.0)
        assert ordered.events[0][1] == first, offset
    sides = set()
    for offset in offsets:
        ref = reference_chain.simulate(reference, offset)
        if ref.band_margin < EDGE:
            continue
        assert_agrees(compiled.simulate("drop", offset), ref, f"{compiled.name} tilt {offset}")
        sides.add(offset > 0)
    assert sides == {False, True}
