"""Sweeps over the initial pitch th0: outcomes at fixed inputs and optimal policies/values.

The paper's Figs. 2-4 are sweeps: outcomes at fixed inputs (Figs. 2, 3) and the optimal
outcome, policy and value (Fig. 4, Eqs. (5), (6) of [1]_). Every grid holds th0 = 0 exactly when
it straddles 0, because that is where the mode order changes (MODEL.md Sec. 3). Results are
frozen values of arrays with :meth:`to_json`; a small progress bar on stderr is optional. Both
run on the one lane: the library biped's compiled kernel in parallel batches
(:meth:`~biped_opt.simulation.compiled.CompiledSystem.simulate_batch`) and the one solver
(:func:`biped_opt.control.solve.optimal_sweep`, through :func:`biped_opt.paper.solve.
optimal_sweep`); branches are named in the paper's words (``AIR->LEFT->GROUND``).

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from biped_opt.control.solve import OptimalResult, branch_of
from biped_opt.errors import InvalidInputError
from biped_opt.paper.biped import (
    FIXED_INPUTS,
    INPUT_NAMES,
    BipedParams,
    check_theta0,
    compiled_biped,
    parse_maneuver,
    theta0_limit,
)
from biped_opt.paper.problems import OptimalControlProblem, paper_branch
from biped_opt.paper.solve import optimal_sweep
from biped_opt.piecewise import theta_grid
from biped_opt.progress import Progress
from biped_opt.progress import bar as _bar
from biped_opt.simulation.options import DEFAULT_OPTIONS, SimulatorOptions

__all__ = [
    "Progress",
    "sweep_grid",
    "FixedSweep",
    "OptimalSweep",
    "sweep_fixed",
    "sweep_optimal",
]

Array = npt.NDArray[np.float64]


def sweep_grid(
    maneuver: str, lo: float | None = None, hi: float | None = None, num: int = 201
) -> Array:
    """``num`` evenly spaced th0 in [lo, hi] (default: the maneuver's valid range), 0 included."""
    limit = theta0_limit(maneuver)
    lo = -limit if lo is None else check_theta0(maneuver, lo)
    hi = limit if hi is None else check_theta0(maneuver, hi)
    if not lo < hi:
        raise InvalidInputError(f"theta0 range must have min < max, got [{lo}, {hi}]")
    if isinstance(num, bool) or not isinstance(num, int) or num < 2:
        raise InvalidInputError(f"num must be an integer >= 2, got {num!r}")
    return theta_grid(lo, hi, num)


def _as_grid(maneuver: str, theta0: npt.ArrayLike) -> Array:
    th = np.atleast_1d(np.asarray(theta0, dtype=np.float64))
    if th.ndim != 1 or th.size == 0:
        raise InvalidInputError(f"theta0 must be a non-empty 1-D array, got shape {th.shape}")
    for value in th:
        check_theta0(maneuver, value)
    th = np.unique(th)
    if th[0] < 0.0 < th[-1] and 0.0 not in th:
        th = np.unique(np.append(th, 0.0))
    return th


@dataclass(frozen=True, eq=False)
class FixedSweep:
    """Outcomes th_f(th0) of one maneuver at fixed inputs (paper Figs. 2, 3)."""

    maneuver: str
    inputs: Array  # (3,) u1, u2, u12
    theta0: Array  # (N,)
    outcome: Array  # (N,) th(t_f) [rad]
    t_final: Array  # (N,)
    status: tuple[str, ...]  # Status names, "OK" on success
    branch: tuple[str, ...]  # mode order per th0
    event_times: tuple[tuple[float, ...], ...] = field(repr=False)
    #: right-hand-side evaluations per th0, where counted (the batch simulator does not)
    nfev: npt.NDArray[np.int64] | None = field(repr=False, default=None)

    @property
    def success(self) -> npt.NDArray[np.bool_]:
        return np.array([s == "OK" for s in self.status])

    def as_dict(self) -> dict:
        return {
            "kind": "fixed",
            "maneuver": self.maneuver,
            "inputs": dict(zip(INPUT_NAMES, map(float, self.inputs))),
            "theta0": self.theta0.tolist(),
            "outcome": self.outcome.tolist(),
            "t_final": self.t_final.tolist(),
            "status": list(self.status),
            "branch": list(self.branch),
            "event_times": [list(t) for t in self.event_times],
        }

    def to_json(self, **kwargs: object) -> str:
        return json.dumps(self.as_dict(), **kwargs)  # type: ignore[arg-type]


@dataclass(frozen=True, eq=False)
class OptimalSweep:
    """Optimal policy, value and outcome over th0 (paper Fig. 4, Eqs. (5), (6))."""

    problem: OptimalControlProblem = field(repr=False)
    theta0: Array  # (N,)
    policy: dict[str, Array]  # decision name -> (N,)
    value: Array  # (N,)
    outcome: Array  # (N,) th_f at the optimum [rad]
    branch: tuple[str, ...]  # optimum's mode order per th0
    active: tuple[str | None, ...]  # acting decision per th0
    bound: tuple[str | None, ...]  # "lower"/"upper" when the acting decision is at a bound
    success: npt.NDArray[np.bool_]
    nsim: npt.NDArray[np.int64]
    nfev: npt.NDArray[np.int64]
    results: tuple[OptimalResult, ...] = field(repr=False)

    @classmethod
    def from_results(cls, problem: OptimalControlProblem, results: tuple[OptimalResult, ...]
                     ) -> OptimalSweep:
        return cls(
            problem=problem,
            theta0=np.array([r.theta0 for r in results]),
            policy={d: np.array([r.policy[d] for r in results]) for d in problem.decisions},
            value=np.array([r.value for r in results]),
            outcome=np.array([r.outcome for r in results]),
            branch=tuple(r.branch for r in results),
            active=tuple(r.active for r in results),
            bound=tuple(r.bound for r in results),
            success=np.array([r.success for r in results]),
            nsim=np.array([r.nsim for r in results], dtype=np.int64),
            nfev=np.array([r.nfev for r in results], dtype=np.int64),
            results=results,
        )

    def as_dict(self) -> dict:
        return {
            "kind": "optimal",
            "problem": self.problem.describe(),
            "theta0": self.theta0.tolist(),
            "policy": {d: v.tolist() for d, v in self.policy.items()},
            "value": self.value.tolist(),
            "outcome": self.outcome.tolist(),
            "branch": list(self.branch),
            "active": list(self.active),
            "bound": list(self.bound),
            "success": self.success.tolist(),
            "nsim": self.nsim.tolist(),
        }

    def to_json(self, **kwargs: object) -> str:
        return json.dumps(self.as_dict(), **kwargs)  # type: ignore[arg-type]


def sweep_fixed(
    maneuver: str,
    theta0: npt.ArrayLike,
    inputs: npt.ArrayLike | None = None,
    *,
    params: BipedParams | None = None,
    options: SimulatorOptions = DEFAULT_OPTIONS,
    progress: bool | Progress = False,
    chunks: int = 8,
) -> FixedSweep:
    """Outcomes over ``theta0`` at fixed ``inputs`` (default: the paper's, MODEL.md Sec. 5).

    The grid is sorted and gets th0 = 0 when it straddles 0. It runs as ``chunks`` parallel
    batches so that the progress bar moves.
    """
    name = parse_maneuver(maneuver).value
    th = _as_grid(name, theta0)
    compiled = compiled_biped(params)
    u = compiled.input_vector(FIXED_INPUTS[name] if inputs is None else inputs)
    first = compiled.initial_mode(name)
    bar = _bar(progress, th.size, f"{name} fixed sweep")
    outcome, t_final, status, branch, events = [], [], [], [], []
    for idx in np.array_split(np.arange(th.size), max(1, min(int(chunks), th.size))):
        b = compiled.simulate_batch(name, th[idx], u, options=options)
        outcome.append(b["outcome"])
        t_final.append(b["t_final"])
        for k, st_k in enumerate(b.statuses()):
            rows = b["events"][k, : int(b["n_events"][k])]
            st = st_k.name
            status.append(st)
            branch.append(paper_branch(branch_of(compiled, first, rows, st)))
            events.append(tuple(float(t) for t in rows[:, 0]))
        bar.update(int(idx[-1]) + 1, th.size)
    return FixedSweep(
        maneuver=name,
        inputs=u,
        theta0=th,
        outcome=np.concatenate(outcome),
        t_final=np.concatenate(t_final),
        status=tuple(status),
        branch=tuple(branch),
        event_times=tuple(events),
    )


def sweep_optimal(
    problem: OptimalControlProblem,
    theta0: npt.ArrayLike,
    *,
    progress: bool | Progress = False,
    **solver: object,
) -> OptimalSweep:
    """Optimal policy and value over ``theta0`` (0 inserted when straddled); see optimal_sweep.

    ``solver`` keywords (grid_points, xatol) go to :func:`~biped_opt.paper.solve.optimal_sweep`.
    """
    th = _as_grid(problem.maneuver, theta0)
    bar = _bar(progress, th.size, f"{problem.name} optimal sweep")
    results = optimal_sweep(problem, th, callback=bar.update, **solver)  # type: ignore[arg-type]
    return OptimalSweep.from_results(problem, results)
