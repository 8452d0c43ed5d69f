"""The benchmark's comparators against MODEL.md and biped_opt, and the benchmark's result shape."""

from __future__ import annotations

import importlib
import math

import numpy as np
import pytest

from biped_opt.cli.bench_cmd import load_bench
from biped_opt.paper.biped import BipedParams, ContactMode, simulate
from biped_opt.simulation.trajectory import Status
from tests.conftest import REFERENCE

# the checkout's bench/ package, whatever sys.path pytest set up
bench_run = load_bench()
reference = importlib.import_module("bench.solve_ivp_reference")
relaxation = importlib.import_module("bench.relaxation")
biped_model = importlib.import_module("bench.biped_model")

#: MODEL.md Sec. 7: a correct implementation reproduces the outcomes to 1e-9
OUTCOME_TOL = 1e-9
#: relaxation error bound: each event time is off by at most the strip (1e-5) and the outcome
#: moves by |d th_f / d t_event| <~ 3 per unit of event time over at most 3 events, so <~ 1e-4;
#: RK4's global error at dt = 1e-3 (~1e-10) is negligible. Measured: <= 1e-5 on 200 cases.
#: Valid only away from th0 = 0, where events closer than the strip merge (see below).
RELAXATION_TOL = 1e-4


def random_cases(n: int, seed: int = 7) -> list:
    """n cases per maneuver in the benchmark's ranges, |th0| >= 0.01 so no events merge."""
    rng = np.random.default_rng(seed)
    cases = []
    for _ in range(n):
        th = rng.choice([-1.0, 1.0]) * rng.uniform(0.01, 0.25)
        cases.append(("touchdown", th, (*rng.uniform(-0.5, 1.5, 2), 0.0)))
        th = rng.choice([-1.0, 1.0]) * rng.uniform(0.01, 0.3)
        cases.append(("liftoff", th, (1.5, 3.0, rng.uniform(-0.5, 0.5))))
    return cases


CASES = random_cases(3) + [
    ("touchdown", 0.0, (2.0, 0.5, 0.0)),  # simultaneous touchdown of both feet
    ("liftoff", 0.0, (1.5, 3.0, 0.0)),  # simultaneous liftoff
]


@pytest.mark.parametrize("name", sorted(REFERENCE))
def test_reference_reproduces_model_numbers(name: str) -> None:
    maneuver, theta0, u, expected = REFERENCE[name]
    r = reference.simulate(maneuver, theta0, u)
    assert r.outcome == pytest.approx(expected, abs=OUTCOME_TOL)
    assert 100 < r.nfev < 2000  # MODEL.md: the reference needs ~200-400 evaluations


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c[0]}:{c[1]:+.3f}")
def test_reference_agrees_with_biped_opt(case: tuple) -> None:
    maneuver, theta0, u = case
    tr = simulate(maneuver, theta0, u)
    r = reference.simulate(maneuver, theta0, u)
    assert tr.success
    assert r.outcome == pytest.approx(tr.outcome, abs=OUTCOME_TOL)
    assert r.t_final == pytest.approx(tr.t_final, abs=1e-8)
    assert r.mode_sequence == tuple(ContactMode(m).name for m in tr.mode_sequence)


def test_reference_simultaneous_events_at_zero() -> None:
    assert reference.simulate("touchdown", 0.0, (2.0, 0.5)).mode_sequence == ("AIR", "GROUND")
    assert reference.simulate("liftoff", 0.0, (1.5, 3.0)).mode_sequence == ("GROUND", "AIR")
    assert reference.simulate("touchdown", 0.1, (2.0, 0.5)).mode_sequence == (
        "AIR", "LEFT", "GROUND"
    )


def test_failures_match_biped_opt() -> None:
    # a heavy body (mb = 4) never leaves the ground: the apex comes in double stance
    heavy = BipedParams(mb=4.0)
    assert simulate("liftoff", 0.1, (1.5, 3.0), params=heavy).status is Status.APEX_IN_CONTACT
    for sim in (reference.simulate, relaxation.simulate):
        with pytest.raises(biped_model.ComparatorError, match="apex .* mode GROUND"):
            sim("liftoff", 0.1, (1.5, 3.0), params=biped_model.Params(mb=4.0))
    # mb = 20 squashes the legs past horizontal: after the left liftoff, without u1 the left
    # foot is pushed down (force coupling) and sinks into the ground
    squashed = BipedParams(mb=20.0)
    assert simulate("liftoff", 0.1, (1.5, 3.0), params=squashed).status is Status.INCONSISTENT
    for sim in (reference.simulate, relaxation.simulate):
        with pytest.raises(biped_model.ComparatorError, match="foot 1 went through the ground"):
            sim("liftoff", 0.1, (1.5, 3.0), params=biped_model.Params(mb=20.0))
    with pytest.raises(biped_model.ComparatorError, match="horizon"):
        reference.simulate("touchdown", 0.1, (2.0, 0.5), t_end=0.5)


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c[0]}:{c[1]:+.3f}")
def test_relaxation_is_close_but_not_exact(case: tuple) -> None:
    maneuver, theta0, u = case
    exact = simulate(maneuver, theta0, u)
    r = relaxation.simulate(maneuver, theta0, u)
    assert r.mode_sequence == tuple(ContactMode(m).name for m in exact.mode_sequence)
    assert r.outcome == pytest.approx(exact.outcome, abs=RELAXATION_TOL)
    assert abs(r.t_final - exact.t_final) <= 2 * relaxation.STRIP * len(r.mode_sequence)


