"""ArviZ's rank ECDF plot of a fit's walkers pooled into groups (:func:`plot_rank`)."""

import matplotlib as mpl
import numpy as np
import xarray as xr
from cycler import cycler

from skinfit.plots.reading import sampled_slots
from skinfit.plots.style import COLOURS, MAX_WIDTH, MIN_FONT, ensure_backend, finish_figure, suptitle
from skinfit.results.fit import as_fit

__all__ = ["plot_rank", "walker_groups"]


def walker_groups(fit, n_groups=4):
    """The posterior as ``n_groups`` chains, each the draws of a block of emcee's walkers one
    walker after another (walkers are not independent chains; :func:`~skinfit.plots.trace.plot_trace` groups them
    the same way), as a DataTree for arviz-plots."""
    post = fit.group("posterior")
    groups = np.array_split(np.arange(post.sizes["chain"]), min(n_groups, post.sizes["chain"]))
    size = min(len(g) for g in groups)
    out = {}
    for name, da in post.data_vars.items():
        da = da.transpose("chain", "draw", ...)
        parts = [da.isel(chain=g[:size]).values.reshape(1, -1, *da.shape[2:]) for g in groups]
        out[name] = (("chain", "draw", *da.dims[2:]), np.concatenate(parts))
    ds = xr.Dataset(out, coords={d: post[d] for d in post.dims if d not in ("chain", "draw")})
    ds = ds.assign_coords(chain=np.arange(len(groups)), draw=np.arange(ds.sizes["draw"]))
    return xr.DataTree.from_dict({"posterior": ds})


def plot_rank(fit, path=None, *, var_names=None, n_groups=4, ncols=4):
    """ArviZ's (arviz-plots) rank ECDF plot, the walkers pooled into ``n_groups`` chains, in
    the report's palette, width and >= 8 pt text (bench/results/arviz_plots.md measured these
    settings against the layout rules)."""
    fit = as_fit(fit)
    ensure_backend()
    # arviz-plots and arviz-base (seconds to import, scipy.stats with them) and pyplot, through which
    # arviz-plots draws, imported where this figure is drawn: the report's figures do not use them
    import arviz_plots as azp
    import matplotlib.pyplot as plt
    from arviz_base import rc_context, rcParams

    tree = walker_groups(fit, n_groups)
    n = sum(var_names is None or s["base"] in var_names for s in sampled_slots(fit))  # panels
    cols = max(1, min(ncols, n))
    size = (min(3.0 * cols, MAX_WIDTH), 2.3 * -(-n // cols) + 0.7)
    rc = {"axes.prop_cycle": cycler(color=list(COLOURS)), "font.size": 9, "axes.titlesize": 9,
          "axes.labelsize": 9, "xtick.labelsize": MIN_FONT, "ytick.labelsize": MIN_FONT,
          "legend.fontsize": MIN_FONT}
    with mpl.rc_context(rc), rc_context({"plot.max_subplots": max(n, rcParams["plot.max_subplots"])}):
        pc = azp.plot_rank(tree, var_names=var_names, backend="matplotlib", col_wrap=cols,
                           figure_kwargs={"figsize": size, "figsize_units": "inches", "layout": "constrained"})
        fig = pc.viz["figure"].item()
        plt.close(fig)  # keep pyplot's registry clean; the Figure stays usable
        groups = tree["posterior"].sizes["chain"]
        suptitle(fig, f"{fit.model_id} on {fit.dataset_id}: rank ECDF ({groups} walker groups)")
    return finish_figure(fig, path)
