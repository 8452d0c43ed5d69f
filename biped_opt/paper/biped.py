"""The paper's biped [1]_ in its own words (MODEL.md Secs. 2-4), over the library's ``biped``.

The biped is a system of the library like any other (``systems/library/biped.py``: the walker
with two legs ``left`` and ``right`` and inputs u1, u2, u12), simulated by the one compiled
simulator (:class:`~biped_opt.simulation.compiled.CompiledSystem`). What this module adds is the
paper's vocabulary, as its command-line flags, messages and figures use it:

- :class:`ContactMode`: the modes AIR, LEFT, RIGHT and GROUND as the bit masks over the
  constraints (left = bit 0, right = bit 1) that every trajectory of the biped carries;
- :class:`BipedParams`: the physical parameters with the paper's defaults, validated;
- :class:`Maneuver` (``touchdown``, ``liftoff``) and :func:`check_theta0`, the valid range of
  the initial pitch th0 (the s of the library's maneuver, whose declared range it reads);
- :func:`simulate` and :func:`simulate_batch` with the paper's arguments (maneuver, th0, inputs
  as (u1, u2, u12), params), and the fixed inputs of the paper's figures.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import enum
import functools
import math
from dataclasses import asdict, dataclass, fields

import numpy as np
import numpy.typing as npt

from biped_opt.errors import InvalidInputError, InvalidParameterError, quoted
from biped_opt.simulation import compiled as compiled_systems
from biped_opt.simulation.compiled import CompiledSystem, compiled_with
from biped_opt.simulation.options import DEFAULT_OPTIONS, SimulatorOptions
from biped_opt.simulation.trajectory import BatchResult, Trajectory

__all__ = [
    "BIPED",
    "BipedParams",
    "ContactMode",
    "FIXED_INPUTS",
    "INPUT_NAMES",
    "LEFT_BIT",
    "Maneuver",
    "RIGHT_BIT",
    "check_inputs",
    "check_theta0",
    "compiled_biped",
    "kernels_cached",
    "parse_maneuver",
    "simulate",
    "simulate_batch",
    "theta0_limit",
    "warm_up",
]

#: the library system that is the paper's biped
BIPED = "biped"
#: the biped's inputs in its order (single-stance forces u1, u2; double-stance torque u12): the
#: names of the command line's flags (tests check them against the description's)
INPUT_NAMES = ("u1", "u2", "u12")

LEFT_BIT = 1
RIGHT_BIT = 2


class ContactMode(enum.IntEnum):
    """Contact mode J of the biped (paper Sec. II-A): AIR = {}, LEFT = {1}, RIGHT = {2},
    GROUND = {1, 2}, as bit masks over the constraints (bit 0 = left foot, bit 1 = right). The
    values equal the constants of ``biped_opt_interfaces/msg/ContactMode``, so a mode crosses
    every boundary as its plain value."""

    AIR = 0
    LEFT = LEFT_BIT
    RIGHT = RIGHT_BIT
    GROUND = LEFT_BIT | RIGHT_BIT

    @property
    def active(self) -> tuple[int, ...]:
        """Indices (0-based) of the active constraints, i.e. the feet on the ground."""
        return tuple(j for j in range(2) if self.value >> j & 1)

    @classmethod
    def from_active(cls, active: set[int] | frozenset[int] | tuple[int, ...]) -> ContactMode:
        """Mode whose active constraints are ``active`` (0-based foot indices)."""
        mask = 0
        for j in active:
            if j not in (0, 1):
                raise ValueError(f"constraint index must be 0 or 1, got {j}")
            mask |= 1 << j
        return cls(mask)


@dataclass(frozen=True, kw_only=True)
class BipedParams:
    """Masses, geometry and leg spring of the biped (MODEL.md Sec. 2, paper Fig. 1) in gravity
    units (g = 1, so times are in units of sqrt(length / g)); the defaults are the paper's.
    Frozen and validated on construction; the names are the library biped's parameters."""

    mb: float = 1.0  # body mass [mass]
    Ib: float = 0.5  # body pitch inertia [mass length^2]
    mf: float = 1.0  # foot mass [mass]
    g: float = 1.0  # gravity [length / time^2]
    l0: float = 0.5  # leg rest length [length]
    w: float = 0.25  # half hip width: hips sit at +-w along the body [length]
    k: float = 27.0  # leg stiffness [force / length]
    c: float = 0.0  # leg damping [force time / length]
    gamma: float = 0.0  # coefficient of restitution at touchdown, 0 = plastic [-]

    def __post_init__(self) -> None:
        for f in fields(self):
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

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


DEFAULT_PARAMS = BipedParams()


class Maneuver(str, enum.Enum):
    """The two maneuvers of the paper (Sec. IV; MODEL.md Sec. 4): ``touchdown`` falls from
    rest to the body's nadir after the first touchdown, ``liftoff`` pushes off from double
    stance to the body's apex in the air. Each one's outcome is the body pitch at its end."""

    TOUCHDOWN = "touchdown"
    LIFTOFF = "liftoff"


def parse_maneuver(value: Maneuver | str) -> Maneuver:
    """The :class:`Maneuver` named by ``value``; raises InvalidInputError naming ``maneuver``."""
    if isinstance(value, Maneuver):
        return value
    try:
        return Maneuver(str(value).strip().lower())
    except ValueError:
        names = ", ".join(m.value for m in Maneuver)
        raise InvalidInputError(
            f"maneuver must be one of {names}; got {quoted(value)}") from None


