"""The kernel of a generated module compiled ahead of time, for starts without Numba.

A cached start of a system needs a few calls of the kernel: ``simulate_maneuver`` (one
trajectory: ``simulate``, the optimiser's tries), ``simulate_batch_kernel`` (sweeps) and
``variational_field`` (the derivatives). Through Numba each first sets up Numba's compiler
and target (importing Numba, ~1 s with its load path) only to load machine code from its
cache. Here the kernel's source (:mod:`biped_opt.codegen.kernel`, below its marker) is compiled
together with the system's generated module, its calls of the system's functions bound
directly (:func:`biped_opt.codegen.abi.direct_binding`) instead of through addresses, into a
file beside the module that a later start loads in milliseconds, with NumPy and nothing of
Numba. Two kinds, tried in this order:

1. ``native``: a plain shared library ``<name>_kernel_<key>.so`` of every entry point, made of
   llvmlite object code and a small C runtime (:mod:`biped_opt.codegen.native`), called through
   ctypes (which releases the interpreter lock: batches run in parallel threads);
2. ``extension``: a CPython extension ``<name>_aot_<key><suffix>`` of ``simulate_maneuver``
   made by ``numba.pycc``, which Numba has marked "pending deprecation" since 0.57 with no
   replacement. It is built only where the first cannot be; its start serves ``simulate``,
   and the rest loads through Numba.

Without either (no C compiler: both link with the platform's), every start loads through Numba,
as before. The key in the names hashes the kernel's source, its table, and the code that builds
them: a file built from another kernel is never loaded.

It is the same source compiled for the same arithmetic: no fast-math in any compile, so both
kinds and the shared kernel give bit-identical trajectories (``tests/codegen/test_aot.py``,
``tests/codegen/test_native.py`` check it, at coincident events too). Both target the generic
CPU of the machine's architecture, so a cache shared between machines stays safe to load.

:func:`start` runs the build in a detached process: after a cold compile, and from a cached start
that finds neither kind (a cache from before, or a build that was interrupted). A lock file keeps
it to one build per module. ``BIPED_OPT_AOT`` chooses: ``0`` none (every start loads through
Numba), ``native`` or ``extension`` only that kind, anything else both in the order above.
Run as ``python -m biped_opt.codegen.aot PATH MODULE_NAME NAME``.
"""

from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import os
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path
from types import ModuleType
from typing import Any

from biped_opt import children
from biped_opt.codegen import native
from biped_opt.codegen.abi import ENTRY_SIGNATURES

__all__ = ["KINDS", "EXPORTED", "SIGNATURE", "kinds", "enabled", "native_path", "extension_path",
           "built", "load", "build", "build_once", "start", "wait_built", "load_module",
           "kernel_source", "main"]

#: the kinds of kernel compiled ahead of time, in the order they are tried (module docstring)
KINDS = ("native", "extension")
#: the function the extension exports, and its types: (status, t_f, mode_f, events, samples,
#: nfev, steps, rejected, outcome) from (p, sv, code, s, u, cfg, samples, events, y_out, y0,
#: mode0)
EXPORTED = "simulate_maneuver"
SIGNATURE = ENTRY_SIGNATURES[EXPORTED]
#: a lock older than this belongs to a build that died [s]
STALE_LOCK_S = 1800.0


def kinds() -> tuple[str, ...]:
    """The kinds ``BIPED_OPT_AOT`` allows, in order (none when it is 0)."""
    value = os.environ.get("BIPED_OPT_AOT", "1").strip()
    if value == "0":
        return ()
    return (value,) if value in KINDS else KINDS


def enabled() -> bool:
    return bool(kinds())


_KERNEL = Path(__file__).with_name("kernel.py")
_KEY: list[str] = []


def kernel_key() -> str:
    """A hash of the kernel's source, the table it calls through and the code that compiles
    it ahead (part of a file's name: one built from another kernel is never loaded)."""
    if not _KEY:
        digest = hashlib.sha256()
        for path in (_KERNEL, _KERNEL.with_name("abi.py"), _KERNEL.with_name("native.py"),
                     native.RUNTIME):
            digest.update(path.read_bytes())
        _KEY.append(digest.hexdigest()[:12])
    return _KEY[0]


def native_path(folder: Path, name: str) -> Path:
    """Where the kernel library of the generated module ``name`` lives."""
    return folder / f"{name}_kernel_{kernel_key()}.so"


def extension_path(folder: Path, name: str) -> Path:
    """Where the extension of the generated module ``name`` lives."""
    return folder / f"{name}_aot_{kernel_key()}{importlib.machinery.EXTENSION_SUFFIXES[0]}"


_PATHS = {"native": native_path, "extension": extension_path}


def built(folder: Path, name: str) -> bool:
    """Whether a kernel of an allowed kind is there for module ``name``."""
    return any(_PATHS[kind](folder, name).is_file() for kind in kinds())


def _load_extension(path: Path) -> ModuleType | None:
    module_name = path.name.split(".")[0]
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or spec.loader is None:
        return None
    try:
        module = importlib.util.module_from_spec(spec)  # (an extension loads here)
        spec.loader.exec_module(module)
    except ImportError:
        return None  # (a broken file: the caller loads through Numba)
    if not callable(getattr(module, EXPORTED, None)):
        return None
    sys.modules[module_name] = module
    return module


#: the kernels loaded in this process, by file (a file is loaded once)
_KERNELS: dict[Path, Any] = {}


def load(folder: Path, name: str) -> Any | None:
    """The kernel of module ``name`` compiled ahead, of the first allowed kind that is there and
    loads: an object with the entry points it has (all of
    :data:`biped_opt.codegen.abi.ENTRIES` for a library, :data:`EXPORTED` for an extension),
    called as the shared kernel's; None when there is none."""
    for kind in kinds():
        path = _PATHS[kind](folder, name)
        if path in _KERNELS:
            return _KERNELS[path]
        if not path.is_file():
            continue
        kernel = native.load(path) if kind == "native" else _load_extension(path)
        if kernel is not None:
            _KERNELS[path] = kernel
            return kernel
    return None


