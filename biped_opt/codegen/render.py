"""Source of a system's compiled module: its Eq. (1) as straight-line code, and the simulator.

:func:`render` turns a :class:`~biped_opt.systems.derive.DerivedSystem` into the text of one
Python module that Numba compiles (and caches on disk, keyed by that file):

- ``vector_field(p, mode, y, yo, u, out, off, lam, lo)``: (q', q'') and the reactions lambda of
  mode J at the state y[yo:yo + 2d], Eq. (1a). Straight-line code on scalars, without
  branches on the mode: the forces f_J (common subexpressions shared, inputs gated by 0/1 mode
  factors), an unrolled Cholesky factorisation of M(q) that skips the entries known to be zero
  (a diagonal M costs d divisions), the active constraints' Schur complement Da_J M^-1 Da_J^T
  solved the same way. Nothing allocates.
- ``prepare_parameters(p)`` (plain Python): the parameter vector the compiled functions take,
  p followed by what depends on the parameters alone (a constant M's factor, the Schur
  complement of constant constraint rows), so that no evaluation recomputes it.
- ``apply_impact(p, mode, y)``: q'+ = Delta_J q'- on entering J, Eq. (1b).
- the constraints a(q) and their rates Da q', the maneuvers' initial states, terminal guards and
  outcomes, and the guards of every mode (a_j in the air, lambda_j in contact, the terminal one);
- the DOP853 step (:mod:`biped_opt.codegen.dop853` with this system's dimensions; a small
  vector field written out into its twelve stages, a large one called from them, see
  :data:`INLINE_FIELD_LINES`, and a larger one still from one loop over the stages, see
  :data:`LOOP_STEP_LINES`);
- the system's table and the C-callable wrappers of these functions through which the
  event-driven kernel, one for every system, calls them (:mod:`biped_opt.codegen.abi`,
  :mod:`biped_opt.codegen.kernel`): a new system compiles only its own functions.

Parameters and inputs are arguments (``p``, ``u``), never constants: changing a parameter value
does not change the source, so it does not recompile.

This module assembles the functions; each idea they rest on is a module of its own, readable
one at a time (each imports only those before it):

1. :mod:`biped_opt.codegen.emit`: printing expressions from SymPy's tree and emitting them as
   straight-line code with shared subexpressions and folded zeros;
2. :mod:`biped_opt.codegen.linalg`: the unrolled, fill-reducing Cholesky factorisation and the
   solves with it;
3. :mod:`biped_opt.codegen.hoist`: the modes' forces mixed by 0/1 factors, and what depends on
   the parameters alone hoisted out of every evaluation;
4. :mod:`biped_opt.codegen.tree`: a body tree's M and forces by CRBA and RNEA;
5. :mod:`biped_opt.codegen.impact`: the impact map, unrolled per mode or as one loop;
6. :mod:`biped_opt.codegen.inline`: the step's copies of the vector field, probe and
   sine/cosine made on the syntax tree (:func:`~biped_opt.codegen.inline.expand`), never by
   pasting an argument's text into a body, and the assignments no one reads dropped
   (:func:`~biped_opt.codegen.inline.prune`: Numba types every statement of every copy).
"""

from __future__ import annotations

import ast
import hashlib
import inspect
import re
import textwrap
from collections.abc import Callable

import numpy as np
import sympy as sp

from biped_opt.codegen import abi, dop853
from biped_opt.codegen.emit import (
    Emitter,
    UnsupportedExpressionError,
    bind_symbols,
    is_zero,
    summed,
    symbol_names,
    times,
)
from biped_opt.codegen.hoist import (
    SINCOS_ANGLES,
    Hoisted,
    mode_mixed,
    reciprocal_of,
    schedule,
    sincos_angles,
)
from biped_opt.codegen.impact import impact_map
from biped_opt.codegen.inline import expand, literal_node, prune
from biped_opt.codegen.linalg import Inverse, Permuted, cholesky, separable, solve, solved_columns
from biped_opt.codegen.tree import BodyTree
from biped_opt.systems.derive import DerivedManeuver, DerivedSystem

