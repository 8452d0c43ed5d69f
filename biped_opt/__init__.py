"""biped_opt: nonsmooth optimal value and policy functions of mechanical systems with unilateral
constraints, and of the paper's biped.

Implements B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in
mechanical systems subject to unilateral constraints" (IEEE Control Systems Letters, 2020).

Any system: :class:`CompiledSystem` (or :func:`simulate_system` / :func:`simulate_system_batch`)
runs a description's maneuvers and returns a :class:`Trajectory` / :class:`BatchResult`. The
paper's biped: :func:`simulate` and :func:`simulate_batch` take its maneuvers, th0 and inputs
(u1, u2, u12) and return the same types; :class:`ContactMode` names its contact modes.
"""

from biped_opt.codegen.status import Status
from biped_opt.errors import (
    BipedOptError,
    InvalidInputError,
    InvalidParameterError,
    SimulationError,
)
from biped_opt.paper.biped import BipedParams, ContactMode, Maneuver, simulate, simulate_batch
from biped_opt.simulation.compiled import CompiledSystem, compile_system
from biped_opt.simulation.compiled import simulate as simulate_system
from biped_opt.simulation.compiled import simulate_batch as simulate_system_batch
from biped_opt.simulation.options import SimulatorOptions
from biped_opt.simulation.trajectory import BatchResult, Event, Segment, Trajectory
from biped_opt.version import __version__

__all__ = [
    "__version__",
    # every system
    "CompiledSystem",
    "compile_system",
    "simulate_system",
    "simulate_system_batch",
    "Trajectory",
    "BatchResult",
    "Event",
    "Segment",
    "Status",
    "SimulatorOptions",
    "BipedOptError",
    "InvalidInputError",
    "InvalidParameterError",
    "SimulationError",
    # the paper's biped
    "simulate",
    "simulate_batch",
    "Maneuver",
    "BipedParams",
    "ContactMode",
]
