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
does not change the source, so it does not recompile. Assignments a function never reads are
dropped (:func:`_prune`): Numba types every statement of every inlined copy.

Meaning is kept by construction: expressions are printed from SymPy's tree (a power or a
quotient of a sum keeps its brackets); a system's symbols are written ``q__<name>``,
``v__<name>``, ``p__<name>``, ``u__<name>``, ``s__<name>`` and the generator's own names never
contain a double underscore, so a description may name its symbols anything (no reserved
names); and the step's copies of the vector field, probe and sine/cosine are made on the
syntax tree (:func:`_expand`), never by pasting an argument's text into a body.
"""

from __future__ import annotations

import ast
import hashlib
import inspect
import io
import math
import re
import textwrap
import tokenize
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from biped_opt.codegen import abi, dop853
from biped_opt.systems.derive import DerivedManeuver, DerivedSystem
from biped_opt.systems.description import System, SystemDescriptionError

__all__ = ["render", "source_key", "UnsupportedExpressionError"]
#: bump when the generated code's form changes (the cache key includes it)
FORMAT = 11


class UnsupportedExpressionError(SystemDescriptionError):
    """An expression of a description has no compiled form (a function generated code
    cannot call); the message names the system and the function."""


def _symbol_names(system: System) -> dict[sp.Symbol, str]:
    """The names a system's symbols take in generated code: ``q__th`` for the coordinate th,
    ``v__th`` for its velocity, ``p__m``, ``u__u1`` and ``s__s`` for a parameter, an input and
    the maneuvers' s. The generator's own names never contain a double underscore, so no
    name a description chooses (``y``, ``s``, ``j``, ``math``...) can stand for one of them:
    there are no reserved names."""
    kinds = (("q", system.q, system.coordinate_names), ("v", system.dq, system.coordinate_names),
             ("p", tuple(system.p), system.p.names()), ("u", tuple(system.u), system.u.names()),
             ("s", (system.s,), (str(system.s),)))
    return {sym: f"{kind}__{name}" for kind, symbols, names in kinds
            for sym, name in zip(symbols, names)}


class _Printer(PythonCodePrinter):
    """``math.*`` calls and float literals, the form Numba compiles best; a system's symbols
    by their names in generated code (setting ``names``, see :func:`_symbol_names`)."""

    _default_settings = {**PythonCodePrinter._default_settings, "names": {}}

    def _print_Symbol(self, expr: sp.Symbol) -> str:
        name = self._settings["names"].get(expr)
        return super()._print_Symbol(expr) if name is None else name

    def _print_Piecewise(self, expr: sp.Piecewise) -> str:
        # NaN where no condition holds, as SymPy evaluates it (not None, which Numba rejects)
        if expr.args[-1].cond != sp.true:
            expr = sp.Piecewise(*expr.args, (sp.nan, True))
        return super()._print_Piecewise(expr)

    def _print_not_supported(self, expr: sp.Basic) -> str:
        raise UnsupportedExpressionError(
            f"{type(expr).__name__} ({expr}) has no compiled form: write the system with "
            "elementary functions (sin, exp, log, sqrt, Abs, Piecewise, ...)")

    def _print_Float(self, expr: sp.Float) -> str:
        # every digit of the double (SymPy prints 15, which need not read back as the same
        # number: a URDF's inertia or a rotation's entries would move by ~1e-16)
        value = float(expr)
        return repr(value) if math.isfinite(value) else super()._print_Float(expr)

    def _print_Integer(self, expr: sp.Integer) -> str:
        return f"{float(expr)!r}"

    def _print_Rational(self, expr: sp.Rational) -> str:
        return f"{float(expr)!r}"

    def _print_Half(self, expr: sp.Rational) -> str:
        return "0.5"

    def _print_Pow(self, expr: sp.Pow, rational: bool = False) -> str:
        # small integer powers as products (exact, and no call to pow); others as usual
        base, exp = expr.as_base_exp()
        if exp.is_Integer and 2 <= int(exp) <= 4:
            factor = self.parenthesize(base, sp.printing.precedence.PRECEDENCE["Mul"])
            # parenthesised: the product may be printed as a divisor (3/w**2 -> 3/(w*w))
            return "(" + "*".join([factor] * int(exp)) + ")"
        if exp.is_Integer and int(exp) == -1:
            return f"1.0/{self.parenthesize(base, sp.printing.precedence.PRECEDENCE['Pow'])}"
        return super()._print_Pow(expr, rational)


def _share_products(subs: list[tuple[sp.Symbol, sp.Expr]], reduced: list[sp.Expr]
                    ) -> tuple[list[tuple[sp.Symbol, sp.Expr]], list[sp.Expr]]:
    """``sp.cse``'s result with each product that holds every factor of an earlier
    subexpression's product rewritten to use that subexpression (largest first). SymPy's
    CSE leaves some of these: the biped's torque multiplied out e_x, 1/L, sin(th) and w again
    although e_x/L and w sin(th) were named, four products per evaluation for nothing."""
    products: list[tuple[sp.Symbol, Counter]] = []

    def rewrite(e: sp.Expr) -> sp.Expr:
        if e.is_Atom:
            return e
        args = [rewrite(a) for a in e.args]
        if args != list(e.args):
            e = e.func(*args)
        if not e.is_Mul:
            return e
        factors = Counter(e.args)
        for sym, known in products:  # (sorted largest first)
            if not known.keys() <= factors.keys():
                continue  # (most products: one set operation instead of a count per factor)
            while known != factors and all(factors[f] >= k for f, k in known.items()):
                factors -= known
                factors[sym] += 1
        return sp.Mul(*factors.elements()) if factors != Counter(e.args) else e

    out = []
    for sym, sub in subs:
        sub = rewrite(sub)
        out.append((sym, sub))
        if sub.is_Mul:
            products.append((sym, Counter(sub.args)))
            products.sort(key=lambda item: -sum(item[1].values()))
    return out, [rewrite(r) for r in reduced]


class _Emitter:
    """Lines of one function body with fresh scalar names and structural zeros folded."""

    def __init__(self, names: dict[sp.Symbol, str], indent: str = "    ", *,
                 sincos: bool = False) -> None:
        self.lines: list[str] = []
        self.indent = indent
        self.count = 0
        self.names = names
        self.printer = _Printer({"fully_qualified_modules": True, "names": names})
        self.trig: dict[sp.Expr, tuple[sp.Symbol, sp.Symbol]] = {}
        self.named: dict[str, str] = {}
        self.stems: set[str] = set()  # the names of exprs's subexpressions start so
        self.sincos = sincos

    def line(self, text: str) -> None:
        self.lines.append(self.indent + text)

    def branch(self, offset: int | None = None) -> _Emitter:
        """An emitter for a branch of this body (one level deeper); ``offset`` starts its
        fresh names that far from this one's."""
        br = _Emitter(self.names, self.indent + "    ")
        if offset is not None:
            br.count = self.count + offset
        return br

    def fresh(self, prefix: str) -> str:
        self.count += 1
        return f"_{prefix}{self.count}"  # (a system's symbols: see _symbol_names)

    def expr(self, e: sp.Expr) -> str:
        return self.printer.doprint(e)

    def assign(self, prefix: str, text: str) -> str:
        if _is_zero(text):
            return "0.0"
        if _LITERAL.fullmatch(text) or text.isidentifier():
            return text  # a number or a name needs no new name (and a hoisted one no slot)
        if text not in self.named:  # the same value twice is named once
            self.named[text] = self.fresh(prefix)
            self.line(f"{self.named[text]} = {text}")
        return self.named[text]

    def exprs(self, values: list[sp.Expr], prefix: str) -> list[str]:
        """Assign each expression (common subexpressions once) and return the names, or
        "0.0" for the ones that are zero."""
        if self.sincos:
            values = self._sincos(values)
        stem = f"_s{prefix}{self.count}_"
        while stem in self.stems:  # (a call that named nothing new leaves count as it was)
            stem = stem + "x_"
        self.stems.add(stem)
        subs, reduced = _share_products(*sp.cse(values, symbols=sp.numbered_symbols(stem)))
        for sym, sub in subs:
            self.line(f"{sym} = {self.expr(sub)}")
        return [self.assign(prefix, self.expr(r)) if r != 0 else "0.0" for r in reduced]


    def _sincos(self, values: list[sp.Expr]) -> list[sp.Expr]:
        """``values`` with sin(a) and cos(a) replaced by the names of one ``sincos(a)`` call
        per angle and function body (polynomials for |a| <= pi/4 where libm's sin and cos
        would sit on the evaluation's critical path: see runtime.sincos). Only the vector
        field uses them: elsewhere the ~30 inlined operations would cost more compile time
        than they save at run time, and the guards keep one definition of sin and cos."""
        values = [sp.sympify(v) for v in values]
        found = _atoms(values, (sp.sin, sp.cos))
        if not found:
            return values
        for angle in sorted({f.args[0] for f in found}, key=sp.default_sort_key):
            if angle not in self.trig:
                sin, cos = self.fresh("sin"), self.fresh("cos")
                self.line(f"{sin}, {cos} = _sincos({self.expr(angle)})")
                self.trig[angle] = (sp.Symbol(sin), sp.Symbol(cos))
        swap = {f: self.trig[f.args[0]][0 if isinstance(f, sp.sin) else 1] for f in found}
        return _xreplace(values, swap)


def _atoms(values: list[sp.Basic], types: tuple[type, ...]) -> set[sp.Basic]:
    """The subexpressions of ``values`` of the given types, each distinct subexpression
    visited once (``atoms`` walks shared subexpressions again at every use)."""
    seen: set[sp.Basic] = set()
    found = set()
    stack = list(values)
    while stack:
        e = stack.pop()
        if e in seen:
            continue
        seen.add(e)
        if isinstance(e, types):
            found.add(e)
        stack.extend(e.args)
    return found


