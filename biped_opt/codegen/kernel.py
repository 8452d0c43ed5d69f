"""The event-driven kernel, one for every system (MODEL.md Sec. 3, SYSTEMS.md Sec. 1).

The kernel reaches a system only through the system vector ``sv`` (biped_opt.codegen.abi):
the addresses of the system's compiled functions (``_field_at``, ``step``,
``dense_coefficients``, ``apply_impact``, ``constraint_rates``, ``guard_value``,
``guard_values``, ``initial_state``, ``outcome_value``, ``reaction``), which it calls through
the ``sys_*`` bindings below, and the system's table (state length, constraints, maneuvers,
which guards are one state component). So this module is compiled once per installation and
kept in Numba's cache beside it, and a new system compiles only its own functions. The code
below the ``# --- kernel ---`` marker is also compiled, ahead of time, into one module with a
system's functions (biped_opt.codegen.aot), its ``sys_*`` calls then bound directly
(:func:`biped_opt.codegen.abi.direct_binding`): one source for both.

The algorithm: an adaptive Dormand-Prince 8(5,3) integrator with its 7th-order dense output
(Hairer, Norsett and Wanner, *Solving ODEs I*, Sec. II.10; the step is the unrolled code of
:mod:`biped_opt.codegen.dop853`); guards monitored at the step ends and at every stage (a
guard that dips below zero inside a step is not missed); event times as roots of the guard on the
dense output (regula falsi with the Anderson-Bjorck modification, bracket < 1e-13 of the step:
event times good to ~1e-12); contact guards within SIMULTANEOUS_TOL of zero and moving toward
it flip together with the first (simultaneous events, MODEL.md Sec. 3), armed or not: a
constraint in the air that approaches its surface there joins the impact whatever earlier
events did to it; the terminal guard never joins (it is ordered by time); a constraint in the
air whose rate shows a lowest point inside a step has that point checked; a flipped guard at ~0
stays disarmed until it is farther than REARM_TOL from zero, and is watched inside each step
meanwhile (its flight's apex, dense-output probes), so that a bounce and a return within one
step are two events; restitution: after an impact with gamma > 0 a constraint whose velocity
Da_j q'+ is positive separates at once; the mode after an event is the one the complementarity
conditions allow (``_consistent_mode``); contacts whose rows of Da are linearly dependent
(a face's four corners) continue in an independent subset, the basis, that satisfies them
(``_consistent_basis``), the others held on their surface at zero reaction; an air constraint
found below its surface at an event ends the run (CONSTRAINT_VIOLATED), as does a held contact
that leaves its surface. docs/SYSTEMS.md, "Events", states these rules. Everything lives in
flat float arrays; nothing allocates per step.

Layouts: ``events[k] = [t, kind, touchdown_mask, liftoff_mask, mode_before, mode_after,
y_before (2d), y_after (2d)]``; ``samples[k] = [t, y (2d), mode, lambda (n)]``.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils, errors
from numba.extending import intrinsic

from biped_opt._jit import HOT_PATH
from biped_opt.codegen import abi
from biped_opt.codegen.abi import (
    CFG_ATOL,
    CFG_H_MAX,
    CFG_MAX_EVENTS,
    CFG_RTOL,
    CFG_SAMPLE_DT,
    CFG_T_END,
    CFG_TOUCHED_DOWN,
    INDEX,
    MANEUVER_WIDTH,
    SV_DEPENDENT,
    SV_GUARDS,
    SV_NCON,
    SV_NSTATE,
    SV_WORKSPACE,
)
from biped_opt.codegen.status import EVENT_CONTACT, EVENT_TERMINAL, SEPARATION_TOL, Status

#: the digest of the table (biped_opt.codegen.abi) this file's calls were written for: Numba's
#: cache of this module is keyed on this file alone, so a change of the table must change it
ABI = "3159dbb543ae038e"
if abi.digest() != ABI:
    raise ImportError(f"biped_opt.codegen.kernel was written for the system table {ABI}, "
                      f"biped_opt.codegen.abi is {abi.digest()}: update both together")


def _lowered(context, builder, ty, value):
    """(LLVM types, values) of one argument as a system function takes it: an array as its
    data pointer and its shape, an integer as int64, a float as double."""
    if isinstance(ty, types.Array):
        array = cgutils.create_struct_proxy(ty)(context, builder, value=value)
        double_ptr = ir.DoubleType().as_pointer()
        shape = cgutils.unpack_tuple(builder, array.shape, ty.ndim)
        return ([double_ptr] + [ir.IntType(64)] * ty.ndim,
                [builder.bitcast(array.data, double_ptr), *shape])
    if isinstance(ty, types.Integer):
        return [ir.IntType(64)], [context.cast(builder, value, ty, types.int64)]
    return [ir.DoubleType()], [context.cast(builder, value, ty, types.float64)]


_KINDS = {"A": types.Array(types.float64, 1, "C"), "F": types.Array(types.float64, 2, "C"),
          "i": types.int64, "f": types.float64}


@intrinsic
def _call(typingctx, name, sv, *args):
    """``_call(name, sv, *args)``: call the system function ``name`` (a string literal, a key of
    biped_opt.codegen.abi.FUNCTIONS) compiled as a C function, at the address sv holds for it
    (its index in the table), with ``args`` lowered as :func:`_lowered` does. The arguments'
    types are
    checked against the table when the kernel is compiled: the C function reads its arguments
    by the table, so a float where it expects an integer, or an array that is not a
    C-contiguous float64 one, would be read wrong rather than converted; such a call does not
    compile."""
    if len(args) == 1 and isinstance(args[0], types.StarArgTuple):
        args = args[0].types
    if not isinstance(name, types.StringLiteral) or name.literal_value not in abi.FUNCTIONS:
        raise errors.TypingError(f"_call: the first argument must name a function of "
                                 f"biped_opt.codegen.abi.FUNCTIONS, got {name}")
    if sv != types.Array(types.int64, 1, "C"):
        raise errors.TypingError(f"_call: sv must be a C-contiguous int64 vector, got {sv}")
    index = INDEX[name.literal_value]
    kinds, result = abi.FUNCTIONS[name.literal_value]
    got = [types.unliteral(t) for t in args]
    wanted = [_KINDS[k] for k in kinds]
    if len(got) != len(wanted) or any(
            g != w if k in "AF" else not isinstance(g, type(w))
            for g, w, k in zip(got, wanted, kinds)):
        raise errors.TypingError(f"_call of {name.literal_value}: arguments {got} do not match "
                                 f"the table's {wanted}")
    restype = types.void if result == "v" else types.float64
    signature = restype(name, sv, types.StarArgTuple.from_types(args))

    def codegen(context, builder, sig, llargs):
        _, sv_value, packed = llargs
        table = cgutils.create_struct_proxy(sig.args[1])(context, builder, value=sv_value)
        address_value = builder.load(builder.gep(table.data, [ir.Constant(ir.IntType(64),
                                                                          index)]))
        arg_types = sig.args[2].types
        values = cgutils.unpack_tuple(builder, packed, len(arg_types))
        ll_types, ll_values = [], []
        for ty, value in zip(arg_types, values):
            t, v = _lowered(context, builder, ty, value)
            ll_types += t
            ll_values += v
        ret = ir.VoidType() if restype is types.void else ir.DoubleType()
        fn = builder.inttoptr(address_value, ir.FunctionType(ret, ll_types).as_pointer())
        out = builder.call(fn, ll_values)
        return context.get_dummy_value() if restype is types.void else out

    return signature, codegen


# the kernel's calls of a system's functions, through sv (the same names and arguments as
# biped_opt.codegen.abi.direct_binding)


@nb.njit(**HOT_PATH)
def sys_field_at(sv, p, mode, y, yo, u, out, off, lam, lo):
    _call("_field_at", sv, p, mode, y, yo, u, out, off, lam, lo)


@nb.njit(**HOT_PATH)
def sys_step(sv, p, mode, u, term_sign, y, f, h, W, y_new, f_new, lam, rtol, atol, probe):
    return _call("step", sv, p, mode, u, term_sign, y, f, h, W, y_new, f_new, lam, rtol, atol,
                 probe)


@nb.njit(**HOT_PATH)
def sys_dense_coefficients(sv, p, mode, u, y, f, h, W, y_new, f_new, F):
    _call("dense_coefficients", sv, p, mode, u, y, f, h, W, y_new, f_new, F)


@nb.njit(**HOT_PATH)
def sys_apply_impact(sv, p, mode, y):
    _call("apply_impact", sv, p, mode, y)


@nb.njit(**HOT_PATH)
def sys_constraint_rates(sv, p, y, yo, out):
    _call("constraint_rates", sv, p, y, yo, out)


@nb.njit(**HOT_PATH)
def sys_guard_value(sv, p, mode, u, code, y, yo, lam, lo, i):
    return _call("guard_value", sv, p, mode, u, code, y, yo, lam, lo, i)


@nb.njit(**HOT_PATH)
def sys_guard_values(sv, p, mode, u, code, y, yo, lam, lo, out):
    _call("guard_values", sv, p, mode, u, code, y, yo, lam, lo, out)


@nb.njit(**HOT_PATH)
def sys_initial_state(sv, code, s, p, y0):
    _call("initial_state", sv, code, s, p, y0)


@nb.njit(**HOT_PATH)
def sys_outcome_value(sv, code, p, y, yo):
    return _call("outcome_value", sv, code, p, y, yo)


@nb.njit(**HOT_PATH)
def sys_reaction(sv, p, mode, u, y, j):
    return _call("reaction", sv, p, mode, u, y, j)


# --- kernel ---

OK = int(Status.OK)
HORIZON = int(Status.HORIZON)
MAX_EVENTS = int(Status.MAX_EVENTS)
INCONSISTENT = int(Status.INCONSISTENT)
APEX_IN_CONTACT = int(Status.APEX_IN_CONTACT)
STEP_FAILURE = int(Status.STEP_FAILURE)
CONSTRAINT_VIOLATED = int(Status.CONSTRAINT_VIOLATED)

SIMULTANEOUS_TOL = 1e-9
REARM_TOL = 1e-10
#: a constraint in the air more than this below its surface at an event is a violation
VIOLATION_TOL = 1e-9

# --- DOP853 step control ---
_SAFETY = 0.9
_MIN_FACTOR = 0.2
_MAX_FACTOR = 10.0
_MAX_STEPS = 100_000
#: a step size that is a guess rather than the controller's prediction (the first step, the
#: first after an event) may be rejected by any factor its error estimate asks for, down to this
_MIN_FACTOR_TRIAL = 1e-3
#: after an event the controller's prediction comes from the previous mode's dynamics; starting
#: the new mode at this fraction of it avoids most rejected first steps (~4% fewer evaluations
#: on the biped's benchmark cases with these two settings)
_EVENT_STEP_FRACTION = 0.7
#: event roots are located to this fraction of the step: 1e-13 of a step is ~4e-15 in time,
#: about where the guards' rounding noise leaves the root undetermined anyway
_ROOT_XTOL = 1e-13

#: the y0 argument of simulate_maneuver that starts from the maneuver's own initial state at s
#: (an array of 2d entries is the state to start from)
FROM_S = np.empty(0)


@nb.njit(**HOT_PATH)
def _inverse_eighth_root(err):
    return 1.0 / math.sqrt(math.sqrt(math.sqrt(err)))


@nb.njit(**HOT_PATH)
def _dense_eval(F, y, x, out):
    """The 7th-order interpolant at fraction x of the step that started at y."""
    xm = 1.0 - x
    for i in range(y.shape[0]):
        out[i] = y[i] + x * (F[0, i] + xm * (F[1, i] + x * (F[2, i] + xm * (
            F[3, i] + x * (F[4, i] + xm * (F[5, i] + x * F[6, i]))))))


@nb.njit(**HOT_PATH)
def _guard_component(sv, mode, code, i):
    """(k, sign) when guard i in this mode and maneuver is sign * y[k] (event roots then
    interpolate that one component), else (-1, 1.0): from the system's table."""
    ncon = sv[SV_NCON]
    if i < ncon:
        if mode >> i & 1:
            return -1, 1.0  # (a reaction)
        at = SV_GUARDS + 2 * i
    else:
        at = SV_GUARDS + 2 * ncon + MANEUVER_WIDTH * code
    return sv[at], float(sv[at + 1])


