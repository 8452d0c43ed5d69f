"""Optimal policies and values on any system (biped_opt.control.solve), checked against
independent brute-force optimisers written here. (The biped's problems are checked against the
numbers the retired biped-only solver recorded: tests/paper/test_same_numbers.py.)"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize, minimize_scalar

from biped_opt.control.problems import get_problem
from biped_opt.control.solve import compiled_for, optimal_policy, optimal_sweep


def _brute_force(problem, s: float, per_axis: int) -> float:
    """An independent optimiser: a dense grid over the whole decision box in one batch, then
    Nelder-Mead (derivative-free, clipped to the box) from the best 5 grid points."""
    compiled = compiled_for(problem)
    names = problem.decision_names
    lo = np.array([problem.bound(d)[0] for d in names])
    hi = np.array([problem.bound(d)[1] for d in names])
    axes = [np.linspace(a, b, per_axis) for a, b in zip(lo, hi)]
    mesh = np.stack([m.ravel() for m in np.meshgrid(*axes, indexing="ij")], axis=1)
    rows = np.array([problem.inputs(dict(zip(names, x))) for x in mesh])
    out = compiled.simulate_batch(problem.maneuver, np.full(len(rows), s), rows)
    costs = np.where(out["status"] == 0, problem.cost(out["outcome"], out["y_final"], rows),
                     np.inf)

    def cost(x: np.ndarray) -> float:
        u = problem.inputs(dict(zip(names, np.clip(x, lo, hi))))
        tr = compiled.simulate(problem.maneuver, s, u)
        return float(problem.cost(tr.outcome, tr.y_final, u)) if tr.success else math.inf

    best = float(costs.min())
    for k in np.argsort(costs)[:5]:
        if len(names) == 1:
            step = (hi[0] - lo[0]) / (per_axis - 1)
            res = minimize_scalar(lambda v: cost(np.array([v])), method="bounded",
                                  bounds=(max(lo[0], mesh[k, 0] - step),
                                          min(hi[0], mesh[k, 0] + step)),
                                  options={"xatol": 1e-12})
        else:
            res = minimize(cost, mesh[k], method="Nelder-Mead",
                           options={"xatol": 1e-11, "fatol": 1e-17, "maxiter": 4000})
        best = min(best, float(res.fun))
    return best


@pytest.mark.parametrize(("system", "problem", "s", "per_axis"), [
    ("rocking_bar", "drop", -0.1, 4001),
    ("rocking_bar", "drop", 0.15, 4001),
    ("walker2_decoupled", "touchdown", -0.1, 101),  # two decisions acting jointly
    ("walker2_decoupled", "touchdown", 0.02, 101),
    ("walker3_decoupled", "liftoff_variant", 0.02, 31),  # three decisions acting jointly
    ("walker3_coupled", "touchdown", -0.1, 31),
])
def test_values_agree_with_an_independent_optimiser(system: str, problem: str, s: float,
                                                    per_axis: int) -> None:
    """Optimal values agree with a dense-grid + Nelder-Mead optimiser to 1e-9: the cost is
    simulated to ~1e-14 and both optimisers stop within ~1e-6 of the minimiser of a cost whose
    curvature is O(1), so their values differ by far less; and the solver is never worse than
    the brute force by more than that (it must find the global optimum)."""
    p = get_problem(system, problem)
    r = optimal_policy(p, s)
    assert r.success
    reference = _brute_force(p, s, per_axis)
    assert r.value <= reference + 1e-9
    assert r.value == pytest.approx(reference, abs=1e-9)


def test_decisions_that_do_not_act_sit_at_their_cheapest_value() -> None:
    """walker3 coupled touchdown at s < 0: foot 3 lands first, so only u3 acts (u_i acts in
    {foot i} alone); u1, u2 cost weight but move nothing, so they are exactly 0."""
    r = optimal_policy(get_problem("walker3_coupled", "touchdown"), -0.1)
    assert r.active == "u3"
    assert r.policy["u1"] == 0.0 and r.policy["u2"] == 0.0
    assert r.branch.startswith("air->foot3->")


def test_rocking_bar_branch_names_the_impacts() -> None:
    """Impacts after which the end separates at once (restitution) are named in brackets: the
    drop from th0 = 0 hits with both ends at once."""
    p = get_problem("rocking_bar", "drop")
    compiled = compiled_for(p)
    tr = compiled.simulate("drop", 0.0, [0.0])
    from biped_opt.control.solve import branch_of

    assert branch_of(compiled, tr.initial_mode, tr.event_rows[: tr.n_events]) == \
        "air->air[left+right]"


def test_sweep_is_the_pointwise_solution() -> None:
    p = get_problem("rocking_bar", "drop")
    s = [-0.05, 0.05]
    swept = optimal_sweep(p, s)
    for r, x in zip(swept, s):
        assert r.value == optimal_policy(p, x).value  # same algorithm, bit for bit
