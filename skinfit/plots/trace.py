"""Walker traces and rank histograms of a fit's draws (:func:`plot_trace`)."""

import numpy as np

from skinfit.plots.reading import param_label, sampled_slots, slot_values, use_log
from skinfit.plots.style import COLOURS, MIN_FONT, finish_figure, log_ticks, new_figure, plain_scale, suptitle
from skinfit.results.fit import as_fit

__all__ = ["plot_trace"]


def _ranks(x):
    """Pooled ranks (0..1) of an array of any shape."""
    flat = x.ravel()
    r = np.empty(len(flat))
    r[np.argsort(flat, kind="stable")] = np.arange(len(flat))
    return (r / max(len(flat) - 1, 1)).reshape(x.shape)


def plot_trace(fit, path=None, *, var_names=None, n_groups=4, max_points=300, max_walkers=8):
    """Walker traces (left) and rank histograms per walker group (right), one row per parameter.

    emcee walkers are not independent chains; the walkers are cut into ``n_groups`` groups
    and the ranks of their draws among all draws histogrammed: flat histograms that agree
    mean the groups sample the same distribution.
    """
    fit = as_fit(fit)
    slots = sampled_slots(fit)
    if var_names is not None:
        slots = [s for s in slots if s["name"] in var_names or s["base"] in var_names]
    ds = fit.group("posterior")
    sampler = fit.attr("sampler")
    fig = new_figure(10, 1.35 * len(slots) + 0.9)
    axes = fig.subplots(len(slots), 2, squeeze=False, width_ratios=[3, 1])
    for i, s in enumerate(slots):
        v = slot_values(ds, s)  # (walkers, draws)
        # plain numbers: the card's display unit, an SI prefix or a power of ten in the unit
        factor, unit = plain_scale(v, s["unit"], s["display"])
        v = v / factor
        ax = axes[i, 0]
        step = max(1, v.shape[1] // max_points)  # the picture of a long chain, at a fraction of the ink
        shown = np.linspace(0, len(v) - 1, min(len(v), max_walkers)).astype(int)
        ax.plot(np.arange(0, v.shape[1], step), v[shown, ::step].T, lw=0.6, alpha=0.7)
        if use_log(s, v):
            ax.set_yscale("log")
            log_ticks(ax, "y")
        ax.set_ylabel(param_label(s["name"], unit), fontsize=8)
        ax.tick_params(labelsize=MIN_FONT)
        ranks = _ranks(v)
        groups = np.array_split(np.arange(len(v)), min(n_groups, len(v)))
        bins = np.linspace(0, 1, 21)
        axr = axes[i, 1]
        for g, members in enumerate(groups):
            h, _ = np.histogram(ranks[members].ravel(), bins=bins, density=True)
            axr.stairs(h, bins, color=COLOURS[g % len(COLOURS)], lw=1, baseline=None)
        axr.axhline(1.0, color="black", lw=0.6, ls=":")
        axr.set_ylim(0, None)
        axr.set_yticks([])
        axr.tick_params(labelsize=MIN_FONT)
        if i < len(slots) - 1:
            ax.tick_params(labelbottom=False)
            axr.tick_params(labelbottom=False)
    axes[-1, 0].set_xlabel(f"draw (after {sampler['burn']} burn-in steps, thinned by {sampler['thin']}); "
                           f"{min(len(v), max_walkers)} of {sampler['nwalkers']} walkers shown")
    axes[-1, 1].set_xlabel(f"rank (fraction), {len(groups)} walker groups")
    axes[0, 1].set_title("rank histograms (flat = mixed)", fontsize=9)
    suptitle(fig, f"{fit.model_id} on {fit.dataset_id}: traces")
    return finish_figure(fig, path)
