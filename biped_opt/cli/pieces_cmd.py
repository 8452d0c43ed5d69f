"""``biped-opt pieces``: the count of smooth pieces near simultaneous contact against (n!)^k
(paper Sec. V-B), and the linear pieces of the B-derivative, on the n-leg walker."""

from __future__ import annotations

import argparse
import time

from biped_opt.cli.args import (
    MAX_POINTS,
    MAX_SEED,
    int_in_range,
    output_file,
    path_arg,
    positive_float,
)
from biped_opt.cli.output import emit_json

#: the exact derivatives are accurate to ~1e-10 (variational tolerance); a cone whose further
#: direction misses g.d by more than this is cut into more than one linear piece
LINEAR_TOL = 1e-8
#: most rounds to count: the unperturbed walker has a few simultaneous rounds in its 12 s, and
#: k beyond them counts nothing more
MAX_ROUNDS = 10


def _max_legs() -> int:
    from biped_opt.analysis.pieces import MAX_LEGS

    return MAX_LEGS


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "pieces", help="count the smooth pieces near simultaneous contact vs (n!)^k",
        description="Samples the n-leg walker's foot offsets around the simultaneous touchdown "
                    "(seeded), labels each sample by its contact-mode sequence over k rounds "
                    "(touchdown, liftoff, touchdown), confirms each piece's boundary by "
                    "bisection, and compares the count with (n!)^k; then checks one linear "
                    "piece of the B-derivative per touchdown order against finite differences.")
    p.add_argument("--legs", type=int_in_range("--legs", 1, _max_legs), nargs="+",
                   default=None, metavar="N",
                   help="numbers of legs (default: every number the study supports, 1..4)")
    p.add_argument("--rounds", type=int_in_range("--rounds", 1, MAX_ROUNDS), default=3, metavar="K",
                   help="count for k = 1..K rounds, as far as the walker has them (default 3)")
    p.add_argument("--samples", type=int_in_range("--samples", 2, MAX_POINTS), default=400,
                   help="samples of the neighbourhood per count (default 400)")
    p.add_argument("--max-samples", type=int_in_range("--max-samples", 2, MAX_POINTS),
                   default=None, metavar="N",
                   help="double the samples until a doubling finds no new piece, up to N per "
                        "count (default: --samples only)")
    p.add_argument("--radius", type=positive_float("--radius", maximum=0.01), default=1e-3,
                   help="size of the perturbation s (default 1e-3, at most 0.01)")
    p.add_argument("--seed", type=int_in_range("--seed", 0, MAX_SEED), default=0,
                   help="seed of the samples and of the check directions (default 0)")
    p.add_argument("--no-derivative", action="store_true",
                   help="skip the B-derivative's linear pieces")
    p.add_argument("--figure", type=path_arg(output_file, "--figure", overwrite=True),
                   metavar="FILE.png",
                   help="also draw the counts (and linear pieces) against (n!)^k")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from biped_opt.analysis.pieces import (
        count_pieces,
        derivative_pieces,
        distinct_gradients,
        simultaneous_rounds,
    )

    start = time.perf_counter()
    counts, derivatives = [], {}
    for n in sorted(set(args.legs or range(1, _max_legs() + 1))):
        rounds = simultaneous_rounds(n)
        for k in range(1, min(args.rounds, len(rounds)) + 1):
            for velocities in (False, True):
                counts.append(count_pieces(
                    n, k, samples=args.samples, radius=args.radius, seed=args.seed,
                    velocities=velocities, rounds=rounds,
                    max_samples=None if args.max_samples is None
                    else max(args.max_samples, args.samples)))
        if not args.no_derivative:
            derivatives[n] = derivative_pieces(n, seed=args.seed)
    if args.json:
        emit_json({
            "counts": [c.as_dict() for c in counts],
            "derivative": {str(n): [p.as_dict() for p in ps] for n, ps in derivatives.items()}})
    else:
        _print(counts, derivatives, args, distinct_gradients)
    if args.figure is not None:
        from biped_opt.plots.pieces import pieces_figure

        linear = {n: distinct_gradients(ps) for n, ps in derivatives.items()}
        print(f"figure: {pieces_figure(args.figure, counts, linear or None)}")
    if not args.json:
        print(f"total {time.perf_counter() - start:.1f} s")
    return 0


def _print(counts, derivatives, args, distinct_gradients) -> None:
    most = "" if args.max_samples is None else f", doubled up to {args.max_samples}"
    print(f"Pieces near simultaneous contact (radius {args.radius:g}, {args.samples} samples"
          f"{most}, seed {args.seed}): distinct contact-mode sequences over k rounds\n")
    print(f"{'n':>2} {'k':>2}  {'rounds':<30} {'heights':>8} {'+veloc.':>8} {'(n!)^k':>7}  "
          "boundaries confirmed")
    by_key = {(c.n, c.k, c.velocities): c for c in counts}
    for (n, k, velocities), c in by_key.items():
        if velocities:
            continue
        both = by_key.get((n, k, True))
        rounds = ", ".join(r.kind for r in c.rounds)
        confirmed = f"{sum(c.confirmed.values())}/{c.count}"
        if both is not None:
            confirmed += f", {sum(both.confirmed.values())}/{both.count}"
        print(f"{n:>2} {k:>2}  {rounds:<30} {c.count:>8} "
              f"{both.count if both is not None else '-':>8} {c.bound:>7}  {confirmed}")
    print("\nCounts are lower bounds (a piece no sample hit is missed). Growth, samples: count "
          "('stable': the last doubling or half of the samples found no new piece):")
    for c in counts:
        growth = "  ".join(f"{m}: {v}" for m, v in c.growth)
        print(f"{c.n:>2} {c.k:>2}  {'+veloc.' if c.velocities else 'heights':<8} {growth}"
              f"{'  stable' if c.stable else ''}")
    for n in sorted({c.n for c in counts}):
        available = max(c.k for c in counts if c.n == n)
        if available < args.rounds:
            print(f"   n = {n}: the unperturbed walker has {available} simultaneous rounds only")
    if not derivatives:
        return
    print("\nB-derivative of the touchdown outcome (pitch at the nadir) at the simultaneous "
          "point, along the offsets:")
    print(f"{'n':>2} {'orders':>6} {'linear':>6} {'distinct':>8}  {'max |exact - g.d|':>18} "
          f"{'max |exact - FD|':>17}")
    for n, ps in derivatives.items():
        lin = max(abs(p.exact - p.linear) for p in ps)
        fd = max(abs(p.exact - p.finite_difference) for p in ps)
        linear = sum(abs(p.exact - p.linear) <= LINEAR_TOL for p in ps)
        print(f"{n:>2} {len(ps):>6} {linear:>6} {distinct_gradients(ps):>8}  {lin:>18.2e} "
              f"{fd:>17.2e}")
    print(f"  linear: orders whose cone is one linear piece (a further direction inside it "
          f"agrees with g.d to {LINEAR_TOL:g})")
