"""The systems that ship with biped_opt (SYSTEMS.md Secs. 2-3c), each a short description."""

from __future__ import annotations

from collections.abc import Callable

from biped_opt.systems.description import System
from biped_opt.systems.library.biped import biped
from biped_opt.systems.library.chain import chain
from biped_opt.systems.library.robots import ROBOT_SIZES, ROBOTS
from biped_opt.systems.library.rocking_bar import rocking_bar
from biped_opt.systems.library.walker import walker

__all__ = ["LIBRARY", "BY_NAME", "SIZES", "ROBOTS", "biped", "chain", "quadruped", "rocking_bar",
           "walker"]

def quadruped() -> System:
    """The quadruped (:mod:`biped_opt.systems.library.quadruped`), imported when first built:
    its kinematics import ``sympy.physics`` (a tenth of a second), which a process that only
    lists or loads other systems should not pay."""
    from biped_opt.systems.library.quadruped import quadruped as build

    return build()


#: name -> factory of the library's systems (the walker with its defaults: n = 3, coupled; the
#: chain with one link per leg)
LIBRARY: dict[str, Callable[[], System]] = {
    "biped": biped,
    "walker": walker,
    "rocking_bar": rocking_bar,
    "chain": chain,
}


def biped_smooth() -> System:
    """The biped with its input switch smoothed (:mod:`biped_opt.systems.library.smooth_biped`,
    the gradient study's smoothed model)."""
    from biped_opt.systems.library.smooth_biped import smooth_biped

    return smooth_biped()


def rocking_bar_soft() -> System:
    """The rocking bar with soft contacts (:mod:`biped_opt.systems.library.soft_rocking_bar`,
    the gradient study's smoothed model)."""
    from biped_opt.systems.library.soft_rocking_bar import soft_rocking_bar

    return soft_rocking_bar()


#: library systems built only when named: the quadruped's description takes seconds (3-D
#: kinematics), too long for every listing of the library; the gradient study's smoothed
#: models are named so that a process finds them compiled (the start index) as any other
BY_NAME: dict[str, Callable[[], System]] = {
    "quadruped": quadruped,
    "biped_smooth": biped_smooth,
    "rocking_bar_soft": rocking_bar_soft,
    **ROBOTS,  # (robots from their URDFs: SYSTEMS.md Sec. 3c)
}

#: (constraints, coordinates) of the fixed-size library systems, known without building them
#: (a node checks a request's system against its limits before anything is built)
SIZES: dict[str, tuple[int, int]] = {
    "biped": (2, 7),
    "walker": (3, 9),
    "rocking_bar": (2, 3),
    "chain": (2, 5),
    "quadruped": (4, 20),
    "biped_smooth": (2, 7),
    "rocking_bar_soft": (0, 3),
    **ROBOT_SIZES,
}
