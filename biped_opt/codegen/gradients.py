"""The gradients Theorem 1's derivatives start and end with, as a plain NumPy module.

The variational equations (:mod:`biped_opt.control.derivatives`) need four derivatives of a
system's description besides its vector fields, guards and resets (which the generated module and
its kernel compute):

- ``jacobian(q, p)``: Da(q), the constraints' Jacobian;
- ``initial_rate_<k>(s, p)``: d x0 / ds of maneuver k's initial state;
- ``terminal_gradient_<k>(q, q', u, p)``: D_(q, q', u) of maneuver k's terminal guard;
- ``outcome_gradient_<k>(q, q', p)``: D_(q, q') of maneuver k's outcome;

each taking its variables one by one and then the parameter values in their declared order (k:
the maneuver's index in the generated module). :func:`render_gradients` writes them with SymPy's
NumPy printer (``lambdify``, common subexpressions eliminated) into one module that imports only
NumPy, so that a process which finds it in the cache computes derivatives without SymPy.
"""

from __future__ import annotations

import inspect
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from biped_opt.systems.derive import DerivedSystem

__all__ = ["render_gradients"]

#: what SymPy's lambdify runs before its NumPy functions (so the printed code means the same)
_HEADER = '''"""Gradients of {name}'s description (biped_opt.codegen.gradients); generated."""
import numpy
from numpy import *
from numpy.linalg import *

I = 1j
'''


def render_gradients(derived: DerivedSystem) -> str:
    """The module text of the docstring's functions for ``derived``."""
    import sympy as sp

    system = derived.system
    params = [system.p[k] for k in system.defaults]
    q, dq, u = list(system.q), list(system.dq), list(system.u)
    state = q + dq

    def function(name: str, expr: sp.Matrix, args: list[sp.Symbol]) -> str:
        made = sp.lambdify(args + params, expr, modules="numpy", cse=True)
        text = inspect.getsource(made)
        assert text.startswith("def _lambdifygenerated(")
        return text.replace("_lambdifygenerated", name, 1)

    parts = [_HEADER.format(name=system.name), function("jacobian", derived.jacobian, q)]
    for k, m in enumerate(derived.maneuvers.values()):
        parts += [
            function(f"initial_rate_{k}", sp.Matrix(m.initial).diff(system.s), [system.s]),
            function(f"terminal_gradient_{k}", sp.Matrix([m.terminal]).jacobian(state + u),
                     state + u),
            function(f"outcome_gradient_{k}", sp.Matrix([m.outcome]).jacobian(state), state)]
    return "\n\n".join(parts)
