"""The library's robots from URDF (issue 35 part 6): what they cost, against Pinocchio.

For each robot (``solo12``, ``bolt``, ``g1``; ``--robots``), in one run:

- ``cold``: a new interpreter with an empty cache importing the URDF, compiling the robot and
  simulating one drop (the kernel every system shares is compiled once per installation);
- ``cached``: a new process running ``biped-opt simulate`` of a drop from that cache, once the
  kernel compiled ahead of time is there (best of 2);
- ``per drop``: single ``simulate`` calls of the drop maneuver over ``--cases`` values of s
  spread over its range, per case (best of ``--rounds`` loops); ``batch``: one
  ``simulate_batch`` of them, per case;
- ``per rhs``: the per-drop time over the drop's right-hand-side evaluations (nfev): the cost
  of one evaluation of the field with the active contacts, the kernel's stepping, event
  location and Python call included (an upper bound on the field alone);
- Pinocchio in the same process, called from Python on its own model of the URDF (a free-flyer
  root, the same contact points), per call the best of 5 rounds of 400: ``crba`` (M), ``rnea`` (bias
  forces), ``aba``, one ``rhs`` as a simulator needs it for the contacts in contact (kinematics
  with velocities, the contacts' Jacobian rows and classical accelerations, then
  ``forwardDynamics`` with them), and ``impulseDynamics`` (the plastic impact);
- ``SciPy``: the same drop by SciPy's ``solve_ivp`` (DOP853, rtol 1e-11 as the simulator,
  atol 1e-12) on Pinocchio's dynamics, with its event location (heights in the air, reactions
  in contact, the nadir after the first touchdown, a guard left at zero by an event watched
  again once 2e-10 clear, steps of at most 1e-5 meanwhile), plastic impacts and the
  complementarity rule for the mode after each event
  (``tests/systems/pinocchio_reference.py``'s model), per drop over
  ``--reference-cases`` of the cases; ``speed-up``: the median over those cases of SciPy's time
  over ours on the same case. For g1, whose soles'
  contacts are dependent, the tests' reference (``reference_rigid``'s event rules, DOP853 at
  rtol 1e-12, each step's guards sampled 16 times), which this loop is not (its ratio is to
  a slower and stricter reference), at s = 0 and 0.002 (it does not model a sole that rolls
  off an edge while resting on a dependent set, as larger tilts make it do);
- ``max |err|``: the largest difference of the outcome (the base's roll rate at the nadir) and
  of the final time between ours and SciPy's over those cases.

Targets (issue 35): solo12's cold compile <= 15 s, the humanoid's <= 60 s; per rhs no more than
Pinocchio's rhs; per drop >= 50 times faster than SciPy + Pinocchio.

    python bench/urdf_robots.py [--robots solo12 bolt g1] [--cases 10] [--rounds 3]
                                [--reference-cases 3] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from bench.scaling import _process_seconds, _time, _wait_for_ahead_of_time  # noqa: E402

_COLD = """
import sys, time
t0 = time.perf_counter()
from biped_opt.simulation.compiled import CompiledSystem
system = CompiledSystem(sys.argv[1])
system.simulate("drop", 0.01)
print(time.perf_counter() - t0)
"""

#: each robot's contact points for Pinocchio's model, read by hand from its URDF (as the
#: tests do): (link, point in its frame, radius)
CONTACTS = {
    "solo12": [(f"{leg}_FOOT", (0.0, 0.0, 0.0), 0.0) for leg in ("FL", "FR", "HL", "HR")],
    "bolt": [(f"{leg}_FOOT", (0.0, 0.0, 0.0), 0.0) for leg in ("FL", "FR")],
    "g1": [(f"{side}_ankle_roll_link", centre, 0.005) for side in ("left", "right")
           for centre in ((-0.05, 0.025, -0.03), (-0.05, -0.025, -0.03), (0.12, 0.03, -0.03),
                          (0.12, -0.03, -0.03))],
}


def _best(call, n: int = 2000) -> float:
    best = np.inf
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(n // 5):
            call()
        best = min(best, (time.perf_counter() - t0) / (n // 5))
    return float(best)


def pinocchio_costs(name: str, system: Any) -> dict[str, float]:
    """Pinocchio's own timings on its free-flyer model of the robot (see the docstring)."""
    import pinocchio as pin

    from biped_opt.systems.library.robots import ROBOT_FILES

    model = pin.buildModelFromUrdf(str(ROBOT_FILES[name]), pin.JointModelFreeFlyer())
    locked = dict(system.robot.locked)
    if locked:
        q_ref = pin.neutral(model)
        for joint, value in locked.items():
            q_ref[model.joints[model.getJointId(joint)].idx_q] = value
        model = pin.buildReducedModel(model, [model.getJointId(j) for j in locked], q_ref)
    frames = []
    for k, (link, point, _r) in enumerate(CONTACTS[name]):
        body = model.frames[model.getFrameId(link)]
        frames.append(model.addFrame(pin.Frame(
            f"contact_{k}", body.parentJoint,
            body.placement * pin.SE3(np.eye(3), np.array(point)), pin.FrameType.OP_FRAME)))
    data = model.createData()
    rng = np.random.default_rng(1)
    q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    v, tau = rng.uniform(-1, 1, model.nv), rng.uniform(-1, 1, model.nv)
    world = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

    def rhs() -> None:
        pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        J = np.array([pin.getFrameJacobian(model, data, f, world)[2] for f in frames])
        gamma = np.array([pin.getFrameClassicalAcceleration(model, data, f, world).linear[2]
                          for f in frames])
        pin.forwardDynamics(model, data, q, v, tau, J, gamma)

    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    # (independent rows for the impact: at most three contacts per rigid sole)
    rows = [0, 1, 2] + ([4, 5, 6] if len(frames) == 8 else list(range(3, len(frames))))
    rows = rows[:len(frames)]
    J_impact = np.array([pin.getFrameJacobian(model, data, frames[k], world)[2] for k in rows])
    return {"crba": _best(lambda: pin.crba(model, data, q)),
            "rnea": _best(lambda: pin.rnea(model, data, q, v, tau)),
            "aba": _best(lambda: pin.aba(model, data, q, v, tau)),
            "rhs": _best(rhs),
            "impulse": _best(lambda: pin.impulseDynamics(model, data, q, v, J_impact, 0.0))}


