"""Contact modes of the biped: the set J of active unilateral constraints (paper Sec. II-A).

A mode is stored as a bit mask over the constraints: bit 0 is the left foot (constraint 1), bit 1
the right foot (constraint 2). The integer values equal the constants of
``biped_opt_interfaces/msg/ContactMode``, so a mode crosses every boundary as its plain value.
"""

from __future__ import annotations

import enum

__all__ = ["ContactMode", "LEFT_BIT", "RIGHT_BIT"]

LEFT_BIT = 1
RIGHT_BIT = 2


class ContactMode(enum.IntEnum):
    """Contact mode J of the biped: AIR = {}, LEFT = {1}, RIGHT = {2}, GROUND = {1, 2}."""

    AIR = 0
    LEFT = LEFT_BIT
    RIGHT = RIGHT_BIT
    GROUND = LEFT_BIT | RIGHT_BIT

    @property
    def active(self) -> tuple[int, ...]:
        """Indices (0-based) of the active constraints, i.e. the feet on the ground."""
        return tuple(j for j in range(2) if self.value >> j & 1)

    @classmethod
    def from_active(cls, active: set[int] | frozenset[int] | tuple[int, ...]) -> ContactMode:
        """Mode whose active constraints are ``active`` (0-based foot indices)."""
        mask = 0
        for j in active:
            if j not in (0, 1):
                raise ValueError(f"constraint index must be 0 or 1, got {j}")
            mask |= 1 << j
        return cls(mask)
