"""The body tree's M(q) and forces: CRBA and RNEA as straight-line code (SYSTEMS.md Sec. 1a).

A system declared as a tree of rigid bodies gets its mass matrix and its bodies' generalised
forces from :class:`BodyTree` (Featherstone's composite rigid body and recursive Newton-Euler
algorithms, written out on the tree's joints) instead of from the expanded Lagrangian;
:func:`mass_factor` factors that M (:mod:`biped_opt.codegen.linalg`).
"""

from __future__ import annotations

from typing import Any

from biped_opt.codegen.emit import Emitter, bracketed, negated, summed, times
from biped_opt.codegen.hoist import Hoisted
from biped_opt.codegen.linalg import cholesky
from biped_opt.systems.derive import DerivedSystem

__all__ = ["BodyTree", "mass_factor", "Vec"]


def _mass_entries(derived: DerivedSystem, em: Emitter) -> list[str]:
    """M(q)'s entries (row by row) as scalars of the function body: the given matrix's
    expressions, or the bodies' (see :class:`BodyTree`)."""
    d = derived.ndof
    if derived.bodies:
        return BodyTree(derived, em, motion=False).mass_matrix()
    return em.exprs([derived.mass_matrix[i, j] for i in range(d) for j in range(d)], "m")


Vec = list[str]  # three names (or literals) of a function body


class BodyTree:
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

    def __init__(self, derived: DerivedSystem, em: Emitter, *, motion: bool,
                 hoist: Hoisted | None = None) -> None:
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
            h = [em.assign("t", times(mass, lever[j])) for j in range(3)]
            square = summed([times(lever[j], lever[j]) for j in range(3)])
            J = [[em.assign("t", summed([rot_inertia[a][c], times(mass, bracketed(summed(
                [square if a == c else "0.0", negated(times(lever[a], lever[c]))])))]))
                  for c in range(3)] for a in range(3)]
            inertia_of.append((mass, h, J))
            if not motion:
                continue
            w_rel = [em.assign("t", summed([times(jw[k][j], names_dq[k]) for k in ks]))
                     for j in range(3)]
            v_rel = [em.assign("t", summed([times(jp[k][j], names_dq[k]) for k in ks]))
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
            f = [em.assign("t", times(mass, bracketed(summed([a_c[j], negated(gravity[j])]))))
                 for j in range(3)]
            torque = self.add(self.matvec(rot_inertia, alpha),
                              self.cross(w, self.matvec(rot_inertia, w)))
            wrench_of.append((self.add(torque, self.cross(lever, f)), f))
        self.inertia = self.subtree_sums(inertia_of)
        self.wrench = self.subtree_sums(wrench_of) if motion else []

    # -- 3-vectors and 3 x 3 matrices of names
    def add(self, a: Vec, b: Vec) -> Vec:
        return [self.em.assign("t", summed([a[j], b[j]])) for j in range(3)]

    def sub(self, a: Vec, b: Vec) -> Vec:
        return [self.em.assign("t", summed([a[j], negated(b[j])])) for j in range(3)]

    def scale(self, c: str, a: Vec) -> Vec:
        return [self.em.assign("t", times(c, a[j])) for j in range(3)]

    def cross(self, a: Vec, b: Vec) -> Vec:
        return [self.em.assign("t", summed([times(a[(j + 1) % 3], b[(j + 2) % 3]),
                                          negated(times(a[(j + 2) % 3], b[(j + 1) % 3]))]))
                for j in range(3)]

    def matvec(self, m: list[Vec], v: Vec) -> Vec:
        return [self.em.assign("t", summed([times(m[j][t], v[t]) for t in range(3)]))
                for j in range(3)]

    def matmul(self, a: list[Vec], b: list[Vec]) -> list[Vec]:
        return [[self.em.assign("t", summed([times(a[i][t], b[t][j]) for t in range(3)]))
                 for j in range(3)] for i in range(3)]

    def congruent(self, R: list[Vec], inertia: list[Vec]) -> list[Vec]:
        """R I R^T, symmetric (the upper triangle mirrored)."""
        ri = self.matmul(R, inertia)
        out = [["0.0"] * 3 for _ in range(3)]
        for i in range(3):
            for j in range(i, 3):
                out[i][j] = out[j][i] = self.em.assign(
                    "t", summed([times(ri[i][t], R[j][t]) for t in range(3)]))
        return out

    def subtree_sums(self, items: list[Any]) -> list[Any]:
        """Each body's item plus its descendants' (children are declared after parents)."""
        terms = [[item] for item in items]
        for i in reversed(range(len(items))):
            if self.parent[i] >= 0:
                terms[self.parent[i]] += terms[i]

        def total(parts: list[Any]) -> Any:
            if isinstance(parts[0], str):
                return self.em.assign("t", summed(list(parts)))
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
                spin = [em.assign("t", summed([times(J[j][t], s[t]) for t in range(3)]))
                        for j in range(3)]
                L = self.add(spin, self.cross(h, u))
                p = self.add(self.scale(mass, u), self.cross(s, h))
                line = self._ancestors(b)
                for k in range(d):
                    for a in self.owners[k]:
                        if a not in line or (a == b and k > col):
                            continue
                        term = em.assign("m", summed(
                            [*(times(self.s[k, a][j], L[j]) for j in range(3)),
                             *(times(self.u[k, a][j], p[j]) for j in range(3))]))
                        key = (min(k, col), max(k, col))
                        terms.setdefault(key, []).append(term)
                        if k == col and a != b:
                            terms[key].append(term)
        m = [["0.0"] * d for _ in range(d)]
        for (k, col), parts in terms.items():
            m[k][col] = m[col][k] = parts[0] if len(parts) == 1 else em.assign("m", summed(parts))
        return [m[i][j] for i in range(d) for j in range(d)]

    def forces(self) -> list[str]:
        """The bodies' generalised forces (weights and velocity products)."""
        out = []
        for k in range(self.d):
            parts = []
            for b in self.owners[k]:
                n, f = self.wrench[b]
                parts += [*(times(self.s[k, b][j], n[j]) for j in range(3)),
                          *(times(self.u[k, b][j], f[j]) for j in range(3))]
            out.append(self.em.assign("g", negated(summed(parts))) if parts else "0.0")
        return out


def mass_factor(derived: DerivedSystem, em: Emitter
             ) -> tuple[list[list[str]], list[list[str]]]:
    """Cholesky factor L of M(q) and the entries of Da(q), as scalars of the function body."""
    d, n = derived.ndof, derived.nconstraints
    m = _mass_entries(derived, em)
    L = cholesky(em, [[m[i * d + j] for j in range(d)] for i in range(d)], "c")
    da = em.exprs(list(derived.jacobian), "a") if n else []
    return L, [[da[j * d + i] for i in range(d)] for j in range(n)]
