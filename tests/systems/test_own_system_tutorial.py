"""The "Your own system" tutorial's example runs as written: the file builds, compiles and
simulates, and its outcome is checked against the same maneuver run on the description's
NumPy evaluation of Eq. (1) with SciPy (an implementation that shares only the description)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

TUTORIAL = Path(__file__).resolve().parents[2] / "docs" / "tutorials" / "own_system.md"


def _blocks() -> list[str]:
    text = TUTORIAL.read_text()
    start = text.index("## Your own system")
    section = text[start:text.index("\n## ", start)]  # (to the next section)
    return re.findall(r"```python\n(.*?)```", section, re.S)


def test_the_example_file_is_short_and_runs(tmp_path, monkeypatch, capsys):
    system_file, usage = _blocks()
    assert len(system_file.splitlines()) < 40
    (tmp_path / "hopper.py").write_text(system_file)
    monkeypatch.chdir(tmp_path)
    exec(compile(usage, "tutorial usage", "exec"), {})  # noqa: S102 - the tutorial's own code
    status, *_ = capsys.readouterr().out.split()
    assert status == "OK"


def test_the_example_agrees_with_an_independent_integration(tmp_path):
    """The first touchdown of the hopper: event time and state from the compiled kernel and
    from SciPy's DOP853 on the NumPy evaluation (rtol 1e-12), to 1e-9."""
    from scipy.integrate import solve_ivp

    from biped_opt.simulation.compiled import compile_system
    from biped_opt.systems import derive, load_system

    (tmp_path / "hopper.py").write_text(_blocks()[0])
    system = load_system(str(tmp_path / "hopper.py"))
    numeric = derive(system).numeric(k=60.0)
    y0, _mode = numeric.initial_state("bounce", 0.3)
    d = numeric.ndof

    def air(_t, y):
        acc = np.linalg.solve(numeric.mass_matrix(y[:d]),
                              numeric.forces(y[:d], y[d:], np.array([0.2]), 0))
        return np.concatenate([y[d:], acc])

    def touchdown(_t, y):
        return numeric.constraints(y[:d])[0]

    touchdown.terminal, touchdown.direction = True, -1
    ref = solve_ivp(air, (0, 10), y0, method="DOP853", rtol=1e-12, atol=1e-13,
                    events=touchdown)
    tr = compile_system(str(tmp_path / "hopper.py"), k=60.0).simulate("bounce", 0.3,
                                                                      {"push": 0.2})
    assert tr.event_times[0] == pytest.approx(ref.t_events[0][0], abs=1e-9)
    np.testing.assert_allclose(tr.events[0].state_before, ref.y_events[0][0], atol=1e-9)
