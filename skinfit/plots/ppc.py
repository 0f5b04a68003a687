"""The posterior-predictive check in the model's natural axes (:func:`plot_ppc`); its numbers
come from :mod:`skinfit.plots.predictive`."""

import math
import warnings

import matplotlib
import matplotlib.colors
import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from skinfit.errors import InputError
from skinfit.plots.predictive import (
    BAND_COLUMNS,
    MAX_PANELS,
    N_GRID,
    median_curves,
    ppc_bands,
    ppc_draws,
    ppc_median_curves,
    reference_curve,
)
from skinfit.plots.reading import axis_label, data_units, unit_factor
from skinfit.plots.style import COLOURS, MAX_WIDTH, MIN_FONT, finish_figure, log_ticks, new_figure, suptitle, wrap_title
from skinfit.results.fit import as_fit

__all__ = ["plot_ppc"]

#: A median marked at the data's x, where no curve may join the data's points: a short bar
#: (the other levels' medians, thin and grey, as a plain one).
_MEDIAN_MARK = {"ls": "", "marker": "_", "ms": 10, "mew": 2}
_OTHER_MARK = {"ls": "", "marker": "_"}


def _grid(fig, nrows, ncols, n_panels, multi, n_obs, transpose=False):
    """Axes as rows[r][panel]: multi = one row per observable (+ pair row), y shared per row,
    x shared down a column (``transpose``: the same axes laid out one panel per row, one
    observable per column, x shared by every panel of the observables and by every pair
    panel, so that only the bottom row needs x labels); otherwise one row of ``n_panels``
    wrapped, all axes shared."""
    if not multi:
        axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True, sharey=True).ravel()
        for ax in axes[n_panels:]:
            ax.set_visible(False)
        return [list(axes[:n_panels])]
    gs = fig.add_gridspec(ncols, nrows) if transpose else fig.add_gridspec(nrows, ncols)
    rows = []
    for r in range(nrows):
        row = []
        for c in range(ncols):
            if transpose:  # the covariate's panels with the first of them, the pair panels with theirs
                sharex = (row[0] if c else None) if r in (0, n_obs) else rows[0][0]
            else:
                sharex = rows[0][c] if 0 < r < n_obs else None
            row.append(fig.add_subplot(gs[c, r] if transpose else gs[r, c], sharex=sharex,
                                       sharey=row[0] if c else None))
        rows.append(row)
    return rows


def _bands_overlap(bands, observable, panel, n_colours, share=0.5):
    """True when, in some panel, two colour levels' 90% bands overlap over more than ``share``
    of the narrower band at the x values they share (then each level gets a panel)."""
    sub = bands[bands["observable"] == observable]
    for p in np.unique(panel):
        agg = {c: sub[(sub["panel"] == p) & (sub["colour"] == c)].groupby("x")[["q05", "q95"]].mean()
               for c in range(n_colours)}
        for a in range(n_colours):
            for b in range(a + 1, n_colours):
                common = agg[a].index.intersection(agg[b].index)
                if not len(common):
                    continue
                lo = np.maximum(agg[a].loc[common, "q05"], agg[b].loc[common, "q05"])
                hi = np.minimum(agg[a].loc[common, "q95"], agg[b].loc[common, "q95"])
                narrow = np.minimum(agg[a].loc[common, "q95"] - agg[a].loc[common, "q05"],
                                    agg[b].loc[common, "q95"] - agg[b].loc[common, "q05"])
                if np.mean(np.clip(hi - lo, 0, None) / np.where(narrow > 0, narrow, np.inf)) > share:
                    return True
    return False


