"""The paper's optimal-control problems: its names and fields over the library biped's problems.

The paper ([1]_ Eqs. (14), (15); MODEL.md Secs. 5, 6) names three problems of its biped, which
the library's ``biped`` declares like any system's (:func:`biped_opt.systems.library.walker`):

===================  ===================  ========================================================
paper                library biped        decisions, fixed inputs, target, weights
===================  ===================  ========================================================
``touchdown``        ``touchdown``        u1, u2 in [-0.5, 1.5]; th* = -0.1; alpha = (3e-4, 3e-3)
``liftoff``          ``liftoff``          u12 in [-0.5, 0.5], u1 = 1.5, u2 = 3; th* = 0.01; 0.01
``liftoff-variant``  ``liftoff_variant``  u1, u2 in [0, 3], u12 = 0; th* = -0.02; (1e-5, 2e-5)
===================  ===================  ========================================================

An :class:`OptimalControlProblem` is one of them in the paper's words, as the command line and
the nodes accept overrides of it: the target pitch th* (``theta_star``), the weights alpha
(``alphas``) and ``bounds`` per decision, the fixed inputs as (u1, u2, u12), the biped's
parameters as :class:`~biped_opt.paper.biped.BipedParams` and the simulator's options. Its
constructor validates each field and names the offending one; its :attr:`~OptimalControlProblem.
problem` is the same problem as the one :class:`~biped_opt.control.problems.Problem` of the
library biped that every computation (solver, sweeps, derivatives, nonsmooth tables) runs on:

    c(th0, u) = (th_f(th0, u) - th*)^2 + sum_i alpha_i u_i^2     (over the decisions only)

The factories' numbers are read from the library biped's declarations (one source).

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from biped_opt.control.problems import COST_LIMIT, Problem
from biped_opt.control.problems import get_problem as declared_problem
from biped_opt.errors import InvalidInputError, InvalidParameterError
from biped_opt.paper.biped import BIPED, INPUT_NAMES, BipedParams, Maneuver, parse_maneuver
from biped_opt.simulation.compiled import system_facts
from biped_opt.simulation.facts import SystemFacts
from biped_opt.simulation.options import DEFAULT_OPTIONS, SimulatorOptions

if TYPE_CHECKING:
    from biped_opt.systems.description import System

__all__ = [
    "LIBRARY_NAMES",
    "OptimalControlProblem",
    "PROBLEMS",
    "get_problem",
    "liftoff_problem",
    "liftoff_variant_problem",
    "paper_branch",
    "paper_problem",
    "touchdown_problem",
]

Array = npt.NDArray[np.float64]

#: the paper's problem names -> the names the library's biped declares them by
LIBRARY_NAMES = {"touchdown": "touchdown", "liftoff": "liftoff",
                 "liftoff-variant": "liftoff_variant"}
#: the one lane's contact-mode names (constraints in contact, joined by +) -> the paper's
MODE_WORDS = {"air": "AIR", "left": "LEFT", "right": "RIGHT", "left+right": "GROUND"}


def _real(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InvalidParameterError(f"{name} must be a real number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise InvalidParameterError(f"{name} must be finite, got {value!r}")
    return out


def paper_branch(label: str) -> str:
    """A mode sequence in the paper's words: ``air->left->left+right`` -> ``AIR->LEFT->GROUND``
    (a failed simulation's ``FAILED:<status>`` unchanged)."""
    if label.startswith("FAILED:"):
        return label
    return re.sub(r"[a-z+]+", lambda m: MODE_WORDS.get(m.group(0), m.group(0)), label)


@dataclass(frozen=True, kw_only=True)
class OptimalControlProblem:
    """Minimise c(th0, u) = (th_f - th*)^2 + sum_i alpha_i u_i^2 over the decision inputs.

    Eqs. (4)-(6), (14), (15) of [1]_ in the paper's words (the defaults: the touchdown
    problem's numbers). ``decisions`` names the decided inputs (a subset of u1, u2, u12);
    ``bounds`` and ``alphas`` are per decision, in the same order; ``fixed_inputs`` gives
    (u1, u2, u12) for the inputs that are not decided (entries of decisions are ignored).
    :attr:`problem` is the one-lane :class:`~biped_opt.control.problems.Problem` it stands for.
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
    #: the same problem on the library biped (what the solver, sweeps and derivatives run on)
    problem: Problem = field(init=False, repr=False, compare=False)

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
                f"got {self.decisions!r}")
        if len(set(decisions)) != len(decisions):
            raise InvalidParameterError(f"decisions must not repeat, got {self.decisions!r}")
        object.__setattr__(self, "decisions", decisions)
        fixed = tuple(self.fixed_inputs)
        if len(fixed) != len(INPUT_NAMES):
            raise InvalidParameterError(
                f"fixed_inputs must be (u1, u2, u12), got {self.fixed_inputs!r}")
        object.__setattr__(self, "fixed_inputs", tuple(
            _real(f"fixed_inputs[{n}]", v) for n, v in zip(INPUT_NAMES, fixed)))
        object.__setattr__(self, "bounds", self._checked_bounds(decisions))
        alphas = tuple(self.alphas)
        if len(alphas) != len(decisions):
            raise InvalidParameterError(
                f"alphas must give one weight per decision {decisions}, got {self.alphas!r}")
        alphas = tuple(_real(f"alphas[{d}]", a) for d, a in zip(decisions, alphas))
        for d, a in zip(decisions, alphas):
            if a < 0.0:
                raise InvalidParameterError(f"alphas[{d}] must be non-negative, got {a}")
        object.__setattr__(self, "alphas", alphas)
        object.__setattr__(self, "theta_star", _real("theta_star", self.theta_star))
        # every term of the cost must be a number the solver can also square (its fits and
        # SciPy's interpolation do): a weight of 1e308 overflowed to inf and failed in lstsq
        for d, a, (lo, hi) in zip(decisions, alphas, self.bounds):
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
        object.__setattr__(self, "problem", self._one_lane())

    def _checked_bounds(self, decisions: tuple[str, ...]) -> tuple[tuple[float, float], ...]:
        bounds = tuple(self.bounds)
        if len(bounds) != len(decisions):
            raise InvalidParameterError(
                f"bounds must give one (lower, upper) per decision {decisions}, "
                f"got {self.bounds!r}")
        checked = []
        for d, b in zip(decisions, bounds):
            try:
                lo, hi = b
            except (TypeError, ValueError):
                raise InvalidParameterError(
                    f"bounds[{d}] must be a (lower, upper) pair, got {b!r}") from None
            lo, hi = _real(f"bounds[{d}] lower", lo), _real(f"bounds[{d}] upper", hi)
            if not lo < hi:
                raise InvalidParameterError(f"bounds[{d}] must have lower < upper, got {b!r}")
            checked.append((lo, hi))
        return tuple(checked)

    def _one_lane(self) -> Problem:
        """The library biped's Problem with these fields: BipedParams fields that differ from
        the system's defaults become its parameters."""
        defaults = _biped_defaults()
        parameters = tuple((k, v) for k, v in self.params.as_dict().items()
                           if v != defaults.get(k))
        return Problem(
            system=BIPED, maneuver=self.maneuver.value,
            decisions=tuple(zip(self.decisions, self.bounds)), weights=self.alphas,
            fixed=tuple((n, v) for n, v in zip(INPUT_NAMES, self.fixed_inputs)
                        if n not in self.decisions),
            target=self.theta_star, parameters=parameters, name=self.name,
            options=self.options)

    # --- the one lane's names for the same things ---------------------------------------------
    @property
    def decision_names(self) -> tuple[str, ...]:
        return self.decisions

    @property
    def description(self) -> System:
        """The library biped's description."""
        return self.problem.description

    @property
    def facts(self) -> SystemFacts:
        """The library biped's names (no SymPy: :mod:`biped_opt.simulation.facts`)."""
        return self.problem.facts

    # --- accessors ---------------------------------------------------------------------------
    def index(self, name: str) -> int:
        """Position of decision ``name`` in :attr:`decisions`."""
        try:
            return self.decisions.index(name)
        except ValueError:
            raise InvalidInputError(
                f"{name!r} is not a decision input of the {self.name} problem "
                f"(decisions: {', '.join(self.decisions)})") from None

    def bound(self, name: str) -> tuple[float, float]:
        return self.bounds[self.index(name)]

    def alpha(self, name: str) -> float:
        return self.alphas[self.index(name)]

    def default_decision(self, name: str) -> float:
        """The value a decision takes when it cannot affect the outcome: the bound point nearest
        0 (its cost alpha u^2 is least there)."""
        self.index(name)
        return self.problem.default_decision(name)

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
        """Full input vector (u1, u2, u12): fixed inputs, decisions from ``decision_values``
        (missing ones at :meth:`default_decision`)."""
        unknown = [k for k in (decision_values or {}) if k not in self.decisions]
        if unknown:
            raise InvalidInputError(
                f"{', '.join(unknown)} not decision inputs of the {self.name} problem")
        return self.problem.inputs(decision_values)

    def cost(self, outcome: npt.ArrayLike, inputs: npt.ArrayLike) -> Array | float:
        """Eqs. (14), (15): (th_f - th*)^2 + sum over decisions of alpha_i u_i^2.

        ``inputs`` is (u1, u2, u12), shape (3,) or (N, 3); ``outcome`` th_f, scalar or (N,).
        """
        c = self.problem.cost(outcome, (), inputs)  # (no final-state terms: no state needed)
        return float(c) if np.ndim(c) == 0 else c

    def outcome_slope(self, outcome: float) -> float:
        """dc/dth_f = 2 (th_f - th*): how the cost moves with the outcome (the chain rule's first
        factor wherever an outcome derivative becomes a cost or value derivative)."""
        return 2.0 * (outcome - self.theta_star)

    def describe(self) -> dict[str, Any]:
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


@functools.cache
def _biped_defaults() -> dict[str, float]:
    return dict(system_facts(BIPED).defaults)


@functools.cache
def _declared(name: str) -> dict[str, Any]:
    """The fields of the paper's problem ``name`` as the library biped declares it."""
    p = declared_problem(BIPED, LIBRARY_NAMES[name])
    fixed = dict(p.fixed)
    return {"name": name, "maneuver": p.maneuver, "decisions": p.decision_names,
            "fixed_inputs": tuple(fixed.get(n, 0.0) for n in INPUT_NAMES),
            "bounds": tuple(b for _, b in p.decisions), "theta_star": p.target,
            "alphas": p.weights}


def touchdown_problem(**overrides: Any) -> OptimalControlProblem:
    """MODEL.md Sec. 5 touchdown problem, Eq. (14): c = (th_f + 0.1)^2 + 3e-4 u1^2 + 3e-3 u2^2.

    u1, u2 in [-0.5, 1.5]. Only the input of the single stance that occurs affects th_f.
    """
    return OptimalControlProblem(**{**_declared("touchdown"), **overrides})


def liftoff_problem(**overrides: Any) -> OptimalControlProblem:
    """MODEL.md Sec. 5 liftoff problem, Eq. (15): c = (th_f - 0.01)^2 + 0.01 u12^2.

    u12 in [-0.5, 0.5] with u1 = 1.5, u2 = 3 fixed; the cost is discontinuous in u12.
    """
    return OptimalControlProblem(**{**_declared("liftoff"), **overrides})


def liftoff_variant_problem(**overrides: Any) -> OptimalControlProblem:
    """MODEL.md Sec. 6 variant: u12 = 0, decide the single-stance forces u1, u2 in [0, 3].

    c = (th_f + 0.02)^2 + 1e-5 u1^2 + 2e-5 u2^2; its optimal value jumps at th0 = 0.
    """
    return OptimalControlProblem(**{**_declared("liftoff-variant"), **overrides})


#: the paper's problems by name
PROBLEMS = {
    "touchdown": touchdown_problem,
    "liftoff": liftoff_problem,
    "liftoff-variant": liftoff_variant_problem,
}


def get_problem(name: str, **overrides: Any) -> OptimalControlProblem:
    """The paper's problem ``name`` (touchdown, liftoff, liftoff-variant) with overrides of its
    fields (theta_star, alphas, bounds, fixed_inputs, params, options, ...)."""
    key = str(name).strip().lower()
    if key not in PROBLEMS:
        raise InvalidInputError(f"problem must be one of {', '.join(PROBLEMS)}; got {name!r}")
    return PROBLEMS[key](**overrides)


def paper_problem(name: str, **overrides: Any) -> Problem:
    """The paper's problem ``name`` with overrides, as the library biped's one-lane Problem."""
    return get_problem(name, **overrides).problem
