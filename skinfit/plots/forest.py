"""A parameter across fits, subjects and conditions, with its population (:func:`plot_forest`)."""

import re

import numpy as np
import pandas as pd

from skinfit.errors import InputError
from skinfit.plots.reading import param_label, parameter_units
from skinfit.plots.style import COLOURS, MIN_FONT, finish_figure, log_ticks, new_figure, suptitle
from skinfit.results.fit import Fit, as_fit

__all__ = ["plot_forest"]


def _forest_rows(items, parameter):
    """(label, mean, lo, hi) rows and the parameter's unit from fits and/or summary tables."""
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
                label = f.dataset_id if len(datasets) > 1 else f.model_id
            pairs.append((label, f))
    rows, unit = [], None
    pattern = re.compile(rf"^{re.escape(parameter)}(\[(.*)\])?$")
    for label, item in pairs:
        if not isinstance(item, pd.DataFrame):
            item = as_fit(item)
            unit = unit or parameter_units(item).get(parameter)
            table = item.summary()
            post = item.group("posterior")
            dims = ([d for d in post[parameter].dims if d not in ("chain", "draw")]
                    if parameter in post.data_vars else [])
        else:
            table, dims = item, []
        for name in table.index:
            m = pattern.match(str(name))
            if not m:
                continue
            level = m.group(2)
            level_text = f"{dims[0]} = {level}" if level is not None and dims else level
            text = " · ".join(t for t in (str(label), level_text) if t) or parameter
            rows.append((text, float(table.loc[name, "mean"]), float(table.loc[name, "hdi_3%"]),
                         float(table.loc[name, "hdi_97%"])))
    return rows, unit


def _population_interval(spec):
    """(centre, lo, hi) of a population distribution given as a mapping, draws or a scipy dist."""
    if hasattr(spec, "ppf"):
        lo, mid, hi = spec.ppf([0.03, 0.5, 0.97])
        return float(mid), float(lo), float(hi)
    if isinstance(spec, dict):
        if "mean" in spec and "sd" in spec and not {"lo", "hi"} & set(spec):
            m, sd = float(spec["mean"]), float(spec["sd"])
            return m, m - 1.881 * sd, m + 1.881 * sd  # central 94% of a normal
        centre = float(spec.get("median", spec.get("mean")))
        return centre, float(spec.get("lo", spec.get("hdi_3%"))), float(spec.get("hi", spec.get("hdi_97%")))
    draws = np.asarray(spec, dtype=float).ravel()
    lo, mid, hi = np.quantile(draws, [0.03, 0.5, 0.97])
    return float(mid), float(lo), float(hi)


def plot_forest(fits_or_tables, parameter, path=None, *, population=None, unit=None):
    """Posterior mean and 94% HDI of ``parameter`` across fits (subjects, conditions) and levels.

    Parameters
    ----------
    fits_or_tables : Fit, summary DataFrame, or a list / dict (label -> item) of them
        A parameter split by a column gives one row per level.
    parameter : str
    population : optional
        The population distribution of the parameter, drawn as a band over all rows and a
        row of its own: a mapping (``mean``/``sd``, or ``median``/``lo``/``hi``), an array of
        population draws, or a frozen scipy.stats distribution (94% central interval).
    unit : str, optional
        Unit for the axis label when only tables are given (fits carry their own).
    """
    rows, card_unit = _forest_rows(fits_or_tables, parameter)
    if not rows:
        raise InputError("plot_forest", f"no parameter {parameter!r} in the given fits or tables")
    unit = unit or card_unit
    labels = [r[0] for r in rows]
    mean = np.array([r[1] for r in rows])
    lo = np.array([r[2] for r in rows])
    hi = np.array([r[3] for r in rows])
    n = len(rows) + (1 if population is not None else 0)
    fig = new_figure(6.4, 0.32 * n + 1.4)
    ax = fig.subplots()
    y = np.arange(len(rows))[::-1]
    ax.hlines(y, lo, hi, color=COLOURS[0], lw=1.6)
    ax.plot(mean, y, "o", color=COLOURS[0], ms=4, label="mean and 94% HDI")
    ticks, ticklabels = list(y), labels
    values = np.concatenate([lo, hi])
    if population is not None:
        c, plo, phi = _population_interval(population)
        ax.axvspan(plo, phi, color="0.6", alpha=0.2, lw=0)
        ax.axvline(c, color="0.3", lw=0.8, ls="--")
        ax.hlines(len(rows), plo, phi, color="black", lw=2.2)
        ax.plot(c, len(rows), "D", color="black", ms=5, label="population (94%)")
        ticks, ticklabels = ticks + [len(rows)], labels + ["population"]
        values = np.concatenate([values, [plo, phi]])
    ax.set_yticks(ticks, ticklabels, fontsize=8)
    ax.set_ylim(-0.7, n - 0.3)
    if np.all(values > 0) and values.max() / values.min() > 20:
        ax.set_xscale("log")
        log_ticks(ax)
    ax.set_xlabel(param_label(parameter, unit))
    ax.grid(axis="x", alpha=0.3, lw=0.5)
    fig.legend(fontsize=MIN_FONT, frameon=False, loc="outside lower center", ncols=2)
    suptitle(fig, f"{parameter} across fits and conditions")
    return finish_figure(fig, path)
