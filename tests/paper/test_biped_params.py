from __future__ import annotations

import math

import pytest

from biped_opt.errors import BipedOptError, InvalidParameterError
from biped_opt.paper.biped import BipedParams, ContactMode, compiled_biped
from tests.paper.biped_physics import PARAM_ORDER, packed


def test_defaults_are_the_papers():
    p = BipedParams()
    assert (p.mb, p.Ib, p.mf, p.g, p.l0, p.w, p.k, p.c, p.gamma) == (
        1.0, 0.5, 1.0, 1.0, 0.5, 0.25, 27.0, 0.0, 0.0)
    values = packed(p)  # (as the hand-written reference model takes them)
    assert list(values[:9]) == [getattr(p, n) for n in PARAM_ORDER]
    assert list(values[9:]) == [1 / p.mb, 1 / p.Ib, 1 / p.mf]


def test_parameters_are_the_library_bipeds():
    """BipedParams names exactly the library biped's parameters, with its defaults."""
    assert compiled_biped().parameters == BipedParams().as_dict()


def test_frozen():
    with pytest.raises(AttributeError):
        BipedParams().k = 1.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [("mb", 0.0, "mb must be positive"), ("k", -1.0, "k must be positive"),
     ("c", -0.1, "c must be non-negative"), ("gamma", 1.5, "gamma must lie in"),
     ("l0", math.nan, "l0 must be finite"), ("w", "a", "w must be a real number")],
)
def test_validation_names_the_field(field, value, match):
    with pytest.raises(InvalidParameterError, match=match) as info:
        BipedParams(**{field: value})
    assert isinstance(info.value, (ValueError, BipedOptError))


def test_contact_modes_are_bit_masks_matching_the_interface_constants():
    assert [int(m) for m in ContactMode] == [0, 1, 2, 3]
    assert ContactMode.GROUND.active == (0, 1)
    assert ContactMode.from_active({1}) is ContactMode.RIGHT
