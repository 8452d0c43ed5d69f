"""Where outcome, policy and value fail to be C^1 in th0, and why ([1]_ Sec. III, MODEL.md Sec. 6).

Along a sweep every quantity is smooth while three discrete things stay fixed: the mode order of
the (optimal) trajectory, which decision acts, and which bound, if any, holds it. Nonsmoothness
can only arise where one of them changes, so the analysis

1. labels every grid point with (mode order, acting decision, active bound) - for fixed inputs
   the mode order alone;
2. locates every change of label to a bracket of width <= 1e-10 in th0 by bisection
   (:func:`biped_opt.piecewise.locate_switch`), searching again right of each change found (a
   coarse grid's interval can hold several); a bracket that ends in a band thinner than
   :data:`MERGE_TOL` (the simultaneous events around th0 = 0 have a label of their own) is
   widened over it, and changes closer than MERGE_TOL are one point, put at 0 when the band
   holds 0. A bound reached or left is bisected again on the sign of the cost's slope at the
   bound (:func:`bound_relocation`): the optimiser's own verdict flickers near it. So the
   bracket holds the point on any grid, two angles included;
3. measures one-sided limits, first and second derivatives of each quantity there
   (:func:`biped_opt.piecewise.one_sided`) and classifies: **jump** (limits differ), **kink**
   (continuous, first derivatives differ), **second-derivative** (C^1, second derivatives differ;
   outcome and value only: the policy's second differences are dominated by the optimiser's
   tolerance);
4. names the cause from the labels on both sides (mode order change, optimal branch switch,
   change of acting input, bound reached or left by a decision that acts on both sides: the
   bound of a decision that acts on nothing does not shape the value, :func:`describe_change`).

Where the simulation (or the optimum) fails on one side - its label reads ``FAILED:<status>`` -
the change is a **failure** boundary, not a jump or kink of the outcome: it is reported once,
with the failing status in its cause, the working side's limits and slopes, and NaN for the
failing side (nothing is extrapolated into a failed region). Every point carries its bracket;
``location_error`` is the distance from the reported point to the bracket's far end.

A change of label hidden between two grid points that cancels out (left and right labels equal)
is not seen; a finer grid finds it.

.. [1] B. Banjanin and S. A. Burden, "Nonsmooth optimal value and policy functions in mechanical
   systems subject to unilateral constraints", IEEE Control Systems Letters 4(2), 2020.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from biped_opt import strict_json
from biped_opt.errors import SimulationError
from biped_opt.piecewise import OneSided, locate_switch, one_sided
from biped_opt.progress import Progress

__all__ = ["NonsmoothPoint", "NonsmoothReport", "Sample", "Evaluator", "analyse_switches",
           "Relocate", "BoundSlope", "bound_relocation", "bound_labels", "CauseWords",
           "describe_change", "LOCATE_TOL", "MERGE_TOL", "FAILED"]

#: width of the th0 bracket every point is located to
LOCATE_TOL = 1e-10
#: label changes closer than this are one point (simultaneous-event band is ~1e-9 wide)
MERGE_TOL = 1e-7
#: one-sided limits further apart than this are a jump (outcome/value error ~1e-11; the policy's
#: own tolerance, ~1e-8 from the bounded Brent stop rule, sets its larger threshold)
JUMP_TOL = {"outcome": 1e-7, "value": 1e-7, "policy": 1e-5}
#: absolute part of the kink threshold on one-sided first derivatives
KINK_TOL = {"outcome": 1e-5, "value": 1e-5, "policy": 1e-3}
#: relative threshold on second derivatives (C^1 quantities only)
SECOND_TOL = 1e-2
#: label changes searched for between two neighbouring grid points
MAX_SWITCHES_PER_INTERVAL = 16
#: largest and smallest one-sided steps [rad]
H0 = 1e-2
H_MIN = 1e-6
#: shrink factor of the one-sided step between ladders
SHRINK = 8.0
#: the label prefix of a failed simulation or optimum (``FAILED:<status>``)
FAILED = "FAILED:"


def _one_sided_converged(
    f: Callable[[float], float], x: float, side: int, h: float, h_min: float
) -> OneSided:
    """One-sided limit and derivatives from ladders shrinking by SHRINK until two agree.

    A coarse ladder over a strongly curved piece (a policy that turns sharply before a bound)
    extrapolates badly; two successive ladders agreeing in limit and slope means the finer one
    has left that regime (and is more accurate in the second derivative).
    """
    est = one_sided(f, x, side, h0=h)
    best, best_gap = est, math.inf
    while h / SHRINK >= h_min:
        h /= SHRINK
        finer = one_sided(f, x, side, h0=h)
        scale = max(1.0, abs(est.derivative), abs(finer.derivative))
        gap = abs(finer.derivative - est.derivative) / scale
        if abs(finer.limit - est.limit) <= 1e-9 * max(1.0, abs(est.limit)) + 1e-3 * h:
            if gap <= 1e-3:
                return finer
            if gap < best_gap:
                best, best_gap = est, gap
        est = finer
    # no two ladders agreed: noise grows as the step shrinks, keep the most consistent coarse one
    return best if math.isfinite(best_gap) else est


@dataclass(frozen=True)
class NonsmoothPoint:
    """A th0 where one quantity is not C^1 (or, for C^1 quantities, not C^2).

    ``left``/``right`` are what differs: the one-sided limits for a jump, first derivatives for
    a kink, second derivatives for a second-derivative jump; all three pairs are kept as well.
    """

    theta0: float
    quantity: str  #: "outcome", "policy" or "value"
    input: str | None  #: the policy component (None for outcome and value)
    kind: str  #: "jump", "kink", "second-derivative" or "failure" (a failed side)
    left: float
    right: float
    cause: str
    limits: tuple[float, float]
    derivatives: tuple[float, float]
    second_derivatives: tuple[float, float]
    at: float  #: the quantity at theta0 itself
    bracket: tuple[float, float]  #: width <= LOCATE_TOL (wider only for a simultaneous band)
    labels: tuple[str, str]  #: mode order left | right

    @property
    def location_error(self) -> float:
        """Distance from ``theta0`` to the far end of its bracket."""
        return float(max(self.theta0 - self.bracket[0], self.bracket[1] - self.theta0))

    def as_dict(self) -> dict:
        return {
            "theta0": self.theta0,
            "quantity": self.quantity,
            "input": self.input,
            "kind": self.kind,
            "left": self.left,
            "right": self.right,
            "cause": self.cause,
            "limits": list(self.limits),
            "derivatives": list(self.derivatives),
            "second_derivatives": list(self.second_derivatives),
            "at": self.at,
            "bracket": list(self.bracket),
            "location_error": self.location_error,
            "modes": list(self.labels),
        }


@dataclass(frozen=True)
class NonsmoothReport:
    """Every nonsmooth point found along a sweep, sorted by th0."""

    subject: str  #: maneuver (fixed inputs) or problem name
    optimal: bool
    theta0_range: tuple[float, float]
    grid_size: int
    points: tuple[NonsmoothPoint, ...]
    nsim: int = field(default=0)
    parameter: str = "theta0"  #: the name of the swept parameter (a system's s)

    def as_dict(self) -> dict:
        return {
            "subject": self.subject,
            "optimal": self.optimal,
            "theta0_range": list(self.theta0_range),
            "parameter": self.parameter,
            "grid_size": self.grid_size,
            "points": [p.as_dict() for p in self.points],
        }

    def to_json(self, **kwargs: object) -> str:
        return strict_json.dumps(self.as_dict(), **kwargs)  # a failing side's NaN: null

    def table(self) -> str:
        """A plain-text table, one line per point."""
        lines = [f"{self.parameter:>16} {'quantity':<10} {'kind':<17} {'left':>14} "
                 f"{'right':>14}  cause"]
        for p in self.points:
            q = p.quantity if p.input is None else f"{p.quantity}:{p.input}"
            lines.append(
                f"{p.theta0:>16.10g} {q:<10} {p.kind:<17} {p.left:>14.9g} {p.right:>14.9g}  "
                f"{p.cause}"
            )
        return "\n".join(lines)


# --- evaluation samples ----------------------------------------------------------------------
@dataclass(frozen=True)
class Sample:
    label: Hashable
    values: dict[str, float]  # "outcome", "value", "policy:u1"...
    branch: str
    active: str | None = None
    bound: str | None = None
    result: Any = None  #: the optimum sampled (its ``candidates`` and ``problem`` name causes)


class Evaluator:
    """th0 -> Sample with a cache (bisection and one-sided ladders revisit points)."""

    def __init__(self, fn: Callable[[float], Sample]) -> None:
        self.fn = fn
        self.cache: dict[float, Sample] = {}

    def __call__(self, th: float) -> Sample:
        th = float(th)
        if th not in self.cache:
            self.cache[th] = self.fn(th)
        return self.cache[th]

    def label(self, th: float) -> Hashable:
        return self(th).label


# --- the engine -------------------------------------------------------------------------------
def _across_band(ev: Evaluator, lo: float, hi: float, la: Hashable, lb: Hashable,
                 limit: float) -> tuple[float, float, Hashable, Hashable]:
    """Widen the bracket [lo, hi] of a change la | lb over a thin band on either side.

    Near-simultaneous events are simulated as simultaneous within a band ~1e-9 wide around the
    point where they coincide, and that band has a label of its own (AIR->GROUND between
    AIR->RIGHT->GROUND and AIR->LEFT->GROUND). When a grid point falls inside the band, bisection
    finds only the band's edge, a bracket that excludes the point itself (th0 = 2e-9 instead of
    0). So: a label that does not reach MERGE_TOL beyond the bracket is a band, and the bracket
    extends to its far edge."""
    outer = max(lo - MERGE_TOL, -limit)
    if outer < lo and ev.label(outer) != ev.label(lo):
        lo, _ = locate_switch(ev.label, outer, lo, tol=LOCATE_TOL)
        la = ev.label(outer)
    outer = min(hi + MERGE_TOL, limit)
    if outer > hi and ev.label(outer) != ev.label(hi):
        _, hi = locate_switch(ev.label, hi, outer, tol=LOCATE_TOL)
        lb = ev.label(outer)
    return lo, hi, la, lb


#: (lo, hi, label_left, label_right) -> a better bracket [lo, hi] of that change
Relocate = Callable[[float, float, Hashable, Hashable], tuple[float, float]]
#: (held, decision, th) -> d c / d u_decision at th, the decision on the bound it has in the
#: sample ``held`` and the other decisions as ``held``'s optimum sets them (at th)
BoundSlope = Callable[[Sample, str, float], float]


def _acting(active: str | None) -> list[str]:
    """The acting decisions of a label's ``active`` part ("u1", "u1+u2" or None)."""
    return [d for d in (active or "").split("+") if d]


