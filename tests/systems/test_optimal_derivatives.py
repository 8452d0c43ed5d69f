"""Theorem 1 on any system: one-sided derivatives of the optimal value, policy and outcome."""

from __future__ import annotations

import pytest

from biped_opt.nonsmooth import one_sided
from biped_opt.optimal.derivatives import one_sided_derivatives
from biped_opt.optimal.problems import get_problem as biped_problem
from biped_opt.systems.optimal import optimal_policy
from biped_opt.systems.optimal_derivatives import optimal_derivatives
from biped_opt.systems.problems import get_problem


@pytest.mark.parametrize(("name", "biped_name", "s"), [
    ("touchdown", "touchdown", -0.1), ("touchdown", "touchdown", 0.0),
    ("liftoff", "liftoff", 0.0), ("liftoff_variant", "liftoff-variant", 0.0),
])
def test_biped_problems_match_the_biped_derivatives(name: str, biped_name: str,
                                                    s: float) -> None:
    """Same Theorem 1, two implementations. Value slopes to 1e-10 (envelope theorem: exact
    first derivatives only); policy slopes to 1e-5 relative and outcome slopes to 1e-7 (they
    need D_uu c and D_us c, differences of exact gradients with steps 1e-4: ~1e-7 relative)."""
    ours = optimal_derivatives(get_problem("biped", name), s)
    ref = one_sided_derivatives(biped_problem(biped_name), s)
    assert ours.value == pytest.approx(ref.value, abs=1e-10)
    for d, pair in ref.policy.items():
        assert ours.policy[d] == pytest.approx(pair, rel=1e-5, abs=1e-8)
    assert ours.outcome == pytest.approx(ref.outcome, abs=1e-7)
    assert ours.value_limits == pytest.approx(ref.value_limits, abs=1e-12)


@pytest.mark.parametrize(("system", "problem", "s"), [
    ("rocking_bar", "drop", 0.05),
    ("walker3_decoupled", "liftoff_variant", 0.02),  # three decisions, two held at a bound
    ("walker2_decoupled", "touchdown", -0.1),  # two free decisions jointly
])
def test_against_extrapolated_differences_of_the_optimum(system: str, problem: str,
                                                         s: float) -> None:
    """Slopes of the solved optimum s -> V(s), u*(s) by extrapolated one-sided differences (steps
    1e-3 .. 6e-5, the optimiser's ~1e-10 policy noise gives ~1e-6 there): value to 1e-7,
    policy to 1e-4."""
    p = get_problem(system, problem)
    ours = optimal_derivatives(p, s)
    cache: dict[float, object] = {}

    def at(x: float):
        if x not in cache:
            cache[x] = optimal_policy(p, x)
        return cache[x]

    for side, k in ((-1, 0), (1, 1)):
        v = one_sided(lambda x: at(x).value, s, side, h0=1e-3)
        assert ours.value[k] == pytest.approx(v.derivative, abs=1e-7)
        for d in p.decision_names:
            w = one_sided(lambda x, d=d: at(x).policy[d], s, side, h0=1e-3)
            assert ours.policy[d][k] == pytest.approx(w.derivative, abs=1e-4)
