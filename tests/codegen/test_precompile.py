"""The second compile process, and the calls between the shared kernel and a system's compiled
functions (biped_opt/codegen/abi.py)."""

from __future__ import annotations

import inspect
import os
import shutil
import subprocess
import sys

from numba import types

from biped_opt.codegen import abi, precompile
from biped_opt.simulation.compiled import compile_system


def test_a_call_that_does_not_match_the_table_does_not_compile():
    """The shared kernel calls a system function through its address, and the C function
    reads its arguments by the table (biped_opt.codegen.abi.FUNCTIONS): a float where it
    expects an integer, or an array that is not C-contiguous float64, would be read wrong
    rather than converted. The kernel's ``_call`` checks every call against the table when it
    is compiled; here a call with the table's types compiles (it is not run: sv would hold no
    address), and each kind of mismatch is refused."""
    import numba as nb
    import pytest
    from numba.core.errors import TypingError

    from biped_opt.codegen.kernel import _call

    @nb.njit
    def right(sv, p, mode, u, y, j):
        return _call("reaction", sv, p, mode, u, y, j)

    vec = types.Array(types.float64, 1, "C")
    sv = types.Array(types.int64, 1, "C")
    right.compile((sv, vec, types.int64, vec, vec, types.int64))
    for wrong in [
        (sv, vec, types.float64, vec, vec, types.int64),  # a float for the mode
        (sv, vec, types.int64, vec, types.Array(types.float64, 1, "A"), types.int64),
        (sv, vec, types.int64, vec, types.Array(types.float64, 2, "C"), types.int64),
    ]:
        with pytest.raises(TypingError, match="do not match the table"):
            right.compile(wrong)

    @nb.njit
    def unknown(sv, p):
        return _call("no_such_function", sv, p)

    with pytest.raises(TypingError, match="must name a function"):
        unknown.compile((sv, vec))


def test_the_direct_binding_has_the_engines_names_and_arguments():
    """The kernel compiled ahead of time binds the same ``sys_*`` names with the same
    arguments as the shared kernel (one kernel source for both)."""
    from biped_opt.codegen import kernel

    namespace: dict = {}
    text = abi.direct_binding().replace('@nb.njit(**HOT_PATH, inline="always")', "")
    exec(compile(text, "<direct binding>", "exec"), namespace)
    for name, binding in abi.binding_names().items():
        ours = list(inspect.signature(namespace[binding]).parameters)
        theirs = list(inspect.signature(getattr(kernel, binding).py_func).parameters)
        assert ours[0] == theirs[0] == "sv" and len(ours) == len(theirs), name


def test_second_process_writes_the_cache(tmp_path):
    """Run on a copy of a generated module in an empty directory (no first process: it waits
    for none), the process exits 0 and leaves a Numba cache index for every function that does
    not call the vector field."""
    bar = compile_system("rocking_bar")
    source = bar.module.__file__
    copy = tmp_path / os.path.basename(source)
    shutil.copyfile(source, copy)
    name = "biped_opt_systems_precompile_test_" + copy.stem
    proc = subprocess.run(
        [sys.executable, "-m", "biped_opt.codegen.precompile", str(copy), name, "0"],
        capture_output=True, text=True, timeout=600, check=False,
        env=dict(os.environ, BIPED_OPT_AOT="0"))
    assert proc.returncode == 0, proc.stderr
    written = {p.name.split(".")[1].split("-")[0] for p in (tmp_path / "__pycache__").glob("*.nbi")}
    assert {f"{n}_c" for n in bar.module.FIELD_FREE} <= written
    assert "_field_at" not in written and "step_c" not in written


def test_turned_off_by_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("BIPED_OPT_PRECOMPILE", "0")
    assert precompile.start(tmp_path / "absent.py", "absent") is None


def test_the_kernel_compiled_at_install_is_the_one_simulations_call():
    """``make venv`` compiles the shared kernel's entry points for explicit types
    (``python -m biped_opt.codegen.kernel``); a simulation and a batch must then call those
    compiled entries, not compile others for slightly different types (a first simulation of
    every new system would pay the kernel's compile again)."""
    script = (
        "from biped_opt.codegen import abi, kernel\n"
        "from biped_opt.simulation.compiled import compile_system\n"
        "kernel.compile_all()\n"
        "c = compile_system('rocking_bar')\n"
        "c.simulate('drop', 0.05)\n"
        "c.simulate('drop', 0.05, sample_dt=0.01)\n"
        "c.simulate_batch('drop', [0.05, -0.05, 0.01])\n"
        "for name in abi.ENTRY_SIGNATURES:\n"
        "    fn = getattr(kernel, name)\n"
        "    assert len(fn.signatures) == 1, (name, fn.signatures)\n"
    )
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
