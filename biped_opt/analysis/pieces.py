"""The count of smooth pieces near simultaneous contact (paper Sec. V-B), measured.

The paper argues that near (near-)simultaneous (de)activation of n constraints over k rounds the
outcome of a maneuver is carved into up to (n!)^k smooth pieces, one per choice of the order of
the events in every round. This module counts them on the n-leg walker's foot-offset variant
(SYSTEMS.md Sec. 3, :func:`biped_opt.systems.library.walker.walker` with ``offsets=True``):
the level body falls from z = 1 with foot i raised by s d_i. At s = 0 all feet touch down at
once, the (passive, u_body = 0) walker stays level, and it bounces: every foot lifts off at the
same instant, then touches down again at the same instant; those are the rounds. Near s = 0 each
round splits into n events whose order depends on the offsets. Here k counts rounds; the
paper's k counts periods of a periodic gait, and a period of this hopping (a touchdown and a
liftoff) is two rounds.

- :func:`count_pieces` samples the neighbourhood {s d : |d| = 1} of the simultaneous point
  (s = ``radius``, d uniform on the unit sphere of R^n, seeded) and labels each sample by its
  contact-mode sequence up to a time between round k and round k + 1 (the variant's ``rounds``
  maneuver, which ends when its clock reaches ``horizon``). Each distinct label is a piece. Each
  piece's boundary is then confirmed by bisection (:func:`biped_opt.piecewise.locate_switch`)
  on the arc from one of its samples to the nearest sample of another piece: at the located
  switch two events must coincide (on one side their time gap falls below ``TIE_TIME``, or the
  simulator merges them into one simultaneous event: a foot that the coupling keeps down after
  the other lifts off makes the later event's time jump, so the gap need not shrink on both
  sides). A sampled count is a lower bound: a piece no sample hit is missed. With
  ``max_samples`` the sample set is doubled (the same seeded stream continued) until a doubling
  adds no piece or ``max_samples`` is reached; ``growth`` lists the count after every doubling
  (and of the first quarter and half of the initial samples), ``stable`` whether the last
  doubling added none. When the last m samples found nothing new, a piece still missed covers
  less than 3 / m of the directions with 95 % confidence (the rule of three), so a stable count
  is complete up to pieces of that size.
- :func:`derivative_pieces` computes, at the simultaneous point, the Bouligand derivative of the
  ``offsets`` maneuver's outcome (the body's pitch at its nadir after touchdown) along the
  offsets, d -> D(d) = lim (o(s d) - o(0)) / s as s -> 0+. It is positively homogeneous and
  linear on each cone of offsets with one touchdown order: one linear piece g_order . d per
  order. The cone of an order is {d : A d in that order}, A the map from offsets to first-order
  touchdown time shifts (a raised foot's compressed leg moves every foot through the body, so A
  is full; it is measured by simulation). Each g is fitted from n exact derivatives inside its
  cone (:func:`biped_opt.control.derivatives.outcome_gradient`) and checked against finite
  differences (:func:`biped_opt.piecewise.one_sided`) along another direction inside it. Only
  the first two feet to land matter to first order (the first one's input acts alone until the
  second lands, then none does, and the feet's impacts do not couple): at most n (n - 1)
  distinct pieces.

Why the counts fall short of (n!)^k: the offsets are n numbers, and raising every foot by the
same amount only delays the whole motion, so the pieces are cones in an (n - 1)-dimensional
space of directions: raising every foot by the same amount keeps the motion symmetric, so every
round stays simultaneous. The order of round 1 is the order of the d_i (all n! orders appear);
the order of each later round is decided, to first order, by linear forms of the same n - 1
numbers, so it adds pieces only where those forms cut the cones of round 1 again. For n = 2
there is one number, d2 - d1, and at most two pieces for every k. ``velocities=True`` perturbs
the feet's initial velocities too (2n numbers), which gives the later rounds room of their own.
"""

from __future__ import annotations

import itertools
import math
import threading
from collections import Counter
from dataclasses import dataclass, field
from typing import cast

import numpy as np
import numpy.typing as npt

from biped_opt.control.derivatives import outcome_gradient
from biped_opt.control.solve import branch_of
from biped_opt.errors import InvalidInputError, SimulationError
from biped_opt.piecewise import locate_switch, one_sided
from biped_opt.simulation.compiled import CompiledSystem
from biped_opt.simulation.options import DEFAULT_OPTIONS, SimulatorOptions

