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

Every argument is checked before the call (dtype and dimensions: an array is passed by its
address, so a wrong one would be read out of bounds; a strided one goes through a contiguous
copy, copied back after the call), and a call after which the runtime counted an error raises
:class:`NativeKernelError` instead of returning what it wrote.
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


def _address(a: np.ndarray) -> int:
    """The address of an array's data: none for an empty one (nothing of it is read), through a
    writable array's buffer (a third of the time of ``a.ctypes.data``, which a call of a dozen
    arrays feels), else the slow way (a read-only array)."""
    if not a.size:
        return 0
    if a.flags.writeable:
        return ctypes.addressof(ctypes.c_byte.from_buffer(a))  # type: ignore[arg-type]
    return int(a.ctypes.data)


def _refuse(name: str, k: int, kind: str, a: Any) -> None:
    dtype, ndim = _ARRAY_KINDS[kind]
    raise TypeError(f"{name}: argument {k} must be a {ndim}-D {dtype} array, got "
                    f"{getattr(a, 'dtype', type(a))!r}"
                    + (f" of {a.ndim} dimensions" if isinstance(a, np.ndarray) else ""))


def _contiguous(a: np.ndarray, back: list | None) -> tuple[np.ndarray, list | None]:
    """A C-contiguous copy of the strided array ``a`` for a call, and the list of what to copy
    back after it (the copy, into ``a``: the function may write into its argument, as the Numba
    one writes into the strided array itself)."""
    copy = np.ascontiguousarray(a)
    if a.flags.writeable:
        back = [*(back or []), (a, copy)]
    return copy, back


def _caller(lib: ctypes.CDLL, name: str, errors: Callable[[], int]) -> Callable[..., Any]:
    """A function that calls entry ``name`` of ``lib`` as the Numba entry point is called:
    written out for its arguments (a call of a single trajectory is ~10 us of work, and a loop
    over a dozen arguments cost half as much again). Each array is checked (an address read
    with the wrong type reads astray) and passed as its address and shape, a strided one
    through a contiguous copy that is copied back after the call; a scalar goes to ctypes,
    which checks it (a float for an int64 is a TypeError)."""
    kinds, result = EXPORTS[name]
    fn = getattr(lib, symbol(name))
    fn.argtypes = _argument_types(kinds, result)
    fn.restype = None if len(result) > 1 or result == "v" else _C_SCALAR[result]
    params = [f"a{k}" for k in range(len(kinds))]
    body, passed = ["    back = None"], []
    for k, kind in enumerate(kinds):
        a = f"a{k}"
        if kind not in _ARRAY_KINDS:
            passed.append(a)
            continue
        ndim = _ARRAY_KINDS[kind][1]
        body += [f"    if not (type({a}) is ndarray and ({a}.dtype is D{kind} or "
                 f"{a}.dtype == D{kind}) and {a}.ndim == {ndim}):",
                 f"        refuse(NAME, {k}, {kind!r}, {a})",
                 f"    if not {a}.flags.c_contiguous:",
                 f"        {a}, back = contiguous({a}, back)"]
        passed += [f"address({a})", *(f"{a}.shape[{d}]" for d in range(ndim))]
    if len(result) > 1:
        body.append(f"    res = Vector{len(result)}()")
        passed.append("res")
    body += ["    before = errors()", "    try:", f"        value = fn({', '.join(passed)})",
             "    except ArgumentError as exc:  # (a scalar of the wrong type)",
             "        raise TypeError(f'{NAME}: {exc}') from None",
             "    if errors() != before:", "        failed(NAME)",
             "    if back:", "        for original, copy in back:",
             "            copyto(original, copy)"]
    if len(result) > 1:
        body.append("    return (" + ", ".join(f"{'int' if r == 'i' else 'float'}(res[{j}])"
                                             for j, r in enumerate(result)) + ",)")
    else:
        body.append("    return value")
    source = "\n".join([f"def {name}({', '.join(params)}):", *body])
    namespace: dict[str, Any] = {
        "ndarray": np.ndarray, "address": _address, "errors": errors, "fn": fn, "NAME": name,
        "refuse": _refuse, "failed": _failed, "contiguous": _contiguous, "copyto": np.copyto,
        "ArgumentError": ctypes.ArgumentError,
        **{f"D{kind}": dtype for kind, (dtype, _n) in _ARRAY_KINDS.items()},
        **({f"Vector{len(result)}": ctypes.c_double * len(result)} if len(result) > 1 else {})}
    exec(compile(source, f"<biped_opt kernel library: {name}>", "exec"), namespace)
    return namespace[name]


def _failed(name: str) -> None:
    raise NativeKernelError(f"{name}: the compiled kernel failed inside (an allocation the "
                            "machine could not give?); nothing it wrote is a result")


class NativeKernel:
    """A kernel library, loaded: one attribute per name of :data:`EXPORTS`, called with the
    arguments of the Numba function of that name."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._lib = ctypes.CDLL(str(path))
        count = ctypes.c_long.in_dll(self._lib, "biped_opt_native_error_count")

        def errors() -> int:  # (read in place: cheaper than a call, twice per call)
            return count.value

        for name in EXPORTS:
            setattr(self, name, _caller(self._lib, name, errors))


def load(path: Path) -> NativeKernel | None:
    """The library at ``path``, or None when it is not there or does not load (a file from
    another machine, or cut short)."""
    if not path.is_file():
        return None
    try:
        return NativeKernel(path)
    except (OSError, AttributeError):
        return None
