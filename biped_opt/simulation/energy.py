"""The energy check of a description (docs/SYSTEMS.md Sec. 4, paragraph "Energy."): a flight
without inputs must keep the energy the description declares.

A description may declare its total energy, ``system.energy``, an expression in the coordinates,
velocities and parameters (kinetic plus potential). Between two events of a run with every input
at zero, Eq. (1a) does no work but the potential forces' (a constraint in contact does none: its
point does not move along its normal), so with no damping the declared energy stays constant to
the integrator's accuracy. A force written wrongly (a Coriolis term with the wrong factor, a sign)
breaks that at once: :func:`energy_drift` simulates the first segment of a maneuver (from the
start to its first event), evaluates the energy at dense samples and reports the drift.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from biped_opt.errors import InvalidInputError
from biped_opt.simulation.compiled import CompiledSystem

__all__ = ["DRIFT_TOLERANCE", "EnergyDrift", "energy_drift"]

#: largest relative drift a conservative flight may show: the integrator's rtol 1e-10 over a
#: flight of a few time units leaves drifts of ~1e-10 of the energy's scale; a wrong force term
#: gives ~1e-3 and more (measured: the test's Coriolis factor 1 instead of 2 gives 1.5e-2)
DRIFT_TOLERANCE = 1e-7
#: samples per time unit of the checked flight
SAMPLES_PER_TIME = 200


@dataclass(frozen=True)
class EnergyDrift:
    """The energy over a maneuver's first segment with zero inputs."""

    system: str
    maneuver: str
    s: float
    t_start: float
    t_end: float  #: the first event (or the run's end)
    samples: int
    energy: float  #: at the start
    drift: float  #: max |E(t) - E(0)| over the samples
    scale: float  #: max |E| and the kinetic energy's scale over the samples
    relative: float  #: drift / scale
    tolerance: float

    @property
    def ok(self) -> bool:
        return self.relative <= self.tolerance

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), "ok": self.ok}


def energy_drift(compiled: CompiledSystem, maneuver: str | None = None, s: float | None = None,
                 *, tolerance: float = DRIFT_TOLERANCE) -> EnergyDrift:
    """The drift of ``compiled``'s declared energy over the first segment of ``maneuver``
    (default its first) at ``s`` (default the middle of the maneuver's range, nudged off 0,
    where symmetric systems hide asymmetric errors) with every input at zero. Raises
    InvalidInputError when the description declares no energy."""
    import sympy as sp

    system = compiled.system
    if system.energy is None:
        raise InvalidInputError(f"{system.where()}: declares no energy (system.energy)")
    name = compiled.maneuvers[0] if maneuver is None else maneuver
    lo, hi = compiled.s_range(name)
    value = 0.5 * (lo + hi) + 0.1234 * (hi - lo) / 2 if s is None else float(s)
    symbols = [*system.q, *system.dq, *system.p]
    unknown = sp.sympify(system.energy).free_symbols - set(symbols)
    if unknown:
        raise InvalidInputError(
            f"{system.where()}: the energy may use coordinates, velocities and parameters only, "
            f"not {', '.join(sorted(map(str, unknown)))}")
    energy = sp.lambdify(symbols, system.energy, modules="math")
    d = len(system.q)
    if system.mass_matrix is not None:
        kinetic = sp.lambdify(symbols, (sp.Matrix(system.dq).T * system.mass_matrix
                                        * sp.Matrix(system.dq))[0, 0] / 2, modules="math")
    else:  # (a description of bodies: M summed from them, SYSTEMS.md Sec. 1a)
        numeric = compiled.derived.numeric(**compiled.parameters)

        def kinetic(*values: float) -> float:
            q, dq = np.array(values[:d]), np.array(values[d:2 * d])
            return float(dq @ numeric.mass_matrix(q) @ dq) / 2
    run = compiled.simulate(name, value, None, sample_dt=1.0 / SAMPLES_PER_TIME)
    t_end = run.contact_events[0].t if run.contact_events else run.t_final
    samples = run.samples
    assert samples is not None
    inside = samples[samples[:, 0] < t_end]
    p = [compiled.parameters[k] for k in system.p.names()]
    values = np.array([energy(*row[1:1 + 2 * d], *p) for row in inside])
    scale_kinetic = max(abs(kinetic(*row[1:1 + 2 * d], *p)) for row in inside)
    e0 = float(values[0])
    drift = float(np.max(np.abs(values - e0)))
    scale = max(float(np.max(np.abs(values))), scale_kinetic, 1e-300)
    return EnergyDrift(system=compiled.name, maneuver=name, s=value, t_start=0.0,
                       t_end=float(t_end), samples=int(len(inside)), energy=e0, drift=drift,
                       scale=scale, relative=drift / scale, tolerance=tolerance)
