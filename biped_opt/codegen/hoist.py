"""What the vector field shares across modes and across evaluations.

- Mode mixing (:func:`mode_mixed`): the forces f_J of the modes are written once, each term
  that differs between modes gated by a 0/1 mode factor, so the vector field has no branches
  on the mode (:func:`_gated`, :func:`_patch`);
- hoisting (:class:`Hoisted`): what depends on the parameters alone (a constant M's factor,
  constant constraint rows, their Schur complement) is computed once per parameter vector by
  ``prepare_parameters`` and read from p[NPARAM:];
- the sines and cosines of the angles a field uses (:func:`sincos_angles`, at most
  :data:`SINCOS_ANGLES` of them computed together) and the order of a body's assignments
  (:func:`schedule`: each value defined just before its first use, which keeps fewer values
  live in the inlined step).
"""

from __future__ import annotations

import re
from typing import Any

import sympy as sp

from biped_opt.codegen.emit import LITERAL, Emitter, atoms_of, is_zero, summed, times
from biped_opt.systems.derive import DerivedSystem

__all__ = ["mode_mixed", "Hoisted", "SINCOS_ANGLES", "sincos_angles", "schedule", "reciprocal_of"]


def _mode_factors(em: Emitter, n: int, masks: set[int]) -> dict[int, str]:
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


def mode_mixed(em: Emitter, derived: DerivedSystem) -> list[str]:
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
            terms.append(times(names[k], str(g)))
            k += 1
        out.append(em.assign("f", summed(terms)))
    return out


class Hoisted:
    """Quantities of the vector field that depend on the parameters alone (a constant mass
    matrix's factor, constant constraint rows, their Schur complement), computed once per
    parameter vector by ``prepare_parameters`` and read from p[NPARAM:] instead of being
    recomputed at every evaluation: ~2% of a simulation, mostly divisions."""

    def __init__(self, derived: DerivedSystem, em: Emitter) -> None:
        self.em = em
        self.pre = Emitter(em.names)
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
        if is_zero(name) or LITERAL.fullmatch(name) or name in self.slots:
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


def sincos_angles(derived: DerivedSystem) -> set[sp.Expr]:
    """The distinct arguments of sin and cos in what the vector field evaluates."""
    values: list[sp.Basic] = [*derived.jacobian, *derived.jacobian_rate]
    for f in {sp.ImmutableMatrix(f) for f in derived.applied}:
        values += list(f)
    if derived.bodies:
        values += [e for b in derived.bodies for e in (*b.rel_rotation, *b.rel_position)]
    else:
        values += list(derived.mass_matrix)
    return {f.args[0] for f in atoms_of([sp.sympify(v) for v in values], (sp.sin, sp.cos))}


_DEFINITION = re.compile(r"    (\w+(?:, \w+)*) = (.*)")


def schedule(body: list[str]) -> list[str]:
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


def reciprocal_of(hoist: Hoisted, a: str) -> str:
    """1 / a for a constraint row's entry a (a literal or a hoisted parameter quantity)."""
    if a == "1.0":
        return "1.0"
    return hoist.load(hoist.pre.assign("kv", f"1.0 / {a}"))
