"""``biped-opt demo``: the paper's sweeps through the ROS graph, MCAP files, figures, summary.

The simulator, optimiser and recorder come up in this process on the ROS backend (real rclpy
or the built-in Cyclone DDS one); the recorder sweeps both maneuvers at fixed inputs (401 angles)
and at their optimal policies (201 angles, one optimiser call per angle) and writes one MCAP file
per sweep. The recordings are then analysed offline (``biped-opt report``: figures and a
grid-resolution nonsmooth table from the files alone), and the paper's figures and the exact
nonsmooth table (every point located to 1e-10 with the core) are reproduced.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from biped_opt.cli.args import output_directory, path_arg

SWEEPS = (  # maneuver, optimal, angles
    ("touchdown", False, 401),
    ("liftoff", False, 401),
    ("touchdown", True, 201),
    ("liftoff", True, 201),
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the paper's sweeps through the nodes; MCAP, figures")
    p.add_argument("--out", type=path_arg(output_directory, "--out", create=False),
                   default=Path("out"), help="output directory (default out/)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from biped_opt import ros
    from biped_opt.cli.signals import stop_requested
    from biped_opt.nodes.graph import Graph
    from biped_opt.nodes.recorder import SweepRequest
    from biped_opt.paper.biped import theta0_limit
    from biped_opt.plots.reproduce import reproduce
    from biped_opt.record.report import report

    output_directory("--out", args.out)
    start = time.perf_counter()
    print(f"bringing up simulator, optimiser, recorder (ROS backend: {ros.BACKEND})", flush=True)
    recorded = []
    # as `record`: a signal while the graph starts abandons it; during the sweeps it stops the
    # current one after its point, finishes its file and skips the rest
    with stop_requested(interrupt=True) as stop:
        try:
            graph = Graph(overrides={"simulator": {"autostart": False}})
        except KeyboardInterrupt:
            return 0
        with graph:
            stop.defer(graph.recorder.stop)
            for maneuver, optimal, num in SWEEPS:
                limit = theta0_limit(maneuver)
                kind = "optimal" if optimal else "fixed"
                t0 = time.perf_counter()
                summary = graph.recorder.record(SweepRequest(
                    maneuver=maneuver, theta0_min=-limit, theta0_max=limit, num=num,
                    optimal=optimal, output=args.out / f"{maneuver}_{kind}.mcap"))
                recorded.append(summary)
                counts = ", ".join(f"{n} {t}" for t, n in summary.counts.items())
                print(f"  {maneuver:9s} {kind:7s} {summary.recorded} angles -> {summary.path} "
                      f"({counts}; {time.perf_counter() - t0:.1f} s)", flush=True)
                if stop.is_set():
                    print(f"stopped by a signal: {len(recorded)} of {len(SWEEPS)} sweeps "
                          "recorded (the last one in part), no analysis", flush=True)
                    return 0
    print("\nanalysing the recordings offline (biped-opt report) ...", flush=True)
    offline = report([s.path for s in recorded], args.out / "report")
    print("\nreproducing the figures and the exact nonsmooth table ...", flush=True)
    result = reproduce(args.out / "figures")
    print("\nNonsmooth points of outcomes, optimal policies and values (left | right)\n")
    print(result.table())
    experiment = control_experiment(args.out / "figures")
    study_figures = two_node_study(args.out)
    piece_counts()
    gradient_methods(args.out / "figures")
    movies = animations(args.out)
    print("\nSummary")
    for s in recorded:
        print(f"  {s.path}  {sum(s.counts.values())} messages, {s.failed} failed points")
    page = (offline.page,) if offline.page is not None else ()
    for path in (*page, *offline.figures, *result.figures, result.captions, experiment,
                 *study_figures, *movies):
        print(f"  {path}")
    print(f"  total {time.perf_counter() - start:.1f} s")
    failed = sum(s.failed for s in recorded)
    return 0 if not failed else 1


def control_experiment(folder: Path) -> Path:
    """The paper's claim as a controlled experiment (SYSTEMS.md Secs. 2-3), printed and drawn:
    the two-leg walker with coupled and decoupled inputs at the paper's fixed inputs, and the
    rocking bar's jumps. Returns the figure's path."""
    from biped_opt.control.derivatives import one_sided_derivatives
    from biped_opt.plots.systems import (
        LIFTOFF_INPUTS,
        TOUCHDOWN_INPUTS,
        control_experiment_data,
        control_experiment_figure,
    )
    from biped_opt.simulation.compiled import CompiledSystem

    print("\nThe control experiment: same walker, coupled vs decoupled inputs (SYSTEMS.md)\n",
          flush=True)
    data = control_experiment_data()
    inputs = {"touchdown": TOUCHDOWN_INPUTS, "liftoff": LIFTOFF_INPUTS}
    for maneuver, marks in (("touchdown", data.touchdown_marks),
                            ("liftoff", data.liftoff_marks)):
        for law in ("coupled", "decoupled"):
            at_zero = [m for m in marks if m.series == law and m.s == 0.0
                       and m.kind in ("kink", "jump")]
            if at_zero:
                m = at_zero[0]
                pair = m.limits if m.kind == "jump" else m.slopes
                what = "limits" if m.kind == "jump" else "slopes"
                line = f"{m.kind} at th0 = 0, {what} {pair[0]:+.10f} | {pair[1]:+.10f}"
            else:
                walker = CompiledSystem(f"walker2_{law}")
                left, right = one_sided_derivatives(walker, maneuver, 0.0,
                                                    list(inputs[maneuver]))
                line = f"smooth at th0 = 0 (no kink, no jump), slopes {left:+.10f} | {right:+.10f}"
            print(f"  walker2 {law:9s} {maneuver:9s} u = {inputs[maneuver]}: {line}")
    print("\n  rocking bar (no input, inertial coupling), drop outcome th'(t_f):")
    for m in data.bar_marks:
        print(f"    {m.kind} at th0 = {m.s:+.10f}: limits {m.limits[0]:+.10f} | "
              f"{m.limits[1]:+.10f}")
    return control_experiment_figure(folder / "control_experiment.png", data)


def piece_counts() -> None:
    """Paper Sec. V-B, small and fast: the smooth pieces of the 1- and 2-leg walker around the
    simultaneous touchdown over k = 1, 2 rounds (``biped-opt pieces`` does n = 1..4, k = 1..3)."""
    from biped_opt.analysis.pieces import count_pieces

    print("\nSmooth pieces near simultaneous contact vs the paper's (n!)^k "
          "(100 seeded samples each; biped-opt pieces for n up to 4)\n", flush=True)
    for n in (1, 2):
        for k in (1, 2):
            for velocities in (False, True):
                c = count_pieces(n, k, samples=100, velocities=velocities)
                what = "heights + velocities" if velocities else "foot heights"
                print(f"  n = {n}, k = {k}, {what:20s}: {c.count} pieces "
                      f"({sum(c.confirmed.values())} confirmed by bisection), (n!)^k = {c.bound}")


def gradient_methods(folder: Path) -> None:
    """Paper Sec. V-A, small: gradient methods on the liftoff problem, whose cost jumps in u12
    (``biped-opt gradients`` runs every problem, larger)."""
    from biped_opt.analysis.gradients import report, run_gradient_study
    from biped_opt.cli.args import GRADIENT_EPS_VALUES, GRADIENT_SAMPLE_COUNTS, GRADIENT_SIGMAS
    from biped_opt.plots.gradients import gradient_figure

    print("\nGradient methods at a jump of the liftoff cost (biped-opt gradients --quick "
          "--problem liftoff, seed 0)\n", flush=True)
    study = run_gradient_study(seed=0, quick=True, problems=["liftoff"],
                               sigmas=GRADIENT_SIGMAS, sample_counts=GRADIENT_SAMPLE_COUNTS,
                               eps_values=GRADIENT_EPS_VALUES)
    print(report(study, GRADIENT_SAMPLE_COUNTS))
    for name in study.curves:
        print(f"  {gradient_figure(study, name, folder / f'gradients_{name}.png')}")


#: the demo's animations (``biped-opt animate --side-by-side --fps 20``, th0 = -+0.02):
#: system, maneuver, simulated seconds per second, file
ANIMATIONS = (("biped", "touchdown", 0.5, "touchdown_pair.gif"),
              ("biped", "liftoff", 0.25, "liftoff_pair.gif"),
              ("rocking_bar", "drop", 0.5, "rocking_bar_pair.gif"))


def animations(out: Path) -> list[Path]:
    """The flip at a simultaneous event, to watch: each maneuver of :data:`ANIMATIONS` at
    s = -0.02 and +0.02 side by side, written into ``out``. Returns the files' paths."""
    from biped_opt.plots.animate import side_by_side

    print("\nAnimations: each maneuver at s = -0.02 and +0.02 side by side (the order of "
          "contacts flips at 0, and with it the outcome)\n", flush=True)
    paths = []
    for system, maneuver, speed, name in ANIMATIONS:
        t0 = time.perf_counter()
        movie = side_by_side(system, maneuver, out / name, delta=0.02, fps=20, speed=speed)
        for p in movie.panels:
            print("  " + p.title.replace("\n", "  "))
        print(f"  -> {out / name} ({movie.frames} frames, {time.perf_counter() - t0:.1f} s)",
              flush=True)
        paths.append(out / name)
    return paths


