"""The sagittal-plane biped of [1]_ Fig. 1 as a mechanical system with unilateral constraints.

MODEL.md Sec. 2. Configuration q = (x, z, th, x1, z1, x2, z2): body centre of mass, body pitch
(counter-clockwise positive) and the two point feet; leg 1 is the left leg (hip at -w along the
body), leg 2 the right (hip at +w). The state is y = (q, q'), 14 floats.

Each leg is a massless spring-damper between its hip and its foot with a mode-dependent actuator
force: u1 acts only in left single stance J = {1}, u2 only in right single stance J = {2}, and the
body torque u12 only in double stance J = {1, 2}. This *force coupling* (paper Sec. II-B) is what
makes outcomes nonsmooth when the order of contact events changes.

The physics is written here by hand, independently of the description the package generates
its simulator from (``systems/library/biped.py``), as compiled functions on flat float arrays,
wrapped by :class:`Biped` for the dense Eq. (1) of :mod:`biped_opt.systems.mechanics`; with the
maneuvers' initial states (MODEL.md Sec. 4) it is the tests' reference model of the biped. The
tests check the generated Eq. (1) and initial states against it, its constraint handling
against Eq. (1) computed with general linear algebra, and the oracle of the biped's variational
equations (:mod:`tests.paper.oracle_biped`) evaluates it directly.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
import numpy.typing as npt

from biped_opt._jit import HOT_PATH
from biped_opt.codegen.runtime import sincos
from biped_opt.paper.biped import BipedParams, ContactMode, Maneuver, check_theta0, parse_maneuver
from biped_opt.systems.mechanics import MechanicalSystem

__all__ = [
    "NDOF",
    "NSTATE",
    "NCONSTRAINTS",
    "Biped",
    "generalised_forces",
    "leg_forces",
    "dynamics",
    "vector_field",
    "sincos",
    "foot_support",
    "apply_impact",
    "energy",
    "packed",
    "initial_state",
]

Array = npt.NDArray[np.float64]

#: order of the parameters in :func:`packed` (the kernels below index by position)
PARAM_ORDER = ("mb", "Ib", "mf", "g", "l0", "w", "k", "c", "gamma")


def packed(params: BipedParams) -> Array:
    """The parameters as the functions below take them: :data:`PARAM_ORDER`, then the inverse
    masses 1/mb, 1/Ib, 1/mf."""
    return np.array([getattr(params, name) for name in PARAM_ORDER]
                    + [1.0 / params.mb, 1.0 / params.Ib, 1.0 / params.mf])


NDOF = 7  #: configuration dimension d
NSTATE = 2 * NDOF  #: state dimension, y = (q, q')
NCONSTRAINTS = 2  #: unilateral constraints a_j(q) = z_j >= 0, one per foot
#: index in y of each foot's height z_j (the constraint a_j) ...
FOOT_Z = (4, 6)
#: ... and of its vertical velocity z_j'
FOOT_DZ = (11, 13)
BODY_DZ = 8  #: index in y of the body's vertical velocity z'




@nb.njit(**HOT_PATH, inline="always")
def _leg(p: Array, y: Array, yo: int, j: int, side: float, wct: float, wst: float, ubar: float
         ) -> tuple[float, float, float]:
    """(F_j, n_jx, n_jz) of leg j (hip at ``side`` * w along the body) for the state at
    y[yo:yo + 14], MODEL.md Sec. 2.

    F_j = k (l0 - L_j) - c L_j' + ubar pushes the hip away from the foot along the unit leg
    vector n_j = e_j / L_j, e_j = hip_j - foot_j.
    """
    ex = y[yo + 0] + side * wct - y[yo + 3 + 2 * j]
    ez = y[yo + 1] + side * wst - y[yo + 4 + 2 * j]
    vx = y[yo + 7] - side * wst * y[yo + 9] - y[yo + 10 + 2 * j]
    vz = y[yo + 8] + side * wct * y[yo + 9] - y[yo + 11 + 2 * j]
    length = math.sqrt(ex * ex + ez * ez)
    inv = 1.0 / length
    nx = ex * inv
    nz = ez * inv
    return p[6] * (p[4] - length) - p[7] * (nx * vx + nz * vz) + ubar, nx, nz


@nb.njit(**HOT_PATH, inline="always")
def leg_forces(p: Array, mode: int, y: Array, yo: int, u: Array
               ) -> tuple[float, float, float, float, float, float, float]:
    """Both legs' forces and unit vectors and the body torque for the state at y[yo:yo + 14]:
    (F1, n1x, n1z, F2, n2x, n2z, torque).

    Force coupling (paper Sec. II-B): u1 acts only in J = {1}, u2 only in J = {2}, the body
    torque u12 only in J = {1, 2}. Straight-line code (no loop over the legs) keeps everything
    in registers, which halves the cost: the simulator evaluates this ~200 times per maneuver.
    The mode selects the inputs by multiplying with 0 or 1, not by branching: see
    :func:`vector_field` for why the inlined hot path has no branches that touch arrays.
    """
    sin_th, cos_th = sincos(y[yo + 2])
    wct = p[5] * cos_th
    wst = p[5] * sin_th
    # inputs are finite (checked on entry), so u * 0.0 is an exact (signed) zero
    f1, n1x, n1z = _leg(p, y, yo, 0, -1.0, wct, wst, u[0] * (mode == 1))
    f2, n2x, n2z = _leg(p, y, yo, 1, 1.0, wct, wst, u[1] * (mode == 2))
    # w (cos th n_z - sin th n_x) is each leg's lever arm about the body's centre
    torque = -(wct * n1z - wst * n1x) * f1 + (wct * n2z - wst * n2x) * f2 + u[2] * (mode == 3)
    return f1, n1x, n1z, f2, n2x, n2z, torque


@nb.njit(**HOT_PATH, inline="always")
def foot_support(p: Array, force: float, nz: float) -> float:
    """mf g + F_j n_jz: the upward force that holds foot j vertically at rest. It is the reaction
    lambda_j while the foot is on the ground (MODEL.md Sec. 2); in the air its negative is the
    foot's net vertical force."""
    return p[2] * p[3] + force * nz