def _xreplace(values: list[sp.Basic], swap: dict[sp.Basic, sp.Basic]) -> list[sp.Basic]:
    """``[v.xreplace(swap) for v in values]``, each distinct subexpression rebuilt once."""
    memo: dict[sp.Basic, sp.Basic] = dict(swap)

    def go(e: sp.Basic) -> sp.Basic:
        hit = memo.get(e)
        if hit is None:
            args = [go(a) for a in e.args]
            hit = memo[e] = e.func(*args) if any(
                a is not b for a, b in zip(args, e.args)) else e
        return hit

    return [go(v) for v in values]


_LITERAL = re.compile(r"-?[0-9]+\.[0-9]*(e[-+]?[0-9]+)?")


def _is_zero(text: str) -> bool:
    return text in ("0", "0.0", "-0.0")


def _mul(a: str, b: str) -> str:
    if _is_zero(a) or _is_zero(b):
        return "0.0"
    return b if a == "1.0" else a if b == "1.0" else f"{a} * {b}"  # (1.0 * v is v, exactly)


def _sum(terms: list[str]) -> str:
    terms = [t for t in terms if not _is_zero(t)]
    return " + ".join(terms) if terms else "0.0"


class _Inverse(list):
    """The names of 1 / m_ii of a structurally diagonal matrix: solving is multiplying."""


class _Permuted(list):
    """A Cholesky factor L of P M P^T, the rows and columns of M taken in ``order``."""

    order: list[int]


def _elimination_order(m: list[list[str]]) -> list[int] | None:
    """A fill-reducing order for the factorisation of the matrix named by ``m`` (greedy
    minimum degree on its structural nonzeros: a tree of bodies' M, eliminated leaves first,
    has no fill-in at all), or None when it would not save work over the natural order (the
    work of a column: the square of its nonzeros below the diagonal)."""
    k = len(m)
    links = [{j for j in range(k) if j != i and not _is_zero(m[i][j])} for i in range(k)]

    def work(order: list[int]) -> int:
        graph = [set(s) for s in links]
        done: set[int] = set()
        total = 0
        for v in order:
            rest = graph[v] - done
            total += len(rest) ** 2
            for a in rest:
                graph[a] |= rest - {a}
            done.add(v)
        return total

    graph = [set(s) for s in links]
    left = set(range(k))
    order = []
    while left:
        v = min(left, key=lambda i: (len(graph[i] & left), i))
        near = graph[v] & left
        for a in near:
            graph[a] |= near - {a}
        order.append(v)
        left.remove(v)
    return order if work(order) < work(list(range(k))) else None


def _cholesky(em: _Emitter, m: list[list[str]], tag: str
              ) -> list[list[str]] | _Inverse | _Permuted:
    """Unrolled Cholesky factor L (lower) of the symmetric matrix named by ``m``: entries that
    are structurally zero stay "0.0", and so do those of L that no fill-in reaches; in a
    fill-reducing order when there is one (:func:`_elimination_order`). A diagonal matrix (the
    biped's, the walker's, the bar's mass matrix) gets its inverse instead: one division per
    entry once, then products."""
    k = len(m)
    if all(_is_zero(m[i][j]) for i in range(k) for j in range(k) if i != j):
        return _Inverse(em.assign(f"{tag}v", f"1.0 / {m[i][i]}") for i in range(k))
    order = _elimination_order(m)
    if order is not None:
        factor = _Permuted(_cholesky(em, [[m[i][j] for j in order] for i in order], tag))
        factor.order = order
        return factor
    L = [["0.0"] * k for _ in range(k)]
    for j in range(k):
        diag = _sum([m[j][j], *(f"-({_mul(L[j][r], L[j][r])})" for r in range(j)
                                if not _is_zero(L[j][r]))])
        L[j][j] = em.assign(f"{tag}d", f"math.sqrt({diag})")
        inv = em.assign(f"{tag}i", f"1.0 / {L[j][j]}")
        for i in range(j + 1, k):
            terms = [m[i][j], *(f"-({_mul(L[i][r], L[j][r])})" for r in range(j)
                                if not _is_zero(_mul(L[i][r], L[j][r])))]
            total = _sum(terms)
            L[i][j] = "0.0" if _is_zero(total) else em.assign(f"{tag}l", f"({total}) * {inv}")
    return L


def _solve(em: _Emitter, L: list[list[str]] | _Inverse, b: list[str], tag: str) -> list[str]:
    """x with L L^T x = b (forward then back substitution, zeros skipped)."""
    if isinstance(L, _Inverse):
        return [em.assign(tag, _mul(b[i], L[i])) for i in range(len(L))]
    if isinstance(L, _Permuted):
        inner = _solve(em, list(L), [b[i] for i in L.order], tag)
        x_out = [""] * len(L)
        for i, v in zip(L.order, inner):
            x_out[i] = v
        return x_out
    k = len(L)
    z: list[str] = []
    for i in range(k):
        total = _sum([b[i], *(f"-({_mul(L[i][r], z[r])})" for r in range(i)
                              if not _is_zero(_mul(L[i][r], z[r])))])
        z.append("0.0" if _is_zero(total) else em.assign(tag, f"({total}) / {L[i][i]}"))
    x = [""] * k
    for i in reversed(range(k)):
        total = _sum([z[i], *(f"-({_mul(L[r][i], x[r])})" for r in range(i + 1, k)
                              if not _is_zero(_mul(L[r][i], x[r])))])
        x[i] = "0.0" if _is_zero(total) else em.assign(tag, f"({total}) / {L[i][i]}")
    return x


def _bindings(derived: DerivedSystem, em: _Emitter, *, velocities: bool, inputs: bool) -> dict:
    """Lines that read q (and q', u, p) into scalars named after the symbols."""
    system = derived.system
    d = derived.ndof
    names = em.names
    for i, c in enumerate(system.q):
        em.line(f"{names[c]} = y[yo + {i}]")
    if velocities:
        for i, c in enumerate(system.dq):
            em.line(f"{names[c]} = y[yo + {d + i}]")
    for k, sym in enumerate(system.p):
        em.line(f"{names[sym]} = p[{k}]")
    if inputs:
        for k, sym in enumerate(system.u):
            em.line(f"{names[sym]} = u[{k}]")
    return {}


def _mass_entries(derived: DerivedSystem, em: _Emitter) -> list[str]:
    """M(q)'s entries (row by row) as scalars of the function body: the given matrix's
    expressions, or the bodies' (see :class:`_Tree`)."""
    d = derived.ndof
    if derived.bodies:
        return _Tree(derived, em, motion=False).mass_matrix()
    return em.exprs([derived.mass_matrix[i, j] for i in range(d) for j in range(d)], "m")


Vec = list[str]  # three names (or literals) of a function body


