"""Generated code computes what a description says, whatever the expressions and the names.

The references here import nothing from biped_opt: each system's M(q), f(q, q', u) and
constraint are SymPy expressions built in this file, handed both to :class:`System` and to
``sympy.lambdify`` for a SciPy ``solve_ivp`` integration (or to a closed form). What is compared
are whole simulated maneuvers through the public API (``compile_system(...).simulate``), so the
DOP853 step with its inlined vector field is what is checked, not only the field.
"""

from __future__ import annotations

import ast
import functools
import math
import re

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp
from scipy.special import ellipk

from biped_opt.codegen.emit import UnsupportedExpressionError
from biped_opt.codegen.inline import expand
from biped_opt.codegen.render import render
from biped_opt.codegen.runtime import Status
from biped_opt.simulation.compiled import compile_system
from biped_opt.simulation.options import SimulatorOptions
from biped_opt.systems import System, derive

#: the compiled integrator as tight as the references (rtol 1e-12), so that what is left of a
#: difference is the two integrators' own error
TIGHT = SimulatorOptions(rtol=1e-12, atol=1e-13)


# --- the expander on its own: inlined text against the same calls, executed ----------------

_SQUARE = '''
def square(x):
    """A body whose parameter is read under operators that bind tighter than +."""
    x2 = x * x
    neg = -x
    cube = x ** 3
    return x2 + 0.0 * neg, cube, neg
'''

_SCALE = '''
def scale(k, v, c0):
    """A body that assigns a parameter and reads an invariant one."""
    kk = k * 2.0
    if v < 0.0:
        c0 = v
    return kk * v, c0
'''


@pytest.mark.parametrize("args", [
    "th + a", "-th", "a - th", "th * a", "-2.0", "2.0", "a ** 2", "(th + a) / 3.0", "th"])
def test_expanding_a_call_keeps_its_meaning(args):
    """The issue's case (sin(th + a) computed x2 = a + th * a + th) and its kin: each argument
    form expanded into a body that squares, negates and cubes it gives what the call gives,
    exactly (the same operations in the same order)."""
    caller = ("def f(th, a):\n"
              "    x2 = 100.0\n"  # (the caller's own x2 and x2_1: a copy must not touch them)
              "    x2_1 = 7.0\n"
              f"    s, c, n = square({args})\n"
              f"    t, u, v = square(th - {args})\n"
              "    return s, c, n, t, u, v, x2, x2_1\n")
    expanded = expand(caller, {"square": _SQUARE}, invariant=set())
    assert "square(" not in expanded
    called, inlined = {}, {}
    exec(_SQUARE + caller, called)  # noqa: S102 - our own test text
    exec(expanded, inlined)  # noqa: S102
    for th, a in ((0.3, 0.5), (-1.7, 2.25), (2.0, -0.125)):
        assert inlined["f"](th, a) == called["f"](th, a)


def test_expanding_hoists_invariant_values_and_renames_assigned_parameters():
    """Values that depend only on invariant arguments are computed once (at the first copy);
    a parameter the body assigns is a new name per copy, never the caller's variable."""
    caller = ("def g(k, v, w):\n"
              "    c0 = 5.0\n"
              "    a, c0 = scale(k, v, c0)\n"
              "    b, c1 = scale(k, w, c0)\n"
              "    return a, b, c0, c1\n")
    expanded = expand(caller, {"scale": _SCALE}, invariant={"k"})
    assert expanded.count("k * 2.0") == 1
    called, inlined = {}, {}
    exec(_SCALE + caller, called)  # noqa: S102
    exec(expanded, inlined)  # noqa: S102
    for v, w in ((1.0, 2.0), (-1.0, 3.0), (2.0, -4.0), (-0.5, -0.25)):
        assert inlined["g"](1.5, v, w) == called["g"](1.5, v, w)


def test_expanding_refuses_a_caller_that_shadows_a_global_of_the_body():
    body = "def h(x):\n    y = math.sqrt(x)\n    return y\n"
    caller = "def f(x):\n    math = 3.0\n    z = h(x)\n    return z + math\n"
    with pytest.raises(ValueError, match="math"):
        expand(caller, {"h": body}, invariant=set())


