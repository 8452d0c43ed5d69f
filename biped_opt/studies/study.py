"""Parameter studies of the nonsmoothness: where do the kinks and jumps persist, how large are they.

The paper says its result "does not depend sensitively on the problem data" but shows one
parameter set. A :class:`Study` is a system, a maneuver at fixed inputs and/or an optimal-control
problem, a set of parameter points (a full grid, or a seeded uniform sample, over named model
parameters and problem data) and the s range. For every parameter point it computes the
nonsmooth table of the fixed-input outcome (:func:`biped_opt.analysis.nonsmooth.find_nonsmooth`)
and of the optimal outcome, policy and value
(:func:`biped_opt.analysis.nonsmooth.find_nonsmooth_optimal`) and returns tidy rows, one per
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
import reprlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from biped_opt.errors import InvalidParameterError

if TYPE_CHECKING:
    from biped_opt.control.problems import Problem

__all__ = ["Study", "StudyLimits", "StudyRow", "evaluate_point", "COLUMNS",
           "PROBLEM_PARAMETERS", "LIMITS"]

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


@dataclass(frozen=True, kw_only=True)
class StudyLimits:
    """The largest study :meth:`Study.from_spec` reads, checked before anything is built: a
    node states its own (parameters), a study file gets :data:`LIMITS`."""

    max_points: int = 1_000_000  #: parameter points (grid points x samples)
    max_num: int = 100_001  #: points of an s grid (num, num_optimal)
    max_values: int = 100_000  #: values of one grid axis, and samples
    max_text: int = 200  #: characters of a name (study, system, problem, maneuver, parameter)

    def __post_init__(self) -> None:
        for name in ("max_points", "max_num", "max_values", "max_text"):
            if getattr(self, name) < 1:
                raise InvalidParameterError(f"{name} must be >= 1, got {getattr(self, name)}")


#: the limits of a study file (a node's parameters may be tighter)
LIMITS = StudyLimits()
#: largest seed of a study file (numpy's generators take 0 <= seed < 2**64; 2**63 keeps it an
#: int64 in the table and the StudyRow message; the command line's own seeds keep numpy's legacy
#: 0..2**32 - 1, biped_opt.cli.args.MAX_SEED)
MAX_STUDY_SEED = 2**63 - 1


def _count(where: str, value: Any, low: int, high: int, limit: str = "") -> int:
    """An integer in [low, high] (an integral float such as 1e3 too); the message names the
    key and, when ``limit`` is given, the limit that bounds it."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or (isinstance(value, (float, np.floating))
                and not (math.isfinite(value) and float(value).is_integer())):
        raise InvalidParameterError(f"{where} must be an integer, got {_short(value)}")
    number = int(value)
    if not low <= number <= high:
        bound = f" ({limit})" if limit else ""
        raise InvalidParameterError(
            f"{where} must be in [{low}, {high}]{bound}, got {number}")
    return number


def _text(where: str, value: Any, limits: StudyLimits) -> str:
    if not isinstance(value, str):
        raise InvalidParameterError(f"{where} must be a string, got {_short(value)}")
    if len(value) > limits.max_text:
        raise InvalidParameterError(
            f"{where} must be at most {limits.max_text} characters, got {len(value)}")
    return value


#: a value's repr for a message, bounded however large or deep the value is (a few lines of
#: YAML aliases make a list of billions of elements, whose full repr would take gigabytes)
_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxlist, _REPR.maxdict, _REPR.maxstring = 2, 4, 4, 40


def _short(value: Any) -> str:
    text = _REPR.repr(value)
    return text if len(text) <= 40 else text[:40] + "..."


def _point_count(grid: Sequence[tuple[str, Sequence[float]]], sample: Sequence[Any],
                 samples: int) -> int:
    """How many parameter points a grid and samples make (counted, never built)."""
    return math.prod(len(v) for _, v in grid) * (samples if sample else 1)


def _check_points(where: str, points: int, limit: int) -> None:
    if points > limit:
        raise InvalidParameterError(f"{where}: {points} parameter points (grid x samples); at "
                                    f"most {limit} (limit max_points)")


def _pairs(where: str, value: Any) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise InvalidParameterError(f"{where} must map names to values, got {_short(value)}")
    return dict(value)


