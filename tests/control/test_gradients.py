"""The gradients Theorem 1's derivatives take from the description (biped_opt/codegen/gradients.py,
CompiledSystem.gradients) against central differences of the generated module's own functions
(the initial state, the constraints, the terminal guard and the outcome: other code, written by
the renderer), at parameter values other than the defaults; and a second process reads them from
the cache without SymPy."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from biped_opt.control.derivatives import _symbolic
from biped_opt.simulation.compiled import compiled_with

ROOT = Path(__file__).resolve().parents[2]

#: (system, non-default parameters): a change of each shows in the gradients
CASES = [("biped", {"l0": 1.13, "w": 0.31}), ("rocking_bar", {}), ("walker", {})]
#: fourth-order central differences with step H on quantities of order 1 are good to
#: ~H^4 + eps / H ~ 1e-11; the tolerance leaves room for curvature of order 10
H, TOL = 1e-3, 1e-8


def _central(f, x: np.ndarray) -> np.ndarray:
    """The Jacobian of f at x, column by column, by the fourth-order stencil."""
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = H
        cols.append((-f(x + 2 * e) + 8 * f(x + e) - 8 * f(x - e) + f(x - 2 * e)) / (12 * H))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize(("name", "parameters"), CASES, ids=[c[0] for c in CASES])
def test_gradients_match_central_differences_of_the_module(name, parameters):
    c = compiled_with(name, parameters)
    mod, p = c.module, c.prepared
    rng = np.random.default_rng(7)
    n, d = int(mod.NSTATE), int(mod.NDOF)
    u = rng.uniform(-1, 1, max(len(c.inputs), 1))
    for maneuver in c.maneuvers:
        code = c.code(maneuver)
        sym = _symbolic(c, maneuver)
        lo, hi = c.s_range(maneuver)
        s = lo + 0.37 * (hi - lo)

        def x0(sv: np.ndarray, code: int = code) -> np.ndarray:
            y0 = np.zeros(n)
            mod.initial_state(code, float(sv[0]), p, y0)
            return y0

        np.testing.assert_allclose(np.ravel(sym.initial_rate(s)),
                                   _central(x0, np.array([s]))[:, 0], rtol=TOL, atol=TOL)
        y = x0(np.array([s])) + rng.uniform(-0.1, 0.1, n)
        m = len(c.inputs)

        def terminal(x: np.ndarray, code: int = code, m: int = m) -> np.ndarray:
            uu = u.copy()
            uu[:m] = x[n:]
            return np.array([mod.terminal_value(code, p, uu, x[:n], 0)])

        np.testing.assert_allclose(np.ravel(sym.terminal_gradient(*y, *u[:m])),
                                   _central(terminal, np.concatenate([y, u[:m]]))[0],
                                   rtol=TOL, atol=TOL)

        def outcome(x: np.ndarray, code: int = code) -> np.ndarray:
            return np.array([mod.outcome_value(code, p, x, 0)])

        np.testing.assert_allclose(np.ravel(sym.outcome_gradient(*y)), _central(outcome, y)[0],
                                   rtol=TOL, atol=TOL)

    def constraints(q: np.ndarray) -> np.ndarray:
        yy = np.concatenate([q, y[d:]])
        return np.array([mod.constraint_value(j, p, yy, 0) for j in range(int(mod.NCON))])

    jac = np.asarray(_symbolic(c, c.maneuvers[0]).jacobian(*y[:d]), dtype=np.float64)
    np.testing.assert_allclose(jac.reshape(int(mod.NCON), d), _central(constraints, y[:d]),
                               rtol=TOL, atol=TOL)


def test_the_parameters_reach_the_gradients():
    """Two parameter sets of one system: one module, different numbers (the values are
    arguments, not baked in)."""
    a, b = compiled_with("biped"), compiled_with("biped", {"l0": 1.13})
    assert a.gradients() is b.gradients()
    ra, rb = (np.ravel(_symbolic(c, "touchdown").initial_rate(0.1)) for c in (a, b))
    assert not np.allclose(ra, rb)


_PROBE = """
import json, sys
from biped_opt.control.theorem1 import optimal_derivatives
from biped_opt.control.problems import get_problem
d = optimal_derivatives(get_problem("rocking_bar", "drop"), 0.1)
print(json.dumps({"value": list(d.value), "sympy": "sympy" in sys.modules}))
"""


def test_a_second_process_reads_them_without_sympy():
    c = compiled_with("rocking_bar")
    c.gradients()  # (in the cache from here)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT),
                                                       os.environ.get("PYTHONPATH", "")]))
    out = [json.loads(subprocess.run([sys.executable, "-c", _PROBE], env=env, text=True,
                                     capture_output=True, check=True, timeout=600).stdout)
           for _ in range(2)]
    assert out[1]["sympy"] is False
    assert out[0]["value"] == out[1]["value"]
