"""Parameter values that give no mechanical system are refused with the reason
(biped_opt.systems.physical); the defaults of the library's systems pass."""

from __future__ import annotations

import pytest
import sympy as sp

from biped_opt.errors import InvalidParameterError
from biped_opt.systems.description import System
from biped_opt.systems.library.rocking_bar import rocking_bar
from biped_opt.systems.physical import check_physical


def test_the_rocking_bars_defaults_pass_and_a_negative_mass_does_not():
    bar = rocking_bar()
    check_physical(bar, bar.defaults, "drop", 0.1)
    with pytest.raises(InvalidParameterError, match=r"rocking_bar: the parameters \(m=-1\) "
                       "give a mass matrix that is not positive definite at the start of drop "
                       r"\(smallest eigenvalue -1\)"):
        check_physical(bar, {**bar.defaults, "m": -1.0}, "drop", 0.1)
    with pytest.raises(InvalidParameterError, match="not positive definite"):
        check_physical(bar, {**bar.defaults, "w": 0.0}, "drop", 0.1)  # (I = 0: singular)


@pytest.mark.parametrize(("gamma", "ok"), [(0.0, True), (1.0, True), (-0.1, False),
                                           (1.01, False)])
def test_a_restitution_must_lie_in_0_1(gamma, ok):
    bar = rocking_bar()
    values = {**bar.defaults, "gamma": gamma}
    if ok:
        check_physical(bar, values, "drop", 0.0)
    else:
        with pytest.raises(InvalidParameterError, match="it must be in \\[0, 1\\]"):
            check_physical(bar, values, "drop", 0.0)


def _pendulum() -> System:
    """A hinge with a massless link frame and a point mass at its end, described as bodies."""
    s = System("pendulum", ["th"], parameters={"m": 1.0, "l": 1.0, "j": 0.0})
    (th,) = s.q
    s.body("link", 0, rotation=((sp.cos(th), 0, -sp.sin(th)), (0, 1, 0),
                                (sp.sin(th), 0, sp.cos(th))))
    s.body("bob", s.p.m, position=(0, 0, -s.p.l), parent="link", inertia=(s.p.j, s.p.j, 0))
    s.constraint("floor", 1 + s.p.l * sp.cos(th) * 0 + th)
    s.forces = lambda J: [0]
    s.maneuver("swing", initial={th: s.s}, terminal=th, outcome=th)
    return s


def test_bodies_are_checked_one_by_one():
    pendulum = _pendulum()
    check_physical(pendulum, pendulum.defaults, "swing", 0.1)  # (a massless frame body: fine)
    with pytest.raises(InvalidParameterError, match="body bob a mass of -2; a mass cannot be "
                                                     "negative"):
        check_physical(pendulum, {**pendulum.defaults, "m": -2.0}, "swing", 0.1)
    with pytest.raises(InvalidParameterError, match="body bob an inertia that is not positive "
                                                     "semidefinite"):
        check_physical(pendulum, {**pendulum.defaults, "j": -0.5}, "swing", 0.1)
