"""The systems that ship with biped_opt (SYSTEMS.md Secs. 2-3), each a short description."""

from __future__ import annotations

from collections.abc import Callable

from biped_opt.systems.description import System
from biped_opt.systems.library.biped import biped
from biped_opt.systems.library.quadruped import quadruped
from biped_opt.systems.library.rocking_bar import rocking_bar
from biped_opt.systems.library.walker import walker

__all__ = ["LIBRARY", "biped", "quadruped", "rocking_bar", "walker"]

#: name -> factory of the library's systems (the walker with its defaults: n = 3, coupled)
LIBRARY: dict[str, Callable[[], System]] = {
    "biped": biped,
    "walker": walker,
    "rocking_bar": rocking_bar,
    "quadruped": quadruped,
}
