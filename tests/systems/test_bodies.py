"""Descriptions of rigid bodies instead of M (SYSTEMS.md Sec. 1a).

- A tumbling box (a free rigid body in 3-D, no gravity, no constraint reached): its angular
  momentum in the world frame and its energy are constants of the motion, a check of the
  gyroscopic terms (w x I w, aw) that shares nothing with how they are derived;
- a box dropped on a corner under gravity: the compiled simulator's flight up to the corner's
  touchdown against SciPy's solve_ivp on Newton-Euler equations written out here in NumPy
  (rotation matrix, body rates);
- the planar chain with one link per leg described as a tree of bodies gives the library
  chain's M, forces and accelerations to rounding;
- a bead on a turning rod has the closed form's Coriolis and centrifugal terms, and a tree with
  joints of every kind (a free base, a crank on a circle, a slider on it) gives what the flat
  sums over the bodies' world Jacobians give;
- what a description of bodies may not do gets a clear error.

Impacts of several bodies' points at once, and inputs within 1e-9 of them, are compared with
an independent reference in ``tests/systems/test_quadruped.py``.
"""

from __future__ import annotations

import importlib.util
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

from biped_opt.codegen.render import render
from biped_opt.simulation.compiled import CompiledSystem
from biped_opt.systems import mechanics
from biped_opt.systems.derive import derive
from biped_opt.systems.description import System, SystemDescriptionError
from biped_opt.systems.library.chain import chain

#: the box: mass, edge lengths (a, b, c), so principal inertias m (b^2 + c^2) / 12, ...
MASS, EDGES = 2.0, (0.3, 0.2, 0.1)
INERTIA = tuple(MASS * (EDGES[(i + 1) % 3] ** 2 + EDGES[(i + 2) % 3] ** 2) / 12
                for i in range(3))


def _rz(a):
    return sp.Matrix([[sp.cos(a), -sp.sin(a), 0], [sp.sin(a), sp.cos(a), 0], [0, 0, 1]])


def _ry(a):
    return sp.Matrix([[sp.cos(a), 0, sp.sin(a)], [0, 1, 0], [-sp.sin(a), 0, sp.cos(a)]])


def _rx(a):
    return sp.Matrix([[1, 0, 0], [0, sp.cos(a), -sp.sin(a)], [0, sp.sin(a), sp.cos(a)]])


def box(name: str = "box", *, gravity: bool = True) -> System:
    """A box on six coordinates (centre x, y, z; yaw, pitch, roll: R = Rz Ry Rx), its lowest
    corner (-a/2, -b/2, -c/2 in its axes) the one constraint. Drop: from height h, tilted by
    s about x and s / 2 about y, spinning at rates w0 about its axes' directions; it ends at the
    centre's lowest point after the touchdown."""
    s = System(name, ["x", "y", "z", "yaw", "pitch", "roll"], s="tilt", restitution=0.5,
               parameters={"m": MASS, "a": EDGES[0], "b": EDGES[1], "c": EDGES[2], "g": 9.81,
                           "h": 0.4})
    x, y, z, yaw, pitch, roll = s.q
    p = s.p
    rot = _rz(yaw) * _ry(pitch) * _rx(roll)
    s.body("box", p.m, position=(x, y, z), rotation=rot,
           inertia=(p.m * (p.b**2 + p.c**2) / 12, p.m * (p.a**2 + p.c**2) / 12,
                    p.m * (p.a**2 + p.b**2) / 12))
    if gravity:
        s.gravity = (0, 0, -p.g)
    corner = sp.Matrix([x, y, z]) + rot * sp.Matrix([-p.a / 2, -p.b / 2, -p.c / 2])
    s.constraint("corner", corner[2], at=tuple(corner))
    q = dict(zip(["x", "y", "z", "yaw", "pitch", "roll"], s.q))
    dq = dict(zip(["x", "y", "z", "yaw", "pitch", "roll"], s.dq))
    s.maneuver("drop", initial={q["z"]: p.h, q["roll"]: s.s, q["pitch"]: s.s / 2,
                                dq["yaw"]: 3.0, dq["roll"]: -2.0, dq["pitch"]: 1.0},
               terminal=-s.dq[2], armed_after="touchdown", outcome=s.dq[5],
               s_range=(-0.5, 0.5))
    return s


# -- an independent model of the box: NumPy, rotation matrices and body rates -------------------

