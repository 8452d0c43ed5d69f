"""The gradient study's estimators, descent and smoothed model (biped_opt.analysis.gradients)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from biped_opt.analysis.gradients import (
    ZEROTH_BASELINES,
    Objective,
    descend,
    estimator_stats,
    find_switches,
    first_order_terms,
    smooth_problem,
    smoothed_gradient,
    zeroth_order_terms,
)
from biped_opt.cli.main import main
from biped_opt.control.problems import get_problem
from biped_opt.control.solve import compiled_for, optimal_policy
from biped_opt.errors import InvalidInputError

SIGMA = 0.2


class Analytic(Objective):
    """An objective with a closed-form cost on the box [-1, 1]^2 (the study's machinery, a known
    answer): c(x, y) = x^3 + sin(y) + x y + jump * [x > 0]."""

    def __init__(self, jump: float = 0.0) -> None:
        self.lo, self.hi = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
        self.width = self.hi - self.lo
        self.cols = [0, 1]
        self.jump, self.nsim, self.ngrad, self.s = jump, 0, 0, 0.0

    def values(self, x):
        x = np.atleast_2d(np.asarray(x, dtype=float))
        self.nsim += len(x)
        return x[:, 0] ** 3 + np.sin(x[:, 1]) + x[:, 0] * x[:, 1] + self.jump * (x[:, 0] > 0)

    def gradient(self, x, direction=None):
        self.ngrad += 1
        a, b = np.asarray(x, dtype=float).ravel()
        return np.array([3 * a * a + b, math.cos(b) + a])

    def branches(self, x):
        return ["right" if v > 0 else "left" for v in np.atleast_2d(x)[:, 0]]

    def smoothed(self, x, sigma):
        """D J_sigma in closed form: E over w ~ N(0, I) of D c(x + sigma w), plus the jump's
        term jump * pdf(x / sigma) / sigma in the first component."""
        a, b = x
        pdf = math.exp(-0.5 * (a / sigma) ** 2) / math.sqrt(2 * math.pi)
        return np.array([3 * a * a + 3 * sigma ** 2 + b + self.jump * pdf / sigma,
                         math.cos(b) * math.exp(-0.5 * sigma ** 2) + a])


@pytest.mark.parametrize("point", [(0.3, -0.4), (-0.5, 0.7)])
def test_quadrature_reference_matches_closed_form(point):
    objective = Analytic()
    ref, err = smoothed_gradient(objective, point, SIGMA)
    # a smooth Gaussian-weighted integrand: the trapezoidal rule on 241^2 points is accurate to
    # ~1e-8 (its own estimate, fine vs coarse, is below 1e-7); what is left is the truncation
    # of w at +-6, where the cubic's w^4 pdf(w) tail holds ~1e-7: tolerance 1e-6
    np.testing.assert_allclose(ref, objective.smoothed(point, SIGMA), atol=1e-6)
    assert err < 1e-7


@pytest.mark.parametrize("estimator", [zeroth_order_terms, first_order_terms])
def test_estimators_unbiased_on_smooth_cost(estimator):
    objective = Analytic()
    rng = np.random.default_rng(1)
    x = np.array([0.3, -0.4])
    terms = estimator(objective, x, SIGMA, rng.standard_normal((40000, 2)))
    mean, se = terms.mean(axis=0), terms.std(axis=0, ddof=1) / math.sqrt(len(terms))
    truth = objective.smoothed(x, SIGMA)
    # unbiased: the mean is within 4 standard errors of D J_sigma (a false alarm has chance
    # ~6e-5 per component); the standard errors are small (< 0.01) so this is a real check
    assert np.all(se < 0.01)
    assert np.all(np.abs(mean - truth) < 4 * se), (mean, truth, se)
    # the per-sample derivatives are the analytic ones to the difference quotient's accuracy
    if estimator is first_order_terms:
        w = rng.standard_normal((50, 2))
        exact = np.array([objective.gradient(x + SIGMA * v) for v in w])
        np.testing.assert_allclose(estimator(objective, x, SIGMA, w), exact, atol=1e-6)


def test_first_order_estimator_misses_a_jump():
    """Near a jump the reparameterised estimator is biased by the jump's term (Suh et al.);
    the score-function estimator is not."""
    objective = Analytic(jump=0.5)
    x = np.array([0.05, 0.2])
    truth = objective.smoothed(x, SIGMA)
    stats = {e.estimator: e for e in estimator_stats(objective, x, SIGMA, truth,
                                                     np.random.default_rng(2), 40000)}
    missing = 0.5 * math.exp(-0.5 * (0.05 / SIGMA) ** 2) / math.sqrt(2 * math.pi) / SIGMA
    # first order: bias = the jump's term (0.966) to within 4 standard errors
    assert abs(stats["first"].bias - missing) < 4 * stats["first"].bias_se + 1e-6
    assert missing > 100 * stats["first"].bias_se
    # zeroth order: no bias beyond 4 standard errors (2-norm over 2 components)
    assert stats["zeroth"].bias < 4 * stats["zeroth"].bias_se
    # the exact derivative is used only where the quotients disagree (a sample within the step
    # of the jump, or a component whose gradient is near 0): at most 0.1% of the samples
    assert stats["first"].exact_calls <= 40


def test_zeroth_order_spread_depends_on_its_baseline():
    """The same draws with each baseline: every one leaves the estimate within 4 standard errors
    of D J_sigma, but the spreads differ (so a ratio of spreads means something only with its
    baseline). Where the cost is far from 0 (here c ~ 5 at the point, jump 5 beyond x = 0),
    no baseline is worst; the recorded spreads are the terms' own."""
    objective = Analytic(jump=5.0)
    x = np.array([0.3, -0.4])
    truth = objective.smoothed(x, SIGMA)
    zeroth = estimator_stats(objective, x, SIGMA, truth, np.random.default_rng(3), 40000)[0]
    w = np.random.default_rng(3).standard_normal((40000, 2))  # the draws estimator_stats used
    assert set(zeroth.baseline_std) == set(ZEROTH_BASELINES)
    assert zeroth.baseline_std["point"] == zeroth.sample_std
    for b in ZEROTH_BASELINES:
        terms = zeroth_order_terms(objective, x, SIGMA, w, baseline=b)
        spread = math.sqrt(np.sum(np.var(terms, axis=0, ddof=1)))
        assert zeroth.baseline_std[b] == pytest.approx(spread, rel=1e-12)
        se = terms.std(axis=0, ddof=1) / math.sqrt(len(terms))
        assert np.all(np.abs(terms.mean(axis=0) - truth) < 4 * se), (b, terms.mean(axis=0))
    # b = 0 adds roughly c(x)^2 m / sigma^2 to the terms' variance (c(x) = 4.5, m = 2, sigma =
    # 0.2: a ratio of ~2.5 by that estimate, 2.18 measured on these draws); 1.5 asserts the
    # effect with room for the estimate's neglected cross terms
    assert zeroth.baseline_std["none"] > 1.5 * zeroth.baseline_std["point"]
    with pytest.raises(InvalidInputError, match="baseline"):
        zeroth_order_terms(objective, x, SIGMA, w[:3], baseline="median")


