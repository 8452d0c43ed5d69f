"""``biped-opt``: entry point and sub-command registry.

Each sub-command lives in its own module exposing ``register(subparsers)``; the module adds its
parser and sets ``func(args) -> int``. The library raises :class:`~biped_opt.errors.BipedOptError`;
this layer turns it into a one-line message on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import functools
import gc
import importlib
import os
import re
import sys
from collections.abc import Sequence
from typing import Any

from biped_opt.errors import BipedOptError

#: modules under biped_opt.cli that provide sub-commands, in help order
COMMAND_MODULES = (
    "simulate_cmd",
    "systems_cmd",
    "demo_cmd",
    "bench_cmd",
    "optimise_cmd",
    "sweep_cmd",
    "nonsmooth_cmd",
    "gradients_cmd",
    "figures_cmd",
    "study_cmd",
    "node_cmd",
    "record_cmd",
    "replay_cmd",
    "report_cmd",
    "info_cmd",
    "pieces_cmd",
    "animate_cmd",
)

EXIT_USAGE = 2


#: a negative number in any form Python's float() reads, so that ``--theta0 -1e-6`` is a value:
#: argparse's own pattern (-1, -.5) misses exponents and treats -1e-6 as an unknown option
NEGATIVE_NUMBER = re.compile(
    r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$", re.IGNORECASE)


class _Parser(argparse.ArgumentParser):
    """argparse that reports bad arguments in one line (no usage dump) with exit status 2 and
    reads every negative number as a value."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


@functools.cache
def build_parser() -> argparse.ArgumentParser:
    """The parser of every sub-command, built once per process (~70 ms: a program that calls
    :func:`main` many times, a test among them, pays it once); parsing leaves it unchanged."""
    parser = _Parser(
        prog="biped-opt",
        description="Nonsmooth optimal control of a biped subject to unilateral constraints.",
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name in COMMAND_MODULES:
        importlib.import_module(f"biped_opt.cli.{name}").register(sub)
    return parser


def say_background(since: int) -> None:
    """One line on stderr naming the builds this command started in the background (the
    ``since``-th and later of the process) that still run (the second compile process of a
    new system, an ahead-of-time kernel): they go on at a lower priority, fill the on-disk
    cache for later commands and end by themselves (:mod:`biped_opt.children`)."""
    from biped_opt.children import BACKGROUND_LIMIT_S, running_in_background

    running = running_in_background(since)
    if running:
        print(f"note: {len(running)} background build{'s' if len(running) > 1 else ''} for "
              f"later runs still going at low priority, ending within "
              f"{BACKGROUND_LIMIT_S / 60:g} min: {'; '.join(running)}", file=sys.stderr,
              flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except KeyboardInterrupt:  # (Ctrl-C during the imports: interrupted all the same)
        print("biped-opt: interrupted", file=sys.stderr)
        return 130
    from biped_opt.children import background_mark

    mark = background_mark()
    try:
        status = int(args.func(args) or 0)
        sys.stdout.flush()
        say_background(mark)
        return status
    except BipedOptError as exc:
        print(f"biped-opt {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"biped-opt {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader went away (``biped-opt simulate ... | head``): what it wanted it has, as
        # with any Unix filter; stdout is pointed at /dev/null so the exit flush stays silent
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return 0
    except OSError as exc:  # (a disk that fills up, a file removed under the command)
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"biped-opt {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE
    except MemoryError:
        print(f"biped-opt {args.command}: error: not enough memory for this command",
              file=sys.stderr)
        return EXIT_USAGE


#: the cyclic collector's youngest-generation threshold in the ``biped-opt`` process (Python's
#: default is 700): see :func:`entry`
YOUNG_THRESHOLD = 10_000


def entry() -> int:
    """The ``biped-opt`` program: :func:`main` in a process that then ends, with the cyclic
    collector set for that (the two settings save 0.05 s of a cached ``simulate``'s 0.2 s and
    0.3 s of a ``report``'s 1.5 s).

    - A command makes most of its objects importing NumPy, SciPy and matplotlib, and keeps
      them. Collecting the youngest generation every 700 new objects, as Python does by default,
      walks them again and again; every :data:`YOUNG_THRESHOLD` (a few megabytes of young
      objects at most) it does so a fourteenth as often. What a long command leaves as cyclic
      garbage is collected as before, a little later.
    - When :func:`main` returns, what is still alive is frozen out of the collector: the
      interpreter's last collections would walk all of it only for the system to reclaim the
      memory. Exit handlers and the flushing and closing of files run as before; garbage in
      reference cycles keeps its finalizers unrun, and the package closes what it writes
      explicitly.

    Not for a caller that goes on afterwards (a test, a script): it calls :func:`main`."""
    gc.set_threshold(YOUNG_THRESHOLD, *gc.get_threshold()[1:])
    try:
        return main()
    finally:
        gc.freeze()


if __name__ == "__main__":
    sys.exit(entry())