__all__ = ["render", "source_key", "UnsupportedExpressionError"]

#: bump when the generated code's form changes (the cache key includes it)
FORMAT = 11


def _vector_field(derived: DerivedSystem) -> tuple[list[str], Hoisted]:
    """Eq. (1a) for the current mode, branch-free: the forces mixed by 0/1 mode factors, and
    the reactions from the Schur complement of *all* constraints with the inactive ones' rows
    and columns replaced by the identity (their reactions come out 0). Without branches Numba
    can drop the reference counting around an inlined call (tests/codegen/test_dop853.py checks
    that none is left). Also returns what it hoisted (:class:`Hoisted`), whose
    ``prepare_parameters`` is written once the impact map has added its blocks."""
    d, n = derived.ndof, derived.nconstraints
    out = ["@nb.njit(**HOT_PATH, inline=\"always\")",
           "def vector_field(p, mode, y, yo, u, out, off, lam, lo):",
           '    """(q\', q\'\') of mode ``mode`` at y[yo:yo + 2d] to out[off:off + 2d], the',
           '    reactions to lam[lo:lo + n] (0 for inactive constraints), Eq. (1a)."""']
    em = Emitter(symbol_names(derived.system), sincos=len(sincos_angles(derived)) <= SINCOS_ANGLES)
    bind_symbols(derived, em, velocities=True, inputs=True)
    hoist = Hoisted(derived, em)
    const_m = not derived.bodies and hoist.constant(derived.mass_matrix)
    const_da = n == 0 or hoist.constant(derived.jacobian)
    m_em = hoist.pre if const_m else em
    tree = BodyTree(derived, em, motion=True, hoist=hoist) if derived.bodies else None
    m = (tree.mass_matrix() if tree is not None else
         m_em.exprs([derived.mass_matrix[i, j] for i in range(d) for j in range(d)], "m"))
    L = cholesky(m_em, [[m[i * d + j] for j in range(d)] for i in range(d)], "c")
    if const_m:
        loaded = hoist.load_all(L)
        if isinstance(L, Permuted):
            permuted = Permuted(loaded)
            permuted.order = L.order
            L = permuted
        else:
            L = Inverse(loaded) if isinstance(L, Inverse) else loaded
    da_em = hoist.pre if const_da else em
    da = da_em.exprs(list(derived.jacobian), "a") if n else []
    Da = [[da[j * d + i] for i in range(d)] for j in range(n)]
    if const_da:
        Da = hoist.load_all(Da)
    rate = em.exprs(list(derived.jacobian_rate), "r") if n else []
    for i in range(d):
        em.line(f"out[off + {i}] = y[yo + {d + i}]")
    f = mode_mixed(em, derived)
    if tree is not None:
        inertial = tree.forces()
        f = [em.assign("f", summed([a, b])) for a, b in zip(f, inertial)]
    x = solve(em, L, f, "x")
    acc = x
    if n:
        on = [em.assign("n", f"float(mode >> {j} & 1)") for j in range(n)]
        off = [em.assign("n", f"1.0 - {on[j]}") for j in range(n)]
        s_em = hoist.pre if const_m and const_da else em
        cols = solved_columns(s_em, L, Da, list(range(n)))
        S = [[s_em.assign("s", summed([times(Da[a][i], cols[b][i]) for i in range(d)]))
              for b in range(n)] for a in range(n)]
        rhs = [em.assign("b", times(on[a], "(-(" + summed(
            [*(times(Da[a][i], x[i]) for i in range(d)), rate[a]]) + "))")) for a in range(n)]
        diagonal = all(is_zero(S[a][b]) for a in range(n) for b in range(n) if a != b)
        coords = separable(L, Da) if s_em is hoist.pre else None
        if coords is not None:
            # each constraint pins its own coordinate k_j of a diagonal M (a foot's height,
            # an end's height): lambda_j = -on_j f_kj / a_j and that coordinate's
            # acceleration is off_j f_kj / m_kj, the arithmetic of a hand-written model
            lam = [em.assign("l", times(on[j], "(-(" + times(f[k], reciprocal_of(hoist, Da[j][k]))
                                       + "))")) for j, k in enumerate(coords)]
            acc = list(x)
            for j, k in enumerate(coords):
                acc[k] = em.assign("q", times(x[k], off[j]))
        elif s_em is hoist.pre and diagonal:
            # the masked matrix is diagonal with entries on_j S_jj + off_j (on_j in {0, 1}), and
            # rhs_j carries the factor on_j: lambda_j = rhs_j / S_jj, no division per evaluation
            inv = hoist.load_all([hoist.pre.assign("kv", f"1.0 / {S[j][j]}") for j in range(n)])
            cols = hoist.load_all(cols)
            lam = [em.assign("l", times(rhs[j], inv[j])) for j in range(n)]
        else:
            if s_em is hoist.pre:
                cols, S = hoist.load_all(cols), hoist.load_all(S)
            masked = [[em.assign("s", summed([times(times(on[a], on[b]), S[a][b]),
                                            off[a] if a == b else "0.0"]))
                       for b in range(n)] for a in range(n)]
            lam = solve(em, cholesky(em, masked, "k"), rhs, "l")
        if coords is None:
            acc = [em.assign("q", summed([x[i], *(times(cols[j][i], lam[j]) for j in range(n))]))
                   for i in range(d)]
        for j in range(n):
            em.line(f"lam[lo + {j}] = {lam[j]} + 0.0")
    for i in range(d):
        em.line(f"out[off + {d + i}] = {acc[i]}")
    return out + schedule(em.lines), hoist