def bound_labels(bound: str | None, active: str | None) -> dict[str, str]:
    """{decision: "lower"/"upper"} from a label's ``bound`` part: "lower"/"upper" for the single
    acting decision, ``"u1=lower,u2=upper"`` when several act."""
    if not bound:
        return {}
    if "=" not in bound:
        return {active: bound} if active else {}
    return dict(part.split("=", 1) for part in bound.split(","))


def _bound_change(la: Hashable, lb: Hashable) -> tuple[str, str, int] | None:
    """(decision, bound, side held) when the only change between the labels (branch, active,
    bound) is one decision, acting on both sides, reaching or leaving a bound (side -1: held on
    the left); None for any other change."""
    if not (isinstance(la, tuple) and isinstance(lb, tuple) and len(la) == len(lb) == 3):
        return None
    (branch_a, active_a, bound_a), (branch_b, active_b, bound_b) = la, lb
    if branch_a != branch_b or active_a != active_b or not _acting(active_a):
        return None
    left, right = bound_labels(bound_a, active_a), bound_labels(bound_b, active_b)
    changed = [d for d in _acting(active_a) if left.get(d) != right.get(d)]
    if len(changed) != 1:
        return None
    (d,) = changed
    a, b = left.get(d), right.get(d)
    if a is not None and b is None:
        return d, a, -1
    if b is not None and a is None:
        return d, b, 1
    return None  # from one bound to the other: not where a free optimum meets a bound


