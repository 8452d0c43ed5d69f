"""Gradient methods at kinks and jumps (the discussion of Sec. V-A of [1]_, measured).

A problem (:class:`~biped_opt.control.problems.Problem`) at a fixed value of its maneuver's
parameter s gives a cost c(u) over the decisions u in a box: piecewise smooth, kinked or
discontinuous where the contact-mode sequence changes with u. This module measures what gradient
methods make of it:

- **descent** from a grid of starting decisions, projected onto the box with an Armijo
  backtracking line search, using (a) the exact one-sided derivative of
  :func:`biped_opt.control.derivatives.outcome_gradient` (what a perfect automatic
  differentiation of the simulator returns: the gradient of the branch the current point is on)
  or (b) central finite differences; and (c) SciPy's L-BFGS-B given the exact derivative. A run
  *reaches the global optimum* when its final cost is within :data:`VALUE_TOL` of the value of
  :func:`biped_opt.control.solve.optimal_policy`; each run records why it stopped and the
  branch (mode sequence) it stopped on;
- **policy-gradient estimators** of the gradient of the Gaussian-smoothed objective
  J_sigma(u) = E c(u + sigma w), w ~ N(0, I): the zeroth-order (score-function) estimator
  mean((c(u + sigma w) - c(u)) w / sigma) and the first-order (reparameterised) estimator
  mean(D c(u + sigma w)), each sample's D c the one-sided derivative of its own branch
  (:meth:`Objective.pathwise_gradients`). Both are unbiased for a C^1 cost; where c jumps the
  first-order one misses the jump's contribution (Suh, Simchowitz, Zhang, Tedrake, ICML 2022).
  Bias is measured against the gradient of J_sigma computed by quadrature of the score identity
  D J_sigma(u) = E (c(u + sigma w) - c(u)) w / sigma on a fine grid of w
  (:func:`smoothed_gradient`), variance from the per-sample spread;
- **stochastic descent** with either estimator (normalised steps, Polyak averaging);
- **smoothing the model**: the same problems on a smoothed model of width eps, the biped with a
  smoothed input switch (:func:`biped_opt.systems.library.smooth_biped.smooth_biped`) and the
  rocking bar with soft contacts
  (:func:`biped_opt.systems.library.soft_rocking_bar.soft_rocking_bar`): its optimum, and what
  that optimum costs on the real (rigid, switched) model.

Every random quantity comes from one ``numpy.random.Generator`` seeded by the caller.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize

from biped_opt.control.derivatives import outcome_gradient
from biped_opt.control.problems import Problem, get_problem
from biped_opt.control.solve import branch_of, compiled_for, optimal_policy
from biped_opt.control.theorem1 import cost_gradient
from biped_opt.errors import InvalidInputError, SimulationError
from biped_opt.simulation.compiled import system_facts
from biped_opt.simulation.trajectory import BatchResult

__all__ = [
    "Objective", "DescentRun", "EstimatorStats", "SmoothingResult", "GradientStudy", "VALUE_TOL",
    "zeroth_order_terms", "first_order_terms", "ZEROTH_BASELINES", "smoothed_gradient",
    "estimator_stats",
    "descend", "where_stopped", "policy_gradient_descent", "find_switches", "study_problems",
    "smooth_problem", "GradientSizes", "FULL", "QUICK",
    "run_gradient_study", "report",
]

Array = npt.NDArray[np.float64]

#: a run reaches the global optimum when its final cost is within this of the optimal value
VALUE_TOL = 1e-6
#: step of the per-sample difference quotients, relative to each decision's bound interval
PATH_STEP = 1e-7
#: forward and backward quotients further apart than this (relative to their size, plus an
#: absolute floor) mean a switch lies within PATH_STEP: the exact derivative is used instead
STRADDLE_RTOL = 1e-3
STRADDLE_ATOL = 1e-8
#: central-difference step of finite-difference descent, relative to each bound interval
FD_STEP = 1e-6
#: Armijo constant and the smallest step (relative to the box) a line search tries
ARMIJO = 1e-4
MIN_STEP = 1e-12
#: descent stops when the projected step is below this (relative to the box)
STEP_TOL = 1e-10
#: distance (relative to the box) within which a descent's end counts as at a switch
SWITCH_PROBE = 1e-6


# --- the objective at fixed s -----------------------------------------------------------------
class Objective:
    """c(u) of ``problem`` at fixed s over its decisions (in ``problem.decision_names`` order),
    with batched values, exact one-sided gradients and per-sample branch gradients."""

    def __init__(self, problem: Problem, s: float) -> None:
        if not isinstance(problem, Problem):
            raise InvalidInputError(f"problem must be a Problem, got {problem!r}")
        self.problem, self.s = problem, float(s)
        self.compiled = compiled_for(problem)
        names = problem.facts.inputs
        self.cols = [names.index(d) for d in problem.decision_names]
        self.lo = np.array([problem.bound(d)[0] for d in problem.decision_names])
        self.hi = np.array([problem.bound(d)[1] for d in problem.decision_names])
        self.width = self.hi - self.lo
        self.base = problem.inputs()
        self.nsim = 0
        self.ngrad = 0

    @property
    def m(self) -> int:
        return len(self.cols)

    def rows(self, x: npt.ArrayLike) -> Array:
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        out = np.tile(self.base, (x.shape[0], 1))
        out[:, self.cols] = x
        return out

    def batch(self, x: npt.ArrayLike) -> tuple[Array, BatchResult]:
        rows = self.rows(x)
        out = self.compiled.simulate_batch(self.problem.maneuver, np.full(len(rows), self.s),
                                           rows)
        self.nsim += len(rows)
        costs = self.problem.cost(out.outcome, out.y_final, rows)
        return np.where(out.success, costs, np.inf), out

    def values(self, x: npt.ArrayLike) -> Array:
        """c at each row of decisions (inf where the maneuver fails)."""
        return self.batch(x)[0]

    def value(self, x: npt.ArrayLike) -> float:
        return float(self.values(x)[0])

    def branches(self, x: npt.ArrayLike) -> list[str]:
        """The mode sequence of each row of decisions, as text."""
        _, out = self.batch(x)
        return [branch_of(self.compiled, out.initial_mode, out.event_rows[k, :n], status)
                for k, (n, status) in enumerate(zip(out.n_events.tolist(), out.status.tolist()))]

    def gradient(self, x: npt.ArrayLike, direction: npt.ArrayLike | None = None) -> Array:
        """The exact gradient of c over the decisions on the branch at x: where x is on a
        switch, the branch that ``direction`` (over the decisions; default all +1) enters."""
        x = np.asarray(x, dtype=np.float64).ravel()
        u = self.rows(x)[0]
        v = np.zeros(1 + u.size)
        v[[1 + c for c in self.cols]] = 1.0 if direction is None else direction
        if not np.any(v):
            v[[1 + c for c in self.cols]] = 1.0
        g = outcome_gradient(self.compiled, self.problem.maneuver, self.s, u, direction=v)
        self.ngrad += 1
        return cost_gradient(self.problem, g, u)[[1 + c for c in self.cols]]

    def pathwise_gradients(self, x: npt.ArrayLike) -> tuple[Array, int]:
        """Each row's gradient on its own branch (the derivative a differentiable simulator
        returns there) and how many rows needed the exact derivative. Forward and backward
        quotients of step PATH_STEP (batched, cheap) are used where they agree; where they do
        not, a switch lies within the step and :meth:`gradient` is evaluated at the row."""
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        k, m = x.shape
        h = PATH_STEP * self.width
        shifted = [x]
        for i in range(m):
            for sign in (1.0, -1.0):
                y = x.copy()
                y[:, i] += sign * h[i]
                shifted.append(y)
        c = self.values(np.vstack(shifted)).reshape(1 + 2 * m, k)
        with np.errstate(invalid="ignore"):
            forward = (c[1::2] - c[0]) / h[:, None]
            backward = (c[0] - c[2::2]) / h[:, None]
            grads = (0.5 * (forward + backward)).T
            scale = np.maximum(np.abs(forward), np.abs(backward))
            bad = np.any(~np.isfinite(scale) | (np.abs(forward - backward) >
                                                STRADDLE_RTOL * scale + STRADDLE_ATOL), axis=0)
        failed = ~np.isfinite(c[0])
        grads[failed] = np.nan  # the maneuver fails at the row itself: no derivative
        for j in np.flatnonzero(bad & ~failed):
            try:
                grads[j] = self.gradient(x[j])
            except SimulationError:
                grads[j] = np.nan
        return grads, int((bad & ~failed).sum())


def find_switches(objective: Objective, x: npt.ArrayLike, axis: int, *, num: int = 401,
                  tol: float = 1e-10) -> list[float]:
    """Values of decision ``axis`` (others as in x) in the box where the branch changes,
    located by bisection to ``tol``."""
    x = np.asarray(x, dtype=np.float64).ravel()
    grid = np.linspace(objective.lo[axis], objective.hi[axis], num)
    rows = np.tile(x, (num, 1))
    rows[:, axis] = grid
    labels = objective.branches(rows)
    found = []
    for k in range(num - 1):
        if labels[k] == labels[k + 1]:
            continue
        a, b, la = grid[k], grid[k + 1], labels[k]
        while b - a > tol:
            mid = 0.5 * (a + b)
            probe = x.copy()
            probe[axis] = mid
            if objective.branches(probe)[0] == la:
                a = mid
            else:
                b = mid
        found.append(0.5 * (a + b))
    return found


# --- estimators -------------------------------------------------------------------------------
#: baselines b of the zeroth-order terms (c(x + sigma w) - b) w / sigma: the cost at the
#: unperturbed point (the estimator's), none, and the mean of the draws' costs. Every b that does
#: not depend on the draw leaves the estimator unbiased (E w = 0) but changes its spread; the
#: draws' mean depends on them weakly (bias O(1/N)) and is the usual variance-reducing choice
ZEROTH_BASELINES = ("point", "none", "mean")


def _zeroth_terms(c: Array, w: Array, sigma: float, baseline: str) -> Array:
    """Terms from the costs c = (c(x), c(x + sigma w_1), ...), NaN for failed draws."""
    draws = c[1:]
    b = {"point": c[0], "none": 0.0,
         "mean": float(np.nanmean(draws)) if np.isfinite(draws).any() else math.nan}.get(baseline)
    if b is None:
        raise InvalidInputError(f"baseline must be one of {', '.join(ZEROTH_BASELINES)}, "
                                f"got {baseline!r}")
    return (draws - b)[:, None] * w / sigma


def _costs(objective: Objective, x: Array, sigma: float, w: Array) -> Array:
    c = objective.values(np.vstack([x, x + sigma * w]))
    c[~np.isfinite(c)] = np.nan  # a draw whose maneuver fails gives no term
    return c


def zeroth_order_terms(objective: Objective, x: npt.ArrayLike, sigma: float, w: Array,
                       baseline: str = "point") -> Array:
    """Per-sample terms (c(x + sigma w) - c(x)) w / sigma of the score-function estimator (the
    baseline c(x) leaves it unbiased and lowers its variance; ``baseline`` picks another of
    :data:`ZEROTH_BASELINES`)."""
    x = np.asarray(x, dtype=np.float64).ravel()
    return _zeroth_terms(_costs(objective, x, sigma, w), w, sigma, baseline)


def first_order_terms(objective: Objective, x: npt.ArrayLike, sigma: float, w: Array) -> Array:
    """Per-sample terms D c(x + sigma w) of the reparameterised estimator."""
    x = np.asarray(x, dtype=np.float64).ravel()
    return objective.pathwise_gradients(x + sigma * w)[0]


def smoothed_gradient(objective: Objective, x: npt.ArrayLike, sigma: float, *,
                      points: int | None = None, half_width: float = 6.0) -> tuple[Array, float]:
    """D J_sigma(x) by the trapezoidal rule on the score identity over a grid of w in
    [-half_width, half_width]^m, and an estimate of its error (the change from half the
    points). Exact for any piecewise smooth c, jumps included (no derivative of c is used)."""
    x = np.asarray(x, dtype=np.float64).ravel()
    m = x.size
    points = points or {1: 8001, 2: 241}.get(m, 41)

    def rule(n: int) -> Array:
        axis = np.linspace(-half_width, half_width, n)
        w = np.array(list(itertools.product(axis, repeat=m)))
        weights = np.prod(np.exp(-0.5 * w ** 2) / math.sqrt(2.0 * math.pi), axis=1)
        weights *= (axis[1] - axis[0]) ** m
        return weights @ zeroth_order_terms(objective, x, sigma, w)

    fine = rule(points)
    coarse = rule((points + 1) // 2)
    return fine, float(np.linalg.norm(fine - coarse))


@dataclass(frozen=True)
class EstimatorStats:
    """Bias and spread of one estimator at one point: bias = |E term - D J_sigma| (2-norm) with
    its standard error, and the standard deviation of one sample's term (the N-sample
    estimator's is this over sqrt N)."""

    estimator: str
    sigma: float
    bias: float
    bias_se: float
    sample_std: float
    exact_calls: int = 0
    failed: int = 0  #: draws whose maneuver failed (left out of the statistics)
    #: zeroth order: sample_std with each of ZEROTH_BASELINES on the same draws
    baseline_std: dict[str, float] = field(default_factory=dict)

    def std(self, n: int) -> float:
        return self.sample_std / math.sqrt(n)


