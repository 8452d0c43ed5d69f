"""The library robots on point feet, solo12 (four) and bolt (two), from their URDFs (SYSTEMS.md
Sec. 3c) against Pinocchio: Eq. (1)'s terms at random states, the compiled field and impact map
in every contact mode, and whole drops against SciPy's DOP853 on Pinocchio's dynamics
(tests/systems/urdf_checks.py has the tolerances and why); and README's solo12 example. Each
compiled robot is shared by this module's tests (one worker)."""

from __future__ import annotations

import functools

import pytest

pytest.importorskip("pinocchio", reason="Pinocchio (pin in requirements-dev.txt) is the "
                                        "independent reference of these tests")

from biped_opt.simulation.compiled import CompiledSystem  # noqa: E402
from biped_opt.systems.files import load_system  # noqa: E402
from biped_opt.systems.library.robots import ROBOT_FILES  # noqa: E402
from tests.systems import urdf_checks as checks  # noqa: E402

#: robot -> its feet, read by hand from the URDF: the origins of the *_FOOT links
FEET = {"solo12": ("FL", "FR", "HL", "HR"), "bolt": ("FL", "FR")}


@functools.cache
def _compiled(name: str) -> CompiledSystem:
    return CompiledSystem(name)


@functools.cache
def _reference(name: str) -> checks.PinocchioRobot:
    contacts = [(f"{leg}_FOOT", (0.0, 0.0, 0.0), 0.0) for leg in FEET[name]]
    return checks.reference_for(load_system(name), ROBOT_FILES[name], contacts)


@pytest.fixture(params=list(FEET))
def robot(request):
    return request.param


def test_eq1_terms_are_pinocchio_s(robot):
    worst = checks.check_eq1_terms(load_system(robot), _reference(robot))
    assert max(worst.values()) < checks.TOL, worst


def test_field_and_impacts_in_every_mode_are_pinocchio_s(robot):
    modes = range(1 << len(FEET[robot]))
    worst = checks.check_generated_code(_compiled(robot), _reference(robot), modes)
    assert max(worst.values()) < checks.TOL, worst


@pytest.mark.parametrize("s", [0.05, -0.03, 0.0])
def test_drops_are_the_reference_s(robot, s):
    """Tilted, the feet land one by one; level, all together in one impact."""
    times, states, events = checks.check_drop(_compiled(robot), _reference(robot), s)
    if s == 0:
        assert events[0][0] == frozenset(range(len(FEET[robot])))
    else:
        assert len(events) >= 2 and all(len(entered) == 1 for entered, _l, _a in events)
    assert times < checks.DROP_TOL and states < checks.DROP_TOL, (times, states)


def test_the_readme_example_runs_and_is_the_library_s_solo12(tmp_path, capsys):
    """README "Your robot from URDF": its ten lines, as written there, build the library's
    solo12 (the same generated module, loaded from this module's compile) and print the drop's
    status, outcome and landings."""
    import re
    import runpy
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    (block,) = [b for b in re.findall(r"```python\n(.*?)```", text, re.S)
                if b.startswith("# solo.py")]
    assert len(block.strip().splitlines()) <= 12  # (ten lines of code and two comments)
    path = tmp_path / "solo.py"
    path.write_text(block)
    runpy.run_path(str(path), run_name="__main__")
    out = capsys.readouterr().out
    run = _compiled("solo12").simulate("drop", 0.05)
    assert out.strip() == f"OK {run.outcome} {[(e.t, e.mask_after) for e in run.contact_events]}"
    assert run.contact_events[0].mask_entered == 0b0010  # (FR_FOOT)