def _reaction(vector_field: list[str], n: int) -> list[str]:
    """``reaction(p, mode, u, y, j)``: lambda_j at the state y (foot j in contact), from the
    vector field's body without its stores (pruned here, the rest by the compiler): a
    reaction guard on the dense output, evaluated ~6 times per liftoff event by the root
    search, needs no accelerations."""
    body = vector_field[vector_field.index('    reactions to lam[lo:lo + n] (0 for inactive '
                                           'constraints), Eq. (1a)."""') + 1:]
    store = re.compile(r"    lam\[lo \+ (\d+)\] = (.*)")
    values = {int(m[1]): m[2] for line in body if (m := store.fullmatch(line))}
    chosen = values.get(n - 1, "0.0")
    for j in reversed(range(n - 1)):
        chosen = f"{values[j]} if j == {j} else {chosen}"
    kept = [line.replace("y[yo + ", "y[") for line in body
            if not line.startswith(("    out[off + ", "    lam[lo + "))]
    return ["@nb.njit(**HOT_PATH)",
            "def reaction(p, mode, u, y, j):",
            '    """lambda_j of mode ``mode`` at the state y (0 for an inactive constraint),',
            '    Eq. (1a)."""',
            *kept,
            f"    return {chosen}"]


def _reaction_through_field(nstate: int, n: int) -> list[str]:
    """``reaction`` for a large vector field: the called field's reactions. A copy of the
    field's body without its stores, as :func:`_reaction` makes, would compile as long as the
    field itself (6 s of a planar chain with d = 9); the accelerations it saves are a small
    part of the field, and a reaction is evaluated only while an event's root is searched.
    The same expressions, so the same value to the last bit."""
    return ["@nb.njit(**HOT_PATH)",
            "def reaction(p, mode, u, y, j):",
            '    """lambda_j of mode ``mode`` at the state y (0 for an inactive constraint),',
            '    Eq. (1a), from the called vector field."""',
            f"    out = np.empty({nstate})",
            f"    lam = np.empty({max(n, 1)})",
            "    _field_at(p, mode, y, 0, u, out, 0, lam, 0)",
            "    return lam[j]"]


def _scalar_function(name: str, doc: str, args: str, derived: DerivedSystem,
                     exprs: list[sp.Expr], target: str, *, inputs: bool) -> list[str]:
    out = ["@nb.njit(**HOT_PATH)", f"def {name}({args}):", f'    """{doc}"""']
    em = Emitter(symbol_names(derived.system))
    bind_symbols(derived, em, velocities=True, inputs=inputs)
    values = em.exprs(exprs, "e") if exprs else []
    for k, v in enumerate(values):
        em.line(f"{target}[{k}] = {v}")
    return out + em.lines