def bound_relocation(ev: Evaluator, limit: float, slope: BoundSlope) -> Relocate:
    """A :data:`Relocate` that brackets a decision reaching or leaving a bound by the sign of the
    cost's slope d c / d u there (Karush-Kuhn-Tucker), for the biped's and any system's tables.

    The optimiser decides "on the bound" from a differenced cost slope whose noise (~2e-10)
    flickers its verdict over ~2e-8 in s around the true point (measured at the biped's
    touchdown u1 bound: brackets from 2 and 41 angles lay 9e-9 apart, each 1e-10 wide, so one
    missed it). The slope at the bound from exact sensitivities (``slope``) is smooth in s and
    crosses 0 where the free optimum meets the bound, to ~1e-11 in s: its sign is bisected over
    MERGE_TOL around the optimiser's bracket instead. Other changes of label, a slope whose sign
    does not change there, or a slope that cannot be had (SimulationError, LinAlgError) keep
    the bracket. The window is MERGE_TOL: the joint optimiser of several acting decisions
    (L-BFGS-B on differenced gradients) can put its verdict further off (~1.2e-7 measured on the
    decoupled two-leg walker's variant), and there the optimiser's bracket stays.
    """

    def relocate(lo: float, hi: float, la: Hashable, lb: Hashable) -> tuple[float, float]:
        change = _bound_change(la, lb)
        if change is None:
            return lo, hi
        decision, which, side = change
        held_sample = ev(lo if side < 0 else hi)
        outward = 1.0 if which == "upper" else -1.0

        def held(th: float) -> bool:  # the cost falls (or is flat) towards the bound
            return outward * slope(held_sample, decision, th) <= 0.0

        a, b = max(lo - MERGE_TOL, -limit), min(hi + MERGE_TOL, limit)
        try:
            if held(a) == held(b):  # the slope does not confirm the change: the optimiser's
                return lo, hi
            return locate_switch(held, a, b, tol=LOCATE_TOL)
        except (SimulationError, np.linalg.LinAlgError):  # no slope (a singular polish too)
            return lo, hi

    return relocate


