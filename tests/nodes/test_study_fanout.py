"""A study fanned out over optimiser nodes on real DDS (each node a participant of its own, as on
another host): the table equals a local run's, nodes that join, vanish or hang mid-study."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from biped_opt import ros
from biped_opt.nodes.coordinator import StudyCoordinator, StudyFailedError
from biped_opt.nodes.optimiser import OptimiserNode
from biped_opt.record.study_table import read_table, run_study
from biped_opt.studies.study import Study
from tests.conftest import unique_domain_id

#: 16 points of the rocking bar's drop at fixed inputs, ~0.1 s each
SPEC = {"system": "rocking_bar", "maneuver": "drop",
        "grid": {"gamma": [0.3 + 0.03 * i for i in range(16)]}, "num": 21}


class Host:
    """A node on a participant and executor of its own (what another machine would run)."""

    def __init__(self, make, domain: int, threads: int = 2) -> None:
        self.context = ros.Context()
        ros.init(args=[], context=self.context, domain_id=domain)
        self.node = make(self.context)
        self.executor = ros.MultiThreadedExecutor(num_threads=threads, context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def close(self) -> None:
        if not self.context.ok():
            return
        self.executor.shutdown(timeout_sec=10)
        self.thread.join(10)
        self.node.destroy_node()
        ros.try_shutdown(context=self.context)


def optimiser(domain: int, name: str, **params) -> Host:
    """An optimiser that has prepared the study's system before it serves (else its first
    items are answered busy while it compiles)."""
    params = {"warm_up": False, "worker": name, "systems": [SPEC["system"]], **params}
    return Host(lambda c: OptimiserNode(
        context=c, namespace=name, parameter_overrides=[
            ros.Parameter(k, value=v) for k, v in params.items()]), domain)


def coordinator(domain: int, **params) -> Host:
    return Host(lambda c: StudyCoordinator(context=c, parameter_overrides=[
        ros.Parameter(k, value=v) for k, v in params.items()]), domain, threads=4)


def local_rows(spec: dict, directory: Path) -> list[dict[str, str]]:
    """The table of ``spec`` computed in this process (what the nodes must reproduce)."""
    run_study(Study.from_spec(spec), directory / "local.csv")
    return read_table(directory / "local.csv")


@pytest.fixture(scope="module")
def local_table(tmp_path_factory) -> list[dict[str, str]]:
    return local_rows(SPEC, tmp_path_factory.mktemp("local"))


@pytest.fixture()
def hosts():
    made: list[Host] = []
    yield made
    for host in reversed(made):
        host.close()


def _by_point(rows: list[dict[str, str]]) -> dict[str, list[dict[str, str]]]:
    out: dict[str, list[dict[str, str]]] = {}
    for r in rows:
        out.setdefault(r["point"], []).append(r)
    return out


def assert_same_table(path: Path, local: list[dict[str, str]]) -> None:
    """Every point exactly once, with the local run's rows: the nodes run the same core on the
    same inputs, and the CSV holds Python's repr of each float, so the text is equal."""
    rows = path.read_text().splitlines()[1:]
    assert len(rows) == len(local)  # nothing torn, nothing twice
    assert _by_point(read_table(path)) == _by_point(local)


def test_two_nodes_share_the_study_and_write_the_local_table(tmp_path, hosts, local_table):
    domain = unique_domain_id()
    hosts += [optimiser(domain, "h1"), optimiser(domain, "h2"), coordinator(domain)]
    coord = hosts[-1].node
    deadline = time.monotonic() + 10
    while len(coord.workers()) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert coord.workers() == ["/h1/optimiser/study/h1", "/h2/optimiser/study/h2"]
    seen: list[tuple[int, int, int]] = []
    summary = coord.run_study(Study.from_spec(SPEC), tmp_path / "t.csv",
                              progress=lambda *a: seen.append(a))
    assert summary.computed == 16 and not summary.stopped
    assert [d for d, _, _ in seen] == list(range(1, 17)) and {t for _, t, _ in seen} == {16}
    assert_same_table(tmp_path / "t.csv", local_table)
    # both kept busy: each did a fair share (one node alone would do all 16)
    assert all(len(coord.served[n]) >= 4 for n in coord.workers())
    assert set(coord.dispatches.values()) == {1}  # nothing lost, nothing re-sent