def _per_maneuver(name: str, doc: str, args: str, derived: DerivedSystem,
                  pick: Callable[[DerivedManeuver], sp.Expr], *, inputs: bool) -> list[str]:
    out = ["@nb.njit(**HOT_PATH)", f"def {name}({args}):", f'    """{doc}"""']
    em = Emitter(symbol_names(derived.system))
    bind_symbols(derived, em, velocities=True, inputs=inputs)
    out += em.lines
    for code, m in enumerate(derived.maneuvers.values()):
        out.append(f"    {'if' if code == 0 else 'elif'} code == {code}:")
        br = em.branch(1000 * (code + 1))
        (value,) = br.exprs([pick(m)], "t")
        out += br.lines
        out.append(f"        return {value}")
    out.append("    return 0.0")
    return out


def _initial(derived: DerivedSystem) -> list[str]:
    system = derived.system
    out = ["@nb.njit(**HOT_PATH)", "def initial_state(code, s, p, y0):",
           '    """The initial state (q, q\') of maneuver ``code`` at s into y0."""']
    em = Emitter(symbol_names(system))
    out += [f"    {em.names[sym]} = p[{k}]" for k, sym in enumerate(system.p)]
    out.append(f"    {em.names[system.s]} = s")
    for code, m in enumerate(derived.maneuvers.values()):
        out.append(f"    {'if' if code == 0 else 'elif'} code == {code}:")
        br = em.branch()
        values = br.exprs(list(m.initial), "i")
        for k, v in enumerate(values):
            br.line(f"y0[{k}] = {v}")
        out += br.lines
    return out


def _guards(derived: DerivedSystem) -> list[str]:
    n = derived.nconstraints
    out = ["@nb.njit(**HOT_PATH)",
           "def constraint_value(j, p, y, yo):",
           '    """a_j(q) at the state y[yo:]."""']
    em = Emitter(symbol_names(derived.system))
    bind_symbols(derived, em, velocities=False, inputs=False)
    out += em.lines
    for j in range(n):
        out.append(f"    {'if' if j == 0 else 'elif'} j == {j}:")
        br = em.branch(1000 * (j + 1))
        (value,) = br.exprs([derived.constraints[j]], "a")
        out += br.lines
        out.append(f"        return {value}")
    out.append("    return 0.0")
    return out + [
        "",
        "",
        "@nb.njit(**HOT_PATH)",
        "def guard_value(p, mode, u, code, y, yo, lam, lo, i):",
        '    """Guard i at the state y[yo:] whose reactions lam[lo:] are known: a_i in the air,',
        '    lambda_i in contact, and for i = n the maneuver\'s terminal guard."""',
        f"    if i == {n}:",
        "        return terminal_value(code, p, u, y, yo)",
        "    if mode >> i & 1:",
        "        return lam[lo + i]",
        "    return constraint_value(i, p, y, yo)",
    ] + ["", ""] + _probe(derived, values=True)


def _as_component(derived: DerivedSystem, expr: sp.Expr) -> tuple[int, float] | None:
    """(k, sign) when ``expr`` is +-y[k], a single coordinate or velocity, else None."""
    state = [*derived.system.q, *derived.system.dq]
    for sign, candidate in ((1.0, expr), (-1.0, -expr)):
        if candidate in state:
            return state.index(candidate), sign
    return None


