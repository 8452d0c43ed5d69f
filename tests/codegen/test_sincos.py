"""The vector field's polynomial sine and cosine against libm."""

from __future__ import annotations

import math

import numpy as np

from biped_opt.codegen.runtime import sincos


def test_sincos_matches_libm_on_the_polynomial_range():
    """On |x| <= pi/4 (dense grid plus the ends and tiny angles) both polynomials agree with libm
    to 2.3e-16 relative for sin (about one ulp; libm itself is within half an ulp) and 2.3e-16
    absolute for cos, whose values lie in [0.7, 1]."""
    xs = np.concatenate([
        np.linspace(-math.pi / 4, math.pi / 4, 20001),
        [1e-300, -1e-12, 3e-8, math.pi / 4, -math.pi / 4],
    ])
    worst_sin = worst_cos = 0.0
    for x in xs:
        s, c = sincos(float(x))
        if x != 0.0:
            worst_sin = max(worst_sin, abs(s - math.sin(x)) / abs(math.sin(x)))
        worst_cos = max(worst_cos, abs(c - math.cos(x)))
    assert worst_sin <= 2.3e-16
    assert worst_cos <= 2.3e-16
    assert sincos(0.0) == (0.0, 1.0)


def test_sincos_falls_back_to_libm_beyond_the_range():
    """Beyond pi/4 (and for non-finite input) the values are libm's, bit for bit."""
    for x in (0.7854, -0.8, 1.0, 3.0, -10.0, 1e6):
        assert sincos(x) == (math.sin(x), math.cos(x))
    s, c = sincos(math.nan)
    assert math.isnan(s) and math.isnan(c)