def _rotation(yaw, pitch, roll):
    cy, sy, cp, sp_, cr, sr = (math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch),
                               math.cos(roll), math.sin(roll))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp_], [0, 1, 0], [-sp_, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def _rates_matrix(pitch, roll):
    """E with body rates w = E (yaw', pitch', roll') for R = Rz Ry Rx."""
    cp, sp_, cr, sr = math.cos(pitch), math.sin(pitch), math.cos(roll), math.sin(roll)
    return np.array([[-sp_, 0, 1], [cp * sr, cr, 0], [cp * cr, -sr, 0]])


def _angular_momentum(y):
    """World angular momentum about the centre, R I w."""
    yaw, pitch, roll = y[3:6]
    w = _rates_matrix(pitch, roll) @ y[9:12]
    return _rotation(yaw, pitch, roll) @ (np.array(INERTIA) * w)


def _reference_flight(y0, t_end, g):
    """Newton-Euler in body rates: m x'' = m g, I w' = -w x I w, R' = R w^, integrated in
    (position, velocity, R, w) without Euler angles (so it shares nothing with the
    description); returns the centre and the world angular velocity at t_end."""
    inertia = np.array(INERTIA)
    yaw, pitch, roll = y0[3:6]
    r0 = _rotation(yaw, pitch, roll)
    w0 = _rates_matrix(pitch, roll) @ y0[9:12]

    def rhs(_t, v):
        rot = v[6:15].reshape(3, 3)
        w = v[15:18]
        skew = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
        return np.concatenate([v[3:6], [0, 0, -g], (rot @ skew).ravel(),
                               -np.cross(w, inertia * w) / inertia])

    v0 = np.concatenate([y0[0:3], y0[6:9], r0.ravel(), w0])
    sol = solve_ivp(rhs, (0, t_end), v0, method="DOP853", rtol=1e-12, atol=1e-13)
    end = sol.y[:, -1]
    return end[0:3], end[6:15].reshape(3, 3) @ end[15:18]


@pytest.fixture(scope="module")
def tumbling():
    return CompiledSystem(box("box_free", gravity=False))


@pytest.fixture(scope="module")
def falling():
    return CompiledSystem(box())


def test_a_free_body_keeps_its_angular_momentum_and_energy(tumbling):
    """Without gravity the box never reaches the ground within the horizon; along the way the
    world angular momentum R I w and the kinetic energy stay constant to 1e-9 of their size
    (the integrator's rtol 1e-11 over ~10 time units); a wrong or missing gyroscopic term
    changes them at O(1) within a fraction of a revolution."""
    tr = tumbling.simulate("drop", 0.2, sample_dt=0.05)
    samples = tr.samples
    assert len(samples) > 100
    moments = np.array([_angular_momentum(row[1:13]) for row in samples])
    assert np.ptp(moments, axis=0).max() < 1e-9 * np.abs(moments[0]).max()
    energy = [0.5 * float(np.dot(np.array(INERTIA) * (w := _rates_matrix(*row[5:7]) @ row[10:13]),
                                 w)) for row in samples]
    assert np.ptp(energy) < 1e-9 * energy[0]


def test_the_falling_box_flies_as_newton_and_euler_say(falling):
    """Before its touchdown the box's centre and world angular velocity agree with the
    independent Newton-Euler integration to 1e-9 (both integrators at rtol 1e-11..1e-12 over
    ~0.3 time units), at the simulator's own touchdown time."""
    for tilt in (-0.3, 0.1, 0.4):
        tr = falling.simulate("drop", tilt)
        assert tr.status.name == "OK", tr.status
        first = tr.contact_events[0]
        y0 = np.zeros(12)  # (the maneuver's start, written out again)
        y0[2], y0[5], y0[4] = 0.4, tilt, tilt / 2
        y0[9], y0[11], y0[10] = 3.0, -2.0, 1.0
        centre, spin = _reference_flight(y0, first.t, 9.81)
        before = first.state_before
        np.testing.assert_allclose(before[0:3], centre, rtol=0, atol=1e-9)
        yaw, pitch, roll = before[3:6]
        ours = _rotation(yaw, pitch, roll) @ _rates_matrix(pitch, roll) @ before[9:12]
        np.testing.assert_allclose(ours, spin, rtol=0, atol=1e-9)
        # the corner is on the ground then (the touchdown is located to rounding of the
        # guard; 1e-12 m leaves room for the corner's rounding from the state)
        corner = before[0:3] + _rotation(yaw, pitch, roll) @ (-np.array(EDGES) / 2)
        assert abs(corner[2]) < 1e-12


def test_the_chain_described_by_its_bodies_is_the_library_chain():
    """chain (one link per leg) again as a tree of bodies: the middle link (x, z, th) and a leg
    hinged at each of its ends. M and the forces of every mode agree with the library's
    explicit description to 1e-13 of their size at random states, through NumericSystem (flat
    sums over the bodies' world Jacobians), through the derived system's symbolic sums and
    through the generated code run as Python (the tree's recursive sums): four derivations,
    different sums."""
    lib = chain()
    s = System("chain_bodies", [str(c) for c in lib.q], s="tilt", restitution=0.6,
               parameters=dict(lib.defaults))
    x, z, th, a1, a2 = s.q
    p = s.p

    def turned(angle):  # a link in the x-z plane, its pitch turning x towards +z
        return sp.Matrix([[sp.cos(angle), 0, -sp.sin(angle)], [0, 1, 0],
                          [sp.sin(angle), 0, sp.cos(angle)]])

    s.body("middle", p.mb, position=(x, 0, z), rotation=turned(th),
           inertia=(0, p.mb * (2 * p.lb) ** 2 / 12, 0))
    for side, hinge in ((-1, a1), (1, a2)):
        s.body(f"leg{'12'[side > 0]}", p.ml, parent="middle", position=(side * p.lb, 0, 0),
               rotation=turned(hinge), centre=(side * p.leg / 2, 0, 0),
               inertia=(0, p.ml * p.leg**2 / 12, 0))
    s.gravity = (0, 0, -p.g)
    s.forces = lambda J: [0, 0, 0, -p.k * (a1 - p.rest), -p.k * (a2 + p.rest)]
    for name, expr in lib.constraints.items():
        s.constraint(name, expr)
    s.maneuver("drop", initial={z: 1.2}, terminal=s.dq[1], outcome=s.dq[2])  # (for render)
    derived = derive(s)
    ours, theirs = derived.numeric(), derive(lib).numeric()
    generated = _python_module(derived)
    # (and the symbolic sums a user may ask a derived system of bodies for)
    values_p = {sym: lib.defaults[str(sym)] for sym in s.p}
    symbolic_m = sp.lambdify(list(s.q), derived.mass_matrix.xreplace(values_p), "numpy")
    symbolic_f = sp.lambdify(list(s.q) + list(s.dq),
                             derived.forces[3].xreplace(values_p), "numpy")
    values = generated.prepare_parameters(np.array([lib.defaults[k] for k in s.p.names()]))
    rng = np.random.default_rng(7)
    for _ in range(5):
        q, dq = rng.uniform(-1.5, 1.5, 5), rng.uniform(-3, 3, 5)
        m1, m2 = ours.mass_matrix(q), theirs.mass_matrix(q)
        np.testing.assert_allclose(m1, m2, rtol=0, atol=1e-13 * np.abs(m2).max())
        np.testing.assert_allclose(np.array(symbolic_m(*q), dtype=float), m2, rtol=0,
                                   atol=1e-13 * np.abs(m2).max())
        f3 = theirs.forces(q, dq, [], 3)
        np.testing.assert_allclose(np.array(symbolic_f(*q, *dq), dtype=float).ravel(), f3,
                                   rtol=0, atol=1e-13 * np.abs(f3).max())
        for mode in range(4):
            f1, f2 = ours.forces(q, dq, [], mode), theirs.forces(q, dq, [], mode)
            np.testing.assert_allclose(f1, f2, rtol=0, atol=1e-13 * np.abs(f2).max())
            acc, lam = mechanics.accelerations(theirs, q, dq, np.zeros(0), mode)
            out, got = np.zeros(10), np.zeros(2)
            generated._field_at.py_func(values, mode, np.concatenate([q, dq]), 0,
                                        np.zeros(0), out, 0, got, 0)
            np.testing.assert_allclose(out[5:], acc, rtol=0, atol=1e-12 * np.abs(acc).max())
            np.testing.assert_allclose(got, lam, rtol=0, atol=1e-12 * max(1, np.abs(lam).max()))


def test_a_bead_on_a_turning_rod_has_the_closed_form_coriolis_terms():
    """A rod turning about the vertical (angle th, inertia Iz about its pivot) with a bead
    sliding along it (r, mass m; a slider on a turning body, the only joint whose relative
    velocity meets its parent's spin): M = diag(Iz + m r^2, m), and the forces are
    -2 m r r' th' on th and m r th'^2 on r (the closed form). The generated field, run as
    Python, gives these accelerations to 1e-13 of their size, in the air and with the stop
    (r >= 0.1) in contact, where the reaction holds r'' at 0."""
    s = System("bead", ["th", "r"], parameters={"m": 0.3, "Iz": 0.2}, s="w0")
    th, r = s.q
    p = s.p
    s.body("rod", 0, rotation=_rz(th), inertia=(0, 0, p.Iz))
    s.body("bead", p.m, parent="rod", position=(r, 0, 0))
    s.constraint("stop", r - sp.Rational(1, 10))
    s.maneuver("spin", initial={r: 0.5, s.dq[0]: s.s}, terminal=s.dq[1], outcome=s.dq[0])
    generated = _python_module(derive(s))
    values = generated.prepare_parameters(np.array([0.3, 0.2]))
    m, iz = 0.3, 0.2
    rng = np.random.default_rng(11)
    for _ in range(5):
        (q_th, q_r), (w, v) = rng.uniform(0.2, 1.5, 2), rng.uniform(-3, 3, 2)
        expected = np.array([-2 * m * q_r * v * w / (iz + m * q_r**2), q_r * w**2])
        for mode, acc in ((0, expected), (1, np.array([expected[0], 0.0]))):
            out, lam = np.zeros(4), np.zeros(1)
            generated._field_at.py_func(values, mode, np.array([q_th, q_r, w, v]), 0,
                                        np.zeros(0), out, 0, lam, 0)
            np.testing.assert_allclose(out[2:], acc, rtol=0,
                                       atol=1e-13 * np.abs(expected).max())
        assert lam[0] == pytest.approx(-m * q_r * w**2, rel=1e-13)


def test_joints_of_every_kind_against_the_flat_sums():
    """A tree that exercises every term of the recursive sums: a free base turning about two
    axes and sliding (relative spin, accelerations of a nonlinear joint), a crank whose origin
    moves on a circle in its parent's frame (the joint's own acceleration at q'' = 0), and a
    slider on the crank (relative velocity against a turning parent), all under gravity. The
    generated field, run as Python, against Eq. (1) from NumericSystem (the flat sums over the
    bodies' world Jacobians) in both modes: 1e-12 of the accelerations' size."""
    s = System("joints", ["x", "z", "yaw", "tilt", "phi", "r"], s="v",
               parameters={"m1": 1.0, "m2": 0.4, "m3": 0.2, "L": 0.3, "g": 9.81})
    x, z, yaw, tilt, phi, r = s.q
    p = s.p
    s.body("base", p.m1, position=(x, 0, z + x**2 / 4), rotation=_rz(yaw) * _rx(tilt),
           centre=(0.05, -0.02, 0.01), inertia=(0.02, 0.03, 0.04))
    s.body("crank", p.m2, parent="base", position=(p.L * sp.cos(phi), p.L * sp.sin(phi), 0),
           rotation=_ry(phi), centre=(0.1, 0, 0), inertia=[[0.01, 0.002, 0], [0.002, 0.02, 0],
                                                            [0, 0, 0.015]])
    s.body("slider", p.m3, parent="crank", position=(r, 0, 0), inertia=(0.001, 0.001, 0.001))
    s.gravity = (0, 0, -p.g)
    s.forces = lambda J: [0, 0, 0, 0, 0, -10 * r]
    s.constraint("floor", z - p.L)
    s.maneuver("fall", initial={z: 1.0, s.dq[2]: s.s}, terminal=s.dq[1], outcome=s.dq[2])
    derived = derive(s)
    generated = _python_module(derived)
    numeric = derived.numeric()
    values = generated.prepare_parameters(np.array(list(s.defaults.values())))
    rng = np.random.default_rng(5)
    for _ in range(4):
        q, dq = rng.uniform(-1.2, 1.2, 6), rng.uniform(-2, 2, 6)
        for mode in (0, 1):
            acc, lam = mechanics.accelerations(numeric, q, dq, np.zeros(0), mode)
            out, got = np.zeros(12), np.zeros(1)
            generated._field_at.py_func(values, mode, np.concatenate([q, dq]), 0, np.zeros(0),
                                        out, 0, got, 0)
            np.testing.assert_allclose(out[6:], acc, rtol=0, atol=1e-12 * np.abs(acc).max())
            np.testing.assert_allclose(got, lam, rtol=0, atol=1e-12 * max(1, np.abs(lam).max()))


def test_a_coordinate_that_moves_several_bodies_against_the_flat_sums():
    """Mimic joints (SYSTEMS.md Sec. 1a): one coordinate moves several bodies, on one line of
    the tree (a hinge and, through a gear, its child's hinge: the diagonal of M meets the
    pair twice) and on two branches (two fingers, one turning with the other at -1.5 times its
    angle plus an offset), with a slider and gravity. The generated field, run as Python,
    against the flat sums over the bodies' world Jacobians (which need no notion of owners),
    in both modes: 1e-12 of the accelerations' size."""
    s = System("gears", ["x", "z", "a", "b"], s="v",
               parameters={"m": 1.0, "L": 0.3, "g": 9.81})
    x, z, a, b = s.q
    p = s.p
    s.body("base", 2 * p.m, position=(x, 0, z), rotation=_ry(b / 3),
           inertia=(0.02, 0.03, 0.04))
    s.body("arm", p.m / 2, parent="base", position=(p.L, 0, 0), rotation=_rz(a),
           centre=(0.1, 0.02, 0), inertia=[[0.01, 0.002, 0], [0.002, 0.02, 0], [0, 0, 0.015]])
    s.body("hand", p.m / 4, parent="arm", position=(p.L, 0, 0), rotation=_rz(2 * a) * _rx(b),
           centre=(0.05, 0, 0.01), inertia=(0.002, 0.003, 0.001))
    s.body("left", p.m / 5, parent="base", position=(0, p.L, 0), rotation=_ry(b),
           centre=(0, 0, -0.1), inertia=(0.001, 0.002, 0.003))
    s.body("right", p.m / 5, parent="base", position=(0, -p.L, 0),
           rotation=_ry(-1.5 * b + 0.2), centre=(0, 0, -0.1), inertia=(0.001, 0.002, 0.003))
    s.gravity = (0, 0, -p.g)
    s.constraint("floor", z - p.L)
    s.maneuver("fall", initial={z: 1.0}, terminal=s.dq[1], outcome=s.dq[2])
    derived = derive(s)
    generated = _python_module(derived)
    numeric = derived.numeric()
    values = generated.prepare_parameters(np.array(list(s.defaults.values())))
    rng = np.random.default_rng(7)
    for _ in range(4):
        q, dq = rng.uniform(-1.2, 1.2, 4), rng.uniform(-2, 2, 4)
        for mode in (0, 1):
            acc, lam = mechanics.accelerations(numeric, q, dq, np.zeros(0), mode)
            out, got = np.zeros(8), np.zeros(1)
            generated._field_at.py_func(values, mode, np.concatenate([q, dq]), 0, np.zeros(0),
                                        out, 0, got, 0)
            np.testing.assert_allclose(out[4:], acc, rtol=0, atol=1e-12 * np.abs(acc).max())
            np.testing.assert_allclose(got, lam, rtol=0, atol=1e-12 * max(1, np.abs(lam).max()))


def _python_module(derived):
    """A derived system's generated module, imported without compiling anything (its
    functions' ``py_func`` run the generated code in Python)."""
    folder = Path(tempfile.mkdtemp(prefix="biped_opt_bodies_"))
    path = folder / f"{derived.system.name}_generated.py"
    path.write_text(render(derived))
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _plain(**kw) -> System:
    s = System("plain", ["x", "th"], parameters={"m": 1.0})
    for k, v in kw.items():
        setattr(s, k, v)
    return s


@pytest.mark.parametrize(("build", "message"), [
    (lambda s: (s.body("b", s.p.m, position=(s.q[0], 0, 0), rotation=_rz(s.q[1])),
                setattr(s, "mass_matrix", sp.eye(2))), "give either it or bodies"),
    (lambda s: setattr(s, "gravity", (0, 0, -1)), "acts on bodies"),
    (lambda s: s.body("b", s.p.m, position=(s.q[0], 0, 0),
                      rotation=sp.diag(1, 1, 2) * _rz(s.q[1])), "not a rotation matrix"),
    (lambda s: s.body("b", s.p.m, position=(s.q[0], 0, 0), rotation=_rz(s.q[1]),
                      inertia=(s.q[0], 1, 1)), "inertia: uses x, which is not a parameter"),
    (lambda s: s.body("b", s.p.m, position=(s.q[0], 0)), r"position must be \(x, y, z\)"),
    (lambda s: s.body("b", s.p.m, position=(s.q[0], 0, 0),
                      inertia=[[1, 2, 0], [0, 1, 0], [0, 0, 1]]), "must be symmetric"),
    (lambda s: s.body("b", s.q[1], position=(s.q[0], 0, 0)), "mass: uses th"),
    (lambda s: (s.body("b", 1, position=(s.q[0], 0, 0)),
                s.body("b", 1, position=(s.q[1], 0, 0))), "given twice"),
    (lambda s: s.body("b", 1, parent="a", position=(s.q[0], 0, 0)),
     "parent 'a' is not a body declared before it"),
    (lambda s: s.body("b", 1, position=(s.q[0], 0, 0)), "coordinate th moves no body"),
])
def test_what_a_description_of_bodies_may_not_do(build, message):
    s = _plain()
    with pytest.raises(SystemDescriptionError, match=message):
        build(s)
        s.forces = [0, 0]
        derive(s)


# -- the examples of SYSTEMS.md Sec. 1a, built as written there --------------------------------

def _doc_example(name: str, folder: Path) -> Path:
    """The fenced example of docs/SYSTEMS.md whose first line is ``# <name>``, as a file."""
    import re

    text = (Path(__file__).resolve().parents[2] / "docs" / "SYSTEMS.md").read_text()
    blocks = [b for b in re.findall(r"```python\n(.*?)```", text, re.S)
              if b.startswith(f"# {name}")]
    assert len(blocks) == 1, f"docs/SYSTEMS.md should hold one example {name}"
    path = folder / name
    path.write_text(blocks[0])
    return path


def test_the_planar_rod_of_the_docs_is_the_library_rocking_bar(tmp_path):
    """The rod of SYSTEMS.md Sec. 1a (bodies, rotation_xz) is the rocking bar of Sec. 2 (M
    given): same parameters, so the same trajectories. 1e-12: both integrate the same
    equations with other arithmetic (the tree's sums against the given diagonal M), and event
    times are located to ~1e-13 of a step."""
    from biped_opt.simulation.compiled import compile_system

    rod = compile_system(str(_doc_example("rod.py", tmp_path)))
    bar = compile_system("rocking_bar")
    for s in (0.0, 1e-6, 0.05, 0.2, -0.15):
        a, b = rod.simulate("drop", s), bar.simulate("drop", s)
        assert a.status.name == b.status.name == "OK"
        assert [e.mask_entered for e in a.contact_events] == \
            [e.mask_entered for e in b.contact_events]
        assert a.outcome == pytest.approx(b.outcome, abs=1e-12)
        assert np.allclose(a.event_times, b.event_times, rtol=0, atol=1e-12)
    assert rod.simulate("drop", 0.0).contact_events[0].entered == ("left", "right")


def test_the_free_box_of_the_docs_lands_on_its_face_and_rests(tmp_path):
    """The box of SYSTEMS.md Sec. 1a, plastic (e = 0): level (s = 0) its four corners land at
    once, at the free fall's time sqrt(2 h0 / g), and it rests on them (its four dependent
    corners, SYSTEMS.md Sec. 5: all four in the final mode); rolled by s it lands on one edge,
    then on the other, and rests the same. Its height ends at c, every rate at 0 (to 1e-12:
    the plastic impacts leave rounding), the clock at T; and the bodies' energy is conserved
    in flight (systems --check)."""
    from biped_opt.simulation.compiled import compile_system
    from biped_opt.simulation.energy import energy_drift

    box_ = compile_system(str(_doc_example("box.py", tmp_path)))
    names = box_.coordinates
    level = box_.simulate("drop", 0.0)
    assert level.status.name == "OK"
    (landing,) = level.contact_events
    assert landing.t == pytest.approx(math.sqrt(2 * 0.3 / 1.0), abs=1e-12)
    assert set(landing.entered) == set(landing.mode_after) == {"fl", "fr", "rl", "rr"}
    for s in (0.05, -0.12):
        tr = box_.simulate("drop", s)
        assert tr.status.name == "OK", tr.message
        assert [len(e.entered) for e in tr.contact_events] == [2, 2]
        assert tr.mode_names(tr.mode_final) == {"fl", "fr", "rl", "rr"}
        q, dq = tr.y_final[:len(names)], tr.y_final[len(names):]
        assert q[names.index("z")] == pytest.approx(0.15, abs=1e-12)
        assert q[names.index("tau")] == pytest.approx(2.0, abs=1e-12)
        assert np.abs(dq[:6]).max() < 1e-12
    drift = energy_drift(box_, "drop")
    assert drift.source == "bodies" and drift.ok and drift.relative < 1e-12
