"""A parameter across fits, subjects and conditions, with its population (:func:`plot_forest`)."""

import re
from statistics import NormalDist

import numpy as np
import pandas as pd
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator

from skinfit.errors import InputError
from skinfit.io.labels import display_unit_map
from skinfit.plots.reading import param_label, parameter_units
from skinfit.plots.style import (
    COLOURS,
    MAX_WIDTH,
    MIN_FONT,
    finish_figure,
    log_ticks,
    new_figure,
    plain_scale,
    suptitle,
    wrap_title,
)
from skinfit.results.fit import Fit, as_fit
from skinfit.results.intervals import CI_PROB, check_ci, interval_columns, interval_name

__all__ = ["plot_forest"]


def _forest_rows(items, parameter, ci_prob=CI_PROB):
    """(label, mean, lo, hi) rows (the HDI at ``ci_prob``), the parameter's unit, its card's
    display unit (None when it names none or only tables are given) and the labels of pooled fits
    (:func:`_pooled`) from fits and/or summary tables (a table holds that HDI's columns,
    :func:`~skinfit.results.intervals.interval_columns`)."""
    lower, upper = interval_columns(ci_prob)
    if isinstance(items, dict):
        pairs = list(items.items())
    else:
        items = list(items) if isinstance(items, (list, tuple)) else [items]
        fits = [i if isinstance(i, pd.DataFrame) else as_fit(i) for i in items]
        datasets = {f.dataset_id for f in fits if isinstance(f, Fit)}
        models = {f.model_id for f in fits if isinstance(f, Fit)}
        pairs = []
        for k, f in enumerate(fits):
            if len(fits) == 1:
                label = ""
            elif not isinstance(f, Fit):
                label = str(k)
            elif len(datasets) > 1 and len(models) > 1:
                label = f"{f.model_id} / {f.dataset_id}"
            else:
                label = _selection(f.dataset_id) if len(datasets) > 1 else f.model_id
            pairs.append((label, f))
    rows, unit, display, pooled = [], None, None, _pooled(pairs)
    pattern = re.compile(rf"^{re.escape(parameter)}(\[(.*)\])?$")
    for label, item in pairs:
        if not isinstance(item, pd.DataFrame):
            item = as_fit(item)
            unit = unit or parameter_units(item).get(parameter)
            display = display or display_unit_map(item).get(parameter)
            table = item.summary(ci_prob)
            post = item.group("posterior")
            dims = ([d for d in post[parameter].dims if d not in ("chain", "draw")]
                    if parameter in post.data_vars else [])
        else:
            table, dims = item, []
            if not {lower, upper} <= set(table.columns):
                raise InputError("plot_forest", f"a summary table without the columns {lower!r}, {upper!r} "
                                                f"of the {interval_name(ci_prob)}")
        for name in table.index:
            m = pattern.match(str(name))
            if not m:
                continue
            level = m.group(2)
            level_text = f"{dims[0]} = {level}" if level is not None and dims else level
            text = " · ".join(t for t in (str(label), level_text) if t) or parameter
            rows.append((text, float(table.loc[name, "mean"]), float(table.loc[name, lower]),
                         float(table.loc[name, upper])))
    pooled = {text for text, *_ in rows if text.split(" · ")[0] in pooled}
    return rows, unit, display, pooled


def _population_interval(spec, ci_prob=CI_PROB):
    """(centre, lo, hi) of a population distribution given as a mapping, draws or a scipy dist:
    its central ``ci_prob`` range (a mapping's ``lo``/``hi`` as given)."""
    tail = (1 - ci_prob) / 2
    if hasattr(spec, "ppf"):
        lo, mid, hi = spec.ppf([tail, 0.5, 1 - tail])
        return float(mid), float(lo), float(hi)
    if isinstance(spec, dict):
        if "mean" in spec and "sd" in spec and not {"lo", "hi"} & set(spec):
            m, sd = float(spec["mean"]), float(spec["sd"])
            z = NormalDist().inv_cdf(1 - tail)  # central ci_prob of a normal (1.881 at 0.94)
            return m, m - z * sd, m + z * sd
        lower, upper = interval_columns(ci_prob)
        centre = float(spec.get("median", spec.get("mean")))
        return centre, float(spec.get("lo", spec.get(lower))), float(spec.get("hi", spec.get(upper)))
    draws = np.asarray(spec, dtype=float).ravel()
    lo, mid, hi = np.quantile(draws, [tail, 0.5, 1 - tail])
    return float(mid), float(lo), float(hi)


