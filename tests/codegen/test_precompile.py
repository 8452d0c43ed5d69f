"""The second compile process: its signatures are the kernel's calls, and it fills the cache."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import numba as nb
import numpy as np

from biped_opt.codegen import precompile
from biped_opt.simulation.compiled import compile_system


def test_signatures_are_the_kernels_calls():
    """Each function the second process compiles, with the types it compiles it for, is one the
    kernel calls with those types: a signature that drifted from the kernel's call would be
    compiled for nothing, and this fails. (A kernel loaded from the cache carries its callees
    inside, so a fresh, uncached copy of it is compiled here: typing it resolves every call.)"""
    bar = compile_system("rocking_bar")
    m = bar.module
    fresh = nb.njit(error_model="numpy")(m.simulate_maneuver.py_func)
    out = fresh(bar.prepared, 0, 0.1, np.zeros(1), bar._maneuver_cfgs[0],
                np.empty((0, m.SAMPLE_WIDTH)), np.empty((17, m.EVENT_WIDTH)), np.empty(m.NSTATE),
                np.empty(0), 0)
    assert out[0] == 0  # OK
    expected = {**precompile.signatures(),
                "step": precompile._types(precompile.STEP_SIGNATURE)}
    for fn, sig in expected.items():
        assert sig in getattr(m, fn).signatures, (fn, getattr(m, fn).signatures)


def test_second_process_writes_the_cache(tmp_path):
    """Run on a copy of a generated module in an empty directory, the process exits 0 and leaves
    a Numba cache index for every function it was given."""
    bar = compile_system("rocking_bar")
    source = bar.module.__file__
    copy = tmp_path / os.path.basename(source)
    shutil.copyfile(source, copy)
    name = "biped_opt_systems_precompile_test_" + copy.stem
    proc = subprocess.run([sys.executable, "-m", "biped_opt.codegen.precompile", str(copy), name],
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    written = {p.name.split(".")[1].split("-")[0] for p in (tmp_path / "__pycache__").glob("*.nbi")}
    assert set(precompile.SIGNATURES) <= written


def test_turned_off_by_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("BIPED_OPT_PRECOMPILE", "0")
    assert precompile.start(tmp_path / "absent.py", "absent") is None