@nb.njit(**HOT_PATH)
def _guard_at(p, sv, mode, u, code, y, i, lam):
    """Guard i at a state y whose reactions are not known yet (lam: scratch)."""
    if i < sv[SV_NCON] and mode >> i & 1:
        return sys_reaction(sv, p, mode, u, y, i)
    return sys_guard_value(sv, p, mode, u, code, y, 0, lam, 0, i)


@nb.njit(**HOT_PATH)
def _guard_on_dense(p, sv, mode, u, code, F, y, x, i, tmp, lam):
    """Guard i on the interpolant at x: one component when the guard is one (a height in the
    air, a velocity as terminal guard: see ``guard_component``), else the whole state."""
    k, sign = _guard_component(sv, mode, code, i)
    if k >= 0:
        xm = 1.0 - x
        return sign * (y[k] + x * (F[0, k] + xm * (F[1, k] + x * (F[2, k] + xm * (
            F[3, k] + x * (F[4, k] + xm * (F[5, k] + x * F[6, k])))))))
    _dense_eval(F, y, x, tmp)
    return _guard_at(p, sv, mode, u, code, tmp, i, lam)


@nb.njit(**HOT_PATH)
def _guard_rate(p, sv, mode, u, code, y, f, i, tmp, lam):
    """d/dt of guard i along the flow of ``mode`` at y (f = vector field at y), by a central
    difference: only its sign is used, to decide which near-zero guards flip together."""
    eps = 1e-6
    for m in range(y.shape[0]):
        tmp[m] = y[m] + eps * f[m]
    g_plus = _guard_at(p, sv, mode, u, code, tmp, i, lam)
    for m in range(y.shape[0]):
        tmp[m] = y[m] - eps * f[m]
    g_minus = _guard_at(p, sv, mode, u, code, tmp, i, lam)
    return (g_plus - g_minus) / (2.0 * eps)


