"""Optimal-control problems on any system: a maneuver, decisions with bounds, and a cost.

A problem (the paper's Eqs. (4)-(6); its Eqs. (14), (15) are instances) fixes a system, one of
its maneuvers, the decided inputs with their bounds, the other inputs' values, and the cost

    c(s, u) = w (outcome - target)^2 + sum_k W_k (y_k(t_f) - r_k)^2 + sum_i alpha_i u_i^2

with the sums over named final-state components (coordinates or ``<name>_dot`` velocities) and
over the decisions. A system description may declare its problems
(:meth:`biped_opt.systems.System.problem`); a problem can also be written in a small file next to
the system (:func:`load_problem`):

.. code-block:: yaml

    system: hopper.py            # a library name, or a path relative to this file
    maneuver: drop
    decisions: {u: [-1, 1]}      # input: [lower, upper], optimised jointly
    weights: {u: 0.01}           # alpha per decision (default 0)
    fixed: {}                    # values of the other inputs (default 0)
    target: 0.0                  # outcome target (default 0)
    outcome_weight: 1.0          # w (default 1)
    final_state: {z_dot: [1.0, 0.0]}   # name: [weight, target] (default none)
    parameters: {k: 30}          # system parameters (default the system's)

or a Python file that leaves a :class:`Problem` in ``PROBLEM``.
"""

from __future__ import annotations

import math
import runpy
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from biped_opt.errors import InvalidParameterError, quoted
from biped_opt.simulation.compiled import system_facts
from biped_opt.simulation.facts import SystemFacts, describe
from biped_opt.simulation.options import DEFAULT_OPTIONS, SimulatorOptions
from biped_opt.system_spec import FileSpec, parse_file_spec

if TYPE_CHECKING:  # (SymPy and the descriptions load when first needed, not imported)
    from biped_opt.systems.description import System

__all__ = ["Problem", "load_problem", "get_problem", "KEYS"]

Array = npt.NDArray[np.float64]

#: the keys of a problem file or of System.problem(...)
KEYS = ("system", "maneuver", "decisions", "weights", "fixed", "target", "outcome_weight",
        "final_state", "parameters", "name")
#: largest cost term allowed: its square must not overflow a double
COST_LIMIT = math.sqrt(sys.float_info.max)


