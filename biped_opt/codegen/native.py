"""The kernel of a generated module as a plain shared library: llvmlite object code, no pycc.

This is the first way of :mod:`biped_opt.codegen.aot` to start a cached system without Numba's
load path, and the one that does not rest on ``numba.pycc`` (marked "pending deprecation").
:func:`build` compiles the same source as the extension: the system's generated module with
the kernel bound directly to its functions (:func:`biped_opt.codegen.aot.kernel_source`),
plus a C-callable wrapper per entry point of :data:`biped_opt.codegen.abi.ENTRIES` and per
function of the module that Python calls (:data:`biped_opt.codegen.abi.MODULE_CALLS`; see
:func:`wrapper_source`: arrays as data pointer and shape, a tuple result into a vector). It
takes the wrappers' LLVM modules (what Numba compiled them to, every function they call linked
in), links them into one, emits it as object code for the generic CPU of the machine's
architecture with llvmlite (the LLVM that Numba itself uses), and links that with the system's
C compiler and the small runtime of ``native_runtime.c`` (memory, and the error path: what
Numba's runtime gives code it loads) into ``<name>_kernel_<key>.so``.

A start loads that library with :mod:`ctypes` (:func:`load`, milliseconds, nothing of Numba)
and calls its entry points with the NumPy arrays the Numba entry points take. A call through
ctypes releases the interpreter lock, so the batch entry runs in parallel threads
(:func:`biped_opt.simulation.compiled.run_batch`) as the Numba one does, and the variational
equations and the optimiser's single trajectories are there too: every command starts without
Numba. No fast-math in either compile: the library's trajectories are bit for bit those of the
shared kernel (``tests/codegen/test_native.py``).

Every argument is checked before the call (dtype, dimensions, C order; an array is passed by
its address, so a wrong one would be read out of bounds), and a call after which the runtime
counted an error raises :class:`NativeKernelError` instead of returning what it wrote.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from biped_opt.codegen.abi import ENTRIES, MODULE_CALLS

__all__ = ["RUNTIME", "EXPORTS", "NativeKernelError", "NativeKernel", "compiler", "wrapper_source",
           "symbol", "build", "load"]

#: the C runtime linked into every library (see its header)
RUNTIME = Path(__file__).with_name("native_runtime.c")

_ARRAY_KINDS = {"A": (np.dtype(np.float64), 1), "I": (np.dtype(np.int64), 1),
                "F": (np.dtype(np.float64), 2), "T": (np.dtype(np.float64), 3)}
_NUMBA_ARGUMENT = {"A": ["types.CPointer(types.float64)", "types.int64"],
                   "I": ["types.CPointer(types.int64)", "types.int64"],
                   "F": ["types.CPointer(types.float64)", "types.int64", "types.int64"],
                   "T": ["types.CPointer(types.float64)", "types.int64", "types.int64",
                         "types.int64"],
                   "i": ["types.int64"], "f": ["types.float64"]}
_NUMBA_RESULT = {"v": "types.void", "i": "types.int64", "f": "types.float64"}
_C_SCALAR = {"i": ctypes.c_int64, "f": ctypes.c_double}


class NativeKernelError(RuntimeError):
    """A call of a kernel library that ended on its runtime's error path."""


def symbol(entry: str) -> str:
    """The exported name of an entry point in the library."""
    return f"biped_opt_{entry}"


def compiler() -> str | None:
    """The C compiler that links a library: ``$CC`` when set, else ``cc`` or ``gcc``."""
    named = os.environ.get("CC", "").strip()
    if named:
        return shutil.which(named.split()[0])
    return shutil.which("cc") or shutil.which("gcc")


#: what a library exports: the kernel's entry points, then the module's functions that Python
#: calls (biped_opt.codegen.abi)
EXPORTS: dict[str, tuple[str, str]] = {**ENTRIES, **MODULE_CALLS}


def wrapper_source() -> str:
    """The C-callable wrappers of :data:`EXPORTS`, ``<name>_native``, to append to a module
    with the kernel compiled into it; ``NATIVE_SIGNATURES`` maps each to its Numba type."""
    out = ["# --- the entry points, C-callable (biped_opt.codegen.native.wrapper_source) ---", "",
           "from numba import types as types  # noqa: E402", ""]
    sigs = {}
    for name, (kinds, result) in EXPORTS.items():
        params, views, types = [], [], []
        for k, kind in enumerate(kinds):
            a = f"a{k}"
            types += _NUMBA_ARGUMENT[kind]
            if kind in _ARRAY_KINDS:
                dims = [f"{a}_{d}" for d in range(_ARRAY_KINDS[kind][1])]
                params += [a, *dims]
                views.append(f"nb.carray({a}, ({', '.join(dims)},))")
            else:
                params.append(a)
                views.append(a)
        call = f"{name}({', '.join(views)})"
        if len(result) > 1:  # (a tuple: into the vector ``res`` of its length)
            params.append("res")
            types.append("types.CPointer(types.float64)")
            body = [f"    r = {call}", f"    out = nb.carray(res, ({len(result)},))"]
            body += [f"    out[{k}] = r[{k}]" for k in range(len(result))]
            ret = "types.void"
        else:
            body = [f"    {'return ' if result != 'v' else ''}{call}"]
            ret = _NUMBA_RESULT[result]
        out += ["", f"def {name}_native({', '.join(params)}):", *body, ""]
        sigs[name] = f"{ret}({', '.join(types)})"
    out += ["", "NATIVE_SIGNATURES = {"]
    out += [f"    {name!r}: {sig}," for name, sig in sigs.items()]
    out += ["}", ""]
    return "\n".join(out)