# --- the offset pendulum: the minimal case, in closed form ------------------------


def _pendulum(roles: dict[str, str] | None = None, extra: tuple[str, ...] = ()) -> System:
    """A pendulum whose angle enters as sin(th + a), with a wall at th = -wall it bounces off,
    S the sum of the ``extra`` parameters (0 by default) in its inertia m l^2 (1 + S) and
    restitution e + S: the functions that read them (the parameters' preparation, the impact)
    bind every parameter, and they are not the step, which keeps the compile cheap.
    ``roles`` renames every symbol (for the name test); the structure is the same for any
    names."""
    r = {k: k for k in ("th", "m", "l", "g", "a", "wall", "e", "u1", "u2", "s")}
    r.update(roles or {})
    params = {r["m"]: 1.3, r["l"]: 0.8, r["g"]: 9.81, r["a"]: 0.5, r["wall"]: 10.0, r["e"]: 0.4}
    params.update({name: 0.0 for name in extra})
    sym = {k: sp.Symbol(v, real=True) for k, v in r.items()}
    th, m, length, g, a = (sym[k] for k in ("th", "m", "l", "g", "a"))
    dth = sp.Symbol(f"{r['th']}_dot", real=True)
    S = sp.Add(*(sp.Symbol(name, real=True) for name in extra))
    p = System("pendulum_offset", [r["th"]], parameters=params, inputs=[r["u1"], r["u2"]],
               restitution=sym["e"] + S, s=r["s"])
    p.mass_matrix = [[m * length**2 * (1 + S)]]
    p.forces = [-m * g * length * sp.sin(th + a) + sym["u1"] * sp.cos(th + sym["u2"])]
    p.constraint("stop", th + sym["wall"])
    p.maneuver("swing", initial={th: sym["s"] - a}, terminal=-dth, outcome=th)
    p.maneuver("bounce", initial={th: sym["s"] - a}, terminal=dth, outcome=th,
               armed_after="touchdown")
    return p


@pytest.mark.parametrize("s", [0.5, 1.2, 2.5])
def test_offset_pendulum_swings_to_its_mirror_angle(pendulum, s):
    """phi = th + a released from rest at phi = s swings to phi = -s (energy) in half a period,
    2 sqrt(l/g) K(sin^2(s/2)) (complete elliptic integral). With the argument pasted as text
    the step computed sin(a + th * a + th): th(t_f) came out 0.7 off at s = 0.5, and the run
    hit the horizon at s = 2.5. 1e-9: the event time and state are good to ~1e-11 here (the
    integrator's tolerance 1e-11 over half a period, and the root to 1e-12)."""
    a, length, g, m = 0.5, 0.8, 9.81, 1.3
    pendulum.set_parameters()  # (the defaults: S = 0, the wall out of reach)
    tr = pendulum.simulate("swing", s, sample_dt=0.01)
    assert tr.status is Status.OK and tr.n_events == 0
    assert tr.outcome == pytest.approx(-s - a, abs=1e-9)
    assert tr.t_final == pytest.approx(2 * math.sqrt(length / g) * ellipk(math.sin(s / 2) ** 2),
                                       abs=1e-9)
    th, dth = tr.samples[:, 1], tr.samples[:, 2]
    energy = 0.5 * m * length**2 * dth**2 - m * g * length * np.cos(th + a)
    assert np.max(np.abs(energy - energy[0])) < 1e-9 * m * g * length


# --- no name a description chooses collides with the generator's ------------------------


def _identifiers(text: str) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Name):
            out.add(node.id)
        elif isinstance(node, ast.arg):
            out.add(node.arg)
        elif isinstance(node, ast.FunctionDef):
            out.add(node.name)
        elif isinstance(node, ast.alias):
            out.add(node.asname or node.name.split(".")[0])
    return out


#: the symbols of _pendulum() named like every name of its rendered module (collected from the
#: syntax tree, so the test follows the generator), each where it once did harm: the
#: coordinate is y (it crashed Numba), a is s (initial_state's argument), wall is j
#: (constraint_value's), e is mode (apply_impact's); the rest become the extra parameters,
#: summed into S
_ROLES = {"th": "y", "a": "s", "wall": "j", "e": "mode", "g": "p", "l": "u", "m": "code",
          "u1": "math", "u2": "yo", "s": "lam"}


