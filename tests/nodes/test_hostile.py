"""The optimiser and the coordinator as a hostile peer on the DDS domain would use them.

Every request field is hostile: a request that names a file (by path, relative, with ``../``,
with trailing spaces, through a problem file) must be refused with a reason and must not run it;
requests for large systems must not hold up a valid one; a study's size is refused before it is
built; a goal's table stays inside the coordinator's output directory; the code of a system file
the operator configured that exits, interrupts or recurses costs one refused request. Requests to
the optimiser are written as raw bytes on the request topic (rmw_cyclonedds' layout: a 16-byte
header of the client's GUID and a sequence number, then the CDR fields), as any peer could.
"""

from __future__ import annotations

import json
import os
import signal
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from biped_opt import ros
from biped_opt.nodes.compiler import BUSY
from biped_opt.nodes.coordinator import StudyCoordinator
from biped_opt.nodes.optimiser import OptimiserNode
from tests.conftest import signal_state, unique_domain_id
from tests.ros.test_robustness import send_raw

from .test_study_fanout import Host

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.skipif(ros.BACKEND != "dds", reason="raw writes of the built-in backend")

#: MODEL.md R5: V(0.05) of the biped's touchdown problem; 1e-10 is far below any change of the
#: problem and above the solver's last-bit differences between processes
R5, R5_TOL = 0.0194158739483, 1e-10


def _string(text: bytes, align: int) -> bytes:
    raw = struct.pack("<I", len(text) + 1) + text + b"\x00"
    return raw + bytes(-len(raw) % align)


def policy_body(maneuver: str, theta0: float, system: str = "", problem: str = "") -> bytes:
    """An OptimalPolicy request's CDR fields: maneuver, theta0 (aligned to 8), system, problem
    (the body starts 8-aligned after the 16-byte header)."""
    return (_string(maneuver.encode(), 8) + struct.pack("<d", theta0)
            + _string(system.encode(), 4) + _string(problem.encode(), 1))


class NodeProcess:
    """A node in a process of its own (as ``biped-opt node NAME``), its log collected."""

    def __init__(self, name: str, domain: int, *params: str, cwd: Path | None = None) -> None:
        args = [sys.executable, "-m", f"biped_opt.nodes.{name}", "--ros-args"]
        for param in params:
            args += ["-p", param]
        env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "PYTHONPATH": str(ROOT)}
        self.proc = subprocess.Popen(args, env=env, cwd=cwd, stderr=subprocess.PIPE,
                                     stdout=subprocess.DEVNULL, text=True)
        self.lines: list[str] = []
        self._ready = threading.Event()
        threading.Thread(target=self._read, daemon=True).start()
        assert self._ready.wait(240), f"{name} did not start: {self.lines[-5:]}"

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.lines.append(line.rstrip())
            if "ready:" in line:
                self._ready.set()

    def rss_kib(self) -> int:
        with open(f"/proc/{self.proc.pid}/status", encoding="ascii") as fh:
            return next(int(line.split()[1]) for line in fh if line.startswith("VmRSS:"))

    def children(self) -> list[int]:
        """Processes this node started (its compile processes)."""
        out = []
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit():
                try:
                    stat = (entry / "stat").read_text()
                except OSError:
                    continue
                if int(stat.rsplit(")", 1)[1].split()[1]) == self.proc.pid:
                    out.append(int(entry.name))
        return out

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                return self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.stuck = signal_state(self.proc.pid)  # (for the failing test's message)
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode


@pytest.fixture(scope="module")
def evil(tmp_path_factory) -> Path:
    """A directory with a system file whose top level writes a marker (``<dir>/marker``),
    problem files naming it, and the node's working directory below it."""
    root = tmp_path_factory.mktemp("evil")
    marker = root / "marker"
    (root / "evil.py").write_text(
        f"from pathlib import Path\nPath({str(marker)!r}).write_text('ran')\n"
        "from biped_opt.systems.library import rocking_bar\nSYSTEM = rocking_bar()\n")
    (root / "evil_problem.yaml").write_text(
        "system: evil.py\nmaneuver: drop\ndecisions: {u_th: [-0.5, 0.5]}\n")
    (root / "abs_problem.yaml").write_text(
        f"system: {root / 'evil.py'}\nmaneuver: drop\ndecisions: {{u_th: [-0.5, 0.5]}}\n")
    (root / "cwd").mkdir()
    return root


@pytest.fixture(scope="module")
def optimiser(evil):
    """The optimiser with its default parameters, working in ``evil/cwd``."""
    domain = unique_domain_id()
    node = NodeProcess("optimiser", domain, cwd=evil / "cwd")
    client = Host(lambda c: ros.Node("peer", context=c), domain)
    policy = client.node.create_client(ros.srvs.OptimalPolicy, "/biped/optimal_policy")
    assert policy.wait_for_service(timeout_sec=30)
    deadline = time.monotonic() + 30
    studies: list[str] = []
    while not studies and time.monotonic() < deadline:
        studies = [n for n, kinds in client.node.get_service_names_and_types()
                   if "biped_opt_interfaces/srv/StudyPoint" in kinds]
        time.sleep(0.1)
    study = client.node.create_client(ros.srvs.StudyPoint, studies[0])
    assert study.wait_for_service(timeout_sec=30)
    yield node, policy, study
    client.close()
    node.stop()


def _reply(future, timeout: float = 20.0):
    assert future is not None, "Cyclone refused the raw request"
    assert future.wait(timeout), "no reply"
    return future.result()


def _study_point(client, spec: dict, indices=(0,)):
    return _reply(client.call_async(ros.srvs.StudyPoint.Request(
        study=json.dumps(spec), indices=list(indices))))


def test_no_request_runs_a_file_it_names(optimiser, evil):
    node, policy, study = optimiser
    path = str(evil / "evil.py")
    cases = [
        {"system": path}, {"system": "../evil.py"}, {"system": "evil.py"},
        {"system": f"../../{evil.name}/evil.py"}, {"system": path + "   "},
        {"system": " evil"}, {"system": "evil"},
        {"problem": str(evil / "evil_problem.yaml")}, {"problem": "../evil_problem.yaml"},
        {"problem": str(evil / "abs_problem.yaml"), "system": "rocking_bar"},
        {"problem": "evil_problem"},
        {"system": "w" * 8192}, {"problem": "p" * 8192, "system": "rocking_bar"},
    ]
    for fields in cases:
        reply = _reply(send_raw(policy, policy_body("drop", 0.1, **fields)))
        assert not reply.success, fields
        # a reason that names the field, and no compile was started for it
        assert reply.message.split(":")[0] in ("system", "problem"), (fields, reply.message)
        assert not reply.message.startswith(BUSY), (fields, reply.message)
        assert len(reply.message) < 400 and "internal error" not in reply.message
    for system in (path, "evil", "../evil.py"):
        spec = {"system": system, "maneuver": "drop", "grid": {"gamma": [0.5]}, "num": 5}
        reply = _study_point(study, spec)
        assert not reply.success and reply.message.startswith("study: system:"), reply.message
    reply = _study_point(study, {"system": "rocking_bar", "problem": str(evil / "evil_problem"
                                                                        ".yaml"),
                                 "grid": {"gamma": [0.5]}, "num": 5})
    assert not reply.success and reply.message.startswith("study: problem:"), reply.message
    time.sleep(1.0)  # (a compile, had one been queued, would have started by now)
    assert not (evil / "marker").exists()
    assert not any("queued a compile" in line for line in node.lines)


