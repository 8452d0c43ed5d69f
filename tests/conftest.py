"""Shared fixtures and reference values for the test suite."""

from __future__ import annotations

import fcntl
import itertools
import os
import tempfile
import threading
from pathlib import Path

import pytest

from biped_opt.paper.biped import BipedParams

#: MODEL.md Sec. 7: outcomes th(t_f) at default parameters (12 significant digits)
REFERENCE = {
    "R1": ("touchdown", +0.1, (2.0, 0.5, 0.0), 0.0703759886205),
    "R2": ("touchdown", -0.2, (2.0, 0.5, 0.0), -0.152911689618),
    "R3": ("liftoff", -1e-6, (1.5, 3.0, 0.0), 0.0262836775109),
    "R4": ("liftoff", +1e-6, (1.5, 3.0, 0.0), -0.00653232497802),
}


@pytest.fixture
def params() -> BipedParams:
    return BipedParams()


# ROS tests: loopback-only discovery keeps them off the network; set before any DDS participant
# exists so subprocesses inherit it too.
os.environ["ROS_LOCALHOST_ONLY"] = "1"
os.environ.pop("CYCLONEDDS_URI", None)

# compiled system modules go to the checkout's own cache (a fresh clone compiles them afresh)
os.environ.setdefault("BIPED_OPT_CACHE", str(Path(__file__).resolve().parents[1] / ".cache"))
# no ahead-of-time kernels (biped_opt.codegen.aot) in the background of every compile and cached
# start: each costs seconds of a core; tests/codegen/test_aot.py builds and checks them
os.environ.setdefault("BIPED_OPT_AOT", "0")

_DOMAIN_COUNTER = itertools.count()
#: the 232 usable domain ids in blocks: each test process holds one block (an flock, released
#: when the process ends, even killed), so two suites running at once on a machine, or two
#: workers of one parallel run (pytest -n), never share a domain (one node test once saw the
#: other run's simulator)
_BLOCKS, _BLOCK_SIZE = 8, 29
_DOMAIN_BLOCK: list[int] = []  # (claimed on first use: a parallel run's controller uses none)
_DOMAIN_LOCK = threading.Lock()


def _claim_block() -> int:
    start = os.getpid() % _BLOCKS
    for k in range(_BLOCKS):
        block = (start + k) % _BLOCKS
        path = Path(tempfile.gettempdir()) / f"biped_opt_test_domains_{block}.lock"
        fd = os.open(path, os.O_CREAT | os.O_RDWR, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        return block  # the descriptor stays open: the lock lives as long as this process
    return start  # more than 8 processes at once: share a block, as ids were shared before


def unique_domain_id() -> int:
    """A DDS domain id in 1..232 that no other test process on this machine uses now (the
    process's block of 29 ids, taken in turn)."""
    with _DOMAIN_LOCK:
        if not _DOMAIN_BLOCK:
            _DOMAIN_BLOCK.append(_claim_block())
    return 1 + _DOMAIN_BLOCK[0] * _BLOCK_SIZE + next(_DOMAIN_COUNTER) % _BLOCK_SIZE


@pytest.fixture()
def domain_id() -> int:
    return unique_domain_id()


# Parallel runs (``pytest -n 2``, as ``make test`` does): every test holds its run's lock
# shared, and a test marked ``alone`` holds it exclusively, so that it starts once the other
# workers' tests have ended and no other test starts before it has (its timing bounds assume a
# core to itself). One file per run (its id, which every worker of the run is given).
_RUN_LOCK: list[tuple[int, Path]] = []


def pytest_configure(config: pytest.Config) -> None:
    run = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    if run and os.environ.get("PYTEST_XDIST_WORKER"):
        path = Path(tempfile.gettempdir()) / f"biped_opt_test_run_{run}.lock"
        _RUN_LOCK.append((os.open(path, os.O_CREAT | os.O_RDWR, 0o600), path))


def pytest_unconfigure(config: pytest.Config) -> None:
    if _RUN_LOCK:
        fd, path = _RUN_LOCK.pop()
        os.close(fd)
        path.unlink(missing_ok=True)  # (a worker still running keeps its descriptor)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    if not _RUN_LOCK:
        return (yield)
    fd = _RUN_LOCK[0][0]
    fcntl.flock(fd, fcntl.LOCK_EX if item.get_closest_marker("alone") else fcntl.LOCK_SH)
    try:
        return (yield)
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """With ``--dist loadgroup``: a test that uses a fixture set up once per module or class
    (a compiled system, a running graph) goes to the worker that runs the module's other such
    tests, which then sets it up once; other tests go wherever a worker is free."""
    for item in items:
        info = getattr(item, "_fixtureinfo", None)
        defs = info.name2fixturedefs.values() if info is not None else ()
        if any(d[-1].scope in ("module", "class") for d in defs if d):
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::")[0]))


def signal_state(pid: int) -> str:
    """What a stuck process shows of its signals and threads, for a failure's message: the
    state, blocked/ignored/caught masks of ``pid`` and of this test process (signals ignored or
    blocked here would be inherited by the processes a test starts)."""
    out = []
    for who, path in ((f"process {pid}", f"/proc/{pid}/status"), ("test process",
                                                               "/proc/self/status")):
        try:
            lines = Path(path).read_text().splitlines()
        except OSError as exc:
            out.append(f"{who}: {exc.strerror}")
            continue
        keep = [ln for ln in lines if ln.split(":")[0] in
                ("State", "Threads", "SigBlk", "SigIgn", "SigCgt")]
        out.append(f"{who}: " + "; ".join(" ".join(ln.split()) for ln in keep))
    return " | ".join(out)
