"""System descriptions: the derived Eq. (1) quantities against the hand-written biped, the
walker and rocking bar facts of SYSTEMS.md, energy bookkeeping of the impact map, and clear
errors for wrong descriptions.

Tolerances: the description and the hand-written model evaluate the same formulas in a
different order, so they agree to a few ulps of the largest term (1e-12 absolute on quantities
of order 1-30); exact identities (symbolic results) are compared exactly or to 1e-14.
"""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from biped_opt.paper.biped import BipedParams
from biped_opt.systems import System, SystemDescriptionError, derive, walker
from biped_opt.systems.library import LIBRARY, biped, rocking_bar
from biped_opt.systems.mechanics import accelerations, impact_map, reaction_forces
from tests.paper.biped_physics import Biped, initial_state

RNG = np.random.default_rng(12)


def _random_state(d: int) -> tuple[np.ndarray, np.ndarray]:
    q = RNG.uniform(-0.3, 0.3, d)
    q[1] += 1.0  # body above its feet
    for j in range(4, d, 2):
        q[j] = RNG.uniform(0.0, 0.2)
    return q, RNG.uniform(-1.0, 1.0, d)


@pytest.fixture(scope="module")
def biped_numeric():
    return derive(biped()).numeric()


@pytest.mark.parametrize("mode", range(4))
def test_biped_description_equals_the_hand_written_model(biped_numeric, mode):
    hand = Biped()
    for _ in range(20):
        q, dq = _random_state(7)
        u = RNG.uniform(-2.0, 2.0, 3)
        np.testing.assert_allclose(biped_numeric.mass_matrix(q), hand.mass_matrix(q),
                                   rtol=0, atol=0)
        np.testing.assert_allclose(biped_numeric.forces(q, dq, u, mode),
                                   hand.forces(q, dq, u, mode), rtol=0, atol=1e-12)
        np.testing.assert_array_equal(biped_numeric.constraints(q), hand.constraints(q))
        np.testing.assert_array_equal(biped_numeric.constraint_jacobian(q),
                                      hand.constraint_jacobian(q))
        np.testing.assert_array_equal(biped_numeric.constraint_jacobian_rate(q, dq),
                                      hand.constraint_jacobian_rate(q, dq))
        for f in (reaction_forces, accelerations):
            np.testing.assert_allclose(np.hstack(f(biped_numeric, q, dq, u, mode)),
                                       np.hstack(f(hand, q, dq, u, mode)), rtol=0, atol=1e-12)


@pytest.mark.parametrize("maneuver", ["touchdown", "liftoff"])
@pytest.mark.parametrize("th0", [-0.2, 0.0, 0.13])
def test_biped_maneuvers_start_where_the_hand_written_ones_do(biped_numeric, maneuver, th0):
    y0, mode = biped_numeric.initial_state(maneuver, th0)
    ref, ref_mode = initial_state(maneuver, th0, BipedParams())
    np.testing.assert_allclose(y0, ref, rtol=0, atol=1e-15)
    assert mode == int(ref_mode)


def test_walker_with_two_legs_is_the_biped(biped_numeric):
    two = derive(walker(2, "coupled")).numeric()
    for mode in range(4):
        q, dq = _random_state(7)
        u = RNG.uniform(-2.0, 2.0, 3)
        np.testing.assert_array_equal(two.forces(q, dq, u, mode),
                                      biped_numeric.forces(q, dq, u, mode))


def test_walker_input_laws():
    """coupled: u_i only when leg i is alone on the ground, u_body only when all are;
    decoupled: u_i whenever foot i is down. Checked on the symbolic forces' input terms."""
    for law in ("coupled", "decoupled"):
        d = derive(walker(3, law))
        u = list(d.system.u)
        for mask in range(8):
            acting = {str(s) for s in d.forces[mask].free_symbols if s in u}
            alone = {0b001: "u1", 0b010: "u2", 0b100: "u3"}
            if law == "coupled":
                expected = ({alone[mask]} if mask in alone else set()) | (
                    {"u_body"} if mask == 0b111 else set())
            else:
                expected = {f"u{j + 1}" for j in range(3) if mask >> j & 1}
            assert acting == expected, (law, mask)
    one = derive(walker(1, "coupled"))
    assert {str(s) for s in one.forces[1].free_symbols} >= {"u1", "u_body"}