def _probe(derived: DerivedSystem, *, values: bool = False) -> list[str]:
    """The stage probe of the DOP853 step, inlined into each of its 12 stages: straight-line
    code (a call per guard and stage cost more than the vector field itself). Each guard is
    chosen by a conditional expression (lambda_j or a_j by the mode, the terminal guard by
    the maneuver) and a stage lowers c_i only when its guard is <= 0: measured, this is ~2%
    of a simulation faster than mixing every guard by 0/1 factors. ``values``: the same
    guards written to ``out`` (what the kernel reads after each step)."""
    n = derived.nconstraints
    if values:
        out = ["@nb.njit(**HOT_PATH, inline=\"always\")",
               "def guard_values(p, mode, u, code, y, yo, lam, lo, out):",
               '    """Every guard at the state y[yo:] with known reactions lam[lo:]."""']
    else:
        cs = ", ".join(f"_c{i}" for i in range(n + 1))
        out = ["@nb.njit(**HOT_PATH, inline=\"always\")",
               f"def probe_stage(p, mode, u, code, y, yo, lam, lo, _c, {cs}):",
               '    """(c0, c1, ...) with ci lowered to the abscissa _c for each guard i <= 0 at',
               '    the stage state y[yo:] (values, not an array: the step keeps them in',
               '    registers)."""']
    em = Emitter(symbol_names(derived.system))
    bind_symbols(derived, em, velocities=True, inputs=True)
    a = em.exprs(list(derived.constraints), "a") if n else []
    terms = em.exprs([m.terminal for m in derived.maneuvers.values()], "t")
    guards = [em.assign("g", f"lam[lo + {j}] if mode >> {j} & 1 else {a[j]}") for j in range(n)]
    chosen = terms[-1]
    for k in reversed(range(len(terms) - 1)):
        chosen = f"{terms[k]} if code == {k} else {chosen}"
    guards.append(em.assign("g", chosen))
    for i, g in enumerate(guards):
        if values:
            em.line(f"out[{i}] = {g}")
        else:
            em.line(f"if {g} <= 0.0 and _c < _c{i}:")
            em.line(f"    _c{i} = _c")
    if not values:
        em.line(f"return {cs}")
    return out + em.lines


def _sincos_source() -> str:
    """The source of :func:`biped_opt.codegen.runtime.sincos` (what ``_sincos`` is in a generated
    module) with its module's float constants written as literals, for :func:`expand`."""
    from biped_opt.codegen import runtime as model

    class Literals(ast.NodeTransformer):
        def visit_Name(self, node: ast.Name) -> ast.expr:
            value = getattr(model, node.id, None)
            return literal_node(value) if type(value) is float else node

    tree = Literals().visit(ast.parse(textwrap.dedent(inspect.getsource(model.sincos))))
    return ast.unparse(tree)


def _int_array(values: list[int]) -> str:
    return f"np.array({values!r}, dtype=np.int64)"


#: the largest vector field (lines of its function) written out into each of the step's twelve
#: stages; a larger one is called from them instead. Written out, the parameters, inputs and
#: mode factors are read once per step rather than once per stage, but Numba types and lowers
#: every copy: measured cold (one process, 2 cores), the biped's field (94 lines) written out
#: compiles in 30.5 s and runs a trajectory in 21.8 us, called in 22.7 s and 24.2 us (+11%);
#: the three-legged walker's (123 lines) in 41.6 s and 53.9 us written out, 27.6 s and 50.5 us
#: called (the copies' live values no longer spill). Outcomes are the same to the last bit.
INLINE_FIELD_LINES = 110
#: the largest called vector field whose step is still written out stage by stage; a larger
#: one gets the step as one loop over the stages (biped_opt.codegen.dop853, ``loop=True``),
#: which compiles one copy of the stage and its guard probe instead of twelve: walker8's step
#: compiles in 1.3 s instead of 10.7 s. Per trajectory (one thread, 50 touchdowns or drops,
#: written out against loop): the five-link chain (field of 212 lines) 653 against 568 us,
#: chain9 6430 against 6412 us, but the four-legged walker (156 lines) 33.2 against 44.0 us
#: and walker8 (285 lines) 73.3 against 100.4 us: a cheap field pays for the loop's index
#: arithmetic. The library's three-legged walker (123 lines) stays written out.
LOOP_STEP_LINES = 150