def _object_code(module: Any) -> bytes:
    """The entry points' wrappers of ``module`` (a module made of :func:`wrapper_source`),
    compiled by Numba and emitted as one object file for the generic CPU."""
    import llvmlite.binding as llvm
    import numba as nb

    linked = None
    for name in EXPORTS:
        cf = nb.cfunc(module.NATIVE_SIGNATURES[name], error_model="numpy")(
            getattr(module, f"{name}_native"))
        ir = llvm.parse_assembly(cf.inspect_llvm())  # (its module, what it calls linked in)
        ir.get_function(cf.native_name).name = symbol(name)
        if linked is None:
            linked = ir
        else:
            linked.link_in(ir)
    assert linked is not None
    linked.verify()
    target = llvm.Target.from_triple(linked.triple)
    machine = target.create_target_machine(cpu="", features="", opt=3, reloc="pic",
                                           codemodel="default")
    return machine.emit_object(linked)


def build(target: Path, module: Any) -> Path:
    """Build the library ``target`` from ``module`` (a module of
    :func:`biped_opt.codegen.aot.kernel_source` and :func:`wrapper_source`): object code, then
    linked with the runtime in a temporary directory beside it, renamed into place."""
    cc = compiler()
    if cc is None:
        raise OSError("no C compiler to link the kernel library with (set CC, or install cc)")
    obj = _object_code(module)
    with tempfile.TemporaryDirectory(dir=target.parent, prefix=f".{target.stem}.") as work:
        o = Path(work) / "kernel.o"
        o.write_bytes(obj)
        made = Path(work) / target.name
        # (-Bsymbolic: its calls of its own runtime bind to it, whatever else is loaded)
        subprocess.run([cc, "-shared", "-fPIC", "-O2", "-Wl,-Bsymbolic", "-o", str(made), str(o),
                        str(RUNTIME), "-lm"], check=True, capture_output=True, timeout=600)
        os.replace(made, target)
    return target


def _argument_types(kinds: str, result: str) -> list[Any]:
    out: list[Any] = []
    for kind in kinds:
        if kind in _ARRAY_KINDS:
            out += [ctypes.c_void_p] + [ctypes.c_int64] * _ARRAY_KINDS[kind][1]
        else:
            out.append(_C_SCALAR[kind])
    if len(result) > 1:
        out.append(ctypes.c_void_p)
    return out


def _caller(lib: ctypes.CDLL, name: str, errors: Callable[[], int]) -> Callable[..., Any]:
    """A function that calls entry ``name`` of ``lib`` as the Numba entry point is called."""
    kinds, result = EXPORTS[name]
    fn = getattr(lib, symbol(name))
    fn.argtypes = _argument_types(kinds, result)
    fn.restype = None if len(result) > 1 or result == "v" else _C_SCALAR[result]
    arrays = [(k, *_ARRAY_KINDS[kind]) for k, kind in enumerate(kinds) if kind in _ARRAY_KINDS]
    scalars = [(k, int if kind == "i" else float) for k, kind in enumerate(kinds)
               if kind not in _ARRAY_KINDS]
    convert = [int if kind == "i" else float for kind in result] if len(result) > 1 else None

    def call(*args: Any) -> Any:
        if len(args) != len(kinds):
            raise TypeError(f"{name} takes {len(kinds)} arguments, got {len(args)}")
        flat: list[Any] = list(args)
        for k, dtype, ndim in arrays:  # (an address read with the wrong layout reads astray)
            a = args[k]
            if not (type(a) is np.ndarray and a.dtype == dtype and a.ndim == ndim
                    and a.flags.c_contiguous):
                raise TypeError(f"{name}: argument {k} must be a C-contiguous {ndim}-D "
                                f"{dtype} array, got {getattr(a, 'dtype', type(a))!r}")
        for k, to in scalars:
            flat[k] = to(args[k])
        expanded: list[Any] = []
        arrays_at = {k for k, _d, _n in arrays}
        for k, value in enumerate(flat):
            if k in arrays_at:
                expanded.append(value.ctypes.data)
                expanded.extend(value.shape)
            else:
                expanded.append(value)
        res = None
        if convert is not None:
            res = np.empty(len(convert))
            expanded.append(res.ctypes.data)
        before = errors()
        value = fn(*expanded)
        if errors() != before:
            raise NativeKernelError(f"{name}: the compiled kernel failed inside (an allocation "
                                    "the machine could not give?); nothing it wrote is a result")
        if res is not None and convert is not None:
            return tuple(to(v) for to, v in zip(convert, res.tolist()))
        return value

    call.__name__ = name
    return call


class NativeKernel:
    """A kernel library, loaded: one attribute per name of :data:`EXPORTS`, called with the
    arguments of the Numba function of that name."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._lib = ctypes.CDLL(str(path))
        count = self._lib.biped_opt_native_errors
        count.argtypes, count.restype = [], ctypes.c_long
        for name in EXPORTS:
            setattr(self, name, _caller(self._lib, name, count))


def load(path: Path) -> NativeKernel | None:
    """The library at ``path``, or None when it is not there or does not load (a file from
    another machine, or cut short)."""
    if not path.is_file():
        return None
    try:
        return NativeKernel(path)
    except (OSError, AttributeError):
        return None
