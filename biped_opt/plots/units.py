"""The units a system's numbers are in, as the pictures label them.

A system description has no item for units (SYSTEMS.md Sec. 6 lists everything a description
says about how it looks); the library's systems state theirs in their documentation, and
:func:`units_of` repeats what it says:

- gravity units, g = 1: the biped (MODEL.md Sec. 2, "Default parameters (gravity units,
  g = 1)"), the n-leg walkers built on its parameters (SYSTEMS.md Sec. 3), the rocking bar
  (Sec. 2, g = 1), the chains (Sec. 3a, g = 1) and the smoothed biped and bar made from them.
  Lengths are in a length unit, times in the time unit that unit and g = 1 give;
- SI: the quadruped (its module: "default parameters (SI units)", g = 9.81): m and s.

In both, the coordinates named x, y, z or x, y, z and a number (positions; the feet's) are
lengths and every other coordinate is an angle in rad. Any other system, a system file among
them, states none: its numbers are in "model units" and its coordinates' units are unknown.
A system built in Python under a library system's name counts as that system.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = ["Units", "GRAVITY", "SI", "MODEL", "units_of", "LIBRARY_UNITS"]

#: a library system's coordinate that is a position (the rest are angles)
_POSITION = re.compile(r"^[xyz][0-9]*$")


@dataclass(frozen=True)
class Units:
    """What a system's numbers are in: ``name`` as its documentation calls them, the
    ``length`` and ``time`` units as an axis label writes them, and whether its coordinates'
    units are known (positions in ``length``, angles in rad)."""

    name: str
    length: str
    time: str
    known: bool = True

    @property
    def axes_note(self) -> str:
        """One line saying what the x-z plane and the clock are in."""
        if not self.known:
            return "x, z and t in model units (the system states none)"
        return f"x, z in {self.length}, t in {self.time} ({self.name})"

    def coordinate(self, name: str) -> str | None:
        """The unit of coordinate ``name`` (rad for an angle), None when unknown."""
        if not self.known:
            return None
        return self.length if _POSITION.match(name) else "rad"

    def outcome(self, expression: str) -> str | None:
        """The unit of an outcome that is one coordinate ``q`` or its rate ``q_dot``; None
        for any other expression or where units are unknown."""
        base, rate = (expression[:-4], True) if expression.endswith("_dot") else \
            (expression, False)
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", base):
            return None
        unit = self.coordinate(base)
        if unit is None or not rate:
            return unit
        per = "s" if self.time == "s" else "time unit"
        return f"{unit}/{per}"


GRAVITY = Units("gravity units, g = 1", "length units", "time units")
SI = Units("SI", "m", "s")
MODEL = Units("model units", "model units", "model units", known=False)

#: library system names (patterns) -> their units, as their documentation states them
LIBRARY_UNITS: tuple[tuple[re.Pattern[str], Units], ...] = (
    (re.compile(r"^(biped|biped_smooth|rocking_bar|rocking_bar_soft)$"), GRAVITY),
    (re.compile(r"^walker[0-9]*(_coupled|_decoupled)?(_offsets)?$"), GRAVITY),
    (re.compile(r"^chain(5|7|9|11)?$"), GRAVITY),
    (re.compile(r"^quadruped$"), SI),
)


def units_of(name: str | None, source: str | None = None) -> Units:
    """The units of the system called ``name`` and loaded from ``source`` (a library name
    or a system file's path; None: built in Python or from the library): a library system's
    as its documentation states them, :data:`MODEL` for any other (a file may reuse a library
    system's name: its own numbers are its own)."""
    key = name if source is None else source
    for pattern, units in LIBRARY_UNITS:
        if key is not None and pattern.match(key):
            return units
    return MODEL