def plot_ppc(fit, path=None):
    """Posterior-predictive plot in the model's natural axes.

    Per panel (a level of the card's ``plot.panels`` columns): the data, the 50% and 90%
    posterior-predictive bands (per observation: quantiles of the ``posterior_predictive``
    draws, clipped at 0 for a non-negative observable, see :func:`ppc_bands`) and the
    posterior median of the noiseless prediction, a curve on a fine grid of x when nothing
    else varies within the panel, else markers at the observed x; for models with two
    observables, one row per observable plus a row of one observable against the other;
    the wavy-surface ball-bearing curve (eq. 2) for reference when the data allow it.
    Levels of a colour column get one colour each (Okabe-Ito or viridis) and, when their bands
    overlap, one panel each (up to 12 panels; for two observables a row or column each). Axes
    are in the units the data came in.

    Returns the matplotlib Figure (written to ``path`` when given).
    """
    fit = as_fit(fit)
    bands = ppc_bands(fit)
    spec = bands.attrs["spec"]
    units = data_units(fit)
    panel_labels, colour_labels = bands.attrs["panel_labels"], bands.attrs["colour_labels"]
    observables = spec["observables"]
    first = bands[bands["observable"] == observables[0]]
    panel = first["panel"].to_numpy()
    colour = first["colour"].to_numpy()
    n_colours = len(colour_labels)
    pair = spec["pair"] if spec["pair"] and all(p in observables for p in spec["pair"]) else None
    keys = panel * n_colours + colour
    fallback = False  # the model's noiseless median not computable here: the predictive one instead
    try:
        curves = median_curves(fit, spec, keys)
    except InputError as exc:  # the saved card's forward function is not available, or its posterior not rebuilt
        curves, fallback = ppc_median_curves(fit, bands, keys), True
        warnings.warn(f"{fit.model_id} on {fit.dataset_id}: the predictive check shows the predictive "
                      f"median at the data's x, not the model's noiseless curve: {exc}", stacklevel=2)

    multi = len(observables) > 1 or pair is not None
    multi_colour = n_colours > 1
    palette = _palette(fit, spec["colours"], n_colours)
    # overlapping bands of several colour levels (of any observable): one panel per (panel,
    # colour) level instead, when that makes at most MAX_PANELS panels
    cells = [(p, c) for p in range(len(panel_labels)) for c in range(n_colours) if np.any((panel == p) & (colour == c))]
    split = (multi_colour and len(cells) <= MAX_PANELS
             and any(_bands_overlap(bands, o, panel, n_colours) for o in observables))
    if not split:
        cells = [(p, None) for p in range(len(panel_labels))]
    n_panels = len(cells)
    transpose = False
    if multi:  # one row per observable (+ the pair row), one column per panel
        ncols, nrows = n_panels, len(observables) + (1 if pair else 0)
        transpose = n_panels > 3  # many panels: one per row instead, the observables across
    else:  # one observable: panels wrapped into a near-square grid
        ncols = min(4, math.ceil(math.sqrt(n_panels)))
        nrows = math.ceil(n_panels / ncols)
    gcols, grows = (nrows, ncols) if transpose else (ncols, nrows)  # as laid out
    width = min(2.9 * gcols + 0.8, MAX_WIDTH)
    title_lines = 2 if split and len(panel_labels) > 1 else 1
    n_handles = 6 + (n_colours if multi_colour else 0)
    x_labels = 0.35  # x tick labels and the x label under a row: the bottom row's alone when transposed
    fig = new_figure(width, (0.7 * (width - 0.8) / gcols + 0.1 + 0.17 * title_lines) * grows
                      + x_labels * (1 if transpose else grows) + 0.2 * math.ceil(n_handles / 3) + 0.6)
    rows = _grid(fig, nrows, ncols, n_panels, multi, len(observables), transpose)
    for ax in fig.axes:  # limits once, from all the data, below: not again after every artist
        ax.set_autoscale_on(False)  # (each would autoscale all the axes it shares limits with)
    x_label = axis_label(spec["x"], units.get(spec["x"]))
    x_factor = unit_factor(units.get(spec["x"]))
    reference_drawn = markers_drawn = curve_drawn = False
    for r, o in enumerate(observables):
        f = unit_factor(units.get(o))
        sub = bands[bands["observable"] == o]
        for k, (p, only) in enumerate(cells):
            ax = rows[r][k]
            if ax.get_xscale() != spec["xscale"]:  # first: a scale set after the artists autoscales them
                ax.set_xscale(spec["xscale"])  # again; once: a shared axis sets it on all its siblings
            if ax.get_yscale() != spec["yscale"]:
                ax.set_yscale(spec["yscale"])
            for c in range(n_colours) if only is None else [only]:
                rows_pc = sub[(sub["panel"] == p) & (sub["colour"] == c)]
                if rows_pc.empty:
                    continue
                col = palette[c]
                agg = rows_pc.groupby("x", sort=True)[list(BAND_COLUMNS)].mean()
                xu = agg.index.to_numpy()
                if len(xu) > 1:
                    ax.fill_between(xu, agg["q05"], agg["q95"], color=col, alpha=0.16, lw=0, gid="band90")
                    ax.fill_between(xu, agg["q25"], agg["q75"], color=col, alpha=0.34, lw=0, gid="band50")
                else:
                    ax.errorbar(xu, agg["q50"], yerr=[agg["q50"] - agg["q05"], agg["q95"] - agg["q50"]],
                                color=col, alpha=0.5, lw=3, capsize=0)
                ax.scatter(rows_pc["x"], rows_pc["observed"], s=12, color=col, edgecolor="black",
                           linewidth=0.4, zorder=3, gid="data")
                xs, ys, on_grid = curves[p * n_colours + c]
                if on_grid:
                    ax.plot(xs / x_factor, ys[o] / f, color=col, lw=1.6, zorder=4, gid="median")
                    curve_drawn = True
                else:  # other covariates vary within the panel: no curve through the data's x
                    ax.plot(xs / x_factor, ys[o] / f, color=col, zorder=4, gid="median", **_MEDIAN_MARK)
                    markers_drawn = True
            if split:  # the other levels' medians, thin and grey, for comparison
                for c in range(n_colours):
                    if c != only and p * n_colours + c in curves:
                        xs, ys, on_grid = curves[p * n_colours + c]
                        ax.plot(xs / x_factor, ys[o] / f, color="0.75", lw=0.8, zorder=1,
                                gid="other_median", **({} if on_grid else _OTHER_MARK))
            if r == 0:  # one reference curve per panel, on a fine grid over the panel's x range
                idx = np.flatnonzero(panel == p)
                x_si = np.asarray(fit.group("constant_data")[spec["x"]].values, dtype=float)[idx]
                grid = np.linspace(x_si.min(), x_si.max(), N_GRID) if idx.size else x_si
                ref = reference_curve(spec, fit, idx, grid) if idx.size else None
                if ref is not None:
                    ax.plot(grid / x_factor, ref / f, color="0.35", lw=1.1, ls="--", zorder=2, gid="reference")
                    reference_drawn = True
            ax.set_xlabel(x_label)
            ax.set_ylabel(axis_label(o, units.get(o)))
            title = panel_labels[p] if only is None else "\n".join(
                t for t in (panel_labels[p], colour_labels[only]) if t)
            if title and (r == 0 or len(observables) == 1):
                ax.set_title(wrap_title(title, ax), fontsize=MIN_FONT + 1)
    if pair:
        _draw_pair_row(fit, rows[-1], cells, pair, spec, units, panel, colour, curves, palette)
    if transpose:  # x shared down each column (_grid): labelled under the bottom row only
        for row in rows:
            for ax in row[:-1]:
                ax.set_xlabel("")
                ax.tick_params(labelbottom=False)
    for ax in fig.axes:
        ax.autoscale(True)
    for row in rows:
        for ax in row:
            ax.grid(alpha=0.25, lw=0.5)
            ax.tick_params(labelsize=MIN_FONT + 1)
            for which in "xy":
                if (ax.get_xscale() if which == "x" else ax.get_yscale()) == "log":
                    log_ticks(ax, which)
    if not multi:
        for ax in rows[0]:
            ax.label_outer()
    handles = [Line2D([], [], ls="", marker="o", mfc="0.5", mec="black", mew=0.4, ms=4, label="data")]
    if curve_drawn:
        handles.append(Line2D([], [], color="0.2", lw=1.6, label="posterior median"))
    if markers_drawn:
        handles.append(Line2D([], [], color="0.2", **_MEDIAN_MARK,
                              label="posterior median at the data's x\n(other covariates vary)" if not fallback
                              else "predictive median at the data's x\n(the model's noiseless curve\n"
                                   "cannot be computed here)"))
    handles += [Patch(color="0.2", alpha=0.34, label="50% predictive"),
                Patch(color="0.2", alpha=0.16, label="90% predictive")]
    clipped = {o: s for o, s in bands.attrs["below_floor"].items() if s > 0}
    if clipped:
        handles.append(Patch(color="none", label="bands clipped at 0\n(" + "; ".join(
            f"{s:.1%} of {o.replace('_', ' ')} draws\nbelow 0 under {_noise(fit, o)} noise" for o, s in clipped.items())
            + ")"))
    if split:
        handles.append(Line2D([], [], color="0.75", lw=0.8, label="other levels' medians",
                              **({} if curve_drawn else _OTHER_MARK)))
    if pair:
        handles.append(Line2D([], [], ls="", marker="o", mfc=COLOURS[0], mec="none", alpha=0.4, ms=3,
                              label="predictive draws (pairs)"))
    if reference_drawn:
        handles.append(Line2D([], [], color="0.35", ls="--", lw=1.1, label="ball bearing, g(x) (eq. 2)"))
    if multi_colour:
        handles += [Patch(color=palette[c], label=lab) for c, lab in enumerate(colour_labels)]
    # below the panels, as many columns as fit the width: never over the title or the data
    longest = max(len(line) for h in handles for line in h.get_label().split("\n"))
    ncols = max(1, min(len(handles), int(fig.get_figwidth() / (longest * 0.6 * MIN_FONT / 72 + 0.6))))
    fig.legend(handles=handles, loc="outside lower center", fontsize=MIN_FONT, frameon=False, ncols=ncols)
    suptitle(fig, f"{fit.model_id} on {fit.dataset_id}: posterior predictive")
    return finish_figure(fig, path)