@nb.njit(**HOT_PATH)
def _root_on_dense(p, sv, mode, u, code, F, y, i, xa, ga, xb, gb, tmp, lam):
    """Root in (xa, xb] of guard i on the dense output (ga > 0 >= gb), by regula falsi with
    the Anderson-Bjorck modification, to a bracket below _ROOT_XTOL of the step. A guard that
    is one state component (see ``guard_component``) iterates on that component's eight
    coefficients, read once; only other guards interpolate the whole state per iterate."""
    k, sign = _guard_component(sv, mode, code, i)
    c = max(k, 0)  # (read but unused when the guard is not one component)
    y0, f0, f1, f2, f3 = y[c], F[0, c], F[1, c], F[2, c], F[3, c]
    f4, f5, f6 = F[4, c], F[5, c], F[6, c]
    side = 0
    for _ in range(200):
        if xb - xa <= _ROOT_XTOL:
            break
        x = (xa * gb - xb * ga) / (gb - ga)
        if not xa < x < xb:
            x = 0.5 * (xa + xb)
        x = min(max(x, xa + 0.5 * _ROOT_XTOL), xb - 0.5 * _ROOT_XTOL)
        if k >= 0:
            xm = 1.0 - x
            gx = sign * (y0 + x * (f0 + xm * (f1 + x * (f2 + xm * (f3 + x * (f4 + xm * (
                f5 + x * f6)))))))
        else:
            _dense_eval(F, y, x, tmp)
            gx = _guard_at(p, sv, mode, u, code, tmp, i, lam)
        if gx > 0.0:
            if side == 1:
                m = 1.0 - gx / ga
                gb *= m if m > 0.0 else 0.5
            xa, ga = x, gx
            side = 1
        else:
            if gx == 0.0:
                xb = x
                break
            if side == -1:
                m = 1.0 - gx / gb
                ga *= m if m > 0.0 else 0.5
            xb, gb = x, gx
            side = -1
    return xb


@nb.njit(**HOT_PATH)
def _rate_on_dense(p, sv, F, y, x, j, tmp, rates):
    """d/dt a_j along the step's interpolant at x: Da_j(q) q' of the interpolated state (the
    velocities are part of the state, so no derivative of the interpolant is needed)."""
    _dense_eval(F, y, x, tmp)
    sys_constraint_rates(sv, p, tmp, 0, rates)
    return rates[j]


@nb.njit(**HOT_PATH)
def _extremum(p, sv, mode, u, code, F, y, j, xa, ra, xb, rb, above, tmp, lam, rates):
    """Toward the extremum of constraint j's height a_j in [xa, xb] of the step, where its rate
    on the interpolant (ra at xa, rb at xb, of opposite signs) is zero: the apex of a flight
    (ra > 0) or a lowest point (ra < 0). Regula falsi on the rate (Illinois), which stops at
    the first iterate where a_j is above the ground (``above`` = 1.0) or at or below it
    (``above`` = 0.0; a float: a literal bool would compile one copy per value): that is all
    the caller needs, and a flight's rate is close to linear, so it mostly stops at the first
    iterate. Returns (x, a_j(x)) of the last iterate (the extremum to 1e-12 of the step when
    no iterate stopped it)."""
    side = 0
    x = 0.5
    g = 0.0
    for _ in range(100):
        x = (xa * rb - xb * ra) / (rb - ra)
        if not xa < x < xb:
            x = 0.5 * (xa + xb)
        g = _guard_on_dense(p, sv, mode, u, code, F, y, x, j, tmp, lam)
        if (g > 0.0) == (above > 0.0) or xb - xa <= 1e-12:
            break
        r = _rate_on_dense(p, sv, F, y, x, j, tmp, rates)
        if (r > 0.0) == (ra > 0.0):
            if side == 1:
                rb *= 0.5
            xa, ra = x, r
            side = 1
        else:
            if side == -1:
                ra *= 0.5
            xb, rb = x, r
            side = -1
    return x, g


#: dense-output probes per searched part of a step (see _first_probe): one in every eighth of
#: the part before a stage probe's sign change, or of the part a constraint whose guard was
#: just reset is watched in (see _separation_point)
_PROBES = 8


@nb.njit(**HOT_PATH)
def _first_probe(p, sv, mode, u, code, F, y, i, xa, xb, last, above, tmp, lam):
    """The first of the points xa + (xb - xa) m / _PROBES, m = 1 .. last, where guard i on the
    interpolant is above zero (``above`` = 1.0) or at or below it (``above`` = 0.0; a float,
    as in _extremum): (x, g there), or (-1.0, 0.0) when none is."""
    for m in range(1, last + 1):
        x = xa + (xb - xa) * m / _PROBES
        g = _guard_on_dense(p, sv, mode, u, code, F, y, x, i, tmp, lam)
        if (g > 0.0) == (above > 0.0):
            return x, g
    return -1.0, 0.0


@nb.njit(**HOT_PATH)
def _separation_point(p, sv, mode, u, code, F, y, j, r0, r1, x_end, tmp, lam, rates):
    """Where in [0, x_end) of the step constraint j, disarmed at ~0 after an event (a bounce, a
    liftoff, a foot that left the ground at once), is above the ground: at the start if it is
    above there and coming down (a flight that began in an earlier step); near the apex of its
    flight when its rate went from separating (r0 > 0) to approaching (r1 < 0); else at the
    first of _PROBES - 1 probes with a_j > 0. -1.0 when a_j never rose above 0 (it went the
    wrong way, or the flight is shorter than the guard's rounding)."""
    if abs(r0) <= SEPARATION_TOL and r1 < 0.0:
        # at rest on its surface at the start (released by a plastic landing or by
        # complementarity; the sign of its rate is rounding): a hop rises at first, so its
        # rate is positive somewhere near the start, found by halving toward it; its apex lies
        # between that point and the first later one where the rate is negative
        xb, rb = 1.0, r1
        x = 0.5
        for _ in range(60):
            r = _rate_on_dense(p, sv, F, y, x, j, tmp, rates)
            if r > 0.0:
                x, g = _extremum(p, sv, mode, u, code, F, y, j, x, r, xb, rb, 1.0, tmp, lam,
                                 rates)
                if g > 0.0 and x < x_end:
                    return x
                break
            xb, rb = x, r
            x *= 0.5
    elif r0 < 0.0 and _guard_on_dense(p, sv, mode, u, code, F, y, 0.0, j, tmp, lam) > 0.0:
        return 0.0
    elif r0 > 0.0 and r1 < 0.0:
        x, g = _extremum(p, sv, mode, u, code, F, y, j, 0.0, r0, 1.0, r1, 1.0, tmp, lam, rates)
        if g > 0.0 and x < x_end:
            return x
    return _first_probe(p, sv, mode, u, code, F, y, j, 0.0, x_end, _PROBES - 1, 1.0, tmp, lam)[0]


@nb.njit(**HOT_PATH)
def _separation_rate(p, sv, mode, u, y, f, j, tmp, rates):
    """d/dt (Da_j q') along the flow of ``mode`` (f: the vector field there): a_j'', the
    separation acceleration of a constraint at rest on its surface, by a central difference
    (only its sign is used)."""
    eps = 1e-6
    for m in range(y.shape[0]):
        tmp[m] = y[m] + eps * f[m]
    sys_constraint_rates(sv, p, tmp, 0, rates)
    r_plus = rates[j]
    for m in range(y.shape[0]):
        tmp[m] = y[m] - eps * f[m]
    sys_constraint_rates(sv, p, tmp, 0, rates)
    return (r_plus - rates[j]) / (2.0 * eps)


#: complementarity is checked to this tolerance (reactions, separation accelerations) when a
#: mode other than the one the event suggests is tried: the sign of a zero is rounding
_COMPLEMENTARITY_TOL = 1e-10


