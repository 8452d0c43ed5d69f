"""Where each command's time goes: its whole process against its own computation.

For every command that computes, at a trivial size and from a cached system, this prints:

- **whole**: the wall time of ``python -m biped_opt.cli.main ARGS`` as a user runs it (median
  of ``--runs`` processes, after one that warms the caches);
- **compute**: the same command called a second time inside one process (``main(ARGS)``, after
  a first call that pays the imports and the loading of compiled code), i.e. the work itself;
- **start-up**: whole - compute, what the process pays before and around the work.

and last the 2001-point touchdown sweep, whole process, against the independent SciPy reference
(``bench/solve_ivp_reference.py``, ``solve_ivp`` DOP853 per trajectory) timed in the same run on
a sample of the same angles and scaled to 2001: the ratio a user of the command line sees.

The commands that read a file get one written first, into a temporary directory: a study of one
parameter point, and a recording of an 11-point sweep (made through the nodes by ``biped-opt
record``) for ``report``, drawn in two processes as the command does by default and in one
(``--jobs 1``). ``gradients`` runs at a trial size (one problem, one start, 64 samples, 3
iterations, a 41-point quadrature); its ``--quick`` study (about 5 s of work per problem) runs
with ``--gradients`` only, once, and its start-up is then the one figure to read.

    python -m bench.cli_start [--runs 3] [--reference-sample 41] [--gradients]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

COMMANDS: dict[str, list[str]] = {
    "simulate": ["simulate", "--maneuver", "touchdown", "--theta0", "0.01"],
    "sweep": ["sweep", "--maneuver", "touchdown", "--theta0-min", "-0.1",
              "--theta0-max", "0.1", "--num", "11", "--no-progress"],
    "optimise": ["optimise", "--maneuver", "touchdown", "--theta0", "0.05"],
    "nonsmooth": ["nonsmooth", "--maneuver", "touchdown"],
    "simulate --system": ["simulate", "--system", "rocking_bar", "--maneuver", "drop",
                          "--s", "0.1"],
    "gradients (trial)": ["gradients", "--quick", "--problem", "touchdown", "--starts", "1",
                          "--samples", "64", "--iterations", "3", "--quadrature", "41"],
}
#: (name, arguments with {dir} for the temporary directory): commands that read a file the
#: bench writes first (see :func:`_files`)
FILE_COMMANDS: dict[str, list[str]] = {
    "study (1 point)": ["study", "{dir}/one.yaml", "--out", "{dir}/one.csv", "--no-progress"],
    "report": ["report", "--out", "{dir}/report", "{dir}/sweep.mcap"],
    "report --jobs 1": ["report", "--out", "{dir}/report1", "--jobs", "1", "{dir}/sweep.mcap"],
    "pieces": ["pieces", "--legs", "2", "--rounds", "1", "--samples", "20", "--no-derivative"],
}
GRADIENTS = ["gradients", "--quick", "--problem", "touchdown"]
#: one parameter point, the fixed-input tables and the optimal ones on small grids
STUDY = """system: biped
maneuver: touchdown
inputs: {u1: 2.0, u2: 0.5}
problem: touchdown
grid: {k: [25]}
s_range: [-0.05, 0.05]
num: 21
num_optimal: 5
"""
SWEEP_2001 = ["sweep", "--maneuver", "touchdown", "--theta0-min", "-0.25", "--theta0-max",
              "0.25", "--num", "2001", "--no-progress"]

#: run inside one process: the command twice, the second timed (the first pays start-up)
_TWICE = """
import contextlib, io, os, pathlib, sys, time
from biped_opt.cli.main import main
argv = sys.argv[1:]
for k in range(2):
    for fresh in filter(None, os.environ.get("BENCH_FRESH", "").split(os.pathsep)):
        pathlib.Path(fresh).unlink(missing_ok=True)
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        start = time.perf_counter()
        main(argv)
        took = time.perf_counter() - start
print(took)
"""


def whole(argv: list[str], runs: int, fresh: tuple[Path, ...] = ()) -> float:
    """Median wall time of ``runs`` processes of the command (one more first, not counted);
    the files ``fresh`` are removed before each (a study's table: else it is continued)."""
    times = []
    for k in range(runs + 1):
        for path in fresh:
            path.unlink(missing_ok=True)
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "biped_opt.cli.main", *argv], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        if k:
            times.append(time.perf_counter() - start)
    return statistics.median(times)


def compute(argv: list[str], fresh: tuple[Path, ...] = ()) -> float:
    env = {**os.environ, "BENCH_FRESH": os.pathsep.join(map(str, fresh))}
    out = subprocess.run([sys.executable, "-c", _TWICE, *argv], check=True,
                         capture_output=True, text=True, env=env).stdout
    return float(out.strip().splitlines()[-1])


def reference_per_trajectory(sample: int) -> float:
    """SciPy's time per touchdown trajectory at the paper's fixed inputs, on ``sample`` of the
    sweep's angles (spread over its range, 0 included)."""
    from bench.solve_ivp_reference import simulate

    angles = np.linspace(-0.25, 0.25, sample)
    start = time.perf_counter()
    for th0 in angles:
        simulate("touchdown", float(th0), (2.0, 0.5, 0.0))
    return (time.perf_counter() - start) / sample


def _files(folder: Path) -> None:
    """The study file and the recording the file commands read (the recording through the
    nodes, on this machine's DDS domain)."""
    (folder / "one.yaml").write_text(STUDY)
    subprocess.run([sys.executable, "-m", "biped_opt.cli.main", "record", "--maneuver",
                    "touchdown", "--theta0-min", "-0.1", "--theta0-max", "0.1", "--num", "11",
                    "--out", str(folder / "sweep.mcap")], check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL, timeout=600)


def _row(name: str, command: list[str], runs: int, fresh: tuple[Path, ...] = ()) -> None:
    w, c = whole(command, runs, fresh), compute(command, fresh)
    print(f"{name:20s} {w:10.3f} {c:12.4f} {w - c:13.3f}", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="processes per command (median)")
    ap.add_argument("--reference-sample", type=int, default=41,
                    help="angles the SciPy reference is timed on")
    ap.add_argument("--gradients", action="store_true",
                    help="also gradients --quick on one problem (about 10 s)")
    args = ap.parse_args(argv)
    print(f"{'command':20s} {'whole [s]':>10s} {'compute [s]':>12s} {'start-up [s]':>13s}")
    for name, command in COMMANDS.items():
        _row(name, command, args.runs)
    with tempfile.TemporaryDirectory() as work:
        _files(Path(work))
        for name, command in FILE_COMMANDS.items():
            fresh = (Path(work) / "one.csv",) if name.startswith("study") else ()
            _row(name, [a.format(dir=work) for a in command], args.runs, fresh)
    if args.gradients:
        _row("gradients --quick", GRADIENTS, 1)
    w = whole(SWEEP_2001, args.runs)
    ref = reference_per_trajectory(args.reference_sample)
    print(f"\n2001-point touchdown sweep: whole process {w:.3f} s; SciPy reference "
          f"{ref * 1e3:.2f} ms per trajectory, {2001 * ref:.1f} s for 2001; "
          f"ratio {2001 * ref / w:.1f}x (the issue's goal: >= 20x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