#: the demo's parameter study: the liftoff jump over leg stiffness and body inertia (5 x 5)
DEMO_STUDY = {"name": "demo", "system": "biped", "maneuver": "liftoff",
              "inputs": {"u1": 1.5, "u2": 3.0},
              "grid": {"k": [20.0, 23.5, 27.0, 31.0, 35.0], "Ib": [0.3, 0.4, 0.5, 0.6, 0.7]},
              "s_range": [-0.02, 0.02], "num": 41}


def two_node_study(out: Path) -> list[Path]:
    """A small parameter study computed by two optimiser nodes on the DDS domain, handed out by
    the coordinator (as on several machines): where the liftoff jump persists."""
    from biped_opt import ros
    from biped_opt.nodes.coordinator import hosted, run_on_domain
    from biped_opt.nodes.optimiser import OptimiserNode
    from biped_opt.plots.study import study_figures
    from biped_opt.record.study_table import read_table
    from biped_opt.studies.study import Study

    def optimiser(name: str):
        return hosted(lambda context: OptimiserNode(
            context=context, namespace=f"/demo_{name}", parameter_overrides=[
                ros.Parameter("warm_up", value=False),
                ros.Parameter("worker", value=f"demo_{name}")]), name=f"optimiser-{name}")

    study = Study.from_spec(DEMO_STUDY)
    table = out / "study_liftoff_jump.csv"
    for stale in (table, table.with_name(table.name + ".study.json")):
        stale.unlink(missing_ok=True)
    print("\nA parameter study through two optimiser nodes (5 x 5 over k and Ib, the "
          "/biped/study coordinator hands out the points)\n", flush=True)
    t0 = time.perf_counter()
    with optimiser("a"), optimiser("b"):
        summary = run_on_domain(study, table)
    rows = read_table(table)
    jumps = {(float(r["k"]), float(r["Ib"])): float(r["size"]) for r in rows
             if r["kind"] == "jump" and r["s"] and abs(float(r["s"])) <= 1e-9}
    print(f"  {summary.points} points in {time.perf_counter() - t0:.1f} s -> {table}")
    print(f"  the liftoff outcome jumps at th0 = 0 at {len(jumps)} of {summary.points} points; "
          f"size (right - left) from {min(jumps.values()):+.4f} to {max(jumps.values()):+.4f}")
    return study_figures(out / "figures", rows, study.parameter_names)
