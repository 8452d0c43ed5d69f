"""Dependent contacts seen from Python: which contact modes of a run have constraint rows that
are linearly dependent (docs/SYSTEMS.md Sec. 5, "Dependent contacts").

The compiled kernel continues such a mode in an independent subset of its constraints (a
basis) and keeps the others on their surface at zero reaction; the motion is unique, the
reactions are not. The tools built on one set of reactions per mode (the B-derivatives of
Theorem 1, whose orderings of simultaneous events assume independent constraints) ask
:func:`require_independent` first and refuse such a run with a message naming the mode.

The test is the kernel's (``DEPENDENT_TOL`` of :mod:`biped_opt.codegen.kernel`): a row whose
distance from the span of the others is below 1e-6 of its length depends on them. Here it is
read off the singular values of the mode's rows, relative to each row's length.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import numpy.typing as npt

from biped_opt.errors import SimulationError
from biped_opt.simulation.compiled import CompiledSystem
from biped_opt.simulation.trajectory import Trajectory, constraint_names

__all__ = ["DEPENDENT_TOL", "DependentContactsError", "jacobian", "rank", "require_independent"]

Array = npt.NDArray[np.float64]

#: as the kernel's: rows closer than this (relative to their length) to the span of the
#: others depend on them
DEPENDENT_TOL = 1e-6


class DependentContactsError(SimulationError):
    """A run visits a contact mode whose constraint rows are linearly dependent, and the
    method asked for assumes independent ones."""


def jacobian(compiled: CompiledSystem, y: npt.ArrayLike) -> Array:
    """Da(q) at the configuration of the state y (n x d): column k is the constraint rates
    Da q' at the unit velocity q' = e_k (exact: the rates are linear in q')."""
    state = np.array(y, dtype=np.float64)
    d = len(compiled.coordinates)
    out = np.empty((len(compiled.constraints), d))
    rates = np.empty(max(len(compiled.constraints), 1))
    rates_at = compiled.module.constraint_rates
    for k in range(d):
        state[d:] = 0.0
        state[d + k] = 1.0
        rates_at(compiled.prepared, state, 0, rates)
        out[:, k] = rates[: out.shape[0]]
    return out


def rank(compiled: CompiledSystem, mode: int, y: npt.ArrayLike) -> int:
    """The rank of the rows of Da that the constraints of ``mode`` (a bit mask) have at y,
    each row scaled to unit length first (a zero row counts for nothing)."""
    rows = jacobian(compiled, y)[[j for j in range(len(compiled.constraints)) if mode >> j & 1]]
    if rows.size == 0:
        return 0
    lengths = np.linalg.norm(rows, axis=1)
    rows = rows[lengths > 0.0] / lengths[lengths > 0.0, None]
    if rows.size == 0:
        return 0
    singular = np.linalg.svd(rows, compute_uv=False)
    return int(np.sum(singular > DEPENDENT_TOL))


def dependent_modes(compiled: CompiledSystem, tr: Trajectory
                    ) -> list[tuple[float, int, int]]:
    """(t, mode, rank) of each contact mode of ``tr`` whose rows are dependent, where it
    begins (the initial mode at the maneuver's initial state)."""
    y0 = np.zeros(len(tr.y_final))
    compiled.module.initial_state(compiled.code(tr.maneuver), tr.s, compiled.prepared, y0)
    starts: Iterable[tuple[float, int, Array]] = [
        (0.0, tr.initial_mode, y0), *((e.t, e.mask_after, e.state_after)
                                      for e in tr.contact_events)]
    found = []
    for t, mode, y in starts:
        if mode.bit_count() >= 2 and (r := rank(compiled, mode, y)) < mode.bit_count():
            found.append((t, mode, r))
    return found


def require_independent(compiled: CompiledSystem, tr: Trajectory, method: str) -> None:
    """Raise :class:`DependentContactsError` when a contact mode of ``tr`` has dependent rows,
    naming the mode, its rank and ``method`` (what assumes independent constraints)."""
    found = dependent_modes(compiled, tr)
    if not found:
        return
    t, mode, r = found[0]
    names = "+".join(constraint_names(mode, tr.constraints))
    raise DependentContactsError(
        f"{compiled.name}: {tr.maneuver} at s = {tr.s!r}: the contact mode {names} from t = "
        f"{t:.10g} has dependent constraints (rank {r} of "
        f"{mode.bit_count()}): {method} assumes independent constraints (its reactions and "
        "the orderings of simultaneous events are not unique here); the simulation, sweeps, "
        "nonsmooth tables and optimal policies by search do not need them")
