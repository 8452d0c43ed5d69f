"""Optimal policy and value functions pi(th0), nu(th0) of Eqs. (4)-(6) of [1]_ (MODEL.md Sec. 5).

For each th0 the problem is a scalar minimisation: in the shipped problems exactly one decision
input acts on the outcome, the one whose contact mode occurs (u1 in LEFT single stance, u2 in
RIGHT single stance, u12 in double stance; MODEL.md Sec. 2). The others cannot change th_f, so
their optimum is the bound point nearest 0 (:meth:`OptimalControlProblem.default_decision`).
Which modes occur is read from the trajectory at the default decisions: in these maneuvers the
inputs act only after the mode sequence has committed to its single stance.

The cost of the active decision is piecewise smooth and, for liftoff, discontinuous where the
mode order flips. The method (MODEL.md Sec. 5):

1. **bracket globally**: evaluate the cost on a uniform grid over the bounds (one parallel
   :func:`~biped_opt.hybrid.simulate_batch` call) and record each point's mode order;
2. **refine each candidate**: around every grid local minimum, within the run of grid points of
   the same mode order (extended to the located switch when the minimum sits at the run's edge),
   run SciPy's ``minimize_scalar(method="bounded")``; the bounds themselves are candidates too;
3. the best candidate is the optimum; its mode order is the result's ``branch``.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from biped_opt.control.solve import GRID_POINTS, XATOL, refine_minimum
from biped_opt.errors import InvalidInputError, InvalidParameterError
from biped_opt.hybrid import simulate, simulate_batch
from biped_opt.hybrid.simulate import INPUT_NAMES
from biped_opt.maneuvers import check_theta0
from biped_opt.model.modes import ContactMode
from biped_opt.model.params import BipedParams
from biped_opt.optimal.problems import INPUT_MODES, OptimalControlProblem
from biped_opt.simulation.trajectory import Trajectory

__all__ = [
    "Candidate",
    "OptimalResult",
    "optimal_policy",
    "optimal_sweep",
    "active_decisions",
    "branch_label",
    "GRID_POINTS",
    "XATOL",
]

Array = npt.NDArray[np.float64]

def branch_label(modes: Sequence[ContactMode] | None, ok: bool = True, status: str = "") -> str:
    """The mode order as text, e.g. ``"AIR->LEFT->GROUND"``; failed simulations are labelled."""
    if not ok or modes is None:
        return f"FAILED:{status}"
    return "->".join(ContactMode(m).name for m in modes)


def active_decisions(
    problem: OptimalControlProblem, modes: Sequence[ContactMode]
) -> tuple[str, ...]:
    """Decisions whose contact mode occurs in ``modes`` (the only ones that can move th_f)."""
    present = {ContactMode(m) for m in modes}
    return tuple(d for d in problem.decisions if INPUT_MODES[d] in present)


@dataclass(frozen=True)
class Candidate:
    """A local optimum found on one branch (mode order) of the active decision's cost."""

    branch: str
    decision: float
    value: float


