"""The kernel library (biped_opt/codegen/native.py): every function it exports computes what the
Numba-compiled one computes, bit for bit (the batch, the variational equations and the module's
functions the derivatives call; the single trajectory is in test_aot.py with the extension);
it frees what it allocates; it refuses arguments it would read astray; a failure inside is
raised, never returned as a result."""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from biped_opt.codegen import abi, native
from biped_opt.control.derivatives import _STENCIL_STEPS, _STENCIL_WEIGHTS, _STEP
from biped_opt.simulation.compiled import kernel_config

from .test_aot import build_kind


@pytest.fixture(scope="module")
def libs():
    return build_kind("native")


def _table(module) -> np.ndarray:
    return np.concatenate((np.zeros(abi.NFUNC, dtype=np.int64), module.SYSTEM_TABLE))


def _batch(fn, sv, c, module, maneuver, ss, us):
    options = c.maneuver_options(maneuver)
    events = np.zeros((ss.size, options.max_events + 1, module.EVENT_WIDTH))
    y_out = np.zeros((ss.size, module.NSTATE))
    outcome = np.zeros(ss.size)
    info = np.zeros((ss.size, 8))
    fn(c.prepared, sv, c.code(maneuver), ss, us, kernel_config(options, 0.0), events, y_out,
       outcome, info, 0, ss.size)
    return events, y_out, outcome, info


# s within 1e-9 of the coincidences (both feet, both ends of the bar at once) and ordinary
# values; inputs varying per row
@pytest.mark.parametrize(("system", "maneuver"), [("rocking_bar", "drop"),
                                                  ("biped", "touchdown"), ("biped", "liftoff")])
def test_batches_bit_for_bit(libs, system, maneuver):
    c, module, lib = libs[system]
    ss = np.array([-0.1, -1e-8, -1e-9, 0.0, 1e-9, 1e-8, 0.05])
    us = np.ascontiguousarray(np.tile(c.input_vector(None), (ss.size, 1)))
    us[:, 0] += np.linspace(-0.05, 0.05, ss.size)
    kernel, sv = c.shared_kernel()
    jit = _batch(kernel.simulate_batch_kernel, sv, c, module, maneuver, ss, us)
    ahead = _batch(lib.simulate_batch_kernel, _table(module), c, module, maneuver, ss, us)
    for a, b in zip(ahead, jit):
        np.testing.assert_array_equal(a, b)
    assert (jit[3][:, 0] == 0).all()  # (status OK everywhere: real trajectories compared)


def _call_args(name, c, module, u, y, mode) -> tuple:
    """Arguments of the module function ``name`` at (y, mode), with fresh outputs."""
    n, code, ncon = module.NSTATE, c.code("touchdown"), module.NCON
    return {
        "outcome_value": lambda: (code, c.prepared, y, 0),
        "terminal_value": lambda: (code, c.prepared, u, y, 0),
        "constraint_value": lambda: (1, c.prepared, y, 0),
        "reaction": lambda: (c.prepared, mode, u, y, 0),
        "guard_value": lambda: (c.prepared, mode, u, code, y, 0, np.zeros(ncon), 0, ncon),
        "constraint_rates": lambda: (c.prepared, y, 0, np.zeros(ncon)),
        "apply_impact": lambda: (c.prepared, 3, y.copy()),
        "_field_at": lambda: (c.prepared, mode, y, 0, u, np.zeros(n), 0, np.zeros(ncon), 0),
        "initial_state": lambda: (code, 0.05, c.prepared, np.zeros(n)),
    }[name]()