def scipy_drop(robot: Any, y0: np.ndarray, *, rtol: float = 1e-11, atol: float = 1e-12,
               t_end: float = 2.0, max_events: int = 40) -> tuple[float, float, int]:
    """The drop by solve_ivp on Pinocchio's dynamics: (final time, outcome, nfev)."""
    from scipy.integrate import solve_ivp

    nq = robot.nq
    z = robot.coordinates.index("base_z")
    roll = robot.coordinates.index("base_roll")
    n = robot.n
    y, t, mode = np.asarray(y0, dtype=float), 0.0, frozenset()
    touched, nfev, events = False, 0, 0
    armed = [True] * n
    while events < max_events:
        current = mode

        def guard(j: int, current: frozenset = current) -> Any:
            def g(_t: float, yy: np.ndarray) -> float:
                if j in current:
                    return float(robot.accel(yy, current)[1][j])
                return float(robot.heights(yy)[j])
            g.terminal, g.direction = True, -1  # type: ignore[attr-defined]
            return g

        def rearm(j: int) -> Any:  # (a guard left at ~0 by an event counts again above 2e-10)
            def g(_t: float, yy: np.ndarray) -> float:
                return float(robot.heights(yy)[j]) - 2e-10
            g.terminal, g.direction = True, 1  # type: ignore[attr-defined]
            return g

        guards = [guard(j) if armed[j] else rearm(j) for j in range(n)]
        owners = list(range(n))
        if touched:
            def nadir(_t: float, yy: np.ndarray) -> float:
                return -float(yy[nq + z])
            nadir.terminal, nadir.direction = True, -1  # type: ignore[attr-defined]
            guards.append(nadir)
        def rhs(_t: float, yy: np.ndarray, current: frozenset = current) -> np.ndarray:
            return robot.field(yy, current)

        # (short steps while a guard sits at zero after an event: a released foot's hop can
        # last a fraction of a millisecond, and solve_ivp sees roots only between step ends)
        sol = solve_ivp(rhs, (t, t_end), y, method="DOP853", rtol=rtol, atol=atol,
                        events=guards, max_step=np.inf if all(armed) else 1e-5)
        nfev += sol.nfev
        hits = [(te[0], k) for k, te in enumerate(sol.t_events) if len(te)]
        if not hits:
            return t_end, float(sol.y[roll + nq, -1]), nfev
        t, k = min(hits)
        y = sol.y_events[k][0]
        if touched and k == len(guards) - 1:
            return t, float(y[nq + roll]), nfev
        j = owners[k]
        if not armed[j]:
            armed[j] = True
            continue
        heights, rates = robot.heights(y), robot.rates(y)
        down = {i for i in range(n) if i not in current and (
            i == j or (abs(heights[i]) <= 1e-9 and rates[i] < 0))}
        up = {j} if j in current else set()
        surface = (current | down) - up
        if down:
            y = robot.impact(y, surface)
            touched = True
        mode = robot.stay(y, surface)
        armed = [i not in (down | up) or abs(robot.heights(y)[i]) > 1e-10 or i in mode
                 for i in range(n)]
        events += 1
    return t, float(y[nq + roll]), nfev


