"""Shared fixtures and reference values for the test suite."""

from __future__ import annotations

import itertools
import os
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


def unique_domain_id() -> int:
    """A DDS domain id in 1..232 unlikely to collide with other test processes on the machine."""
    return 1 + (os.getpid() * 37 + next(_DOMAIN_COUNTER) * 11) % 232


@pytest.fixture()
def domain_id() -> int:
    return unique_domain_id()