def _switches(ev: Evaluator, grid: npt.NDArray[np.float64], limit: float, progress: Progress,
              relocate: Relocate | None = None) -> list[tuple[float, float, Hashable, Hashable]]:
    """Located label changes as (lo, hi, label_left, label_right), merged across bands, each
    bracket then improved by ``relocate`` when given.

    Probes MERGE_TOL beyond both ends of the grid see a change at an end, or the band at 0 when
    it holds the whole range (whose labels are then all alike); the caller keeps only the points
    that lie in the range."""
    grid = np.unique(np.concatenate(
        ([max(grid[0] - MERGE_TOL, -limit)], grid, [min(grid[-1] + MERGE_TOL, limit)])))
    labels = [ev.label(x) for x in grid]
    raw = []
    pairs = [k for k in range(grid.size - 1) if labels[k] != labels[k + 1]]
    for i, k in enumerate(pairs):
        # bisection finds one change; on a coarse grid one interval can hold several (the band
        # at 0 and a bound reached further on): search again right of each one found
        a, b = float(grid[k]), float(grid[k + 1])
        for _ in range(MAX_SWITCHES_PER_INTERVAL):
            lo, hi = locate_switch(ev.label, a, b, tol=LOCATE_TOL)
            raw.append(_across_band(ev, lo, hi, ev.label(lo), ev.label(hi), limit))
            a = max(hi, raw[-1][1])
            if a >= b or ev.label(a) == ev.label(b):
                break
        progress.update(i + 1, max(len(pairs), 1))
    raw.sort(key=lambda r: r[0])
    merged: list[tuple[float, float, Hashable, Hashable]] = []
    for lo, hi, la, lb in raw:
        if merged and lo - merged[-1][1] <= MERGE_TOL:  # (overlapping once widened, too)
            plo, _, pla, _ = merged[-1]
            merged[-1] = (plo, hi, pla, lb)
        else:
            merged.append((lo, hi, la, lb))
    if relocate is not None:
        merged = [(*relocate(lo, hi, la, lb), la, lb) for lo, hi, la, lb in merged]
    return merged