@nb.njit(**HOT_PATH)
def _consistent_mode(p, sv, mode, u, y, f, lam, tmp, tmp2, rates):
    """The contact mode that satisfies the complementarity conditions at y, chosen among the
    subsets of ``mode`` (the constraints at rest on their surface after the event's resets):
    every active constraint with lambda_j >= 0, every released one with a separation
    acceleration a_j'' >= 0. Subsets are tried from the largest down (2^n candidates; the
    Schur complement Da M^-1 Da^T is positive definite, so at most one fits). Returns the mode
    (f and lam then hold its vector field and reactions), or -1 when none fits."""
    ncon = sv[SV_NCON]
    for size in range(ncon, -1, -1):
        for cand in range(1 << ncon):
            if cand & ~mode:
                continue
            bits = 0
            for j in range(ncon):
                bits += cand >> j & 1
            if bits != size:
                continue
            sys_field_at(sv, p, cand, y, 0, u, f, 0, lam, 0)
            ok = True
            for j in range(ncon):
                if not mode >> j & 1:
                    continue
                if cand >> j & 1:
                    ok = lam[j] >= -_COMPLEMENTARITY_TOL
                else:
                    ok = _separation_rate(p, sv, cand, u, y, f, j, tmp2, rates) \
                        >= -_COMPLEMENTARITY_TOL
                if not ok:
                    break
            if ok:
                return cand
    sys_field_at(sv, p, mode, y, 0, u, f, 0, lam, 0)
    return -1


# --- dependent constraints (SYSTEMS.md Sec. 5, "Dependent contacts") ---------------------------

#: a constraint's row of Da whose distance from the span of other rows is below this fraction
#: of its length depends on them. Exactly dependent rows (a flat face's fourth corner) leave
#: ~1e-16; closer than 1e-6 the Schur complement's pivot is below 1e-12 of its diagonal, where
#: reactions and impulses are left to rounding (two contacts whose normals coincide at this
#: very configuration, 1e-9 apart, gave NaN), so such a set is treated as dependent: its
#: motion is well defined, its reactions are not
DEPENDENT_TOL = 1e-6


@nb.njit(**HOT_PATH)
def _count(mask):
    """The number of constraints in a mask."""
    c = 0
    while mask:
        c += mask & 1
        mask >>= 1
    return c


@nb.njit(**HOT_PATH)
def _finite(y):
    """Whether every entry of y is a finite number."""
    for k in range(y.shape[0]):
        if not abs(y[k]) < math.inf:
            return False
    return True


@nb.njit(**HOT_PATH)
def _jacobian(p, sv, y, tmp, rates, Da):
    """Da(q) at the configuration of y, row j the constraint j: column k is the rates Da q' at
    the unit velocity q' = e_k (exact: the rates are linear in q')."""
    d = sv[SV_NSTATE] // 2
    for m in range(d):
        tmp[m] = y[m]
    for k in range(d):
        for m in range(d):
            tmp[d + m] = 0.0
        tmp[d + k] = 1.0
        sys_constraint_rates(sv, p, tmp, 0, rates)
        for j in range(Da.shape[0]):
            Da[j, k] = rates[j]


@nb.njit(**HOT_PATH)
def _orthogonalise(Q, k, d):
    """Q[k] minus its projection on the orthonormal rows Q[:k] (twice, for rounding); returns
    the squared length left."""
    for _ in range(2):
        for r in range(k):
            c = 0.0
            for i in range(d):
                c += Q[r, i] * Q[k, i]
            for i in range(d):
                Q[k, i] -= c * Q[r, i]
    left = 0.0
    for i in range(d):
        left += Q[k, i] * Q[k, i]
    return left


@nb.njit(**HOT_PATH)
def _independent(Da, Q, members, first):
    """A largest independent subset of the constraints in ``members``, greedily: a row is
    taken when it does not depend on the rows taken before it (DEPENDENT_TOL), the rows of
    ``first`` before the others, each group in declared order. Q[:k] receives the taken rows
    orthonormalised. Returns (the mask taken, k)."""
    ncon, d = Da.shape
    taken = 0
    k = 0
    for sweep in range(2):
        for j in range(ncon):
            if not members >> j & 1 or (first >> j & 1) != (sweep == 0):
                continue
            length = 0.0
            for i in range(d):
                Q[k, i] = Da[j, i]
                length += Da[j, i] * Da[j, i]
            left = _orthogonalise(Q, k, d)
            if length > 0.0 and left > DEPENDENT_TOL * DEPENDENT_TOL * length:
                scale = 1.0 / math.sqrt(left)
                for i in range(d):
                    Q[k, i] *= scale
                taken |= 1 << j
                k += 1
    return taken, k


@nb.njit(**HOT_PATH)
def _depends(Da, Q, k, j):
    """Whether row j of Da lies in the span of the orthonormal rows Q[:k] (Q[k]: scratch)."""
    d = Da.shape[1]
    length = 0.0
    for i in range(d):
        Q[k, i] = Da[j, i]
        length += Da[j, i] * Da[j, i]
    return _orthogonalise(Q, k, d) <= DEPENDENT_TOL * DEPENDENT_TOL * length


@nb.njit(**HOT_PATH)
def _held(p, sv, y, basis, gv, tmp, rates, Da, Q, have_da):
    """The constraints outside ``basis`` within SIMULTANEOUS_TOL of their surface (gv: the
    guards at y in the mode ``basis``) whose rows depend on the basis: the basis holds them on
    their surface (they are in contact, at zero reaction). Da is computed here unless
    ``have_da``."""
    ncon = sv[SV_NCON]
    near = 0
    for j in range(ncon):
        if not basis >> j & 1 and abs(gv[j]) <= SIMULTANEOUS_TOL:
            near |= 1 << j
    if near == 0 or basis == 0:
        return 0
    if not have_da:
        _jacobian(p, sv, y, tmp, rates, Da)
    _b, k = _independent(Da, Q, basis, basis)
    held = 0
    for j in range(ncon):
        if near >> j & 1 and _depends(Da, Q, k, j):
            held |= 1 << j
    return held


#: a reaction at ~0 falling faster than this (relative to the largest reaction) makes its basis
#: pull at once; the central difference that estimates the rate is good to ~1e-10 of that scale
_FALLING_TOL = 1e-7


@nb.njit(**HOT_PATH)
def _basis_fits(p, sv, basis, surface, u, code, y, f, lam, tmp, tmp2, rates, lam_tmp, Da, Q, k):
    """Whether the independent set ``basis`` (its rows orthonormal in Q[:k]) of the dependent
    set ``surface`` satisfies complementarity at y: every reaction lambda_j >= 0 (to 1e-10),
    and not falling when it is ~0 (the basis would pull at once: another basis of the same
    contacts carries the load), and every constraint of ``surface`` that the basis does not
    hold (released) not accelerating into its surface. f and lam receive the basis's vector
    field and reactions."""
    ncon = sv[SV_NCON]
    sys_field_at(sv, p, basis, y, 0, u, f, 0, lam, 0)
    scale = 1.0
    for j in range(ncon):
        if basis >> j & 1:
            scale = max(scale, abs(lam[j]))
    for j in range(ncon):
        if not surface >> j & 1:
            continue
        if basis >> j & 1:
            if lam[j] < -_COMPLEMENTARITY_TOL:
                return False
            if lam[j] <= _COMPLEMENTARITY_TOL and _guard_rate(
                    p, sv, basis, u, code, y, f, j, tmp2, lam_tmp) < -_FALLING_TOL * scale:
                return False
        elif not _depends(Da, Q, k, j):
            if _separation_rate(p, sv, basis, u, y, f, j, tmp2, rates) < -_COMPLEMENTARITY_TOL:
                return False
    return True