def test_names_no_compile_can_serve_are_refused_before_the_compile_queue(optimiser):
    """A problem or maneuver a library system does not have, in a request or a work item, is
    refused at once: queued, each such name would cost a compile process and hold a place in
    the compile queue that valid systems then wait for."""
    node, policy, study = optimiser
    for number in range(6):  # (more than compile_queue = 4)
        reply = _reply(send_raw(policy, policy_body("drop", 0.1, "rocking_bar", f"no{number}")))
        assert not reply.success and reply.message.startswith(
            f"problem: rocking_bar declares no problem 'no{number}'"), reply.message
        reply = _study_point(study, {"system": "rocking_bar", "problem": f"no{number}",
                                     "grid": {"gamma": [0.5]}, "num": 5})
        assert not reply.success and reply.message.startswith(
            f"study: problem: rocking_bar declares no problem 'no{number}'"), reply.message
    reply = _reply(send_raw(policy, policy_body("hop", 0.1, "rocking_bar")))
    assert not reply.success and reply.message.startswith(
        "maneuver: rocking_bar has no maneuver 'hop'"), reply.message
    assert not any("queued a compile" in line for line in node.lines)


def test_a_huge_grid_is_refused_before_it_is_built(optimiser):
    """400^4 = 2.56e10 points: refused by counting (limit max_points), the node's memory
    unchanged (building even the list of points would take terabytes; 20 MB is noise)."""
    node, _, study = optimiser
    before = node.rss_kib()
    spec = {"system": "rocking_bar", "maneuver": "drop", "num": 5,
            "grid": {name: [0.1 * (i + 1) for i in range(400)]
                     for name in ("gamma", "k", "mb", "l0")}}
    reply = _study_point(study, spec, indices=[0])
    assert not reply.success
    assert "25600000000 parameter points" in reply.message and "max_points" in reply.message
    for key, value, what in (("num", 10**12, "max_num"), ("seed", -1, "seed"),
                             ("num", "abc", "num must be an integer"),
                             ("s_range", [0.1, -0.1], "s_range must have low < high")):
        reply = _study_point(study, {**spec, "grid": {"gamma": [0.5]}, key: value})
        assert not reply.success and what in reply.message, reply.message
    assert node.rss_kib() - before < 20_000


@pytest.mark.alone  # (5 s bounds on replies while the node's own compile takes a core)
def test_large_systems_do_not_hold_up_a_valid_request_and_sigint_stops_the_node():
    """Five requests for systems the node has not compiled (one beyond its limits, four that
    start or queue a compile of minutes) are answered at once; a biped request right after is
    answered within seconds; SIGINT then stops the node and its compile process."""
    domain = unique_domain_id()
    node = NodeProcess("optimiser", domain)
    client = Host(lambda c: ros.Node("peer", context=c), domain)
    try:
        policy = client.node.create_client(ros.srvs.OptimalPolicy, "/biped/optimal_policy")
        assert policy.wait_for_service(timeout_sec=30)
        replies = []
        for system in ("walker99", "walker6", "walker5_decoupled", "walker6_decoupled",
                       "walker5"):
            start = time.monotonic()
            replies.append(_reply(send_raw(policy, policy_body("touchdown", 0.1, system))))
            assert time.monotonic() - start < 5.0, system  # (the first loads SymPy: ~3 s)
        assert not any(r.success for r in replies)
        assert "walker99 has 99 constraints and 201 coordinates" in replies[0].message
        assert "max_legs" in replies[0].message
        assert all(r.message.startswith(BUSY) for r in replies[1:]), [r.message for r in replies]
        start = time.monotonic()
        reply = _reply(send_raw(policy, policy_body("touchdown", 0.05)))
        assert time.monotonic() - start < 5.0
        assert reply.success and abs(reply.value - R5) < R5_TOL
        time.sleep(0.5)
        compiling = node.children()
        assert compiling, "no compile process under way"
    finally:
        client.close()
        start = time.monotonic()
        status = node.stop()
    assert status == 0 and time.monotonic() - start < 10.0, getattr(node, "stuck", "")
    time.sleep(0.5)
    assert not any(Path(f"/proc/{pid}").exists() and "compiler" in
                   Path(f"/proc/{pid}/cmdline").read_text(errors="replace")
                   for pid in compiling)


