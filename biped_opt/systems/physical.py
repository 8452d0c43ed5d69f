"""Whether parameter values make a mechanical system (paper Eq. (1)): a mass matrix M(q) that
is positive definite (the kinetic energy q'^T M q' / 2 is positive for every q' != 0), and a
restitution in [0, 1].

A description declares its parameters with defaults only; a user who sets one (``--param
m=-1``) may make M indefinite, which the simulator would integrate all the same (M stays
invertible) into accelerations of no mechanical system. :func:`check_physical` checks M at a
maneuver's initial configuration, q0(s): from the declared ``mass_matrix``, or for a tree of
bodies (SYSTEMS.md Sec. 1a) body by body (no mass negative: a massless body is a frame
between joints; each inertia positive semidefinite: a point mass has none), and the
restitution where it is a number or an expression of the parameters.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import sympy as sp

from biped_opt.errors import InvalidParameterError
from biped_opt.systems.description import System

__all__ = ["check_physical"]

#: how far below zero an eigenvalue may be and still count as zero (rounding of a zero inertia)
TOLERANCE = 1e-12


def _changed(values: Mapping[str, float], system: System) -> str:
    changed = [f"{k}={v:g}" for k, v in values.items() if system.defaults.get(k) != v]
    return f" ({', '.join(changed)})" if changed else ""


def _number(expression: Any, subs: Mapping[Any, float]) -> float:
    return float(sp.sympify(expression).subs(subs))


def check_physical(system: System, values: Mapping[str, float], maneuver: str, s: float
                   ) -> None:
    """Raise :class:`InvalidParameterError` when ``values`` (all of the system's parameters)
    give no mechanical system at the start of ``maneuver`` from ``s`` (see the module
    docstring); the message names the values that differ from the defaults."""
    params = {system.p[name]: float(value) for name, value in values.items()}
    where = f"{system.name}: the parameters{_changed(values, system)}"
    if system.restitution is not None:
        try:
            gamma = _number(system.restitution, params)
        except (TypeError, ValueError):
            gamma = None  # (an expression of more than the parameters: not checked here)
        if gamma is not None and not 0.0 <= gamma <= 1.0:
            raise InvalidParameterError(f"{where} give a restitution of {gamma:g}; it must be "
                                        "in [0, 1]")
    for body in system.bodies.values():
        mass = _number(body.mass, params)
        inertia = np.array([[_number(v, params) for v in row] for row in body.inertia])
        if not mass >= 0.0:
            raise InvalidParameterError(f"{where} give body {body.name} a mass of {mass:g}; "
                                        "a mass cannot be negative")
        smallest = float(np.linalg.eigvalsh((inertia + inertia.T) / 2).min())
        if smallest < -TOLERANCE:
            raise InvalidParameterError(
                f"{where} give body {body.name} an inertia that is not positive semidefinite "
                f"(smallest principal moment {smallest:g})")
    if system.mass_matrix is None:
        return
    description = system.maneuvers[maneuver]
    subs: dict[Any, float] = {**params, system.s: float(s)}
    q0 = [_number(description.initial.get(q, 0), subs) for q in system.q]
    matrix = sp.Matrix(system.mass_matrix)
    evaluate = sp.lambdify([list(system.q), list(params)], matrix, "numpy")
    numbers = np.array(evaluate(q0, list(params.values())), dtype=float)
    smallest = float(np.linalg.eigvalsh((numbers + numbers.T) / 2).min())
    if not smallest > 0.0:
        raise InvalidParameterError(
            f"{where} give a mass matrix that is not positive definite at the start of "
            f"{maneuver} (smallest eigenvalue {smallest:g}): masses and inertias must be "
            "positive")