__all__ = ["Round", "PieceCount", "LinearPiece", "offsets_walker", "simultaneous_rounds",
           "count_pieces", "derivative_pieces", "leg_inputs", "MAX_LEGS"]

Array = npt.NDArray[np.float64]

MAX_LEGS = 4
#: the legs' inputs run geometrically from LEG_INPUTS[0] to LEG_INPUTS[1] (n = 2: the paper's
#: touchdown inputs (2, 0.5); n = 3: SYSTEMS.md's (2, 1, 0.5)); each acts while its foot alone
#: is down (the paper's coupled law). Unequal inputs: with equal ones and symmetric hips the two
#: orders of n = 2 give the same first-order torque and the derivative has one piece. No body
#: torque, so that the unperturbed walker stays level and every round is simultaneous.
LEG_INPUTS = (2.0, 0.5)
#: two events of a confirmed boundary are this close in time on one side of it, or merged into
#: one (the bisection brackets the switch to ~1e-10 in the offsets, so their gap there is
#: ~1e-10 s times a slope of order 1; elsewhere the gaps are of the order of the radius, 1e-3)
TIE_TIME = 1e-7
#: bracket width of the boundary bisections, on the arc parameter in [0, 1]
BISECT_TOL = 1e-10
#: simulator options of the counts: room for every event of a few rounds
OPTIONS = SimulatorOptions(max_events=80, t_end=100.0)
_LOCK = threading.Lock()
_SYSTEMS: dict[int, CompiledSystem] = {}


@dataclass(frozen=True)
class Round:
    """One simultaneous round of the unperturbed walker: its time and what all feet do."""

    t: float
    kind: str  # "touchdown" or "liftoff"


@dataclass(frozen=True, kw_only=True)
class PieceCount:
    """The pieces found around the simultaneous point for n legs and k rounds."""

    n: int
    k: int
    radius: float
    samples: int
    seed: int
    velocities: bool  #: the neighbourhood also perturbs the feet's velocities
    horizon: float
    rounds: tuple[Round, ...]
    #: label (mode sequence up to ``horizon``) -> number of samples on that piece
    pieces: dict[str, int]
    #: label -> the arc bisection confirmed a boundary of that piece at a tie of two events
    confirmed: dict[str, bool]
    #: label -> the smallest time gap between two events at its located boundary
    tie_gap: dict[str, float] = field(repr=False)
    #: (samples, distinct labels among the first that many) after each doubling
    growth: tuple[tuple[int, int], ...] = ()
    #: the last doubling of the samples added no piece
    stable: bool = False

    @property
    def count(self) -> int:
        return len(self.pieces)

    @property
    def bound(self) -> int:
        """The paper's (n!)^k."""
        return math.factorial(self.n) ** self.k

    def as_dict(self) -> dict:
        return {"n": self.n, "k": self.k, "count": self.count, "bound": self.bound,
                "confirmed": sum(self.confirmed.values()), "samples": self.samples,
                "growth": [list(g) for g in self.growth], "stable": self.stable,
                "radius": self.radius, "seed": self.seed, "velocities": self.velocities,
                "horizon": self.horizon,
                "rounds": [[r.t, r.kind] for r in self.rounds],
                "pieces": [{"sequence": k, "samples": v, "confirmed": self.confirmed[k],
                            "tie_gap": self.tie_gap[k]} for k, v in self.pieces.items()]}


@dataclass(frozen=True, kw_only=True)
class LinearPiece:
    """The linear piece g . d of the Bouligand derivative on one touchdown order's cone."""

    order: tuple[int, ...]  #: feet (1-based) in the order they touch down
    gradient: Array  #: g over (d1..dn)
    check_direction: Array  #: a further direction inside the cone
    exact: float  #: the exact directional derivative there
    linear: float  #: g . direction
    finite_difference: float  #: extrapolated one-sided difference quotient there
    fd_error: float  #: the extrapolation's own error estimate

    def as_dict(self) -> dict:
        return {"order": list(self.order), "gradient": self.gradient.tolist(),
                "direction": self.check_direction.tolist(), "exact": self.exact,
                "linear": self.linear, "finite_difference": self.finite_difference,
                "fd_error": self.fd_error}