class _Tree:
    """Eq. (1a)'s M and the bodies' forces for a tree of rigid bodies (SYSTEMS.md Sec. 1a), as
    straight-line code that follows the tree: each body's pose, velocity and acceleration from
    its parent's and its joint's (the joint's few expressions, common subexpressions shared),
    then the composite rigid body sums for M and the recursive Newton-Euler sums for the
    velocity products and weights (Featherstone's CRBA and RNEA, in world axes about one
    point P, the root's origin, so that sums over a subtree need no transforms).

    A coordinate q_k moves the bodies b whose pose relative to their parent depends on it (its
    owners: one for a plain joint, more for a mimic joint, whose followers turn with it); its
    unit motion of b is the twist S_kb = (s_kb, u_kb): the angular velocity and the velocity of
    the point of b at P that q_k' = 1 gives b relative to its parent. A body's spatial inertia
    about P is (m, h = m d, J = I_c + m (|d|^2 1 - d d^T)), d from P to its centre, I_c its
    inertia in world axes; the momentum of twist (w, u) is (J w + h x u, m u + w x h). Then
    M_kl = sum over the owners a of k and b of l on one line of the tree of
    S_ka . (inertia of the subtree of the deeper of a, b) S_lb (0 for owners on different
    branches), and the bodies' generalised force is -sum over the owners b of k of
    S_kb . (the wrench about P of m (a_c - g) and I_c alpha + w x I_c w, summed over the
    subtree of b) with the accelerations at q'' = 0."""

    def __init__(self, derived: DerivedSystem, em: _Emitter, *, motion: bool,
                 hoist: _Hoisted | None = None) -> None:
        self.em, self.d = em, derived.ndof
        bodies = derived.bodies
        d = self.d
        const = [e for b in bodies for e in (b.mass, *b.inertia, *b.centre, *b.gravity)]
        names = (hoist.load_all(hoist.pre.exprs(const, "i")) if hoist is not None
                 else em.exprs(const, "i"))
        own = [[k for k in range(d) if any(b.rel_jw[r, k] != 0 or b.rel_jp[r, k] != 0
                                           for r in range(3))] for b in bodies]
        varying = []
        for b, ks in zip(bodies, own):
            varying += [*b.rel_rotation, *b.rel_position]
            varying += [b.rel_jw[r, k] for k in ks for r in range(3)]
            varying += [b.rel_jp[r, k] for k in ks for r in range(3)]
            if motion:
                varying += [*b.rel_aw, *b.rel_ap]
        values = iter(em.exprs(varying, "j"))
        consts = iter(names)
        #: the bodies each coordinate moves (in the order of the bodies), and its twists
        self.owners: list[list[int]] = [[] for _ in range(d)]
        self.s: dict[tuple[int, int], Vec] = {}
        self.u: dict[tuple[int, int], Vec] = {}
        self.parent = [b.parent for b in bodies]
        inertia_of: list[tuple[str, Vec, list[Vec]]] = []  # (m, h, J) about P, per body
        wrench_of: list[tuple[Vec, Vec]] = []
        axes: list[list[Vec]] = []
        origins: list[Vec] = []
        spins: list[Vec] = []
        turns: list[Vec] = []  # angular accelerations at q'' = 0
        accs: list[Vec] = []  # the origins' accelerations at q'' = 0
        zero = ["0.0"] * 3
        names_dq = [em.names[v] for v in derived.system.dq]
        for i, (b, ks) in enumerate(zip(bodies, own)):
            mass = next(consts)
            inertia = [[next(consts) for _ in range(3)] for _ in range(3)]
            centre = [next(consts) for _ in range(3)]
            gravity = [next(consts) for _ in range(3)]
            rel = [[next(values) for _ in range(3)] for _ in range(3)]
            offset = [next(values) for _ in range(3)]
            jw = {k: [next(values) for _ in range(3)] for k in ks}
            jp = {k: [next(values) for _ in range(3)] for k in ks}
            aw, ap = ([next(values) for _ in range(3)], [next(values) for _ in range(3)]) \
                if motion else (zero, zero)
            up = b.parent
            if up < 0:
                R = rel
                r = offset
                o = offset
            else:
                R = self.matmul(axes[up], rel)
                r = self.matvec(axes[up], offset)
                o = self.add(origins[up], r)
            axes.append(R)
            origins.append(o)
            if i == 0:
                self.P = o
            to_p = zero if i == 0 else self.sub(self.P, o)
            for k in ks:
                self.owners[k].append(i)
                s = self.s[k, i] = self.matvec(axes[up], jw[k]) if up >= 0 else jw[k]
                t = self.matvec(axes[up], jp[k]) if up >= 0 else jp[k]
                self.u[k, i] = self.add(t, self.cross(s, to_p))
            # the centre, and the body's inertia in world axes and about P
            arm = self.matvec(R, centre)
            lever = self.sub(self.add(o, arm), self.P)
            rot_inertia = self.congruent(R, inertia)
            h = [em.assign("t", _mul(mass, lever[j])) for j in range(3)]
            square = _sum([_mul(lever[j], lever[j]) for j in range(3)])
            J = [[em.assign("t", _sum([rot_inertia[a][c], _mul(mass, _bracket(_sum(
                [square if a == c else "0.0", _neg(_mul(lever[a], lever[c]))])))]))
                  for c in range(3)] for a in range(3)]
            inertia_of.append((mass, h, J))
            if not motion:
                continue
            w_rel = [em.assign("t", _sum([_mul(jw[k][j], names_dq[k]) for k in ks]))
                     for j in range(3)]
            v_rel = [em.assign("t", _sum([_mul(jp[k][j], names_dq[k]) for k in ks]))
                     for j in range(3)]
            if up < 0:
                w, alpha = w_rel, aw
                a = ap
            else:
                w_world = self.matvec(axes[up], w_rel)
                v_world = self.matvec(axes[up], v_rel)
                w = self.add(spins[up], w_world)
                alpha = self.add(self.add(turns[up], self.cross(spins[up], w_world)),
                                 self.matvec(axes[up], aw))
                a = self.add(accs[up], self.add(
                    self.add(self.cross(turns[up], r),
                             self.cross(spins[up], self.cross(spins[up], r))),
                    self.add(self.scale("2.0", self.cross(spins[up], v_world)),
                             self.matvec(axes[up], ap))))
            spins.append(w)
            turns.append(alpha)
            accs.append(a)
            a_c = self.add(a, self.add(self.cross(alpha, arm),
                                       self.cross(w, self.cross(w, arm))))
            f = [em.assign("t", _mul(mass, _bracket(_sum([a_c[j], _neg(gravity[j])]))))
                 for j in range(3)]
            torque = self.add(self.matvec(rot_inertia, alpha),
                              self.cross(w, self.matvec(rot_inertia, w)))
            wrench_of.append((self.add(torque, self.cross(lever, f)), f))
        self.inertia = self.subtree_sums(inertia_of)
        self.wrench = self.subtree_sums(wrench_of) if motion else []

    # -- 3-vectors and 3 x 3 matrices of names
    def add(self, a: Vec, b: Vec) -> Vec:
        return [self.em.assign("t", _sum([a[j], b[j]])) for j in range(3)]

    def sub(self, a: Vec, b: Vec) -> Vec:
        return [self.em.assign("t", _sum([a[j], _neg(b[j])])) for j in range(3)]

    def scale(self, c: str, a: Vec) -> Vec:
        return [self.em.assign("t", _mul(c, a[j])) for j in range(3)]

    def cross(self, a: Vec, b: Vec) -> Vec:
        return [self.em.assign("t", _sum([_mul(a[(j + 1) % 3], b[(j + 2) % 3]),
                                          _neg(_mul(a[(j + 2) % 3], b[(j + 1) % 3]))]))
                for j in range(3)]

    def matvec(self, m: list[Vec], v: Vec) -> Vec:
        return [self.em.assign("t", _sum([_mul(m[j][t], v[t]) for t in range(3)]))
                for j in range(3)]

    def matmul(self, a: list[Vec], b: list[Vec]) -> list[Vec]:
        return [[self.em.assign("t", _sum([_mul(a[i][t], b[t][j]) for t in range(3)]))
                 for j in range(3)] for i in range(3)]

    def congruent(self, R: list[Vec], inertia: list[Vec]) -> list[Vec]:
        """R I R^T, symmetric (the upper triangle mirrored)."""
        ri = self.matmul(R, inertia)
        out = [["0.0"] * 3 for _ in range(3)]
        for i in range(3):
            for j in range(i, 3):
                out[i][j] = out[j][i] = self.em.assign(
                    "t", _sum([_mul(ri[i][t], R[j][t]) for t in range(3)]))
        return out

    def subtree_sums(self, items: list[Any]) -> list[Any]:
        """Each body's item plus its descendants' (children are declared after parents)."""
        terms = [[item] for item in items]
        for i in reversed(range(len(items))):
            if self.parent[i] >= 0:
                terms[self.parent[i]] += terms[i]

        def total(parts: list[Any]) -> Any:
            if isinstance(parts[0], str):
                return self.em.assign("t", _sum(list(parts)))
            return [total([p[j] for p in parts]) for j in range(len(parts[0]))]

        return [total(t) for t in terms]

    def _ancestors(self, i: int) -> list[int]:
        out = []
        while i >= 0:
            out.append(i)
            i = self.parent[i]
        return out

    def mass_matrix(self) -> list[str]:
        """M by composite rigid bodies: for each coordinate col and each body b it moves, the
        momentum of its twist under the subtree of b, projected on the twists of the
        coordinates that move b or an ancestor of b (a pair moving one body once: the
        upper triangle, mirrored; a coordinate that moves two bodies on one line meets
        itself twice on the diagonal, as (a, b) and (b, a))."""
        d, em = self.d, self.em
        terms: dict[tuple[int, int], list[str]] = {}
        for col in range(d):
            for b in self.owners[col]:
                mass, h, J = self.inertia[b]
                s, u = self.s[col, b], self.u[col, b]
                spin = [em.assign("t", _sum([_mul(J[j][t], s[t]) for t in range(3)]))
                        for j in range(3)]
                L = self.add(spin, self.cross(h, u))
                p = self.add(self.scale(mass, u), self.cross(s, h))
                line = self._ancestors(b)
                for k in range(d):
                    for a in self.owners[k]:
                        if a not in line or (a == b and k > col):
                            continue
                        term = em.assign("m", _sum(
                            [*(_mul(self.s[k, a][j], L[j]) for j in range(3)),
                             *(_mul(self.u[k, a][j], p[j]) for j in range(3))]))
                        key = (min(k, col), max(k, col))
                        terms.setdefault(key, []).append(term)
                        if k == col and a != b:
                            terms[key].append(term)
        m = [["0.0"] * d for _ in range(d)]
        for (k, col), parts in terms.items():
            m[k][col] = m[col][k] = parts[0] if len(parts) == 1 else em.assign("m", _sum(parts))
        return [m[i][j] for i in range(d) for j in range(d)]

    def forces(self) -> list[str]:
        """The bodies' generalised forces (weights and velocity products)."""
        out = []
        for k in range(self.d):
            parts = []
            for b in self.owners[k]:
                n, f = self.wrench[b]
                parts += [*(_mul(self.s[k, b][j], n[j]) for j in range(3)),
                          *(_mul(self.u[k, b][j], f[j]) for j in range(3))]
            out.append(self.em.assign("g", _neg(_sum(parts))) if parts else "0.0")
        return out


def _neg(text: str) -> str:
    return "0.0" if _is_zero(text) else f"-({text})"


def _bracket(text: str) -> str:
    return "0.0" if _is_zero(text) else f"({text})"


def _factors(derived: DerivedSystem, em: _Emitter
             ) -> tuple[list[list[str]], list[list[str]]]:
    """Cholesky factor L of M(q) and the entries of Da(q), as scalars of the function body."""
    d, n = derived.ndof, derived.nconstraints
    m = _mass_entries(derived, em)
    L = _cholesky(em, [[m[i * d + j] for j in range(d)] for i in range(d)], "c")
    da = em.exprs(list(derived.jacobian), "a") if n else []
    return L, [[da[j * d + i] for i in range(d)] for j in range(n)]


def _schur(br: _Emitter, L: list[list[str]], Da: list[list[str]], active: list[int]
           ) -> tuple[list[list[str]], list[list[str]]]:
    """Columns M^-1 Da_j^T of the active constraints and the Cholesky factor of
    Da_J M^-1 Da_J^T."""
    d = len(L)
    cols = _columns(br, L, Da, active)
    S = [[br.assign("s", _sum([_mul(Da[ja][i], cols[b][i]) for i in range(d)]))
          for b in range(len(active))] for ja in active]
    return cols, _cholesky(br, S, "k")


def _mode_factors(em: _Emitter, n: int, masks: set[int]) -> dict[int, str]:
    """0.0/1.0 factors "mode == J" for the modes in ``masks``."""
    out = {}
    for mask in sorted(masks):
        out[mask] = em.assign("o", f"1.0 * (mode == {mask})")
    return out


def _patch(base: sp.Expr, other: sp.Expr) -> tuple[sp.Expr, sp.Expr] | None:
    """(node, extra) when ``other`` is ``base`` with one sum ``node`` of it extended by the
    terms ``extra`` (an input added to a leg's force in the modes it acts in), else None."""
    if base == other:
        return None
    if isinstance(base, sp.Add) and isinstance(other, sp.Add):
        mine, theirs = set(base.args), set(other.args)
        if mine < theirs:
            return base, sp.Add(*(theirs - mine))
    if base.is_Atom or base.func != other.func or len(base.args) != len(other.args):
        raise ValueError
    only_base = [a for a in base.args if a not in other.args]
    only_other = [a for a in other.args if a not in base.args]
    if len(only_base) != 1 or len(only_other) != 1:
        raise ValueError
    return _patch(only_base[0], only_other[0])


