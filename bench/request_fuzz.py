"""Fuzz the optimiser node with malformed requests and check it keeps serving.

Starts one optimiser node in its own process and writes N requests (default 10,000) straight
onto ``rq/biped/optimal_policyRequest`` with Cyclone's raw write, each a seeded random
corruption of a valid request: bit flips in the maneuver name or anywhere in the body, random
bytes of random length as the name (mostly not UTF-8), wrong string lengths. Cyclone refuses
the structurally invalid ones at the writer (its CDR check; a receiving Cyclone applies the
same check); every other one reaches the node. Prints how many were written, refused by
Cyclone, answered ``success = false``, answered otherwise and left unanswered, whether a valid
request is still answered correctly afterwards, the node's exit status on SIGINT and whether
its stderr holds a traceback.

    python bench/request_fuzz.py [--requests 10000] [--seed 1]

``--hostile`` sends instead, as any peer on the domain can, what would make a node run the
requester's code, write where the requester says or stall the service, to an optimiser and a
coordinator it starts with their default parameters (the optimiser's ``worker`` named so that
its work-item service is known), both in a fresh directory:

- ``OptimalPolicy`` requests whose ``system`` or ``problem`` names a ``.py`` file (absolute,
  relative to the node's working directory, ``../``, with a trailing space) or a ``.yaml``
  problem naming a ``.py`` system; ``StudyPoint`` work items and ``/biped/study`` goals whose
  study names them; each file's top level creates a marker file of its own;
- a ``/biped/study`` goal for a valid one-point study whose ``out`` is ``../<name>.csv``;
- a system name and a system path of 8 KB; a ``StudyPoint`` item and a goal with a 400^4 grid
  (the nodes run with an address space cap, ``--memory-cap-gb``);
- five requests for the library system ``walker99`` (a compile of minutes), then a valid
  biped request, whose latency is measured.

It prints the markers that exist afterwards (``code_executed``, must be 0), the files the goal
named that exist (``files_written``, must be 0), the requests left unanswered, the replies that
are ``internal error``, the valid request's latency, the nodes' peak memory and how they
stopped (SIGINT, else SIGTERM, else SIGKILL). Its exit status is 1 when any code ran or any
file was written there.

    python bench/request_fuzz.py --hostile [--timeout 60] [--valid-timeout 60] [--keep-files]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

os.environ.setdefault("ROS_LOCALHOST_ONLY", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cyclonedds._clayer import ddspy_write  # noqa: E402

from bench.service_load import (  # noqa: E402
    close_client,
    optimiser_client,
    rss_kib,
    start_node,
)


def _string(text: bytes) -> bytes:
    raw = struct.pack("<I", len(text) + 1) + text + b"\x00"
    return raw + bytes(-len(raw) % 8)


#: the request's fields after theta0: system and problem, both "" (length 1, NUL, padding)
_TAIL = struct.pack("<I", 1) + bytes(4) + struct.pack("<I", 1) + bytes(1)


#: the biped request whose answer is known, and the answer (MODEL.md R5)
VALID = {"maneuver": "touchdown", "theta0": 0.05}
VALID_VALUE = 0.0194158739483


def valid_answer(reply: Any) -> bool:
    """Whether ``reply`` is the right answer to VALID: within 1e-10 of R5, far below any change
    of the problem and above the solver's last-bit differences between processes and machines
    (R5 is given to 12 digits; a node here answers 0.0194158739485)."""
    return bool(reply.success) and abs(reply.value - VALID_VALUE) < 1e-10


def corrupt(rng: random.Random, i: int) -> bytes:
    """The body (after the 16-byte header) of the i-th malformed OptimalPolicy request."""
    name = bytearray(rng.choice([b"touchdown", b"liftoff"]))
    kind = i % 4
    if kind == 0:  # bit flips in the name
        for _ in range(rng.randint(1, 4)):
            name[rng.randrange(len(name))] ^= 1 << rng.randrange(8)
        return _string(bytes(name)) + (struct.pack("<d", 0.05) + _TAIL)
    if kind == 1:  # random bytes as the name
        return _string(rng.randbytes(rng.randrange(1, 64))) + (struct.pack("<d", 0.05) + _TAIL)
    if kind == 2:  # bit flips anywhere in the body
        body = bytearray(_string(bytes(name)) + (struct.pack("<d", 0.05) + _TAIL))
        for _ in range(rng.randint(1, 4)):
            body[rng.randrange(len(body))] ^= 1 << rng.randrange(8)
        return bytes(body)
    body = _string(bytes(name)) + (struct.pack("<d", 0.05) + _TAIL)  # a wrong string length
    return struct.pack("<I", rng.randrange(1 << 16)) + body[4:]


def run(requests: int, seed: int, domain_id: int) -> dict:
    from biped_opt import ros

    node_proc = start_node(domain_id, None)
    rss_before = rss_kib(node_proc.pid)
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    node, cli, executor = optimiser_client("fuzzer")
    rng = random.Random(seed)
    futures, refused = [], 0
    t0 = time.perf_counter()
    for i in range(requests):
        future = ros.Future()
        with cli._pending_lock:
            seq = next(cli._seq)
            cli._pending[seq] = future
        data = b"\x00\x01\x00\x00" + struct.pack("<Qq", cli.guid, seq) + corrupt(rng, i)
        if ddspy_write(cli._writer._ref, data.ljust(-(-len(data) // 4) * 4, b"\x00")) < 0:
            cli.remove_pending_request(future)
            refused += 1
        else:
            futures.append(future)
    deadline = time.monotonic() + 120.0
    while not all(f.done() for f in futures) and time.monotonic() < deadline:
        time.sleep(0.05)
    elapsed = time.perf_counter() - t0
    done = [f.result() for f in futures if f.done()]
    probe = cli.call_async(ros.srvs.OptimalPolicy.Request(**VALID))
    probe_ok = probe.wait(60.0) and valid_answer(probe.result())
    rss_after = rss_kib(node_proc.pid)
    close_client(node, executor)
    node_proc.send_signal(2)
    status = node_proc.wait(30)
    time.sleep(0.2)  # the collecting thread reads the last lines
    stderr_lines = [line.rstrip() for line in node_proc.log_lines]
    return {
        "requests": requests, "seed": seed, "refused_by_cyclone": refused,
        "reached_the_node": len(futures),
        "answered_success_false": sum(not r.success for r in done),
        "answered_success_true": sum(bool(r.success) for r in done),
        "unanswered": len(futures) - len(done), "seconds": elapsed,
        "valid_request_after": bool(probe_ok), "node_exit_status": status,
        "traceback_in_node_stderr": any("Traceback" in line for line in stderr_lines),
        "node_log_lines": len(stderr_lines),
        "node_log_sample": stderr_lines[1:3],
        "node_rss_kib_before": rss_before, "node_rss_kib_after": rss_after,
    }


# -- hostile requests ----------------------------------------------------------------------------

#: the library system whose first compile takes minutes
HEAVY_SYSTEM = "walker99"
#: the study every study-shaped case starts from: one point of the rocking bar's drop
BASE_STUDY = {"system": "rocking_bar", "maneuver": "drop", "grid": {"gamma": [0.5]},
              "num": 21}
#: the StudyPoint service of the optimiser the hostile mode starts (its parameter worker)
WORKER = "hostile"


@dataclass(frozen=True)
class Case:
    """One hostile request: what it is (``policy``: OptimalPolicy, ``point``: StudyPoint,
    ``goal``: a /biped/study goal), its message, and the marker its code would create."""

    name: str
    kind: str
    message: Any
    marker: Path | None = None


def _marker_code(marker: Path) -> str:
    return f"from pathlib import Path\nPath({str(marker)!r}).write_text('ran')\n"


def plant_files(root: Path, name: str) -> dict[str, tuple[str, Path]]:
    """Write the ``.py`` files of case family ``name`` under ``root`` (the node runs in
    ``root/cwd``); returns {variant: (the path a request gives, the marker its code writes)}.
    Variants: absolute, relative, ``../``, trailing space, problem file (.py), problem file
    (.yaml naming a .py system next to it)."""
    cwd = root / "cwd"
    cwd.mkdir(parents=True, exist_ok=True)
    out: dict[str, tuple[str, Path]] = {}

    def plant(variant: str, path: Path) -> Path:
        marker = root / f"ran_{name}_{variant}"
        path.write_text(_marker_code(marker), encoding="utf-8")
        return marker

    absolute = root / f"{name}_abs.py"
    out["absolute"] = (str(absolute), plant("absolute", absolute))
    out["relative"] = (f"{name}_rel.py", plant("relative", cwd / f"{name}_rel.py"))
    out["parent"] = (f"../{name}_up.py", plant("parent", root / f"{name}_up.py"))
    spaced = root / f"{name}_space.py"
    out["trailing_space"] = (f"{spaced} ", plant("trailing_space", spaced))
    problem = root / f"{name}_problem.py"
    out["problem_py"] = (str(problem), plant("problem_py", problem))
    system = root / f"{name}_yaml_system.py"
    marker = plant("problem_yaml", system)
    yaml_file = root / f"{name}_problem.yaml"
    yaml_file.write_text(f"system: {system.name}\nmaneuver: drop\nname: hostile\n",
                         encoding="utf-8")
    out["problem_yaml"] = (str(yaml_file), marker)
    return out


def _study_json(variant: str, path: str) -> str:
    spec = dict(BASE_STUDY)
    if variant.startswith("problem"):
        spec.pop("maneuver")
        spec["problem"] = path
    else:
        spec["system"] = path
    return json.dumps(spec)


def code_cases(root: Path, *, coordinator: bool = True) -> list[Case]:
    """Every request that names a file of code: OptimalPolicy, StudyPoint and (with a
    coordinator) Study goals, each variant of :func:`plant_files`."""
    from biped_opt import ros

    cases = []
    for variant, (path, marker) in plant_files(root, "policy").items():
        field = "problem" if variant.startswith("problem") else "system"
        request = ros.srvs.OptimalPolicy.Request(maneuver="drop", theta0=0.0, **{field: path})
        cases.append(Case(f"policy_{variant}", "policy", request, marker))
    for variant, (path, marker) in plant_files(root, "point").items():
        request = ros.srvs.StudyPoint.Request(study=_study_json(variant, path), indices=[0])
        cases.append(Case(f"point_{variant}", "point", request, marker))
    if coordinator:
        for variant, (path, marker) in plant_files(root, "goal").items():
            goal = ros.actions.Study.Goal(study=_study_json(variant, path),
                                          out=str(root / f"table_{variant}.csv"))
            cases.append(Case(f"goal_{variant}", "goal", goal, marker))
        # the node's working directory is root/cwd: this table would land in root
        goal = ros.actions.Study.Goal(study=json.dumps(BASE_STUDY), out="../escaped.csv")
        cases.append(Case("goal_out_parent", "goal", goal))
    return cases


def grid_study(values: int = 400, dims: int = 4) -> str:
    """A study of ``values**dims`` points (the rocking bar has four parameters)."""
    names = ("m", "w", "g", "gamma")[:dims]
    grid = {name: [0.5 + 0.001 * i for i in range(values)] for name in names}
    return json.dumps({**BASE_STUDY, "grid": grid})


def bound_cases(root: Path, *, name_bytes: int = 8192, grid_values: int = 400,
                coordinator: bool = True) -> list[Case]:
    """Requests that must be refused before any large allocation: a system name and a system
    path of about ``name_bytes``, a grid of ``grid_values**4`` points (work item and goal)."""
    from biped_opt import ros

    long_name = "s" * name_bytes
    # a path of as many bytes: directories of 100 characters, longer than PATH_MAX
    long_path = ("/" + "d" * 99) * max(1, (name_bytes - 5) // 100) + "/s.py"
    cases = [
        Case("policy_long_system_name", "policy",
             ros.srvs.OptimalPolicy.Request(maneuver="drop", theta0=0.0, system=long_name)),
        Case("point_long_system_name", "point", ros.srvs.StudyPoint.Request(
            study=json.dumps({**BASE_STUDY, "system": long_name}), indices=[0])),
        Case("policy_long_system_path", "policy",
             ros.srvs.OptimalPolicy.Request(maneuver="drop", theta0=0.0, system=long_path)),
        Case("point_long_system_path", "point", ros.srvs.StudyPoint.Request(
            study=json.dumps({**BASE_STUDY, "system": long_path}), indices=[0])),
        Case("point_huge_grid", "point",
             ros.srvs.StudyPoint.Request(study=grid_study(grid_values), indices=[0])),
    ]
    if coordinator:
        cases.append(Case("goal_huge_grid", "goal", ros.actions.Study.Goal(
            study=grid_study(grid_values), out=str(root / "table_grid.csv"))))
    return cases


def heavy_requests(count: int = 5, system: str = HEAVY_SYSTEM) -> list[Any]:
    """``count`` OptimalPolicy requests for a library system of minutes of compile, on a
    maneuver it has (a walker's touchdown), so that nothing short of the compile refuses them."""
    from biped_opt import ros

    return [ros.srvs.OptimalPolicy.Request(maneuver="touchdown", theta0=0.001 * k,
                                           system=system) for k in range(count)]


class _Peer:
    """The attacker: a node of its own with clients of the optimiser's two services and an
    action client of the coordinator's study."""

    def __init__(self) -> None:
        from biped_opt import ros

        ros.init(args=[])
        self.node = ros.Node("hostile_peer")
        group = ros.ReentrantCallbackGroup()
        self.policy = self.node.create_client(ros.srvs.OptimalPolicy, "/biped/optimal_policy",
                                              callback_group=group)
        self.point = self.node.create_client(ros.srvs.StudyPoint,
                                             f"/optimiser/study/{WORKER}", callback_group=group)
        self.study = ros.ActionClient(self.node, ros.actions.Study, "/biped/study",
                                      callback_group=group)
        self.executor = ros.MultiThreadedExecutor(num_threads=2)
        self.executor.add_node(self.node)
        threading.Thread(target=self.executor.spin, daemon=True).start()

    def wait(self, coordinator: bool) -> None:
        for ready in (self.policy.wait_for_service(60.0), self.point.wait_for_service(60.0),
                      not coordinator or self.study.wait_for_server(timeout_sec=60.0)):
            if not ready:
                raise SystemExit("request_fuzz: a node's service did not appear within 60 s")

    def send(self, case: Case) -> Any:
        """A future of the reply (a goal: of its result, or of its rejection)."""
        from biped_opt import ros

        if case.kind == "policy":
            return self.policy.call_async(case.message)
        if case.kind == "point":
            return self.point.call_async(case.message)
        outcome = ros.Future()

        def finished(done: Any) -> None:
            if done.result() is not None:  # None: canceled when the peer closes
                outcome.set_result(done.result().result)

        def accepted(sent: Any) -> None:
            handle = sent.result()
            if handle is None:
                return
            if not handle.accepted:
                outcome.set_result(None)
                return
            handle.get_result_async().add_done_callback(finished)

        self.study.send_goal_async(case.message).add_done_callback(accepted)
        return outcome

    def close(self) -> None:
        from biped_opt import ros

        self.study.destroy()
        self.executor.shutdown()
        self.node.destroy_node()
        ros.try_shutdown()


def _message(reply: Any) -> str:
    if reply is None:
        return "goal rejected"
    text = str(getattr(reply, "message", ""))
    return ("ok: " if getattr(reply, "success", False) else "") + text[:160]


def _exchange(peer: _Peer, cases: list[Case], timeout: float) -> dict[str, dict]:
    """Send ``cases`` at once and wait up to ``timeout`` for their replies: for each, whether
    it was answered, after how long and what the reply said."""
    answered_at: dict[str, float] = {}
    t0 = time.monotonic()
    futures = {}
    for case in cases:
        future = peer.send(case)
        future.add_done_callback(
            lambda _f, name=case.name: answered_at.setdefault(name, time.monotonic()))
        futures[case.name] = future
    deadline = t0 + timeout
    for future in futures.values():
        future.wait(max(0.0, deadline - time.monotonic()))
    out = {}
    for name, future in futures.items():
        done = name in answered_at and future.done()
        out[name] = {"answered": done,
                     "seconds": round(answered_at[name] - t0, 3) if done else None,
                     "reply": _message(future.result()) if done else None}
    return out


def _stop(proc: subprocess.Popen) -> str:
    """SIGINT, then SIGTERM, then SIGKILL, 10 s apart: how the node ended."""
    for sig, label in ((signal.SIGINT, "SIGINT"), (signal.SIGTERM, "SIGTERM")):
        t0 = time.monotonic()
        proc.send_signal(sig)
        try:
            status = proc.wait(10)
            return f"{label}: exit {status} after {time.monotonic() - t0:.1f} s"
        except subprocess.TimeoutExpired:
            pass
    proc.kill()
    proc.wait()
    return "SIGKILL (SIGINT and SIGTERM did not stop it within 10 s each)"


def _peak_mib(pid: int) -> float:
    """A node's peak resident memory [MiB]; NaN once it has exited (no memory left to read)."""
    try:
        return rss_kib(pid, "VmHWM") / 1024
    except RuntimeError:
        return float("nan")


def run_hostile(args: argparse.Namespace) -> dict:
    """The hostile mode (module doc): start an optimiser and a coordinator with their default
    parameters (the optimiser's worker named), send every case, count what happened."""
    from biped_opt import ros

    os.environ["ROS_DOMAIN_ID"] = str(args.domain_id)
    root = Path(tempfile.mkdtemp(prefix="hostile_")).resolve()
    cases = code_cases(root)
    bounds = bound_cases(root)
    cap = int(args.memory_cap_gb * 2**30)
    cwd = root / "cwd"
    optimiser = start_node(args.domain_id, None, parameters=(f"worker:={WORKER}",), cwd=cwd,
                           memory_cap=cap)
    coordinator = start_node(args.domain_id, None, kind="coordinator", cwd=cwd,
                             memory_cap=cap)
    peer = _Peer()
    result: dict[str, Any] = {"directory": str(root)}
    try:
        peer.wait(coordinator=True)
        # code first, then the sizes (a study point of 400^4 would hold the work item queue)
        replies = _exchange(peer, cases, args.timeout)
        replies.update(_exchange(peer, bounds, args.timeout))
        # five requests of minutes of compile each, then one that every node answers at once
        heavy = [peer.policy.call_async(r) for r in heavy_requests()]
        time.sleep(1.0)
        t0 = time.monotonic()
        valid = peer.policy.call_async(ros.srvs.OptimalPolicy.Request(**VALID))
        answered = valid.wait(args.valid_timeout)
        latency = time.monotonic() - t0 if answered else None
        valid_ok = bool(answered and valid_answer(valid.result()))
        heavy_replies = [_message(f.result()) if f.done() else None for f in heavy]
        result["peak_rss_mib"] = {"optimiser": _peak_mib(optimiser.pid),
                                  "coordinator": _peak_mib(coordinator.pid)}
    finally:
        try:
            peer.close()
        finally:
            result["stopped"] = {"optimiser": _stop(optimiser),
                                 "coordinator": _stop(coordinator)}
    executed = sorted(c.name for c in cases if c.marker is not None and c.marker.exists())
    # every goal names its table in root (absolute, or ../ from the nodes' directory root/cwd)
    written = sorted(p.name for p in root.iterdir()
                     if p.suffix == ".csv" or p.name.endswith(".study.json"))
    if not args.keep_files:
        shutil.rmtree(root)
    result.update({
        "cases": len(cases) + len(bounds), "code_executed": len(executed), "executed": executed,
        "files_written": len(written), "written": written,
        "unanswered": sorted(n for n, r in replies.items() if not r["answered"]),
        "internal_errors": sorted(n for n, r in replies.items()
                                  if r["reply"] and "internal error" in r["reply"]),
        "heavy_requests_answered": sum(r is not None for r in heavy_replies),
        "heavy_replies": sorted({r for r in heavy_replies if r is not None}),
        "valid_latency_s": None if latency is None else round(latency, 3),
        "valid_correct": valid_ok, "replies": replies,
    })
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--domain-id", type=int, default=1 + os.getpid() % 200)
    parser.add_argument("--hostile", action="store_true",
                        help="send the hostile cases instead of corrupted requests")
    parser.add_argument("--timeout", type=float, default=60.0,
                        help="hostile: seconds for the replies to the cases")
    parser.add_argument("--valid-timeout", type=float, default=60.0,
                        help="hostile: seconds for the valid request after the heavy ones")
    parser.add_argument("--memory-cap-gb", type=float, default=3.0,
                        help="hostile: the nodes' address space limit")
    parser.add_argument("--keep-files", action="store_true",
                        help="hostile: keep the directory of planted files and markers")
    args = parser.parse_args()
    if args.hostile:
        hostile = run_hostile(args)
        print(json.dumps(hostile, indent=2))
        return 1 if hostile["code_executed"] or hostile["files_written"] else 0
    result = run(args.requests, args.seed, args.domain_id)
    print(json.dumps(result, indent=2))
    ok = (result["unanswered"] == 0 and result["valid_request_after"]
          and result["node_exit_status"] == 0 and not result["traceback_in_node_stderr"])
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