def _check_n(n: int) -> int:
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_LEGS:
        raise InvalidInputError(f"pieces: n must be an integer in 1..{MAX_LEGS}, got {n!r}")
    return n


def offsets_walker(n: int) -> CompiledSystem:
    """The compiled foot-offset variant of the coupled n-leg walker (one per process and n)."""
    _check_n(n)
    with _LOCK:
        found = _SYSTEMS.get(n)
    if found is None:
        # (by its library name: a later process starts it from the cache's index, SymPy-free)
        found = CompiledSystem(f"walker{n}_coupled_offsets")
        with _LOCK:
            _SYSTEMS[n] = found
    return found


def leg_inputs(n: int) -> list[float]:
    """The legs' inputs (see LEG_INPUTS) and u_body = 0."""
    a, b = LEG_INPUTS
    return [a if n == 1 else a * (b / a) ** (i / (n - 1)) for i in range(n)] + [0.0]


def _set_offsets(compiled: CompiledSystem, d: npt.ArrayLike, horizon: float | None = None
                 ) -> None:
    """Heights d1..dn, and the velocities v1..vn when ``d`` has 2n entries (else 0)."""
    d = np.asarray(d, dtype=float)
    n = (len(compiled.inputs) - 1)
    full = np.zeros(2 * n)
    full[: d.size] = d
    values = {f"{c}{i + 1}": float(full[j * n + i]) for j, c in enumerate("dv")
              for i in range(n)}
    values["horizon"] = compiled.parameters["horizon"] if horizon is None else horizon
    compiled.set_parameters(**values)


def simultaneous_rounds(n: int, *, t_end: float = 12.0) -> tuple[Round, ...]:
    """The rounds of the unperturbed walker (s = 0) up to ``t_end``: each is a contact event in
    which every foot touches down or every foot lifts off."""
    compiled = offsets_walker(n)
    _set_offsets(compiled, np.zeros(n), t_end)
    tr = compiled.simulate("rounds", 0.0, leg_inputs(n), options=OPTIONS)
    every = (1 << n) - 1
    rounds = []
    # a failed run (a landing foot that the stretched leg pulls up: INCONSISTENT) keeps the
    # rounds before the failing event only
    events = tr.contact_events if tr.success else tr.contact_events[:-1]
    for e in events:
        if e.mask_entered == every:
            rounds.append(Round(e.t, "touchdown"))
        elif e.mask_left == every:
            rounds.append(Round(e.t, "liftoff"))
        else:
            break  # not a round of all feet: the rounds end here
    return tuple(rounds)


def _horizon(rounds: tuple[Round, ...], k: int, n: int) -> float:
    """A time between round k and round k + 1 (or after round k by half the last gap)."""
    if k > len(rounds):
        raise InvalidInputError(
            f"pieces: the {n}-leg walker has {len(rounds)} simultaneous rounds "
            f"({', '.join(r.kind for r in rounds)}), so k must be at most {len(rounds)}, "
            f"got {k}")
    t_k = rounds[k - 1].t
    if k < len(rounds):
        return 0.5 * (t_k + rounds[k].t)
    gap = t_k - rounds[k - 2].t if k >= 2 else t_k
    return t_k + 0.5 * gap


def _events(compiled: CompiledSystem, d: Array, radius: float, inputs: list[float]
            ) -> tuple[str, float]:
    """(label, tie gap) of the sample s d: the tie gap is the smallest time between two contact
    events, 0 when one event flips several constraints at once (the kernel merges events that
    are simultaneous to its tolerance)."""
    _set_offsets(compiled, d)
    tr = compiled.simulate("rounds", radius, inputs, options=OPTIONS)
    label = branch_of(compiled, tr.initial_mode, tr.event_rows[: tr.n_events], tr.status)
    if any(e.simultaneous for e in tr.contact_events):
        return label, 0.0
    times = tr.event_times
    return label, float(np.min(np.diff(times))) if len(times) > 1 else math.inf