def test_relaxation_merges_events_inside_the_strip() -> None:
    # R3: th0 = -1e-6 lifts the right foot first, ~1e-6 before the left; the strip hides that
    maneuver, theta0, u, expected = REFERENCE["R3"]
    r = relaxation.simulate(maneuver, theta0, u)
    assert r.mode_sequence == ("GROUND", "AIR")
    assert abs(r.outcome - expected) > 0.02  # the jump of the liftoff outcome is lost


def test_run_benchmark_quick_has_all_keys() -> None:
    result = bench_run.run_benchmark(n_cases=4, quick=True, compile_cost=False)
    methods = {"biped_opt", "solve_ivp", "relaxation"}
    assert set(result["per_trajectory_s"]) == methods
    assert set(result["max_abs_error"]) == methods
    assert set(result["speedup_vs_solve_ivp"]) == {"biped_opt", "relaxation"}
    assert set(result["sweep_s"]) == {"touchdown", "liftoff"}
    assert result["compile_s"] == {"cold": None, "cached": None}
    numbers = [
        *result["per_trajectory_s"].values(),
        *result["speedup_vs_solve_ivp"].values(),
        *result["max_abs_error"].values(),
        *result["sweep_s"].values(),
        result["batch_per_trajectory_s"],
        result["biped_opt_after_other_method_s"],
        result["reference_self_check"],
    ]
    assert all(isinstance(v, float) and math.isfinite(v) for v in numbers)
    assert all(v > 0 for v in result["per_trajectory_s"].values())
    assert result["max_abs_error"]["biped_opt"] <= OUTCOME_TOL
    assert result["mode_sequence_mismatches"] == {"solve_ivp": 0, "relaxation": 0}
    for key in ("cpu_count", "python", "numpy", "numba"):
        assert result["machine"][key]


def test_make_cases_shape() -> None:
    cases = bench_run.make_cases(10, seed=1)
    assert [c[0] for c in cases] == ["touchdown"] * 5 + ["liftoff"] * 5
    assert cases[0][1] == 0.0 and cases[5][1] == 0.0
    assert all(abs(th) <= 0.25 and -0.5 <= u[0] <= 1.5 for m, th, u in cases[:5])
    assert all(abs(th) <= 0.3 and u[:2] == (1.5, 3.0) for m, th, u in cases[5:])
    assert bench_run.make_cases(10, seed=1) == cases
    with pytest.raises(ValueError, match="n_cases"):
        bench_run.make_cases(1)


def test_compile_cost_plumbing(monkeypatch: pytest.MonkeyPatch) -> None:
    # the real script compiles for ~15 s; check the subprocess and parsing with a stand-in
    monkeypatch.setattr(
        bench_run, "_COMPILE_SCRIPT",
        "import os\nassert os.listdir(os.environ['NUMBA_CACHE_DIR']) == []\nprint(0.5, 0.25)",
    )
    out = bench_run._compile_cost()
    assert out["cold"] == pytest.approx(0.75) and out["cached"] == pytest.approx(0.75)
    assert out["cold_first_call"] == pytest.approx(0.25)


# -- the comparators of the generated simulators (bench/system_reference.py) -------------------
system_reference = importlib.import_module("bench.system_reference")
rocking_bar_model = importlib.import_module("bench.rocking_bar_model")
walker_model = importlib.import_module("bench.walker_model")


def test_rocking_bar_comparator_reproduces_systems_md():
    """SYSTEMS.md Sec. 2's numbers come from independent implementations; this one must
    reproduce them to their 10 digits."""
    small = system_reference.simulate(rocking_bar_model, "drop", 1e-6, (0.0,))
    assert small.outcome == pytest.approx(-0.1988749738, abs=1e-9)
    assert small.touchdowns == (1, 2, 1)
    zero = system_reference.simulate(rocking_bar_model, "drop", 0.0, (0.0,))
    assert zero.touchdowns == (3,) and abs(zero.outcome) < 1e-12
    assert zero.t_final == pytest.approx(1.5 * math.sqrt(2.0), abs=1e-9)
    assert system_reference.simulate(rocking_bar_model, "drop", 0.2, (0.0,)).outcome == \
        pytest.approx(2.42070065442, abs=1e-9)


def test_walker_comparator_with_two_legs_is_the_biped_comparator():
    """The n-leg walker model with n = 2 against the biped's (both written from the
    specifications, separately): same outcomes to 1e-9."""
    two = walker_model.Walker(2, "coupled")
    for case in random_cases(3, seed=11):
        maneuver, th, u = case
        got = system_reference.simulate(two, maneuver, th, u).outcome
        assert got == pytest.approx(reference.simulate(maneuver, th, u).outcome, abs=1e-9)


@pytest.mark.parametrize("law", ["coupled", "decoupled"])
def test_generated_walker_agrees_with_its_comparator(law):
    from biped_opt.simulation.compiled import compile_system
    from biped_opt.systems import walker

    generated = compile_system(walker(3, law))
    model = walker_model.Walker(3, law)
    for maneuver, u in (("touchdown", (2.0, 1.0, 0.5, 0.0)), ("liftoff", (1.5, 3.0, 2.0, 0.1))):
        for th in (-0.1, -1e-4, 0.0, 0.05, 0.2):
            ref = system_reference.simulate(model, maneuver, th, u)
            tr = generated.simulate(maneuver, th, u)
            assert tr.modes == ref.modes
            assert tr.outcome == pytest.approx(ref.outcome, abs=1e-9)
