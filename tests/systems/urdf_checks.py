"""Checks of a robot imported from URDF against Pinocchio (``pinocchio_reference``), shared by
the test modules of each robot (``test_urdf_<robot>.py``: one compile of each robot per test
run, on one worker, kept in the checkout's cache for the next run).

Tolerances, each relative to the quantity's own size:

- ``TOL`` = 1e-10 for M, the bias forces, the contact Jacobian and its rate term, constrained
  accelerations, reactions and plastic impact velocities: two evaluations of the same
  mechanics in different orders and coordinates agree to ~1e-15; what 1e-10 leaves out is any
  error of a term (a wrong inertia, axis or sign is O(1e-3) and more);
- ``DROP_TOL`` = 1e-8 for a whole drop's event times and states: both integrators run at
  rtol 1e-11 / 1e-12 over ~0.2 s, their global errors ~1e-10, and a wrong event changes the
  state by O(1).
"""

from __future__ import annotations

import numpy as np

from tests.systems.pinocchio_reference import PinocchioRobot, drop, relative_error

TOL = 1e-10
DROP_TOL = 1e-8


def reference_for(system, urdf, contacts, **kw) -> PinocchioRobot:
    """Pinocchio's model of ``urdf`` in the system's coordinates, with what the importer
    recorded as locked joints, mimic joints, posture and the posture hold's gains."""
    imported = system.robot
    return PinocchioRobot(str(urdf), list(system.coordinate_names), contacts=contacts,
                          locked=dict(imported.locked), mimic=dict(imported.mimic),
                          posture=dict(imported.posture), kp=system.defaults["kp"],
                          kd=system.defaults["kd"], g=system.defaults["g"],
                          floating=imported.base == "floating", **kw)


def drop_start(compiled, s):
    """The drop's initial state at s, from the compiled system's own initial-state function."""
    y0 = np.zeros(2 * len(compiled.coordinates))
    compiled.module.initial_state(compiled.code("drop"), float(s), compiled.prepared, y0)
    return y0


def random_states(system, count, seed, start):
    """States around ``start`` (the drop's): joints within 0.6 rad of the posture, the base
    within 0.5 rad of level, velocities up to 2."""
    d = len(system.q)
    rng = np.random.default_rng(seed)
    for _ in range(count):
        q = start[:d] + rng.uniform(-0.6, 0.6, d)
        q[3:6] = rng.uniform(-0.5, 0.5, 3)
        yield q, rng.uniform(-2, 2, d), rng.uniform(-1, 1, len(system.u))


def check_eq1_terms(system, reference, seed=11, count=4):
    """M, the forces (bodies, damping, efforts, posture hold), the contacts' heights,
    Jacobian and rate term of the derived system (NumericSystem) against Pinocchio's."""
    from biped_opt.systems.derive import derive

    numeric = derive(system).numeric()
    names = system.u.names()
    worst = {}
    start = numeric.initial_state("drop", 0.0)[0]
    for q, dq, u in random_states(system, count, seed, start):
        y = np.concatenate([q, dq])
        reference.set_efforts({joint: u[names.index(inp)]
                               for joint, inp in system.robot.inputs.items()})
        pairs = {
            "M": (numeric.mass_matrix(q), reference.mass(y)),
            "forces": (numeric.forces(q, dq, u, 0), reference.force(y, frozenset())),
            "heights": (numeric.constraints(q), reference.heights(y)),
            "Da": (numeric.constraint_jacobian(q), reference.jac(y)),
            "rate": (numeric.constraint_jacobian_rate(q, dq), reference.drift(y)),
        }
        for key, (ours, theirs) in pairs.items():
            worst[key] = max(worst.get(key, 0.0), relative_error(ours, theirs))
    return worst


def check_generated_code(compiled, reference, modes, seed=12, count=3):
    """The compiled system's vector field (accelerations and reactions) in ``modes`` and its
    plastic impact map against Pinocchio's constrained dynamics (least squares on M^-1/2) and
    M-orthogonal projection, at random states: the worst relative errors."""
    system = compiled.system
    d = len(system.q)
    n = len(system.constraints)
    module = compiled.module
    p = compiled.prepared
    worst = {"acceleration": 0.0, "reaction": 0.0, "impact": 0.0}
    for q, dq, u in random_states(system, count, seed, drop_start(compiled, 0.0)):
        y = np.concatenate([q, dq])
        names = system.u.names()
        reference.set_efforts({joint: u[names.index(inp)]
                               for joint, inp in system.robot.inputs.items()})
        for mode in modes:
            active = [j for j in range(n) if mode >> j & 1]
            out, lam = np.zeros(2 * d), np.zeros(n)
            module._field_at(p, mode, y.copy(), 0, u.copy(), out, 0, lam, 0)
            acc, reactions = reference.accelerations(y, active)
            worst["acceleration"] = max(worst["acceleration"], relative_error(out[d:], acc))
            if active:
                worst["reaction"] = max(worst["reaction"],
                                        relative_error(lam[active], reactions[active]))
                after = y.copy()
                module.apply_impact(p, mode, after)
                worst["impact"] = max(worst["impact"], relative_error(
                    after[d:], reference.impact_velocity(y, active)))
    return worst


def check_drop(compiled, reference, s):
    """A whole drop by the compiled simulator and by the reference (SciPy DOP853 on
    Pinocchio's dynamics, the event rules of reference_rigid): the same events with the same
    contact sets, and the worst differences of event times and of states (before and after
    each event, and at the end) relative to max(1, |state|)."""
    system = compiled.system
    reference.set_efforts({})  # (the drop's inputs are 0)
    y0 = drop_start(compiled, s)
    ours = compiled.simulate("drop", s)
    theirs = drop(reference, y0)
    assert ours.status.name == theirs.status, (ours.status, theirs.status, ours.message)

    def feet(mask):
        return frozenset(j for j in range(len(system.constraints)) if mask >> j & 1)

    mine = [(feet(e.mask_entered), feet(e.mask_left), feet(e.mask_after))
            for e in ours.contact_events]
    ref = [(e.entered, e.left, e.after) for e in theirs.events]
    assert mine == ref, f"s = {s}: events {mine}, reference {ref}"
    times = max([abs(a.t - b.t) for a, b in zip(ours.contact_events, theirs.events)]
                + [abs(ours.t_final - theirs.t_final)])
    states = [(ours.y_final, theirs.y_final)]
    for a, b in zip(ours.contact_events, theirs.events):
        states += [(a.state_before, b.y_before), (a.state_after, b.y_after)]
    error = max(float(np.abs(x - y).max() / max(1.0, np.abs(y).max())) for x, y in states)
    return times, error, mine
