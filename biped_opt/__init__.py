"""biped_opt: nonsmooth optimal value and policy functions of a biped with unilateral constraints.

Implements B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in
mechanical systems subject to unilateral constraints" (IEEE Control Systems Letters, 2020).
"""

from biped_opt.errors import (
    BipedOptError,
    InvalidInputError,
    InvalidParameterError,
    SimulationError,
)
from biped_opt.hybrid import SimulatorOptions, Status, Trajectory, simulate, simulate_batch
from biped_opt.maneuvers import Maneuver
from biped_opt.model import BipedParams, ContactMode
from biped_opt.version import __version__

__all__ = [
    "__version__",
    "BipedOptError",
    "BipedParams",
    "ContactMode",
    "InvalidInputError",
    "InvalidParameterError",
    "Maneuver",
    "SimulationError",
    "SimulatorOptions",
    "Status",
    "Trajectory",
    "simulate",
    "simulate_batch",
]
