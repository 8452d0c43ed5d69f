"""Numba compilation flags of the simulator's hot path, in one place.

- ``cache``: compiled code is kept on disk (``__pycache__``), so the compile is paid once.
- ``error_model="numpy"``: a float division by zero gives inf or nan, as in NumPy, instead of a
  checked branch that raises; the integrator rejects non-finite steps itself.

No ``fastmath``, not even ``contract`` (fusing a * b + c into one multiply-add): a fused sum of
mirror-image terms, such as the two legs' torques, no longer cancels exactly, and the simulation
from th0 = 0 must stay exactly symmetric (outcome 0.0, MODEL.md Sec. 3). Measured with the
symmetric sums kept unfused, it would make a simulation only ~1% faster.
"""

from __future__ import annotations

from typing import Literal, TypedDict

__all__ = ["HOT_PATH"]


class _JitFlags(TypedDict):
    """The keywords of ``numba.njit`` that ``HOT_PATH`` sets, typed as ``njit`` declares them."""

    cache: bool
    error_model: Literal["python", "numpy"]


#: keyword arguments of ``numba.njit`` for every compiled function of the hot path
HOT_PATH: _JitFlags = {"cache": True, "error_model": "numpy"}