def _number(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InvalidParameterError(f"{where} must be a number, got {value!r}")
    out = float(value)
    if not math.isfinite(out) or abs(out) > COST_LIMIT:
        raise InvalidParameterError(f"{where} must be a finite number below 1e154, got {value!r}")
    return out


def _mapping(where: str, value: Any) -> Mapping[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise InvalidParameterError(f"{where} must be a mapping of names to values, got "
                                    f"{value!r}")
    return value


@dataclass(frozen=True, kw_only=True)
class Problem:
    """An optimal-control problem on a system (see the module docstring)."""

    system: System | str
    maneuver: str
    decisions: tuple[tuple[str, tuple[float, float]], ...]
    weights: tuple[float, ...] = ()  #: alpha per decision, in the order of ``decisions``
    fixed: tuple[tuple[str, float], ...] = ()
    target: float = 0.0
    outcome_weight: float = 1.0
    final_state: tuple[tuple[str, float, float], ...] = ()  #: (name, weight, target)
    parameters: tuple[tuple[str, float], ...] = ()
    name: str = ""
    #: the simulator's settings (the default: each maneuver's own event budget and horizon)
    options: SimulatorOptions = field(default=DEFAULT_OPTIONS, compare=True)
    #: the system's names and declared problems (what the fields are checked against; read
    #: without SymPy when the system is compiled already: biped_opt.simulation.facts)
    facts: SystemFacts = field(init=False, repr=False, compare=False)
    #: the decisions' columns in the input vector, and (state column, weight, target) of each
    #: final-state term: looked up once, the cost is evaluated per simulation
    decision_columns: tuple[int, ...] = field(init=False, repr=False, compare=False)
    final_state_columns: tuple[tuple[int, float, float], ...] = field(
        init=False, repr=False, compare=False)

    @classmethod
    def from_spec(cls, spec: Mapping[str, Any], *, system: System | str | None = None,
                  where: str = "problem") -> Problem:
        """A problem from a mapping with the keys of :data:`KEYS` (a file's or a system's)."""
        spec = _mapping(where, spec)
        unknown = sorted(set(spec) - set(KEYS))
        if unknown:
            raise InvalidParameterError(
                f"{where}: unknown key {unknown[0]!r} (keys: {', '.join(KEYS)})")
        target_system = spec.get("system", system)
        if target_system is None:
            raise InvalidParameterError(f"{where}: 'system' is missing")
        if "maneuver" not in spec:
            raise InvalidParameterError(f"{where}: 'maneuver' is missing")
        decisions = _mapping(f"{where}: decisions", spec.get("decisions"))
        bounds = []
        for key, value in decisions.items():
            if not isinstance(value, (list, tuple)) or len(value) != 2:
                raise InvalidParameterError(
                    f"{where}: decisions: {key}: must be [lower, upper], got {value!r}")
            bounds.append((str(key), (_number(f"{where}: decisions: {key} lower", value[0]),
                                      _number(f"{where}: decisions: {key} upper", value[1]))))
        weights = _mapping(f"{where}: weights", spec.get("weights"))
        extra = sorted(set(weights) - set(decisions))
        if extra:
            raise InvalidParameterError(
                f"{where}: weights: {extra[0]!r} is not a decision "
                f"(decisions: {', '.join(map(str, decisions)) or 'none'})")
        final = []
        for key, value in _mapping(f"{where}: final_state", spec.get("final_state")).items():
            if not isinstance(value, (list, tuple)) or len(value) != 2:
                raise InvalidParameterError(
                    f"{where}: final_state: {key}: must be [weight, target], got {value!r}")
            final.append((str(key), _number(f"{where}: final_state: {key} weight", value[0]),
                          _number(f"{where}: final_state: {key} target", value[1])))
        return cls(
            system=target_system, maneuver=spec["maneuver"], decisions=tuple(bounds),
            weights=tuple(_number(f"{where}: weights: {k}", weights.get(k, 0.0))
                          for k in decisions),
            fixed=tuple((str(k), _number(f"{where}: fixed: {k}", v)) for k, v in
                        _mapping(f"{where}: fixed", spec.get("fixed")).items()),
            target=_number(f"{where}: target", spec.get("target", 0.0)),
            outcome_weight=_number(f"{where}: outcome_weight", spec.get("outcome_weight", 1.0)),
            final_state=tuple(final),
            parameters=tuple((str(k), _number(f"{where}: parameters: {k}", v)) for k, v in
                             _mapping(f"{where}: parameters", spec.get("parameters")).items()),
            name=str(spec.get("name", "")))

    def __post_init__(self) -> None:
        system = system_facts(self.system)
        object.__setattr__(self, "facts", system)
        where = f"{system.where()}: problem {self.name or self.maneuver!r}"
        if not isinstance(self.maneuver, str) or self.maneuver not in system.maneuvers:
            raise InvalidParameterError(
                f"{where}: unknown maneuver {quoted(str(self.maneuver))} "
                f"(maneuvers: {', '.join(system.maneuvers) or 'none'})")
        if not self.name:
            object.__setattr__(self, "name", f"{system.name}:{self.maneuver}")
        inputs = system.inputs
        names = [d for d, _ in self.decisions]
        if not names:
            raise InvalidParameterError(f"{where}: needs at least one decision input")
        for d, (lo, hi) in self.decisions:
            if d not in inputs:
                raise InvalidParameterError(
                    f"{where}: decision {quoted(d)} is not an input of the system "
                    f"(inputs: {', '.join(inputs) or 'none'})")
            if not lo < hi:
                raise InvalidParameterError(
                    f"{where}: decision {d}: bounds must have lower < upper, got [{lo}, {hi}]")
        if len(set(names)) != len(names):
            raise InvalidParameterError(f"{where}: a decision is given twice: {names}")
        weights = tuple(self.weights) or (0.0,) * len(names)
        if len(weights) != len(names):
            raise InvalidParameterError(
                f"{where}: {len(weights)} weights for {len(names)} decisions")
        object.__setattr__(self, "weights", tuple(_number(f"{where}: weight", w)
                                                  for w in weights))
        for k, _ in self.fixed:
            if k not in inputs:
                raise InvalidParameterError(
                    f"{where}: fixed input {quoted(k)} is not an input of the system "
                    f"(inputs: {', '.join(inputs) or 'none'})")
            if k in names:
                raise InvalidParameterError(f"{where}: input {k} is both fixed and decided")
        states = [*system.coordinates, *system.velocities]
        for k, _, _ in self.final_state:
            if k not in states:
                raise InvalidParameterError(
                    f"{where}: final_state {quoted(k)} is not a coordinate or velocity "
                    f"({', '.join(states)})")
        object.__setattr__(self, "decision_columns", tuple(inputs.index(d) for d in names))
        object.__setattr__(self, "final_state_columns", tuple(
            (states.index(k), w, r) for k, w, r in self.final_state))
        if not isinstance(self.options, SimulatorOptions):
            raise InvalidParameterError(f"{where}: options must be SimulatorOptions, got "
                                        f"{self.options!r}")
        for k, _ in self.parameters:
            if k not in system.defaults:
                raise InvalidParameterError(
                    f"{where}: unknown parameter {quoted(k)} "
                    f"(parameters: {', '.join(system.defaults) or 'none'})")

    # -- derived views ------------------------------------------------------------------------
    @property
    def description(self) -> System:
        """The system's description (:func:`describe`: built with SymPy when first asked for
        in a process)."""
        return describe(self.system)

    @property
    def decision_names(self) -> tuple[str, ...]:
        return tuple(d for d, _ in self.decisions)

    def bound(self, decision: str) -> tuple[float, float]:
        return dict(self.decisions)[decision]

    def alpha(self, decision: str) -> float:
        return self.weights[self.decision_names.index(decision)]

    def default_decision(self, decision: str) -> float:
        """The cheapest value of a decision that does not act: the bound point nearest 0."""
        lo, hi = self.bound(decision)
        return min(max(0.0, lo), hi)

    def inputs(self, policy: Mapping[str, float] | None = None) -> Array:
        """The full input vector (system order): fixed values, decisions from ``policy`` or at
        their defaults."""
        names = self.facts.inputs
        u = np.zeros(max(len(names), 1))
        for k, v in self.fixed:
            u[names.index(k)] = v
        for d, col in zip(self.decision_names, self.decision_columns):
            u[col] = (policy or {}).get(d, self.default_decision(d))
        return u

    def cost(self, outcome: npt.ArrayLike, y_final: npt.ArrayLike, inputs: npt.ArrayLike
             ) -> Array:
        """c for rows of outcomes, final states and input vectors (broadcasting)."""
        y = np.asarray(y_final, dtype=np.float64)
        u = np.asarray(inputs, dtype=np.float64)
        c = self.outcome_weight * (np.asarray(outcome, dtype=np.float64) - self.target) ** 2
        for col, w, r in self.final_state_columns:
            c = c + w * (y[..., col] - r) ** 2
        for col, a in zip(self.decision_columns, self.weights):
            c = c + a * u[..., col] ** 2
        return c

    def parameter_values(self) -> dict[str, float]:
        return dict(self.parameters)

    def as_dict(self) -> dict[str, Any]:
        """The problem as the mapping a problem file holds (the system by name or path)."""
        system = self.facts
        return {
            "name": self.name,
            "system": system.source or system.name,
            "maneuver": self.maneuver,
            "decisions": {d: list(b) for d, b in self.decisions},
            "weights": dict(zip(self.decision_names, self.weights)),
            "fixed": dict(self.fixed),
            "target": self.target,
            "outcome_weight": self.outcome_weight,
            "final_state": {k: [w, r] for k, w, r in self.final_state},
            "parameters": dict(self.parameters),
        }


def get_problem(system: System | str, name: str) -> Problem:
    """A problem the system's description declares (:meth:`System.problem`)."""
    description = system_facts(system)
    if name not in description.problems:
        raise InvalidParameterError(
            f"{description.where()}: unknown problem {quoted(name)} "
            f"(problems: {', '.join(description.problems) or 'none'})")
    return Problem.from_spec({**description.problems[name], "name": name}, system=system,
                             where=f"{description.where()}: problem {name}")


def read_yaml(path: Path) -> Any:
    """The YAML document of the regular file ``path``; anything that keeps it from being read
    (a syntax error, text that is not UTF-8, a device, too many bytes) is one line naming the
    file (:func:`biped_opt.input_files.read_yaml`)."""
    from biped_opt.input_files import InputFileError
    from biped_opt.input_files import read_yaml as read

    try:
        return read(path)
    except InputFileError as exc:
        raise InvalidParameterError(str(exc)) from None


def load_problem(spec: str | Path, *, system: System | str | None = None) -> Problem:
    """A problem from a file (``.yaml``/``.yml`` or ``.py`` with ``PROBLEM``), or by the name of
    one that ``system`` declares."""
    text = str(spec)
    path = Path(text)
    if path.suffix not in (".yaml", ".yml", ".py"):
        if system is None:
            raise InvalidParameterError(
                f"problem {quoted(text)}: not a problem file (.yaml, .yml, .py) and no system "
                "given to look it up in")
        return get_problem(system, text)
    if not path.is_file():
        raise InvalidParameterError(f"{path}: no such problem file")
    if path.suffix == ".py":
        try:
            namespace = runpy.run_path(str(path), run_name="biped_opt_problem")
        except Exception as exc:  # the user's code: what and where, never our traceback
            raise InvalidParameterError(f"{path}: {type(exc).__name__}: {exc}") from None
        problem = namespace.get("PROBLEM")
        if not isinstance(problem, Problem):
            raise InvalidParameterError(f"{path}: must define PROBLEM = Problem(...)")
        return problem
    spec_map = read_yaml(path)
    if not isinstance(spec_map, Mapping):
        raise InvalidParameterError(f"{path}: must hold a mapping with the keys "
                                    f"{', '.join(KEYS)}")
    spec_map = dict(spec_map)
    target = spec_map.get("system", system)
    file = parse_file_spec(target) if isinstance(target, str) else None
    if file is not None and not file.path.is_absolute():  # a system file next to the problem
        target = str(FileSpec(path.parent / file.path, file.arguments))
    spec_map["system"] = target
    spec_map.setdefault("name", path.stem)
    return Problem.from_spec(spec_map, where=str(path))
