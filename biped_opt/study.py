"""Parameter studies of the nonsmoothness: where do the kinks and jumps persist, how large are they.

The paper says its result "does not depend sensitively on the problem data" but shows one
parameter set. A :class:`Study` is a system, a maneuver at fixed inputs and/or an optimal-control
problem, a set of parameter points (a full grid, or a seeded uniform sample, over named model
parameters and problem data) and the s range. For every parameter point it computes the
nonsmooth table of the fixed-input outcome (:func:`biped_opt.systems.nonsmooth.find_nonsmooth`)
and of the optimal outcome, policy and value
(:func:`biped_opt.systems.nonsmooth.find_nonsmooth_optimal`) and returns tidy rows, one per
parameter point and nonsmooth point (a point with none gets one row of kind ``none``, so every
point is accounted for).

Parameters are named as the system's (``k``, ``Ib``, ...) or as problem data: ``target``,
``outcome_weight`` and ``weight.<decision>``.

Everything here is computation; :mod:`biped_opt.study_io` writes and resumes the table.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from biped_opt.errors import InvalidParameterError

__all__ = ["Study", "StudyRow", "evaluate_point", "COLUMNS", "PROBLEM_PARAMETERS"]

#: problem data a study can vary besides the system's parameters
PROBLEM_PARAMETERS = ("target", "outcome_weight")
#: the fixed columns of a study's table, after ``point`` and the parameter columns
COLUMNS = ("table", "quantity", "input", "kind", "s", "left", "right", "size", "cause",
           "rows")


@dataclass(frozen=True)
class StudyRow:
    """One nonsmooth point at one parameter point (``kind`` "none": the point has none).

    ``size`` is what the kind measures: right - left limit for a jump, right - left slope for a
    kink, right - left second derivative for a second-derivative point. ``rows`` is how many
    rows the parameter point has (a reader keeps a point only when all are there).
    """

    point: int
    parameters: tuple[tuple[str, float], ...]
    table: str  #: "fixed" (outcome at fixed inputs) or "optimal"
    quantity: str
    input: str
    kind: str
    s: float
    left: float
    right: float
    size: float
    cause: str
    rows: int

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"point": self.point}
        out.update(self.parameters)
        out.update({k: getattr(self, k) for k in COLUMNS})
        return out


def _pairs(where: str, value: Any) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise InvalidParameterError(f"{where} must map names to values, got {value!r}")
    return dict(value)


def _finite(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
            or not math.isfinite(float(value)):
        raise InvalidParameterError(f"{where} must be a finite number, got {value!r}")
    return float(value)


@dataclass(frozen=True, kw_only=True)
class Study:
    """What to compute (see the module docstring). ``grid`` maps parameter names to the values
    of a full factorial grid; ``sample`` maps names to (low, high) of a uniform sample of
    ``samples`` points drawn with ``seed``; both may be given (every grid point with every
    sample). ``s_range`` defaults to the maneuver's; ``num`` and ``num_optimal`` are the s grids
    of the fixed-input and optimal tables."""

    system: str
    maneuver: str | None = None
    inputs: tuple[tuple[str, float], ...] = ()
    problem: str | None = None
    grid: tuple[tuple[str, tuple[float, ...]], ...] = ()
    sample: tuple[tuple[str, tuple[float, float]], ...] = ()
    samples: int = 0
    seed: int = 0
    s_range: tuple[float, float] | None = None
    num: int = 201
    num_optimal: int = 41
    name: str = "study"

    @classmethod
    def from_spec(cls, spec: Mapping[str, Any], *, where: str = "study") -> Study:
        """A study from a mapping (a study file's, or the ROS action goal's)."""
        spec = _pairs(where, spec)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(spec) - known)
        if unknown:
            raise InvalidParameterError(
                f"{where}: unknown key {unknown[0]!r} (keys: {', '.join(sorted(known))})")
        if "system" not in spec:
            raise InvalidParameterError(f"{where}: 'system' is missing")
        grid = []
        for key, values in _pairs(f"{where}: grid", spec.get("grid")).items():
            if not isinstance(values, (list, tuple)) or not values:
                raise InvalidParameterError(
                    f"{where}: grid: {key}: must be a non-empty list of values")
            grid.append((str(key), tuple(_finite(f"{where}: grid: {key}", v) for v in values)))
        sample = []
        for key, pair in _pairs(f"{where}: sample", spec.get("sample")).items():
            if not isinstance(pair, (list, tuple)) or len(pair) != 2:
                raise InvalidParameterError(f"{where}: sample: {key}: must be [low, high]")
            lo, hi = (_finite(f"{where}: sample: {key}", v) for v in pair)
            if not lo < hi:
                raise InvalidParameterError(f"{where}: sample: {key}: needs low < high")
            sample.append((str(key), (lo, hi)))
        s_range = spec.get("s_range")
        if s_range is not None:
            if not isinstance(s_range, (list, tuple)) or len(s_range) != 2:
                raise InvalidParameterError(f"{where}: s_range must be [low, high]")
            s_range = tuple(_finite(f"{where}: s_range", v) for v in s_range)
        return cls(
            system=str(spec["system"]),
            maneuver=None if spec.get("maneuver") is None else str(spec["maneuver"]),
            inputs=tuple((str(k), _finite(f"{where}: inputs: {k}", v))
                         for k, v in _pairs(f"{where}: inputs", spec.get("inputs")).items()),
            problem=None if spec.get("problem") is None else str(spec["problem"]),
            grid=tuple(grid), sample=tuple(sample),
            samples=int(spec.get("samples", 0)), seed=int(spec.get("seed", 0)),
            s_range=s_range,  # type: ignore[arg-type]
            num=int(spec.get("num", 201)), num_optimal=int(spec.get("num_optimal", 41)),
            name=str(spec.get("name", "study")))

    def __post_init__(self) -> None:
        from biped_opt.systems.problems import describe

        system = describe(self.system)
        where = f"study {self.name!r} on {system.where()}"
        if self.maneuver is None and self.problem is None:
            raise InvalidParameterError(f"{where}: give a maneuver, a problem or both")
        if self.maneuver is not None and self.maneuver not in system.maneuvers:
            raise InvalidParameterError(
                f"{where}: unknown maneuver {self.maneuver!r} "
                f"(maneuvers: {', '.join(system.maneuvers)})")
        for key, _ in self.inputs:
            if key not in system.u.names():
                raise InvalidParameterError(
                    f"{where}: unknown input {key!r} (inputs: {', '.join(system.u.names())})")
        decisions = self._problem().decision_names if self.problem is not None else ()
        allowed = [*system.defaults, *PROBLEM_PARAMETERS, *(f"weight.{d}" for d in decisions)]
        names = [k for k, _ in self.grid] + [k for k, _ in self.sample]
        for key in names:
            if key not in allowed:
                raise InvalidParameterError(
                    f"{where}: cannot vary {key!r} (parameters: {', '.join(allowed)})")
            if key not in system.defaults and self.problem is None:
                raise InvalidParameterError(f"{where}: {key!r} is problem data: give a problem")
        if len(set(names)) != len(names):
            raise InvalidParameterError(f"{where}: a parameter is varied twice: {names}")
        if not names:
            raise InvalidParameterError(f"{where}: vary at least one parameter (grid, sample)")
        if self.sample and self.samples < 1:
            raise InvalidParameterError(f"{where}: sample needs samples >= 1")
        if self.num < 3 or self.num_optimal < 3:
            raise InvalidParameterError(f"{where}: num and num_optimal must be >= 3")

    # -- the parameter points -------------------------------------------------------------------
    @property
    def parameter_names(self) -> tuple[str, ...]:
        return (*(k for k, _ in self.grid), *(k for k, _ in self.sample))

    def points(self) -> list[dict[str, float]]:
        """Every parameter point, in a fixed order (its index is the point's id)."""
        grid = [dict(zip([k for k, _ in self.grid], combo))
                for combo in itertools.product(*(v for _, v in self.grid))] or [{}]
        if not self.sample:
            return grid
        rng = np.random.default_rng(self.seed)
        draws = [{k: float(rng.uniform(lo, hi)) for k, (lo, hi) in self.sample}
                 for _ in range(self.samples)]
        return [{**g, **d} for g in grid for d in draws]

    def as_dict(self) -> dict[str, Any]:
        """The mapping :meth:`from_spec` reads (JSON-ready)."""
        return {"name": self.name, "system": self.system, "maneuver": self.maneuver,
                "inputs": dict(self.inputs), "problem": self.problem,
                "grid": {k: list(v) for k, v in self.grid},
                "sample": {k: list(v) for k, v in self.sample}, "samples": self.samples,
                "seed": self.seed, "s_range": None if self.s_range is None
                else list(self.s_range), "num": self.num, "num_optimal": self.num_optimal}

    def _problem(self):
        from biped_opt.systems.problems import load_problem

        return load_problem(self.problem, system=self.system)  # type: ignore[arg-type]


def _grid(compiled: Any, maneuver: str, num: int, s_range: Sequence[float] | None):
    from biped_opt.systems.nonsmooth import s_grid

    lo, hi = (None, None) if s_range is None else s_range
    return s_grid(compiled, maneuver, num, lo, hi)


def _size(kind: str, left: float, right: float) -> float:
    return right - left if kind != "none" else 0.0


_LOCK = threading.Lock()


def evaluate_point(study: Study, index: int, values: Mapping[str, float]) -> list[StudyRow]:
    """The rows of parameter point ``index`` (``values`` from :meth:`Study.points`)."""
    from biped_opt.systems.compiled import shared
    from biped_opt.systems.nonsmooth import find_nonsmooth, find_nonsmooth_optimal
    from biped_opt.systems.problems import describe

    system = describe(study.system)
    model = {k: v for k, v in values.items() if k in system.defaults}
    found: list[tuple[str, Any]] = []
    if study.maneuver is not None:
        with _LOCK:  # the process's compiled system, its parameters set per point
            compiled = shared(study.system)
            compiled.set_parameters(**model)
            grid = _grid(compiled, study.maneuver, study.num, study.s_range)
            report = find_nonsmooth(compiled, study.maneuver, dict(study.inputs), s=grid)
        found += [("fixed", p) for p in report.points] or [("fixed", None)]
    if study.problem is not None:
        from biped_opt.systems.optimal import compiled_for

        problem = study._problem()
        weights = list(problem.weights)
        for k, v in values.items():
            if k.startswith("weight."):
                weights[problem.decision_names.index(k.split(".", 1)[1])] = v
        problem = dataclasses.replace(
            problem, parameters=tuple({**dict(problem.parameters), **model}.items()),
            weights=tuple(weights), target=values.get("target", problem.target),
            outcome_weight=values.get("outcome_weight", problem.outcome_weight))
        grid = _grid(compiled_for(problem), problem.maneuver, study.num_optimal, study.s_range)
        report = find_nonsmooth_optimal(problem, grid)
        found += [("optimal", p) for p in report.points] or [("optimal", None)]
    params = tuple((k, float(values[k])) for k in study.parameter_names)
    rows = []
    for table, p in found:
        if p is None:
            rows.append(StudyRow(point=index, parameters=params, table=table, quantity="",
                                 input="", kind="none", s=math.nan, left=math.nan,
                                 right=math.nan, size=0.0, cause="", rows=len(found)))
            continue
        rows.append(StudyRow(point=index, parameters=params, table=table, quantity=p.quantity,
                             input=p.input or "", kind=p.kind, s=p.theta0, left=p.left,
                             right=p.right, size=_size(p.kind, p.left, p.right), cause=p.cause,
                             rows=len(found)))
    return rows