@nb.njit(**HOT_PATH, inline="always")
def _force_components(p: Array, mode: int, y: Array, yo: int, u: Array
                      ) -> tuple[float, float, float, float, float, float, float]:
    """f_J(q, q', u) for the state at y[yo:yo + 14], as values (MODEL.md Sec. 2): body x, z and
    pitch, then foot 1 x, z and foot 2 x, z. Each foot's z force is -(mf g + F_j n_jz), minus
    the reaction that holds it while it is on the ground."""
    f1, n1x, n1z, f2, n2x, n2z, torque = leg_forces(p, mode, y, yo, u)
    return (
        f1 * n1x + f2 * n2x,
        f1 * n1z + f2 * n2z - p[0] * p[3],
        torque,
        -f1 * n1x,
        -foot_support(p, f1, n1z),
        -f2 * n2x,
        -foot_support(p, f2, n2z),
    )


@nb.njit(**HOT_PATH)
def generalised_forces(
    p: Array, mode: int, y: Array, u: Array, f: Array, off: int
) -> None:
    """Write f_J(q, q', u) into ``f[off:off + 7]`` (MODEL.md Sec. 2).

    p: packed parameters (:func:`packed`); mode: contact
    mode bit mask; y: state, shape (14,); u: inputs (u1, u2, u12), shape (3,).
    """
    fx, fz, fth, f1x, f1z, f2x, f2z = _force_components(p, mode, y, 0, u)
    f[off + 0] = fx
    f[off + 1] = fz
    f[off + 2] = fth
    f[off + 3] = f1x
    f[off + 4] = f1z
    f[off + 5] = f2x
    f[off + 6] = f2z


@nb.njit(**HOT_PATH, inline="always")
def vector_field(
    p: Array, mode: int, y: Array, yo: int, u: Array, out: Array, off: int, lam: Array, lo: int
) -> None:
    """Vector field of mode J at the state y[yo:yo + 14]: (q', q'') to ``out[off:off + 14]``,
    the reactions (lambda_1, lambda_2) to ``lam[lo:lo + 2]``.

    Eq. (1a): M is diagonal and Da_j = e_{z_j}, so lambda_j = -f_J[z_j] = mf g + F_j n_jz and
    z_j'' = 0 for every active constraint j; inactive reactions are 0. The contact mode acts
    through factors 0.0 and 1.0, not branches (an inlined function with branches keeps Numba's
    reference counting of its array arguments).
    """
    fx, fz, fth, f1x, f1z, f2x, f2z = _force_components(p, mode, y, yo, u)
    inv_mb, inv_ib, inv_mf = p[9], p[10], p[11]
    for i in range(NDOF):
        out[off + i] = y[yo + NDOF + i]
    out[off + 7] = fx * inv_mb
    out[off + 8] = fz * inv_mb
    out[off + 9] = fth * inv_ib
    out[off + 10] = f1x * inv_mf
    out[off + 12] = f2x * inv_mf
    on1 = float(mode & 1)  # 1.0 while foot 1 is on the ground: lambda_1 holds it, z_1'' = 0
    on2 = float(mode >> 1 & 1)
    # "+ 0.0" turns the -0.0 of a foot in the air into +0.0 (the reactions are reported)
    lam[lo] = -f1z * on1 + 0.0
    lam[lo + 1] = -f2z * on2 + 0.0
    out[off + 11] = f1z * inv_mf * (1.0 - on1)
    out[off + 13] = f2z * inv_mf * (1.0 - on2)


@nb.njit(**HOT_PATH)
def dynamics(p: Array, mode: int, y: Array, u: Array, dy: Array, lam: Array) -> None:
    """Vector field of mode J: dy = (q', q''), and reaction forces lam (shape (2,)), Eq. (1a)."""
    vector_field(p, mode, y, 0, u, dy, 0, lam, 0)


