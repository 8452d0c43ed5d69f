"""A second process that compiles a freshly generated module's event functions, in parallel.

A system's first simulation compiles its kernel, and Numba compiles the kernel's callees as it
meets them: the initial state and step, then the DOP853 step (about half of the whole compile),
then the functions that locate and handle events (dense output, guards on the interpolant, roots,
guard rates: a quarter). None of them depends on the step, so :func:`start` hands them to a
second interpreter as soon as the module is written; it compiles them with their explicit
signatures (:data:`SIGNATURES`, the types the kernel calls them with) into Numba's on-disk cache,
while the first process compiles the step (:func:`step_first`) and then the kernel, which loads
them from there (Numba reads a function's cache index each time it compiles it). On 2 cores
this takes ~3 s off a cold compile.

It only ever saves time: if the second process is late, fails, or a signature differs from the
kernel's call (``tests/codegen/test_precompile.py`` checks that they agree), the first process
compiles the function itself, as without it. ``BIPED_OPT_PRECOMPILE=0`` turns it off.

Run as ``python -m biped_opt.codegen.precompile PATH MODULE_NAME``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

from biped_opt.codegen import aot
from biped_opt.codegen.aot import load_module

__all__ = ["SIGNATURES", "STEP_SIGNATURE", "signatures", "start", "step_first", "main"]

#: the kernel's calls, by callee: argument types in Numba's signature syntax (A: a C-contiguous
#: float array, F: the interpolant's 2-D coefficients; i8 mode, code, guard index; f8 scalars)
SIGNATURES: dict[str, str] = {
    "initial_state": "i8, f8, A, A",
    "_initial_step": "A, i8, A, A, A, f8, f8, f8, A, A, A",
    "_guard_on_dense": "A, i8, A, i8, F, A, f8, i8, A, A",
    "_root_on_dense": "A, i8, A, i8, F, A, i8, f8, f8, f8, f8, A, A",
    "dense_coefficients": "A, i8, A, A, A, f8, A, A, A, F",
    "_guard_rate": "A, i8, A, i8, A, A, i8, A, A",
    "apply_impact": "A, i8, A",
    "_first_probe": "A, i8, A, i8, F, A, i8, f8, f8, i8, f8, A, A",
    "_separation_point": "A, i8, A, i8, F, A, i8, f8, f8, f8, A, A, A",
    "_extremum": "A, i8, A, i8, F, A, i8, f8, f8, f8, A, A, A",
    "_consistent_mode": "A, i8, A, A, A, A, A, A, A",
}


#: the step, which the first process compiles before anything else (see :func:`step_first`)
STEP_SIGNATURE = "A, i8, A, i8, A, A, f8, A, A, A, A, f8, f8, A"


def _types(text: str) -> tuple:
    from numba import types

    names = {"A": types.Array(types.float64, 1, "C"), "F": types.Array(types.float64, 2, "C"),
             "i8": types.int64, "f8": types.float64}
    return tuple(names[t.strip()] for t in text.split(","))


def signatures() -> dict[str, tuple]:
    """:data:`SIGNATURES` as tuples of Numba types."""
    return {fn: _types(text) for fn, text in SIGNATURES.items()}


def step_first(module: ModuleType) -> None:
    """Compile the new module's step now, in this process: the kernel's typing would otherwise
    meet the initial state and the initial step first and compile them here too, while the
    second process has them (and the event functions) ready by the time the step is done."""
    if os.environ.get("BIPED_OPT_PRECOMPILE", "1") != "0":
        module.step.compile(_types(STEP_SIGNATURE))


def start(path: Path, module_name: str) -> subprocess.Popen | None:
    """Start the second process for the module at ``path`` (imported as ``module_name``), or
    None when turned off. It runs detached: nothing waits for it."""
    if os.environ.get("BIPED_OPT_PRECOMPILE", "1") == "0":
        return None
    try:
        return subprocess.Popen(
            [sys.executable, "-m", "biped_opt.codegen.precompile", str(path), module_name],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            start_new_session=True)
    except OSError:
        return None  # (no process to spare: the first one compiles everything itself)


def main(argv: list[str] | None = None) -> int:
    path, module_name = (sys.argv[1:] if argv is None else argv)[:2]
    module = load_module(Path(path), module_name)
    for fn, sig in signatures().items():
        getattr(module, fn).compile(sig)
    # then the kernel ahead of time, for later starts (biped_opt.codegen.aot): after the event
    # functions, which the first process waits for
    aot.build_once(module, Path(path).parent, Path(path).stem)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