@nb.njit(**HOT_PATH)
def _consistent_basis(p, sv, surface, first, u, code, y, f, lam, tmp, tmp2, rates, lam_tmp, Da,
                      Q):
    """The mode to continue in when the constraints ``surface`` at rest on their surface have
    dependent rows (Da computed at y): an independent subset, the basis, that satisfies
    complementarity (:func:`_basis_fits`); the constraints of ``surface`` that depend on it
    stay in contact at zero reaction. Largest first: the greedy basis (the constraints of
    ``first``, the previous basis, before the others), then every other independent subset of
    that size in mask order, then smaller ones. Returns the basis (f and lam hold its field and
    reactions), or -1 when none fits."""
    ncon = sv[SV_NCON]
    greedy, rank = _independent(Da, Q, surface, first)
    for size in range(rank, -1, -1):
        for trial in range(-1, 1 << ncon):
            cand = greedy if trial < 0 else trial
            if trial >= 0 and (cand == greedy or cand & ~surface):
                continue
            if _count(cand) != size:
                continue
            b, k = _independent(Da, Q, cand, cand)
            if b != cand:
                continue
            if _basis_fits(p, sv, cand, surface, u, code, y, f, lam, tmp, tmp2, rates, lam_tmp,
                           Da, Q, k):
                return cand
    sys_field_at(sv, p, greedy, y, 0, u, f, 0, lam, 0)
    return -1


@nb.njit(**HOT_PATH)
def _pivot(p, sv, basis, held, lifted, u, code, y, f, lam, tmp, tmp2, rates, lam_tmp, Da, Q):
    """Another basis of the same contacts when the reactions of ``lifted`` (members of
    ``basis``) fell through 0 while ``held`` contacts depend on the basis (Da computed at y):
    the lifted ones replaced by as many held ones, independent, every reaction >= 0 and none
    ~0 and falling (:func:`_basis_fits`). The contacts do not change: the support moved to
    another vertex of the admissible reactions (a table whose load crosses a diagonal of its
    legs), a pivot in the simplex method's words. Returns the basis (f and lam hold its field
    and reactions), or -1 when none carries the load (then they lift)."""
    ncon = sv[SV_NCON]
    need = _count(lifted)
    kept = basis & ~lifted
    contact = basis | held
    for extra in range(1, 1 << ncon):
        if extra & ~held or _count(extra) != need:
            continue
        cand = kept | extra
        b, k = _independent(Da, Q, cand, cand)
        if b != cand:
            continue
        if _basis_fits(p, sv, cand, contact, u, code, y, f, lam, tmp, tmp2, rates, lam_tmp, Da,
                       Q, k):
            return cand
    return -1


@nb.njit(**HOT_PATH)
def _record_sample(sv, samples, ns, t, y, mode, lam):
    if ns < samples.shape[0]:
        samples[ns, 0] = t
        n = sv[SV_NSTATE]
        for k in range(n):
            samples[ns, 1 + k] = y[k]
        samples[ns, 1 + n] = mode
        for j in range(sv[SV_NCON]):
            samples[ns, 2 + n + j] = lam[j]
    return ns + 1


@nb.njit(**HOT_PATH)
def _initial_step(p, sv, mode, u, y, f, rtol, atol, h_max, tmp, ftmp, lam):
    """Starting step size (Hairer, Norsett and Wanner, Sec. II.4), one extra evaluation."""
    n = y.shape[0]
    d0 = 0.0
    d1 = 0.0
    for i in range(n):
        scale = atol + rtol * abs(y[i])
        d0 += (y[i] / scale) ** 2
        d1 += (f[i] / scale) ** 2
    d0 = math.sqrt(d0 / n)
    d1 = math.sqrt(d1 / n)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    for i in range(n):
        tmp[i] = y[i] + h0 * f[i]
    sys_field_at(sv, p, mode, tmp, 0, u, ftmp, 0, lam, 0)
    d2 = 0.0
    for i in range(n):
        scale = atol + rtol * abs(y[i])
        d2 += ((ftmp[i] - f[i]) / scale) ** 2
    d2 = math.sqrt(d2 / n) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / 8.0)
    return min(100.0 * h0, h1, h_max)


@nb.njit(**HOT_PATH, inline="always")
def _all_guards(p, sv, mode, u, code, y, lam, out):
    sys_guard_values(sv, p, mode, u, code, y, 0, lam, 0, out)