def _finite(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
            or not math.isfinite(float(value)):
        raise InvalidParameterError(f"{where} must be a finite number, got {_short(value)}")
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
    def from_spec(cls, spec: Mapping[str, Any], *, where: str = "study",
                  limits: StudyLimits = LIMITS) -> Study:
        """A study from a mapping (a study file's, or the ROS action goal's). Every value is
        checked, and the study's size against ``limits``, before anything is built."""
        return cls(**cls.fields_from_spec(spec, where=where, limits=limits))

    @classmethod
    def fields_from_spec(cls, spec: Mapping[str, Any], *, where: str = "study",
                         limits: StudyLimits = LIMITS) -> dict[str, Any]:
        """The checked keyword arguments of :meth:`from_spec`'s study, nothing described yet
        (a node resolves the system's name before it builds the study)."""
        spec = _pairs(where, spec)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(spec) - known, key=str)
        if unknown:
            raise InvalidParameterError(
                f"{where}: unknown key {_short(unknown[0])} (keys: {', '.join(sorted(known))})")
        if "system" not in spec:
            raise InvalidParameterError(f"{where}: 'system' is missing")
        grid = []
        for key, values in _pairs(f"{where}: grid", spec.get("grid")).items():
            key = _text(f"{where}: grid: a name", key, limits)
            if not isinstance(values, (list, tuple)) or not values:
                raise InvalidParameterError(
                    f"{where}: grid: {key}: must be a non-empty list of values")
            if len(values) > limits.max_values:
                raise InvalidParameterError(
                    f"{where}: grid: {key}: at most {limits.max_values} values (limit "
                    f"max_values), got {len(values)}")
            grid.append((key, tuple(_finite(f"{where}: grid: {key}", v) for v in values)))
        sample = []
        for key, pair in _pairs(f"{where}: sample", spec.get("sample")).items():
            key = _text(f"{where}: sample: a name", key, limits)
            if not isinstance(pair, (list, tuple)) or len(pair) != 2:
                raise InvalidParameterError(f"{where}: sample: {key}: must be [low, high]")
            lo, hi = (_finite(f"{where}: sample: {key}", v) for v in pair)
            if not lo < hi:
                raise InvalidParameterError(f"{where}: sample: {key}: needs low < high")
            sample.append((key, (lo, hi)))
        samples = _count(f"{where}: samples", spec.get("samples", 0), 0, limits.max_values,
                         "max_values")
        _check_points(where, _point_count(grid, sample, samples), limits.max_points)
        s_range = spec.get("s_range")
        if s_range is not None:
            if not isinstance(s_range, (list, tuple)) or len(s_range) != 2:
                raise InvalidParameterError(f"{where}: s_range must be [low, high]")
            s_range = tuple(_finite(f"{where}: s_range", v) for v in s_range)
            if not s_range[0] < s_range[1]:
                raise InvalidParameterError(
                    f"{where}: s_range must have low < high, got {list(s_range)}")
        optional = {key: None if spec.get(key) is None else
                    _text(f"{where}: {key}", spec[key], limits)
                    for key in ("maneuver", "problem")}
        return dict(
            system=_text(f"{where}: system", spec["system"], limits),
            maneuver=optional["maneuver"],
            inputs=tuple((_text(f"{where}: inputs: a name", k, limits),
                          _finite(f"{where}: inputs: {k}", v))
                         for k, v in _pairs(f"{where}: inputs", spec.get("inputs")).items()),
            problem=optional["problem"],
            grid=tuple(grid), sample=tuple(sample), samples=samples,
            seed=_count(f"{where}: seed", spec.get("seed", 0), 0, MAX_STUDY_SEED),
            s_range=s_range,
            num=_count(f"{where}: num", spec.get("num", 201), 3, limits.max_num, "max_num"),
            num_optimal=_count(f"{where}: num_optimal", spec.get("num_optimal", 41), 3,
                               limits.max_num, "max_num"),
            name=_text(f"{where}: name", spec.get("name", "study"), limits))

    @classmethod
    def described_elsewhere(cls, **fields: Any) -> Study:
        """The study of ``fields`` (:meth:`fields_from_spec`'s, the system and problem
        resolved) that another process has built and checked: made here without describing
        its system again. A node that must not run a system file's code (the study
        coordinator) has its compile process build the study and keeps only its values."""
        study = object.__new__(cls)
        for item in dataclasses.fields(cls):
            object.__setattr__(study, item.name, fields.get(item.name, item.default))
        return study

    def __post_init__(self) -> None:
        from biped_opt.simulation.compiled import system_facts

        # (before anything is described or built)
        _check_points(f"study {self.name!r}", self.size, LIMITS.max_points)
        system = system_facts(self.system)
        where = f"study {self.name!r} on {system.where()}"
        if self.maneuver is None and self.problem is None:
            raise InvalidParameterError(f"{where}: give a maneuver, a problem or both")
        if self.maneuver is not None and self.maneuver not in system.maneuvers:
            raise InvalidParameterError(
                f"{where}: unknown maneuver {self.maneuver!r} "
                f"(maneuvers: {', '.join(system.maneuvers)})")
        for key, _ in self.inputs:
            if key not in system.inputs:
                raise InvalidParameterError(
                    f"{where}: unknown input {key!r} (inputs: {', '.join(system.inputs)})")
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

    @property
    def size(self) -> int:
        """How many parameter points :meth:`points` makes (counted, not built)."""
        return _point_count(self.grid, self.sample, self.samples)

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

    def _problem(self) -> Problem:
        from biped_opt.control.problems import load_problem

        return load_problem(self.problem, system=self.system)  # type: ignore[arg-type]


def _grid(compiled: Any, maneuver: str, num: int,
          s_range: Sequence[float] | None) -> npt.NDArray[np.float64]:
    from biped_opt.analysis.nonsmooth import s_grid

    lo, hi = (None, None) if s_range is None else s_range
    return s_grid(compiled, maneuver, num, lo, hi)


def _size(kind: str, left: float, right: float) -> float:
    return right - left if kind != "none" else 0.0



def evaluate_point(study: Study, index: int, values: Mapping[str, float]) -> list[StudyRow]:
    """The rows of parameter point ``index`` (``values`` from :meth:`Study.points`)."""
    from biped_opt.analysis.nonsmooth import find_nonsmooth, find_nonsmooth_optimal
    from biped_opt.simulation.compiled import compiled_with, system_facts

    system = system_facts(study.system)
    model = {k: v for k, v in values.items() if k in system.defaults}
    found: list[tuple[str, Any]] = []
    if study.maneuver is not None:
        compiled = compiled_with(study.system, model)  # (one object per parameter set)
        grid = _grid(compiled, study.maneuver, study.num, study.s_range)
        report = find_nonsmooth(compiled, study.maneuver, dict(study.inputs), s=grid)
        found += [("fixed", p) for p in report.points] or [("fixed", None)]
    if study.problem is not None:
        from biped_opt.control.solve import compiled_for

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