def _gated(variants: dict[sp.Expr, list[int]], gates: dict[tuple[int, ...], sp.Symbol]
           ) -> sp.Expr | None:
    """One expression for every variant of a force entry: the variant of the most modes with
    each other variant's extra terms added times its 0/1 mode factor, or None when the variants
    are not of that form. For finite values it is exact per mode (e + 0.0 * t is e), cheaper
    than mixing whole variants, and it is how a hand-written model adds its gated inputs."""
    ordered = sorted(variants.items(), key=lambda kv: -len(kv[1]))
    base = ordered[0][0]
    extra: dict[sp.Expr, sp.Expr] = {}
    try:
        for expr, masks in ordered[1:]:
            found = _patch(base, expr)
            if found is None:
                return None
            node, terms = found
            extra[node] = extra.get(node, sp.S.Zero) + gates[tuple(masks)] * terms
    except ValueError:
        return None
    whole = extra.pop(base, sp.S.Zero)  # terms added to the entry itself (a body torque)
    merged = base.xreplace({node: sp.Add(node, terms) for node, terms in extra.items()})
    merged = sp.Add(merged, whole)
    # each mode's variant comes back exactly; the substitution depends only on the gates the
    # merged entry holds, so each of their 0/1 patterns is substituted once (not once per mode)
    present = [(key, g) for key, g in gates.items() if merged.has(g)]
    back: dict[tuple[bool, ...], sp.Expr] = {}
    for expr, masks in ordered:
        for mask in masks:
            pattern = tuple(mask in key for key, _g in present)
            if pattern not in back:
                back[pattern] = merged.xreplace(
                    {g: sp.S.One if on else sp.S.Zero for (_k, g), on in zip(present, pattern)})
            if back[pattern] != expr:
                return None
    return merged


def _mode_mixed(em: _Emitter, derived: DerivedSystem) -> list[str]:
    """f_J(q, q', u) of the current mode without a branch. Per entry, one expression with the
    extra terms of some modes gated by their 0/1 factors (see :func:`_gated`), or else each
    distinct expression (over the modes) times the 0/1 factor of the modes that have it.
    Exact: 1.0 * e + 0.0 * e' is e for finite values (the inputs are checked finite on
    entry)."""
    d, n = derived.ndof, derived.nconstraints
    variants: list[dict[sp.Expr, list[int]]] = []
    for i in range(d):
        by_expr: dict[sp.Expr, list[int]] = {}
        for mask in range(1 << n):
            by_expr.setdefault(derived.applied[mask][i], []).append(mask)
        variants.append(by_expr)
    needed = {m for by_expr in variants if len(by_expr) > 1 for ms in by_expr.values()
              for m in ms}
    factor = _mode_factors(em, n, needed)
    gates: dict[tuple[int, ...], sp.Symbol] = {}
    for by_expr in variants:
        for masks in by_expr.values():
            key = tuple(masks)
            if len(by_expr) > 1 and key not in gates:
                weight = " + ".join(factor[m] for m in masks)
                gates[key] = sp.Symbol(weight if len(masks) == 1 else em.assign("o", weight))
    entries: list[list[sp.Expr]] = []
    for by_expr in variants:
        merged = _gated(by_expr, gates) if len(by_expr) > 1 else None
        entries.append([merged] if merged is not None else list(by_expr))
    names = em.exprs([e for entry in entries for e in entry], "f")
    out, k = [], 0
    for by_expr, entry in zip(variants, entries):
        if len(entry) == 1:
            out.append(names[k])
            k += 1
            continue
        terms = []
        for masks in by_expr.values():
            g = gates[tuple(masks)]
            terms.append(_mul(names[k], str(g)))
            k += 1
        out.append(em.assign("f", _sum(terms)))
    return out


class _Hoisted:
    """Quantities of the vector field that depend on the parameters alone (a constant mass
    matrix's factor, constant constraint rows, their Schur complement), computed once per
    parameter vector by ``prepare_parameters`` and read from p[NPARAM:] instead of being
    recomputed at every evaluation: ~2% of a simulation, mostly divisions."""

    def __init__(self, derived: DerivedSystem, em: _Emitter) -> None:
        self.em = em
        self.pre = _Emitter(em.names)
        self.pre.count = 10**6  # its names live in the vector field's scope too
        self.offset = len(derived.system.p)
        self.slots: dict[str, int] = {}
        self.params = {derived.system.p[name] for name in derived.system.p.names()}
        #: contiguous blocks after the slots (apply_impact's constant entries), each a list
        #: of names or literals; reserved once the vector field has taken its slots
        self.blocks: list[list[str]] = []

    def constant(self, matrix: sp.Matrix) -> bool:
        return matrix.free_symbols <= self.params

    def load(self, name: str) -> str:
        """``name`` (computed in ``pre``) made available to the vector field."""
        if _is_zero(name) or _LITERAL.fullmatch(name) or name in self.slots:
            return name
        assert not self.blocks, "a slot after a block would move the block"
        self.slots[name] = len(self.slots)
        self.em.line(f"{name} = p[{self.offset + self.slots[name]}]")
        return name

    def load_all(self, names: list[Any]) -> list[Any]:  # nested lists of names
        return [self.load_all(v) if isinstance(v, list) else self.load(v) for v in names]

    def block(self, values: list[str]) -> int:
        """Where ``values`` (names computed in ``pre``, or literals) start in the prepared
        parameter vector, one after another."""
        start = self.offset + len(self.slots) + sum(len(b) for b in self.blocks)
        self.blocks.append(list(values))
        return start

    def function(self, derived: DerivedSystem) -> list[str]:
        out = ["def prepare_parameters(p):",
               '    """The parameter vector the compiled functions take: the values p (in the',
               "    declared order), then the quantities that depend on them alone (computed once",
               '    here, in Python, instead of at every evaluation)."""']
        system = derived.system
        out += [f"    {self.pre.names[sym]} = p[{k}]" for k, sym in enumerate(system.p)]
        return out + self.pre.lines + ["    return np.array([", "        *p,"] + [
            f"        {v}," for v in self.slots] + [
            f"        {v}," for b in self.blocks for v in b] + ["    ], dtype=np.float64)"]


#: the vector field computes sine and cosine by inlined polynomials (runtime.sincos) for at most
#: this many angles, by the library's calls beyond: each inlined pair costs compile time, and a
#: field with many angles (the quadruped's 17: a fifth of its compile) does so much else that
#: the pairs' share of its evaluation is small
SINCOS_ANGLES = 12


def _angles(derived: DerivedSystem) -> set[sp.Expr]:
    """The distinct arguments of sin and cos in what the vector field evaluates."""
    values: list[sp.Basic] = [*derived.jacobian, *derived.jacobian_rate]
    for f in {sp.ImmutableMatrix(f) for f in derived.applied}:
        values += list(f)
    if derived.bodies:
        values += [e for b in derived.bodies for e in (*b.rel_rotation, *b.rel_position)]
    else:
        values += list(derived.mass_matrix)
    return {f.args[0] for f in _atoms([sp.sympify(v) for v in values], (sp.sin, sp.cos))}


def _vector_field(derived: DerivedSystem) -> tuple[list[str], _Hoisted]:
    """Eq. (1a) for the current mode, branch-free: the forces mixed by 0/1 mode factors, and
    the reactions from the Schur complement of *all* constraints with the inactive ones' rows
    and columns replaced by the identity (their reactions come out 0). Without branches Numba
    can drop the reference counting around an inlined call (tests/codegen/test_dop853.py checks
    that none is left). Also returns what it hoisted (:class:`_Hoisted`), whose
    ``prepare_parameters`` is written once the impact map has added its blocks."""
    d, n = derived.ndof, derived.nconstraints
    out = ["@nb.njit(**HOT_PATH, inline=\"always\")",
           "def vector_field(p, mode, y, yo, u, out, off, lam, lo):",
           '    """(q\', q\'\') of mode ``mode`` at y[yo:yo + 2d] to out[off:off + 2d], the',
           '    reactions to lam[lo:lo + n] (0 for inactive constraints), Eq. (1a)."""']
    em = _Emitter(_symbol_names(derived.system), sincos=len(_angles(derived)) <= SINCOS_ANGLES)
    _bindings(derived, em, velocities=True, inputs=True)
    hoist = _Hoisted(derived, em)
    const_m = not derived.bodies and hoist.constant(derived.mass_matrix)
    const_da = n == 0 or hoist.constant(derived.jacobian)
    m_em = hoist.pre if const_m else em
    tree = _Tree(derived, em, motion=True, hoist=hoist) if derived.bodies else None
    m = (tree.mass_matrix() if tree is not None else
         m_em.exprs([derived.mass_matrix[i, j] for i in range(d) for j in range(d)], "m"))
    L = _cholesky(m_em, [[m[i * d + j] for j in range(d)] for i in range(d)], "c")
    if const_m:
        loaded = hoist.load_all(L)
        if isinstance(L, _Permuted):
            permuted = _Permuted(loaded)
            permuted.order = L.order
            L = permuted
        else:
            L = _Inverse(loaded) if isinstance(L, _Inverse) else loaded
    da_em = hoist.pre if const_da else em
    da = da_em.exprs(list(derived.jacobian), "a") if n else []
    Da = [[da[j * d + i] for i in range(d)] for j in range(n)]
    if const_da:
        Da = hoist.load_all(Da)
    rate = em.exprs(list(derived.jacobian_rate), "r") if n else []
    for i in range(d):
        em.line(f"out[off + {i}] = y[yo + {d + i}]")
    f = _mode_mixed(em, derived)
    if tree is not None:
        inertial = tree.forces()
        f = [em.assign("f", _sum([a, b])) for a, b in zip(f, inertial)]
    x = _solve(em, L, f, "x")
    acc = x
    if n:
        on = [em.assign("n", f"float(mode >> {j} & 1)") for j in range(n)]
        off = [em.assign("n", f"1.0 - {on[j]}") for j in range(n)]
        s_em = hoist.pre if const_m and const_da else em
        cols = _columns(s_em, L, Da, list(range(n)))
        S = [[s_em.assign("s", _sum([_mul(Da[a][i], cols[b][i]) for i in range(d)]))
              for b in range(n)] for a in range(n)]
        rhs = [em.assign("b", _mul(on[a], "(-(" + _sum(
            [*(_mul(Da[a][i], x[i]) for i in range(d)), rate[a]]) + "))")) for a in range(n)]
        diagonal = all(_is_zero(S[a][b]) for a in range(n) for b in range(n) if a != b)
        coords = _separable(L, Da) if s_em is hoist.pre else None
        if coords is not None:
            # each constraint pins its own coordinate k_j of a diagonal M (a foot's height,
            # an end's height): lambda_j = -on_j f_kj / a_j and that coordinate's
            # acceleration is off_j f_kj / m_kj, the arithmetic of a hand-written model
            lam = [em.assign("l", _mul(on[j], "(-(" + _mul(f[k], _reciprocal(hoist, Da[j][k]))
                                       + "))")) for j, k in enumerate(coords)]
            acc = list(x)
            for j, k in enumerate(coords):
                acc[k] = em.assign("q", _mul(x[k], off[j]))
        elif s_em is hoist.pre and diagonal:
            # the masked matrix is diagonal with entries on_j S_jj + off_j (on_j in {0, 1}), and
            # rhs_j carries the factor on_j: lambda_j = rhs_j / S_jj, no division per evaluation
            inv = hoist.load_all([hoist.pre.assign("kv", f"1.0 / {S[j][j]}") for j in range(n)])
            cols = hoist.load_all(cols)
            lam = [em.assign("l", _mul(rhs[j], inv[j])) for j in range(n)]
        else:
            if s_em is hoist.pre:
                cols, S = hoist.load_all(cols), hoist.load_all(S)
            masked = [[em.assign("s", _sum([_mul(_mul(on[a], on[b]), S[a][b]),
                                            off[a] if a == b else "0.0"]))
                       for b in range(n)] for a in range(n)]
            lam = _solve(em, _cholesky(em, masked, "k"), rhs, "l")
        if coords is None:
            acc = [em.assign("q", _sum([x[i], *(_mul(cols[j][i], lam[j]) for j in range(n))]))
                   for i in range(d)]
        for j in range(n):
            em.line(f"lam[lo + {j}] = {lam[j]} + 0.0")
    for i in range(d):
        em.line(f"out[off + {d + i}] = {acc[i]}")
    return out + _schedule(em.lines), hoist