def test_rocking_bar_is_inertially_coupled():
    """Da_1 M^-1 Da_2^T = 1/m - w^2 cos^2 th / I (SYSTEMS.md Sec. 2): nonzero, so one end's
    impact moves the other."""
    d = derive(rocking_bar())
    m, w = d.system.p.m, d.system.p.w
    th = d.system.q[2]
    coupling = (d.jacobian[0, :] * d.mass_matrix.inv() * d.jacobian[1, :].T)[0, 0]
    inertia = m * (2 * w) ** 2 / 12
    assert sp.simplify(coupling - (1 / m - w**2 * sp.cos(th) ** 2 / inertia)) == 0
    # a_j = z + s_j w sin th: (d/dt Da_j) q' = -s_j w sin th th'^2 (w = 0.5, th' = 2)
    num = derive(rocking_bar()).numeric()
    rate = num.constraint_jacobian_rate(np.array([0, 1, 0.3]), np.array([0, 0, 2.0]))
    assert rate == pytest.approx([2.0 * np.sin(0.3), -2.0 * np.sin(0.3)], abs=1e-14)


@pytest.mark.parametrize("gamma", [0.0, 0.5, 1.0])
def test_impact_energy_bookkeeping(gamma):
    """Kinetic energy across Delta_J: gamma = 1 conserves it; otherwise the loss is
    (1 - gamma^2)/2 * v^T Da^T (Da M^-1 Da^T)^-1 Da v (the energy of the normal velocity)."""
    num = derive(rocking_bar()).numeric(gamma=gamma)
    q = np.array([0.0, 0.25 * np.sin(0.2), 0.2])
    v = np.array([0.3, -1.2, 0.7])
    mass = num.mass_matrix(q)
    for mode in (1, 2, 3):
        after = impact_map(num, q, mode) @ v
        da = num.constraint_jacobian(q)[[j for j in range(2) if mode >> j & 1]]
        normal = da @ v
        loss = 0.5 * (1 - gamma**2) * normal @ np.linalg.solve(
            da @ np.linalg.solve(mass, da.T), normal)
        lost = 0.5 * v @ mass @ v - 0.5 * after @ mass @ after
        assert lost == pytest.approx(loss, abs=1e-14)
        np.testing.assert_allclose(da @ after, -gamma * normal, atol=1e-14)


def test_the_library_derives():
    for name, make in LIBRARY.items():
        d = derive(make())
        assert d.system.maneuvers, name
        assert len(d.forces) == 1 << d.nconstraints


def _bar(**changes):
    s = System("bar", ["x", "z"], parameters={"m": 1.0}, inputs=["u"])
    x, z = s.q
    s.mass_matrix = sp.diag(s.p.m, s.p.m)
    s.forces = lambda J: [0, -s.p.m]
    s.constraint("ground", z)
    s.maneuver("drop", initial={z: 1 + s.s}, terminal=s.dq[1], outcome=x)
    for key, value in changes.items():
        setattr(s, key, value)
    return s


@pytest.mark.parametrize(("changes", "message"), [
    ({"mass_matrix": sp.diag(1, 1, 1)}, "bar: mass_matrix: must be 2x2, got 3x3"),
    ({"mass_matrix": sp.Matrix([[1, 2], [0, 1]])}, "bar: mass_matrix: must be symmetric"),
    ({"mass_matrix": None}, "bar: mass_matrix: not given"),
    ({"mass_matrix": sp.diag(sp.Symbol("k"), 1)}, "bar: mass_matrix: uses k, which is not"),
    ({"forces": lambda J: [0, 0, 0]}, "bar: forces in mode {}: must be a vector of 2, got 3x1"),
    ({"forces": lambda J: [0, 1 / 0]}, "bar: forces in mode {}: ZeroDivisionError"),
    ({"forces": lambda J: [sp.Symbol("v"), 0]}, "bar: forces in mode {}: uses v"),
    ({"restitution": sp.Symbol("x")}, "bar: restitution: uses x, which is not a parameter"),
])
def test_a_wrong_description_names_the_item(changes, message):
    with pytest.raises(SystemDescriptionError, match=message.replace("{", r"\{")
                       .replace("}", r"\}").replace("(", r"\(")):
        derive(_bar(**changes))