def _dependent_rows(derived: DerivedSystem) -> bool:
    """Whether the constraints' rows of Da are linearly dependent at generic configurations
    (biped_opt.codegen.abi.SV_DEPENDENT): the rank of Da at three pseudo-random q (and the
    default parameters) below n at each. Rows that depend on each other for every q (a face's
    corners) give rank < n everywhere; a set dependent only at some configurations (a leg
    stretched straight) is not found here, and a random q never lands on one."""
    system = derived.system
    n, d = derived.nconstraints, derived.ndof
    if n < 2:
        return False
    if n > d:
        return True
    jacobian = sp.lambdify([*system.q, *system.p], derived.jacobian.tolist(), modules="math",
                           cse=True)
    rng = np.random.default_rng(20261129)
    params = [float(system.defaults[name]) for name in system.p.names()]
    found = 0
    for _ in range(3):
        for _attempt in range(20):  # (a q where an expression is undefined is drawn again)
            try:
                da = np.array(jacobian(*rng.uniform(-1.0, 1.0, d), *params), dtype=np.float64)
            except (ValueError, ZeroDivisionError, OverflowError):
                continue
            if np.all(np.isfinite(da)):
                break
        else:
            return False
        lengths = np.linalg.norm(da, axis=1)
        if np.any(lengths == 0.0):
            found += 1
            continue
        singular = np.linalg.svd(da / lengths[:, None], compute_uv=False)
        found += int(singular[-1] <= 1e-9)
    return found == 3


def render(derived: DerivedSystem) -> str:
    """The whole module's source (see the module docstring)."""
    system = derived.system
    d, n = derived.ndof, derived.nconstraints
    maneuvers = list(derived.maneuvers.values())
    final = [-1 if m.final_mode is None else m.final_mode for m in maneuvers]
    after = [int(m.description.armed_after == "touchdown") for m in maneuvers]
    table = abi.system_table(
        2 * d, n, 18 * (2 * d + max(n, 1)),
        [_as_component(derived, a) for a in derived.constraints],
        [(_as_component(derived, m.terminal), bool(a), f, m.mode)
         for m, a, f in zip(maneuvers, after, final)],
        dependent=_dependent_rows(derived))
    head = [
        f'"""Compiled simulator of the system {system.name!r}.',
        "",
        "GENERATED by biped_opt.codegen.render from the system's description: do not edit.",
        '"""',
        "",
        "import math",
        "",
        "import numba as nb",
        "import numpy as np",
        "",
        "from biped_opt._jit import HOT_PATH",
        "from biped_opt.codegen.runtime import sincos as _sincos",
        "",
        f"NDOF = {d}",
        f"NSTATE = {2 * d}",
        f"NCON = {n}",
        f"NGUARDS = {n + 1}",
        f"NPARAM = {len(system.p)}",
        f"NINPUT = {len(system.u)}",
        f"INITIAL_MODE = {_int_array([m.mode for m in maneuvers])}",
        f"FINAL_MODE = {_int_array(final)}",
        f"TERM_AFTER_TOUCHDOWN = {_int_array(after)}",
        "#: the layouts of the kernel's event rows and samples (biped_opt.codegen.kernel)",
        f"EVENT_WIDTH = {6 + 4 * d}",
        f"SAMPLE_WIDTH = {2 + 2 * d + n}",
        "#: the system's table for the shared kernel (biped_opt.codegen.abi.system_table)",
        f"SYSTEM_TABLE = {_int_array(table)}",
        "",
    ]
    try:
        vector_field, hoist = _vector_field(derived)
        field_lines = prune(vector_field)
        inline_field = len(field_lines) <= INLINE_FIELD_LINES
        impact = impact_map(derived, hoist)
        parts = [
            head,
            hoist.function(derived),
            vector_field,
            _reaction(vector_field, n) if inline_field else _reaction_through_field(2 * d, n),
            impact,
            _scalar_function("constraint_rates", "Da(q) q' into out[:n].", "p, y, yo, out",
                             derived, list(derived.jacobian * sp.Matrix(system.dq))
                             if n else [], "out", inputs=False),
            _per_maneuver("terminal_value", "The terminal guard of maneuver ``code``.",
                          "code, p, u, y, yo", derived, lambda m: m.terminal, inputs=True),
            _per_maneuver("outcome_value", "The outcome of maneuver ``code`` at the state y.",
                          "code, p, y, yo", derived, lambda m: m.outcome, inputs=False),
            _initial(derived),
            _guards(derived),
        ]
        probe = _probe(derived)
    except UnsupportedExpressionError as exc:
        raise UnsupportedExpressionError(f"{system.where()}: {exc}") from None
    text = "\n\n\n".join("\n".join(prune(part)) for part in parts) + "\n"
    step = dop853.render(n=2 * d, imports="",
                         rhs="vector_field" if inline_field else "_field_at",
                         probe="probe_stage", nlam=max(n, 1), registers=True, nguards=n + 1,
                         probe_head="p, mode, u, term_sign", dense_rhs="_field_at",
                         loop=len(field_lines) > LOOP_STEP_LINES)
    step = step[step.index("\nSTRIDE = ") + 1:]
    # the vector field with its sines and cosines expanded (one pass over its text): expanded
    # further into the step's stages, or the body of the called field
    field_text = expand("\n".join(field_lines), {"_sincos": _sincos_source()},
                         invariant=set(), tag="s")
    expanded = {"vector_field": field_text} if inline_field else {}
    expanded["probe_stage"] = "\n".join(prune(probe))
    step = expand(step, expanded, invariant={"p", "u", "mode", "term_sign"})
    return (text + "\n\n" + step + "\n\n" + _field_at(None if inline_field else field_text)
            + "\n\n" + abi.cfunc_source())


