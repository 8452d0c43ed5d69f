"""Theorem 1 on any system: one-sided derivatives of the optimal value, policy and outcome.

Every tolerance is SAFETY times the error estimates of the two numbers compared
(:mod:`tests.extrapolated`): Theorem 1's own (:class:`DerivativeErrors`) and the reference's.
"""

from __future__ import annotations

import numpy as np
import pytest

from biped_opt.control.derivatives import DEFAULT_VARIATIONAL
from biped_opt.control.problems import get_problem
from biped_opt.control.solve import optimal_policy
from biped_opt.control.theorem1 import (
    HESSIAN_STEP,
    optimal_derivatives_with_errors,
    polish_optimum,
)
from biped_opt.paper.problems import get_problem as biped_problem
from biped_opt.simulation.options import DEFAULT_OPTIONS
from tests.extrapolated import SAFETY, extrapolated, relative_noise
from tests.paper.oracle_biped import one_sided_derivatives


@pytest.mark.parametrize(("name", "biped_name", "s"), [
    ("touchdown", "touchdown", -0.1), ("touchdown", "touchdown", 0.0),
    ("liftoff", "liftoff", 0.0), ("liftoff_variant", "liftoff-variant", 0.0),
])
def test_biped_problems_match_the_biped_derivatives(name: str, biped_name: str,
                                                    s: float) -> None:
    """Same Theorem 1, two implementations (the oracle's on the hand-written biped physics):
    each is off by about our error estimate, so they agree to SAFETY times twice it. Value
    limits: one simulation each."""
    ours, err = optimal_derivatives_with_errors(get_problem("biped", name), s)
    ref = one_sided_derivatives(biped_problem(biped_name), s)
    for k in (0, 1):
        assert ours.value[k] == pytest.approx(ref.value[k], abs=2 * SAFETY * err.value[k])
        assert ours.outcome[k] == pytest.approx(ref.outcome[k], abs=2 * SAFETY * err.outcome[k])
        for d, pair in ref.policy.items():
            if d in ours.at_bound[k] or ours.policy[d][k] == 0.0:
                # held or not acting: ours is 0 by construction, the biped's the rounding of
                # its differences of a zero gradient (in the decision, over its own
                # second_order_step 1e-3, then solved against D_uu c; at most 4.4e-10 measured
                # on these cases): bounded as our mixed difference of a gradient good to rtol
                # over HESSIAN_STEP would be, times SAFETY
                tol = SAFETY * DEFAULT_VARIATIONAL.rtol / HESSIAN_STEP
            else:
                tol = 2 * SAFETY * err.policy[d][k]
            assert ours.policy[d][k] == pytest.approx(pair[k], abs=tol), (d, k)
    # the same branch limit simulated twice: as far apart as two runs at rtol 1e-11 can be
    assert ours.value_limits == pytest.approx(ref.value_limits, rel=1e-10, abs=1e-12)


#: h0 and levels of the reference's one-sided differences (sum |w_k| = 6e4: the polished
#: optima's ~1e-11 error reaches the slopes as ~1e-6)
H0, LEVELS = 1e-3, 4


@pytest.mark.parametrize(("system", "problem", "s"), [
    ("rocking_bar", "drop", 0.05),
    ("walker3_decoupled", "liftoff_variant", 0.02),  # three decisions, two held at a bound
    ("walker2_decoupled", "touchdown", -0.1),  # two free decisions jointly
])
def test_against_extrapolated_differences_of_the_optimum(system: str, problem: str,
                                                         s: float) -> None:
    """Slopes of the solved optimum s -> V(s), u*(s) by extrapolated one-sided differences.

    The joint optimiser's policy is ~1e-9 off the optimum (L-BFGS-B on differenced gradients),
    which the extrapolation's weights (sum |w_k| = 6e4 here) would turn into ~1e-4 of slope: the
    references are the solver's optima polished by Newton on the exact gradient
    (:func:`polish_optimum`, each to its own estimated distance ~1e-11, which is the samples'
    noise). The polished optimum must be no worse than the solver's (the polish found the same
    minimum, not another stationary point)."""
    p = get_problem(system, problem)
    ours, err = optimal_derivatives_with_errors(p, s)
    for side, k in ((-1, 0), (1, 1)):
        samples, hessian = {}, None
        for x in s + side * H0 / 2.0 ** np.arange(LEVELS):
            solved = optimal_policy(p, x)
            polished = polish_optimum(p, x, solved, side=side, hessian=hessian)
            hessian = polished.hessian
            # no worse than the solver's optimum, up to the cost's rounding
            assert polished.value <= solved.value + 1e-14 * max(1.0, abs(solved.value))
            samples[float(x)] = polished

        def at(x: float, samples: dict = samples) -> object:
            return samples[float(x)]

        # the value is stationary in u (the polish's error reaches it squared): its samples
        # carry the simulation's relative tolerance
        v = extrapolated(lambda x: at(x).value, s, side, h0=H0, levels=LEVELS,
                         noise=relative_noise(DEFAULT_OPTIONS.rtol))
        assert ours.value[k] == pytest.approx(v.derivative, abs=v.tolerance(err.value[k]))
        for d in p.decision_names:
            w = extrapolated(lambda x, d=d: at(x).policy[d], s, side, h0=H0, levels=LEVELS,
                             noise=lambda x, value: at(x).error)
            assert ours.policy[d][k] == pytest.approx(w.derivative,
                                                      abs=w.tolerance(err.policy[d][k]))
