"""The rank histograms of simulation-based calibration (:mod:`skinfit.analysis.sbc`)."""

import math

import numpy as np
from matplotlib.figure import Figure
from scipy import stats

from skinfit.analysis.sbc import n_bins
from skinfit.plots.style import save_figure

__all__ = ["plot_ranks"]


def plot_ranks(result, path=None):
    """Rank histograms, one panel per parameter, with the central 99% band of a uniform
    histogram's bin counts (binomial; Talts et al. 2018, Fig. 3 style)."""
    names = list(result.ranks.columns)
    ncol = min(4, len(names))
    nrow = math.ceil(len(names) / ncol)
    fig = Figure(figsize=(3.2 * ncol, 2.4 * nrow), layout="constrained")
    axes = fig.subplots(nrow, ncol, squeeze=False).ravel()
    n, L = len(result.ranks), result.n_draws
    b = n_bins(n, L)
    lo, hi = stats.binom.ppf([0.005, 0.995], n, 1.0 / b)
    for ax, name in zip(axes, names):
        counts = np.bincount(result.ranks[name].to_numpy(dtype=int) * b // (L + 1), minlength=b)
        ax.axhspan(lo, hi, color="0.85", zorder=0)
        ax.axhline(n / b, color="0.5", lw=0.8)
        ax.bar(np.arange(b), counts, width=1.0, color="C0", edgecolor="white")
        row = result.table.loc[name]
        ax.set_title(f"{name}\np_chi2={row['p_chi2']:.3g}  p_KS={row['p_ks']:.3g}", fontsize=8)
        ax.set_xticks([0, b - 1], ["0", f"L={L}"])
        ax.tick_params(labelsize=7)
    for ax in axes[len(names):]:
        ax.set_visible(False)
    fig.suptitle(f"SBC rank histograms: {result.model} on the design of {result.dataset} "
                 f"({n} simulations; grey: 99% band under uniformity)", fontsize=9)
    if path is not None:
        save_figure(fig, path, dpi=110)
    return fig