def estimator_stats(objective: Objective, x: npt.ArrayLike, sigma: float, reference: Array,
                    rng: np.random.Generator, samples: int) -> list[EstimatorStats]:
    """Both estimators at x from ``samples`` draws each (the same draws for both)."""
    w = rng.standard_normal((samples, objective.m))
    x = np.asarray(x, dtype=np.float64).ravel()
    costs = _costs(objective, x, sigma, w)

    def spread_of(terms: Array) -> float:
        ok = np.all(np.isfinite(terms), axis=1)
        return float(math.sqrt(np.sum(np.var(terms[ok], axis=0, ddof=1)))) if ok.sum() > 1 \
            else math.nan

    out = []
    for name in ("zeroth", "first"):
        before = objective.ngrad
        terms = _zeroth_terms(costs, w, sigma, "point") if name == "zeroth" else \
            first_order_terms(objective, x, sigma, w)
        by_baseline = {b: spread_of(_zeroth_terms(costs, w, sigma, b))
                       for b in ZEROTH_BASELINES} if name == "zeroth" else {}
        ok = np.all(np.isfinite(terms), axis=1)
        terms = terms[ok]
        spread = spread_of(terms)
        out.append(EstimatorStats(
            estimator=name, sigma=sigma,
            bias=float(np.linalg.norm(terms.mean(axis=0) - reference)) if ok.any() else math.nan,
            bias_se=spread / math.sqrt(max(int(ok.sum()), 1)), sample_std=spread,
            exact_calls=objective.ngrad - before, failed=int((~ok).sum()),
            baseline_std=by_baseline))
    return out