def test_no_module_of_the_working_directory_runs_in_the_compile_process(tmp_path, domain_id):
    """The node started (as ``biped-opt node optimiser``) from a folder holding a ``json.py``:
    one ordinary request for the rocking bar starts a compile process, which must import the
    real json (``python -m`` would put that folder first on its path)."""
    folder = tmp_path / "downloads"
    folder.mkdir()
    marker = tmp_path / "planted_json_ran"
    (folder / "json.py").write_text(f"open({str(marker)!r}, 'w').write('ran')\n")
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [str(Path(sys.executable).with_name("biped-opt")), "node", "optimiser", "--ros-args",
         "-p", "warm_up:=false"], env=env, cwd=folder, stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL, text=True)
    lines: list[str] = []
    ready = threading.Event()

    def read() -> None:
        assert proc.stderr is not None
        for line in proc.stderr:
            lines.append(line.rstrip())
            if "ready:" in line:
                ready.set()

    threading.Thread(target=read, daemon=True).start()
    peer = Host(lambda c: ros.Node("peer", context=c), domain_id)
    try:
        assert ready.wait(240), lines[-5:]
        policy = peer.node.create_client(ros.srvs.OptimalPolicy, "/biped/optimal_policy")
        assert policy.wait_for_service(timeout_sec=30)
        reply = _when_compiled(policy, "rocking_bar")
        assert any("queued a compile of system rocking_bar" in line for line in lines), lines
        assert reply.success, reply.message
        assert not marker.exists()
    finally:
        peer.close()
        proc.send_signal(signal.SIGINT)
        proc.wait(30)


def _goal(node, study: dict | str, out: str):
    action = ros.ActionClient(node, ros.actions.Study, "/biped/study",
                              callback_group=ros.ReentrantCallbackGroup())
    try:
        assert action.wait_for_server(timeout_sec=10)
        future = action.send_goal_async(ros.actions.Study.Goal(
            study=study if isinstance(study, str) else json.dumps(study), out=out))
        assert future.wait(10)
        done = future.result().get_result_async()
        assert done.wait(30)
        return done.result().result
    finally:
        action.destroy()


def test_a_goal_chooses_no_file_and_no_code(tmp_path, evil):
    domain = unique_domain_id()
    out = tmp_path / "tables"
    host = Host(lambda c: StudyCoordinator(context=c, parameter_overrides=[
        ros.Parameter("output_dir", value=str(out))]), domain, threads=4)
    peer = Host(lambda c: ros.Node("peer", context=c), domain)
    try:
        good = {"system": "rocking_bar", "maneuver": "drop", "grid": {"gamma": [0.5]}, "num": 5}
        for name in (f"../{tmp_path.name}/escape.csv", str(tmp_path / "abs.csv"), "..", ".hidden",
                     "a/b.csv", "x" * 200):
            result = _goal(peer.node, good, name)
            assert not result.success and result.message.startswith("out: "), result.message
        assert not (tmp_path / "escape.csv").exists() and not (tmp_path / "abs.csv").exists()
        for spec in ({**good, "system": str(evil / "evil.py")}, {**good, "system": "evil"},
                     {**good, "problem": str(evil / "evil_problem.yaml")}):
            result = _goal(peer.node, spec, "t.csv")
            assert not result.success and result.message.startswith("study: "), result.message
        huge = {**good, "grid": {k: list(range(1, 401)) for k in ("gamma", "k", "mb", "l0")}}
        result = _goal(peer.node, huge, "t.csv")
        assert not result.success and "max_points" in result.message
        result = _goal(peer.node, "[" * 100_000, "t.csv")
        assert not result.success and "max_request_chars" in result.message
        # an integer of more digits than Python converts (4300): the parser's ValueError is a
        # bad goal, not an internal error
        result = _goal(peer.node, "num: " + "9" * 5000, "t.csv")
        assert not result.success and result.message == \
            "study: neither JSON nor YAML (ValueError)", result.message
        assert not (evil / "marker").exists()
        assert not out.exists()  # nothing written, not even the directory, for a refusal
    finally:
        peer.close()
        host.close()