@nb.njit(**HOT_PATH)
def simulate_maneuver(p, sv, code, s, u, cfg, samples, events, y_out, y0, mode0):
    """Integrate maneuver ``code`` from t = 0 to its terminal event: from its initial state at
    s, or, when y0 has 2d entries, from (y0, mode0) (a trajectory continued after an event;
    s then unused). One compiled call per trajectory, and one function: a wrapper around the
    kernel cost a second compile, in which LLVM optimises the linked step again (~1 s).

    The contact mode (what events, samples and the result report) is ``basis | held``:
    ``basis``, the mode the system's functions are called in, has independent rows; ``held``
    are the contacts whose rows depend on the basis's (0 unless some do, SYSTEMS.md Sec. 5).

    Returns (status, t_final, mode_final, n_events, n_samples, nfev, nsteps, nrejected,
    outcome at the final state).
    """
    ncon = sv[SV_NCON]
    maneuver = SV_GUARDS + 2 * ncon + MANEUVER_WIDTH * code  # (this maneuver's entries)
    term_after_touchdown = sv[maneuver + 2] != 0 and cfg[CFG_TOUCHED_DOWN] == 0.0
    term_mode = sv[maneuver + 3]
    t_end = cfg[CFG_T_END]
    max_events = int(cfg[CFG_MAX_EVENTS])
    rtol = cfg[CFG_RTOL]
    atol = cfg[CFG_ATOL]
    h_max = cfg[CFG_H_MAX]
    sample_dt = cfg[CFG_SAMPLE_DT]
    term = ncon  # index of the terminal guard
    nguards = ncon + 1
    nlam = max(ncon, 1)

    n = sv[SV_NSTATE]
    d = n // 2
    workspace = sv[SV_WORKSPACE]
    # one allocation carved into views (a dozen small arrays cost more than a step)
    # (the matrices apart: a reshaped view would call Numba's run-time reshape, which a
    # kernel library loaded without Numba does not have, biped_opt.codegen.native)
    buf = np.zeros(workspace + 6 * n + 6 * nlam + 3 * nguards)
    W = buf[:workspace]
    o = workspace
    F = np.zeros((7, n))
    y = buf[o:o + n]
    f = buf[o + n:o + 2 * n]
    y_new = buf[o + 2 * n:o + 3 * n]
    f_new = buf[o + 3 * n:o + 4 * n]
    tmp = buf[o + 4 * n:o + 5 * n]
    tmp2 = buf[o + 5 * n:o + 6 * n]
    o += 6 * n
    rates = buf[o:o + nlam]
    lam = buf[o + nlam:o + 2 * nlam]
    lam_new = buf[o + 2 * nlam:o + 3 * nlam]
    lam_tmp = buf[o + 3 * nlam:o + 4 * nlam]
    rate0 = buf[o + 4 * nlam:o + 5 * nlam]  # Da q' at the step's start
    rate1 = buf[o + 5 * nlam:o + 6 * nlam]  # and at its end
    o += 6 * nlam
    gv = buf[o:o + nguards]
    gv_new = buf[o + nguards:o + 2 * nguards]
    probe = buf[o + 2 * nguards:o + 3 * nguards]
    o += 3 * nguards
    Da = np.zeros((ncon, d))  # the constraints' Jacobian, at events
    Q = np.zeros((ncon + 1, d))  # its rows, orthonormal
    flags = np.zeros(2 * nguards, dtype=np.bool_)
    armed = flags[:nguards]
    flips = flags[nguards:]
    if y0.shape[0] == n:
        for k in range(n):
            y[k] = y0[k]
        mode = mode0
    else:
        sys_initial_state(sv, code, s, p, y)
        mode = sv[maneuver + 4]
    t = 0.0
    nfev = 0
    nsteps = 0
    nrejected = 0
    n_events = 0
    ns = 0
    status = OK
    term_enabled = not term_after_touchdown
    sampling = sample_dt > 0.0
    next_sample = 0
    finished = False
    held = 0
    # dependent contact sets are looked for only in systems that have them (SV_DEPENDENT): the
    # others take the paths they took before, to the last bit and at no cost
    may_depend = sv[SV_DEPENDENT] != 0
    if may_depend and _count(mode) >= 2:
        # an initial mode with dependent rows continues in a basis of it
        _jacobian(p, sv, y, tmp, rates, Da)
        independent, _k = _independent(Da, Q, mode, mode)
        if independent != mode:
            chosen = _consistent_basis(p, sv, mode, 0, u, code, y, f, lam, tmp, tmp2, rates,
                                       lam_tmp, Da, Q)
            nfev += 1 << ncon
            if chosen < 0:
                status = INCONSISTENT
                finished = True
            else:
                _all_guards(p, sv, chosen, u, code, y, lam, gv)
                held = _held(p, sv, y, chosen, gv, tmp, rates, Da, Q, True)
                mode = chosen

    sys_field_at(sv, p, mode, y, 0, u, f, 0, lam, 0)
    nfev += 1
    _all_guards(p, sv, mode, u, code, y, lam, gv)
    sys_constraint_rates(sv, p, y, 0, rate0)
    for i in range(nguards):
        armed[i] = gv[i] > REARM_TOL and not held >> i & 1
    if not term_enabled:
        armed[term] = False
    if sampling:
        ns = _record_sample(sv, samples, ns, t, y, mode | held, lam)
        next_sample = 1

    h = _initial_step(p, sv, mode, u, y, f, rtol, atol, h_max, tmp, tmp2, lam_tmp)
    nfev += 1
    trial = True
    step_rejected = False

    while not finished:
        if nsteps >= _MAX_STEPS or h < 1e-14 * max(1.0, t):
            status = STEP_FAILURE
            break
        if t >= t_end:
            status = HORIZON
            break
        h_step = min(h, h_max, t_end - t)
        err = sys_step(sv, p, mode, u, code, y, f, h_step, W, y_new, f_new, lam_new, rtol, atol,
                       probe)
        nfev += 12
        nsteps += 1
        if not err < 1.0:
            h = h_step * max(_MIN_FACTOR_TRIAL if trial else _MIN_FACTOR,
                             _SAFETY * _inverse_eighth_root(err))
            nrejected += 1
            step_rejected = True
            continue
        if err == 0.0:
            factor = _MAX_FACTOR
        else:
            factor = min(_MAX_FACTOR, _SAFETY * _inverse_eighth_root(err))
        if step_rejected:
            factor = min(1.0, factor)
        step_rejected = False
        trial = False
        h = h_step * factor

        _all_guards(p, sv, mode, u, code, y_new, lam_new, gv_new)
        sys_constraint_rates(sv, p, y_new, 0, rate1)
        # candidates: an armed guard seen <= 0 at the end or at a stage state; a constraint in
        # the air that is above the ground at both ends but was moving down at the start and
        # up at the end (its lowest point is inside the step: is it below the ground?); a
        # constraint disarmed after an event that ends the step at or below the ground (it
        # may have left and come back within the step). Held contacts are no guards.
        any_candidate = False
        for i in range(nguards):
            if armed[i] and gv[i] > 0.0 and (gv_new[i] <= 0.0 or probe[i] <= 1.0):
                any_candidate = True
            elif i < ncon and not (mode | held) >> i & 1:
                if armed[i]:
                    if gv[i] > 0.0 and rate0[i] < 0.0 and rate1[i] > 0.0:
                        any_candidate = True
                elif gv_new[i] <= 0.0:
                    any_candidate = True

        dense_ready = False
        if any_candidate or sampling:
            sys_dense_coefficients(sv, p, mode, u, y, f, h_step, W, y_new, f_new, F)
            nfev += 3
            dense_ready = True

        first = -1
        x_first = 2.0
        wrong_way = False
        if any_candidate:
            # the armed guards first, then the reset constraints, searched only up to the
            # earliest root found (the common case: the step also holds the terminal event)
            for i in range(nguards):
                if not armed[i] or gv[i] <= 0.0:
                    continue
                if gv_new[i] <= 0.0:
                    xb = 1.0
                    gb = gv_new[i]
                elif probe[i] <= 1.0:
                    xb, gb = _first_probe(p, sv, mode, u, code, F, y, i, 0.0, probe[i], _PROBES,
                                          0.0, tmp, lam_tmp)
                    if xb < 0.0:
                        continue
                elif i < ncon and not mode >> i & 1 and rate0[i] < 0.0 and rate1[i] > 0.0:
                    # its lowest point is inside the step: at or below the ground?
                    xb, gb = _extremum(p, sv, mode, u, code, F, y, i, 0.0, rate0[i], 1.0,
                                       rate1[i], 0.0, tmp, lam_tmp, rates)
                    if gb > 0.0:
                        continue
                else:
                    continue
                x = _root_on_dense(p, sv, mode, u, code, F, y, i, 0.0, gv[i], xb, gb, tmp, lam_tmp)
                if x < x_first:
                    x_first = x
                    first = i
            for i in range(ncon):
                if armed[i] or (mode | held) >> i & 1 or gv_new[i] > 0.0:
                    continue
                x_end = min(x_first, 1.0)
                g_end = gv_new[i]
                if x_end < 1.0:
                    g_end = _guard_on_dense(p, sv, mode, u, code, F, y, x_end, i, tmp, lam_tmp)
                    if g_end > 0.0:
                        continue
                xa = _separation_point(p, sv, mode, u, code, F, y, i, rate0[i], rate1[i], x_end,
                                       tmp, lam_tmp, rates)
                if xa < 0.0:
                    wrong_way = wrong_way or g_end < -REARM_TOL
                    continue
                ga = _guard_on_dense(p, sv, mode, u, code, F, y, xa, i, tmp, lam_tmp)
                # the first probe at or below, else the end of the searched part
                xb, gb = _first_probe(p, sv, mode, u, code, F, y, i, xa, x_end, _PROBES - 1, 0.0,
                                      tmp, lam_tmp)
                if xb < 0.0:
                    xb = x_end
                    gb = g_end
                x = _root_on_dense(p, sv, mode, u, code, F, y, i, xa, ga, xb, gb, tmp, lam_tmp)
                # a return approaches its surface; a root where the constraint moves away (or
                # rests) is the rounding of a gap at ~0 (a release's first instants), no landing
                if x < x_first and _rate_on_dense(p, sv, F, y, x, i, tmp, rates) \
                        < -SEPARATION_TOL:
                    x_first = x
                    first = i
        t_stop = t + h_step if first < 0 else t + x_first * h_step

        if sampling and dense_ready:
            while True:
                ts = next_sample * sample_dt
                if ts > t_stop or (first >= 0 and ts >= t_stop):
                    break
                _dense_eval(F, y, (ts - t) / h_step, tmp)
                sys_field_at(sv, p, mode, tmp, 0, u, tmp2, 0, lam_tmp, 0)
                nfev += 1
                ns = _record_sample(sv, samples, ns, ts, tmp, mode | held, lam_tmp)
                next_sample += 1

        if first < 0:
            t = t_stop
            for k in range(n):
                y[k] = y_new[k]
                f[k] = f_new[k]
            for j in range(nlam):
                lam[j] = lam_new[j]
                rate0[j] = rate1[j]
            for i in range(nguards):
                gv[i] = gv_new[i]
                if held >> i & 1:
                    if gv[i] < -VIOLATION_TOL:
                        status = CONSTRAINT_VIOLATED  # a held contact went through its surface
                        finished = True
                    elif gv[i] > VIOLATION_TOL:
                        # it rose off its surface: held only where its row coincided with the
                        # basis's (not for every q); it is in the air from here, at zero force
                        held &= ~(1 << i)
                        armed[i] = True
                elif not armed[i] and (i < term or term_enabled):
                    if gv[i] > REARM_TOL:
                        armed[i] = True
                    elif i < term and mode >> i & 1 and gv[i] < -REARM_TOL:
                        wrong_way = True  # a contact's reaction turned to pulling at once
            if wrong_way and not finished:
                status = INCONSISTENT  # a disarmed contact guard went the wrong way
                finished = True
            continue

        # --- event at t_stop: the state is the 7th-order interpolant at the root -----------
        t = t_stop
        _dense_eval(F, y, x_first, tmp)
        for k in range(n):
            y[k] = tmp[k]
        sys_field_at(sv, p, mode, y, 0, u, f, 0, lam, 0)
        nfev += 1
        _all_guards(p, sv, mode, u, code, y, lam, gv_new)
        # contact guards near zero and moving toward it flip with a contact guard (MODEL.md
        # Sec. 3); the terminal guard is ordered by time: it never joins contact events
        rates_known = False
        for i in range(nguards):
            flips[i] = i == first
            if i == first or i == term or first == term or held >> i & 1:
                continue
            if abs(gv_new[i]) > SIMULTANEOUS_TOL:
                continue
            if armed[i]:
                flips[i] = _guard_rate(p, sv, mode, u, code, y, f, i, tmp, lam_tmp) < 0.0
            elif not mode >> i & 1:
                # a constraint that an earlier event left at ~0 with a velocity >= 0 (a
                # bounce, a liftoff, a release) and that approaches its surface now has flown
                # and comes back: it joins, however low its flight (arming only keeps a reset
                # constraint from flipping at its own reset)
                if not rates_known:
                    sys_constraint_rates(sv, p, y, 0, rates)
                    rates_known = True
                flips[i] = rates[i] < -SEPARATION_TOL
        for j in range(ncon):
            if held >> j & 1:
                if gv_new[j] < -VIOLATION_TOL:
                    status = CONSTRAINT_VIOLATED  # a held contact went through its surface
                    finished = True
                elif gv_new[j] > VIOLATION_TOL:
                    held &= ~(1 << j)  # (it rose off its surface, as at a step end)
            elif not flips[j] and not mode >> j & 1 and gv_new[j] < -VIOLATION_TOL:
                status = CONSTRAINT_VIOLATED  # (a root missed before this event)
                finished = True
        touchdown = 0
        liftoff = 0
        for j in range(ncon):
            if flips[j]:
                if mode >> j & 1:
                    liftoff |= 1 << j
                else:
                    touchdown |= 1 << j
        if (touchdown | liftoff) and not finished:
            row = events[n_events]
            row[0] = t
            row[1] = EVENT_CONTACT
            row[2] = touchdown
            row[3] = liftoff
            contact = mode | held
            row[4] = contact
            for k in range(n):
                row[6 + k] = y[k]
            if sampling:
                ns = _record_sample(sv, samples, ns, t, y, contact, lam)
            term_was_armed = armed[term] and gv_new[term] > 0.0
            before = mode
            # the constraints at rest on their surface after the event's resets
            surface = (contact | touchdown) & ~liftoff
            have_da = False
            pivot = -1
            if may_depend and liftoff and held and not touchdown:
                # a reaction of the basis fell through 0 while some contacts are held: another
                # basis of the same contacts may carry the load (no contact changes: a pivot);
                # else the held contacts that only the lifted ones supported lift with them
                _jacobian(p, sv, y, tmp, rates, Da)
                have_da = True
                pivot = _pivot(p, sv, mode, held, liftoff, u, code, y, f, lam, tmp, tmp2, rates,
                               lam_tmp, Da, Q)
                nfev += 1 << _count(held)
                if pivot < 0:
                    kept = mode & ~liftoff
                    _b, k = _independent(Da, Q, kept, kept)
                    for j in range(ncon):
                        if held >> j & 1 and not _depends(Da, Q, k, j):
                            surface &= ~(1 << j)
            if touchdown:
                impacted = surface
                if may_depend and _count(surface) >= 2:
                    # Eq. (1b) for a set with dependent rows: any basis of it gives the same
                    # velocities (the rows' dependence carries over to their velocities)
                    _jacobian(p, sv, y, tmp, rates, Da)
                    have_da = True
                    impacted, _k = _independent(Da, Q, surface, mode)
                sys_apply_impact(sv, p, impacted, y)
                if not may_depend and _count(surface) >= 2 and not _finite(y):
                    # rows that coincide at this very configuration (not for every q, so the
                    # table does not flag the system): the impact again, with an independent
                    # subset of the impacted set, from the state before it
                    for k in range(n):
                        y[k] = row[6 + k]
                    _jacobian(p, sv, y, tmp, rates, Da)
                    have_da = True
                    impacted, _k = _independent(Da, Q, surface, mode)
                    sys_apply_impact(sv, p, impacted, y)
                # restitution: an impacted constraint moving apart leaves the mode at once
                sys_constraint_rates(sv, p, y, 0, rates)
                for j in range(ncon):
                    if touchdown >> j & 1 and rates[j] > SEPARATION_TOL:
                        surface &= ~(1 << j)
            if pivot >= 0:
                mode = pivot  # (f and lam hold its field and reactions)
            elif not may_depend:
                mode = surface
                sys_field_at(sv, p, mode, y, 0, u, f, 0, lam, 0)
                nfev += 1
                # complementarity: the next mode has every active constraint pressing
                # (lambda >= 0) and every released one not accelerating into its surface;
                # when the mode the event suggests has a pulling contact, the others are tried
                # (and when its reactions are not numbers: rows that coincide at this very
                # configuration, a singular Schur complement, which no candidate with both
                # passes)
                for j in range(ncon):
                    if mode >> j & 1 and not lam[j] >= 0.0:
                        chosen = _consistent_mode(p, sv, mode, u, y, f, lam, tmp, tmp2, rates)
                        nfev += 1 << ncon
                        if chosen < 0:
                            status = INCONSISTENT  # no mode fits: every one pulls or penetrates
                            finished = True
                        else:
                            mode = chosen
                        break
            else:
                # a system with dependent sets: continue in a basis of the surface's contacts
                # that satisfies complementarity (the surface itself first when it is
                # independent), none of whose reactions is ~0 and falling
                if not have_da:
                    _jacobian(p, sv, y, tmp, rates, Da)
                    have_da = True
                chosen = _consistent_basis(p, sv, surface, mode, u, code, y, f, lam, tmp, tmp2,
                                           rates, lam_tmp, Da, Q)
                nfev += 1 << ncon
                if chosen < 0:
                    status = INCONSISTENT
                    finished = True
                    mode = surface  # (reported as the mode no basis of which fits)
                else:
                    mode = chosen
            if pivot >= 0:
                held = contact & ~mode
                _all_guards(p, sv, mode, u, code, y, lam, gv)
            else:
                held = 0
            if not finished and pivot < 0:
                _all_guards(p, sv, mode, u, code, y, lam, gv)
                # contacts whose rows depend on the basis stay on their surface with it
                if may_depend:
                    held = _held(p, sv, y, mode, gv, tmp, rates, Da, Q, have_da)
            elif finished and not may_depend:
                _all_guards(p, sv, mode, u, code, y, lam, gv)
            row[5] = mode | held
            for k in range(n):
                row[6 + n + k] = y[k]
            if touchdown or mode | held != contact or finished:
                n_events += 1
            # (else only the basis of the same contacts changed: not a contact event)
            if sampling:
                ns = _record_sample(sv, samples, ns, t, y, mode | held, lam)
            if touchdown and term_after_touchdown:
                term_enabled = True
            sys_constraint_rates(sv, p, y, 0, rate0)
            for i in range(nguards):
                if held >> i & 1:
                    armed[i] = False  # (a held contact has no guard)
                elif flips[i] or not armed[i] or (i < term and (before ^ mode) >> i & 1):
                    # events can follow each other without a plain step between them (a bar's
                    # impacts 1e-7 apart): a guard away from zero since is armed again here;
                    # one at ~0 (a reset constraint) is watched by the next steps instead; a
                    # constraint whose guard changed kind (released or taken into the basis
                    # without flipping) starts afresh
                    armed[i] = gv[i] > REARM_TOL and (i < term or term_enabled)
            h *= _EVENT_STEP_FRACTION
            trial = True
            if term_was_armed and gv[term] <= 0.0 and not finished:
                flips[term] = True  # the reset itself took the terminal guard through 0
            if not finished and n_events >= max_events and not flips[term]:
                status = MAX_EVENTS
                finished = True
        if flips[term] and not finished:
            row = events[n_events]
            row[0] = t
            row[1] = EVENT_TERMINAL
            row[2] = 0
            row[3] = 0
            row[4] = mode | held
            row[5] = mode | held
            for k in range(n):
                row[6 + k] = y[k]
                row[6 + n + k] = y[k]
            if term_mode >= 0 and mode | held != term_mode:
                status = APEX_IN_CONTACT
            finished = True

    if sampling:
        ns = _record_sample(sv, samples, ns, t, y, mode | held, lam)
    for k in range(n):
        y_out[k] = y[k]
    outcome = sys_outcome_value(sv, code, p, y_out, 0)
    return status, t, mode | held, n_events, ns, nfev, nsteps, nrejected, outcome


