"""Event-driven hybrid simulation of the biped's maneuvers (MODEL.md Sec. 3): the paper's names
(maneuvers, th0, u1/u2/u12, BipedParams) over the one simulator of every system.

MODEL.md Sec. 3: events located to |dt| <= 1e-10, simultaneous events flipped together,
reset guards disarmed, inconsistent contacts and exhausted budgets reported by status. The
results are :mod:`biped_opt.simulation.trajectory`'s.
"""

from biped_opt.hybrid.simulate import (
    SimulatorOptions,
    kernels_cached,
    simulate,
    simulate_batch,
    warm_up,
)
from biped_opt.simulation.trajectory import BatchResult, Event, Segment, Status, Trajectory

__all__ = [
    "BatchResult",
    "Event",
    "Segment",
    "SimulatorOptions",
    "Status",
    "Trajectory",
    "kernels_cached",
    "simulate",
    "simulate_batch",
    "warm_up",
]