def _unit_sphere(rng: np.random.Generator, count: int, n: int) -> Array:
    d = rng.standard_normal((count, n))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _closest_pair(directions: Array, mine: list[int], others: list[int]) -> tuple[int, int]:
    """(i, j), i in ``mine`` and j in ``others``, with the largest d_i . d_j (the first such)."""
    best, pair = -math.inf, (mine[0], others[0])
    rest = directions[others]
    for start in range(0, len(mine), 256):  # in blocks: thousands by thousands of dot products
        block = mine[start:start + 256]
        dots = directions[block] @ rest.T
        flat = int(np.argmax(dots))
        if dots.flat[flat] > best:
            best = float(dots.flat[flat])
            pair = (block[flat // len(others)], others[flat % len(others)])
    return pair


def count_pieces(n: int, k: int, *, samples: int = 400, radius: float = 1e-3, seed: int = 0,
                 velocities: bool = False, rounds: tuple[Round, ...] | None = None,
                 max_samples: int | None = None) -> PieceCount:
    """Pieces of the first k rounds for n legs (see the module docstring); ``velocities``:
    the neighbourhood perturbs the feet's initial velocities too (2n dimensions);
    ``max_samples``: double ``samples`` until a doubling adds no piece, up to this many."""
    _check_n(n)
    if isinstance(k, bool) or not isinstance(k, int) or k < 1:
        raise InvalidInputError(f"pieces: k must be an integer >= 1, got {k!r}")
    if not (isinstance(samples, int) and samples >= 2):
        raise InvalidInputError(f"pieces: samples must be an integer >= 2, got {samples!r}")
    if max_samples is not None and not (isinstance(max_samples, int)
                                        and not isinstance(max_samples, bool)
                                        and max_samples >= samples):
        raise InvalidInputError(f"pieces: max_samples must be an integer >= samples "
                                f"({samples}), got {max_samples!r}")
    if not (math.isfinite(radius) and 0 < radius <= 0.01):
        raise InvalidInputError(f"pieces: radius must be in (0, 0.01], got {radius!r}")
    rounds = rounds if rounds is not None else simultaneous_rounds(n)
    horizon = _horizon(rounds, k, n)
    compiled = offsets_walker(n)
    _set_offsets(compiled, np.zeros(n), horizon)
    inputs = leg_inputs(n)
    rng = np.random.default_rng(seed)
    dim = 2 * n if velocities else n
    directions = _unit_sphere(rng, samples, dim)
    labels = [_events(compiled, d, radius, inputs)[0] for d in directions]
    growth = [(m, len(set(labels[:m]))) for m in (samples // 4, samples // 2) if m >= 1]
    growth.append((samples, len(set(labels))))
    while max_samples is not None and len(labels) < max_samples:
        more = _unit_sphere(rng, min(len(labels), max_samples - len(labels)), dim)
        labels += [_events(compiled, d, radius, inputs)[0] for d in more]
        directions = np.vstack([directions, more])
        growth.append((len(labels), len(set(labels))))
        if growth[-1][1] == growth[-2][1]:
            break
    stable = growth[-1][1] == growth[-2][1] if len(growth) > 1 else False
    counts = Counter(labels)
    confirmed: dict[str, bool] = {}
    gaps: dict[str, float] = {}
    for label in counts:
        mine = [i for i, lab in enumerate(labels) if lab == label]
        others = [i for i, lab in enumerate(labels) if lab != label]
        if not others:  # one piece: no boundary to confirm
            confirmed[label], gaps[label] = True, math.nan
            continue
        a, b = _closest_pair(directions, mine, others)
        da, db = directions[a], directions[b]

        def along(x: float, da: Array = da, db: Array = db) -> Array:
            v = (1.0 - x) * da + x * db
            return v / np.linalg.norm(v)

        lo, hi = locate_switch(lambda x: _events(compiled, along(x), radius, inputs)[0],
                               0.0, 1.0, tol=BISECT_TOL)
        gap = min(_events(compiled, along(x), radius, inputs)[1] for x in (lo, hi))
        confirmed[label], gaps[label] = gap < TIE_TIME, gap
    _set_offsets(compiled, np.zeros(n))
    return PieceCount(n=n, k=k, radius=radius, samples=len(labels), seed=seed,
                      horizon=horizon, velocities=velocities,
                      rounds=tuple(rounds[:k]), pieces=dict(sorted(counts.items())),
                      confirmed=confirmed, tie_gap=gaps, growth=tuple(growth), stable=stable)


def _touchdown_shifts(compiled: CompiledSystem, d: Array, inputs: list[float], t0: float,
                      s: float = 1e-6) -> Array:
    """tau(d): each foot's first touchdown time at offsets s d, minus the simultaneous time t0,
    over s (the first-order time shifts, good to ~1e-3 of their size at this s)."""
    _set_offsets(compiled, d)
    tr = compiled.simulate("offsets", s, inputs, options=OPTIONS)
    n = d.size
    tau = np.full(n, np.nan)
    for e in tr.contact_events:
        for i in range(n):
            if e.mask_entered >> i & 1 and math.isnan(tau[i]):
                tau[i] = (e.t - t0) / s
    if np.isnan(tau).any():
        raise SimulationError(f"pieces: a foot did not touch down at offsets {d.tolist()}")
    return tau


def _shift_map(compiled: CompiledSystem, n: int, inputs: list[float]) -> Array:
    """A with tau(d) = A d to first order (column j from offset e_j). The offsets perturb the
    initial state (a raised foot's leg starts compressed), and through the body every foot's
    fall: a foot's touchdown time depends on all the offsets, so the cone of a touchdown order
    is {d : A d in that order}, not {d : d in that order}."""
    _set_offsets(compiled, np.zeros(n))
    tr = compiled.simulate("offsets", 0.0, inputs, options=OPTIONS)
    t0 = tr.events[0].t
    return np.column_stack([_touchdown_shifts(compiled, np.eye(n)[j], inputs, t0)
                            for j in range(n)])


def _offsets_for(A: Array, tau: Array) -> Array:
    """Offsets d with A d = tau, raised in common until every offset is at least 0.5 (raising
    every foot alike delays all touchdowns alike: A 1 = alpha 1, so the order is kept)."""
    d = cast(Array, np.linalg.solve(A, tau))  # (float64 in, float64 out)
    return d + max(0.0, 0.5 - float(d.min()))


def derivative_pieces(n: int, *, seed: int = 0, h0: float = 1e-3,
                      options: SimulatorOptions = DEFAULT_OPTIONS) -> list[LinearPiece]:
    """One linear piece of the Bouligand derivative per touchdown order (see the module
    docstring), each checked against finite differences along a seeded random direction."""
    _check_n(n)
    compiled = offsets_walker(n)
    inputs = leg_inputs(n)
    e_s = np.zeros(1 + len(compiled.inputs))
    e_s[0] = 1.0
    rng = np.random.default_rng(seed)

    def exact(d: Array) -> float:
        _set_offsets(compiled, d)
        g = outcome_gradient(compiled, "offsets", 0.0, inputs, direction=e_s, options=options)
        return float(g.gradient[0])

    def outcome(s: float) -> float:
        tr = compiled.simulate("offsets", s, inputs, options=options)
        if not tr.success:
            raise SimulationError(f"pieces: offsets maneuver at s = {s} ended {tr.status.name}")
        return tr.outcome

    A = _shift_map(compiled, n, inputs)
    pieces = []
    for order in itertools.permutations(range(n)):
        # the cone's centre in time shifts: the foot that touches down k-th, k later; n
        # independent points around it (steps of 0.2 keep every gap >= 0.6) and a check point
        tau = np.zeros(n)
        tau[list(order)] = np.arange(n, dtype=float)
        basis = np.array([_offsets_for(A, tau + 0.2 * e) for e in np.eye(n)])
        values = np.array([exact(d) for d in basis])
        g = np.linalg.solve(basis, values)
        direction = _offsets_for(A, tau + rng.uniform(-0.2, 0.2, n))
        d_exact = exact(direction)
        _set_offsets(compiled, direction)
        fd = one_sided(outcome, 0.0, +1, h0=h0)
        pieces.append(LinearPiece(order=tuple(i + 1 for i in order), gradient=g,
                                  check_direction=direction, exact=d_exact,
                                  linear=float(g @ direction), finite_difference=fd.derivative,
                                  fd_error=fd.derivative_error))
    _set_offsets(compiled, np.zeros(n))
    return pieces


def distinct_gradients(pieces: list[LinearPiece], *, rtol: float = 1e-6) -> int:
    """How many of the pieces' gradients differ from each other by more than ``rtol`` of the
    largest one's size (each order its own linear piece gives len(pieces))."""
    scale = max((float(np.max(np.abs(p.gradient))) for p in pieces), default=0.0)
    kept: list[Array] = []
    for p in pieces:
        if all(np.max(np.abs(p.gradient - g)) > rtol * scale for g in kept):
            kept.append(p.gradient)
    return len(kept)