@pytest.fixture(scope="module")
def liftoff():
    return Objective(get_problem("biped", "liftoff"), 0.01)


def test_pathwise_gradient_matches_exact_derivative(liftoff):
    x = np.array([[0.2], [-0.3], [0.06]])
    grads, fallback = liftoff.pathwise_gradients(x)
    assert fallback == 0
    exact = np.array([liftoff.gradient(row) for row in x])
    # difference quotients of step 1e-7 on a cost integrated to rtol ~1e-11: agree with the
    # variational (exact) derivative to 1e-3 relative (its own finite-difference columns are
    # accurate to ~1e-6)
    np.testing.assert_allclose(grads, exact, rtol=1e-3, atol=1e-9)


def test_liftoff_switch_and_descent_stall(liftoff):
    """The liftoff cost at s = 0.01 jumps where the feet lift off together (u12 ~ -0.106):
    exact-gradient descent started left of it stops there; started right of it, it reaches the
    global optimum."""
    switches = find_switches(liftoff, [0.0], 0)
    assert len(switches) == 1 and -0.12 < switches[0] < -0.09
    left, right = liftoff.values([[switches[0] - 1e-6], [switches[0] + 1e-6]])
    assert right - left > 1e-4  # a jump up, not a kink (the scan's jump is 7.5e-4)
    best = optimal_policy(liftoff.problem, liftoff.s)
    stuck = descend(liftoff, [-0.4], "exact", best.value)
    assert not stuck.reached
    assert stuck.stop.endswith("at a switch")
    assert abs(stuck.end[0] - switches[0]) < 1e-4
    good = descend(liftoff, [0.25], "exact", best.value)
    assert good.reached and abs(good.end[0] - best.policy["u12"]) < 1e-3
    # at the optimum the cost is flat to its ~1e-14 noise: whether the last step stops on the
    # gradient test or on a failed line search depends on that noise; where it stops does not
    assert good.stop.endswith("on a smooth piece")


def test_smoothed_model_removes_the_liftoff_jump():
    exact = get_problem("biped", "liftoff")
    smooth = smooth_problem(exact, 0.02)
    u = exact.inputs({"u12": 0.0})
    ce, cs = compiled_for(exact), compiled_for(smooth)
    o_exact = [ce.simulate("liftoff", s, u).outcome for s in (-1e-6, 1e-6)]
    o_smooth = [cs.simulate("liftoff", s, u).outcome for s in (-1e-6, 1e-6)]
    # the real model jumps by 0.033 across s = 0 (+0.0263 | -0.0065); the smoothed one changes
    # by its slope (~0.4) times 2e-6
    assert abs(o_exact[1] - o_exact[0]) > 0.01
    assert abs(o_smooth[1] - o_smooth[0]) < 1e-4
    with pytest.raises(InvalidInputError):
        smooth_problem(exact, -1.0)