@functools.lru_cache(maxsize=1)
def _other_names() -> tuple[str, ...]:
    names = _identifiers(render(derive(_pendulum())))
    assert set(_ROLES.values()) <= names
    return tuple(sorted(names - set(_ROLES.values()) - {"y_dot"}))


@pytest.fixture(scope="module")
def pendulum():
    """_pendulum with ordinary names and as many extra parameters as the name test needs
    (0 by default: S = 0), one compile for both tests."""
    return compile_system(_pendulum(extra=tuple(f"k{i}" for i in range(len(_other_names())))))


def test_the_generators_own_names_have_no_double_underscore():
    """A system's symbols are written kind__name (q__th, v__th, p__m, u__u1, s__s) and the
    generator's own names never contain "__", so the two cannot meet, whatever the
    description calls its symbols: every name of a rendered module with "__" is a symbol's,
    or an inlined copy of one (name_suffix)."""
    text = render(derive(_pendulum()))
    symbols = {"q__th", "v__th", "p__m", "p__l", "p__g", "p__a", "p__wall", "p__e",
               "u__u1", "u__u2", "s__s"}
    pattern = re.compile("(" + "|".join(map(re.escape, sorted(symbols))) + r")(_\w+)?")
    odd = {n for n in _identifiers(text) if "__" in n and not pattern.fullmatch(n)}
    assert not odd
    assert {"q__th", "v__th", "p__a", "s__s"} <= _identifiers(text)


def test_a_system_named_like_every_name_of_the_generated_code_simulates_the_same(pendulum):
    """Coordinate, parameters, inputs and s named like every local and global of a rendered
    module (see _ROLES) against the same system with ordinary names: the same trajectories to
    1e-13. Only the order of some products differs (SymPy sorts terms by name), and S is
    exact in any order (each extra value is 2^-10)."""
    rest = _other_names()
    odd = compile_system(_pendulum(_ROLES, rest))
    ref = pendulum
    for wall, maneuver, s, u in ((0.3, "bounce", 0.7, (0.3, -0.2)),
                                 (0.3, "bounce", 1.3, (-0.2, 0.0)),
                                 (10.0, "swing", 1.1, (0.2, 0.1))):
        ref.set_parameters(wall=wall, **{f"k{i}": 2.0**-10 for i in range(len(rest))})
        odd.set_parameters(**{_ROLES["wall"]: wall}, **{n: 2.0**-10 for n in rest})
        want, got = ref.simulate(maneuver, s, u), odd.simulate(maneuver, s, u)
        assert got.status is want.status is Status.OK
        assert got.n_events == want.n_events == (maneuver == "bounce")  # (the wall is hit)
        assert got.outcome == pytest.approx(want.outcome, abs=1e-13)
        assert got.t_final == pytest.approx(want.t_final, abs=1e-13)
        np.testing.assert_allclose(got.y_final, want.y_final, rtol=0, atol=1e-13)


def test_a_function_without_compiled_form_is_named():
    p = _pendulum()
    th = p.q[0]
    p.forces = [sp.besselj(0, th)]
    with pytest.raises(UnsupportedExpressionError, match="pendulum_offset: besselj"):
        render(derive(p))


# --- many expression kinds against SciPy -------------------------------------------------

_Q = sp.symbols("th1 th2 tau", real=True)
_DQ = sp.symbols("th1_dot th2_dot tau_dot", real=True)
_P = dict(m1=1.0, m2=0.7, l1=1.0, l2=0.8, J=0.05, g=9.81, a=0.3, b=-0.4, d=0.2, k=0.3,
          c=0.0, H=10.0, T=1.5)
_PS = {k: sp.Symbol(k, real=True) for k in _P}
_U = sp.Symbol("u", real=True)