def measure(name: str, *, cases: int, rounds: int, reference_cases: int) -> dict[str, Any]:
    """One row of the table (see the module docstring)."""
    from biped_opt.simulation.compiled import CompiledSystem
    from biped_opt.systems.derive import derive
    from biped_opt.systems.files import load_system
    from biped_opt.systems.library.robots import ROBOT_FILES
    from tests.systems.pinocchio_reference import PinocchioRobot, drop

    with tempfile.TemporaryDirectory(prefix="biped_opt_urdf_") as cache:
        env = dict(os.environ, BIPED_OPT_CACHE=cache)
        cold = _process_seconds([sys.executable, "-c", _COLD, name], env)
        _wait_for_ahead_of_time(Path(cache) / "systems")
        cached = min(_process_seconds([sys.executable, "-m", "biped_opt.cli.main", "simulate",
                                       "--system", name, "--large", "--maneuver", "drop",
                                       "--s", "0.01"],
                                      env) for _ in range(2))
        before = os.environ.get("BIPED_OPT_CACHE")
        os.environ["BIPED_OPT_CACHE"] = cache
        try:
            compiled = CompiledSystem(name)
            compiled.simulate_batch("drop", [0.0, 0.01])
            compiled.simulate("drop", 0.0)
        finally:
            if before is None:
                del os.environ["BIPED_OPT_CACHE"]
            else:
                os.environ["BIPED_OPT_CACHE"] = before
    lo, hi = compiled.s_range("drop")
    s_values = np.linspace(lo, hi, cases)
    loop = batch = np.inf
    for _ in range(rounds):
        t0 = time.perf_counter()
        runs = [compiled.simulate("drop", s) for s in s_values]
        loop = min(loop, (time.perf_counter() - t0) / cases)
        t0 = time.perf_counter()
        compiled.simulate_batch("drop", s_values)
        batch = min(batch, (time.perf_counter() - t0) / cases)
    nfev = float(np.mean([r.nfev for r in runs]))
    system = load_system(name)
    imported = system.robot
    robot = PinocchioRobot(str(ROBOT_FILES[name]), list(system.coordinate_names),
                           contacts=CONTACTS[name], locked=dict(imported.locked),
                           posture=dict(imported.posture), kp=system.defaults["kp"])
    numeric = derive(system).numeric()
    picks = list(s_values[:: max(1, cases // reference_cases)])[:reference_cases]
    ref_times, errors, ref_nfev, own_times = [], [], [], []
    flat = any(r > 0 for _l, _p, r in CONTACTS[name])  # (spheres under flat soles)
    if flat:  # (the tilts the reference follows: larger ones roll a resting sole off an edge)
        picks = [0.0, 0.002]
    for s in picks:
        y0, _mode = numeric.initial_state("drop", s)
        t0 = time.perf_counter()
        if flat:
            run = drop(robot, y0)
            t_final, outcome, fev = run.t_final, float(run.y_final[robot.nq + 3]), 0
        else:
            t_final, outcome, fev = scipy_drop(robot, y0)
        ref_times.append(time.perf_counter() - t0)
        ref_nfev.append(fev)
        ours = compiled.simulate("drop", s)
        errors.append(max(abs(ours.outcome - outcome), abs(ours.t_final - t_final)))
        best = np.inf
        for _ in range(rounds):  # (ours on the same case, for the ratio)
            t0 = time.perf_counter()
            compiled.simulate("drop", s)
            best = min(best, time.perf_counter() - t0)
        own_times.append(best)
    pin_costs = pinocchio_costs(name, system)
    reference = float(np.median(ref_times))
    return {"robot": name, "d": len(compiled.coordinates),
            "contacts": len(compiled.constraints), "cold_s": cold, "cached_s": cached,
            "per_drop_s": float(loop), "batch_per_drop_s": float(batch),
            "nfev": nfev, "per_rhs_s": float(loop) / nfev,
            "pinocchio_s": pin_costs, "scipy_per_drop_s": reference,
            "scipy_nfev": float(np.mean(ref_nfev)),
            "speedup": float(np.median(np.array(ref_times) / np.array(own_times))),
            "max_abs_error": float(max(errors))}


def table(rows: list[dict[str, Any]]) -> str:
    head = (f"{'robot':<8}{'d':>3}{'n':>3}{'cold':>8}{'cached':>11}{'per drop':>10}"
            f"{'batch':>10}{'per rhs':>9}{'pin rhs':>9}{'SciPy':>10}{'speed-up':>9}"
            f"{'max |err|':>10}  Pinocchio crba / rnea / aba / impulse")
    lines = [head]
    for r in rows:
        p = r["pinocchio_s"]
        lines.append(
            f"{r['robot']:<8}{r['d']:>3}{r['contacts']:>3}{_time(r['cold_s']):>8}"
            f"{_time(r['cached_s']):>11}{_time(r['per_drop_s']):>10}"
            f"{_time(r['batch_per_drop_s']):>10}{_time(r['per_rhs_s']):>9}"
            f"{_time(p['rhs']):>9}{_time(r['scipy_per_drop_s']):>10}{r['speedup']:>8.0f}x"
            f"{r['max_abs_error']:>10.1e}  {_time(p['crba'])} / {_time(p['rnea'])} / "
            f"{_time(p['aba'])} / {_time(p['impulse'])}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", nargs="*", default=["solo12", "bolt", "g1"],
                    choices=sorted(CONTACTS))
    ap.add_argument("--cases", type=int, default=10)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--reference-cases", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    rows = []
    for name in args.robots:
        rows.append(measure(name, cases=args.cases, rounds=args.rounds,
                            reference_cases=args.reference_cases))
        print(table(rows[-1:]).splitlines()[-1], file=sys.stderr if args.json else sys.stdout,
              flush=True)
    print(json.dumps(rows, indent=2) if args.json else table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