@nb.njit(**HOT_PATH, nogil=True)
def simulate_batch_kernel(p, sv, code, ss, us, cfg, events, y_out, outcome, info, start, stop):
    """:func:`simulate_maneuver` for the cases start <= k < stop of many s and inputs (row k of
    each array); ``outcome[k]`` receives the maneuver's outcome at the final state. It releases
    the GIL: Python threads run it on disjoint ranges in parallel
    (:meth:`biped_opt.simulation.compiled.CompiledSystem.simulate_batch` hands out the ranges),
    which shares the work out by how fast each thread actually runs, where a parallel loop
    splits it evenly in advance and waits for a thread whose core is busy elsewhere."""
    no_samples = np.empty((0, 2 + sv[SV_NSTATE] + sv[SV_NCON]))
    from_s = np.empty(0)  # (FROM_S, allocated here: a global array would be frozen into code)
    # (unused with from_s; a variable, not a literal 0, which Numba would compile a second
    # specialisation of the whole kernel for)
    mode0 = sv[SV_GUARDS + 2 * sv[SV_NCON] + MANEUVER_WIDTH * code + 4]
    for k in range(start, stop):
        status, t_f, mode_f, n_ev, n_s, nfev, nsteps, nrej, value = simulate_maneuver(
            p, sv, code, ss[k], us[k], cfg, no_samples, events[k], y_out[k], from_s, mode0
        )
        outcome[k] = value
        info[k, 0] = status
        info[k, 1] = t_f
        info[k, 2] = mode_f
        info[k, 3] = n_ev
        info[k, 4] = n_s
        info[k, 5] = nfev
        info[k, 6] = nsteps
        info[k, 7] = nrej