# --- descent ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class DescentRun:
    """One descent: start, end, its cost, iterations (gradient evaluations), why it stopped,
    the branch it stopped on, and whether it reached the global optimum."""

    method: str
    s: float
    start: tuple[float, ...]
    end: tuple[float, ...]
    value: float
    iterations: int
    stop: str
    branch: str
    reached: bool


def _project(objective: Objective, x: Array) -> Array:
    return np.clip(x, objective.lo, objective.hi)


def _fd_gradient(objective: Objective, x: Array) -> Array:
    h = FD_STEP * objective.width
    rows = []
    for i in range(x.size):
        for sign in (1.0, -1.0):
            y = x.copy()
            y[i] += sign * h[i]
            rows.append(y)
    rows_arr = _project(objective, np.array(rows))
    c = objective.values(rows_arr)
    return np.array([(c[2 * i] - c[2 * i + 1]) / (rows_arr[2 * i, i] - rows_arr[2 * i + 1, i])
                     for i in range(x.size)])


def where_stopped(objective: Objective, x: npt.ArrayLike) -> str:
    """Where a descent ended: "at a switch" when a step of SWITCH_PROBE (relative to the box)
    along some axis reaches another branch, else "at a bound" when a decision sits on one, else
    "on a smooth piece"."""
    x = np.asarray(x, dtype=np.float64).ravel()
    probes = [x]
    for i in range(x.size):
        for sign in (1.0, -1.0):
            y = x.copy()
            y[i] += sign * SWITCH_PROBE * objective.width[i]
            probes.append(_project(objective, y))
    labels = objective.branches(np.vstack(probes))
    if any(label != labels[0] for label in labels[1:]):
        return "at a switch"
    if np.any((x <= objective.lo) | (x >= objective.hi)):
        return "at a bound"
    return "on a smooth piece"


