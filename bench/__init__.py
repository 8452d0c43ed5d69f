"""Benchmark of the biped simulator against independent comparators (issue 3).

Written only from the model specification (MODEL.md Secs. 2-4), never from :mod:`biped_opt`'s
model or kernels, so that agreement is evidence rather than self-consistency:

- :mod:`bench.biped_model`: the biped's equations of motion (1a), guards and resets (1b);
- :mod:`bench.solve_ivp_reference`: SciPy ``solve_ivp`` (DOP853, rtol 1e-11) with its own event
  location, the comparator of record;
- :mod:`bench.relaxation`: a fixed-step RK4 + bisection simulator in the style of the paper's
  simulation algorithm (dt = 1e-3, event strip 1e-5);
- :mod:`bench.run`: :func:`~bench.run.run_benchmark`, timing and accuracy on the same cases.
"""

from __future__ import annotations

__all__ = ["biped_model", "relaxation", "run", "solve_ivp_reference"]