def test_variational_field_and_module_calls_bit_for_bit(libs):
    c, module, lib = libs["biped"]
    rng = np.random.default_rng(7)
    n, k = module.NSTATE, 4
    tr = c.simulate("touchdown", 0.05, (0.3, -0.2, 0.1), sample_dt=0.05)
    kernel, sv = c.shared_kernel()
    u = c.input_vector((0.3, -0.2, 0.1))
    for row in tr.samples[::3]:
        y, mode = np.ascontiguousarray(row[1:1 + n]), int(row[1 + n])
        w = np.concatenate((y, rng.normal(size=n * k)))
        du = rng.normal(size=(u.size, k))
        outs, counts = [], []
        for fn, vector in ((kernel.variational_field, sv), (lib.variational_field, _table(module))):
            out = np.zeros_like(w)
            counts.append(fn(c.prepared, vector, mode, w, u, du, _STEP, _STENCIL_STEPS,
                             _STENCIL_WEIGHTS, out, np.zeros(max(module.NCON, 1))))
            outs.append(out)
        np.testing.assert_array_equal(outs[0], outs[1])
        assert counts[0] == counts[1] == 1 + 4 * k
        # the module's functions Python calls, one by one
        for name in abi.MODULE_CALLS:
            a, b = _call_args(name, c, module, u, y, mode), _call_args(name, c, module, u, y, mode)
            ra, rb = getattr(module, name)(*a), getattr(lib, name)(*b)
            assert ra == rb or (ra is None and rb is None), name
            for x, z in zip(a, b):
                if isinstance(x, np.ndarray):
                    np.testing.assert_array_equal(x, z, err_msg=name)


def _rss_kib() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") // 1024


@pytest.mark.skipif(not os.path.exists("/proc/self/statm"), reason="Linux's /proc needed")
def test_what_the_kernel_allocates_is_freed(libs):
    # each trajectory allocates its work arrays (the runtime's memory: native_runtime.c), ~3 KiB
    # for the biped; kept, 40,000 trajectories would hold over 100 MB. After rounds that let the
    # allocators settle (the first grow the process by ~9 MB, as the Numba kernel's do), allowed:
    # 4 MB
    c, module, lib = libs["biped"]
    ss = np.linspace(-0.2, 0.2, 2000)
    us = np.ascontiguousarray(np.tile(c.input_vector(None), (ss.size, 1)))
    for _ in range(10):
        _batch(lib.simulate_batch_kernel, _table(module), c, module, "touchdown", ss, us)
    before = _rss_kib()
    for _ in range(20):
        _batch(lib.simulate_batch_kernel, _table(module), c, module, "touchdown", ss, us)
    assert _rss_kib() - before < 4 * 1024


def test_arguments_it_would_read_astray_are_refused(libs):
    c, module, lib = libs["rocking_bar"]
    n = module.NSTATE
    with pytest.raises(TypeError, match="argument 1 must be a 1-D float64 array, got "
                                        "dtype.'float32'. of 1 dimensions"):
        lib.outcome_value(0, c.prepared.astype(np.float32), np.zeros(n), 0)
    with pytest.raises(TypeError, match="argument 2 must be a 1-D float64 array, got "
                                        "dtype.'float64'. of 2 dimensions"):
        lib.outcome_value(0, c.prepared, np.zeros((1, n)), 0)
    with pytest.raises(TypeError, match="missing 1 required positional argument"):
        lib.outcome_value(0, c.prepared, np.zeros(n))
    with pytest.raises(TypeError, match="argument 1 must be a 1-D int64 array"):
        lib.simulate_maneuver(c.prepared, _table(module).astype(np.float64), 0, 0.0,
                              np.zeros(1), np.zeros(abi.CFG_SIZE), np.zeros((0, 1)),
                              np.zeros((1, 1)), np.zeros(n), np.empty(0), 0)
    with pytest.raises(TypeError, match="outcome_value: argument 1: TypeError"):  # (ctypes's)
        lib.outcome_value(0.0, c.prepared, np.zeros(n), 0)


def test_a_strided_array_is_read_and_written_as_numba_does(libs):
    # the Numba function takes a strided view as it is (another specialisation); the library
    # passes a contiguous copy and copies it back: the same values read, the same ones written
    c, module, lib = libs["biped"]
    n = module.NSTATE
    for fn in (module.initial_state, lib.initial_state):
        y = np.full(2 * n, -1.0)
        fn(c.code("touchdown"), 0.05, c.prepared, y[::2])
        if fn is module.initial_state:
            expected = y.copy()
        else:
            np.testing.assert_array_equal(y, expected)
    assert (expected[1::2] == -1.0).all() and (expected[::2] != -1.0).any()
    y = np.ascontiguousarray(expected[::2])
    wide = np.zeros(3 * n)
    wide[::3] = y
    assert lib.outcome_value(0, c.prepared, wide[::3], 0) == module.outcome_value(
        0, c.prepared, y, 0)
    frozen = wide[::3]
    frozen.flags.writeable = False  # (read-only: copied in, nothing copied back)
    assert lib.outcome_value(0, c.prepared, frozen, 0) == module.outcome_value(
        0, c.prepared, y, 0)


