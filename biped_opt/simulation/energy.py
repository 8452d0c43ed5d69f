"""The energy check of a description (docs/SYSTEMS.md Sec. 4, paragraph "Energy."): a flight
without inputs must keep the energy the description declares, or, for a description of bodies
that declares none, the bodies' own energy (kinetic plus the weight's potential).

A description may declare its total energy, ``system.energy``, an expression in the coordinates,
velocities and parameters (kinetic plus potential). Between two events of a run with every input
at zero, Eq. (1a) does no work but the potential forces' (a constraint in contact does none: its
point does not move along its normal), so with no damping the declared energy stays constant to
the integrator's accuracy. A force written wrongly (a Coriolis term with the wrong factor, a sign)
breaks that at once: :func:`energy_drift` simulates the first segment of a maneuver (from the
start to its first event), evaluates the energy at dense samples and reports the drift.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from biped_opt.errors import InvalidInputError
from biped_opt.simulation.compiled import CompiledSystem

__all__ = ["DRIFT_TOLERANCE", "EnergyDrift", "energy_drift", "bodies_energy"]

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
    #: where the energy came from: "declared" (system.energy) or "bodies" (kinetic plus the
    #: weight's potential, for a description of bodies that declares none)
    source: str = "declared"

    @property
    def ok(self) -> bool:
        return self.relative <= self.tolerance

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), "ok": self.ok}


def bodies_energy(compiled: CompiledSystem) -> Callable[..., float]:
    """The energy of a description of bodies (SYSTEMS.md Sec. 1a) that declares none, as a
    function of (q, q', parameters) like a declared one: the kinetic energy q'^T M q' / 2 and
    the potential -m g . c of each body's weight (c its centre in the world). It is the total
    energy only when the applied forces do no work in a flight with every input at zero:
    :func:`energy_drift` checks that they are zero there. Raises InvalidInputError for a
    description without bodies."""
    import sympy as sp

    system = compiled.system
    derived = compiled.derived
    if not derived.bodies:
        raise InvalidInputError(f"{system.where()}: declares no energy (system.energy) and no "
                                "bodies to take it from")
    d = len(system.q)
    potential = sp.S.Zero
    for b in derived.bodies:
        centre = b.origin + b.axes * b.centre
        potential -= b.mass * (b.gravity.T * centre)[0, 0]
    height = sp.lambdify([*system.q, *system.p], potential, modules="math")
    numeric = derived.numeric(**compiled.parameters)

    def energy(*values: float) -> float:
        q, dq = np.array(values[:d]), np.array(values[d:2 * d])
        return float(dq @ numeric.mass_matrix(q) @ dq) / 2 + float(
            height(*values[:d], *values[2 * d:]))

    return energy


def _applied_in_flight(compiled: CompiledSystem, mode: int) -> list[str]:
    """The coordinates on which the applied forces of ``mode`` are not zero with every input at
    zero, at the current parameters (sampled at random states: a spring or a damper)."""
    import sympy as sp

    system = compiled.system
    subs = {sym: compiled.parameters[sym.name] for sym in system.p}
    subs.update({sym: 0.0 for sym in system.u})
    forces = [sp.sympify(f).xreplace(subs) for f in compiled.derived.applied[mode]]
    rng = np.random.default_rng(7)
    state = [*system.q, *system.dq]
    acting = []
    for name, f in zip(system.coordinate_names, forces):
        if f == 0:
            continue
        at = sp.lambdify(state, f, modules="math")
        if any(abs(at(*rng.uniform(-1.0, 1.0, len(state)))) > 0.0 for _ in range(3)):
            acting.append(name)
    return acting


def energy_drift(compiled: CompiledSystem, maneuver: str | None = None, s: float | None = None,
                 *, tolerance: float = DRIFT_TOLERANCE) -> EnergyDrift:
    """The drift of ``compiled``'s declared energy over the first segment of ``maneuver``
    (default its first) at ``s`` (default the middle of the maneuver's range, nudged off 0,
    where symmetric systems hide asymmetric errors) with every input at zero. A description
    of bodies that declares no energy is checked with :func:`bodies_energy` when its applied
    forces are zero in that flight. Raises InvalidInputError when there is no energy to
    check."""
    import sympy as sp

    system = compiled.system
    name = compiled.maneuvers[0] if maneuver is None else maneuver
    lo, hi = compiled.s_range(name)
    value = 0.5 * (lo + hi) + 0.1234 * (hi - lo) / 2 if s is None else float(s)
    symbols = [*system.q, *system.dq, *system.p]
    d = len(system.q)
    source = "declared"
    if system.energy is not None:
        unknown = sp.sympify(system.energy).free_symbols - set(symbols)
        if unknown:
            raise InvalidInputError(
                f"{system.where()}: the energy may use coordinates, velocities and parameters "
                f"only, not {', '.join(sorted(map(str, unknown)))}")
        energy = sp.lambdify(symbols, system.energy, modules="math")
    elif compiled.derived.bodies:
        acting = _applied_in_flight(compiled, compiled.initial_mode(name))
        if acting:
            raise InvalidInputError(
                f"{system.where()}: declares no energy (system.energy), and the applied forces "
                f"on {', '.join(acting)} are not zero with the inputs at zero: the bodies' "
                "energy (kinetic plus the weight's) leaves out their work; declare "
                "system.energy with their potential")
        energy = bodies_energy(compiled)
        source = "bodies"
    else:
        raise InvalidInputError(f"{system.where()}: declares no energy (system.energy)")
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
                       scale=scale, relative=drift / scale, tolerance=tolerance,
                       source=source)