def _palette(fit, columns, n):
    """One colour per colour level: ordered numeric levels along viridis (dark to green, its
    pale yellow end left out), categories in Okabe-Ito's colour-blind-safe set; both remain
    distinct to deuteranopes and in greyscale (viridis) or by hue (Okabe-Ito)."""
    if n <= 1:
        return [COLOURS[0]]
    cd = fit.group("constant_data")
    numeric = all(np.issubdtype(cd[c].dtype, np.number) for c in columns) and len(columns) == 1
    if numeric or n > len(COLOURS):
        cmap = matplotlib.colormaps["viridis"]
        return [matplotlib.colors.to_hex(cmap(v)) for v in np.linspace(0.0, 0.85, n)]
    return list(COLOURS[:n])


def _noise(fit, observable):
    return fit.attr("setup").get("noise", {}).get(observable, "normal")


def _draw_pair_row(fit, axes, cells, pair, spec, units, panel, colour, curves, palette):
    """One observable against the other, an axes per (panel, colour level or None for all)
    cell: data, joint predictive draws, median curve."""
    xo, yo = pair
    od = fit.group("observed_data")
    fx, fy = unit_factor(units.get(xo)), unit_factor(units.get(yo))
    px, py = ppc_draws(fit, xo, 20), ppc_draws(fit, yo, 20)
    for ax, (p, only) in zip(axes, cells):
        for c in range(len(palette)) if only is None else [only]:
            idx = np.flatnonzero((panel == p) & (colour == c))
            if not len(idx):
                continue
            col = palette[c]
            ax.scatter(px[:, idx].ravel() / fx, py[:, idx].ravel() / fy, s=4, color=col, alpha=0.12,
                       lw=0, rasterized=True)
            ax.scatter(od[xo].values[idx] / fx, od[yo].values[idx] / fy, s=12, color=col,
                       edgecolor="black", linewidth=0.4, zorder=3, gid="data")
            _, ys, on_grid = curves[p * len(palette) + c]  # markers where the main panels have them
            ax.plot(ys[xo] / fx, ys[yo] / fy, color=col, zorder=4,
                    **({"lw": 1.6} if on_grid else _MEDIAN_MARK))
        ax.set_xlabel(axis_label(xo, units.get(xo)))
        ax.set_ylabel(axis_label(yo, units.get(yo)))
        ax.set_xscale(spec["yscale"])
        ax.set_yscale(spec["yscale"])
