"""Backend choice of biped_opt.ros and the rclpy path (skipped only when rclpy is absent)."""

from __future__ import annotations

import importlib
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _import_with(backend: str) -> subprocess.CompletedProcess:
    code = ("from biped_opt import ros; print(ros.BACKEND, ros.msgs.BipedState.__name__, "
            "ros.srvs.OptimalPolicy.Request.__name__, ros.msgs.ContactMode.GROUND)")
    env = dict(os.environ, BIPED_OPT_BACKEND=backend, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, timeout=60)


def test_dds_backend_exposes_types():
    out = _import_with("dds")
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["dds", "BipedState", "OptimalPolicy_Request", "3"]


def test_bad_backend_name():
    out = _import_with("zenoh")
    assert out.returncode != 0 and "BIPED_OPT_BACKEND" in out.stderr


@pytest.mark.skipif(importlib.util.find_spec("rclpy") is not None, reason="rclpy is installed")
def test_rclpy_backend_requested_but_absent():
    out = _import_with("rclpy")
    assert out.returncode != 0 and "BIPED_OPT_BACKEND=rclpy" in out.stderr


def test_core_never_imports_ros():
    code = ("import sys, biped_opt, biped_opt.paper.biped, biped_opt.paper.sweeps; "
            "print(any(m.startswith(('biped_opt.ros', 'rclpy', 'cyclonedds')) "
            "for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert out.stdout.strip() == "False", out.stderr


def _have_rclpy() -> bool:
    try:
        importlib.import_module("rclpy")
        importlib.import_module("biped_opt_interfaces.srv")
    except ImportError:
        return False
    return True


@pytest.mark.skipif(not _have_rclpy(), reason="rclpy / built biped_opt_interfaces not importable")
def test_rclpy_service_round_trip(domain_id):
    """The same node code on real rclpy: the echo node served and called in one process."""
    env = dict(os.environ, BIPED_OPT_BACKEND="rclpy", PYTHONPATH=str(ROOT),
               ROS_DOMAIN_ID=str(domain_id))
    code = """
from biped_opt import ros
from tests.ros._echo_node import EchoNode
ctx = ros.Context(); ros.init(context=ctx)
node = EchoNode(context=ctx)
client = node.create_client(ros.srvs.OptimalPolicy, '/echo/optimal_policy')
assert client.wait_for_service(timeout_sec=10.0)
ex = ros.SingleThreadedExecutor(context=ctx); ex.add_node(node)
future = client.call_async(ros.srvs.OptimalPolicy.Request(maneuver='m', theta0=0.5))
ex.spin_until_future_complete(future, timeout_sec=10.0)
print(ros.BACKEND, future.result().value, list(future.result().mode_sequence))
node.destroy_node(); ros.try_shutdown(context=ctx)
"""
    out = subprocess.run([sys.executable, "-c", code], env=env, cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[:2] == ["rclpy", "1.0"]