def _chain_expressions():
    """A double pendulum with a relative joint angle th2 (full, configuration-dependent M), a
    clock tau (tau' = 1, so the maneuvers end at t = T), a potential packing many expression
    kinds, damping c and an input u (both zero: energy is conserved), and its tip above a floor
    at depth H as the constraint. Returns (M, f, V, E, a)."""
    th1, th2, tau = _Q
    d1, d2, dtau = _DQ
    P = _PS
    q, dq = sp.Matrix(_Q), sp.Matrix(_DQ)
    x1, y1 = P["l1"] * sp.sin(th1), -P["l1"] * sp.cos(th1)
    x2, y2 = x1 + P["l2"] * sp.sin(th1 + th2), y1 - P["l2"] * sp.cos(th1 + th2)
    v = [sp.Matrix([x, y]).jacobian(q) * dq for x, y in ((x1, y1), (x2, y2))]
    kinetic = (P["m1"] * (v[0].T * v[0])[0] + P["m2"] * (v[1].T * v[1])[0]
               + P["J"] * (d1 + d2) ** 2 + dtau**2) / 2
    M = sp.hessian(kinetic, dq).applyfunc(sp.simplify)
    a, b, dd = P["a"], P["b"], P["d"]
    extra = (
        (1 - sp.cos(th1 + th2 - a))
        + sp.sin(2 * th1 - th2 / 3 + b) ** 2
        + (th1 + a) ** 2 * (th2 - b) ** 3 / 10
        + sp.sqrt(1 + (th1 - th2) ** 2)
        + sp.exp(-(th1 + th2 / 2) ** 2)
        + sp.log(2 + sp.cos(th1 + th2))
        + (3 + sp.sin(-th1 + b)) ** sp.Rational(3, 2)
        + (2 + th2**2) ** sp.Rational(-1, 3)
        + sp.Abs(th1 - 4) * sp.sin(th2) / 5
        + sp.Piecewise(((th2 - dd) ** 3, th2 > dd), (0, True))
        + sp.sin(sp.cos(th1 + th2) * th1)
        + sp.tanh(th1 - th2) + sp.atan(th2 + a)
        + sp.cos(th1) ** 3 * sp.sin(th2 + a) ** 2 / (2 + sp.sin(th1 + th2))
    )
    V = P["g"] * (P["m1"] * y1 + P["m2"] * y2) + P["k"] * extra
    # M q'' = f: -(dM/dt) q' + dT/dq - dV/dq, plus damping and input (nonconservative)
    f = -(sp.Matrix([[sum(sp.diff(M[i, j], qk) * dk for qk, dk in zip(q, dq))
                      for j in range(3)] for i in range(3)]) * dq)
    f += sp.Matrix([sp.diff(kinetic, qi) - sp.diff(V, qi) for qi in q])
    f += sp.Matrix([-P["c"] * (d1 + sp.sin(th2 + th1) * d2) + _U * sp.cos(th1 + _U),
                    -P["c"] * d2 * (1 + d1**2) - _U**2 * sp.sin(th2 - a), 0])
    return M, f, V, kinetic + V, y2 + P["H"]


def _chain_system(M, f, a) -> System:
    th1, th2, tau = _Q
    P = _PS
    c = System("chain_kinds", ["th1", "th2", "tau"], parameters=_P, inputs=["u"])
    c.mass_matrix = M
    c.forces = f
    c.constraint("floor", a)
    start = {th1: c.s, th2: 0.4, _DQ[1]: 0.3, _DQ[2]: 1}
    c.maneuver("swing", initial=start, terminal=P["T"] - tau, outcome=th1)
    # the tip on the floor at rest: th1 + th2 from the tip's height (an acos of a quotient)
    touching = {th1: c.s, th2: sp.acos((P["H"] - P["l1"] * sp.cos(c.s)) / P["l2"]) - c.s,
                _DQ[2]: 1}
    c.maneuver("slide", initial=touching, mode=["floor"], terminal=P["T"] - tau, outcome=th1)
    return c


