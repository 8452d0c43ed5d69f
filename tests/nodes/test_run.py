"""What every node does around its work: the warm-up message, the ready line, the exit status
of a bad parameter."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from biped_opt import ros
from biped_opt.nodes import run


def test_kernels_cached_reads_the_on_disk_cache(tmp_path):
    """In a fresh interpreter whose Numba cache directory is empty nothing is cached (the check
    the first-compile message rests on; the next test checks the cached case)."""
    code = "from biped_opt.paper.biped import kernels_cached\nprint(kernels_cached())\n"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=60)
    assert out.stdout.strip() == "False", out.stderr


def test_kernels_cached_in_this_checkout():
    """The test session has compiled (or loaded) the kernels: they are in the cache."""
    from biped_opt.paper.biped import kernels_cached, warm_up

    warm_up()
    assert kernels_cached()


def test_first_compile_is_announced_with_its_duration(monkeypatch, context_node, capfd):
    monkeypatch.setattr(run, "kernels_cached", lambda: False)
    monkeypatch.setattr(run, "warm_up", lambda: 41.5)
    run.warm_up_kernels(context_node)
    err = capfd.readouterr().err.splitlines()
    assert len(err) == 2
    assert err[0].endswith("compiling the simulator's kernels (first start in this checkout): "
                           "about 30-60 s on 2 cores; later starts load them in about a second")
    assert err[1].endswith("compiled the simulator's kernels in 41.5 s (cached for later runs)")


def test_a_cached_start_says_nothing(monkeypatch, context_node, capfd):
    monkeypatch.setattr(run, "kernels_cached", lambda: True)
    monkeypatch.setattr(run, "warm_up", lambda: 0.4)
    run.warm_up_kernels(context_node)
    assert capfd.readouterr().err == ""


def test_ready_line(context_node, capfd):
    run.announce_ready(context_node, serves=("/a",), calls=("/b", "/c"), publishes=("/d",))
    assert capfd.readouterr().err.strip().endswith(
        "[runner]: ready: serving /a; calling /b, /c; publishing /d")


@pytest.mark.parametrize(("node", "param", "message"), [
    ("optimiser", "cache_size:=-1", "optimiser: error: cache_size must be >= 0"),
    ("simulator", "theta0:=abc", "simulator: error: Trying to set parameter 'theta0' to 'abc' "
                                 "of type 'STRING', expecting type 'DOUBLE'"),
    ("simulator", "noequals", "simulator: error: --ros-args: couldn't parse parameter override "
                              "rule -p 'noequals' (expected name:=value)"),
    ("simulator", "inputs:=[1.0, 2.0", "simulator: error: Trying to set parameter 'inputs'"),
    ("simulator", "inputs:=[1.0, 'a']", "simulator: error: --ros-args: -p \"inputs:=[1.0, 'a']\": "
                                        "an array parameter holds values of one type"),
    ("recorder", "num:=1.5", "recorder: error: Trying to set parameter 'num' to 1.5 of type "
                             "'DOUBLE', expecting type 'INTEGER'"),
])
def test_a_bad_parameter_ends_the_node_with_status_2_and_one_line(domain_id, node, param,
                                                                 message):
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    out = subprocess.run([sys.executable, "-m", f"biped_opt.nodes.{node}", "--ros-args", "-p",
                          param, "-p", "warm_up:=false"], env=env, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == [out.stderr.strip()]
    assert out.stderr.startswith(message), out.stderr


@pytest.fixture()
def context_node(domain_id):
    ctx = ros.Context()
    ros.init(args=[], context=ctx, domain_id=domain_id)
    node = ros.Node("runner", context=ctx)
    yield node
    node.destroy_node()
    ros.try_shutdown(context=ctx)