@pytest.mark.parametrize(("build", "message"), [
    (lambda: System("bar", []), "bar: coordinates: at least one is needed"),
    (lambda: System("bar", ["x", "x"]), "coordinate 'x' is also a coordinate name"),
    (lambda: System("bar", ["x"], parameters={"x_dot": 1}), "parameter 'x_dot' is also a"),
    (lambda: System("bar", ["1x"]), "coordinate must be a Python identifier, got '1x'"),
    (lambda: System("bar", ["x"], parameters={"m": "heavy"}), "parameter 'm': default must"),
    (lambda: _bar().constraint("ground", 1), "constraint 'ground' is given twice"),
    (lambda: _bar().maneuver("hop", initial={}, terminal=0, outcome=0, armed_after="apex"),
     "armed_after must be None or 'touchdown'"),
])
def test_a_wrong_declaration_is_refused_at_once(build, message):
    with pytest.raises(SystemDescriptionError, match=message):
        build()


def test_a_maneuver_names_unknown_modes_and_symbols():
    s = _bar()
    s.maneuver("stand", initial={s.q[1]: 0}, terminal=s.dq[1], outcome=s.q[0], mode=["floor"])
    with pytest.raises(SystemDescriptionError, match="maneuver 'stand': .*unknown constraint "
                                                     "'floor'"):
        derive(s)
    s = _bar()
    s.maneuver("fly", initial={s.q[1]: sp.Symbol("h")}, terminal=s.dq[1], outcome=s.q[0])
    with pytest.raises(SystemDescriptionError, match="maneuver 'fly': initial z: uses h"):
        derive(s)


USER_FILE = '''
import sympy as sp
from biped_opt.systems import System

ball = System("ball", ["x", "z"], parameters={"m": 2.0, "g": 1.0}, s="v0")
x, z = ball.q
ball.mass_matrix = sp.diag(ball.p.m, ball.p.m)
ball.forces = lambda J: [0, -ball.p.m * ball.p.g]
ball.constraint("floor", z)
ball.maneuver("throw", initial={z: 1, ball.dq[0]: ball.s},
              terminal=ball.dq[1], outcome=x, armed_after="touchdown", s_range=(0, 2))
SYSTEM = ball
'''


def test_a_system_file_loads_and_derives(tmp_path):
    from biped_opt.systems import load_system

    path = tmp_path / "ball.py"
    path.write_text(USER_FILE)
    system = load_system(str(path))
    assert system.name == "ball" and system.source == str(path)
    num = derive(system).numeric(m=3.0)
    np.testing.assert_array_equal(num.mass_matrix(np.zeros(2)), 3.0 * np.eye(2))
    y0, mode = num.initial_state("throw", 0.5)
    np.testing.assert_array_equal(y0, [0.0, 1.0, 0.5, 0.0])
    assert mode == 0
    assert load_system("rocking_bar").name == "rocking_bar"


@pytest.mark.parametrize(("text", "message"), [
    ("import sympy\nx = 1 / 0\n", r"ball\.py: line 2: ZeroDivisionError: division by zero"),
    ("from biped_opt.systems import System\nSystem('b', ['x', 'x'])\n",
     r"ball\.py: line 2: b: coordinate 'x' is also a coordinate name"),
    ("x = 1\n", r"ball\.py: defines 0 System objects; name the one to use SYSTEM"),
    ("SYSTEM = 3\n", r"ball\.py: SYSTEM must be a biped_opt\.systems\.System, got int"),
])
def test_a_broken_system_file_is_one_clear_error(tmp_path, text, message):
    from biped_opt.systems import load_system

    path = tmp_path / "ball.py"
    path.write_text(text)
    with pytest.raises(SystemDescriptionError, match=message):
        load_system(str(path))