_DEFINITION = re.compile(r"    (\w+(?:, \w+)*) = (.*)")


def _schedule(body: list[str]) -> list[str]:
    """Straight-line ``body`` reordered so that each value is computed (or read from y, p, u)
    just before its first use, the stores keeping their order: each output's chain then comes
    as one block, as in hand-written code. With every binding at the top, the vector field
    inlined twelve times into the step kept ~30 more values live than registers, and the
    spills cost ~4% of a step (measured on the biped: 710 stack moves per step against 357)."""
    defined: dict[str, int] = {}
    for k, line in enumerate(body):
        if m := _DEFINITION.fullmatch(line):
            defined.update((name, k) for name in m[1].split(", "))
    done: set[int] = set()
    out: list[str] = []

    def emit(k: int) -> None:
        done.add(k)
        m = _DEFINITION.fullmatch(body[k])
        for word in re.findall(r"[A-Za-z_]\w*", m[2] if m else body[k]):
            if word in defined and defined[word] not in done:
                emit(defined[word])
        out.append(body[k])

    for k, line in enumerate(body):
        if not _DEFINITION.fullmatch(line):
            emit(k)
    return out


def _separable(L: list[list[str]] | _Inverse, Da: list[list[str]]) -> list[int] | None:
    """The coordinates k_j when M is diagonal and each (constant) constraint row j has one
    nonzero entry, in column k_j, all distinct: then the constraints do not couple, and
    lambda_j and q''_kj follow from f_kj alone. Else None."""
    if not isinstance(L, _Inverse):
        return None
    coords = []
    for row in Da:
        nonzero = [i for i, v in enumerate(row) if not _is_zero(v)]
        if len(nonzero) != 1 or nonzero[0] in coords:
            return None
        coords.append(nonzero[0])
    return coords


def _reciprocal(hoist: _Hoisted, a: str) -> str:
    """1 / a for a constraint row's entry a (a literal or a hoisted parameter quantity)."""
    if a == "1.0":
        return "1.0"
    return hoist.load(hoist.pre.assign("kv", f"1.0 / {a}"))


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


def _columns(em: _Emitter, L: list[list[str]], Da: list[list[str]], active: list[int]
             ) -> list[list[str]]:
    """M^-1 Da_j^T for the constraints in ``active``."""
    d = len(L)
    return [_solve(em, L, [Da[j][i] for i in range(d)], "y") for j in active]


#: systems with at least this many constraints get the impact map as one set of expressions
#: (every constraint's column M^-1 Da_j^T, Da M^-1 Da^T, Da q') and a loop that factors the
#: active constraints' block at run time, instead of one unrolled branch per contact mode: the
#: 2^n branches were most of a many-legged walker's compile (25.7 of ~70 s for 8 legs)
IMPACT_LOOP_CONSTRAINTS = 4


def _impact(derived: DerivedSystem, hoist: _Hoisted) -> list[str]:
    d, n = derived.ndof, derived.nconstraints
    out = ["@nb.njit(**HOT_PATH)",
           "def apply_impact(p, mode, y):",
           '    """q\'+ = Delta_J q\'- in place on entering mode J, Eq. (1b)."""',
           "    yo = 0"]
    em = _Emitter(_symbol_names(derived.system))
    _bindings(derived, em, velocities=True, inputs=False)
    gamma = em.assign("g", em.expr(derived.restitution)) if derived.restitution != 0 else "0.0"
    if derived.bodies:
        _impact_tree(derived, em, gamma, hoist)
        return out + em.lines
    L, Da = _factors(derived, em)
    v = [em.names[c] for c in derived.system.dq]
    if n >= IMPACT_LOOP_CONSTRAINTS:
        _impact_loop(em, L, Da, v, gamma)
        return out + em.lines
    out += em.lines
    for mask in range(1, 1 << n):  # the air mode has no impact
        active = [j for j in range(n) if mask >> j & 1]
        out.append(f"    {'if' if mask == 1 else 'elif'} mode == {mask}:")
        br = em.branch(1000 * (mask + 1))
        cols, Ls = _schur(br, L, Da, active)
        normal = [br.assign("v", _sum([_mul(Da[a][i], v[i]) for i in range(d)])) for a in active]
        w = _solve(br, Ls, normal, "w")
        for i in range(d):
            delta = _sum([_mul(cols[b][i], w[b]) for b in range(len(active))])
            if not _is_zero(delta):
                br.line(f"y[{d + i}] = {v[i]} - (1.0 + {gamma}) * ({delta})")
        out += br.lines
    return out


#: apply_impact of a system of bodies after its joints' expressions: the tree's M by composite
#: rigid bodies (the sums of render's _Tree, as loops over the vectors filled before: ``rel``
#: each body's frame in its parent's (12 per body), ``body`` its mass, inertia and centre (13),
#: ``twist`` the relative angular and origin velocity per rate of each (coordinate, body)
#: entry (6), ``da`` Da row by row), its
#: Cholesky factor, the columns M^-1 Da_j^T, and Eq. (1b) for the active constraints
_IMPACT_TREE = """\
R = np.empty((NB, 3, 3))
o = np.empty((NB, 3))
for i in range(NB):
    up = parent[i]
    for a in range(3):
        for c in range(3):
            if up < 0:
                R[i, a, c] = rel[12 * i + 3 * a + c]
            else:
                R[i, a, c] = (R[up, a, 0] * rel[12 * i + c] + R[up, a, 1] * rel[12 * i + 3 + c]
                              + R[up, a, 2] * rel[12 * i + 6 + c])
        if up < 0:
            o[i, a] = rel[12 * i + 9 + a]
        else:
            o[i, a] = (o[up, a] + R[up, a, 0] * rel[12 * i + 9] + R[up, a, 1] * rel[12 * i + 10]
                       + R[up, a, 2] * rel[12 * i + 11])
comp = np.zeros((NB, 13))
lever = np.empty(3)
for i in range(NB):
    m = body[13 * i + 0]
    for a in range(3):
        lever[a] = (o[i, a] + R[i, a, 0] * body[13 * i + 10] + R[i, a, 1] * body[13 * i + 11]
                    + R[i, a, 2] * body[13 * i + 12] - o[0, a])
    sq = lever[0] * lever[0] + lever[1] * lever[1] + lever[2] * lever[2]
    comp[i, 0] = m
    for a in range(3):
        comp[i, 1 + a] = m * lever[a]
        for c in range(3):
            ic = 0.0
            for s in range(3):
                for t in range(3):
                    ic += R[i, a, s] * body[13 * i + 1 + 3 * s + t] * R[i, c, t]
            comp[i, 4 + 3 * a + c] = ic + m * ((sq if a == c else 0.0) - lever[a] * lever[c])
for i in range(NB - 1, 0, -1):
    if parent[i] >= 0:
        for c in range(13):
            comp[parent[i], c] += comp[i, c]
S = np.empty((NE, 6))
for e in range(NE):
    i = ebody[e]
    up = parent[i]
    for a in range(3):
        if up < 0:
            S[e, a] = twist[6 * e + a]
            S[e, 3 + a] = twist[6 * e + 3 + a]
        else:
            S[e, a] = (R[up, a, 0] * twist[6 * e + 0] + R[up, a, 1] * twist[6 * e + 1]
                       + R[up, a, 2] * twist[6 * e + 2])
            S[e, 3 + a] = (R[up, a, 0] * twist[6 * e + 3] + R[up, a, 1] * twist[6 * e + 4]
                           + R[up, a, 2] * twist[6 * e + 5])
    for a in range(3):
        lever[a] = o[0, a] - o[i, a]
    for a in range(3):
        S[e, 3 + a] += (S[e, (a + 1) % 3] * lever[(a + 2) % 3]
                        - S[e, (a + 2) % 3] * lever[(a + 1) % 3])
M = np.zeros((ND, ND))
mom = np.empty(6)
for e in range(NE):
    col = ecoord[e]
    b = ebody[e]
    for a in range(3):
        mom[a] = (comp[b, 4 + 3 * a] * S[e, 0] + comp[b, 5 + 3 * a] * S[e, 1]
                  + comp[b, 6 + 3 * a] * S[e, 2]
                  + comp[b, 1 + (a + 1) % 3] * S[e, 3 + (a + 2) % 3]
                  - comp[b, 1 + (a + 2) % 3] * S[e, 3 + (a + 1) % 3])
        mom[3 + a] = (comp[b, 0] * S[e, 3 + a] + S[e, (a + 1) % 3] * comp[b, 1 + (a + 2) % 3]
                      - S[e, (a + 2) % 3] * comp[b, 1 + (a + 1) % 3])
    for f in range(NE):
        k = ecoord[f]
        a = ebody[f]
        x = b
        while x >= 0 and x != a:
            x = parent[x]
        if x != a or (a == b and k > col):
            continue
        term = 0.0
        for c in range(6):
            term += S[f, c] * mom[c]
        lo = min(k, col)
        hi = max(k, col)
        M[lo, hi] += term
        if k == col and a != b:
            M[lo, hi] += term
for r in range(ND):
    for c in range(r):
        M[r, c] = M[c, r]
for c in range(ND):
    acc = M[c, c]
    for r in range(c):
        acc = acc - M[c, r] * M[c, r]
    M[c, c] = math.sqrt(acc)
    inv = 1.0 / M[c, c]
    for i in range(c + 1, ND):
        acc = M[i, c]
        for r in range(c):
            acc = acc - M[i, r] * M[c, r]
        M[i, c] = acc * inv
cols = np.empty((NC, ND))
for j in range(NC):
    for i in range(ND):
        acc = da[ND * j + i]
        for r in range(i):
            acc = acc - M[i, r] * cols[j, r]
        cols[j, i] = acc / M[i, i]
    for i in range(ND - 1, -1, -1):
        acc = cols[j, i]
        for r in range(i + 1, ND):
            acc = acc - M[r, i] * cols[j, r]
        cols[j, i] = acc / M[i, i]
schur = np.empty((NC, NC))
rates = np.empty(NC)
for j in range(NC):
    rates[j] = 0.0
    for i in range(ND):
        rates[j] += da[ND * j + i] * vel[i]
    for k in range(NC):
        acc = 0.0
        for i in range(ND):
            acc += da[ND * j + i] * cols[k, i]
        schur[j, k] = acc
link = np.ones((NC, NC), np.bool_)
"""