def descend(objective: Objective, start: npt.ArrayLike, method: str, optimum: float, *,
            max_iter: int = 60) -> DescentRun:
    """Projected descent from ``start`` with ``method`` = "exact" (one-sided derivatives),
    "fd" (central differences) or "lbfgsb" (SciPy L-BFGS-B with the exact derivative)."""
    x = _project(objective, np.asarray(start, dtype=np.float64).ravel())
    x0 = x.copy()
    if method == "lbfgsb":
        count = [0]

        def fun(z: Array) -> tuple[float, Array]:
            count[0] += 1
            c = objective.value(z)
            if not math.isfinite(c):
                return 1e300, np.zeros_like(z)
            return c, objective.gradient(z)

        try:
            res = minimize(fun, x, jac=True, method="L-BFGS-B",
                           bounds=list(zip(objective.lo, objective.hi)),
                           options={"maxiter": max_iter, "maxfun": 2 * max_iter,
                                    "ftol": 1e-15, "gtol": 1e-12})
            x, iterations = _project(objective, res.x), count[0]
            stop = ("converged" if res.status == 0 else
                    "iteration limit" if res.status == 1 else "line search failed")
        except SimulationError:
            iterations, stop = count[0], "simulation failed"
    elif method in ("exact", "fd"):
        grad: Callable[[Array], Array] = (
            objective.gradient if method == "exact" else lambda z: _fd_gradient(objective, z))
        c = objective.value(x)
        stop, iterations = "iteration limit", 0
        try:
            g = grad(x)
            iterations = 1
            t = 0.25 / max(float(np.max(np.abs(g) / objective.width)), 1e-300)
            while iterations < max_iter:
                accepted = False
                while t * float(np.max(np.abs(g) / objective.width)) > MIN_STEP:
                    y = _project(objective, x - t * g)
                    cy = objective.value(y)
                    if math.isfinite(cy) and cy <= c - ARMIJO * float(g @ (x - y)):
                        accepted = True
                        break
                    t *= 0.5
                if not accepted:
                    stop = "line search failed"
                    break
                moved = float(np.max(np.abs(y - x) / objective.width))
                x, c, t = y, cy, 2.0 * t
                if moved < STEP_TOL:
                    stop = "converged"
                    break
                g = grad(x)
                iterations += 1
        except SimulationError:
            stop = "simulation failed"
    else:
        raise InvalidInputError(f"method must be exact, fd or lbfgsb, got {method!r}")
    value = objective.value(x)
    return DescentRun(method=method, s=objective.s, start=tuple(x0.tolist()),
                      end=tuple(x.tolist()), value=value, iterations=iterations,
                      stop=f"{stop}, {where_stopped(objective, x)}",
                      branch=objective.branches(x)[0],
                      reached=bool(value - optimum <= VALUE_TOL))