def _classify(
    name: str, left: OneSided, right: OneSided, at: float
) -> tuple[str, float, float] | None:
    family = name.split(":")[0]
    if abs(right.limit - left.limit) > JUMP_TOL[family] * max(1.0, abs(left.limit)):
        return "jump", left.limit, right.limit
    scale = max(1.0, abs(left.derivative), abs(right.derivative))
    noise = 10.0 * (left.derivative_error + right.derivative_error)
    if abs(right.derivative - left.derivative) > max(KINK_TOL[family] * scale, noise):
        return "kink", left.derivative, right.derivative
    if family != "policy":
        d2l, d2r = left.second_derivative, right.second_derivative
        if abs(d2r - d2l) > SECOND_TOL * max(1.0, abs(d2l), abs(d2r)):
            return "second-derivative", d2l, d2r
    return None


@dataclass(frozen=True)
class CauseWords:
    """How a table words a change of mode order and of acting inputs (the biped's tables say
    "mode order changes", any system's "mode sequence changes")."""

    modes: str = "mode order changes"
    acting: str = "acting input changes"


#: the biped's tables' words (MODEL.md Sec. 6, the paper's demo table)
BIPED_WORDS = CauseWords()


def describe_change(words: CauseWords = BIPED_WORDS
                    ) -> Callable[[Sample, Sample, bool, bool], str]:
    """The cause of a point from the samples on its two sides, in ``words``: mode order change
    or optimal branch switch, change of acting inputs, and a bound reached, left or swapped by
    each decision that acts on both sides. A decision acting on one side only sits at its
    cheapest value on the other, on a bound or not: its bound does not shape the value there
    (the change of acting inputs already names it), so it is not a bound change."""

    def cause(sl: Sample, sr: Sample, optimal: bool, policy_jumps: bool) -> str:
        causes = []
        if sl.branch != sr.branch:
            # the optimum changes branch although both branches exist on both sides: the global
            # minimum jumps between two local minima (not a change of which modes are possible)
            both = (
                sl.result is not None and sr.result is not None
                and sr.branch in {c.branch for c in sl.result.candidates}
                and sl.branch in {c.branch for c in sr.result.candidates}
            )
            if optimal and policy_jumps and both:
                causes.append(
                    f"optimal branch switches: {sl.branch} | {sr.branch} "
                    "(the global minimum moves to another local minimum)"
                )
            else:
                causes.append(f"{words.modes}: {sl.branch} | {sr.branch}")
        if optimal and sl.active != sr.active:
            causes.append(f"{words.acting}: {sl.active or 'none'} | {sr.active or 'none'}")
        if optimal and sl.result is not None:
            problem = sl.result.problem
            left, right = bound_labels(sl.bound, sl.active), bound_labels(sr.bound, sr.active)
            on_right = set(_acting(sr.active))
            for d in (d for d in _acting(sl.active) if d in on_right):
                a, b = left.get(d), right.get(d)
                if a == b:
                    continue
                lo, hi = problem.bound(d)
                if b is not None:
                    verb = "reaches" if a is None else "moves to"
                    causes.append(f"input {d} {verb} its {b} bound "
                                  f"{lo if b == 'lower' else hi:g}")
                else:
                    causes.append(f"input {d} leaves its {a} bound "
                                  f"{lo if a == 'lower' else hi:g}")
        return "; ".join(causes) if causes else "change of label without a mode change"

    return cause


