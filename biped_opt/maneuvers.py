"""The touchdown and liftoff maneuvers of [1]_ Sec. IV (MODEL.md Sec. 4).

A maneuver fixes the initial state as a function of the initial body pitch th0, the initial
contact mode, and the terminal event; its *outcome* is the body pitch th(t_f) at that event.

- **touchdown**: falls from rest, legs at rest length and perpendicular to the body, and ends at
  the body's nadir (z' rising through 0 after the first touchdown). Valid for |th0| <= 0.25.
- **liftoff**: pushes off from rest in double stance with vertical, compressed legs, and ends at the
  body's apex (z' falling through 0), which must come after both feet left the ground. Valid for
  |th0| <= 0.3.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numba as nb
import numpy as np
import numpy.typing as npt

from biped_opt._jit import HOT_PATH
from biped_opt.errors import InvalidInputError, quoted
from biped_opt.model.biped import NSTATE
from biped_opt.model.modes import ContactMode
from biped_opt.model.params import BipedParams

__all__ = ["Maneuver", "ManeuverSpec", "spec", "initial_state", "parse_maneuver"]

_DEFAULT_PARAMS = BipedParams()


class Maneuver(str, enum.Enum):
    """The two maneuvers of the paper."""

    TOUCHDOWN = "touchdown"
    LIFTOFF = "liftoff"


@dataclass(frozen=True)
class ManeuverSpec:
    """What the simulator needs to know about a maneuver besides its initial state."""

    maneuver: Maneuver
    initial_mode: ContactMode
    #: +1: ends when z' falls through 0 (apex); -1: when z' rises through 0 (nadir)
    term_sign: float
    #: the terminal event counts only after the first touchdown
    term_after_touchdown: bool
    #: mode the terminal event must occur in (None: any); otherwise status APEX_IN_CONTACT
    term_mode: ContactMode | None
    #: valid range of |th0| (beyond it the legs splay and other mode sequences appear)
    theta0_limit: float
    #: one line for humans
    description: str
    #: index of the maneuver in the compiled initial-state function
    code: int

    #: the initial mode as a plain int (what the compiled kernels take)
    mode_code: int = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode_code", int(self.initial_mode))


_SPECS = {
    Maneuver.TOUCHDOWN: ManeuverSpec(
        maneuver=Maneuver.TOUCHDOWN,
        initial_mode=ContactMode.AIR,
        term_sign=-1.0,
        term_after_touchdown=True,
        term_mode=None,
        theta0_limit=0.25,
        description="fall from rest at z = 1 to the body's nadir after touchdown",
        code=0,
    ),
    Maneuver.LIFTOFF: ManeuverSpec(
        maneuver=Maneuver.LIFTOFF,
        initial_mode=ContactMode.GROUND,
        term_sign=1.0,
        term_after_touchdown=False,
        term_mode=ContactMode.AIR,
        theta0_limit=0.3,
        description="push off from double stance at z = l0 - 0.15 to the body's apex in the air",
        code=1,
    ),
}

_SPECS_BY_NAME = {m.value: s for m, s in _SPECS.items()}

#: initial body height of the touchdown maneuver [length]
TOUCHDOWN_HEIGHT = 1.0
#: initial leg compression of the liftoff maneuver [length]
LIFTOFF_COMPRESSION = 0.15


def parse_maneuver(value: Maneuver | str) -> Maneuver:
    """The :class:`Maneuver` named by ``value``; raises InvalidInputError naming ``maneuver``."""
    if isinstance(value, Maneuver):
        return value
    try:
        return Maneuver(str(value).strip().lower())
    except ValueError:
        names = ", ".join(m.value for m in Maneuver)
        raise InvalidInputError(
            f"maneuver must be one of {names}; got {quoted(value)}") from None


def spec(maneuver: Maneuver | str | ManeuverSpec) -> ManeuverSpec:
    """The :class:`ManeuverSpec` of ``maneuver``."""
    if isinstance(maneuver, ManeuverSpec):
        return maneuver
    found = _SPECS_BY_NAME.get(maneuver) if isinstance(maneuver, str) else None
    return found if found is not None else _SPECS[parse_maneuver(maneuver)]


def check_theta0(maneuver: Maneuver | str | ManeuverSpec, theta0: float) -> float:
    """theta0 as a float, validated against the maneuver's range; the error names ``theta0``."""
    s = spec(maneuver)
    if type(theta0) is float and abs(theta0) <= s.theta0_limit:  # the common case (NaN fails)
        return theta0
    try:
        value = float(theta0)
    except (TypeError, ValueError):
        raise InvalidInputError(f"theta0 must be a number, got {theta0!r}") from None
    if not math.isfinite(value):
        raise InvalidInputError(f"theta0 must be finite, got {value}")
    if abs(value) > s.theta0_limit:
        raise InvalidInputError(
            f"theta0 = {value} is outside the valid range |theta0| <= {s.theta0_limit} "
            f"of the {s.maneuver.value} maneuver"
        )
    return value


@nb.njit(**HOT_PATH)
def fill_initial_state(code: int, th: float, p: npt.NDArray[np.float64],
                       y0: npt.NDArray[np.float64]) -> None:
    """Initial state of maneuver ``code`` (ManeuverSpec.code) at pitch th into y0 (14,).

    touchdown: at rest at z = 1, legs at rest length and perpendicular to the body,
    foot_j = body + R(th) (s_j w, -l0); liftoff: at rest at z = l0 - 0.15 with vertical,
    compressed legs, feet on the ground directly below the hips. p: packed parameters.
    """
    l0, w = p[4], p[5]
    wc = w * math.cos(th)
    ws = w * math.sin(th)
    for i in range(y0.shape[0]):
        y0[i] = 0.0
    y0[2] = th
    if code == 0:
        z = TOUCHDOWN_HEIGHT
        lx = l0 * math.sin(th)
        lz = l0 * math.cos(th)
        y0[1] = z
        y0[3] = -wc + lx
        y0[4] = z - ws - lz
        y0[5] = wc + lx
        y0[6] = z + ws - lz
    else:
        y0[1] = l0 - LIFTOFF_COMPRESSION
        y0[3] = -wc
        y0[5] = wc


def initial_state(
    maneuver: Maneuver | str | ManeuverSpec, theta0: float, params: BipedParams | None = None
) -> tuple[npt.NDArray[np.float64], ContactMode]:
    """Initial state y0 = (q, q') and contact mode of ``maneuver`` at body pitch ``theta0``."""
    s = spec(maneuver)
    th = check_theta0(s, theta0)
    p = params if params is not None else _DEFAULT_PARAMS
    y0 = np.empty(NSTATE)
    fill_initial_state(s.code, th, p.as_array(), y0)
    return y0, s.initial_mode
