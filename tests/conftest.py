"""Shared fixtures and reference values for the test suite."""

from __future__ import annotations

import pytest

from biped_opt.model.params import BipedParams

#: MODEL.md Sec. 7: outcomes th(t_f) at default parameters (12 significant digits)
REFERENCE = {
    "R1": ("touchdown", +0.1, (2.0, 0.5, 0.0), 0.0703759886205),
    "R2": ("touchdown", -0.2, (2.0, 0.5, 0.0), -0.152911689618),
    "R3": ("liftoff", -1e-6, (1.5, 3.0, 0.0), 0.0262836775109),
    "R4": ("liftoff", +1e-6, (1.5, 3.0, 0.0), -0.00653232497802),
}


@pytest.fixture
def params() -> BipedParams:
    return BipedParams()
