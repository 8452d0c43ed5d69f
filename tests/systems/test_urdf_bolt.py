"""bolt (a library robot from its URDF, SYSTEMS.md Sec. 3c) against Pinocchio: Eq. (1)'s terms
at random states, the compiled field and impact map in every contact mode, and whole drops
against SciPy's DOP853 on Pinocchio's dynamics (tests/systems/urdf_checks.py has the
tolerances and why). The compiled robot is shared by this module's tests (one worker)."""

from __future__ import annotations

import pytest

pytest.importorskip("pinocchio", reason="Pinocchio (pin in requirements-dev.txt) is the "
                                        "independent reference of these tests")

from biped_opt.simulation.compiled import CompiledSystem  # noqa: E402
from biped_opt.systems.files import load_system  # noqa: E402
from biped_opt.systems.library.robots import ROBOT_FILES  # noqa: E402
from tests.systems import urdf_checks as checks  # noqa: E402

NAME = "bolt"
#: the feet, read by hand from the URDF: the origins of the *_FOOT links
CONTACTS = [(f"{leg}_FOOT", (0.0, 0.0, 0.0), 0.0) for leg in ("FL", "FR")]


@pytest.fixture(scope="module")
def reference():
    return checks.reference_for(load_system(NAME), ROBOT_FILES[NAME], CONTACTS)


@pytest.fixture(scope="module")
def compiled():
    return CompiledSystem(NAME)


def test_eq1_terms_are_pinocchio_s(reference):
    worst = checks.check_eq1_terms(load_system(NAME), reference)
    assert max(worst.values()) < checks.TOL, worst


def test_field_and_impacts_in_every_mode_are_pinocchio_s(compiled, reference):
    worst = checks.check_generated_code(compiled, reference, range(4))
    assert max(worst.values()) < checks.TOL, worst


@pytest.mark.parametrize("s", [0.05, -0.03, 0.0])
def test_drops_are_the_reference_s(compiled, reference, s):
    """Tilted, the feet land one by one; level, all together in one impact."""
    times, states, events = checks.check_drop(compiled, reference, s)
    if s == 0:
        assert events[0][0] == frozenset(range(2))
    else:
        assert len(events) >= 2 and all(len(entered) == 1 for entered, _l, _a in events)
    assert times < checks.DROP_TOL and states < checks.DROP_TOL, (times, states)