@nb.njit(**HOT_PATH)
def variational_field(p, sv, mode, w, u, du, step, steps, weights, out, lam):
    """d/dt of w = (y, Z), Z = dy/dp stored row-major (2d x k), into ``out``; returns the
    field evaluations used. f(y, u) first; then column c of Z' is the derivative of f along
    (Z[:, c], du[:, c]): the central difference sum_b weights[b] f(y + steps[b] h Z[:, c],
    u + steps[b] h du[:, c]) / (12 h), h = step / (the column's largest entry), 0 for a zero
    column. The arithmetic of :meth:`biped_opt.control.derivatives._Model.variational_rhs`
    in one compiled call (from Python, each field evaluation cost a dispatch)."""
    n = sv[SV_NSTATE]
    k = du.shape[1]
    m = u.shape[0]
    sys_field_at(sv, p, mode, w, 0, u, out, 0, lam, 0)
    ys = np.empty(n)
    us = np.empty(m)
    fs = np.empty(n)
    acc = np.empty(n)
    count = 1
    for c in range(k):
        scale = 0.0
        for i in range(n):
            scale = max(scale, abs(w[n + i * k + c]))
        for i in range(du.shape[0]):
            scale = max(scale, abs(du[i, c]))
        if scale == 0.0:
            for i in range(n):
                out[n + i * k + c] = 0.0
            continue
        h = step / scale
        for b in range(steps.shape[0]):
            off = steps[b] * h
            for i in range(n):
                ys[i] = w[i] + off * w[n + i * k + c]
            for i in range(m):
                us[i] = u[i] + off * du[i, c]
            sys_field_at(sv, p, mode, ys, 0, us, fs, 0, lam, 0)
            for i in range(n):
                acc[i] = weights[0] * fs[i] if b == 0 else acc[i] + weights[b] * fs[i]
            count += 1
        for i in range(n):
            out[n + i * k + c] = acc[i] / (12.0 * h)
    return count


def compile_all() -> float:
    """Compile the kernel's entry points for the types they are called with (or load them from
    Numba's cache); returns the seconds it took. ``make venv`` runs it once after installing,
    so that no system's first compile includes the kernel's."""
    import time

    t0 = time.perf_counter()
    for name, signature in abi.ENTRY_SIGNATURES.items():
        globals()[name].compile(signature)
    return time.perf_counter() - t0


if __name__ == "__main__":
    print(f"biped_opt's shared kernel compiled (or loaded) in {compile_all():.1f} s")