@dataclass(frozen=True, kw_only=True, eq=False)
class OptimalResult:
    """Optimal policy pi(th0) and value nu(th0) (Eqs. (5), (6) of [1]_) at one th0.

    ``policy`` maps every decision input to its optimal value; ``inputs`` is the full vector
    (u1, u2, u12) simulated. ``branch`` is the optimum's mode order, ``active`` the decision that
    acts (None when none does, e.g. touchdown at th0 = 0), ``bound`` "lower"/"upper" when the
    active decision sits on that bound. ``nsim`` counts simulations, ``nfev`` right-hand-side
    evaluations, ``nit`` minimize_scalar iterations.
    """

    problem: OptimalControlProblem = field(repr=False)
    theta0: float
    policy: dict[str, float]
    inputs: Array = field(repr=False)
    value: float
    outcome: float
    modes: tuple[ContactMode, ...]
    event_times: Array = field(repr=False)
    branch: str
    active: str | None
    bound: str | None
    candidates: tuple[Candidate, ...] = field(repr=False)
    success: bool
    status: int
    message: str
    nfev: int
    nsim: int
    nit: int
    trajectory: Trajectory | None = field(repr=False, default=None)

    @property
    def fun(self) -> float:
        """SciPy's name for the optimal value."""
        return self.value

    @property
    def x(self) -> Array:
        """Optimal decisions in the order of ``problem.decisions`` (SciPy's name)."""
        return np.array([self.policy[d] for d in self.problem.decisions])

    def as_dict(self) -> dict:
        """Plain-data form (JSON-ready)."""
        return {
            "problem": self.problem.name,
            "theta0": self.theta0,
            "policy": dict(self.policy),
            "value": self.value,
            "outcome": self.outcome,
            "modes": [m.name for m in self.modes],
            "event_times": [float(t) for t in self.event_times],
            "branch": self.branch,
            "active": self.active,
            "bound": self.bound,
            "candidates": [
                {"branch": c.branch, "decision": c.decision, "value": c.value}
                for c in self.candidates
            ],
            "success": self.success,
            "status": self.status,
            "message": self.message,
            "nfev": self.nfev,
            "nsim": self.nsim,
            "nit": self.nit,
        }


# --- internals ------------------------------------------------------------------------------
class _Counter:
    def __init__(self) -> None:
        self.nsim = 0
        self.nfev = 0
        self.nit = 0


def _check_grid_points(grid_points: int) -> int:
    if isinstance(grid_points, bool) or not isinstance(grid_points, int) or grid_points < 3:
        raise InvalidInputError(f"grid_points must be an integer >= 3, got {grid_points!r}")
    return grid_points


def _check_xatol(xatol: float) -> float:
    if not (isinstance(xatol, (int, float)) and math.isfinite(xatol) and xatol > 0):
        raise InvalidInputError(f"xatol must be a positive number, got {xatol!r}")
    return float(xatol)


def _single(problem: OptimalControlProblem, th0: float, count: _Counter
            ) -> Callable[[Array], tuple[float, str, Trajectory]]:
    """u (3,) -> (cost, branch, trajectory), counting simulations."""

    def run(u: Array) -> tuple[float, str, Trajectory]:
        tr = simulate(problem.maneuver, th0, u, params=problem.params, options=problem.options)
        count.nsim += 1
        count.nfev += tr.nfev
        label = branch_label(tr.mode_sequence, tr.success, tr.status.name)
        cost = problem.cost(tr.outcome, u) if tr.success else math.inf
        return float(cost), label, tr

    return run


def _active_of(problem: OptimalControlProblem, th0: float, label: str) -> str | None:
    if label.startswith("FAILED"):
        return None
    active = active_decisions(problem, [ContactMode[n] for n in label.split("->")])
    if len(active) > 1:
        raise InvalidParameterError(
            f"{problem.name} problem at theta0 = {th0}: decisions {', '.join(active)} all act on "
            "the outcome; only problems with one acting decision per th0 are supported"
        )
    return active[0] if active else None


def _refine(
    problem: OptimalControlProblem,
    th0: float,
    active: str,
    us: Array,
    costs: Array,
    labels: Sequence[str],
    count: _Counter,
    xatol: float,
) -> tuple[float, list[Candidate]]:
    """Best decision value of ``active`` from the grid data, and the candidates examined."""
    run = _single(problem, th0, count)
    base = problem.inputs()
    j = INPUT_NAMES.index(active)
    lo_b, hi_b = problem.bound(active)

    def at(u: float) -> Array:
        x = base.copy()
        x[j] = u
        return x

    n = us.size
    finite = np.isfinite(costs)
    minima = [
        k for k in range(n)
        if finite[k]
        and (k == 0 or costs[k] <= costs[k - 1])
        and (k == n - 1 or costs[k] <= costs[k + 1])
    ]
    candidates: list[Candidate] = []
    seen: set[tuple[float, float]] = set()
    for k in minima:
        best_u, best_c, nit, key = refine_minimum(lambda u: run(at(u)), us, costs, labels, k,
                                                  (lo_b, hi_b), xatol)
        count.nit += nit
        if key in seen:
            continue
        seen.add(key)
        candidates.append(Candidate(branch=labels[k], decision=best_u, value=best_c))
    if not candidates:
        return math.nan, []
    best = min(candidates, key=lambda c: c.value)
    return best.decision, candidates