def policy_gradient_descent(objective: Objective, start: npt.ArrayLike, estimator: str,
                            sigma: float, samples: int, optimum: float,
                            rng: np.random.Generator, *, iterations: int = 60,
                            rate: float = 0.1) -> DescentRun:
    """Stochastic projected descent of J_sigma with the ``estimator`` ("zeroth" or "first")
    of ``samples`` draws: steps of rate / sqrt(k) of the box along the estimate's direction;
    the answer is the mean of the last half of the iterates (Polyak averaging)."""
    terms_of = {"zeroth": zeroth_order_terms, "first": first_order_terms}.get(estimator)
    if terms_of is None:
        raise InvalidInputError(f"estimator must be zeroth or first, got {estimator!r}")
    x = _project(objective, np.asarray(start, dtype=np.float64).ravel())
    x0 = x.copy()
    tail = []
    for k in range(1, iterations + 1):
        g = terms_of(objective, x, sigma, rng.standard_normal((samples, objective.m)))
        g = g[np.all(np.isfinite(g), axis=1)]  # draws whose maneuver failed are left out
        g = (g.mean(axis=0) if len(g) else np.zeros(objective.m)) * objective.width
        norm = float(np.linalg.norm(g))
        if norm > 0 and math.isfinite(norm):
            x = _project(objective, x - rate / math.sqrt(k) * objective.width * g / norm)
        if k > iterations // 2:
            tail.append(x)
    x = np.mean(tail, axis=0)
    value = objective.value(x)
    return DescentRun(method=f"pg-{estimator} sigma={sigma:g} N={samples}", s=objective.s,
                      start=tuple(x0.tolist()), end=tuple(x.tolist()), value=value,
                      iterations=iterations,
                      stop=f"iteration budget, {where_stopped(objective, x)}",
                      branch=objective.branches(x)[0],
                      reached=bool(value - optimum <= VALUE_TOL))


# --- the smoothed model -----------------------------------------------------------------------
#: the library's smoothed counterpart of a system, by the system's name
SMOOTHED = {"biped": "biped_smooth", "rocking_bar": "rocking_bar_soft"}


def smoothed_system(name: str) -> str:
    """The library name of the smoothed counterpart of a library system: the biped with its
    input switch smoothed over eps (:mod:`~biped_opt.systems.library.smooth_biped`), the rocking
    bar with soft contacts of width eps (:mod:`~biped_opt.systems.library.soft_rocking_bar`)."""
    if name not in SMOOTHED:
        raise InvalidInputError(f"no smoothed model of {name!r} (smoothed models: "
                                f"{', '.join(SMOOTHED)})")
    return SMOOTHED[name]


def smooth_problem(problem: Problem, eps: float) -> Problem:
    """``problem`` on its system's smoothed model (:func:`smoothed_system`) of width eps."""
    if not (isinstance(eps, float) and eps > 0 and math.isfinite(eps)):
        raise InvalidInputError(f"eps must be a positive number, got {eps!r}")
    smooth_system = smoothed_system(problem.facts.name)
    name = problem.name.split(":")[-1]
    declared = system_facts(smooth_system).problems
    smooth = get_problem(smooth_system, name if name in declared else problem.maneuver)
    return replace(smooth, parameters=(*problem.parameters, ("eps", eps)),
                   name=f"{name} (eps={eps:g})")


@dataclass(frozen=True)
class SmoothingResult:
    """The optimum of the smoothed model against the real one at one s: policies, the smoothed
    model's value, the real value V*, and what the smoothed optimum costs on the real model."""

    problem: str
    eps: float
    s: float
    policy: dict[str, float]
    smooth_value: float
    exact_policy: dict[str, float]
    exact_value: float
    cost_on_exact: float

    @property
    def loss(self) -> float:
        """c_exact(u*_eps) - V*: the price of optimising the smoothed model."""
        return self.cost_on_exact - self.exact_value


# --- the study --------------------------------------------------------------------------------
#: (system, problem, s of the estimator study, s values of the descent study)
PROBLEMS = (
    ("biped", "touchdown", 0.05, (-0.1, -0.02, 0.02, 0.1)),
    ("biped", "liftoff", 0.01, (-0.05, -0.01, 0.005, 0.01, 0.05)),
    ("biped", "liftoff_variant", 0.02, (-0.1, -0.02, 0.02, 0.1)),
    ("rocking_bar", "drop", 0.05, (-0.1, -0.02, 0.02, 0.1)),
)


def study_problems(names: Sequence[str] | None = None) -> list[tuple[Problem, float, tuple]]:
    out = []
    for system, name, s_est, s_descent in PROBLEMS:
        if names and name not in names:
            continue
        out.append((get_problem(system, name), s_est, s_descent))
    if not out:
        raise InvalidInputError(f"no such problem among {', '.join(p[1] for p in PROBLEMS)}: "
                                f"{', '.join(names or [])}")
    return out


