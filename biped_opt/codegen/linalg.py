"""Symbolic linear algebra written out as straight-line code: M(q)'s factor and the solves.

Eq. (1a) needs M^-1 applied to forces and the Schur complement Da_J M^-1 Da_J^T of the active
constraints. Both are emitted as unrolled code on named scalars (:mod:`biped_opt.codegen.emit`):

- :func:`cholesky` factors a symmetric matrix whose entries are known as text, skipping the
  entries that are structurally zero, in a fill-reducing elimination order
  (:func:`_elimination_order`, minimum degree) when reordering saves work; a structurally
  diagonal matrix becomes its reciprocals (:class:`Inverse`: d divisions);
- :func:`solve` the two triangular solves with that factor, :func:`solved_columns` M^-1 Da^T
  column by column, :func:`schur_complement` the active constraints' contact matrix;
- :func:`separable` recognises constraint rows that touch disjoint coordinates of a diagonal
  M, whose contact matrix is diagonal too.
"""

from __future__ import annotations

from biped_opt.codegen.emit import Emitter, is_zero, summed, times

__all__ = ["Inverse", "Permuted", "cholesky", "solve", "schur_complement", "separable",
           "solved_columns"]


class Inverse(list):
    """The names of 1 / m_ii of a structurally diagonal matrix: solving is multiplying."""


class Permuted(list):
    """A Cholesky factor L of P M P^T, the rows and columns of M taken in ``order``."""

    order: list[int]


def _elimination_order(m: list[list[str]]) -> list[int] | None:
    """A fill-reducing order for the factorisation of the matrix named by ``m`` (greedy
    minimum degree on its structural nonzeros: a tree of bodies' M, eliminated leaves first,
    has no fill-in at all), or None when it would not save work over the natural order (the
    work of a column: the square of its nonzeros below the diagonal)."""
    k = len(m)
    links = [{j for j in range(k) if j != i and not is_zero(m[i][j])} for i in range(k)]

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


def cholesky(em: Emitter, m: list[list[str]], tag: str
              ) -> list[list[str]] | Inverse | Permuted:
    """Unrolled Cholesky factor L (lower) of the symmetric matrix named by ``m``: entries that
    are structurally zero stay "0.0", and so do those of L that no fill-in reaches; in a
    fill-reducing order when there is one (:func:`_elimination_order`). A diagonal matrix (the
    biped's, the walker's, the bar's mass matrix) gets its inverse instead: one division per
    entry once, then products."""
    k = len(m)
    if all(is_zero(m[i][j]) for i in range(k) for j in range(k) if i != j):
        return Inverse(em.assign(f"{tag}v", f"1.0 / {m[i][i]}") for i in range(k))
    order = _elimination_order(m)
    if order is not None:
        factor = Permuted(cholesky(em, [[m[i][j] for j in order] for i in order], tag))
        factor.order = order
        return factor
    L = [["0.0"] * k for _ in range(k)]
    for j in range(k):
        diag = summed([m[j][j], *(f"-({times(L[j][r], L[j][r])})" for r in range(j)
                                if not is_zero(L[j][r]))])
        L[j][j] = em.assign(f"{tag}d", f"math.sqrt({diag})")
        inv = em.assign(f"{tag}i", f"1.0 / {L[j][j]}")
        for i in range(j + 1, k):
            terms = [m[i][j], *(f"-({times(L[i][r], L[j][r])})" for r in range(j)
                                if not is_zero(times(L[i][r], L[j][r])))]
            total = summed(terms)
            L[i][j] = "0.0" if is_zero(total) else em.assign(f"{tag}l", f"({total}) * {inv}")
    return L


def solve(em: Emitter, L: list[list[str]] | Inverse, b: list[str], tag: str) -> list[str]:
    """x with L L^T x = b (forward then back substitution, zeros skipped)."""
    if isinstance(L, Inverse):
        return [em.assign(tag, times(b[i], L[i])) for i in range(len(L))]
    if isinstance(L, Permuted):
        inner = solve(em, list(L), [b[i] for i in L.order], tag)
        x_out = [""] * len(L)
        for i, v in zip(L.order, inner):
            x_out[i] = v
        return x_out
    k = len(L)
    z: list[str] = []
    for i in range(k):
        total = summed([b[i], *(f"-({times(L[i][r], z[r])})" for r in range(i)
                              if not is_zero(times(L[i][r], z[r])))])
        z.append("0.0" if is_zero(total) else em.assign(tag, f"({total}) / {L[i][i]}"))
    x = [""] * k
    for i in reversed(range(k)):
        total = summed([z[i], *(f"-({times(L[r][i], x[r])})" for r in range(i + 1, k)
                              if not is_zero(times(L[r][i], x[r])))])
        x[i] = "0.0" if is_zero(total) else em.assign(tag, f"({total}) / {L[i][i]}")
    return x


def schur_complement(br: Emitter, L: list[list[str]], Da: list[list[str]], active: list[int]
           ) -> tuple[list[list[str]], list[list[str]]]:
    """Columns M^-1 Da_j^T of the active constraints and the Cholesky factor of
    Da_J M^-1 Da_J^T."""
    d = len(L)
    cols = solved_columns(br, L, Da, active)
    S = [[br.assign("s", summed([times(Da[ja][i], cols[b][i]) for i in range(d)]))
          for b in range(len(active))] for ja in active]
    return cols, cholesky(br, S, "k")


def separable(L: list[list[str]] | Inverse, Da: list[list[str]]) -> list[int] | None:
    """The coordinates k_j when M is diagonal and each (constant) constraint row j has one
    nonzero entry, in column k_j, all distinct: then the constraints do not couple, and
    lambda_j and q''_kj follow from f_kj alone. Else None."""
    if not isinstance(L, Inverse):
        return None
    coords = []
    for row in Da:
        nonzero = [i for i, v in enumerate(row) if not is_zero(v)]
        if len(nonzero) != 1 or nonzero[0] in coords:
            return None
        coords.append(nonzero[0])
    return coords


def solved_columns(em: Emitter, L: list[list[str]], Da: list[list[str]], active: list[int]
             ) -> list[list[str]]:
    """M^-1 Da_j^T for the constraints in ``active``."""
    d = len(L)
    return [solve(em, L, [Da[j][i] for i in range(d)], "y") for j in active]