@nb.njit(**HOT_PATH)
def apply_impact(p: Array, mode: int, y: Array) -> None:
    """q'+ = Delta_J q'- in place, on entering mode J, Eq. (1b).

    With M diagonal and Da_j = e_{z_j}, Delta_J only scales each contacting foot's vertical
    velocity by -gamma: the body's velocity does not jump (the legs decouple the feet's impacts).
    """
    gamma = p[8]
    for j in range(2):
        if mode >> j & 1:
            y[11 + 2 * j] *= -gamma


def energy(params: BipedParams, y: Array) -> float:
    """Total mechanical energy: kinetic + gravitational + leg springs (no actuation)."""
    p = params
    q, dq = y[:NDOF], y[NDOF:]
    masses = np.array([p.mb, p.mb, p.Ib, p.mf, p.mf, p.mf, p.mf])
    kinetic = 0.5 * float(masses @ dq**2)
    gravity = p.g * (p.mb * q[1] + p.mf * (q[4] + q[6]))
    springs = 0.0
    for j, s in enumerate((-1.0, 1.0)):
        hip = np.array([q[0] + s * p.w * np.cos(q[2]), q[1] + s * p.w * np.sin(q[2])])
        length = float(np.hypot(*(hip - q[3 + 2 * j : 5 + 2 * j])))
        springs += 0.5 * p.k * (p.l0 - length) ** 2
    return kinetic + gravity + springs


class Biped(MechanicalSystem):
    """The biped through the generic interface of :class:`MechanicalSystem` (Eq. (1) of [1]_)."""

    ndof = NDOF
    nconstraints = NCONSTRAINTS

    def __init__(self, params: BipedParams | None = None) -> None:
        self.params = params if params is not None else BipedParams()
        self._p = packed(self.params)

    @property
    def restitution(self) -> float:
        return self.params.gamma

    def mass_matrix(self, q: Array) -> Array:
        p = self.params
        return np.diag([p.mb, p.mb, p.Ib, p.mf, p.mf, p.mf, p.mf])

    def forces(self, q: Array, dq: Array, u: Array, mode: int) -> Array:
        f = np.empty(NDOF)
        y = np.concatenate([q, dq]).astype(np.float64)
        generalised_forces(self._p, int(mode), y, _inputs3(u), f, 0)
        return f

    def constraints(self, q: Array) -> Array:
        return np.array([q[FOOT_Z[0]], q[FOOT_Z[1]]], dtype=np.float64)

    def constraint_jacobian(self, q: Array) -> Array:
        da = np.zeros((NCONSTRAINTS, NDOF))
        da[0, FOOT_Z[0]] = 1.0
        da[1, FOOT_Z[1]] = 1.0
        return da

    def constraint_jacobian_rate(self, q: Array, dq: Array) -> Array:
        return np.zeros(NCONSTRAINTS)


def _inputs3(u: Array | tuple[float, ...]) -> Array:
    """Inputs padded to (u1, u2, u12)."""
    out = np.zeros(3)
    values = np.asarray(u, dtype=np.float64).ravel()
    out[: values.size] = values
    return out


#: initial body height of the touchdown maneuver [length]
TOUCHDOWN_HEIGHT = 1.0
#: initial leg compression of the liftoff maneuver [length]
LIFTOFF_COMPRESSION = 0.15
#: the initial contact mode of each maneuver
INITIAL_MODE = {Maneuver.TOUCHDOWN: ContactMode.AIR, Maneuver.LIFTOFF: ContactMode.GROUND}


def initial_state(maneuver: Maneuver | str, theta0: float, params: BipedParams | None = None
                  ) -> tuple[Array, ContactMode]:
    """Initial state y0 = (q, q') and contact mode of ``maneuver`` at body pitch ``theta0``
    (MODEL.md Sec. 4). touchdown: at rest at z = 1, legs at rest length and perpendicular to the
    body, foot_j = body + R(th) (s_j w, -l0); liftoff: at rest at z = l0 - 0.15 with vertical,
    compressed legs, feet on the ground directly below the hips."""
    m = parse_maneuver(maneuver)
    th = check_theta0(m, theta0)
    p = params if params is not None else BipedParams()
    wc, ws = p.w * math.cos(th), p.w * math.sin(th)
    y0 = np.zeros(NSTATE)
    y0[2] = th
    if m is Maneuver.TOUCHDOWN:
        z = TOUCHDOWN_HEIGHT
        lx, lz = p.l0 * math.sin(th), p.l0 * math.cos(th)
        y0[1] = z
        y0[3:7] = (-wc + lx, z - ws - lz, wc + lx, z + ws - lz)
    else:
        y0[1] = p.l0 - LIFTOFF_COMPRESSION
        y0[3], y0[5] = -wc, wc
    return y0, INITIAL_MODE[m]