@pytest.fixture(scope="module")
def configured(tmp_path_factory):
    """An optimiser whose operator configured a directory of system files (system_paths):
    one that builds the rocking bar, and ones whose code exits, interrupts, recurses, runs out
    of memory."""
    folder = tmp_path_factory.mktemp("systems")
    (folder / "bar_copy.py").write_text(
        "from biped_opt.systems.library import rocking_bar\nSYSTEM = rocking_bar()\n")
    (folder / "exits.py").write_text("import sys\nsys.exit(3)\n")
    (folder / "interrupts.py").write_text("raise KeyboardInterrupt\n")
    (folder / "recurses.py").write_text("def f():\n    return f()\nf()\n")
    (folder / "exhausts.py").write_text("raise MemoryError('out of memory (a stand-in)')\n")
    domain = unique_domain_id()
    host = Host(lambda c: OptimiserNode(context=c, parameter_overrides=[
        ros.Parameter("warm_up", value=False), ros.Parameter("system_paths", value=[str(folder)])]),
        domain, threads=4)
    peer = Host(lambda c: ros.Node("peer", context=c), domain)
    policy = peer.node.create_client(ros.srvs.OptimalPolicy, "/biped/optimal_policy")
    assert policy.wait_for_service(timeout_sec=30)
    yield policy
    peer.close()
    host.close()


def _when_compiled(policy, system: str, timeout: float = 240.0):
    deadline = time.monotonic() + timeout
    while True:
        reply = _reply(policy.call_async(ros.srvs.OptimalPolicy.Request(
            maneuver="drop", theta0=0.1, system=system)))
        if not reply.message.startswith(BUSY) or time.monotonic() > deadline:
            return reply
        time.sleep(0.5)


def test_system_files_of_system_paths_are_served_by_name(configured):
    reply = _when_compiled(configured, "bar_copy")
    assert reply.success and list(reply.decision_names) == ["u_th"], reply.message


def test_a_system_file_the_operator_lists_in_systems_is_compiled_before_serving(tmp_path):
    """``systems`` naming the operator's file by path compiles it at start-up (its directory
    joins system_paths): the first request by its stem is answered, not ``busy``."""
    (tmp_path / "listed_bar.py").write_text(
        "from biped_opt.systems.library import rocking_bar\nSYSTEM = rocking_bar()\n")
    domain = unique_domain_id()
    host = Host(lambda c: OptimiserNode(context=c, parameter_overrides=[
        ros.Parameter("warm_up", value=False),
        ros.Parameter("systems", value=[str(tmp_path / "listed_bar.py")])]), domain, threads=4)
    peer = Host(lambda c: ros.Node("peer", context=c), domain)
    try:
        policy = peer.node.create_client(ros.srvs.OptimalPolicy, "/biped/optimal_policy")
        assert policy.wait_for_service(timeout_sec=30)
        reply = _reply(policy.call_async(ros.srvs.OptimalPolicy.Request(
            maneuver="drop", theta0=0.1, system="listed_bar")), timeout=60)
        assert reply.success and list(reply.decision_names) == ["u_th"], reply.message
    finally:
        peer.close()
        host.close()


@pytest.mark.parametrize(("system", "reason"), [
    ("exits", "SystemExit"), ("interrupts", "KeyboardInterrupt"),
    ("recurses", "RecursionError"), ("exhausts", "MemoryError")])
