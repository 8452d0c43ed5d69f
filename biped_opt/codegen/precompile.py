"""A second process that compiles a freshly generated module's functions, in parallel.

A new system compiles only its own functions: the kernel that calls them is shared by every
system (:mod:`biped_opt.codegen.kernel`, compiled once per installation). The first process
needs the vector field and the step first (:func:`step_first`: half of the work for a large
system) and then the others, in the table's order (``function_addresses``,
biped_opt.codegen.abi). :func:`start` hands those that do not call the vector field (the impact
map, the guards, the initial states...: ``FIELD_FREE``) to a second interpreter as soon as the
module is written; it compiles them in the opposite order into Numba's on-disk cache, so that
the first process, after the step, finds them there (a C-callable function is looked up in the
cache each time it is made).

It only ever saves time: if the second process is late or fails, the first compiles what it
does not find, as without it. ``BIPED_OPT_PRECOMPILE=0`` turns it off. After the functions it
builds the kernel ahead of time for later starts (:mod:`biped_opt.codegen.aot`).

Run as ``python -m biped_opt.codegen.precompile PATH MODULE_NAME [WAIT_S]`` (WAIT_S: how long
to wait for the first process, :data:`WAIT_S` by default).
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

from biped_opt import children
from biped_opt.codegen import abi, aot
from biped_opt.codegen.aot import load_module

__all__ = ["FIRST", "cached", "step_first", "start", "main"]

#: what the first process compiles before anything else
FIRST = "step"


def enabled() -> bool:
    return os.environ.get("BIPED_OPT_PRECOMPILE", "1") != "0"


def step_first(module: ModuleType) -> None:
    """Compile the new module's step now, in this process (the second process compiles the
    other functions meanwhile)."""
    if enabled():
        module.compile_functions([FIRST])


def start(path: Path, module_name: str) -> subprocess.Popen | None:
    """Start the second process for the module at ``path`` (imported as ``module_name``), or
    None when turned off. It runs detached: nothing waits for it."""
    if not enabled():
        return None
    try:  # (niced, limited in time, -P and a directory of its own: biped_opt.children)
        return children.popen(
            "biped_opt.codegen.precompile", str(path), module_name,
            background=f"the compile of {Path(path).stem}", stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    except OSError:
        return None  # (no process to spare: the first one compiles everything itself)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    path, module_name = args[:2]
    held: list[Path] = []  # (the build lock, while this process holds it)

    def release() -> None:
        for lock in held:
            lock.unlink(missing_ok=True)

    children.limit_background(release)
    wait = float(args[2]) if len(args) > 2 else WAIT_S
    module = load_module(Path(path), module_name)
    # what does not call the vector field, in the opposite of the first process's order; then,
    # once the first process has the field in the cache (it compiles it for the step; compiling
    # it here too would only slow that process down on a shared core), the rest but the step
    for name in reversed([n for n in abi.FUNCTIONS if n in module.FIELD_FREE]):
        module.compile_functions([name])
    if _wait(lambda: cached(module._field_at, unknown=True), timeout=wait):
        for name in reversed([n for n in abi.FUNCTIONS
                              if n not in module.FIELD_FREE and n != FIRST]):
            module.compile_functions([name])
    if not aot.enabled():
        return 0
    # then, once the first process has compiled everything (or after a while), the kernel ahead
    # of time for later starts (biped_opt.codegen.aot), at a low priority
    _wait(lambda: all(cached(getattr(module, name + "_c"), unknown=True)
                      for name in abi.FUNCTIONS), timeout=wait)
    with contextlib.suppress(OSError):
        os.nice(10)
    aot.build_once(Path(path), Path(path).stem, held=held)
    return 0


#: how long the second process waits for the first before it builds the ahead-of-time kernel
WAIT_S = 600.0


def cached(fn: Any, *, unknown: bool) -> bool:
    """Whether Numba's on-disk cache has an entry for ``fn``: a dispatcher, or the Python
    function of a C-callable one (``<name>_c``); ``unknown`` where that cannot be told (another
    Numba's layout)."""
    from numba.core.caching import FunctionCache

    try:
        cache = fn._cache if hasattr(fn, "_cache") else FunctionCache(fn)
        return bool(cache._cache_file._load_index())
    except (AttributeError, OSError, RuntimeError):
        return unknown


def _wait(ready: Callable[[], bool], timeout: float) -> bool:
    """Poll ``ready`` every 0.2 s until it holds (True) or ``timeout`` [s] passes (False)."""
    deadline = time.monotonic() + timeout
    while not ready():
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.2)
    return True


if __name__ == "__main__":
    raise SystemExit(main())
