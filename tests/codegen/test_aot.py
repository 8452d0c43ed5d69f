"""The kernel compiled ahead of time (biped_opt/codegen/aot.py), of both kinds: the kernel
library (llvmlite object code, biped_opt/codegen/native.py) and the pycc extension. The same
trajectories, bit for bit, as the shared kernel that calls the system's functions through their
addresses (biped_opt/codegen/kernel.py, abi.py), and a cached start that imports neither Numba,
SymPy nor SciPy (the optimiser: SciPy only)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from biped_opt.codegen import abi, aot
from biped_opt.simulation.compiled import (
    _MODULE_PREFIX,
    CompiledSystem,
    _AheadModule,
    cache_dir,
    cached_module,
    kernel_config,
)

ROOT = Path(__file__).resolve().parents[2]

# (system, maneuver, inputs, s values): each maneuver's coincidence of events at s = 0 (both
# feet, or both ends of the bar, at once) and 1e-9 on either side (the bar's ends then land
# within the simulator's 1e-9 s of each other: one simultaneous event), 1e-8 on either side for
# the bar (two events, in either order: the outcome flips), plus ordinary values
CASES = [
    ("rocking_bar", "drop", None, [-0.1, -1e-8, -1e-9, 0.0, 1e-9, 1e-8, 0.05]),
    ("biped", "touchdown", (0.1, -0.2, 0.05), [-0.2, -1e-9, 0.0, 1e-9, 0.1]),
    ("biped", "liftoff", (2.0, 1.5, 0.3), [-0.1, -1e-9, 0.0, 1e-9, 0.15]),
]


def build_kind(kind: str, names=("rocking_bar", "biped")) -> dict:
    """The ahead-of-time kernel of ``kind`` of each system's module, built in this process
    (once per module: later runs find it in the cache): name -> (compiled, module, kernel)."""
    before = os.environ.get("BIPED_OPT_AOT")
    os.environ["BIPED_OPT_AOT"] = kind
    try:
        out = {}
        for name in names:
            c = CompiledSystem(name)
            c.gradients()  # (rendered into the cache: the optimiser's starts import them)
            module = cached_module(name)  # (the module itself, not a view of it)
            assert module is not None
            stem = module.__name__[len(_MODULE_PREFIX):]
            if aot.build_once(Path(module.__file__), stem) is None:  # (built, or being built
                aot.wait_built(cache_dir(), stem, 600.0)  # by the compile's second process)
            out[name] = (c, module, aot.load(cache_dir(), stem))
            assert out[name][2] is not None
        return out
    finally:
        os.environ["BIPED_OPT_AOT"] = "0" if before is None else before


@pytest.fixture(scope="module", params=aot.KINDS)
def built(request):
    """Both kinds, built (each test runs on each kind, with BIPED_OPT_AOT set to it)."""
    out = build_kind(request.param)
    os.environ["BIPED_OPT_AOT"] = request.param
    request.addfinalizer(lambda: os.environ.__setitem__("BIPED_OPT_AOT", "0"))
    return out


def _run(fn, sv, c, module, code, s, u, sample_dt):
    options = c.maneuver_options(c.maneuvers[code])
    cfg = kernel_config(options, sample_dt)
    samples = np.zeros((int(options.t_end / sample_dt) + 200, module.SAMPLE_WIDTH)) if sample_dt \
        else np.empty((0, module.SAMPLE_WIDTH))
    events = np.zeros((options.max_events + 1, module.EVENT_WIDTH))
    y_out = np.zeros(module.NSTATE)
    result = fn(c.prepared, sv, code, s, u, cfg, samples, events, y_out, np.empty(0), 0)
    return result, y_out, events[: result[3]], samples[: result[4]]


@pytest.mark.parametrize("sample_dt", [0.0, 0.01])
@pytest.mark.parametrize(("system", "maneuver", "inputs", "ss"), CASES)
def test_same_trajectories_bit_for_bit(built, system, maneuver, inputs, ss, sample_dt):
    # the same source, no fast-math in either compile: every event time, state, sample and
    # counter must be equal exactly, not to a tolerance
    c, module, ahead_kernel = built[system]
    code = c.code(maneuver)
    u = c.input_vector(inputs)
    kernel, sv = c.shared_kernel()
    table = np.concatenate((np.zeros(abi.NFUNC, dtype=np.int64), module.SYSTEM_TABLE))
    assert sv[abi.NFUNC:].tolist() == table[abi.NFUNC:].tolist() and sv[:abi.NFUNC].all()
    outcomes = []
    for s in ss:
        jit = _run(kernel.simulate_maneuver, sv, c, module, code, s, u, sample_dt)
        ahead = _run(ahead_kernel.simulate_maneuver, table, c, module, code, s, u, sample_dt)
        assert ahead[0] == jit[0]
        for a, b in zip(ahead[1:], jit[1:]):
            np.testing.assert_array_equal(a, b)
        assert jit[0][0] == 0  # (status OK: a real trajectory, not an early stop)
        outcomes.append(jit[0][-1])
    if system == "rocking_bar":  # the cases straddle the coincidence: the outcome flips sign
        assert outcomes[1] * outcomes[5] < 0 and outcomes[2:5] == [0.0] * 3


def test_a_start_from_the_index_uses_the_kernel_and_loads_the_rest_on_demand(built,
                                                                               monkeypatch):
    from biped_opt.simulation import compiled

    # a process that has imported the module uses it as it is
    assert not isinstance(CompiledSystem("rocking_bar").module, _AheadModule)
    # one that has not (as a new process: the module forgotten here) gets the kernel's view
    stem = built["rocking_bar"][1].__name__[len(_MODULE_PREFIX):]
    monkeypatch.delitem(compiled._LOADED, stem)
    monkeypatch.setattr(compiled, "_AHEAD", {})
    c = CompiledSystem("rocking_bar")
    assert isinstance(c.module, _AheadModule)
    tr = c.simulate("drop", 0.05, sample_dt=0.01)
    ref = built["rocking_bar"][0].simulate("drop", 0.05, sample_dt=0.01)
    assert tr.outcome == ref.outcome and tr.status == ref.status
    np.testing.assert_array_equal(tr.samples, ref.samples)
    # a batch from the library, or (the extension has only single trajectories) from the module
    batch = c.simulate_batch("drop", np.array([0.05, -0.05]))
    np.testing.assert_array_equal(batch.outcome, [ref.outcome, -ref.outcome])
    assert ("simulate_batch_kernel" in c.module.entries) == (os.environ["BIPED_OPT_AOT"] ==
                                                             "native")
    assert c.module.NDOF == 3 and "NDOF" in vars(c.module)  # (from the index, not the module)


_HEAVY = """
import json, sys
from biped_opt.cli.main import main
status = main(sys.argv[1:])
heavy = sorted(m for m in sys.modules if m.split(".")[0] in ("numba", "sympy", "scipy", "llvmlite"))
print(json.dumps({"status": status, "heavy": heavy}))
"""


#: (command, what it may import of the heavy packages from a cached start with each kind: the
#: library serves every command's kernel calls, the extension only single trajectories)
STARTS = [
    (["simulate", "--system", "rocking_bar", "--maneuver", "drop", "--s", "0.05"],
     {"native": (), "extension": ()}),
    (["simulate", "--maneuver", "touchdown", "--theta0", "1e-9", "--u1", "0.1"],
     {"native": (), "extension": ()}),
    (["sweep", "--maneuver", "touchdown", "--theta0-min", "-0.1", "--theta0-max", "0.1", "--num",
      "21", "--no-progress"], {"native": ()}),
    (["sweep", "--system", "rocking_bar", "--maneuver", "drop", "--num", "9", "--no-progress"],
     {"native": ()}),
    (["nonsmooth", "--maneuver", "touchdown", "--num", "41"], {"native": ()}),
    # (the walker of the pieces study, by its library name: built for this case only)
    (["pieces", "--legs", "2", "--rounds", "1", "--samples", "20", "--no-derivative", "--json"],
     {"native": ()}),
    # (the optimiser is SciPy's and its Theorem 1 derivatives integrate with solve_ivp: SciPy;
    # the problem's names come from the index and the gradients from the cache: no SymPy)
    (["optimise", "--maneuver", "touchdown", "--theta0", "0.05"], {"native": ("scipy",)}),
    (["optimise", "--system", "rocking_bar", "--problem", "drop", "--s", "0.1"],
     {"native": ("scipy",)}),
]


@pytest.mark.parametrize(("args", "allowed"), STARTS, ids=lambda v: " ".join(v[:3])
                         if isinstance(v, list) else None)
def test_a_cached_cli_start_imports_no_numba(built, args, allowed):
    kind = os.environ["BIPED_OPT_AOT"]
    if kind not in allowed:
        pytest.skip(f"the {kind} kernel does not serve {args[0]} (it loads through Numba)")
    if args[0] == "pieces":
        build_kind(kind, names=("walker2_coupled_offsets",))

    def run(ahead: str):
        env = dict(os.environ, BIPED_OPT_AOT=ahead,
                   PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
        done = subprocess.run([sys.executable, "-c", _HEAVY, *args], env=env, text=True,
                              capture_output=True, timeout=300, check=False)
        assert done.returncode == 0, done.stderr
        return done.stdout.splitlines()

    ahead, jit = run(kind), run("0")
    report = json.loads(ahead[-1])
    assert report["status"] == 0
    assert {m.split(".")[0] for m in report["heavy"]} <= set(allowed[kind])
    assert "numba" in json.loads(jit[-1])["heavy"]  # (the check can fail: without, it loads)
    assert ahead[:-1] == jit[:-1]  # the same printout, every digit


def test_a_broken_file_is_ignored(built, tmp_path, monkeypatch):
    kind = os.environ["BIPED_OPT_AOT"]
    path = (aot.native_path if kind == "native" else aot.extension_path)(tmp_path, "nothing_0123")
    path.write_bytes(b"not a shared object")
    assert aot.load(tmp_path, "nothing_0123") is None
    monkeypatch.setenv("BIPED_OPT_AOT", "0")
    stem = built["rocking_bar"][1].__name__[len(_MODULE_PREFIX):]
    assert aot.load(cache_dir(), stem) is None  # (turned off: not even a built one is used)


def test_one_build_per_module_and_a_dead_builds_lock_expires(tmp_path):
    lock = tmp_path / ".x_aot.lock"
    assert aot._take_lock(lock)
    assert not aot._take_lock(lock)  # a live build holds it
    old = time.time() - aot.STALE_LOCK_S - 60
    os.utime(lock, (old, old))
    assert aot._take_lock(lock)  # its builder died long ago

