"""The paper's sagittal biped (MODEL.md Sec. 2) as a description: the walker with two legs,
feet ``left`` and ``right``, inputs u1, u2 (single stance) and u12 (double stance)."""

from __future__ import annotations

from biped_opt.systems.description import System
from biped_opt.systems.library.walker import walker

__all__ = ["biped"]


def biped() -> System:
    return walker(2, "coupled", name="biped", feet=["left", "right"], inputs=["u1", "u2", "u12"])