def _impact_tree(derived: DerivedSystem, em: _Emitter, gamma: str, hoist: _Hoisted) -> None:
    """apply_impact of a system of bodies (Eq. (1b)): the joints' expressions, the bodies'
    constants and Da unrolled (common subexpressions shared), then M by composite rigid
    bodies, its factor and the impact as loops (:data:`_IMPACT_TREE`, then the active set's
    Schur complement as :func:`_impact_loop` solves it). The unrolled sums of the vector field
    (render's _Tree) would be compiled again here for an event that happens a few times per
    trajectory: the loops compile in a fraction of the time (the same sums in another order,
    equal to rounding)."""
    d, n = derived.ndof, derived.nconstraints
    bodies = derived.bodies
    own = [[k for k in range(d) if any(b.rel_jw[r, k] != 0 or b.rel_jp[r, k] != 0
                                       for r in range(3))] for b in bodies]
    entries = [(k, i) for i, ks in enumerate(own) for k in ks]
    rel: list[sp.Expr] = []
    for b in bodies:
        rel += [*b.rel_rotation, *b.rel_position]
    twist: list[sp.Expr] = []
    for k, i in entries:
        twist += [bodies[i].rel_jw[r, k] for r in range(3)]
        twist += [bodies[i].rel_jp[r, k] for r in range(3)]
    body = [sp.sympify(e) for b in bodies for e in (b.mass, *b.inertia, *b.centre)]
    arrays = {"rel": rel, "body": body, "twist": twist, "da": list(derived.jacobian)}
    # entries of the parameters alone come from prepare_parameters, one block per array
    # copied in at once; those of q are computed here (common subexpressions shared) and
    # stored one by one: a store costs Numba compile time, and most entries are constants
    # (fixed offsets, a hinge's axis, the masses and inertias)
    varying: list[tuple[str, int, sp.Expr]] = []
    nb, ne = len(bodies), len(entries)
    em.line(f"NB, NE, ND, NC = {nb}, {ne}, {d}, {n}")
    em.line(f"parent = np.array({[b.parent for b in bodies]}, dtype=np.int64)")
    em.line(f"ebody = np.array({[i for _k, i in entries]}, dtype=np.int64)")
    em.line(f"ecoord = np.array({[k for k, _i in entries]}, dtype=np.int64)")
    for name, values in arrays.items():
        fixed = [k for k, e in enumerate(values) if hoist.constant(sp.Matrix([e]))]
        names = hoist.pre.exprs([values[k] for k in fixed], "ib") if fixed else []
        block = ["0.0"] * len(values)
        for k, value in zip(fixed, names):
            block[k] = value
        start = hoist.block(block)
        em.line(f"{name} = p[{start}:{start + len(values)}].copy()")
        varying += [(name, k, e) for k, e in enumerate(values) if k not in set(fixed)]
    computed = em.exprs([e for _n, _k, e in varying], "j") if varying else []
    for (name, k, _e), value in zip(varying, computed):
        if not _is_zero(value):
            em.line(f"{name}[{k}] = {value}")
    em.line("vel = y[ND:2 * ND].copy()")
    for text in _IMPACT_TREE.splitlines():
        em.line(text)
    _impact_active(em, d, n, gamma)


def _impact_loop(em: _Emitter, L: list[list[str]] | _Inverse, Da: list[list[str]],
                 v: list[str], gamma: str) -> None:
    """The impact map for any mode (see :data:`IMPACT_LOOP_CONSTRAINTS`). The loop performs the
    operations of the unrolled branch of the same mode in the same order (the columns, the
    entries of Da M^-1 Da^T, then either, for a block with no structurally nonzero entry off
    its diagonal, products by the reciprocals of its entries, or its Cholesky factor with
    products by the reciprocal of each diagonal and the two substitutions), so both give the
    same values to the bit."""
    d, n = len(v), len(Da)
    cols = _columns(em, L, Da, list(range(n)))
    S = [[em.assign("s", _sum([_mul(Da[j][i], cols[k][i]) for i in range(d)]))
          for k in range(n)] for j in range(n)]
    rates = [em.assign("v", _sum([_mul(Da[j][i], v[i]) for i in range(d)])) for j in range(n)]
    em.line(f"cols = np.empty(({n}, {d}))")
    em.line(f"schur = np.empty(({n}, {n}))")
    em.line(f"rates = np.empty({n})")
    em.line(f"vel = np.empty({d})")
    # which constraints' entries of Da M^-1 Da^T are structurally nonzero off the diagonal:
    # a block without any is inverted entry by entry, as the unrolled branch does
    em.line(f"link = np.zeros(({n}, {n}), np.bool_)")
    for j in range(n):
        for k in range(n):
            if j != k and not _is_zero(S[j][k]):
                em.line(f"link[{j}, {k}] = True")
    for j in range(n):
        for i in range(d):
            em.line(f"cols[{j}, {i}] = {cols[j][i]}")
        for k in range(n):
            em.line(f"schur[{j}, {k}] = {S[j][k]}")
        em.line(f"rates[{j}] = {rates[j]}")
    for i in range(d):
        em.line(f"vel[{i}] = {v[i]}")
    _impact_active(em, d, n, gamma)


def _impact_active(em: _Emitter, d: int, n: int, gamma: str) -> None:
    """Eq. (1b) for the active constraints of ``mode`` from the arrays ``cols`` (M^-1 Da_j^T),
    ``schur`` (Da M^-1 Da^T), ``link`` (its structurally nonzero entries off the diagonal),
    ``rates`` (Da q'-) and ``vel`` (q'-) of the function body."""
    for text in (
        f"act = np.empty({n}, np.int64)",
        "na = 0",
        f"for j in range({n}):",
        "    if mode >> j & 1:",
        "        act[na] = j",
        "        na += 1",
        "fac = np.empty((na, na))",
        "diagonal = True",
        "for a in range(na):",
        "    for b in range(na):",
        "        fac[a, b] = schur[act[a], act[b]]",
        "        diagonal = diagonal and not link[act[a], act[b]]",
        "w = np.empty(na)",
        "if diagonal:",
        "    for i in range(na):",
        "        w[i] = rates[act[i]] * (1.0 / fac[i, i])",
        "for c in range(na if not diagonal else 0):",  # Cholesky: fac = K K^T, lower
        "    acc = fac[c, c]",
        "    for r in range(c):",
        "        acc = acc - fac[c, r] * fac[c, r]",
        "    fac[c, c] = math.sqrt(acc)",
        "    inv = 1.0 / fac[c, c]",
        "    for i in range(c + 1, na):",
        "        acc = fac[i, c]",
        "        for r in range(c):",
        "            acc = acc - fac[i, r] * fac[c, r]",
        "        fac[i, c] = acc * inv",
        "for i in range(na if not diagonal else 0):",  # K z = rates_J
        "    acc = rates[act[i]]",
        "    for r in range(i):",
        "        acc = acc - fac[i, r] * w[r]",
        "    w[i] = acc / fac[i, i]",
        "for i in range(na - 1 if not diagonal else -1, -1, -1):",  # K^T w = z
        "    acc = w[i]",
        "    for r in range(i + 1, na):",
        "        acc = acc - fac[r, i] * w[r]",
        "    w[i] = acc / fac[i, i]",
        f"for i in range({d}):",
        "    delta = 0.0",
        "    for b in range(na):",
        "        delta = delta + cols[act[b], i] * w[b]",
        f"    y[{d} + i] = vel[i] - (1.0 + {gamma}) * delta",
    ):
        em.line(text)


