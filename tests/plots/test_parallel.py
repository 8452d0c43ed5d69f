"""Drawing in forked processes (:func:`biped_opt.plots.parallel.draw_all`): the same results in
the same order as one after the other, a child's exception raised here as it was raised there,
a killed child's share drawn again here, and no fork beside another thread. Each case runs in a
fresh interpreter, the only thread of its process as on the command line (a test runner's
worker may run threads of its own, and then draw_all rightly does not fork)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

PROBE = """\
import json, os, signal, sys, threading, time
from biped_opt.plots.parallel import draw_all

mode, parent = sys.argv[1], os.getpid()
if mode == "thread":
    threading.Thread(target=time.sleep, args=(5,), daemon=True).start()

def job(i):
    def run():
        here = os.getpid() != parent
        if mode == "kill" and i == 1 and here:
            os.kill(os.getpid(), signal.SIGKILL)
        if mode == "raise" and i == 4:
            raise ValueError(f"job {i} refused in a {'child' if here else 'parent'}")
        return [i, i * i, here]
    return run

try:
    print(json.dumps(draw_all([job(i) for i in range(6)], processes=3)))
except ValueError as exc:
    print(json.dumps({"raised": str(exc)}))
"""


def _probe(mode: str):
    proc = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def test_jobs_run_in_three_processes_and_come_back_in_order():
    results = _probe("plain")
    assert [r[:2] for r in results] == [[i, i * i] for i in range(6)]
    # jobs 0 and 3 here, 1 and 4 in one child, 2 and 5 in another
    assert [r[2] for r in results] == [False, True, True, False, True, True]


def test_a_childs_exception_is_raised_here_as_it_was_raised():
    assert _probe("raise") == {"raised": "job 4 refused in a child"}


def test_a_killed_childs_share_is_drawn_again_here():
    results = _probe("kill")
    assert [r[:2] for r in results] == [[i, i * i] for i in range(6)]
    # the killed child's share (1 and 4) was drawn here; the other child's (2 and 5) there
    assert [r[2] for r in results] == [False, False, True, False, False, True]


def test_no_fork_beside_another_thread():
    assert [r[2] for r in _probe("thread")] == [False] * 6


@pytest.mark.parametrize("processes", [0, 1])
def test_one_process_or_fewer_draws_here(processes):
    from biped_opt.plots.parallel import draw_all

    assert draw_all([lambda: 1, lambda: 2], processes=processes) == [1, 2]