@dataclass(frozen=True)
class GradientSizes:
    """How much the study computes; a pair holds the size for a problem of one decision, then
    for one of two or more.

    - ``starts``: starting decisions per axis of each descent grid;
    - ``samples``: draws of each estimator's bias and spread;
    - ``iterations``: the budget of every descent, deterministic and stochastic;
    - ``quadrature``: grid points per axis of the reference D J_sigma;
    - ``every_other_s``: descend at every other of a problem's s values only."""

    starts: tuple[int, int] = (7, 4)
    samples: int = 20000
    iterations: int = 60
    quadrature: tuple[int, int] = (8001, 241)
    every_other_s: bool = False

    #: the bounds of each size, (low, high): the work is bounded before anything is allocated
    LIMITS: ClassVar[dict[str, tuple[int, int]]] = {
        "starts": (1, 20), "samples": (2, 200_000), "iterations": (1, 1000),
        "quadrature": (3, 20_001)}
    #: the most points of a quadrature grid (points per axis ** decisions)
    MAX_QUADRATURE_POINTS: ClassVar[int] = 1_000_000

    def __post_init__(self) -> None:
        for name, (low, high) in self.LIMITS.items():
            value = getattr(self, name)
            paired = name in ("starts", "quadrature")
            values = value if paired and isinstance(value, tuple) and len(value) == 2 else \
                None if paired else (value,)
            if values is None or not all(isinstance(v, int) and not isinstance(v, bool)
                                         and low <= v <= high for v in values):
                what = "a pair of integers" if paired else "an integer"
                raise InvalidInputError(f"{name} must be {what} in [{low}, {high}], "
                                        f"got {value!r}")
        if not isinstance(self.every_other_s, bool):
            raise InvalidInputError(f"every_other_s must be True or False, got "
                                    f"{self.every_other_s!r}")

    @staticmethod
    def _of(pair: tuple[int, int], m: int) -> int:
        return pair[0] if m == 1 else pair[1]

    def starts_per_axis(self, m: int) -> int:
        return self._of(self.starts, m)

    def quadrature_points(self, m: int) -> int:
        """Grid points per axis of the reference for ``m`` decisions (refused when the grid
        would exceed :data:`MAX_QUADRATURE_POINTS`)."""
        n = self._of(self.quadrature, m)
        if n ** m > self.MAX_QUADRATURE_POINTS:
            raise InvalidInputError(f"a quadrature of {n} points per axis over {m} decisions is "
                                    f"{n ** m} points, more than {self.MAX_QUADRATURE_POINTS}")
        return n

    def describe(self) -> str:
        def pair(v: tuple[int, int]) -> str:
            return f"{v[0]}" if v[0] == v[1] else f"{v[0]} (one decision) or {v[1]} (two)"

        return (f"starts {pair(self.starts)} per axis, samples {self.samples}, iterations "
                f"{self.iterations}, quadrature {pair(self.quadrature)} per axis"
                f"{', every other s' if self.every_other_s else ''}")


#: the whole study (the tables of the docs)
FULL = GradientSizes()
#: ``--quick``: small grids and samples (a few seconds per problem)
QUICK = GradientSizes(starts=(3, 2), samples=2000, iterations=30, every_other_s=True)


@dataclass
class GradientStudy:
    """Everything one run of the study measured, per problem name."""

    seed: int
    quick: bool
    sizes: GradientSizes = FULL
    optimum: dict[str, dict[float, float]] = field(default_factory=dict)
    switches: dict[str, list[float]] = field(default_factory=dict)
    points: dict[str, dict[str, tuple[float, ...]]] = field(default_factory=dict)
    references: dict[str, dict[tuple[str, float], tuple[Array, float]]] = field(
        default_factory=dict)
    stats: dict[str, dict[str, list[EstimatorStats]]] = field(default_factory=dict)
    runs: dict[str, list[DescentRun]] = field(default_factory=dict)
    smoothing: dict[str, list[SmoothingResult]] = field(default_factory=dict)
    curves: dict[str, dict[str, Any]] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """The measured numbers as plain data (for JSON)."""
        return {
            "seed": self.seed, "quick": self.quick,
            "sizes": asdict(self.sizes),
            "problems": {name: {
                "optimum": {str(s): v for s, v in self.optimum[name].items()},
                "switches": [float(v) for v in self.switches[name]],
                "points": {k: list(v) for k, v in self.points[name].items()},
                "estimators": [
                    {"point": label, "reference": self.references[name][(label, e.sigma)][0]
                     .tolist(), "reference_error": self.references[name][(label, e.sigma)][1],
                     **asdict(e)}
                    for label, stats in self.stats[name].items() for e in stats],
                "descent": [{**row, "failures": [list(f) for f in row["failures"]]}
                            for row in self.summary(name)],
                "runs": [asdict(r) for r in self.runs[name]],
                "smoothing": [{**asdict(r), "loss": r.loss}
                              for r in self.smoothing.get(name, [])],
            } for name in self.curves}}

    def summary(self, name: str) -> list[dict[str, Any]]:
        """Per method: runs, fraction reaching the optimum, median iterations, the median
        final gap c - V* (how far the runs that fall short stop: a stochastic method's step
        schedule shows here), and the failures counted by (stop reason, branch)."""
        by: dict[str, list[DescentRun]] = {}
        for r in self.runs.get(name, []):
            by.setdefault(r.method, []).append(r)
        rows = []
        for method, runs in by.items():
            failed = [r for r in runs if not r.reached]
            rows.append({
                "method": method, "runs": len(runs),
                "reached": sum(r.reached for r in runs) / len(runs),
                "iterations": float(np.median([r.iterations for r in runs])),
                "gap": float(np.median([r.value - self.optimum[name][r.s] for r in runs])),
                "failures": Counter(f"{r.stop} on {r.branch}" for r in failed).most_common(3)})
        return rows


