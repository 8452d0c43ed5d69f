"""What every generated module imports: the kernel's status codes and event kinds, and
:func:`sincos`, the fast sine and cosine the generated vector fields call.

These are the vocabulary of the compiled kernel (:mod:`biped_opt.codegen.kernel`); the
simulation layer (:mod:`biped_opt.simulation`) turns the codes into its result types.
"""

from __future__ import annotations

import math

import numba as nb

from biped_opt._jit import HOT_PATH
from biped_opt.codegen.status import EVENT_CONTACT, EVENT_TERMINAL, Status

__all__ = ["EVENT_CONTACT", "EVENT_TERMINAL", "Status", "sincos"]


# Taylor coefficients of sin and cos. On |x| <= pi/4 the first omitted terms (x^17/17!, x^18/18!)
# are below 7e-17 relative, so the polynomials are as accurate as the libm functions (the tests
# check 2.3e-16 over the range).
_S3, _S5, _S7, _S9 = -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0
_S11, _S13, _S15 = -1.0 / 39916800.0, 1.0 / 6227020800.0, -1.0 / 1307674368000.0
_C2, _C4, _C6, _C8 = -0.5, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0
_C10, _C12 = -1.0 / 3628800.0, 1.0 / 479001600.0
_C14, _C16 = -1.0 / 87178291200.0, 1.0 / 20922789888000.0
_QUARTER_PI = math.pi / 4.0


@nb.njit(**HOT_PATH, inline="always")
def sincos(x: float) -> tuple[float, float]:
    """(sin x, cos x): polynomials in Estrin's form for |x| <= pi/4, libm beyond.

    The body pitch stays well inside pi/4 in every maneuver, and the vector field needs its sine
    and cosine at every evaluation. The libm calls sit on the evaluation's critical path (and
    force the compiler to spill registers around them); the polynomials' short dependency
    chains make the whole simulation ~8% faster.

    Written with one return and no early exit: the generated systems' DOP853 step has this
    body expanded into each of its stages, on its syntax tree with every argument bound to a
    name first (:func:`biped_opt.codegen.inline.expand`).
    """
    x2 = x * x
    x4 = x2 * x2
    x8 = x4 * x4
    s_lo = (_S3 + _S5 * x2) + x4 * (_S7 + _S9 * x2)
    s_hi = (_S11 + _S13 * x2) + x4 * _S15
    c_lo = (_C2 + _C4 * x2) + x4 * (_C6 + _C8 * x2)
    c_hi = (_C10 + _C12 * x2) + x4 * (_C14 + _C16 * x2)
    if abs(x) <= _QUARTER_PI:
        s = x + x * x2 * (s_lo + x8 * s_hi)
        c = 1.0 + x2 * (c_lo + x8 * c_hi)
    else:  # (NaN too)
        s = math.sin(x)
        c = math.cos(x)
    return s, c
