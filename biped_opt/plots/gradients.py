"""The gradient study's figure, one per problem (:mod:`biped_opt.analysis.gradients`).

Three panels: the cost along one decision at the estimator study's s with its switches and the
Gaussian-smoothed costs J_sigma; the bias of each estimator against the gradient of J_sigma,
near the switch and at the optimum, over sigma; and the fraction of descent runs that reached
the global optimum, per method.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from biped_opt.analysis.figure_data import smoothed_curve  # noqa: E402
from biped_opt.plots.figures import _finish  # noqa: E402

__all__ = ["gradient_figure", "smoothed_curve"]


def gradient_figure(study: Any, name: str, path: str | Path) -> Path:
    """The figure of problem ``name`` of a :class:`biped_opt.analysis.gradients.GradientStudy`."""
    curve = study.curves[name]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    ax = axes[0]
    u, cost = curve["u"], curve["cost"]
    ax.plot(u, cost, "k-", lw=1.2, label="c (exact model)")
    width = float(u[-1] - u[0])
    sigmas = sorted({e.sigma for stats in study.stats[name].values() for e in stats})
    for sigma in sigmas:
        ax.plot(u, smoothed_curve(u, cost, sigma * width), lw=1,
                label=f"J_sigma, sigma = {sigma:g} of the interval")
    for k, v in enumerate(study.switches[name]):
        ax.axvline(v, color="tab:red", ls=":", lw=1, label="branch switch" if k == 0 else None)
    ax.axvline(curve["optimum"], color="tab:green", ls="--", lw=1, label="global optimum")
    ax.set_xlabel(curve["axis"])
    ax.set_ylabel("cost")
    ax.set_title(f"{name}: cost at s = {curve['s']:g}")
    ax.set_xlim(u[0] - 0.02 * width, u[-1] + 0.02 * width)
    ax.legend(fontsize=7)

    ax = axes[1]
    markers = {"zeroth": "o", "first": "s"}
    colours = {"near": "tab:red", "away": "tab:blue"}
    for label, stats in study.stats[name].items():
        for est in ("zeroth", "first"):
            rows = [e for e in stats if e.estimator == est]
            sig = np.array([e.sigma for e in rows])
            bias = np.array([max(e.bias, 1e-16) for e in rows])
            se = np.array([e.bias_se for e in rows])
            ax.errorbar(sig, bias, yerr=2 * se, marker=markers[est], color=colours[label],
                        ls="-" if est == "first" else "--", capsize=3,
                        label=f"{est}-order, {label}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("sigma / bound interval")
    ax.set_ylabel("|bias| of the gradient estimate (bars: 2 s.e.)")
    ax.set_title("estimator bias vs the gradient of J_sigma")
    ax.legend(fontsize=7)

    ax = axes[2]
    rows = study.summary(name)
    ax.barh([r["method"] for r in rows], [100 * r["reached"] for r in rows], color="tab:gray")
    ax.set_xlim(0, 100)
    ax.set_xlabel("% of runs reaching the global optimum (within 1e-6)")
    ax.tick_params(axis="y", labelsize=7)
    ax.invert_yaxis()
    ax.set_title("descent from a grid of starts and s")
    fig.tight_layout()
    return _finish(fig, Path(path))
