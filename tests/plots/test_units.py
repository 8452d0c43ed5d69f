"""The units the pictures label (biped_opt.plots.units): the library's systems as their
documentation states them, anything else in model units, an outcome's unit from its
expression."""

from __future__ import annotations

import pytest

from biped_opt.plots.units import GRAVITY, MODEL, SI, units_of


@pytest.mark.parametrize("name, units", [
    ("biped", GRAVITY),               # MODEL.md Sec. 2: gravity units, g = 1
    ("walker2_coupled", GRAVITY),     # SYSTEMS.md Sec. 3: the biped's parameters
    ("walker3_decoupled_offsets", GRAVITY),
    ("rocking_bar", GRAVITY),         # SYSTEMS.md Sec. 2: g = 1
    ("chain7", GRAVITY),              # SYSTEMS.md Sec. 3a: g = 1
    ("quadruped", SI),                # its module: SI units, g = 9.81
    ("plain_ball", MODEL),            # a system of a user's
    ("walkers", MODEL),
])
def test_library_systems_have_the_units_their_documentation_states(name, units):
    assert units_of(name) is units


def test_a_file_is_in_model_units_whatever_its_name():
    """A system file may call its system "biped": its numbers are its own. A recording names
    its source: a library name (the node's parameter) counts as that system."""
    assert units_of("biped", "examples/biped.py") is MODEL
    assert units_of("walker2_coupled", "walker2") is GRAVITY
    assert units_of(None) is MODEL


def test_outcome_units_follow_the_coordinate():
    assert GRAVITY.outcome("th") == "rad"
    assert GRAVITY.outcome("th_dot") == "rad/time unit"
    assert GRAVITY.outcome("z1") == "length units"
    assert SI.outcome("roll_dot") == "rad/s" and SI.outcome("x_dot") == "m/s"
    assert GRAVITY.outcome("th + x") is None  # (an expression: unit not known)
    assert MODEL.outcome("th") is None
    assert MODEL.axes_note == "x, z and t in model units (the system states none)"