def test_a_node_vanishing_mid_study_loses_nothing_and_one_joining_gets_work(
        tmp_path, hosts, local_table):
    domain = unique_domain_id()
    first = optimiser(domain, "h1")
    hosts += [first, coordinator(domain, discovery_period=0.2)]
    coord = hosts[-1].node

    def progress(done: int, total: int, index: int) -> None:
        if done == 3:  # the second node joins...
            hosts.append(optimiser(domain, "h2"))
        if done == 9:  # ...and the first vanishes (its participant deleted, items in hand:
            first.close()  # a request it had not taken is never answered)

    summary = coord.run_study(Study.from_spec(SPEC), tmp_path / "t.csv", progress=progress)
    assert summary.computed == 16
    assert_same_table(tmp_path / "t.csv", local_table)
    late = coord.served.get("/h2/optimiser/study/h2", [])
    assert len(late) >= 3 and min(late) >= 3  # it joined after three points were done


class Hanging(ros.Node):
    """A work-item service that takes requests and never answers (a frozen host)."""

    def __init__(self, context) -> None:
        super().__init__("hanging", context=context)
        self.release = threading.Event()
        self.taken: list[int] = []
        self.create_service(ros.srvs.StudyPoint, "~/study/frozen", self._on_request,
                            callback_group=ros.ReentrantCallbackGroup())

    def _on_request(self, request, response):
        self.taken.extend(int(i) for i in request.indices)
        self.release.wait(30)
        response.success, response.message = False, "too late"
        return response


def test_items_of_a_node_that_does_not_answer_go_to_another(tmp_path, hosts, local_table):
    domain = unique_domain_id()
    frozen = Host(Hanging, domain, threads=4)
    hosts += [frozen, coordinator(domain, item_timeout=1.5, discovery_period=0.2)]
    coord = hosts[-1].node
    deadline = time.monotonic() + 10
    while not coord.workers() and time.monotonic() < deadline:
        time.sleep(0.05)
    joined = threading.Timer(0.5, lambda: hosts.append(optimiser(domain, "h1")))
    joined.start()
    try:
        summary = coord.run_study(Study.from_spec(SPEC), tmp_path / "t.csv")
    finally:
        frozen.node.release.set()
    assert summary.computed == 16
    assert_same_table(tmp_path / "t.csv", local_table)
    assert frozen.node.taken and set(coord.served) == {"/h1/optimiser/study/h1"}
    assert all(coord.dispatches[i] == 2 for i in frozen.node.taken)  # each re-sent once


def test_a_refused_item_ends_the_study_with_the_node_message(tmp_path, hosts):
    domain = unique_domain_id()
    hosts += [optimiser(domain, "h1"), coordinator(domain)]
    coord = hosts[-1].node
    # a study the coordinator accepts but the node cannot read: another msg_defs version
    study = Study.from_spec(SPEC)
    coord_spec = study.as_dict

    class Future(Study):
        def as_dict(self):
            return {**coord_spec(), "colour": "blue"}

    odd = Future(**{f: getattr(study, f) for f in study.__dataclass_fields__})
    with pytest.raises(StudyFailedError, match="failed on /h1/optimiser/study/h1: .*'colour'"):
        coord.run_study(odd, tmp_path / "t.csv")


@pytest.mark.parametrize(("args", "message"), [
    (["--ros", "--workers", "2"], "--workers: not with --ros"),
    (["--item-timeout", "5"], "--item-timeout: only with --ros"),
])
def test_cli_ros_options_are_checked(tmp_path, capsys, args, message):
    from tests.cli.test_systems_cmd import _run

    spec = tmp_path / "s.yaml"
    spec.write_text("system: rocking_bar\nmaneuver: drop\ngrid: {gamma: [0.5]}\n")
    status, _, err = _run(["study", str(spec), "--out", str(tmp_path / "t.csv"), *args], capsys)
    assert status == 2 and message in err and "Traceback" not in err
