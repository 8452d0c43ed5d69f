"""A fresh Context on a unique DDS domain per test (the domain fixture is in tests/conftest.py)."""

from __future__ import annotations

import pytest


@pytest.fixture()
def context(domain_id):
    from biped_opt.ros import dds

    ctx = dds.Context()
    dds.init(context=ctx, domain_id=domain_id)
    yield ctx
    ctx.try_shutdown()


@pytest.fixture(autouse=True)
def _fresh_log_throttle():
    """Each test starts with no log line held back by an earlier test's throttling."""
    from biped_opt.ros.dds import log

    log._SITES.clear()
