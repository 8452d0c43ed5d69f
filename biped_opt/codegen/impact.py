"""The impact map q'+ = Delta_J q'- as generated code, Eq. (1b).

:func:`impact_map` writes ``apply_impact(p, mode, y)``: one unrolled branch per contact mode
for a system with few constraints, and for more than :data:`IMPACT_LOOP_CONSTRAINTS` of them
one loop over the active constraints (:func:`_impact_loop`, :func:`_impact_active`), whose
contact matrix is formed and solved at run time; a body tree's impact builds its M from the
tree at run time (:data:`_IMPACT_TREE`), so that the tree's long straight-line code is not
compiled a second time for an event that happens a few times per run.
"""

from __future__ import annotations

import sympy as sp

from biped_opt.codegen.emit import Emitter, bind_symbols, is_zero, summed, symbol_names, times
from biped_opt.codegen.hoist import Hoisted
from biped_opt.codegen.linalg import Inverse, schur_complement, solve, solved_columns
from biped_opt.codegen.tree import mass_factor
from biped_opt.systems.derive import DerivedSystem

__all__ = ["impact_map", "IMPACT_LOOP_CONSTRAINTS"]


#: systems with at least this many constraints get the impact map as one set of expressions
#: (every constraint's column M^-1 Da_j^T, Da M^-1 Da^T, Da q') and a loop that factors the
#: active constraints' block at run time, instead of one unrolled branch per contact mode: the
#: 2^n branches were most of a many-legged walker's compile (25.7 of ~70 s for 8 legs)
IMPACT_LOOP_CONSTRAINTS = 4


def impact_map(derived: DerivedSystem, hoist: Hoisted) -> list[str]:
    d, n = derived.ndof, derived.nconstraints
    out = ["@nb.njit(**HOT_PATH)",
           "def apply_impact(p, mode, y):",
           '    """q\'+ = Delta_J q\'- in place on entering mode J, Eq. (1b)."""',
           "    yo = 0"]
    em = Emitter(symbol_names(derived.system))
    bind_symbols(derived, em, velocities=True, inputs=False)
    gamma = em.assign("g", em.expr(derived.restitution)) if derived.restitution != 0 else "0.0"
    if derived.bodies:
        _impact_tree(derived, em, gamma, hoist)
        return out + em.lines
    L, Da = mass_factor(derived, em)
    v = [em.names[c] for c in derived.system.dq]
    if n >= IMPACT_LOOP_CONSTRAINTS:
        _impact_loop(em, L, Da, v, gamma)
        return out + em.lines
    out += em.lines
    for mask in range(1, 1 << n):  # the air mode has no impact
        active = [j for j in range(n) if mask >> j & 1]
        out.append(f"    {'if' if mask == 1 else 'elif'} mode == {mask}:")
        br = em.branch(1000 * (mask + 1))
        cols, Ls = schur_complement(br, L, Da, active)
        normal = [br.assign("v", summed([times(Da[a][i], v[i]) for i in range(d)])) for a in active]
        w = solve(br, Ls, normal, "w")
        for i in range(d):
            delta = summed([times(cols[b][i], w[b]) for b in range(len(active))])
            if not is_zero(delta):
                br.line(f"y[{d + i}] = {v[i]} - (1.0 + {gamma}) * ({delta})")
        out += br.lines
    return out


#: apply_impact of a system of bodies after its joints' expressions: the tree's M by composite
#: rigid bodies (the sums of tree.BodyTree, as loops over the vectors filled before: ``rel``
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


def _impact_tree(derived: DerivedSystem, em: Emitter, gamma: str, hoist: Hoisted) -> None:
    """apply_impact of a system of bodies (Eq. (1b)): the joints' expressions, the bodies'
    constants and Da unrolled (common subexpressions shared), then M by composite rigid
    bodies, its factor and the impact as loops (:data:`_IMPACT_TREE`, then the active set's
    Schur complement as :func:`_impact_loop` solves it). The unrolled sums of the vector field
    (tree.BodyTree) would be compiled again here for an event that happens a few times per
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
        if not is_zero(value):
            em.line(f"{name}[{k}] = {value}")
    em.line("vel = y[ND:2 * ND].copy()")
    for text in _IMPACT_TREE.splitlines():
        em.line(text)
    _impact_active(em, d, n, gamma)


def _impact_loop(em: Emitter, L: list[list[str]] | Inverse, Da: list[list[str]],
                 v: list[str], gamma: str) -> None:
    """The impact map for any mode (see :data:`IMPACT_LOOP_CONSTRAINTS`). The loop performs the
    operations of the unrolled branch of the same mode in the same order (the columns, the
    entries of Da M^-1 Da^T, then either, for a block with no structurally nonzero entry off
    its diagonal, products by the reciprocals of its entries, or its Cholesky factor with
    products by the reciprocal of each diagonal and the two substitutions), so both give the
    same values to the bit."""
    d, n = len(v), len(Da)
    cols = solved_columns(em, L, Da, list(range(n)))
    S = [[em.assign("s", summed([times(Da[j][i], cols[k][i]) for i in range(d)]))
          for k in range(n)] for j in range(n)]
    rates = [em.assign("v", summed([times(Da[j][i], v[i]) for i in range(d)])) for j in range(n)]
    em.line(f"cols = np.empty(({n}, {d}))")
    em.line(f"schur = np.empty(({n}, {n}))")
    em.line(f"rates = np.empty({n})")
    em.line(f"vel = np.empty({d})")
    # which constraints' entries of Da M^-1 Da^T are structurally nonzero off the diagonal:
    # a block without any is inverted entry by entry, as the unrolled branch does
    em.line(f"link = np.zeros(({n}, {n}), np.bool_)")
    for j in range(n):
        for k in range(n):
            if j != k and not is_zero(S[j][k]):
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


def _impact_active(em: Emitter, d: int, n: int, gamma: str) -> None:
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