def test_a_failure_inside_is_raised_not_returned(libs):
    c, module, lib = libs["rocking_bar"]
    handle = lib._lib._handle
    # the runtime's error path, as Numba's code takes it (with the interpreter lock held: a
    # PyDLL call): counted, and a Python error set
    pylib = ctypes.PyDLL(str(lib.path), handle=handle)
    count = ctypes.c_long.in_dll(lib._lib, "biped_opt_native_error_count")  # (what calls read)
    before = count.value
    with pytest.raises(RuntimeError, match="the compiled kernel failed"):
        pylib.numba_do_raise(None)
    assert count.value == before + 1
    # a call during which the count moves is an error, whatever it wrote
    failing = native._caller(lib._lib, "outcome_value", iter(range(100)).__next__)
    with pytest.raises(native.NativeKernelError, match="nothing it wrote is a result"):
        failing(0, c.prepared, np.zeros(module.NSTATE), 0)


def test_a_library_loads_in_a_process_without_numba(libs):
    c, module, lib = libs["rocking_bar"]
    code = textwrap.dedent(f"""
        import sys
        import numpy as np
        from biped_opt.codegen import native
        k = native.load(__import__("pathlib").Path({str(lib.path)!r}))
        y = np.zeros({module.NSTATE})
        k.initial_state(0, 0.05, np.array({c.prepared.tolist()!r}), y)
        heavy = sorted(m for m in sys.modules if m.startswith(("numba", "llvmlite")))
        print(repr(y.tolist()), heavy)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120).stdout.strip()
    y = np.zeros(module.NSTATE)
    module.initial_state(0, 0.05, c.prepared, y)
    assert out == f"{y.tolist()!r} []"


def test_without_a_c_compiler_nothing_is_built_and_starts_load_through_numba(libs, tmp_path,
                                                                             monkeypatch):
    from biped_opt.codegen import aot

    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    monkeypatch.setenv("BIPED_OPT_AOT", "1")
    assert native.compiler() is None
    module_path = tmp_path / "sys_0123.py"
    module_path.write_text("")
    assert aot.start(module_path, "biped_opt_sys_0123", "sys_0123") is None  # (no build)
    assert not list(tmp_path.glob(".*lock"))
    with pytest.raises(OSError, match="no C compiler"):
        native.build(tmp_path / "x.so", None)


def test_the_extension_is_built_where_the_library_cannot_be(libs, tmp_path, monkeypatch):
    # the order of aot.KINDS: a library that fails to build (its linker refuses, say) leaves the
    # pycc extension, which then serves single trajectories, bit for bit
    from biped_opt.codegen import aot

    c, module, lib = libs["rocking_bar"]
    path = tmp_path / "rocking_bar_copy.py"
    path.write_text(open(module.__file__).read())

    def refuse(*_args, **_kwargs):
        raise subprocess.CalledProcessError(1, "cc", stderr=b"ld: unknown option -Bsymbolic")

    monkeypatch.setattr(native, "build", refuse)
    monkeypatch.setenv("BIPED_OPT_AOT", "1")
    made = aot.build(path, "rocking_bar_copy")
    assert made == aot.extension_path(tmp_path, "rocking_bar_copy") and made.is_file()
    assert not aot.native_path(tmp_path, "rocking_bar_copy").exists()
    ext = aot.load(tmp_path, "rocking_bar_copy")
    assert not hasattr(ext, "simulate_batch_kernel")
    options = c.maneuver_options("drop")
    outs = []
    for fn in (ext.simulate_maneuver, lib.simulate_maneuver):
        events = np.zeros((options.max_events + 1, module.EVENT_WIDTH))
        y = np.zeros(module.NSTATE)
        outs.append((fn(c.prepared, _table(module), c.code("drop"), 1e-9, c.input_vector(None),
                        kernel_config(options, 0.0), np.zeros((0, module.SAMPLE_WIDTH)),
                        events, y, np.empty(0), 0), events, y))
    assert outs[0][0] == outs[1][0]
    np.testing.assert_array_equal(outs[0][1], outs[1][1])
    np.testing.assert_array_equal(outs[0][2], outs[1][2])