def _reference(M, f, a, values, u, y0, contact, t_end, times):
    """SciPy's DOP853 at rtol 1e-12 on the lambdified M, f (and, in contact, the constraint
    force from [[M, -Da^T], [Da, 0]] [q''; lam] = [f; -(d/dt Da) q'])."""
    q, dq = sp.Matrix(_Q), sp.Matrix(_DQ)
    subs = {_PS[k]: v for k, v in values.items()} | {_U: u}
    da = sp.Matrix([a]).jacobian(q)
    rate = (da * dq).jacobian(q) * dq
    args = [*_Q, *_DQ]
    Mf, ff = (sp.lambdify(args, e.subs(subs), "numpy") for e in (M, f))
    daf, ratef = (sp.lambdify(args, e.subs(subs), "numpy") for e in (da, rate))

    def rhs_lam(y):
        m, force = np.array(Mf(*y), float), np.array(ff(*y), float).ravel()
        if not contact:
            return np.linalg.solve(m, force), 0.0
        j = np.array(daf(*y), float).reshape(1, 3)
        kkt = np.block([[m, -j.T], [j, np.zeros((1, 1))]])
        sol = np.linalg.solve(kkt, np.concatenate([force, -np.ravel(ratef(*y))]))
        return sol[:3], sol[3]

    def rhs(t, y):
        return np.concatenate([y[3:], rhs_lam(y)[0]])

    sol = solve_ivp(rhs, (0.0, t_end), y0, method="DOP853", rtol=1e-12, atol=1e-13,
                    dense_output=True)
    assert sol.success
    return sol.sol(times).T, np.array([rhs_lam(y)[1] for y in sol.sol(times).T])


@pytest.fixture(scope="module")
def chain():
    M, f, V, E, a = _chain_expressions()
    return compile_system(_chain_system(M, f, a)), (M, f, E, a)


@pytest.mark.parametrize(("maneuver", "s", "c", "u"), [
    ("swing", 0.6, 0.0, 0.0), ("swing", -0.9, 0.25, 0.7),
    ("slide", 0.6, 0.0, 0.0), ("slide", 0.5, 0.1, 0.3)])
def test_chain_of_many_expression_kinds_against_solve_ivp(chain, maneuver, s, c, u):
    """The compiled maneuver (the step with its inlined field, the constraint's reactions in
    contact) against SciPy on the same expressions, sampled along the way and at the end; in
    flight the floor is out of reach (H = 10), in contact the tip slides on it (H = 1.5) and
    stays pressed (no event). 1e-9 on the state: both integrators run at rtol 1e-12 and
    differ by 3e-13 to 1.1e-10 over this short horizon (measured; the chain is not yet
    chaotic by t = 1.5); the reactions by 3e-13 (1e-8: they are accelerations, one derivative
    rougher). Without damping and input the energy (scale 15) drifts by 3e-12: 1e-9 of m g
    leaves room for the integrator and nothing for a wrong force term."""
    system, (M, f, E, a) = chain
    values = dict(_P, c=c, H=10.0 if maneuver == "swing" else 1.5)
    system.set_parameters(**values)
    tr = system.simulate(maneuver, s, (u,), options=TIGHT, sample_dt=0.1)
    assert tr.status is Status.OK and tr.n_events == 0
    assert tr.t_final == pytest.approx(values["T"], abs=1e-11)
    ts = tr.samples[:, 0]
    ref, lam = _reference(M, f, a, values, u, tr.samples[0, 1:7], maneuver == "slide",
                          tr.t_final, ts)
    np.testing.assert_allclose(tr.samples[:, 1:7], ref, rtol=0, atol=1e-9)
    if maneuver == "slide":
        assert np.all(lam > 0.1)  # (pressed throughout: the contact mode is the right one)
        np.testing.assert_allclose(tr.samples[:, 8], lam, rtol=0, atol=1e-8)
        height = sp.lambdify([*_Q], a.subs({_PS[k]: v for k, v in values.items()}))
        assert abs(height(*tr.y_final[:3])) < 1e-9
    if c == 0.0 and u == 0.0:
        energy = sp.lambdify([*_Q, *_DQ], E.subs({_PS[k]: v for k, v in values.items()}))
        e = np.array([energy(*row) for row in tr.samples[:, 1:7]])
        assert np.max(np.abs(e - e[0])) < 1e-9 * values["g"] * (values["m1"] + values["m2"])