def _starts(objective: Objective, per_axis: int) -> Array:
    axes = [np.linspace(lo, hi, per_axis + 2)[1:-1] for lo, hi in zip(objective.lo,
                                                                      objective.hi)]
    return np.array(list(itertools.product(*axes)))


def run_gradient_study(*, seed: int = 0, quick: bool = False,
                       problems: Sequence[str] | None = None,
                       sigmas: Sequence[float] = (0.003, 0.03),
                       sample_counts: Sequence[int] = (4, 64),
                       eps_values: Sequence[float] = (0.02, 0.002),
                       sizes: GradientSizes | None = None,
                       progress: Callable[[str], None] | None = None) -> GradientStudy:
    """The gradient study (module docstring) on the study problems, as big as ``sizes`` says
    (default :data:`QUICK` when ``quick``, for ``make demo`` and tests, else :data:`FULL`).
    Reproducible: all draws come from ``seed``."""
    say = progress or (lambda _msg: None)
    sizes = sizes if sizes is not None else QUICK if quick else FULL
    if not isinstance(sizes, GradientSizes):
        raise InvalidInputError(f"sizes must be GradientSizes, got {sizes!r}")
    study = GradientStudy(seed=seed, quick=quick, sizes=sizes)
    chosen = study_problems(problems)
    for problem, _, _ in chosen:  # (a grid too big is refused before any work)
        sizes.quadrature_points(len(problem.decision_names))
    for problem, s_est, s_values in chosen:
        name = problem.name.split(":")[-1]
        # one stream per problem: its numbers do not depend on which others are studied
        rng = np.random.default_rng([seed, [p[1] for p in PROBLEMS].index(name)])
        s_values = s_values[1::2] if sizes.every_other_s else s_values
        say(f"{name}: optima")
        study.optimum[name] = {s: optimal_policy(problem, s).value for s in (*s_values, s_est)}
        # estimators at the switch nearest the optimum (near) and at the optimum (away)
        best = optimal_policy(problem, s_est)
        objective = Objective(problem, s_est)
        x_best = best.inputs[objective.cols]
        axis = int(np.argmax(np.abs(x_best - 0.5 * (objective.lo + objective.hi))
                             / objective.width)) if objective.m > 1 else 0
        switches = find_switches(objective, x_best, axis)
        study.switches[name] = switches
        points = {"away": tuple(x_best.tolist())}
        if switches:
            near = x_best.copy()
            near[axis] = min(switches, key=lambda v: abs(v - x_best[axis]))
            points["near"] = tuple(near.tolist())
        study.points[name] = points
        study.references[name] = {}
        study.stats[name] = {}
        for label, x in points.items():
            study.stats[name][label] = []
            for sigma in sigmas:
                say(f"{name}: estimators {label}, sigma {sigma:g}")
                ref = smoothed_gradient(objective, x, sigma * float(objective.width[axis]),
                                        points=sizes.quadrature_points(objective.m))
                study.references[name][(label, sigma)] = ref
                # recorded with sigma relative to the decision's bound interval
                study.stats[name][label] += [replace(e, sigma=sigma) for e in estimator_stats(
                    objective, x, sigma * float(objective.width[axis]), ref[0], rng,
                    sizes.samples)]
        grid = np.linspace(objective.lo[axis], objective.hi[axis], 801)
        rows = np.tile(x_best, (grid.size, 1))
        rows[:, axis] = grid
        study.curves[name] = {"s": s_est, "axis": problem.decision_names[axis], "u": grid,
                              "cost": objective.values(rows), "optimum": x_best[axis]}
        # deterministic and stochastic descent from a grid of starts at each s
        runs = []
        for s in s_values:
            obj = Objective(problem, s)
            opt = study.optimum[name][s]
            for start in _starts(obj, sizes.starts_per_axis(obj.m)):
                say(f"{name}: descent at s = {s:g} from {np.round(start, 3).tolist()}")
                for method in ("exact", "fd", "lbfgsb"):
                    runs.append(descend(obj, start, method, opt, max_iter=sizes.iterations))
                for estimator in ("zeroth", "first"):
                    for sigma in sigmas:
                        for n in sample_counts:
                            runs.append(policy_gradient_descent(
                                obj, start, estimator, sigma, n, opt, rng,
                                iterations=sizes.iterations))
        study.runs[name] = runs
        if problem.facts.name in SMOOTHED:
            study.smoothing[name] = []
            for eps in eps_values:
                smooth = smooth_problem(problem, float(eps))
                for s in s_values:
                    say(f"{name}: smoothed model eps = {eps:g}, s = {s:g}")
                    r = optimal_policy(smooth, s)
                    exact = optimal_policy(problem, s)
                    obj = Objective(problem, s)
                    study.smoothing[name].append(SmoothingResult(
                        problem=name, eps=float(eps), s=s, policy=r.policy,
                        smooth_value=r.value, exact_policy=exact.policy,
                        exact_value=exact.value,
                        cost_on_exact=obj.value(r.inputs[obj.cols])))
    return study


