"""The impact map as one loop over the active constraints (codegen/impact.py,
``IMPACT_LOOP_CONSTRAINTS``) instead of one unrolled branch per contact mode.

Two checks. (1) The rocking bar, whose block Da M^-1 Da^T is full (both ends move with the
pitch), generated both ways: the loop performs the unrolled branch's operations in the same
order, so every run is the same to the bit, simultaneous impacts at s = 0 and within 1e-9 of it
included. (2) The walker with four legs, which takes the loop by default, against the SciPy
comparator written from SYSTEMS.md without biped_opt (bench/system_reference.py with
bench/walker_model.py): outcomes to 1e-9, MODEL.md Sec. 7's bound for a correct implementation.
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from biped_opt.codegen import impact
from biped_opt.simulation.compiled import CompiledSystem
from biped_opt.systems.library import rocking_bar, walker

system_reference = importlib.import_module("bench.system_reference")
walker_model = importlib.import_module("bench.walker_model")

#: MODEL.md Sec. 7: a correct implementation reproduces the outcomes to 1e-9
OUTCOME_TOL = 1e-9


def test_the_loop_is_the_unrolled_impact_to_the_bit(monkeypatch):
    unrolled = CompiledSystem(rocking_bar())
    monkeypatch.setattr(impact, "IMPACT_LOOP_CONSTRAINTS", 1)
    looped = CompiledSystem(rocking_bar())
    assert looped.module is not unrolled.module
    assert "act = np.empty(" in looped.module.__loader__.get_source(looped.module.__name__)
    cases = [*np.linspace(-0.3, 0.3, 41), 0.0, 1e-9, -1e-9, 1e-12, -1e-12]
    for u in (0.0, 0.3):
        for s in cases:
            a = unrolled.simulate("drop", s, [u])
            b = looped.simulate("drop", s, [u])
            assert a.status == b.status and a.n_events == b.n_events >= 1
            assert np.array_equal(a.y_final, b.y_final), s
            assert np.array_equal(a.event_rows, b.event_rows), s


@pytest.mark.parametrize("s", [-0.2, -0.05, 0.03, 0.15])
def test_four_legs_take_the_loop_and_match_the_comparator(s):
    compiled = CompiledSystem(walker(4))
    assert "act = np.empty(" in compiled.module.__loader__.get_source(
        compiled.module.__name__)
    u = [0.3, -0.2, 0.5, 0.1, 0.0]
    tr = compiled.simulate("touchdown", s, u)
    ref = system_reference.simulate(walker_model.Walker(4, "coupled"), "touchdown", s, u)
    assert tr.success
    assert abs(tr.outcome - ref.outcome) <= OUTCOME_TOL