def _result(
    problem: OptimalControlProblem,
    th0: float,
    active: str | None,
    decision: float,
    candidates: list[Candidate],
    count: _Counter,
) -> OptimalResult:
    policy = {d: problem.default_decision(d) for d in problem.decisions}
    if active is not None and math.isfinite(decision):
        policy[active] = decision
    u = problem.inputs(policy)
    cost, label, tr = _single(problem, th0, count)(u)
    if active is not None and not candidates:
        status, message = 1, "no grid point of the decision interval gave a successful simulation"
    elif not tr.success:
        status, message = 2, f"simulation at the optimum failed: {tr.message}"
    else:
        status, message = 0, "optimum found" if active else (
            "no decision input acts on the outcome at this th0: decisions at their default"
        )
    bound = None
    if active is not None:
        lo, hi = problem.bound(active)
        bound = "lower" if policy[active] == lo else "upper" if policy[active] == hi else None
    return OptimalResult(
        problem=problem,
        theta0=th0,
        policy=policy,
        inputs=u,
        value=cost,
        outcome=tr.outcome,
        modes=tuple(map(ContactMode, tr.mode_sequence)),
        event_times=np.array(tr.event_times),
        branch=label,
        active=active,
        bound=bound,
        candidates=tuple(candidates),
        success=status == 0,
        status=status,
        message=message,
        nfev=count.nfev,
        nsim=count.nsim,
        nit=count.nit,
        trajectory=tr,
    )


def _grid(problem: OptimalControlProblem, active: str, grid_points: int) -> Array:
    lo, hi = problem.bound(active)
    us = np.linspace(lo, hi, grid_points)
    us[0], us[-1] = lo, hi
    return us


def _with_params(
    problem: OptimalControlProblem, params: BipedParams | None
) -> OptimalControlProblem:
    if not isinstance(problem, OptimalControlProblem):
        raise InvalidInputError(f"problem must be an OptimalControlProblem, got {problem!r}")
    if params is None:
        return problem
    if not isinstance(params, BipedParams):
        raise InvalidInputError(f"params must be BipedParams, got {params!r}")
    return dataclasses.replace(problem, params=params)


# --- public API ----------------------------------------------------------------------------
def optimal_policy(
    problem: OptimalControlProblem,
    theta0: float,
    *,
    params: BipedParams | None = None,
    grid_points: int = GRID_POINTS,
    xatol: float = XATOL,
) -> OptimalResult:
    """Optimal policy and value at ``theta0`` (Eqs. (4)-(6) of [1]_), globally bracketed.

    ``params`` overrides the problem's biped parameters; ``grid_points`` is the size of the
    bracketing grid over the active decision's bounds, ``xatol`` the tolerance of the bounded
    Brent refinement. Raises only for invalid arguments; a failure to find any feasible point is
    reported by ``success``/``status``.
    """
    problem = _with_params(problem, params)
    th0 = check_theta0(problem.maneuver, theta0)
    grid_points = _check_grid_points(grid_points)
    xatol = _check_xatol(xatol)
    count = _Counter()
    _, label0, _ = _single(problem, th0, count)(problem.inputs())
    active = _active_of(problem, th0, label0)
    if active is None:
        return _result(problem, th0, None, math.nan, [], count)
    us = _grid(problem, active, grid_points)
    u_grid = np.tile(problem.inputs(), (us.size, 1))
    u_grid[:, INPUT_NAMES.index(active)] = us
    batch = simulate_batch(
        problem.maneuver, np.full(us.size, th0), u_grid, params=problem.params,
        options=problem.options,
    )
    costs, labels = _batch_costs(problem, batch, slice(0, us.size))
    count.nsim += us.size
    count.nfev += int(batch.nfev.sum())
    decision, candidates = _refine(problem, th0, active, us, costs, labels, count, xatol)
    return _result(problem, th0, active, decision, candidates, count)


