"""Integrator and bookkeeping settings of the hybrid simulator, shared by every system."""

from __future__ import annotations

import math
from dataclasses import dataclass

from biped_opt.errors import InvalidParameterError

__all__ = ["SimulatorOptions", "DEFAULT_OPTIONS"]


@dataclass(frozen=True, kw_only=True)
class SimulatorOptions:
    """Integrator and bookkeeping settings of the hybrid simulator."""

    rtol: float = 1e-11  # relative tolerance of the DOP853 error estimate
    atol: float = 1e-12  # absolute tolerance
    h_max: float = 0.5  # largest step [time]; the RK stages probe guards inside each step
    t_end: float = 10.0  # time horizon [time]
    max_events: int = 16  # contact events allowed before giving up

    def __post_init__(self) -> None:
        for name in ("rtol", "atol", "h_max", "t_end"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InvalidParameterError(f"{name} must be a positive number, got {value!r}")
        if self.rtol < 1e-15:
            raise InvalidParameterError(f"rtol must be at least 1e-15, got {self.rtol}")
        if not isinstance(self.max_events, int) or self.max_events < 1:
            raise InvalidParameterError(
                f"max_events must be a positive integer, got {self.max_events!r}"
            )


DEFAULT_OPTIONS = SimulatorOptions()
