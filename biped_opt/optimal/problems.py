"""Optimal-control problems of the paper as values: costs (14), (15) and MODEL.md Sec. 5 defaults.

A problem fixes the maneuver, which inputs are decided and which are held fixed, the decisions'
bounds, the target pitch th* and the input weights alpha. Its running cost is

    c(th0, u) = (th_f(th0, u) - th*)^2 + sum_i alpha_i u_i^2        (Eqs. (14), (15) of [1]_)

summed over the decision inputs only (fixed inputs carry no weight, as in Eq. (15) where u1, u2
are fixed and only u12 is penalised). Three problems ship with MODEL.md's numbers:

- :func:`touchdown_problem`: decisions u1, u2 in [-0.5, 1.5], th* = -0.1, alpha = (3e-4, 3e-3);
- :func:`liftoff_problem`: decision u12 in [-0.5, 0.5], u1 = 1.5 and u2 = 3 fixed, th* = 0.01,
  alpha = 0.01;
- :func:`liftoff_variant_problem`: u12 = 0 fixed, decisions the single-stance forces u1, u2 in
  [0, 3], th* = -0.02, alpha = (1e-5, 2e-5) (MODEL.md Sec. 6: its optimal value jumps).

Every field can be overridden with :func:`dataclasses.replace` or the factories' keyword
arguments; the constructor validates and names the offending field.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from biped_opt.errors import InvalidInputError, InvalidParameterError
from biped_opt.hybrid.simulate import DEFAULT_OPTIONS, INPUT_NAMES, SimulatorOptions
from biped_opt.maneuvers import Maneuver, parse_maneuver
from biped_opt.model.modes import ContactMode
from biped_opt.model.params import BipedParams

__all__ = [
    "INPUT_NAMES",
    "INPUT_MODES",
    "OptimalControlProblem",
    "touchdown_problem",
    "liftoff_problem",
    "liftoff_variant_problem",
    "PROBLEMS",
    "get_problem",
]

Array = npt.NDArray[np.float64]

#: the contact mode in which each input acts (MODEL.md Sec. 2, force coupling)
INPUT_MODES = {"u1": ContactMode.LEFT, "u2": ContactMode.RIGHT, "u12": ContactMode.GROUND}


#: largest cost term allowed: its square must not overflow a double (sqrt of the largest one)
COST_LIMIT = math.sqrt(sys.float_info.max)


def _real(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InvalidParameterError(f"{name} must be a real number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise InvalidParameterError(f"{name} must be finite, got {value!r}")
    return out


@dataclass(frozen=True, kw_only=True)
class OptimalControlProblem:
    """Minimise c(th0, u) = (th_f - th*)^2 + sum_i alpha_i u_i^2 over the decision inputs.

    Eqs. (4)-(6), (14), (15) of [1]_. ``decisions`` names the decided inputs (a subset of
    u1, u2, u12); ``bounds`` and ``alphas`` are per decision, in the same order.
    ``fixed_inputs`` gives (u1, u2, u12) for the inputs that are not decided (entries of decision
    inputs are ignored).
    """

    name: str = "custom"  # label for reports
    maneuver: Maneuver = Maneuver.TOUCHDOWN
    decisions: tuple[str, ...] = ("u1", "u2")
    fixed_inputs: tuple[float, float, float] = (0.0, 0.0, 0.0)  # (u1, u2, u12) [force, torque]
    bounds: tuple[tuple[float, float], ...] = ((-0.5, 1.5), (-0.5, 1.5))  # per decision
    theta_star: float = -0.1  # target outcome th* [rad]
    alphas: tuple[float, ...] = (3e-4, 3e-3)  # input weights, per decision [1 / force^2]
    params: BipedParams = field(default_factory=BipedParams)
    options: SimulatorOptions = DEFAULT_OPTIONS

    def __post_init__(self) -> None:
        try:
            maneuver = parse_maneuver(self.maneuver)
        except InvalidInputError as exc:
            raise InvalidParameterError(f"maneuver: {exc}") from None
        object.__setattr__(self, "maneuver", maneuver)
        if not isinstance(self.name, str) or not self.name:
            raise InvalidParameterError(f"name must be a non-empty string, got {self.name!r}")
        decisions = tuple(self.decisions) if not isinstance(self.decisions, str) else ()
        if not decisions or any(d not in INPUT_NAMES for d in decisions):
            raise InvalidParameterError(
                f"decisions must be a non-empty subset of {', '.join(INPUT_NAMES)}, "
                f"got {self.decisions!r}"
            )
        if len(set(decisions)) != len(decisions):
            raise InvalidParameterError(f"decisions must not repeat, got {self.decisions!r}")
        object.__setattr__(self, "decisions", decisions)
        fixed = tuple(self.fixed_inputs)
        if len(fixed) != 3:
            raise InvalidParameterError(
                f"fixed_inputs must be (u1, u2, u12), got {self.fixed_inputs!r}"
            )
        object.__setattr__(
            self, "fixed_inputs", tuple(_real(f"fixed_inputs[{n}]", v) for n, v in
                                        zip(INPUT_NAMES, fixed))
        )
        bounds = tuple(self.bounds)
        if len(bounds) != len(decisions):
            raise InvalidParameterError(
                f"bounds must give one (lower, upper) per decision {decisions}, "
                f"got {self.bounds!r}"
            )
        checked = []
        for d, b in zip(decisions, bounds):
            try:
                lo, hi = b
            except (TypeError, ValueError):
                raise InvalidParameterError(
                    f"bounds[{d}] must be a (lower, upper) pair, got {b!r}"
                ) from None
            lo, hi = _real(f"bounds[{d}] lower", lo), _real(f"bounds[{d}] upper", hi)
            if not lo < hi:
                raise InvalidParameterError(f"bounds[{d}] must have lower < upper, got {b!r}")
            checked.append((lo, hi))
        object.__setattr__(self, "bounds", tuple(checked))
        alphas = tuple(self.alphas)
        if len(alphas) != len(decisions):
            raise InvalidParameterError(
                f"alphas must give one weight per decision {decisions}, got {self.alphas!r}"
            )
        alphas = tuple(_real(f"alphas[{d}]", a) for d, a in zip(decisions, alphas))
        for d, a in zip(decisions, alphas):
            if a < 0.0:
                raise InvalidParameterError(f"alphas[{d}] must be non-negative, got {a}")
        object.__setattr__(self, "alphas", alphas)
        object.__setattr__(self, "theta_star", _real("theta_star", self.theta_star))
        # every term of the cost must be a number the solver can also square (its fits and
        # SciPy's interpolation do): a weight of 1e308 overflowed to inf and failed in lstsq
        for d, a, (lo, hi) in zip(decisions, alphas, checked):
            if not a * max(lo * lo, hi * hi) <= COST_LIMIT:
                raise InvalidParameterError(
                    f"alphas[{d}] = {a:g} with bounds [{lo:g}, {hi:g}] makes the input cost "
                    f"alpha {d}^2 exceed {COST_LIMIT:.3g}")
        if not abs(self.theta_star) <= 0.5 * math.sqrt(COST_LIMIT):
            raise InvalidParameterError(
                f"theta_star = {self.theta_star:g} makes the terminal cost exceed "
                f"{COST_LIMIT:.3g}")
        if not isinstance(self.params, BipedParams):
            raise InvalidParameterError(f"params must be BipedParams, got {self.params!r}")
        if not isinstance(self.options, SimulatorOptions):
            raise InvalidParameterError(f"options must be SimulatorOptions, got {self.options!r}")

    # --- accessors ---------------------------------------------------------------------------
    def index(self, name: str) -> int:
        """Position of decision ``name`` in :attr:`decisions`."""
        try:
            return self.decisions.index(name)
        except ValueError:
            raise InvalidInputError(
                f"{name!r} is not a decision input of the {self.name} problem "
                f"(decisions: {', '.join(self.decisions)})"
            ) from None

    def bound(self, name: str) -> tuple[float, float]:
        return self.bounds[self.index(name)]

    def alpha(self, name: str) -> float:
        return self.alphas[self.index(name)]

    def default_decision(self, name: str) -> float:
        """The value a decision takes when it cannot affect the outcome: the bound point nearest 0.

        Its cost is then alpha u^2 alone, minimised there (0 whenever the bounds contain 0).
        """
        lo, hi = self.bound(name)
        return min(max(0.0, lo), hi)

    # --- overrides ---------------------------------------------------------------------------
    def with_alpha(self, name: str, value: float) -> OptimalControlProblem:
        """Copy with the weight of decision ``name`` replaced."""
        alphas = list(self.alphas)
        alphas[self.index(name)] = value
        return dataclasses.replace(self, alphas=tuple(alphas))

    def with_bounds(self, name: str, lower: float, upper: float) -> OptimalControlProblem:
        """Copy with the bounds of decision ``name`` replaced."""
        bounds = list(self.bounds)
        bounds[self.index(name)] = (lower, upper)
        return dataclasses.replace(self, bounds=tuple(bounds))

    # --- cost ----------------------------------------------------------------------------------
    def inputs(self, decision_values: Mapping[str, float] | None = None) -> Array:
        """Full input vector (u1, u2, u12): fixed inputs, decisions from ``decision_values``.

        Decisions missing from ``decision_values`` take :meth:`default_decision`.
        """
        u = np.array(self.fixed_inputs, dtype=np.float64)
        values = dict(decision_values or {})
        for d in self.decisions:
            u[INPUT_NAMES.index(d)] = values.pop(d, self.default_decision(d))
        if values:
            raise InvalidInputError(
                f"{', '.join(values)} not decision inputs of the {self.name} problem"
            )
        return u

    def cost(self, outcome: npt.ArrayLike, inputs: npt.ArrayLike) -> Array | float:
        """Eqs. (14), (15): (th_f - th*)^2 + sum over decisions of alpha_i u_i^2.

        ``inputs`` is (u1, u2, u12), shape (3,) or (N, 3); ``outcome`` th_f, scalar or (N,).
        """
        th_f = np.asarray(outcome, dtype=np.float64)
        u = np.asarray(inputs, dtype=np.float64)
        c = (th_f - self.theta_star) ** 2
        for d, a in zip(self.decisions, self.alphas):
            c = c + a * u[..., INPUT_NAMES.index(d)] ** 2
        return float(c) if np.ndim(c) == 0 else c

    def outcome_slope(self, outcome: float) -> float:
        """dc/dth_f = 2 (th_f - th*): how the cost moves with the outcome (the chain rule's first
        factor wherever an outcome derivative becomes a cost or value derivative)."""
        return 2.0 * (outcome - self.theta_star)

    def describe(self) -> dict:
        """Plain-data description (for JSON output and captions)."""
        return {
            "name": self.name,
            "maneuver": self.maneuver.value,
            "decisions": list(self.decisions),
            "fixed_inputs": {
                n: v for n, v in zip(INPUT_NAMES, self.fixed_inputs) if n not in self.decisions
            },
            "bounds": {d: list(b) for d, b in zip(self.decisions, self.bounds)},
            "theta_star": self.theta_star,
            "alphas": dict(zip(self.decisions, self.alphas)),
        }


def touchdown_problem(**overrides: object) -> OptimalControlProblem:
    """MODEL.md Sec. 5 touchdown problem, Eq. (14): c = (th_f + 0.1)^2 + 3e-4 u1^2 + 3e-3 u2^2.

    u1, u2 in [-0.5, 1.5]. Only the input of the single stance that occurs affects th_f.
    """
    base = {
        "name": "touchdown",
        "maneuver": Maneuver.TOUCHDOWN,
        "decisions": ("u1", "u2"),
        "fixed_inputs": (0.0, 0.0, 0.0),
        "bounds": ((-0.5, 1.5), (-0.5, 1.5)),
        "theta_star": -0.1,
        "alphas": (3e-4, 3e-3),
    }
    return OptimalControlProblem(**{**base, **overrides})  # type: ignore[arg-type]


def liftoff_problem(**overrides: object) -> OptimalControlProblem:
    """MODEL.md Sec. 5 liftoff problem, Eq. (15): c = (th_f - 0.01)^2 + 0.01 u12^2.

    u12 in [-0.5, 0.5] with u1 = 1.5, u2 = 3 fixed; the cost is discontinuous in u12.
    """
    base = {
        "name": "liftoff",
        "maneuver": Maneuver.LIFTOFF,
        "decisions": ("u12",),
        "fixed_inputs": (1.5, 3.0, 0.0),
        "bounds": ((-0.5, 0.5),),
        "theta_star": 0.01,
        "alphas": (0.01,),
    }
    return OptimalControlProblem(**{**base, **overrides})  # type: ignore[arg-type]


def liftoff_variant_problem(**overrides: object) -> OptimalControlProblem:
    """MODEL.md Sec. 6 variant: u12 = 0, decide the single-stance forces u1, u2 in [0, 3].

    c = (th_f + 0.02)^2 + 1e-5 u1^2 + 2e-5 u2^2; its optimal value jumps at th0 = 0.
    """
    base = {
        "name": "liftoff-variant",
        "maneuver": Maneuver.LIFTOFF,
        "decisions": ("u1", "u2"),
        "fixed_inputs": (0.0, 0.0, 0.0),
        "bounds": ((0.0, 3.0), (0.0, 3.0)),
        "theta_star": -0.02,
        "alphas": (1e-5, 2e-5),
    }
    return OptimalControlProblem(**{**base, **overrides})  # type: ignore[arg-type]


#: the shipped problems by name
PROBLEMS = {
    "touchdown": touchdown_problem,
    "liftoff": liftoff_problem,
    "liftoff-variant": liftoff_variant_problem,
}


def get_problem(name: str, **overrides: object) -> OptimalControlProblem:
    """The shipped problem ``name`` (touchdown, liftoff, liftoff-variant) with overrides."""
    key = str(name).strip().lower()
    if key not in PROBLEMS:
        raise InvalidInputError(
            f"problem must be one of {', '.join(PROBLEMS)}; got {name!r}"
        )
    return PROBLEMS[key](**overrides)
