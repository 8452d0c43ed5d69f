"""The count of smooth pieces against the paper's (n!)^k (Sec. V-B), drawn from the records of
:func:`biped_opt.analysis.pieces.count_pieces` (any records with ``n``, ``k``, ``count`` and
``velocities``) and, optionally, the number of distinct linear pieces of the Bouligand derivative
per n (:func:`biped_opt.analysis.pieces.derivative_pieces`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from biped_opt.errors import InvalidInputError  # noqa: E402
from biped_opt.plots.figures import _finish  # noqa: E402

__all__ = ["pieces_figure"]


def pieces_figure(path: str | Path, counts: Sequence[Any],
                  derivative: Mapping[int, int] | None = None) -> Path:
    """Piece counts over the number of rounds k, one colour per number of legs n, on a log
    scale, with (n!)^k dashed; solid markers: the neighbourhood of the feet's heights, open
    ones: heights and velocities. ``derivative`` (n -> distinct linear pieces of the
    B-derivative at the simultaneous point) adds a panel against n!."""
    if not counts:
        raise InvalidInputError("pieces_figure: no counts to draw")
    legs = sorted({int(c.n) for c in counts})
    panels = 2 if derivative else 1
    fig, axes = plt.subplots(1, panels, figsize=(5.2 * panels, 4.0), squeeze=False)
    ax = axes[0][0]
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, n in enumerate(legs):
        colour = colours[i % len(colours)]
        mine = [c for c in counts if int(c.n) == n]
        ks = sorted({int(c.k) for c in mine})
        ax.plot(ks, [math.factorial(n) ** k for k in ks], "--", color=colour, lw=1.0)
        for velocities, marker in ((False, "o"), (True, "s")):
            rows = sorted((int(c.k), int(c.count)) for c in mine
                          if bool(c.velocities) == velocities)
            if rows:
                ax.plot([k for k, _ in rows], [v for _, v in rows], marker=marker,
                        color=colour, mfc=colour if not velocities else "white",
                        lw=1.5 if not velocities else 0.8,
                        label=f"n = {n}" + (" (heights + velocities)" if velocities else ""))
    ax.plot([], [], "--", color="0.4", lw=1.0, label="(n!)^k")
    ax.set_yscale("log")
    ax.set_xlabel("rounds k (touchdown, liftoff, touchdown)")
    ax.set_ylabel("smooth pieces (distinct mode sequences)")
    ax.set_xticks(sorted({int(c.k) for c in counts}))
    ax.set_title("pieces near simultaneous contact", fontsize=10)
    ax.legend(fontsize=7)
    ax.grid(True, which="both", alpha=0.3)
    if derivative:
        bx = axes[0][1]
        ns = sorted(derivative)
        bx.plot(ns, [math.factorial(n) for n in ns], "--", color="0.4", label="n!")
        bx.plot(ns, [derivative[n] for n in ns], "o-", label="distinct g over the n! order cones")
        bx.set_yscale("log")
        bx.set_xticks(ns)
        bx.set_xlabel("legs n")
        bx.set_ylabel("linear pieces g . d of the B-derivative")
        bx.set_title("B-derivative at the simultaneous touchdown", fontsize=10)
        bx.legend(fontsize=7)
        bx.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return _finish(fig, Path(path))
