"""The compiled kernel's status codes and event kinds, importable without Numba.

The kernel (:mod:`biped_opt.codegen.kernel`) returns these codes; the simulation layer turns
them into its result types. :mod:`biped_opt.codegen.runtime` re-exports them to the generated
modules; a start that only reads results (a cached ``biped-opt simulate``) imports this module
alone.
"""

from __future__ import annotations

import enum

__all__ = ["EVENT_CONTACT", "EVENT_TERMINAL", "SEPARATION_TOL", "Status"]


#: a constraint separates after an impact when its velocity exceeds this (the kernel's rule,
#: which the derivatives follow: biped_opt.control.derivatives)
SEPARATION_TOL = 1e-12

#: kind of an event row: a contact event, or the terminal one (read by the compiled kernel)
EVENT_CONTACT = 1
EVENT_TERMINAL = 2


class Status(enum.IntEnum):
    """How a simulation ended (the codes the compiled kernel returns). Only ``OK`` is a
    success."""

    OK = 0
    HORIZON = 1
    MAX_EVENTS = 2
    INCONSISTENT = 3
    APEX_IN_CONTACT = 4
    STEP_FAILURE = 5
    CONSTRAINT_VIOLATED = 6

    @property
    def message(self) -> str:
        return _STATUS_MESSAGES[self]


_STATUS_MESSAGES = {
    Status.OK: "the maneuver reached its terminal event",
    Status.HORIZON: "the time horizon was reached before the terminal event",
    Status.MAX_EVENTS: "the maximum number of contact events was reached",
    Status.INCONSISTENT: "inconsistent contact: no contact mode satisfies the complementarity "
    "conditions (in each, a foot in contact would need a negative reaction force or a released "
    "one would accelerate into the ground), or a foot in the air went through the ground right "
    "after it was released",
    Status.APEX_IN_CONTACT: "the body reached its apex while a foot was still on the ground",
    Status.STEP_FAILURE: "the integrator's step size underflowed or it took too many steps",
    Status.CONSTRAINT_VIOLATED: "a constraint was found more than 1e-9 below its surface at an "
    "event: the trajectory is not a solution",
}