def test_a_system_file_that_exits_interrupts_or_fails_costs_one_request(configured, system,
                                                                        reason):
    reply = _when_compiled(configured, system)
    assert not reply.success and reason in reply.message and len(reply.message) < 600, \
        reply.message
    again = _reply(configured.call_async(ros.srvs.OptimalPolicy.Request(
        maneuver="touchdown", theta0=0.05)))
    assert again.success and abs(again.value - R5) < R5_TOL  # the node serves on


@pytest.mark.parametrize(("node", "param", "message"), [
    ("optimiser", "systems:=[no_such_system]", "optimiser: error: systems: unknown system "
                                               "'no_such_system'"),
    ("optimiser", "system_paths:=[/no/such/dir]", "optimiser: error: system_paths: "
                                                  "/no/such/dir: no such directory"),
    ("optimiser", "compile_queue:=-1", "optimiser: error: compile_queue must be an integer"),
    ("coordinator", "in_flight:=0", "studycoordinator: error: in_flight must be an integer"),
    ("simulator", "theta0:=5.0", "simulator: error: cannot start from the parameters: theta0:"),
])
def test_a_bad_parameter_ends_the_node_with_status_2_and_one_line(domain_id, node, param,
                                                                 message):
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-m", f"biped_opt.nodes.{node}", "--ros-args", "-p",
                          param, "-p", "warm_up:=false"], env=env, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    assert out.stderr.strip().splitlines() == [out.stderr.strip()]
    assert out.stderr.startswith(message), out.stderr


def test_a_goal_whose_system_file_exits_or_recurses_is_aborted_with_the_reason(tmp_path):
    """The coordinator has a goal's system described in a compile process (to count and check
    the study): a system file of its system_paths that exits or recurses ends that goal, not
    the node, and its code never runs in the coordinator's process."""
    marker = tmp_path / "pids"
    (tmp_path / "records_pid.py").write_text(
        f"import os\nopen({str(marker)!r}, 'a').write(f'{{os.getpid()}}\\n')\n"
        "from biped_opt.systems.library import rocking_bar\nSYSTEM = rocking_bar()\n")
    (tmp_path / "exits.py").write_text("import sys\nsys.exit(3)\n")
    (tmp_path / "interrupts.py").write_text("raise KeyboardInterrupt\n")
    (tmp_path / "recurses.py").write_text("def f():\n    return f()\nf()\n")
    domain = unique_domain_id()
    host = Host(lambda c: StudyCoordinator(context=c, parameter_overrides=[
        ros.Parameter("output_dir", value=str(tmp_path / "tables")),
        ros.Parameter("system_paths", value=[str(tmp_path)])]), domain, threads=4)
    peer = Host(lambda c: ros.Node("peer", context=c), domain)
    try:
        for system, reason in (("exits", "SystemExit: 3"), ("interrupts", "KeyboardInterrupt"),
                               ("recurses", "RecursionError")):
            spec = {"system": system, "maneuver": "drop", "grid": {"gamma": [0.5]}}
            result = _goal(peer.node, spec, "t.csv")
            assert not result.success and reason in result.message, result.message
            assert str(tmp_path) not in result.message
        spec = {"system": "records_pid", "maneuver": "drop", "grid": {"gamma": [0.5]},
                "num": 5}
        result = _goal(peer.node, {**spec, "grid": {"no_such": [0.5]}}, "t.csv")
        assert not result.success and "cannot vary 'no_such'" in result.message
        pids = marker.read_text().split()
        assert pids and str(os.getpid()) not in pids  # described, but not here
    finally:
        peer.close()
        host.close()