def _scalar_function(name: str, doc: str, args: str, derived: DerivedSystem,
                     exprs: list[sp.Expr], target: str, *, inputs: bool) -> list[str]:
    out = ["@nb.njit(**HOT_PATH)", f"def {name}({args}):", f'    """{doc}"""']
    em = _Emitter(_symbol_names(derived.system))
    _bindings(derived, em, velocities=True, inputs=inputs)
    values = em.exprs(exprs, "e") if exprs else []
    for k, v in enumerate(values):
        em.line(f"{target}[{k}] = {v}")
    return out + em.lines


def _per_maneuver(name: str, doc: str, args: str, derived: DerivedSystem,
                  pick: Callable[[DerivedManeuver], sp.Expr], *, inputs: bool) -> list[str]:
    out = ["@nb.njit(**HOT_PATH)", f"def {name}({args}):", f'    """{doc}"""']
    em = _Emitter(_symbol_names(derived.system))
    _bindings(derived, em, velocities=True, inputs=inputs)
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
    em = _Emitter(_symbol_names(system))
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
    em = _Emitter(_symbol_names(derived.system))
    _bindings(derived, em, velocities=False, inputs=False)
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
    em = _Emitter(_symbol_names(derived.system))
    _bindings(derived, em, velocities=True, inputs=True)
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


_ASSIGNMENT = re.compile(r"\s+(\w+) = [^=]+")


def _prune(lines: list[str]) -> list[str]:
    """``lines`` without the assignments to names that their function never reads (bindings
    of symbols it does not use, ``x = y[yo + 0]``, and values no output needs): Numba types
    every statement of every inlined copy, so unread ones cost compile time (the stage probes,
    inlined eleven times, read three of the biped's 26 symbols). Every such assignment is a
    pure expression of the generated code, so dropping it changes nothing else."""
    starts = [k for k, line in enumerate(lines) if line.startswith("def ")] + [len(lines)]
    out = lines[: starts[0]]
    for a, b in zip(starts, starts[1:]):
        body = lines[a:b]
        while True:
            # (a name on no line but its own assignment's: counted once over the body)
            seen = Counter(w for line in body for w in set(re.findall(r"\w+", line)))
            unread = {k for k, line in enumerate(body) if (m := _ASSIGNMENT.fullmatch(line))
                      and seen[m[1]] == 1}
            if not unread:
                break
            body = [line for k, line in enumerate(body) if k not in unread]
        out += body
    return out


_WORD = re.compile(r"[A-Za-z_]\w*")


def _literal_node(value: float) -> ast.expr:
    """``value`` as a syntax node; a negative one as a negation, which ``ast.unparse``
    brackets where needed ((-2.0) ** 2, where a negative constant would print as -2.0 ** 2)."""
    if value < 0 or (value == 0 and math.copysign(1.0, value) < 0):
        return ast.UnaryOp(ast.USub(), ast.Constant(-value))
    return ast.Constant(value)


def _end_line(node: ast.expr | ast.stmt) -> int:
    """The last line of ``node`` (1-based), which ``ast.parse`` always records."""
    return cast(int, node.end_lineno)


def _segment(lines: list[str], node: ast.expr) -> str:
    """The source text of ``node`` (``lines``: its module's, ASCII)."""
    first, last = node.lineno - 1, _end_line(node) - 1
    if first == last:
        return lines[first][node.col_offset:node.end_col_offset]
    return "\n".join([lines[first][node.col_offset:], *lines[first + 1:last],
                      lines[last][:node.end_col_offset]])


def _statement_text(lines: list[str], stmt: ast.stmt) -> str:
    """The lines of ``stmt``, which must be alone on them, without its indentation."""
    rest = lines[_end_line(stmt) - 1][stmt.end_col_offset:].strip()
    if lines[stmt.lineno - 1][:stmt.col_offset].strip() or (rest and rest[0] != "#"):
        raise ValueError(f"line {stmt.lineno}: a statement to copy must be alone on its lines")
    out = []
    for line in lines[stmt.lineno - 1:stmt.end_lineno]:
        blank = len(line) - len(line.lstrip())
        out.append(line[min(blank, stmt.col_offset):])
    return "\n".join(out)


class _Template:
    """One statement's (or expression's) text with slots for the names a copy renames:
    ``pieces`` of text between the ``slots`` (the original names). A slot is a whole name
    token that is a variable (not an attribute after a dot; not in a comment or string), so
    filling it with another name, or a non-negative number, changes nothing else."""

    def __init__(self, text: str, names: frozenset[str]) -> None:
        starts = [0]
        for line in text.split("\n"):
            starts.append(starts[-1] + len(line) + 1)
        self.pieces: list[str] = []
        self.slots: list[str] = []
        at, previous = 0, None
        for tok in tokenize.generate_tokens(io.StringIO(text).readline):
            if tok.type == tokenize.NAME and tok.string in names and previous != ".":
                begin = starts[tok.start[0] - 1] + tok.start[1]
                self.pieces.append(text[at:begin])
                self.slots.append(tok.string)
                at = begin + len(tok.string)
            if tok.type not in (tokenize.NL, tokenize.NEWLINE, tokenize.COMMENT):
                previous = tok.string
        self.pieces.append(text[at:])

    def fill(self, values: dict[str, str]) -> str:
        out = [self.pieces[0]]
        for name, piece in zip(self.slots, self.pieces[1:]):
            out += (values[name], piece)
        return "".join(out)


@dataclass(frozen=True)
class _Statement:
    template: _Template
    stored: frozenset[str]  # the names it assigns
    single: str | None  # its target when it is a top-level ``name = value``
    reads: frozenset[str]  # the names its value reads (when ``single``)


@dataclass(frozen=True)
class _Inlinable:
    """A function :func:`_expand` can inline: statements (branches allowed) and at most one
    ``return``, its last statement; no nested scopes or keyword arguments."""

    params: tuple[str, ...]
    body: tuple[_Statement, ...]
    returns: _Template | None
    returned: tuple[str | None, ...]  # the returned names (None: not a name)
    rebound: frozenset[str]  # parameters the body assigns
    once: frozenset[str]  # names assigned exactly once, at the top level (may be hoisted)
    free: frozenset[str]  # names it reads and never assigns, parameters aside (globals)
    words: frozenset[str]  # every word of its source

    @classmethod
    def parse(cls, name: str, source: str) -> _Inlinable:
        fn = next(n for n in ast.parse(source).body if isinstance(n, ast.FunctionDef))
        lines = source.split("\n")
        args = fn.args
        if args.posonlyargs or args.vararg or args.kwonlyargs or args.kwarg or args.defaults:
            raise ValueError(f"{name}: only plain positional parameters can be inlined")
        body = list(fn.body)
        if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
            body = body[1:]  # the docstring
        returns = (cast(ast.Return, body.pop()).value
                   if body and isinstance(body[-1], ast.Return) else None)
        unsupported = (ast.Return, ast.FunctionDef, ast.Lambda, ast.Global, ast.Nonlocal,
                       ast.ListComp, ast.SetComp, ast.DictComp, ast.GeneratorExp, ast.Yield,
                       ast.Break, ast.Continue, ast.keyword, ast.NamedExpr, ast.JoinedStr)
        nodes = [n for stmt in body for n in ast.walk(stmt)]
        for node in nodes:
            if isinstance(node, unsupported):
                raise ValueError(f"{name}: a {type(node).__name__} cannot be inlined (one "
                                 "return, as the last statement, no nested scopes)")
        params = tuple(a.arg for a in args.args)
        stored = Counter(n.id for n in nodes
                         if isinstance(n, ast.Name) and not isinstance(n.ctx, ast.Load))
        read = {n.id for n in nodes if isinstance(n, ast.Name)}
        if returns is not None:
            read |= {n.id for n in ast.walk(returns) if isinstance(n, ast.Name)}
        renamed = frozenset(stored) | frozenset(params)
        statements = []
        for stmt in body:
            single = (stmt.targets[0].id if isinstance(stmt, ast.Assign)
                      and len(stmt.targets) == 1 and isinstance(stmt.targets[0], ast.Name)
                      else None)
            statements.append(_Statement(
                template=_Template(_statement_text(lines, stmt), renamed),
                stored=frozenset(n.id for n in ast.walk(stmt) if isinstance(n, ast.Name)
                                 and not isinstance(n.ctx, ast.Load)),
                single=single,
                reads=frozenset(n.id for n in ast.walk(stmt.value) if isinstance(n, ast.Name))
                if single and isinstance(stmt, ast.Assign) else frozenset()))
        top = Counter(s.single for s in statements if s.single)
        items = returns.elts if isinstance(returns, ast.Tuple) else [returns]
        returned = tuple(e.id if isinstance(e, ast.Name) else None for e in items)
        return cls(params=params, body=tuple(statements), returned=returned,
                   returns=None if returns is None
                   else _Template(_segment(lines, returns), renamed),
                   rebound=frozenset(stored) & set(params),
                   once=frozenset(v for v, k in top.items() if k == stored[v] == 1),
                   free=frozenset(read - set(stored) - set(params)),
                   words=frozenset(_WORD.findall(source)))


