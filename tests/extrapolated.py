"""Reference derivatives by extrapolated one-sided differences, with the error they carry.

:func:`biped_opt.piecewise.one_sided` fits the polynomial through f(x0 + side h0 / 2^k),
k < levels, and reads its slope at x0 (Richardson extrapolation). Its error has two parts, both
computed here rather than assumed:

- truncation: the difference between the last two extrapolants (the fit through all points and
  through all but the coarsest), the usual Richardson estimate;
- noise: the slope is a linear combination sum_k w_k f_k of the samples, so errors e_k of the
  samples (integration tolerance, an optimiser's stopping distance) reach it as at most
  sum_k |w_k| e_k; the weights grow like 1 / h0 and steeply with ``levels`` (5 levels from
  h0 = 1e-3: sum |w_k| = 1.5e5).

A test passes when the two numbers it compares differ by at most SAFETY times the sum of their
error estimates: estimates are sizes, not bounds, and the factor covers their misjudging.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from biped_opt.piecewise import one_sided

#: estimates are sizes, not bounds: a difference up to this many times their sum is agreement
SAFETY = 10.0


@dataclass(frozen=True)
class Extrapolated:
    limit: float
    derivative: float
    truncation: float  #: |last two extrapolants' slopes|
    noise: float  #: sum_k |w_k| e_k

    @property
    def error(self) -> float:
        return self.truncation + self.noise

    def tolerance(self, other_error: float = 0.0) -> float:
        """The largest difference from a value whose own error estimate is ``other_error``."""
        return SAFETY * (self.error + other_error)


def noise_weights(side: int, h0: float, levels: int) -> np.ndarray:
    """w_k with slope = sum_k w_k f(x0 + side h0 / 2^k) for the fit of one_sided."""
    offsets = side * h0 / 2.0 ** np.arange(levels)
    return np.array([np.polynomial.polynomial.polyfit(offsets, e, levels - 1)[1]
                     for e in np.eye(levels)])


def extrapolated(f: Callable[[float], float], x0: float, side: int, *, h0: float,
                 levels: int = 5, noise: Callable[[float, float], float] | float = 0.0
                 ) -> Extrapolated:
    """One-sided limit and slope of f at x0 with their error; ``noise`` is the error of one
    sample, a number or ``noise(x, f(x))``."""
    seen: dict[float, float] = {}

    def g(x: float) -> float:
        seen[x] = f(x)
        return seen[x]

    fit = one_sided(g, x0, side, h0=h0, levels=levels)
    errors = np.array([noise(x, v) if callable(noise) else float(noise)
                       for x, v in seen.items()])  # in the order one_sided sampled them
    amplified = float(np.abs(noise_weights(side, h0, levels)) @ errors)
    return Extrapolated(limit=fit.limit, derivative=fit.derivative,
                        truncation=fit.derivative_error, noise=amplified)


def relative_noise(rtol: float) -> Callable[[float, float], float]:
    """Sample error rtol max(1, |f|): an integrated quantity at relative tolerance rtol (its
    global error changes smoothly with x except where the step sequence changes, by about one
    step's local error)."""
    return lambda x, value: rtol * max(1.0, abs(value))


@dataclass(frozen=True)
class Central:
    derivative: np.ndarray | float
    error: np.ndarray | float  #: truncation (last two extrapolants) + noise, per component

    def tolerance(self, other_error: float = 0.0) -> np.ndarray | float:
        return SAFETY * (self.error + other_error)


def central(f: Callable[[float], object], x: float, h: float, *, rtol: float) -> Central:
    """Central differences at h, h/2, h/4 extrapolated twice (error O(h^6)); f may be
    vector-valued. Error: the change made by the last extrapolation, plus the samples' error
    rtol max(1, |f|) times the scheme's weights, sum |w_k| = 297 / (45 h)."""
    d, scale = [], 0.0
    for k in (h, h / 2, h / 4):
        up, down = np.asarray(f(x + k), dtype=float), np.asarray(f(x - k), dtype=float)
        scale = np.maximum(scale, np.maximum(np.abs(up), np.abs(down)))
        d.append((up - down) / (2 * k))
    r1 = [(4 * d[1] - d[0]) / 3, (4 * d[2] - d[1]) / 3]
    final = (16 * r1[1] - r1[0]) / 15
    noise = 297.0 / (45.0 * h) * rtol * np.maximum(1.0, scale)
    return Central(derivative=final, error=np.abs(final - r1[1]) + noise)
