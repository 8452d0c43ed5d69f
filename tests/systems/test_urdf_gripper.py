"""The importer's features against Pinocchio on ``urdf/gripper.urdf`` (a floating box, a slider,
a wrist on a skew axis, two fingers of which the second is a mimic of the first with multiplier
-1.5 and an offset, damping on three joints, inertias off their links' origins and turned, a
fixed tip merged into its finger, a collision box and sphere as contacts): Eq. (1)'s terms at
random states and the compiled field and impact map in contact modes with independent rows.
Pinocchio's model keeps the mimic joint as a joint of its own; the reference restricts it to
the mimic's line (pinocchio_reference.py), so the check covers the tree's sums over bodies
that one coordinate moves (tolerances: urdf_checks.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("pinocchio", reason="Pinocchio (pin in requirements-dev.txt) is the "
                                        "independent reference of these tests")

from biped_opt.simulation.compiled import CompiledSystem  # noqa: E402
from biped_opt.systems.urdf import system_from_urdf  # noqa: E402
from tests.systems import urdf_checks as checks  # noqa: E402

URDF = Path(__file__).resolve().parent / "urdf" / "gripper.urdf"
SPEC = f"{URDF}:contacts=base_link+tip"
#: the contacts, read by hand from the URDF: the box's bottom corners (its collision origin
#: 0.05 below the link's, half its height 0.05 lower), the tip sphere's centre and radius
CONTACTS = [("base_link", (0.15 * sx, 0.1 * sy, -0.1), 0.0)
            for sx, sy in ((1, 1), (1, -1), (-1, 1), (-1, -1))] + [("tip", (0.01, 0, 0), 0.01)]
#: modes with independent rows: none, each contact alone, three corners, three and the tip
MODES = [0, 1, 2, 4, 8, 16, 0b00111, 0b10111, 0b11110]


@pytest.fixture(scope="module")
def reference():
    return checks.reference_for(system_from_urdf(URDF, contacts="base_link+tip"), URDF,
                                CONTACTS)


def test_eq1_terms_are_pinocchio_s(reference):
    system = system_from_urdf(URDF, contacts="base_link+tip")
    assert system.robot.mimic == {"finger_b_joint": ("finger_a_joint", -1.5, 0.2)}
    worst = checks.check_eq1_terms(system, reference, count=5)
    assert max(worst.values()) < checks.TOL, worst


def test_field_and_impacts_are_pinocchio_s(reference):
    worst = checks.check_generated_code(CompiledSystem(SPEC), reference, MODES, count=3)
    assert max(worst.values()) < checks.TOL, worst