class _Expander:
    """The state of one :func:`_expand` pass (see there)."""

    def __init__(self, functions: dict[str, str], invariant: set[str], tag: str) -> None:
        self.functions = {name: _Inlinable.parse(name, src) for name, src in functions.items()}
        self.order = list(functions)
        self.invariant = invariant
        self.tag = tag
        self.taken: set[str] = set().union(*(f.words for f in self.functions.values()))
        self.copies = 0
        self.lines: list[str] = []

    def fresh(self, base: str) -> str:
        """``base``, or ``base_k`` for the first k that makes it a word used nowhere yet."""
        name, k = base, 0
        while name in self.taken:
            k += 1
            name = f"{base}_{k}"
        self.taken.add(name)
        return name

    def run(self, text: str) -> str:
        tree = ast.parse(text)
        self.taken |= set(_WORD.findall(text))  # (a superset of the names: words of comments)
        lines = self.lines = text.split("\n")
        edits: list[tuple[int, int, list[str]]] = []
        for fn in tree.body:
            if isinstance(fn, ast.FunctionDef):
                scope = {"assigned": _assigned(fn.body) | {a.arg for a in fn.args.args},
                         "hoisted": {}, "first": {}}
                self.block(fn.body, scope, True, lines, edits)
        for first, last, new in sorted(edits, reverse=True):
            lines[first - 1:last] = new
        return "\n".join(lines)

    def block(self, stmts: list[ast.stmt], scope: dict, top: bool, lines: list[str],
              edits: list[tuple[int, int, list[str]]]) -> None:
        for stmt in stmts:
            call, target = None, None
            if isinstance(stmt, ast.Expr):
                call = stmt.value
            elif isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 and (
                    isinstance(stmt.targets[0], ast.Name) or (
                        isinstance(stmt.targets[0], ast.Tuple)
                        and all(isinstance(t, ast.Name) for t in stmt.targets[0].elts))):
                call, target = stmt.value, stmt.targets[0]
            if (isinstance(call, ast.Call) and isinstance(call.func, ast.Name)
                    and call.func.id in self.functions):
                if (lines[stmt.lineno - 1][:stmt.col_offset].strip()
                        or lines[_end_line(stmt) - 1][stmt.end_col_offset:].strip()):
                    raise ValueError(f"line {stmt.lineno}: a call to inline must be a "
                                     "statement of its own lines")
                indent = " " * stmt.col_offset
                new = self.inline(call, target, scope, top)
                edits.append((stmt.lineno, _end_line(stmt),
                              [indent + line for s in new for line in s.split("\n")]))
                continue
            for field in ("body", "orelse", "finalbody"):
                inner = getattr(stmt, field, None)
                if isinstance(inner, list) and not isinstance(stmt, ast.FunctionDef):
                    self.block(inner, scope, False, lines, edits)
            for handler in getattr(stmt, "handlers", ()):
                self.block(handler.body, scope, False, lines, edits)

    def inline(self, call: ast.Call, target: ast.expr | None, scope: dict, top: bool
               ) -> list[str]:
        name = cast(ast.Name, call.func).id  # block() inlines only calls of a name
        fn = self.functions[name]
        if call.keywords or len(call.args) != len(fn.params) or any(
                isinstance(a, ast.Starred) for a in call.args):
            raise ValueError(f"{name}: the call at line {call.lineno} does not match "
                             f"({', '.join(fn.params)})")
        shadowed = fn.free & scope["assigned"]
        if shadowed:
            raise ValueError(f"{name}: the caller assigns {', '.join(sorted(shadowed))}, "
                             f"which {name} reads as a global")
        if target is not None and fn.returns is None:
            raise ValueError(f"{name}: returns nothing to assign")
        self.copies += 1
        out: list[str] = []
        values: dict[str, str] = {}
        # block() passes a name or a tuple of names
        targets = ([cast(ast.Name, t).id for t in target.elts] if isinstance(target, ast.Tuple)
                   else [cast(ast.Name, target).id] if target is not None else [])
        names = [a.id for a in call.args if isinstance(a, ast.Name)]
        for param, arg in zip(fn.params, call.args):
            if isinstance(arg, ast.Name) and param not in fn.rebound:
                values[param] = arg.id  # a name stands for itself
            elif (isinstance(arg, ast.Name) and names.count(arg.id) == 1
                  and targets.count(arg.id) == 1 and fn.returned.count(param) == 1
                  and len(targets) == len(fn.returned)
                  and fn.returned[targets.index(arg.id)] == param):
                # a parameter the body assigns and returns into the very variable passed for
                # it (c0 = probe(..., c0)): that variable can be the parameter throughout
                values[param] = arg.id
            elif (isinstance(arg, ast.Constant) and type(arg.value) in (int, float)
                  and 0 <= cast(float, arg.value) < math.inf and param not in fn.rebound):
                values[param] = repr(arg.value)  # so does a number (a negative one is bound)
            else:  # evaluated once, before the body, as a call would
                values[param] = self.fresh(f"{param}_{self.tag}{self.copies}")
                text = _segment(self.lines, arg)
                atom = isinstance(arg, (ast.Name, ast.Constant))
                out.append(f"{values[param]} = {text if atom else f'({text})'}")
        invariant = {param for param, arg in zip(fn.params, call.args)
                     if param not in fn.rebound and isinstance(arg, ast.Name)
                     and arg.id in self.invariant}
        first = name not in scope["hoisted"]
        hoisted: dict[str, str] = scope["hoisted"].setdefault(name, {})
        if first:
            scope["first"][name] = {p: values[p] for p in invariant}
        elif hoisted and any(p not in invariant or values[p] != ident
                             for p, ident in scope["first"][name].items()):
            raise ValueError(f"{name}: the call at line {call.lineno} passes other values "
                             "for the parameters its hoisted statements read")
        values.update(hoisted)
        for stmt in fn.body:
            if stmt.single in hoisted:
                continue  # computed where the first copy stands
            if (first and top and stmt.single in fn.once
                    and all(v in hoisted or v in invariant or v in fn.free
                            for v in stmt.reads)):
                hoisted[stmt.single] = values[stmt.single] = self.fresh(
                    f"{stmt.single}_h{self.tag}{self.order.index(name)}")
            for v in sorted(stmt.stored - values.keys()):
                values[v] = self.fresh(f"{v}_{self.tag}{self.copies}")
            out.append(_fold_offsets(stmt.template.fill(values)))
        if target is not None and fn.returns is not None:  # (no returns with a target raised)
            value = _fold_offsets(fn.returns.fill(values))
            if value.replace("(", "").replace(")", "") != _segment(self.lines, target):
                out.append(f"{_segment(self.lines, target)} = {value}")
        return out


def _assigned(stmts: list[ast.stmt]) -> set[str]:
    """The names ``stmts`` assign (at any depth), without walking their expressions."""
    out: set[str] = set()
    for stmt in stmts:
        targets = {ast.Assign: lambda s: s.targets, ast.AugAssign: lambda s: [s.target],
                   ast.AnnAssign: lambda s: [s.target], ast.For: lambda s: [s.target],
                   ast.With: lambda s: [i.optional_vars for i in s.items if i.optional_vars]}
        for kind, get in targets.items():
            if isinstance(stmt, kind):
                out |= {n.id for t in get(stmt) for n in ast.walk(t) if isinstance(n, ast.Name)}
        if isinstance(stmt, (ast.FunctionDef, ast.ClassDef)):
            out.add(stmt.name)
            continue
        for field in ("body", "orelse", "finalbody"):
            inner = getattr(stmt, field, None)
            if isinstance(inner, list):
                out |= _assigned(inner)
        for handler in getattr(stmt, "handlers", ()):
            out |= _assigned(handler.body)
    return out


_OFFSET = re.compile(r"\[(\d+) \+ (\d+)\]")


def _fold_offsets(text: str) -> str:
    """``W[128 + 3]`` as ``W[131]`` (a subscript that is a sum of two integer literals)."""
    return _OFFSET.sub(lambda m: f"[{int(m[1]) + int(m[2])}]", text)


def _expand(text: str, functions: dict[str, str], invariant: set[str], tag: str = "") -> str:
    """``text`` with each statement that calls one of ``functions`` (name -> source), alone or
    assigned to names (``a, b = f(x)``), replaced by the function's body. Exact by
    construction, whatever the arguments: the body is read as a syntax tree and written back
    (``ast.unparse``) with its parameters and locals as slots, and only names or non-negative
    numbers fill a slot; any other argument (``th + a``, ``-1.0``, ``W[3] * h``) is first
    bound to a new name, once, as a call evaluates it. Every name the body assigns gets a name
    of its own per copy (``x`` of the third copy is ``x_<tag>3``, with a further suffix when
    the text or a body already has that word: a copy can neither read nor overwrite a name of
    the caller or of another copy); a body's globals must not be assigned by the caller. The
    returned value is assigned to the call's targets; a literal offset ``y[yo + 3]`` with
    ``yo = 128`` becomes ``W[131]``. A top-level assignment that depends only on ``invariant``
    names (arguments that do not change through the text: p, u, the mode), globals and
    earlier such values is computed once, where the first copy of its function stands
    (``x_h<tag><k>``). Only the calls' lines change; the rest of ``text`` stays as it is.

    The step calls the vector field and the stage probe twelve times each. Numba's own
    inlining of them (inline="always") took a quarter of the module's compile time; the
    expanded text compiles to the same arithmetic, and the parameters, inputs and mode
    factors are read once per step instead of once per stage."""
    return _Expander(functions, invariant, tag).run(text)


def _sincos_source() -> str:
    """The source of :func:`biped_opt.codegen.runtime.sincos` (what ``_sincos`` is in a generated
    module) with its module's float constants written as literals, for :func:`_expand`."""
    from biped_opt.codegen import runtime as model

    class Literals(ast.NodeTransformer):
        def visit_Name(self, node: ast.Name) -> ast.expr:
            value = getattr(model, node.id, None)
            return _literal_node(value) if type(value) is float else node

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
        field_lines = _prune(vector_field)
        inline_field = len(field_lines) <= INLINE_FIELD_LINES
        impact = _impact(derived, hoist)
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
    text = "\n\n\n".join("\n".join(_prune(part)) for part in parts) + "\n"
    step = dop853.render(n=2 * d, imports="",
                         rhs="vector_field" if inline_field else "_field_at",
                         probe="probe_stage", nlam=max(n, 1), registers=True, nguards=n + 1,
                         probe_head="p, mode, u, term_sign", dense_rhs="_field_at",
                         loop=len(field_lines) > LOOP_STEP_LINES)
    step = step[step.index("\nSTRIDE = ") + 1:]
    # the vector field with its sines and cosines expanded (one pass over its text): expanded
    # further into the step's stages, or the body of the called field
    field_text = _expand("\n".join(field_lines), {"_sincos": _sincos_source()},
                         invariant=set(), tag="s")
    expanded = {"vector_field": field_text} if inline_field else {}
    expanded["probe_stage"] = "\n".join(_prune(probe))
    step = _expand(step, expanded, invariant={"p", "u", "mode", "term_sign"})
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
