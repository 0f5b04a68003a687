"""Prior against posterior, one panel per parameter (:func:`plot_prior_posterior`)."""

import math

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from skinfit.plots.reading import param_label, sampled_slots, slot_values, use_log
from skinfit.plots.style import (
    COLOURS,
    MIN_FONT,
    finish_figure,
    log_ticks,
    new_figure,
    plain_scale,
    suptitle,
    wrap_title,
)
from skinfit.results.fit import as_fit

__all__ = ["plot_prior_posterior"]


def plot_prior_posterior(fit, path=None, *, var_names=None, ncols=4):
    """Prior (line, exact density) against posterior (filled histogram), one panel per parameter.

    Positive parameters on log axes, densities per unit of the axis coordinate, each curve
    scaled to its peak; the title gives the contraction 1 - var(post)/var(prior) of
    :meth:`Fit.summary`: near 1 the data determined the parameter, near 0 the prior did.
    """
    fit = as_fit(fit)
    slots = sampled_slots(fit, densities=True)
    if var_names is not None:
        slots = [s for s in slots if s["name"] in var_names or s["base"] in var_names]
    summary = fit.summary()
    ds = fit.group("posterior")
    ncols = min(ncols, len(slots))
    nrows = math.ceil(len(slots) / ncols)
    fig = new_figure(3.0 * ncols, 2.3 * nrows + 0.7)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    for ax in axes.ravel()[len(slots):]:
        ax.set_visible(False)
    for k, s in enumerate(slots):
        ax = axes.ravel()[k]
        v = slot_values(ds, s).ravel()
        prior = s["prior"]
        # the axis in plain numbers (an SI prefix or a power of ten in the unit): x = SI / factor
        factor, unit = plain_scale(v, s["unit"], s["display"])
        v = v / factor
        lo_q, hi_q = (prior.ppf(np.array([0.005, 0.995])) / factor if prior is not None
                      else np.quantile(v, [0, 1]))
        lo_q = max(lo_q, np.min(v) * 1e-3) if s["log"] else lo_q
        log = use_log(s, [lo_q, hi_q, v.min(), v.max()])
        t = np.log10(v) if log else v
        if log:
            lo_q, hi_q = np.log10(lo_q), np.log10(hi_q)
        lo, hi = min(lo_q, t.min()), max(hi_q, t.max())
        h, edges = np.histogram(t, bins=50, density=True)
        ax.stairs(h / h.max(), 10 ** edges if log else edges, fill=True, color=COLOURS[0], alpha=0.55,
                  label="posterior")
        if prior is not None:
            grid = np.linspace(lo, hi, 400)
            xs = 10 ** grid if log else grid
            with np.errstate(divide="ignore", over="ignore"):
                dens = np.exp(prior.logpdf(xs * factor)) * (xs * math.log(10) if log else 1.0)
            if np.nanmax(dens) > 0:
                ax.plot(xs, dens / np.nanmax(dens), color="black", lw=1.2, label="prior")
        if log:
            ax.set_xscale("log")
        ax.set_xlim(10 ** lo if log else lo, 10 ** hi if log else hi)
        if log:
            log_ticks(ax)
        ax.set_ylim(0, 1.08)
        ax.set_yticks([])
        ax.set_xlabel(param_label(s["name"], unit), fontsize=9)
        ax.tick_params(labelsize=MIN_FONT)
        c = summary.loc[s["name"], "contraction"] if s["name"] in summary.index else np.nan
        ax.set_title(wrap_title(f"{s['name']}: contraction {c:.2f}", ax, 9), fontsize=9)
    for row in axes:
        row[0].set_ylabel("density (scaled to peak)", fontsize=8)
    fig.legend(handles=[Patch(color=COLOURS[0], alpha=0.55, label="posterior"),
                        Line2D([], [], color="black", lw=1.2, label="prior")],
               loc="outside right upper", fontsize=9, frameon=False)
    suptitle(fig, f"{fit.model_id} on {fit.dataset_id}: prior vs posterior")
    return finish_figure(fig, path)
