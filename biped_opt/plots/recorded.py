"""A recorded sweep of any system drawn as recorded: points coloured by mode sequence.

``biped-opt report`` draws the biped's recordings as the paper's figures
(:mod:`biped_opt.plots.figures`); a recording of another system gets :func:`sweep_figure`: its
outcome over s (an optimal sweep adds its value and policy), one colour per recorded mode
sequence, and a dashed line at each nonsmooth point estimated from the samples
(:func:`biped_opt.analysis.sampled.grid_nonsmooth`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

from biped_opt.plots.figures import plt  # (its import selects the file backend)

__all__ = ["sweep_figure"]


def sweep_figure(path: str | Path, s: npt.ArrayLike, branch: Sequence[str],
                 outcome: npt.ArrayLike, *, value: npt.ArrayLike | None = None,
                 policy: Mapping[str, npt.ArrayLike] | None = None,
                 points: Sequence[float] = (), title: str = "") -> Path:
    """Outcome over s (and, given, the value and one curve per policy component below it),
    points coloured by their mode sequence ``branch``, dashed lines at ``points`` (s values)."""
    x = np.asarray(s, dtype=np.float64)
    rows: list[tuple[str, dict[str, npt.NDArray[np.float64]]]] = [
        ("outcome", {"": np.asarray(outcome, dtype=np.float64)})]
    if value is not None:
        rows.append(("value", {"": np.asarray(value, dtype=np.float64)}))
    if policy is not None:
        rows.append(("policy", {d: np.asarray(v, dtype=np.float64) for d, v in policy.items()}))
    fig, axes = plt.subplots(len(rows), 1, figsize=(6.4, 2.2 + 1.8 * len(rows)), sharex=True,
                             squeeze=False)
    names = list(dict.fromkeys(branch))
    for ax, (what, series) in zip(axes[:, 0], rows):
        for name, y in series.items():
            for b in names:
                k = np.array([v == b for v in branch])
                ax.plot(x[k], y[k], ".", label=b if what == "outcome" else None,
                        color=f"C{names.index(b)}")
            if name:
                ax.plot(x, y, "-", color="0.7", lw=0.6, zorder=0)
                ax.annotate(name, (x[-1], y[-1]), fontsize="small")
        for p in points:
            ax.axvline(p, color="0.6", lw=0.8, ls="--")
        ax.set_ylabel(what)
    axes[-1, 0].set_xlabel("s")
    axes[0, 0].set_title(title)
    axes[0, 0].legend(fontsize="small", title="mode sequence")
    fig.tight_layout()
    fig.savefig(Path(path), dpi=120)
    plt.close(fig)
    return Path(path)
