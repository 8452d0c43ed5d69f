"""The systems that ship with biped_opt (SYSTEMS.md Secs. 2-3a), each a short description."""

from __future__ import annotations

from collections.abc import Callable

from biped_opt.systems.description import System
from biped_opt.systems.library.biped import biped
from biped_opt.systems.library.chain import chain
from biped_opt.systems.library.rocking_bar import rocking_bar
from biped_opt.systems.library.walker import walker

__all__ = ["LIBRARY", "biped", "chain", "rocking_bar", "walker"]

#: name -> factory of the library's systems (the walker with its defaults: n = 3, coupled; the
#: chain with one link per leg)
LIBRARY: dict[str, Callable[[], System]] = {
    "biped": biped,
    "walker": walker,
    "rocking_bar": rocking_bar,
    "chain": chain,
}
