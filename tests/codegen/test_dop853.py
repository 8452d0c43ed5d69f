"""The generated DOP853 step: of the orders it claims, laid out as documented, and free of
reference counting in the biped's module."""

from __future__ import annotations

import importlib
import math
import re
import sys

import numpy as np
import pytest

from biped_opt.codegen import dop853
from biped_opt.paper.biped import BipedParams, compiled_biped
from tests.paper.biped_physics import initial_state

_OSCILLATOR = '''
import numba as nb


@nb.njit(cache=True, inline="always")
def oscillator(p, mode, y, yo, u, out, off, lam, lo):
    """q'' = -q as (q, v): the exact flow is a rotation."""
    out[off] = y[yo + 1]
    out[off + 1] = -y[yo]
    lam[lo] = 0.0
    lam[lo + 1] = 0.0


@nb.njit(cache=True, inline="always")
def no_probe(mode, term_sign, y, yo, lam, lo, c, c0, c1, c2):
    return c0, c1, c2
'''


def _oscillator_module(tmp_path_factory, form: str):
    """The template rendered for a 2-state oscillator in ``form`` (stages written out, or as a
    loop), imported from a temporary directory."""
    name = f"osc_dop853_{form}"
    if name in sys.modules:
        return sys.modules[name]
    d = tmp_path_factory.mktemp(name)
    (d / "osc_rhs.py").write_text(_OSCILLATOR)
    (d / f"{name}.py").write_text(
        dop853.render(
            n=2,
            imports="from biped_opt._jit import HOT_PATH\nfrom osc_rhs import no_probe, oscillator",
            rhs="oscillator",
            probe="no_probe",
            loop=form == "loop",
        )
    )
    sys.path.insert(0, str(d))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(d))


@pytest.fixture(scope="module", params=["written_out", "loop"])
def oscillator_step(tmp_path_factory, request):
    """The oscillator's step in each form."""
    return _oscillator_module(tmp_path_factory, request.param)


def _one_step(mod, h):
    y = np.array([1.0, 0.0])
    f = np.array([0.0, -1.0])
    W = np.zeros(mod.WORKSPACE)
    y_new, f_new, lam, probe = np.empty(2), np.empty(2), np.empty(2), np.empty(3)
    empty = np.empty(0)
    err = mod.step(empty, 0, empty, 1.0, y, f, h, W, y_new, f_new, lam, 1e-10, 1e-10, probe)
    F = np.empty((7, 2))
    mod.dense_coefficients(empty, 0, empty, y, f, h, W, y_new, f_new, F)
    x, xm = 0.5, 0.5  # the interpolant at mid-step (SciPy's Dop853DenseOutput form)
    mid = y + x * (F[0] + xm * (F[1] + x * (F[2] + xm * (F[3] + x * (F[4] + xm * (
        F[5] + x * F[6]))))))
    exact_end = np.array([math.cos(h), -math.sin(h)])
    exact_mid = np.array([math.cos(h / 2), -math.sin(h / 2)])
    return err, np.abs(y_new - exact_end).max(), np.abs(mid - exact_mid).max(), f_new


def test_step_is_eighth_order_and_dense_output_seventh(oscillator_step):
    """Halving h divides the local error of the step by ~2^9 (order 8) and that of the
    interpolant at mid-step by ~2^8 (order 7). h = 0.4 and 0.2 keep both errors (1e-9 to
    1e-14) far above rounding, so the observed orders are within ~0.3 of the asymptotic ones;
    one coefficient wrong in its fifth digit drops them to 6 and 5."""
    _, e_big, d_big, _ = _one_step(oscillator_step, 0.4)
    _, e_small, d_small, f_new = _one_step(oscillator_step, 0.2)
    assert math.log2(e_big / e_small) > 8.6
    assert math.log2(d_big / d_small) > 7.6
    # FSAL: the returned derivative is the vector field at the new point
    assert f_new == pytest.approx([-math.sin(0.2), -math.cos(0.2)], abs=1e-13)