def analyse_switches(
    ev: Evaluator,
    grid: npt.NDArray[np.float64],
    quantities: list[str],
    limit: float,
    optimal: bool,
    progress: Progress,
    relocate: Relocate | None = None,
    cause: Callable[[Sample, Sample, bool, bool], str] | None = None,
) -> list[NonsmoothPoint]:
    """Locate the label changes of ``ev`` along ``grid`` and classify each quantity there
    (the engine of both the biped's and any system's tables; ``cause`` names why a point is
    there from the samples on its two sides, by default :func:`describe_change`'s)."""
    cause = cause or describe_change()
    switches = _switches(ev, grid, limit, progress, relocate)
    points: list[NonsmoothPoint] = []
    xs = [0.0 if lo <= 0.0 <= hi else 0.5 * (lo + hi) for lo, hi, _, _ in switches]
    for i, (lo, hi, _, _) in enumerate(switches):
        x = xs[i]
        if not grid[0] <= x <= grid[-1]:
            continue  # seen from a probe beyond the range, but outside it
        left_gap = x - (xs[i - 1] if i > 0 else -limit)
        right_gap = (xs[i + 1] if i + 1 < len(xs) else limit) - x
        # stay inside the smooth pieces on each side, and beyond the bracket/band
        h = min(H0, 0.45 * left_gap, 0.45 * right_gap)
        h_min = max(H_MIN, 64.0 * (hi - lo))
        h = max(h, h_min)
        failed = (_failure(ev(lo)), _failure(ev(hi)))
        sides = {}
        if not any(failed):
            # (a failed run still has numbers: a side whose samples meet one is a failing
            # side, not a limit; a failed region can be a sliver inside the bracket's sides)
            seen: list[str | None] = [None, None]
            for q in quantities:
                sides[q] = (_one_sided_converged(_watched(ev, q, seen, 0), x, -1, h, h_min),
                            _one_sided_converged(_watched(ev, q, seen, 1), x, +1, h, h_min))
            sl = ev(x - h / 16)
            sr = ev(x + h / 16)
            failed = (seen[0] or _failure(sl), seen[1] or _failure(sr))
        if any(failed):
            points.append(_failure_point(ev, x, lo, hi, h, h_min, failed, quantities))
            continue
        policy_jumps = any(
            abs(sides[q][1].limit - sides[q][0].limit) > JUMP_TOL["policy"]
            for q in quantities if q.startswith("policy:")
        )
        why = cause(sl, sr, optimal, policy_jumps)
        for q in quantities:
            left, right = sides[q]
            found = _classify(q, left, right, ev(x).values[q])
            if found is None:
                continue
            kind, a, b = found
            family, _, comp = q.partition(":")
            points.append(
                NonsmoothPoint(
                    theta0=x,
                    quantity=family,
                    input=comp or None,
                    kind=kind,
                    left=a,
                    right=b,
                    cause=why,
                    limits=(left.limit, right.limit),
                    derivatives=(left.derivative, right.derivative),
                    second_derivatives=(left.second_derivative, right.second_derivative),
                    at=ev(x).values[q],
                    bracket=(lo, hi),
                    labels=(sl.branch, sr.branch),
                )
            )
    return points


def _watched(ev: Evaluator, q: str, seen: list[str | None], k: int) -> Callable[[float], float]:
    """Quantity ``q`` of ``ev`` at s, noting in ``seen[k]`` the status of the first failed
    sample it is asked for."""
    def f(th: float) -> float:
        sample = ev(th)
        if seen[k] is None:
            seen[k] = _failure(sample)
        return sample.values[q]
    return f


def _failure(sample: Sample) -> str | None:
    """The status of a failed sample (branch ``FAILED:<status>``), None for a working one."""
    return sample.branch[len(FAILED):] if sample.branch.startswith(FAILED) else None


def _failure_point(ev: Evaluator, x: float, lo: float, hi: float, h: float, h_min: float,
                   failed: tuple[str | None, str | None], quantities: list[str]
                   ) -> NonsmoothPoint:
    """The boundary of a failed region at x (bracket [lo, hi]): the first quantity's limits
    and slopes on the working side, NaN on a failing one."""
    q = quantities[0]
    nan = OneSided(side=0, limit=math.nan, derivative=math.nan, derivative_error=math.nan,
                   second_derivative=math.nan)
    seen = list(failed)
    sides = []
    for k, side in ((0, -1), (1, 1)):
        # (a working side whose samples meet a failed run fails too)
        one = nan if seen[k] else _one_sided_converged(_watched(ev, q, seen, k), x, side, h,
                                                        h_min)
        sides.append(nan if seen[k] else one)
    left, right = sides
    where = [f"{side}: {seen[k]}" for k, side in ((0, "left"), (1, "right")) if seen[k]]
    family, _, comp = q.partition(":")
    return NonsmoothPoint(
        theta0=x, quantity=family, input=comp or None, kind="failure",
        left=left.limit, right=right.limit,
        cause=f"failure boundary ({'; '.join(where)}): no outcome on the failing side",
        limits=(left.limit, right.limit), derivatives=(left.derivative, right.derivative),
        second_derivatives=(left.second_derivative, right.second_derivative),
        at=math.nan if _failure(ev(x)) else ev(x).values[q], bracket=(lo, hi),
        labels=(ev(lo).branch, ev(hi).branch))
