"""g1 (a library robot from its URDF, SYSTEMS.md Sec. 3c: a humanoid, its waist and arms locked,
each sole four collision spheres: dependent contacts) against Pinocchio: Eq. (1)'s terms at
random states, the compiled field and impact map in contact modes whose rows are independent,
and whole drops against SciPy's DOP853 on Pinocchio's dynamics, landing on the soles' corners
one by one and, level, on all eight at once (tests/systems/urdf_checks.py has the tolerances
and why). The compiled robot is shared by this module's tests (one worker)."""

from __future__ import annotations

import pytest

pytest.importorskip("pinocchio", reason="Pinocchio (pin in requirements-dev.txt) is the "
                                        "independent reference of these tests")

from biped_opt.simulation.compiled import CompiledSystem  # noqa: E402
from biped_opt.systems.files import load_system  # noqa: E402
from biped_opt.systems.library.robots import ROBOT_FILES  # noqa: E402
from tests.systems import urdf_checks as checks  # noqa: E402

NAME = "g1"
#: the soles' collision spheres, read by hand from the URDF (the same on both feet)
SPHERES = ((-0.05, 0.025, -0.03), (-0.05, -0.025, -0.03), (0.12, 0.03, -0.03),
           (0.12, -0.03, -0.03))
CONTACTS = [(f"{side}_ankle_roll_link", centre, 0.005) for side in ("left", "right")
            for centre in SPHERES]
#: modes with independent rows: none, each sphere alone, three of a sole, three of each
MODES = [0, *(1 << j for j in range(8)), 0b0111, 0b1110, 0b0111_0111, 0b1011_1101]


@pytest.fixture(scope="module")
def reference():
    return checks.reference_for(load_system(NAME), ROBOT_FILES[NAME], CONTACTS)


@pytest.fixture(scope="module")
def compiled():
    return CompiledSystem(NAME)


def test_eq1_terms_are_pinocchio_s(reference):
    worst = checks.check_eq1_terms(load_system(NAME), reference, count=2)
    assert max(worst.values()) < checks.TOL, worst


def test_field_and_impacts_are_pinocchio_s(compiled, reference):
    worst = checks.check_generated_code(compiled, reference, MODES, count=2)
    assert max(worst.values()) < checks.TOL, worst


@pytest.mark.parametrize("s", [0.002, 0.0])
def test_drops_are_the_reference_s(compiled, reference, s):
    """Tilted by 0.002, the spheres land one or two at a time, some lift again and all eight end
    on the ground (13 events, dependent sets among them); level, all eight land together in
    one impact (a contact set of rank 6). (A larger tilt rolls the robot off a sole's edge
    while that sole rests on a dependent set, which the reference does not model.)"""
    times, states, events = checks.check_drop(compiled, reference, s)
    if s == 0:
        assert events[0][0] == frozenset(range(8))
    else:
        assert len(events) >= 10 and events[-1][2] == frozenset(range(8))
    assert times < checks.DROP_TOL and states < checks.DROP_TOL, (times, states)
