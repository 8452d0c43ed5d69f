"""Shared fixtures: a fresh Context on a unique DDS domain per test, loopback only."""

from __future__ import annotations

import itertools
import os

import pytest

# Loopback-only discovery keeps the tests off the network; set before any participant exists
# so subprocesses inherit it too.
os.environ["ROS_LOCALHOST_ONLY"] = "1"
os.environ.pop("CYCLONEDDS_URI", None)

_COUNTER = itertools.count()


def unique_domain_id() -> int:
    """A domain id in 1..232 unlikely to collide with other test processes on the machine."""
    return 1 + (os.getpid() * 37 + next(_COUNTER) * 11) % 232


@pytest.fixture()
def domain_id() -> int:
    return unique_domain_id()


@pytest.fixture()
def context(domain_id):
    from biped_opt.ros import dds

    ctx = dds.Context()
    dds.init(context=ctx, domain_id=domain_id)
    yield ctx
    ctx.try_shutdown()
