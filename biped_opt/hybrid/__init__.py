"""Event-driven hybrid simulator of mechanical systems with unilateral constraints.

MODEL.md Sec. 3: events located to |dt| <= 1e-10, simultaneous events flipped together,
reset guards disarmed, inconsistent contacts and exhausted budgets reported by status.
"""

from biped_opt.hybrid.simulate import (
    BatchResult,
    SimulatorOptions,
    kernels_cached,
    simulate,
    simulate_batch,
    warm_up,
)
from biped_opt.hybrid.trajectory import Event, Segment, Status, Trajectory

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
