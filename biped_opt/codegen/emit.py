"""Printing SymPy expressions as Python and emitting them as straight-line code.

The first layer of the code generator (:mod:`biped_opt.codegen.render` assembles the module):

- :class:`Printer` prints an expression from SymPy's tree (a power or a quotient of a sum keeps
  its brackets), a system's symbols as ``q__<name>``, ``v__<name>``, ``p__<name>``,
  ``u__<name>``, ``s__<name>`` (:func:`symbol_names`): the generator's own names never contain
  a double underscore, so a description may name its symbols anything;
- :class:`Emitter` collects the lines of one function body, with fresh scalar names, common
  subexpressions shared and structural zeros folded;
- :func:`times`, :func:`summed`, :func:`negated`, :func:`bracketed` build the text of a
  product, a sum, a negation, a bracketed term, folding the literal zeros and ones exactly
  (``1.0 * v`` is ``v``), which is what lets the linear algebra above skip known zeros.
"""

from __future__ import annotations

import math
import re
from collections import Counter

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from biped_opt.systems.derive import DerivedSystem
from biped_opt.systems.description import System, SystemDescriptionError

__all__ = ["UnsupportedExpressionError", "symbol_names", "Printer", "Emitter", "atoms_of",
           "LITERAL", "is_zero", "times", "summed", "bind_symbols", "negated", "bracketed"]


class UnsupportedExpressionError(SystemDescriptionError):
    """An expression of a description has no compiled form (a function generated code
    cannot call); the message names the system and the function."""


def symbol_names(system: System) -> dict[sp.Symbol, str]:
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


class Printer(PythonCodePrinter):
    """``math.*`` calls and float literals, the form Numba compiles best; a system's symbols
    by their names in generated code (setting ``names``, see :func:`symbol_names`)."""

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


class Emitter:
    """Lines of one function body with fresh scalar names and structural zeros folded."""

    def __init__(self, names: dict[sp.Symbol, str], indent: str = "    ", *,
                 sincos: bool = False) -> None:
        self.lines: list[str] = []
        self.indent = indent
        self.count = 0
        self.names = names
        self.printer = Printer({"fully_qualified_modules": True, "names": names})
        self.trig: dict[sp.Expr, tuple[sp.Symbol, sp.Symbol]] = {}
        self.named: dict[str, str] = {}
        self.stems: set[str] = set()  # the names of exprs's subexpressions start so
        self.sincos = sincos

    def line(self, text: str) -> None:
        self.lines.append(self.indent + text)

    def branch(self, offset: int | None = None) -> Emitter:
        """An emitter for a branch of this body (one level deeper); ``offset`` starts its
        fresh names that far from this one's."""
        br = Emitter(self.names, self.indent + "    ")
        if offset is not None:
            br.count = self.count + offset
        return br

    def fresh(self, prefix: str) -> str:
        self.count += 1
        return f"_{prefix}{self.count}"  # (a system's symbols: see symbol_names)

    def expr(self, e: sp.Expr) -> str:
        return self.printer.doprint(e)

    def assign(self, prefix: str, text: str) -> str:
        if is_zero(text):
            return "0.0"
        if LITERAL.fullmatch(text) or text.isidentifier():
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
        found = atoms_of(values, (sp.sin, sp.cos))
        if not found:
            return values
        for angle in sorted({f.args[0] for f in found}, key=sp.default_sort_key):
            if angle not in self.trig:
                sin, cos = self.fresh("sin"), self.fresh("cos")
                self.line(f"{sin}, {cos} = _sincos({self.expr(angle)})")
                self.trig[angle] = (sp.Symbol(sin), sp.Symbol(cos))
        swap = {f: self.trig[f.args[0]][0 if isinstance(f, sp.sin) else 1] for f in found}
        return _xreplace(values, swap)


def atoms_of(values: list[sp.Basic], types: tuple[type, ...]) -> set[sp.Basic]:
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


LITERAL = re.compile(r"-?[0-9]+\.[0-9]*(e[-+]?[0-9]+)?")


def is_zero(text: str) -> bool:
    return text in ("0", "0.0", "-0.0")


def times(a: str, b: str) -> str:
    if is_zero(a) or is_zero(b):
        return "0.0"
    return b if a == "1.0" else a if b == "1.0" else f"{a} * {b}"  # (1.0 * v is v, exactly)


def summed(terms: list[str]) -> str:
    terms = [t for t in terms if not is_zero(t)]
    return " + ".join(terms) if terms else "0.0"


def bind_symbols(derived: DerivedSystem, em: Emitter, *, velocities: bool, inputs: bool) -> dict:
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


def negated(text: str) -> str:
    return "0.0" if is_zero(text) else f"-({text})"


def bracketed(text: str) -> str:
    return "0.0" if is_zero(text) else f"({text})"