#: the paper's inputs of its fixed-input figures (MODEL.md Sec. 5): (u1, u2, u12)
FIXED_INPUTS = {
    "touchdown": (2.0, 0.5, 0.0),
    "liftoff": (1.5, 3.0, 0.0),
}


def compiled_biped(params: BipedParams | None = None) -> CompiledSystem:
    """The library biped compiled, with ``params`` (default the paper's; one per process and
    parameter set)."""
    if params is None or params == DEFAULT_PARAMS:
        return _default()
    return compiled_with(BIPED, params.as_dict())


@functools.cache
def _default() -> CompiledSystem:  # (found without hashing parameters: on every trajectory)
    return compiled_with(BIPED)


@functools.cache
def _limits() -> dict[str, float]:
    c = compiled_biped()
    out = {}
    for m in Maneuver:
        lo, hi = c.s_range(m.value)
        if lo != -hi:  # (the paper's ranges are symmetric: |th0| <= limit)
            raise RuntimeError(f"the biped's {m.value} range {(lo, hi)} is not symmetric")
        out[m.value] = hi
    return out


def theta0_limit(maneuver: Maneuver | str) -> float:
    """The largest |th0| of ``maneuver``'s valid range (beyond it the legs splay and other
    mode sequences appear): 0.25 for touchdown, 0.3 for liftoff, as the biped declares them."""
    return _limits()[parse_maneuver(maneuver).value]


def check_theta0(maneuver: Maneuver | str, theta0: float) -> float:
    """theta0 as a float, validated against the maneuver's range; the error names ``theta0``."""
    limits = _limits()
    limit = limits.get(maneuver) if type(maneuver) is str else None
    if limit is None:
        limit = limits[parse_maneuver(maneuver).value]
    if type(theta0) is float and abs(theta0) <= limit:  # the common case (NaN fails)
        return theta0
    try:
        value = float(theta0)
    except (TypeError, ValueError):
        raise InvalidInputError(f"theta0 must be a number, got {theta0!r}") from None
    if not math.isfinite(value):
        raise InvalidInputError(f"theta0 must be finite, got {value}")
    if abs(value) > limit:
        raise InvalidInputError(
            f"theta0 = {value} is outside the valid range |theta0| <= {limit} "
            f"of the {parse_maneuver(maneuver).value} maneuver"
        )
    return value


def check_inputs(inputs: npt.ArrayLike | None) -> npt.NDArray[np.float64]:
    """Inputs as (u1, u2, u12), zero-padded; the error names the offending input."""
    return compiled_biped().input_vector(inputs)


def simulate(
    maneuver: Maneuver | str,
    theta0: float,
    inputs: npt.ArrayLike | None = None,
    *,
    params: BipedParams | None = None,
    options: SimulatorOptions = DEFAULT_OPTIONS,
    sample_dt: float | None = None,
) -> Trajectory:
    """Simulate ``maneuver`` from initial pitch ``theta0`` with inputs (u1, u2, u12) (fewer are
    zero-padded): :meth:`CompiledSystem.simulate` of the library biped.

    ``sample_dt`` requests dense samples on the grid t = k sample_dt (plus the events and t_f).
    The trajectory's ``status`` says how it ended; this function raises only for invalid
    arguments. Contact modes in the result are masks that :class:`ContactMode` names.
    """
    name = maneuver if type(maneuver) is str else parse_maneuver(maneuver).value
    th = check_theta0(name, theta0)
    biped = _default() if params is None else compiled_biped(params)
    return biped.simulate(name, th, inputs, options=options, sample_dt=sample_dt)


def simulate_batch(
    maneuver: Maneuver | str,
    theta0: npt.ArrayLike,
    inputs: npt.ArrayLike | None = None,
    *,
    params: BipedParams | None = None,
    options: SimulatorOptions = DEFAULT_OPTIONS,
) -> BatchResult:
    """Simulate ``maneuver`` for every th0 in ``theta0`` (shape (N,)) in parallel compiled
    threads; ``inputs`` is one input vector for all ((3,) or shorter) or one per angle (N, <=3).
    """
    name = parse_maneuver(maneuver).value
    try:
        th = np.atleast_1d(np.asarray(theta0, dtype=np.float64))
    except (TypeError, ValueError):
        raise InvalidInputError(f"theta0 must be numbers, got {theta0!r}") from None
    if th.ndim != 1:
        raise InvalidInputError(f"theta0 must be a 1-D array of angles, got shape {th.shape}")
    bad = np.flatnonzero(~(np.abs(th) <= theta0_limit(name)))  # NaN fails the comparison too
    if bad.size:
        check_theta0(name, float(th[bad[0]]))  # raises, naming theta0 and the valid range
    biped = _default() if params is None else compiled_biped(params)
    return biped.simulate_batch(name, th, inputs, options=options)


def kernels_cached() -> bool:
    """True when the biped's compiled kernels are on disk for the current sources."""
    return compiled_systems.kernels_cached(BIPED)


def warm_up() -> float:
    """Compile (or load) the biped's simulation kernels now; the seconds it took (~15-20 s in a
    fresh checkout, well under one once cached)."""
    return compiled_systems.warm_up(BIPED)
