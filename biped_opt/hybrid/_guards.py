"""Guards of the biped's maneuvers at states whose reaction forces are already known.

Every event is "a guard falls through zero" (MODEL.md Sec. 3):

- guard j < 2 (foot j): a_j(q) = z_j while foot j is in the air (touchdown), lambda_j while it is on
  the ground (liftoff);
- guard 2 (termination): ``term_sign * z'``: -z' ends the touchdown maneuver at the body's nadir,
  +z' ends the liftoff maneuver at its apex.

The integrator evaluates the vector field (and with it the reactions lambda) at every stage and
step end, so these guards cost no extra evaluation there. Guards at other states (on the dense
output, at an event) are in :mod:`biped_opt.hybrid._kernel`.
"""

from __future__ import annotations

import numba as nb

from biped_opt._jit import HOT_PATH

NGUARDS = 3


@nb.njit(**HOT_PATH, inline="always")
def contact_guard(mode, j, y, yo, lam, lo):
    """Guard of foot j: its reaction lambda_j = lam[lo + j] in contact, its height z_j in the air
    (state at y[yo:yo + 14])."""
    return lam[lo + j] if mode >> j & 1 else y[yo + 4 + 2 * j]


@nb.njit(**HOT_PATH, inline="always")
def guard_values(mode, term_sign, y, lam, out):
    """All guards at the state y, whose reactions lam are known."""
    out[0] = contact_guard(mode, 0, y, 0, lam, 0)
    out[1] = contact_guard(mode, 1, y, 0, lam, 0)
    out[2] = term_sign * y[8]


@nb.njit(**HOT_PATH, inline="always")
def probe_stage(mode, term_sign, y, yo, lam, lo, c, c0, c1, c2):
    """(c0, c1, c2) updated with the stage at abscissa c: ci = min(ci, c) for each guard i that is
    <= 0 at the stage state y[yo:yo + 14] (reactions lam[lo:lo + 2]). The stages sample the step's
    interior for free, which catches a guard that dips below zero and comes back within one step.
    (Values, not an array: the step keeps them in registers.)"""
    if contact_guard(mode, 0, y, yo, lam, lo) <= 0.0 and c < c0:
        c0 = c
    if contact_guard(mode, 1, y, yo, lam, lo) <= 0.0 and c < c1:
        c1 = c
    if term_sign * y[yo + 8] <= 0.0 and c < c2:
        c2 = c
    return c0, c1, c2
