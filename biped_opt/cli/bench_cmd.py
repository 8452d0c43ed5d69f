"""``biped-opt bench``: the issue-3 benchmark (biped_opt vs solve_ivp vs relaxation).

The benchmark lives in the source checkout's top-level ``bench/`` package, next to
``biped_opt/``, not in the installed package: it is a development tool with its own comparator
simulators. The editable install maps only ``biped_opt`` (a setuptools path finder), so
``import bench`` does not work from the ``biped-opt`` entry point unless the checkout happens to
be the working directory. :func:`load_bench` therefore loads ``bench`` from the checkout that
``biped_opt`` itself was imported from, without touching ``sys.path``; from a non-editable
install (no checkout) the command reports that in one line and exits with status 2.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import math
import sys
from pathlib import Path
from types import ModuleType

from biped_opt.cli.args import MAX_POINTS, MAX_SEED, int_in_range
from biped_opt.cli.output import emit_json
from biped_opt.errors import BipedOptError
from biped_opt.version import PACKAGE_DIR

__all__ = ["BenchUnavailableError", "load_bench", "register", "run", "format_table"]


class BenchUnavailableError(BipedOptError, ImportError):
    """The benchmark package (the checkout's ``bench/``) cannot be found or imported."""


def checkout_root() -> Path:
    """Directory holding the ``biped_opt`` package that is running (the checkout, if editable)."""
    return PACKAGE_DIR.parent


def load_bench() -> ModuleType:
    """``bench.run`` from the checkout next to the running ``biped_opt``."""
    init = checkout_root() / "bench" / "__init__.py"
    if not init.is_file():
        raise BenchUnavailableError(
            f"the benchmark needs a source checkout: no bench/ package next to {checkout_root()}"
            " (biped_opt is not an editable install)"
        )
    loaded = sys.modules.get("bench")
    if loaded is not None:
        where = getattr(loaded, "__file__", None)
        if where is None or Path(where).resolve() != init.resolve():
            raise BenchUnavailableError(
                f"another module named 'bench' is already imported (from {where})"
            )
    else:
        module_spec = importlib.util.spec_from_file_location(
            "bench", init, submodule_search_locations=[str(init.parent)]
        )
        assert module_spec is not None and module_spec.loader is not None
        module = importlib.util.module_from_spec(module_spec)
        sys.modules["bench"] = module
        try:
            module_spec.loader.exec_module(module)
        except Exception:
            del sys.modules["bench"]
            raise
    try:
        return importlib.import_module("bench.run")
    except ImportError as exc:
        raise BenchUnavailableError(f"cannot import the benchmark: {exc}") from None


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bench", help="time biped_opt against solve_ivp and a relaxation simulator"
    )
    p.add_argument("--cases", type=int_in_range("--cases", 2, MAX_POINTS), default=200,
                   help="number of (maneuver, theta0, inputs) cases, half each (default 200)")
    p.add_argument("--seed", type=int_in_range("--seed", 0, MAX_SEED), default=None,
                   help="seed of the random cases")
    p.add_argument("--quick", action="store_true",
                   help="one timing round, short sweeps, relaxation on a subset")
    p.add_argument("--no-compile", action="store_true",
                   help="skip the cold/cached compile measurement (two fresh interpreters)")
    p.add_argument("--system", action="append", choices=SYSTEM_CHOICES, metavar="NAME",
                   help="instead: the generated simulators of these systems (biped, walker3, "
                        "rocking_bar; repeatable; 'all' for the three) side by side, against "
                        "their SciPy comparators, with cold and cached compile times")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _fmt(value: float | None, unit: str = "") -> str:
    if value is None or not math.isfinite(value):
        return "n/a"
    if unit == "s":
        if value < 1e-3:
            return f"{value * 1e6:.1f} us"
        if value < 1.0:
            return f"{value * 1e3:.2f} ms"
        return f"{value:.2f} s"
    return f"{value:.3g}"


def format_table(r: dict) -> str:
    """The benchmark result as a plain-text table."""
    lines = [
        f"{r['n_cases']} cases ({r['timing']}); relaxation on {r['relaxation_cases']}",
        f"{'method':<12}{'per traj.':>12}{'speed-up':>12}{'max |err|':>12}{'median nfev':>13}",
    ]
    for m in ("biped_opt", "solve_ivp", "relaxation"):
        speed = 1.0 if m == "solve_ivp" else r["speedup_vs_solve_ivp"][m]
        lines.append(
            f"{m:<12}{_fmt(r['per_trajectory_s'][m], 's'):>12}{speed:>11.1f}x"
            f"{r['max_abs_error'][m]:>12.2e}{r['median_nfev'][m]:>13.0f}"
        )
    lines += [
        f"errors vs {r['error_reference']}",
        f"biped_opt right after another method (cold CPU caches): "
        f"{_fmt(r['biped_opt_after_other_method_s'], 's')}",
        f"biped_opt batch path: {_fmt(r['batch_per_trajectory_s'], 's')} per trajectory",
        f"{r['sweep_points']}-point sweep: touchdown {_fmt(r['sweep_s']['touchdown'], 's')}, "
        f"liftoff {_fmt(r['sweep_s']['liftoff'], 's')}",
        f"import + first simulate: cold cache {_fmt(r['compile_s']['cold'], 's')}, "
        f"cached {_fmt(r['compile_s']['cached'], 's')}",
        "machine: " + ", ".join(f"{k} {v}" for k, v in r["machine"].items()),
    ]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    if args.system:
        return run_systems(args)
    bench_run = load_bench()
    kwargs = {} if args.seed is None else {"seed": args.seed}
    result = bench_run.run_benchmark(
        n_cases=args.cases, quick=args.quick, compile_cost=not args.no_compile, **kwargs
    )
    if args.json:
        emit_json(result)
    else:
        print(format_table(result))
    return 0


SYSTEM_CHOICES = ("biped", "walker3", "rocking_bar", "all")


def run_systems(args: argparse.Namespace) -> int:
    """``bench --system``: bench/systems_bench.py on the chosen systems."""
    load_bench()
    systems_bench = importlib.import_module("bench.systems_bench")
    names = [n for n in SYSTEM_CHOICES[:-1] if n in args.system or "all" in args.system]
    kwargs = {} if args.seed is None else {"seed": args.seed}
    result = systems_bench.run_systems_benchmark(
        names, n_cases=min(args.cases, 40) if args.quick else args.cases,
        rounds=1 if args.quick else 3, reference_cases=5 if args.quick else 20,
        compile_cost=not args.no_compile, **kwargs)
    if args.json:
        emit_json(result)
    else:
        print(systems_bench.format_systems_table(result))
    return 0