def test_soft_rocking_bar_is_smooth_where_the_rigid_bar_jumps():
    """The bar with soft contacts of width eps has no jump at s = 0, and as eps shrinks its
    outcome settles on a different value than the rigid bar's (the soft contact's effective
    restitution is not gamma): smoothing changes the problem, not only its nonsmooth points."""
    exact = get_problem("rocking_bar", "drop")
    u = exact.inputs({"u_th": 0.0})
    ce = compiled_for(exact)
    o_exact = [ce.simulate("drop", s, u).outcome for s in (-1e-6, 1e-6)]
    assert o_exact[0] - o_exact[1] == pytest.approx(2 * 0.1988749738, abs=1e-8)  # SYSTEMS.md
    far = {}
    for eps in (0.001, 0.0003):
        cs = compiled_for(smooth_problem(exact, eps))
        o_smooth = [cs.simulate("drop", s, u).outcome for s in (-1e-6, 0.0, 1e-6)]
        # continuous: its slope at 0 (~40 at eps = 1e-3) times 1e-6, far below the jump
        assert abs(o_smooth[2] - o_smooth[0]) < 1e-3 and o_smooth[1] == pytest.approx(0.0,
                                                                                      abs=1e-9)
        far[eps] = cs.simulate("drop", 0.1, u).outcome
    # the soft limit at s = 0.1: -0.2815 and -0.2790 at the two widths, the rigid bar 2.4105
    assert far[0.001] == pytest.approx(far[0.0003], abs=0.01)
    assert abs(far[0.0003] - ce.simulate("drop", 0.1, u).outcome) > 2.0


def test_cli_rejects_unknown_problem(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["gradients", "--problem", "nope"])
    assert exc.value.code == 2
    assert "invalid choice" in capsys.readouterr().err


def test_a_trial_size_study_does_what_its_sizes_say():
    """The sizes a user chooses reach every stage: one start per axis at each of the two s
    values of every_other_s gives two runs per method; the header and the JSON name them."""
    from biped_opt.analysis.gradients import GradientSizes, report, run_gradient_study

    sizes = GradientSizes(starts=(1, 1), samples=64, iterations=3, quadrature=(41, 41),
                          every_other_s=True)
    study = run_gradient_study(seed=0, quick=True, problems=["touchdown"], sizes=sizes,
                               eps_values=(0.02,))
    rows = study.summary("touchdown")
    assert {r["method"] for r in rows} >= {"exact", "fd", "lbfgsb"}
    assert all(r["runs"] == 2 for r in rows)
    assert all(run.iterations <= 3 for run in study.runs["touchdown"] if run.method != "lbfgsb")
    assert report(study).splitlines()[0] == (
        "gradient study, seed 0 (quick); starts 1 per axis, samples 64, iterations 3, "
        "quadrature 41 per axis, every other s")
    assert study.as_dict()["sizes"] == {"starts": (1, 1), "samples": 64, "iterations": 3,
                                        "quadrature": (41, 41), "every_other_s": True}


@pytest.mark.parametrize("bad", [{"samples": 1}, {"starts": (0, 2)}, {"starts": 3},
                                 {"iterations": 1001}, {"quadrature": (41,)},
                                 {"samples": True}, {"every_other_s": 1}])
def test_sizes_out_of_their_bounds_are_refused(bad):
    from biped_opt.analysis.gradients import GradientSizes

    with pytest.raises(InvalidInputError):
        GradientSizes(**bad)


def test_a_quadrature_too_big_is_refused_before_any_work(monkeypatch):
    import biped_opt.analysis.gradients as g

    def no_work(*_args, **_kwargs):
        raise AssertionError("the study started")

    monkeypatch.setattr(g, "optimal_policy", no_work)
    with pytest.raises(InvalidInputError, match="more than 1000000"):
        g.run_gradient_study(problems=["liftoff", "touchdown"],
                             sizes=g.GradientSizes(quadrature=(8001, 1001)))


def test_the_presets_keep_the_studys_sizes():
    """--quick and the full study as they were before sizes could be chosen (the tables of the
    docs were made with these)."""
    from biped_opt.analysis.gradients import FULL, QUICK

    assert [FULL.starts_per_axis(m) for m in (1, 2)] == [7, 4]
    assert [QUICK.starts_per_axis(m) for m in (1, 2)] == [3, 2]
    assert (FULL.samples, FULL.iterations, FULL.every_other_s) == (20000, 60, False)
    assert (QUICK.samples, QUICK.iterations, QUICK.every_other_s) == (2000, 30, True)
    assert [FULL.quadrature_points(m) for m in (1, 2)] == [8001, 241]
    assert QUICK.quadrature == FULL.quadrature
