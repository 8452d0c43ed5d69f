"""biped_opt: nonsmooth optimal value and policy functions of mechanical systems with unilateral
constraints, and of the paper's biped.

Implements B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in
mechanical systems subject to unilateral constraints" (IEEE Control Systems Letters, 2020).

Any system: :class:`CompiledSystem` (or :func:`simulate_system` / :func:`simulate_system_batch`)
runs a description's maneuvers and returns a :class:`Trajectory` / :class:`BatchResult`. The
paper's biped: :func:`simulate` and :func:`simulate_batch` take its maneuvers, th0 and inputs
(u1, u2, u12) and return the same types; :class:`ContactMode` names its contact modes.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from biped_opt.codegen.status import Status
    from biped_opt.errors import (
        BipedOptError,
        InvalidInputError,
        InvalidParameterError,
        SimulationError,
    )
    from biped_opt.paper.biped import (
        BipedParams,
        ContactMode,
        Maneuver,
        simulate,
        simulate_batch,
    )
    from biped_opt.simulation.compiled import CompiledSystem, compile_system
    from biped_opt.simulation.compiled import simulate as simulate_system
    from biped_opt.simulation.compiled import simulate_batch as simulate_system_batch
    from biped_opt.simulation.options import SimulatorOptions
    from biped_opt.simulation.trajectory import BatchResult, Event, Segment, Trajectory

from biped_opt.version import __version__

#: name -> (module, attribute) of the package's exports, imported when first read: a command
#: that needs none of them (a cached ``biped-opt simulate``) does not import Numba or SciPy
_EXPORTS: dict[str, tuple[str, str]] = {
    "Status": ("biped_opt.codegen.status", "Status"),
    **{name: ("biped_opt.errors", name) for name in (
        "BipedOptError", "InvalidInputError", "InvalidParameterError", "SimulationError")},
    **{name: ("biped_opt.paper.biped", name) for name in (
        "BipedParams", "ContactMode", "Maneuver", "simulate", "simulate_batch")},
    "CompiledSystem": ("biped_opt.simulation.compiled", "CompiledSystem"),
    "compile_system": ("biped_opt.simulation.compiled", "compile_system"),
    "simulate_system": ("biped_opt.simulation.compiled", "simulate"),
    "simulate_system_batch": ("biped_opt.simulation.compiled", "simulate_batch"),
    "SimulatorOptions": ("biped_opt.simulation.options", "SimulatorOptions"),
    **{name: ("biped_opt.simulation.trajectory", name) for name in (
        "BatchResult", "Event", "Segment", "Trajectory")},
}


def __getattr__(name: str) -> Any:
    where = _EXPORTS.get(name)
    if where is None:
        raise AttributeError(f"module 'biped_opt' has no attribute {name!r}")
    value = getattr(importlib.import_module(where[0]), where[1])
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})


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
