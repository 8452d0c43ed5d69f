"""README's tour runs as written: every ``$ biped-opt ...`` line of its ``console`` blocks is run
in-process, in a directory of its own (the lines of one block in order, as a reader types them),
and prints what README shows under it.

An output line matches when its words are the same and its numbers agree within a tolerance:
1e-9 (MODEL.md Sec. 7: a correct implementation reproduces outcomes and event times to 1e-9;
README shows them to 12-15 digits) for the simulator's and the analysis' numbers, 1e-8 for
``optimise`` (the policy is where L-BFGS-B stops, at a projected gradient of 1e-11 with the
cost's curvature near 1: another platform's last bits move it by about 1e-10). The one line a
test cannot run as is, a replay looping in the background beside a bridge that serves until
stopped, is checked by its parts (the recording and the report exist) and by tests/ros.
"""

from __future__ import annotations

import contextlib
import io
import math
import re
import shlex
from pathlib import Path

import pytest

from biped_opt.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
_CONSOLE = re.compile(r"```console\n(.*?)```", re.S)
_NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")
#: what a long-running command line of the tour needs to be told apart: it runs in the background
_BACKGROUND = " & "


def blocks() -> list[list[tuple[str, list[str]]]]:
    """Each console block of README as (command line, the output lines README shows)."""
    out = []
    for m in _CONSOLE.finditer((ROOT / "README.md").read_text()):
        runs: list[tuple[str, list[str]]] = []
        for line in m[1].splitlines():
            if line.startswith("$ "):
                runs.append((line[2:], []))
            elif runs and line.strip():
                runs[-1][1].append(line)
        out.append(runs)
    return out


def _same(shown: str, printed: str, tol: float) -> bool:
    a, b = shown.split(), printed.split()
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):
        if x == y:
            continue
        # numbers inside a word (th(t_f) = +0.07..., LEFT@0.977...) compare by value
        xs, ys = re.split(r"([@=(),|])", x), re.split(r"([@=(),|])", y)
        if len(xs) != len(ys):
            return False
        for p, q in zip(xs, ys):
            if p == q:
                continue
            if not (_NUMBER.match(p) and _NUMBER.match(q)):
                return False
            if not math.isclose(float(p), float(q), rel_tol=tol, abs_tol=tol):
                return False
    return True


def _run(argv: list[str]) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        try:
            status = main(argv)
        except SystemExit as exc:  # argparse's --help and errors
            status = int(exc.code or 0)
    return status, out.getvalue()


def test_the_tour_has_its_steps():
    """The tour shows a simulation, both kinds of nonsmoothness, an optimal policy and a
    recording (if a block went missing, the test below would pass on less)."""
    commands = [cmd for block in blocks() for cmd, _ in block]
    for word in ("simulate", "nonsmooth --maneuver touchdown", "nonsmooth --maneuver liftoff",
                 "optimise", "record", "report", "node foxglove"):
        assert any(word in cmd for cmd in commands), word


@pytest.mark.parametrize("index", range(len(blocks())))
def test_console_block(index, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for command, shown in blocks()[index]:
        if _BACKGROUND in command:
            # replay --loop & node foxglove: services that run until stopped
            recording = shlex.split(command.split(_BACKGROUND)[0])[2]
            assert (tmp_path / recording).is_file(), command
            continue
        argv = shlex.split(command)
        assert argv[0] == "biped-opt", command
        status, printed = _run(argv[1:])
        assert status == 0, (command, printed)
        tol = 1e-8 if argv[1] == "optimise" else 1e-9
        lines = printed.splitlines()
        for want in shown:
            assert any(_same(want, got, tol) for got in lines), (command, want, printed)
        if argv[1] == "report":
            assert (tmp_path / argv[argv.index("--out") + 1] / "report.html").is_file()