def test_both_forms_give_the_same_numbers_to_the_last_bit(tmp_path_factory):
    """The stages as a loop add the same terms in the same order as the written-out stages, so a
    step, its error estimate, the derivative at the new point and the dense output's
    coefficients agree bit for bit (a term added out of order would change the last bits)."""
    forms = [_oscillator_module(tmp_path_factory, f) for f in ("written_out", "loop")]
    outs = []
    for mod in forms:
        y, f = np.array([0.3, -1.7]), np.array([-1.7, -0.3])
        W = np.zeros(mod.WORKSPACE)
        y_new, f_new, lam, probe = np.empty(2), np.empty(2), np.empty(2), np.empty(3)
        empty = np.empty(0)
        err = mod.step(empty, 0, empty, 1.0, y, f, 0.37, W, y_new, f_new, lam, 1e-9, 1e-10, probe)
        F = np.empty((7, 2))
        mod.dense_coefficients(empty, 0, empty, y, f, 0.37, W, y_new, f_new, F)
        outs.append((err, y_new, f_new, F))
    assert outs[0][0] == outs[1][0]
    for a, b in zip(outs[0][1:], outs[1][1:]):
        np.testing.assert_array_equal(a, b)


def test_error_estimate_shrinks_with_the_step(oscillator_step):
    """The scaled error estimate falls by ~2^8 when h halves (what the step controller uses)."""
    err_big = _one_step(oscillator_step, 0.4)[0]
    err_small = _one_step(oscillator_step, 0.2)[0]
    assert 7.0 < math.log2(err_big / err_small) < 9.5


def test_biped_workspace_layout():
    """Slots of 14 derivatives + 2 reactions, 16 stage slots, then the stage and initial states;
    after a step of the biped's module slot 12 holds the vector field and reactions at the new
    point, equal to a separate evaluation there (bit for bit: the same arithmetic, in the step
    as text and in the field as a call)."""
    k = compiled_biped()
    m, p = k.module, k.prepared
    assert m.STRIDE == 16
    assert m.WORKSPACE == 18 * 16
    y, mode = initial_state("liftoff", 0.1, BipedParams())
    u = np.array([1.5, 3.0, 0.2])
    f, lam0 = np.empty(14), np.empty(2)
    m._field_at(p, int(mode), y, 0, u, f, 0, lam0, 0)
    W = np.full(m.WORKSPACE, np.nan)
    y_new, f_new, lam, probe = np.empty(14), np.empty(14), np.empty(2), np.empty(3)
    code = k.code("liftoff")
    err = m.step(p, int(mode), u, code, y, f, 0.01, W, y_new, f_new, lam, 1e-11, 1e-12, probe)
    assert 0.0 < err < 1.0
    k12 = 12 * m.STRIDE
    dy_check, lam_check = np.empty(14), np.empty(2)
    m._field_at(p, int(mode), y_new, 0, u, dy_check, 0, lam_check, 0)
    np.testing.assert_array_equal(W[k12 : k12 + 14], dy_check)
    np.testing.assert_array_equal(W[k12 + 14 : k12 + 16], lam_check)
    np.testing.assert_array_equal(f_new, dy_check)
    np.testing.assert_array_equal(lam, lam_check)
    assert lam_check.min() > 0.0  # both feet still pressed on the ground: the check means something
    y_slot = m.SLOT_Y * m.STRIDE
    np.testing.assert_array_equal(W[y_slot : y_slot + 14], y)
    np.testing.assert_array_equal(W[m.SLOT_STAGE * m.STRIDE :][:14], y_new)


def test_step_has_no_reference_counting():
    """The biped module's step has no array reference counting.

    Numba increments and decrements an array's reference count (atomic operations, a barrier to
    reordering) around every inlined function that takes it, and removes the pair only when no
    branch separates them: with a mode-dependent branch in an inlined vector field ~18 pairs per
    stage survived (a whole simulation ~11% slower). The generated step has the vector field
    and guard probes written out as text and calls nothing that takes an array. (The cached
    step cannot be inspected, so a fresh, uncached copy of it is compiled here.)
    """
    import numba as nb

    k = compiled_biped()
    m, p = k.module, k.prepared
    fresh = nb.njit(error_model="numpy")(m.step.py_func)
    y, mode = initial_state("liftoff", 0.1, BipedParams())
    u = np.array([1.5, 3.0, 0.2])
    f, lam = np.empty(14), np.empty(2)
    m._field_at(p, int(mode), y, 0, u, f, 0, lam, 0)
    W = np.zeros(m.WORKSPACE)
    out = [np.empty(14), np.empty(14), np.empty(2), np.empty(3)]
    fresh(p, int(mode), u, k.code("liftoff"), y, f, 0.01, W, out[0], out[1], out[2], 1e-11, 1e-12,
          out[3])
    ir = fresh.inspect_llvm(fresh.signatures[0])
    start = ir.index("define ")  # the step itself comes first, then its Python wrappers
    body = ir[start : ir.index("\n}\n", start)]
    assert not re.search(r"call [^(]*@\S*vector_field", body)
    assert body.count("@NRT_incref") == 0
    assert body.count("@NRT_decref") == 0