#: the called vector field's types (its explicit signature: see :func:`_field_at`)
FIELD_SIGNATURE = "void(f8[::1], i8, f8[::1], i8, f8[::1], f8[::1], i8, f8[::1], i8)"
#: the functions of biped_opt.codegen.abi.FUNCTIONS that a generated module writes without a
#: call of the vector field
FIELD_FREE = ("apply_impact", "constraint_rates", "guard_value", "guard_values", "initial_state",
              "outcome_value")


def _field_at(field_text: str | None) -> str:
    """``_field_at``: the vector field as a call, for the paths outside the step (the start,
    events, samples, the dense output's extra stages) and, for a field too large to write out,
    for the step's stages too. A small field is inlined into it (by Numba: one copy); a large
    one *is* its body (``field_text``: the field with its sines and cosines written out), since
    Numba's inlining of a large function into a small one costs more than compiling the
    function itself (a planar chain with d = 9: 11.8 of the 29.5 s this function took).

    ``_field_ready()`` compiles it for its one signature (or loads it from the cache) and then
    no other: called with the literal offsets of the dense stages, Numba would otherwise compile
    one specialisation per offset. Only when needed (``compile_functions`` calls it first for
    every function but those in ``FIELD_FREE``), so that a second process can compile the
    functions that do not call the field while the first compiles it."""
    head = ["@nb.njit(**HOT_PATH)",
            "def _field_at(p, mode, y, yo, u, out, off, lam, lo):",
            '    """The vector field as a call (biped_opt.codegen.render._field_at)."""']
    ready = ["", "", f'FIELD_SIGNATURE = "{FIELD_SIGNATURE}"',
             "#: the compiled functions that do not call the field",
             f"FIELD_FREE = {FIELD_FREE!r}", "", "",
             "def _field_ready():",
             '    """Compile _field_at for its one signature (see render._field_at)."""',
             "    if not _field_at.signatures:",
             "        _field_at.compile(FIELD_SIGNATURE)",
             "    _field_at.disable_compile()", ""]
    if field_text is None:
        return "\n".join([*head, "    vector_field(p, mode, y, yo, u, out, off, lam, lo)",
                          *ready])
    tree = ast.parse(field_text)
    fn = next(node for node in tree.body if isinstance(node, ast.FunctionDef))
    statements = fn.body
    if statements and isinstance(statements[0], ast.Expr) \
            and isinstance(statements[0].value, ast.Constant):
        statements = statements[1:]  # (the field's docstring)
    lines = field_text.split("\n")
    body = lines[statements[0].lineno - 1:fn.end_lineno]
    return "\n".join([*head, *body]).rstrip() + "\n" + "\n".join(ready)


def source_key(text: str) -> str:
    """Content key of a system's compiled module (the text :func:`render` made) with the
    generator's version: the name of its cached file."""
    return hashlib.sha256(f"{FORMAT}\n{text}".encode()).hexdigest()[:16]