@pytest.fixture()
def outside(tmp_path):
    """A directory of system_paths holding links to files outside it (whose code writes a
    marker), and a file that fails with its path in the message."""
    folder, away = tmp_path / "systems", tmp_path / "elsewhere"
    folder.mkdir()
    away.mkdir()
    marker = tmp_path / "outside_ran"
    (away / "evil.py").write_text(
        f"open({str(marker)!r}, 'w').write('ran')\n"
        "from biped_opt.systems.library import rocking_bar\nSYSTEM = rocking_bar()\n")
    (away / "prob.yaml").write_text("system: rocking_bar\nmaneuver: drop\n"
                                    "decisions: {u_th: [-0.5, 0.5]}\n")
    (folder / "linked.py").symlink_to(away / "evil.py")
    (folder / "linked_problem.yaml").symlink_to(away / "prob.yaml")
    (folder / "beside.yaml").write_text("system: ../elsewhere/evil.py\nmaneuver: drop\n")
    (folder / "fails.py").write_text(f"raise ValueError('cannot read {folder}/data.csv')\n")
    (folder / "inner.py").write_text(
        "from biped_opt.systems.library import rocking_bar\nSYSTEM = rocking_bar()\n")
    (folder / "inner_link.py").symlink_to(folder / "inner.py")  # (stays inside: served)
    return folder, marker


def test_links_out_of_system_paths_are_refused_and_no_reply_names_a_path(outside):
    """A file of system_paths that resolves outside its directory is refused in a request, a
    work item and a goal, and never runs (before: followed, its code ran 9 times in the
    compile process and twice in the coordinator's); a link inside the directory is served.
    No reply to the peer shows where the node's directories are."""
    folder, marker = outside
    domain = unique_domain_id()
    optimiser = Host(lambda c: OptimiserNode(context=c, parameter_overrides=[
        ros.Parameter("warm_up", value=False),
        ros.Parameter("system_paths", value=[str(folder)])]), domain, threads=4)
    coordinator = Host(lambda c: StudyCoordinator(context=c, parameter_overrides=[
        ros.Parameter("output_dir", value=str(folder.parent / "tables")),
        ros.Parameter("system_paths", value=[str(folder)])]), domain, threads=4)
    peer = Host(lambda c: ros.Node("peer", context=c), domain)
    try:
        policy = peer.node.create_client(ros.srvs.OptimalPolicy, "/biped/optimal_policy")
        assert policy.wait_for_service(timeout_sec=30)
        messages = []
        for system, problem in (("linked", ""), ("rocking_bar", "linked_problem")):
            reply = _when_compiled(policy, system) if not problem else _reply(
                policy.call_async(ros.srvs.OptimalPolicy.Request(
                    maneuver="drop", theta0=0.1, system=system, problem=problem)))
            assert not reply.success and "outside its directory" in reply.message, \
                reply.message
            messages.append(reply.message)
        reply = _when_compiled(policy, "fails")
        assert not reply.success and "cannot read data.csv" in reply.message, reply.message
        messages.append(reply.message)
        reply = _reply(policy.call_async(ros.srvs.OptimalPolicy.Request(
            maneuver="drop", theta0=0.1, system="no_such")))
        assert "nor no_such.py or no_such.urdf in the node's system_paths" in reply.message
        messages.append(reply.message)
        spec = {"system": "linked", "maneuver": "drop", "grid": {"gamma": [0.5]}, "num": 5}
        result = _goal(peer.node, spec, "t.csv")
        assert not result.success and "outside its directory" in result.message
        messages.append(result.message)
        result = _goal(peer.node, {**spec, "system": "rocking_bar", "problem": "beside"},
                       "t.csv")
        assert not result.success, result.message
        messages.append(result.message)
        result = _goal(peer.node, {**spec, "system": "rocking_bar"}, "../t.csv")
        assert not result.success and result.message.startswith("out: "), result.message
        messages.append(result.message)
        reply = _when_compiled(policy, "inner_link")
        assert reply.success, reply.message
        assert not marker.exists()
        for message in messages:
            assert str(folder) not in message and str(folder.parent) not in message, message
    finally:
        peer.close()
        coordinator.close()
        optimiser.close()
