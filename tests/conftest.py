"""Shared fixtures and reference values for the test suite."""

from __future__ import annotations

import fcntl
import itertools
import os
import tempfile
from pathlib import Path

import pytest

from biped_opt.model.params import BipedParams

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

_DOMAIN_COUNTER = itertools.count()
#: the 232 usable domain ids in blocks: each test run holds one block (an flock, released when
#: the process ends, even killed), so two suites running at once on a machine never share a
#: domain (one node test once saw the other run's simulator)
_BLOCKS, _BLOCK_SIZE = 8, 29


def _claim_block() -> tuple[int, int | None]:
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
        return block, fd  # the descriptor stays open: the lock lives as long as this process
    return start, None  # more than 8 runs at once: share a block, as ids were shared before


_DOMAIN_BLOCK, _DOMAIN_LOCK = _claim_block()


def unique_domain_id() -> int:
    """A DDS domain id in 1..232 that no other test run on this machine uses now (the run's
    block of 29 ids, taken in turn)."""
    return 1 + _DOMAIN_BLOCK * _BLOCK_SIZE + next(_DOMAIN_COUNTER) % _BLOCK_SIZE


@pytest.fixture()
def domain_id() -> int:
    return unique_domain_id()