#: what the kernel's source needs besides the system's module: the table's layout and the
#: status codes (the engine's own header, which binds its calls through addresses, is not part
#: of it)
_KERNEL_IMPORTS = """
from biped_opt.codegen.abi import *  # noqa
from biped_opt.codegen.status import *  # noqa
"""


def kernel_source(module_text: str) -> str:
    """A system's generated module with the kernel compiled into it: the module, the kernel's
    calls bound directly to its functions, and the kernel's source below its marker."""
    from biped_opt.codegen.abi import direct_binding

    body = _KERNEL.read_text()
    body = body[body.index("\n# --- kernel ---\n") + 1:]
    return "\n\n".join([module_text.rstrip(), _KERNEL_IMPORTS, direct_binding(), body])


def _build_extension(module: ModuleType, target: Path, work: Path) -> None:
    with warnings.catch_warnings():  # (pycc is "pending deprecation": see the module doc)
        warnings.simplefilter("ignore")
        from numba.pycc import CC

    cc = CC(target.name.split(".")[0])
    cc.output_dir = str(work)
    cc.verbose = False
    cc.export(EXPORTED, SIGNATURE)(getattr(module, EXPORTED).py_func)
    cc.compile()
    os.replace(work / target.name, target)


def build(path: Path, name: str) -> Path:
    """Compile the kernel with the generated module at ``path`` (:func:`kernel_source`) into a
    file beside it, of the first allowed kind that builds: built in a temporary directory, then
    renamed into place. Raises the last kind's error when none builds."""
    folder = path.parent
    allowed = kinds() or KINDS
    for k, kind in enumerate(allowed):
        target = _PATHS[kind](folder, name)
        try:
            with tempfile.TemporaryDirectory(dir=folder, prefix=f".{name}_aot.") as work:
                source = Path(work) / f"{name}_with_kernel.py"
                text = kernel_source(path.read_text())
                if kind == "native":
                    text += "\n\n" + native.wrapper_source()
                source.write_text(text)
                module = load_module(source, f"biped_opt_ahead_{name}_{kind}")
                if kind == "native":
                    native.build(target, module)
                else:
                    _build_extension(module, target, Path(work))
            return target
        except (OSError, ImportError, subprocess.SubprocessError, RuntimeError):
            if k == len(allowed) - 1:
                raise
    raise AssertionError("unreachable")


def _compiler() -> bool:
    """A C compiler to link with (both kinds call the platform's)."""
    return native.compiler() is not None


def _lock(folder: Path, name: str) -> Path:
    return folder / f".{name}_aot.lock"


def _take_lock(lock: Path) -> bool:
    """Create ``lock`` (False when a live build holds it)."""
    for _attempt in range(2):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600)
        except FileExistsError:
            try:
                if time.time() - lock.stat().st_mtime < STALE_LOCK_S:
                    return False
                lock.unlink()  # (a build that died long ago)
            except FileNotFoundError:
                pass
            continue
        os.close(fd)
        return True
    return False


def _claim(folder: Path, name: str) -> Path | None:
    """The build lock of module ``name``, taken; None when builds are off, no C compiler is
    there, a kernel is built, or another build holds the lock."""
    if not enabled() or not _compiler() or built(folder, name):
        return None
    lock = _lock(folder, name)
    return lock if _take_lock(lock) else None


def start(path: Path, module_name: str, name: str) -> subprocess.Popen | None:
    """Build the kernel of the module at ``path`` (imported as ``module_name``) in a detached
    process, unless :func:`_claim` says no."""
    lock = _claim(path.parent, name)
    if lock is None:
        return None
    try:  # (niced, limited in time, -P and a directory of its own: biped_opt.children)
        return children.popen(
            "biped_opt.codegen.aot", str(path), module_name, name,
            background=f"the ahead-of-time kernel of {name}", stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    except OSError:
        lock.unlink(missing_ok=True)
        return None


def load_module(path: Path, module_name: str) -> ModuleType:
    """Import the generated module at ``path`` as ``module_name`` (in a second process)."""
    # under the first process's name: Numba's cached code refers to its module by name
    spec = importlib.util.spec_from_file_location(module_name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    spec.loader.exec_module(module)
    return module


def build_once(path: Path, name: str, held: list[Path] | None = None) -> Path | None:
    """:func:`build` here, unless :func:`_claim` says no; ``held`` lists the build's lock while
    it is taken (for a time limit that ends the process to remove)."""
    lock = _claim(path.parent, name)
    if lock is None:
        return None
    if held is not None:
        held.append(lock)
    try:
        return build(path, name)
    finally:
        lock.unlink(missing_ok=True)
        if held is not None:
            held.remove(lock)


def wait_built(folder: Path, name: str, timeout: float) -> bool:
    """Wait until a kernel of module ``name`` is there (True), no build of it is under way any
    more, or ``timeout`` [s] has passed (False)."""
    deadline = time.monotonic() + timeout
    while not built(folder, name):
        if not _lock(folder, name).exists() or time.monotonic() >= deadline:
            return built(folder, name)
        time.sleep(0.2)
    return True


def main(argv: list[str] | None = None) -> int:
    path_text, _module_name, name = (sys.argv[1:] if argv is None else argv)[:3]
    path = Path(path_text)
    lock = _lock(path.parent, name)  # (taken by start())
    children.limit_background(lambda: lock.unlink(missing_ok=True))
    try:
        build(path, name)
    finally:
        lock.unlink(missing_ok=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
