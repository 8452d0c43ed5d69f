"""Optimal policies and values of any system's problems (Eqs. (4)-(6) of [1]_, SYSTEMS.md): the
one solver, the paper's biped included (its preset, :mod:`biped_opt.paper.solve`, names the
results in the paper's words).

For a :class:`~biped_opt.control.problems.Problem` and a value of the maneuver's parameter s,
minimise c(s, u) over the decision box. The cost is piecewise smooth in u (smooth while the mode
sequence is fixed, kinked or discontinuous where it changes), so a local method alone can stop on
the wrong piece. The method:

1. **which decisions act**: an input acts only in the contact modes whose forces depend on it
   (derived with the system: :meth:`~biped_opt.simulation.compiled.CompiledSystem.input_modes`);
   a decision that acts in no mode the trajectory visits cannot move the outcome and sits at its
   cheapest value, the bound point nearest 0;
2. **bracket globally**: the acting decisions' box is sampled on a uniform grid (65 points for
   one decision, 17 per axis for two, fewer beyond) in one parallel ``simulate_batch`` call;
   every grid point that is no worse than its axis neighbours is a candidate (the best 8).
   A grid of more than :data:`MAX_BRACKET` points (a robot's twelve joint efforts: 5^12) is
   replaced by a scrambled Sobol sample of that many points (seeded: the same every run);
   the candidates are then the problem's default inputs and the sample's best 3 points (a
   joint refinement in many dimensions costs thousands of simulations);
3. **refine each candidate** with SciPy: one decision - ``minimize_scalar(method="bounded")``
   inside the run of grid points with the same mode sequence (extended to the located switch),
   then a Newton polish and a Karush-Kuhn-Tucker test at a near bound
   (:func:`refine_minimum`); two or more decisions, optimised jointly -
   ``minimize(method="L-BFGS-B")`` within the bounds, gradients by central differences;
4. the best candidate is the optimum; if it visits a mode where a decision left at its default
   acts, the search is repeated with that decision included.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import enum
import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from biped_opt.control.problems import Problem
from biped_opt.errors import InvalidInputError
from biped_opt.piecewise import locate_switch
from biped_opt.simulation.compiled import CompiledSystem, compiled_with
from biped_opt.simulation.trajectory import Status, Trajectory, mode_name

__all__ = ["Candidate", "OptimalResult", "SystemOptimalResult", "optimal_policy",
           "optimal_sweep", "compiled_for", "branch_of", "GRID_AXIS"]

Array = npt.NDArray[np.float64]

#: grid points per axis of the bracketing stage, by number of acting decisions
GRID_AXIS = {1: 65, 2: 17, 3: 9, 4: 6}
#: candidates refined per s (the grid's best local minima)
MAX_CANDIDATES = 8
#: the most points of the bracketing stage (a power of 2, the Sobol sample's size beyond it;
#: the grid of four decisions, 6^4 = 1296 points, stays a grid)
MAX_BRACKET = 2048
#: candidates refined after a Sobol sample: the default inputs and the sample's best points
SAMPLE_CANDIDATES = 4
#: seed of the Sobol sample that replaces a grid of more than MAX_BRACKET points
SAMPLE_SEED = 0
#: central-difference step of the joint (L-BFGS-B) refinement, relative to each bound interval
GRAD_STEP = 1e-6


#: grid points of the global bracketing stage (spacing 1/64 of the bound interval)
GRID_POINTS = 65
#: absolute tolerance handed to minimize_scalar(method="bounded")
XATOL = 1e-10
#: a switch of mode order inside the decision interval is located to this width
SWITCH_TOL = 1e-12
#: the simulated cost is accurate to ~1e-14: a polished point may be this much worse
COST_NOISE = 1e-14
#: optima within this many polish steps of a bound get the bound (KKT) test
BOUND_ZONE = 10
#: stencil step of the final Newton polish, relative to the bound interval
POLISH_STEP = 5e-4


def _polish(
    run: Callable[[float], tuple[float, str, object]],
    u0: float,
    c0: float,
    label: str,
    a: float,
    b: float,
    step: float,
) -> tuple[float, float]:
    """One Newton step on c'(u) = 0 with fourth-order central differences of step ``step``.

    Brent on cost values alone stops where the cost is flat to its noise (~1e-14), i.e. some
    1e-7 from the minimiser; differences over a wide stencil (noise / step ~ 1e-11) locate it
    to ~1e-10. Skipped (the Brent point kept) unless the stencil stays on the branch and the
    new point is no worse.
    """
    if not (a <= u0 - 2 * step and u0 + 2 * step <= b):
        return u0, c0
    c = {}
    for m in (-2, -1, 1, 2):
        cost, lab, _ = run(u0 + m * step)
        if lab != label or not math.isfinite(cost):
            return u0, c0
        c[m] = cost
    grad = (8.0 * (c[1] - c[-1]) - (c[2] - c[-2])) / (12.0 * step)
    curv = (-c[2] + 16.0 * c[1] - 30.0 * c0 + 16.0 * c[-1] - c[-2]) / (12.0 * step**2)
    if not curv > 0.0:
        return u0, c0
    u1 = u0 - grad / curv
    if abs(u1 - u0) > step:
        return u0, c0
    c1, lab, _ = run(u1)
    if lab == label and c1 <= c0 + COST_NOISE * max(1.0, abs(c0)):
        return u1, c1
    return u0, c0


def _inward_slope(
    run: Callable[[float], tuple[float, str, object]],
    end: float,
    inward: float,
    step: float,
    label: str,
) -> float | None:
    """d c / d u at the bound ``end`` along the inward direction, from a one-sided stencil.

    A quartic through c(end + inward m step), m = 0..4, gives the slope to ~noise / step; a
    non-negative slope means the bound holds the minimum. None if the stencil leaves the branch.
    """
    offsets = inward * step * np.arange(5)
    values = []
    for off in offsets:
        cost, lab, _ = run(end + off)
        if lab != label or not math.isfinite(cost):
            return None
        values.append(cost)
    coeffs = np.polynomial.polynomial.polyfit(offsets, values, 4)
    return float(inward * coeffs[1])


def refine_minimum(
    run: Callable[[float], tuple[float, str, object]],
    us: Array,
    costs: Array,
    labels: Sequence[str],
    k: int,
    bounds: tuple[float, float],
    xatol: float,
) -> tuple[float, float, int, tuple[float, float]]:
    """Refine the grid local minimum k of a one-decision cost ``run(u) -> (cost, label, ...)``
    sampled at ``us``: (decision, cost, Brent iterations, the bracket searched).

    The bracket is the neighbouring grid points on the same branch, else the located switch;
    bounded Brent inside it, a Newton polish, the bounds themselves (Brent never evaluates an
    interval's ends), and near a bound the Karush-Kuhn-Tucker test on the inward slope
    (comparing cost values cannot decide it: the cost is flat there).
    """
    lo_b, hi_b = bounds
    n = us.size

    def label_of(u: float) -> str:
        return run(u)[1]

    if k == 0:
        a = us[0]
    elif labels[k - 1] == labels[k]:
        a = us[k - 1]
    else:
        a = locate_switch(label_of, float(us[k]), float(us[k - 1]), tol=SWITCH_TOL)[0]
    if k == n - 1:
        b = us[-1]
    elif labels[k + 1] == labels[k]:
        b = us[k + 1]
    else:
        b = locate_switch(label_of, float(us[k]), float(us[k + 1]), tol=SWITCH_TOL)[0]
    best_u, best_c, nit = float(us[k]), float(costs[k]), 0
    step = POLISH_STEP * (hi_b - lo_b)
    if b > a:
        from scipy.optimize import minimize_scalar  # (a third of a second: when used)

        res = minimize_scalar(lambda u: run(u)[0], bounds=(a, b), method="bounded",
                              options={"xatol": xatol})
        nit = int(res.nit)
        if res.fun <= best_c:
            best_u, best_c = float(res.x), float(res.fun)
        best_u, best_c = _polish(run, best_u, best_c, labels[k], a, b, step)
    for end in (a, b):
        if end in (lo_b, hi_b) and end != us[k]:
            c_end = run(end)[0]
            if c_end <= best_c:
                best_u, best_c = float(end), c_end
    for end, inward in ((lo_b, 1.0), (hi_b, -1.0)):
        if a <= end <= b and abs(best_u - end) <= BOUND_ZONE * step:
            slope = _inward_slope(run, end, inward, step, labels[k])
            if slope is not None and slope >= 0.0:
                best_u, best_c = float(end), run(end)[0]
    return best_u, best_c, nit, (float(a), float(b))



def compiled_for(problem: Problem) -> CompiledSystem:
    """The compiled system of ``problem`` with its parameters (one per process and parameter
    set: :func:`~biped_opt.simulation.compiled.compiled_with`)."""
    return compiled_with(problem.system, dict(problem.parameters))


def branch_of(compiled: CompiledSystem, initial: int, events: Array,
              status: Status | int | str = Status.OK) -> str:
    """The mode sequence as text from the contact-event rows of a trajectory
    (``air->left->left+right``); an impact after which the constraint separated at once
    (restitution) is named in brackets (``air->air[left]``); failures are labelled (``status``:
    a :class:`Status`, its code or its name)."""
    name = status if isinstance(status, str) else Status(status).name
    if name != "OK":
        return f"FAILED:{name}"
    names = compiled.constraints
    parts = [mode_name(initial, names)]
    for row in events:
        after, touched = int(row[5]), int(row[2])
        bounced = touched & ~after
        parts.append(mode_name(after, names) +
                     (f"[{mode_name(bounced, names)}]" if bounced else ""))
    return "->".join(parts)


@dataclass(frozen=True)
class Candidate:
    """A local optimum on one branch (mode sequence)."""

    branch: str
    policy: dict[str, float]
    value: float


@dataclass(frozen=True, kw_only=True, eq=False)
class OptimalResult:
    """Optimal policy pi(s) and value nu(s) of a problem at one s (Eqs. (5), (6) of [1]_).

    ``problem`` is the problem asked (a :class:`Problem`, or a preset that stands for one and
    offers ``decision_names``, ``name`` and ``facts``); ``inputs`` the full input vector
    simulated; ``modes`` the contact modes visited (bit masks) and ``branch`` their sequence as
    text. ``active`` names the acting decision ("u1+u2" when several act, None when none does);
    ``bound`` is "lower"/"upper" when a single acting decision sits on that bound, or
    ``"u1=lower,u2=upper"`` for several. ``status`` is 0 on success, 1 when no simulation of
    the search succeeded, 2 when the one at the optimum failed. ``nsim`` counts simulations,
    ``nfev`` the right-hand-side evaluations of the single ones (a batch does not report
    them), ``nit`` the bounded-Brent iterations."""

    problem: Any = field(repr=False)
    s: float
    policy: dict[str, float]
    inputs: Array = field(repr=False)
    value: float
    outcome: float
    t_final: float
    y_final: Array = field(repr=False)
    modes: tuple[int, ...]
    event_times: tuple[float, ...]
    branch: str
    active: str | None
    bound: str | None
    candidates: tuple[Candidate, ...] = field(repr=False)
    success: bool
    message: str
    nsim: int
    status: int = 0
    nfev: int = 0
    nit: int = 0
    trajectory: Trajectory | None = field(repr=False, default=None)

    @property
    def theta0(self) -> float:
        """The biped's name for s (its initial pitch)."""
        return self.s

    @property
    def fun(self) -> float:
        """SciPy's name for the optimal value."""
        return self.value

    @property
    def x(self) -> Array:
        """The decisions in the problem's order (SciPy's name)."""
        return np.array([self.policy[d] for d in self.problem.decision_names])

    def as_dict(self) -> dict[str, Any]:
        return {
            "problem": self.problem.name,
            "system": self.problem.facts.name,
            "s": self.s,
            "theta0": self.s,  # (the biped's name for s)
            "policy": dict(self.policy),
            "value": self.value,
            "outcome": self.outcome,
            "t_final": self.t_final,
            # named modes (a preset's enumeration) by name, bit masks as numbers
            "modes": [m.name if isinstance(m, enum.Enum) else int(m) for m in self.modes],
            "branch": self.branch,
            "event_times": [float(t) for t in self.event_times],
            "active": self.active,
            "bound": self.bound,
            "candidates": [{"branch": c.branch, "policy": c.policy, "value": c.value}
                           for c in self.candidates],
            "success": self.success,
            "status": self.status,
            "message": self.message,
            "nsim": self.nsim,
            "nfev": self.nfev,
            "nit": self.nit,
        }


#: the name the any-system lane's result had before it became the only one
SystemOptimalResult = OptimalResult


class _Runner:
    """u -> (cost, branch, trajectory) at one s, with a count of simulations."""

    def __init__(self, problem: Problem, compiled: CompiledSystem, s: float) -> None:
        self.problem, self.compiled, self.s = problem, compiled, s
        self.nsim = self.nfev = self.nit = 0

    def __call__(self, u: Array) -> tuple[float, str, Trajectory]:
        tr = self.compiled.simulate(self.problem.maneuver, self.s, u,
                                    options=self.problem.options)
        self.nsim += 1
        self.nfev += tr.nfev
        label = branch_of(self.compiled, tr.initial_mode, tr.event_rows[: tr.n_events], tr.status)
        cost = float(self.problem.cost(tr.outcome, tr.y_final, u)) if tr.success else math.inf
        return cost, label, tr

    def batch(self, rows: Array) -> tuple[Array, list[str]]:
        out = self.compiled.simulate_batch(self.problem.maneuver, np.full(len(rows), self.s),
                                           rows, options=self.problem.options)
        self.nsim += len(rows)
        costs = np.where(out.success, self.problem.cost(out.outcome, out.y_final, rows), np.inf)
        labels = [branch_of(self.compiled, out.initial_mode, out.event_rows[k, :n], status)
                  for k, (n, status) in enumerate(zip(out.n_events.tolist(), out.status.tolist()))]
        return np.asarray(costs, dtype=np.float64), labels


def _acting(problem: Problem, compiled: CompiledSystem, modes: Sequence[int]) -> list[str]:
    visited = set(modes)
    return [d for d in problem.decision_names if compiled.input_modes(d) & visited]


def _grid_rows(problem: Problem, acting: list[str], base: Array, names: tuple[str, ...],
               points: int | None) -> tuple[Array, list[Array] | None]:
    """The bracketing stage's input rows and the grid's axes (None: a Sobol sample, the grid
    having more than :data:`MAX_BRACKET` points)."""
    per_axis = points or GRID_AXIS.get(len(acting), 5)
    bounds = np.array([problem.bound(d) for d in acting], dtype=np.float64).reshape(-1, 2)
    cols = [names.index(d) for d in acting]
    if per_axis ** len(acting) > MAX_BRACKET:
        from scipy.stats import qmc

        unit = qmc.Sobol(d=len(acting), scramble=True, seed=SAMPLE_SEED).random_base2(
            int(math.log2(MAX_BRACKET)))
        rows = np.tile(base, (unit.shape[0], 1))
        rows[:, cols] = bounds[:, 0] + unit * (bounds[:, 1] - bounds[:, 0])
        return rows, None
    axes = []
    for lo, hi in bounds:
        axis = np.linspace(lo, hi, per_axis)
        axis[0], axis[-1] = lo, hi
        axes.append(axis)
    rows = np.tile(base, (per_axis ** len(acting), 1))
    for col, values in zip(cols, zip(*itertools.product(*axes))):
        rows[:, col] = values
    return rows, axes


def _grid_minima(costs: Array, shape: tuple[int, ...] | None) -> list[int]:
    """Flat indices of grid points no worse than their axis neighbours, best first (``shape``
    None: a sample's points, its best ones)."""
    if shape is None:
        found = np.flatnonzero(np.isfinite(costs))
        return [int(k) for k in found[np.argsort(costs[found], kind="stable")]][:MAX_CANDIDATES]
    grid = costs.reshape(shape)
    keep = np.isfinite(grid)
    for axis in range(grid.ndim):
        for step in (-1, 1):
            neighbour = np.roll(grid, step, axis=axis)
            edge: list[slice | int] = [slice(None)] * grid.ndim
            edge[axis] = 0 if step == 1 else -1
            neighbour[tuple(edge)] = np.inf
            keep &= grid <= neighbour
    found = np.flatnonzero(keep.ravel())
    return [int(k) for k in found[np.argsort(costs[found], kind="stable")]][:MAX_CANDIDATES]


def _refine_one(problem: Problem, run: _Runner, decision: str, base: Array,
                names: tuple[str, ...], axis: Array, costs: Array, labels: list[str],
                k: int, xatol: float) -> tuple[float, float]:
    """(decision value, cost) refined around grid point k of a single acting decision."""
    j = names.index(decision)

    def at(u: float) -> tuple[float, str, Trajectory]:
        x = base.copy()
        x[j] = u
        return run(x)

    best_u, best_c, nit, _ = refine_minimum(at, axis, costs, labels, k, problem.bound(decision),
                                            xatol)
    run.nit += nit
    return best_u, best_c


def _refine_joint(problem: Problem, run: _Runner, acting: list[str], start: Array,
                  names: tuple[str, ...]) -> tuple[Array, float]:
    """L-BFGS-B on the acting decisions jointly from ``start`` (a full input vector)."""
    cols = [names.index(d) for d in acting]
    bounds = [problem.bound(d) for d in acting]
    widths = np.array([hi - lo for lo, hi in bounds])

    def full(x: Array) -> Array:
        u = start.copy()
        u[cols] = np.clip(x, [lo for lo, _ in bounds], [hi for _, hi in bounds])
        return u

    def cost(x: Array) -> float:
        c = run(full(x))[0]
        return c if math.isfinite(c) else 1e300

    def grad(x: Array) -> Array:
        g = np.empty(x.size)
        for i in range(x.size):
            h = GRAD_STEP * widths[i]
            lo, hi = bounds[i]
            up, down = x.copy(), x.copy()
            up[i], down[i] = min(x[i] + h, hi), max(x[i] - h, lo)
            g[i] = (cost(up) - cost(down)) / (up[i] - down[i])
        return g

    from scipy.optimize import minimize  # (a third of a second: when used)

    res = minimize(cost, start[cols], jac=grad, method="L-BFGS-B", bounds=bounds,
                   options={"ftol": 1e-15, "gtol": 1e-11, "maxiter": 200})
    u = full(res.x)
    c = run(u)[0]
    # decisions within a polish step of a bound: the bound if it is no worse
    for i, (lo, hi) in enumerate(bounds):
        for end in (lo, hi):
            if 0 < abs(u[cols[i]] - end) <= POLISH_STEP * widths[i]:
                trial = u.copy()
                trial[cols[i]] = end
                c_end = run(trial)[0]
                if c_end <= c:
                    u, c = trial, c_end
    return u, c


#: a candidate: (input vector, cost, branch, trajectory)
_Found = tuple[Array, float, str, Trajectory]


def _search(problem: Problem, run: _Runner, acting: list[str], base: Array,
            grid_points: int | None, xatol: float) -> list[_Found]:
    names = problem.facts.inputs
    rows, axes = _grid_rows(problem, acting, base, names, grid_points)
    costs, labels = run.batch(rows)
    found = []
    if axes is None:  # (a sample: the default inputs are a candidate too)
        rows = np.vstack([base, rows])
        best = [1 + k for k in _grid_minima(costs, None)[:SAMPLE_CANDIDATES - 1]]
    else:
        best = _grid_minima(costs, tuple(a.size for a in axes))
    for k in best if axes is not None else [0, *best]:
        if axes is not None and len(acting) == 1:
            d = acting[0]
            value, c = _refine_one(problem, run, d, base, names, axes[0], costs, labels, k,
                                   xatol)
            u = base.copy()
            u[names.index(d)] = value
        else:
            u, c = _refine_joint(problem, run, acting, rows[k], names)
        found.append((u, *run(u)))  # (its cost is the refinement's c: same simulation)
    return found


def optimal_policy(problem: Problem, s: float, *, grid_points: int | None = None,
                   xatol: float = XATOL) -> OptimalResult:
    """The optimal policy and value of ``problem`` at s (see the module docstring).

    ``grid_points`` overrides the bracketing grid's points per axis (a grid of more than
    :data:`MAX_BRACKET` points is a Sobol sample of that many).
    """
    if not isinstance(problem, Problem):
        raise InvalidInputError(f"problem must be a Problem, got {problem!r}")
    s = float(s)
    if not math.isfinite(s):
        raise InvalidInputError(f"{problem.name}: s must be finite, got {s}")
    if grid_points is not None and (isinstance(grid_points, bool) or
                                    not isinstance(grid_points, int) or grid_points < 3):
        raise InvalidInputError(f"grid_points must be an integer >= 3, got {grid_points!r}")
    if isinstance(xatol, bool) or not isinstance(xatol, (int, float)) \
            or not math.isfinite(xatol) or xatol <= 0:
        raise InvalidInputError(f"xatol must be a positive number, got {xatol!r}")
    compiled = compiled_for(problem)
    run = _Runner(problem, compiled, s)
    names = problem.facts.inputs
    base = problem.inputs()
    cost0, label0, tr0 = run(base)
    acting = _acting(problem, compiled, tr0.modes)
    found: list[_Found] = [(base, cost0, label0, tr0)]
    searched: list[str] = []
    while acting and acting != searched:
        searched = acting
        found += _search(problem, run, acting, base, grid_points, xatol)
        more = _acting(problem, compiled, min(found, key=lambda f: f[1])[3].modes)
        acting = [d for d in problem.decision_names if d in set(acting) | set(more)]
    u, value, branch, tr = min(found, key=lambda f: f[1])
    policy = {d: float(u[names.index(d)]) for d in problem.decision_names}
    acting_now = _acting(problem, compiled, tr.modes)
    bounds = {d: ("lower" if policy[d] == problem.bound(d)[0] else
                  "upper" if policy[d] == problem.bound(d)[1] else None) for d in acting_now}
    active: str | None
    if len(acting_now) == 1:
        active, bound = acting_now[0], bounds[acting_now[0]]
    else:
        active = "+".join(acting_now) or None
        bound = ",".join(f"{d}={b}" for d, b in bounds.items() if b) or None
    candidates = tuple(Candidate(branch=b, policy={d: float(x[names.index(d)])
                                                   for d in problem.decision_names}, value=c)
                       for x, c, b, _ in found[1:])
    ok = tr.success and math.isfinite(value)
    message = ("optimum found" if acting_now else
               "no decision acts on the outcome at this s: decisions at their cheapest value")
    status = 0
    if not ok:
        status = 1 if not math.isfinite(value) else 2
        message = f"no successful simulation at the optimum ({tr.status.name})"
    return OptimalResult(
        problem=problem, s=s, policy=policy, inputs=u, value=value, outcome=tr.outcome,
        t_final=tr.t_final, y_final=tr.y_final, modes=tr.modes, event_times=tr.event_times,
        branch=branch, active=active, bound=bound, candidates=candidates, success=ok,
        message=message, nsim=run.nsim, status=status, nfev=run.nfev, nit=run.nit,
        trajectory=tr)


def optimal_sweep(problem: Problem, s: npt.ArrayLike, *, grid_points: int | None = None,
                  xatol: float = XATOL, callback: Callable[[int, int], None] | None = None
                  ) -> tuple[OptimalResult, ...]:
    """:func:`optimal_policy` at every s; ``callback(done, total)`` after each."""
    values = np.atleast_1d(np.asarray(s, dtype=np.float64))
    if values.ndim != 1 or values.size == 0:
        raise InvalidInputError(f"s must be a non-empty 1-D array, got shape {values.shape}")
    out = []
    for k, value in enumerate(values):
        out.append(optimal_policy(problem, float(value), grid_points=grid_points, xatol=xatol))
        if callback is not None:
            callback(k + 1, values.size)
    return tuple(out)


def policy_table(results: Sequence[OptimalResult]) -> Mapping[str, Array]:
    """Columns s, value, outcome and one per decision, for figures and files."""
    problem = results[0].problem
    table: dict[str, Array] = {
        "s": np.array([r.s for r in results]),
        "value": np.array([r.value for r in results]),
        "outcome": np.array([r.outcome for r in results]),
    }
    for d in problem.decision_names:
        table[d] = np.array([r.policy[d] for r in results])
    return table