def _selection(dataset_id):
    """``S01`` for a dataset id ``contact_area_synthetic[subject=S01]`` (the levels it selects),
    the id itself for a whole dataset."""
    m = re.search(r"\[(.*)\]$", dataset_id)
    return dataset_id if not m else ", ".join(p.split("=", 1)[-1] for p in m.group(1).split(","))


def _pooled(pairs):
    """Labels of the fits made on a whole dataset among fits of its subsets (a dataset id without
    ``[column=level]``, beside ones with): the pooled fit, never drawn as a subject."""
    ids = {label: item.dataset_id for label, item in pairs if isinstance(item, Fit)}
    if not any("[" in d for d in ids.values()):
        return set()
    return {label for label, d in ids.items() if "[" not in d}


def plot_forest(fits_or_tables, parameter, path=None, *, population=None, unit=None, ci_prob=CI_PROB):
    """Posterior mean and HDI (at ``ci_prob``) of a parameter across fits (subjects, conditions) and levels;
    several parameters side by side, one panel each, sharing the rows.

    Parameters
    ----------
    fits_or_tables : Fit, summary DataFrame, or a list / dict (label -> item) of them
        A parameter split by a column gives one row per level. A fit of a whole dataset among
        fits of its subjects is drawn apart, as the pooled fit (open grey square), never as a
        subject.
    parameter : str or list of str
        One panel per parameter, in up to four columns.
    population : optional
        The population distribution of the parameter (for several: a mapping parameter ->
        distribution), drawn as a band over all rows and a row of its own: a mapping
        (``mean``/``sd``, or ``median``/``lo``/``hi``), an array of population draws, or a
        frozen scipy.stats distribution (its central ``ci_prob`` interval).
    unit : str, optional
        Unit for the axis label when only tables are given (fits carry their own).
    ci_prob : float
        Probability of the intervals drawn and named in the legend (default 0.94); a summary
        table given must hold that HDI's columns (``hdi_5%``/``hdi_95%`` at 0.9).
    """
    ci_prob = check_ci(ci_prob, "plot_forest")
    ci = interval_name(ci_prob)
    share = f"{100 * ci_prob:g}%"
    names = [parameter] if isinstance(parameter, str) else list(parameter)
    pops = population if not isinstance(parameter, str) else {parameter: population}
    pops = pops if isinstance(pops, dict) and set(pops) <= set(names) else {n: pops for n in names}
    panels = []
    for name in names:
        rows, card_unit, display, pooled = _forest_rows(fits_or_tables, name, ci_prob)
        if not rows:
            raise InputError("plot_forest", f"no parameter {name!r} in the given fits or tables")
        # a unit given here is shown as given (with a prefix where needed); else the card's display unit
        panels.append((name, rows, unit or card_unit, pooled, pops.get(name), None if unit else display))
    labels = list(dict.fromkeys(r[0] for _, rows, *_ in panels for r in rows))
    pooled_labels = [lab for lab in labels if any(lab in p[3] for p in panels)]
    subjects = [lab for lab in labels if lab not in pooled_labels]
    order = subjects + pooled_labels + (["population"] if any(p[4] is not None for p in panels) else [])
    ncols = min(len(panels), 4)
    nrows = -(-len(panels) // ncols)
    fig = new_figure(6.4 if ncols == 1 else MAX_WIDTH, nrows * (0.3 * len(order) + 0.9) + 0.9)
    axes = np.atleast_1d(fig.subplots(nrows, ncols, sharey=True, squeeze=False)).ravel()
    y = {lab: len(order) - 1 - k for k, lab in enumerate(order)}
    for ax, (name, rows, u, pooled, pop, display) in zip(axes, panels):
        _forest_panel(ax, name, rows, u, pooled, pop, y, ci_prob, display)
    for ax in axes[len(panels):]:
        ax.set_visible(False)
    axes[0].set_yticks([y[lab] for lab in order], order)
    for ax in axes:
        ax.tick_params(axis="y", labelsize=MIN_FONT)
        if pooled_labels or "population" in order:  # the subjects apart from what sums them up
            ax.axhline(y[order[len(subjects)]] + 0.5, color="0.5", lw=0.6)
    axes[0].set_ylim(-0.7, len(order) - 0.3)
    handles = [Line2D([], [], color=COLOURS[0], marker="o", ms=4, lw=1.6, label=f"fit: posterior mean, {ci}")]
    if pooled_labels:
        handles.append(Line2D([], [], color="0.45", marker="s", mfc="white", ms=5, lw=1.6,
                              label=f"pooled fit (all data): mean, {ci}"))
    if "population" in order:
        handles.append(Line2D([], [], color="black", marker="D", ms=5, lw=2.2, label=f"population: median, {share}"))
        handles.append(Patch(color="0.6", alpha=0.3, lw=0, label=f"population {share} band"))
    fig.legend(handles=handles, fontsize=MIN_FONT, frameon=False, loc="outside lower center",
               ncols=min(len(handles), 2 if ncols == 1 else 4))
    title = f"{names[0]} across fits and conditions" if len(names) == 1 else "parameters across fits and conditions"
    suptitle(fig, title)
    return finish_figure(fig, path)


def _forest_panel(ax, name, rows, unit, pooled, population, y, ci_prob=CI_PROB, display=None):
    """One parameter's panel: a row per fit (``rows``: label, mean, lo, hi, SI values), the
    pooled fits apart, the population band and row when given; the x axis scaled to plain
    numbers (:func:`~skinfit.plots.style.plain_scale`: the card's ``display`` unit first), its
    limits holding every interval with a margin."""
    values = np.array([v for r in rows for v in r[1:]], dtype=float)
    pop = _population_interval(population, ci_prob) if population is not None else None
    if pop is not None:
        values = np.concatenate([values, pop])
    factor, shown = plain_scale(values, unit, display)
    for part, style in ((False, {"color": COLOURS[0], "marker": "o", "ms": 4}),
                        (True, {"color": "0.45", "marker": "s", "mfc": "white", "ms": 5})):
        chosen = [r for r in rows if (r[0] in pooled) == part]
        if chosen:
            ys = [y[r[0]] for r in chosen]
            mean, lo, hi = (np.array([r[k] for r in chosen]) / factor for k in (1, 2, 3))
            ax.hlines(ys, lo, hi, color=style["color"], lw=1.6)
            ax.plot(mean, ys, ls="none", **style)
    if pop is not None:
        c, plo, phi = (v / factor for v in pop)
        ax.axvspan(plo, phi, color="0.6", alpha=0.2, lw=0)
        ax.axvline(c, color="0.3", lw=0.8, ls="--")
        ax.hlines(y["population"], plo, phi, color="black", lw=2.2)
        ax.plot(c, y["population"], "D", color="black", ms=5)
    lo, hi = np.nanmin(values) / factor, np.nanmax(values) / factor
    if lo > 0 and hi / lo > 20:
        ax.set_xscale("log")
        ax.set_xlim(lo / (hi / lo) ** 0.06, hi * (hi / lo) ** 0.06)
        log_ticks(ax, sparse=True)
    else:
        pad = 0.06 * (hi - lo) if hi > lo else 0.06 * abs(hi) or 1.0
        ax.set_xlim(lo - pad, hi + pad)  # the population's ends inside the axes, never cut at its edge
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.ticklabel_format(axis="x", style="plain", useOffset=False)
    ax.tick_params(axis="x", labelsize=MIN_FONT)
    ax.set_xlabel(wrap_title(param_label(name, shown), ax, MIN_FONT), fontsize=MIN_FONT + 1)
    ax.grid(axis="x", alpha=0.3, lw=0.5)
