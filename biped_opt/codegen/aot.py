"""The kernel of a generated module compiled ahead of time, for starts without Numba.

A cached start of a system (``biped-opt simulate --system NAME``) needs one call of the kernel,
``simulate_maneuver``. Through Numba that call first sets up Numba's compiler and target
(importing Numba and SciPy, ~1 s) only to load machine code from its cache. :func:`build` compiles
the kernel's source (:mod:`biped_opt.codegen.kernel`, below its marker) together with the
system's generated module, its calls of the system's functions bound directly
(:func:`biped_opt.codegen.abi.direct_binding`) instead of through addresses, with
``numba.pycc`` into a CPython extension beside the module (``<name>_aot_<kernel key><suffix>``:
a new kernel source is a new file); a later start imports that extension (a few milliseconds)
and NumPy, and nothing of Numba.

It is the same source compiled for the same arithmetic: no fast-math in either, so the
extension and the shared kernel give bit-identical trajectories (``tests/codegen/test_aot.py``
checks it, at coincident events too).
The extension targets the generic x86-64/AArch64 CPU, so a cache shared between machines stays
safe to load. ``numba.pycc`` is marked "pending deprecation" since Numba 0.57 with no replacement
yet; Numba is pinned, and without it (or without a C compiler) every start simply loads through
Numba. Everything else of a system (batches, the variational equations, the derivatives)
keeps using the Numba-compiled module.

:func:`start` runs the build in a detached process: after a cold compile, and from a cached start
that finds no extension (a cache from before, or a build that was interrupted). A lock file keeps
it to one build per module. ``BIPED_OPT_AOT=0`` turns it off; then every start loads through
Numba, as before. Run as ``python -m biped_opt.codegen.aot PATH MODULE_NAME NAME``.
"""

from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path
from types import ModuleType

from biped_opt import children
from biped_opt.codegen.abi import ENTRY_SIGNATURES

__all__ = ["SIGNATURE", "enabled", "extension_path", "load", "build", "build_once", "start",
           "wait_built", "load_module", "main"]

#: the exported function, and its types: (status, t_f, mode_f, events, samples, nfev, steps,
#: rejected, outcome) from (p, sv, code, s, u, cfg, samples, events, y_out, y0, mode0)
EXPORTED = "simulate_maneuver"
SIGNATURE = ENTRY_SIGNATURES[EXPORTED]
#: a lock older than this belongs to a build that died [s]
STALE_LOCK_S = 1800.0


def enabled() -> bool:
    return os.environ.get("BIPED_OPT_AOT", "1") != "0"


_KERNEL = Path(__file__).with_name("kernel.py")
_KEY: list[str] = []


def kernel_key() -> str:
    """A hash of the kernel's source and of the table it calls through (part of an extension's
    name: an extension built from another kernel is never loaded)."""
    if not _KEY:
        digest = hashlib.sha256(_KERNEL.read_bytes())
        digest.update(_KERNEL.with_name("abi.py").read_bytes())
        _KEY.append(digest.hexdigest()[:12])
    return _KEY[0]


def extension_path(folder: Path, name: str) -> Path:
    """Where the extension of the generated module ``name`` lives."""
    return folder / f"{name}_aot_{kernel_key()}{importlib.machinery.EXTENSION_SUFFIXES[0]}"


def load(folder: Path, name: str) -> ModuleType | None:
    """The extension of module ``name``, or None when it is not there (or does not load)."""
    path = extension_path(folder, name)
    if not enabled() or not path.is_file():
        return None
    module_name = path.name.split(".")[0]
    if module_name in sys.modules:
        return sys.modules[module_name]
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


def build(path: Path, name: str) -> Path:
    """Compile the kernel with the generated module at ``path`` (:func:`kernel_source`) into the
    extension of ``name`` beside it: built in a temporary directory, then renamed into place."""
    with warnings.catch_warnings():  # (pycc is "pending deprecation": see the module doc)
        warnings.simplefilter("ignore")
        from numba.pycc import CC

    folder = path.parent
    target = extension_path(folder, name)
    with tempfile.TemporaryDirectory(dir=folder, prefix=f".{name}_aot.") as work:
        source = Path(work) / f"{name}_with_kernel.py"
        source.write_text(kernel_source(path.read_text()))
        module = load_module(source, f"biped_opt_ahead_{name}")
        cc = CC(target.name.split(".")[0])
        cc.output_dir = work
        cc.verbose = False
        cc.export(EXPORTED, SIGNATURE)(getattr(module, EXPORTED).py_func)
        cc.compile()
        made = Path(work) / target.name
        os.replace(made, target)
    return target


def _compiler() -> bool:
    """A C compiler to link the extension with (numba.pycc calls the platform's)."""
    return shutil.which("cc") is not None or shutil.which("gcc") is not None


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
    there, the extension exists, or another build holds the lock."""
    if not enabled() or not _compiler() or extension_path(folder, name).is_file():
        return None
    lock = _lock(folder, name)
    return lock if _take_lock(lock) else None


def start(path: Path, module_name: str, name: str) -> subprocess.Popen | None:
    """Build the extension of the module at ``path`` (imported as ``module_name``) in a detached
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
    """Wait until the extension of ``name`` is there (True), no build of it is under way any
    more, or ``timeout`` [s] has passed (False)."""
    deadline = time.monotonic() + timeout
    while not extension_path(folder, name).is_file():
        if not _lock(folder, name).exists() or time.monotonic() >= deadline:
            return extension_path(folder, name).is_file()
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