# --- text -------------------------------------------------------------------------------------
def report(study: GradientStudy, sample_counts: Sequence[int] = (4, 64)) -> str:
    """The study's three tables as Markdown text."""
    preset = QUICK if study.quick else FULL
    sized = "" if study.sizes == preset else f"; {study.sizes.describe()}"
    lines = [f"gradient study, seed {study.seed}{' (quick)' if study.quick else ''}{sized}", "",
             "estimators of D J_sigma (sigma relative to the decision's bound interval; bias = "
             "|mean - D J_sigma| +- its standard error; std of the N-sample estimate)", "",
             "| problem | point | sigma | D J_sigma | estimator | bias | "
             + " | ".join(f"std N={n}" for n in sample_counts) + " | exact calls | failed |",
             "|---|---|---|---|---|---|" + "---|" * len(sample_counts) + "---|---|"]
    for name, by_point in study.stats.items():
        for label, stats in by_point.items():
            x = study.points[name][label]
            for e in stats:
                sigma = e.sigma
                ref, err = study.references[name][(label, sigma)]
                lines.append(
                    f"| {name} | {label} ({', '.join(f'{v:.4g}' for v in x)}) | {sigma:g} | "
                    f"{', '.join(f'{v:.4g}' for v in ref)} (+-{err:.1g}) | {e.estimator} | "
                    f"{e.bias:.3g} +- {e.bias_se:.2g} | "
                    + " | ".join(f"{e.std(n):.3g}" for n in sample_counts)
                    + f" | {e.exact_calls} | {e.failed} |")
    lines += ["", "zeroth-order spread over first-order spread, by the zeroth-order baseline b "
              "(same draws): c(u) the cost at the point (the estimator's), none, the draws' mean",
              "", "| problem | point | sigma | first-order std | b = c(u) | b = 0 | b = mean |",
              "|---|---|---|---|---|---|---|"]
    for name, by_point in study.stats.items():
        for label, stats in by_point.items():
            for zeroth, first in zip(stats[0::2], stats[1::2]):
                if not zeroth.baseline_std or first.sample_std == 0:
                    continue
                ratios = " | ".join(f"{zeroth.baseline_std[b] / first.sample_std:.3g}x"
                                    for b in ZEROTH_BASELINES)
                lines.append(f"| {name} | {label} | {zeroth.sigma:g} | "
                             f"{first.sample_std:.3g} | {ratios} |")
    lines += ["", "descent from a grid of starts and s (reached: final cost within "
              f"{VALUE_TOL:g} of the global optimum)", "",
              "| problem | method | runs | reached | median iterations | median c - V* | "
              "failures (count) |",
              "|---|---|---|---|---|---|---|"]
    for name in study.runs:
        for row in study.summary(name):
            fails = "; ".join(f"{k} ({v})" for k, v in row["failures"]) or "-"
            lines.append(f"| {name} | {row['method']} | {row['runs']} | "
                         f"{100 * row['reached']:.0f}% | {row['iterations']:g} | "
                         f"{row['gap']:.2g} | {fails} |")
    if study.smoothing:
        lines += ["", "the smoothed model's optimum on the real model (loss = c(u*_eps) - V*)", "",
                  "| problem | eps | s | u*_eps | u* | V* | c(u*_eps) | loss |",
                  "|---|---|---|---|---|---|---|---|"]
        for name, results in study.smoothing.items():
            for r in results:
                pol = ", ".join(f"{v:.4g}" for v in r.policy.values())
                exact = ", ".join(f"{v:.4g}" for v in r.exact_policy.values())
                lines.append(f"| {name} | {r.eps:g} | {r.s:g} | {pol} | {exact} | "
                             f"{r.exact_value:.4g} | {r.cost_on_exact:.4g} | {r.loss:.3g} |")
    return "\n".join(lines)