def _batch_costs(problem: OptimalControlProblem, batch, rows: slice) -> tuple[Array, list[str]]:
    idx = range(rows.start, rows.stop)
    ok = batch.success[rows]
    costs = np.where(ok, problem.cost(batch.outcome[rows], batch.inputs[rows]), np.inf)
    labels = [
        branch_label(batch.mode_sequence(k), bool(batch.success[k]), str(batch.status[k]))
        for k in idx
    ]
    return np.asarray(costs, dtype=np.float64), labels


def optimal_sweep(
    problem: OptimalControlProblem,
    theta0: npt.ArrayLike,
    *,
    params: BipedParams | None = None,
    grid_points: int = GRID_POINTS,
    xatol: float = XATOL,
    callback: Callable[[int, int], None] | None = None,
) -> tuple[OptimalResult, ...]:
    """:func:`optimal_policy` at every angle of ``theta0``, with the bracketing stage batched.

    All grids (every th0 times every grid input) run as one parallel batch; the refinements then
    run per th0. ``callback(done, total)`` is called after each th0 (for progress bars).
    """
    problem = _with_params(problem, params)
    th = np.atleast_1d(np.asarray(theta0, dtype=np.float64))
    if th.ndim != 1 or th.size == 0:
        raise InvalidInputError(f"theta0 must be a non-empty 1-D array, got shape {th.shape}")
    for value in th:
        check_theta0(problem.maneuver, value)
    grid_points = _check_grid_points(grid_points)
    xatol = _check_xatol(xatol)
    n = th.size
    base = simulate_batch(
        problem.maneuver, th, problem.inputs(), params=problem.params, options=problem.options
    )
    _, base_labels = _batch_costs(problem, base, slice(0, n))
    actives = [_active_of(problem, float(th[k]), base_labels[k]) for k in range(n)]
    rows_th, rows_u, owners = [], [], []
    for k, active in enumerate(actives):
        if active is None:
            continue
        us = _grid(problem, active, grid_points)
        u = np.tile(problem.inputs(), (us.size, 1))
        u[:, INPUT_NAMES.index(active)] = us
        rows_th.append(np.full(us.size, th[k]))
        rows_u.append(u)
        owners.append(k)
    starts = {}
    if owners:
        batch = simulate_batch(
            problem.maneuver, np.concatenate(rows_th), np.concatenate(rows_u),
            params=problem.params, options=problem.options,
        )
        for i, k in enumerate(owners):
            starts[k] = i * grid_points
    results = []
    for k in range(n):
        count = _Counter()
        count.nsim, count.nfev = 1, int(base.nfev[k])
        active = actives[k]
        if active is None:
            results.append(_result(problem, float(th[k]), None, math.nan, [], count))
        else:
            rows = slice(starts[k], starts[k] + grid_points)
            costs, labels = _batch_costs(problem, batch, rows)
            count.nsim += grid_points
            count.nfev += int(batch.nfev[rows].sum())
            us = batch.inputs[rows, INPUT_NAMES.index(active)]
            decision, candidates = _refine(
                problem, float(th[k]), active, us, costs, labels, count, xatol
            )
            results.append(_result(problem, float(th[k]), active, decision, candidates, count))
        if callback is not None:
            callback(k + 1, n)
    return tuple(results)