def test_an_unknown_system_is_named(tmp_path):
    from biped_opt.systems import load_system

    with pytest.raises(SystemDescriptionError, match="unknown system 'hexapod'"):
        load_system("hexapod")
    with pytest.raises(SystemDescriptionError, match="no such system file"):
        load_system(str(tmp_path / "none.py"))


def test_sympy_physics_mechanics_output_is_usable():
    """The rocking bar's mass matrix and forces from sympy.physics.mechanics (Lagrange's method
    on dynamic symbols x(t), z(t), th(t) and plain symbols without assumptions) describe the
    same system as the library's: equal derived quantities."""
    from sympy.physics.mechanics import (
        LagrangesMethod,
        Lagrangian,
        Point,
        ReferenceFrame,
        RigidBody,
        dynamicsymbols,
        inertia,
    )

    x, z, th = dynamicsymbols("x z th")
    m, w, g = sp.symbols("m w g")
    frame = ReferenceFrame("N")
    body = frame.orientnew("B", "Axis", (th, frame.z))
    origin = Point("O")
    centre = origin.locatenew("P", x * frame.x + z * frame.y)
    centre.set_vel(frame, centre.pos_from(origin).dt(frame))
    bar = RigidBody("bar", centre, body, m, (inertia(body, 0, 0, m * (2 * w) ** 2 / 12), centre))
    bar.potential_energy = m * g * z
    method = LagrangesMethod(Lagrangian(frame, bar), [x, z, th])
    method.form_lagranges_equations()

    s = System("rocking_bar", ["x", "z", "th"], parameters={"m": 1.0, "w": 0.5, "g": 1.0},
               s="th0")
    s.mass_matrix = method.mass_matrix
    s.forces = lambda J: method.forcing
    s.constraint("left", z - w * sp.sin(th))
    s.constraint("right", z + w * sp.sin(th))
    s.maneuver("drop", initial={z: 1, th: s.s}, terminal=sp.diff(z), outcome=sp.diff(th))
    mine, lib = derive(s), derive(rocking_bar())
    assert mine.mass_matrix == lib.mass_matrix
    assert mine.jacobian == lib.jacobian and mine.jacobian_rate == lib.jacobian_rate
    assert mine.forces[0] == lib.forces[3] == sp.Matrix([0, -lib.system.p.m * lib.system.p.g, 0])
    assert mine.maneuvers["drop"].outcome == lib.system.dq[2]


def test_the_code_printer_keeps_the_meaning_of_every_power():
    """Generated code prints small integer powers as products; a product printed as a divisor
    must stay one (3/w**2 is 3/(w*w), not 3/w*w). Each printed expression is evaluated and
    compared with SymPy's own lambdify to 1e-12 relative."""
    import math

    from biped_opt.codegen.emit import Printer

    x, y, w, m = sp.symbols("x y w m")
    printer = Printer({"fully_qualified_modules": True})
    values = {"x": 1.3, "y": 0.7, "w": 0.45, "m": 2.1}
    for e in (3 / (m * w**2), x**2, (x + y) ** 2 / w**3, 1 / (x + y), x**-2, x**-3 * y,
              2 * x**3 / (y**2 * w), sp.sqrt(x) / w**2, (x - y) ** 4 / (m * (x + w) ** 2),
              sp.cos(x) ** 2 / sp.sin(y) ** 3, x ** sp.Rational(3, 2) / w**4):
        got = eval(printer.doprint(e), {"math": math, **values})  # noqa: S307 - our own output
        want = sp.lambdify((x, y, w, m), e)(**values)
        assert got == pytest.approx(want, rel=1e-12), (e, printer.doprint(e))
