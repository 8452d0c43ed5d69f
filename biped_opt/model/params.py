"""Physical parameters of the sagittal-plane biped (MODEL.md Sec. 2, paper Fig. 1).

Units are gravity units: lengths in body-lengths-ish units with g = 1, so times are in units of
sqrt(length / g). The defaults are the paper's.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields

import numpy as np
import numpy.typing as npt

from biped_opt.errors import InvalidParameterError

__all__ = ["BipedParams"]


@dataclass(frozen=True, kw_only=True)
class BipedParams:
    """Masses, geometry and leg spring of the biped; frozen and validated on construction."""

    mb: float = 1.0  # body mass [mass]
    Ib: float = 0.5  # body pitch inertia [mass length^2]
    mf: float = 1.0  # foot mass [mass]
    g: float = 1.0  # gravity [length / time^2]
    l0: float = 0.5  # leg rest length [length]
    w: float = 0.25  # half hip width: hips sit at +-w along the body [length]
    k: float = 27.0  # leg stiffness [force / length]
    c: float = 0.0  # leg damping [force time / length]
    gamma: float = 0.0  # coefficient of restitution at touchdown, 0 = plastic [-]
    _array: npt.NDArray[np.float64] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for f in fields(self):
            if not f.init:
                continue
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InvalidParameterError(f"{f.name} must be a real number, got {value!r}")
            if not math.isfinite(value):
                raise InvalidParameterError(f"{f.name} must be finite, got {value!r}")
            object.__setattr__(self, f.name, float(value))
        for name in ("mb", "Ib", "mf", "l0", "w", "k"):
            if getattr(self, name) <= 0.0:
                raise InvalidParameterError(f"{name} must be positive, got {getattr(self, name)}")
        for name in ("g", "c"):
            if getattr(self, name) < 0.0:
                raise InvalidParameterError(
                    f"{name} must be non-negative, got {getattr(self, name)}"
                )
        if not 0.0 <= self.gamma <= 1.0:
            raise InvalidParameterError(f"gamma must lie in [0, 1], got {self.gamma}")
        packed = np.array(
            [getattr(self, name) for name in PARAM_ORDER]
            + [1.0 / self.mb, 1.0 / self.Ib, 1.0 / self.mf],
            dtype=np.float64,
        )
        packed.flags.writeable = False
        object.__setattr__(self, "_array", packed)

    def as_array(self) -> npt.NDArray[np.float64]:
        """Parameters packed for the compiled kernels: :data:`PARAM_ORDER`, then the inverse
        masses 1/mb, 1/Ib, 1/mf (read-only, computed once)."""
        return self._array

    def as_dict(self) -> dict[str, float]:
        out = asdict(self)
        out.pop("_array")
        return out


#: Order of the parameters in :meth:`BipedParams.as_array` (the kernels index by position).
PARAM_ORDER = ("mb", "Ib", "mf", "g", "l0", "w", "k", "c", "gamma")
