"""The report's tables as text: cells, file names, Markdown, and the sentences read beside them.

A table is shown as ``{columns, rows, text}`` of formatted cells (:func:`cells`), the same in
the HTML page and in ``summary.md`` (:func:`markdown`); its CSV is written by pandas beside it.
"""

import math
import re

import numpy as np
import pandas as pd
from markupsafe import Markup, escape

from skinfit.io.labels import display_unit_map
from skinfit.io.units import pretty_unit, to_si
from skinfit.results.summary import format_numbers, is_estimate_column

__all__ = ["file_part", "unique_name", "cell_text", "cells", "not_applicable", "markdown", "level_names",
           "base_name", "defang", "break_at_underscores", "ranking_note", "display_units", "shown_unit", "unit_or_dash",
           "unit_cell", "population_units", "effect_units", "in_display_unit"]


def file_part(text):
    """``text`` with every run of characters other than letters, digits, ``_``, ``.`` and ``-``
    replaced by ``_``: safe inside a file name on every platform."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text)


def unique_name(base, taken):
    """``base``, or ``base_2``, ``base_3``... the first not in ``taken`` (which it joins): one
    file name per fit or table of a report, also for names that differ only in characters
    :func:`file_part` replaces (``d[subject=Zoë]``, ``d[subject=Zoé]``; model ids ``a+b``, ``a_b``)."""
    key, k = base, 2
    while key in taken:
        key, k = f"{base}_{k}", k + 1
    taken.add(key)
    return key


def cell_text(value, na=False):
    """Table cell text of a value :func:`skinfit.results.summary.format_numbers` left as it was
    (a float only where no table rounds it: 4 significant digits); a NaN is ``n/a`` in a cell
    that has no value by construction (``na``), else ``nan``."""
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return ("n/a" if na else "nan") if math.isnan(value) else f"{value:.4g}"
    if na and value == "nan":
        return "n/a"
    return "" if value is None else value if isinstance(value, Markup) else str(value)


def cells(df, index_name, na=None, sd=None):
    """A DataFrame as {columns, rows, text} of formatted cells, the index as first column;
    ``text[k]`` is True for a column of words (left-aligned and wrapped in the page). Numbers
    at the precision their uncertainty allows (:func:`skinfit.results.summary.format_numbers`;
    ``sd``: each row's posterior sd when the table has no ``sd`` column); the CSV beside the
    table keeps every digit. ``na``: a boolean array (rows, columns) of the cells that have no
    value by construction (see :func:`not_applicable`), shown as ``n/a`` rather than ``nan``
    (a number not computed)."""
    na = np.zeros(df.shape, dtype=bool) if na is None else np.asarray(na, dtype=bool)
    shown = format_numbers(df, sd)
    return {"columns": [index_name] + [str(c) for c in df.columns],
            "rows": [[cell_text(i)] + [cell_text(v, a) for v, a in zip(row, flags)]
                     for i, row, flags in zip(df.index, shown.itertuples(index=False), na)],
            "text": [True] + [not (pd.api.types.is_numeric_dtype(df[c]) and not pd.api.types.is_bool_dtype(df[c]))
                              for c in df.columns]}


def not_applicable(df, columns, rows=None):
    """(rows, columns) mask of ``df``: True in ``columns`` on the rows where ``rows`` (a boolean
    array; every row when None) holds, the cells that have no value by construction: a derived
    quantity's MAP, tau and contraction (it has no prior), a population's derived rows' R-hat
    and ESS (those of ``mu`` and ``tau``, from which they are computed, are on their own rows),
    a contrast's ratio A / B where B's draws change sign."""
    rows = np.ones(len(df), dtype=bool) if rows is None else np.asarray(rows, dtype=bool)
    return rows[:, None] & np.isin(np.asarray(df.columns, dtype=object), columns)[None, :]


def markdown(shown):
    """A table of :func:`cells` as a Markdown table (``|`` in a cell escaped)."""
    def esc(text):
        return text.replace("|", "\\|")

    lines = ["| " + " | ".join(esc(c) for c in shown["columns"]) + " |",
             "|" + "|".join("---" for _ in shown["columns"]) + "|"]
    lines += ["| " + " | ".join(esc(c) for c in row) + " |" for row in shown["rows"]]
    return "\n".join(lines)


def level_names(fit):
    """Summary row name -> the same name with its condition spelled out, for every parameter or
    derived quantity indexed by a condition: ``gamma[0.5]`` -> ``gamma[actuation_force=0.5 N]``,
    ``beta_h[M10]`` -> ``beta_h[material=M10]`` (levels in the units the data came in)."""
    units = fit.attr("units")
    out = {}
    for group in ("posterior", "derived"):
        try:
            ds = fit.group(group)
        except (KeyError, ValueError):
            continue
        for var in ds.data_vars:
            dims = [d for d in ds[var].dims if d not in ("chain", "draw")]
            if len(dims) != 1:
                continue
            cols = dims[0].split(",")
            for level in ds[dims[0]].values:
                parts = str(level).split(",")
                if len(parts) != len(cols):
                    continue
                named = ", ".join(f"{c}={v}" + (f" {units[c]}" if units.get(c) not in (None, "1", "-") else "")
                                  for c, v in zip(cols, parts))
                out[f"{var}[{level}]"] = f"{var}[{named}]"
    return out


def base_name(slot_name):
    """A summary row's parameter: ``gamma`` of ``gamma[0.5]``."""
    return slot_name.split("[", 1)[0]


def defang(text):
    """Embedded texts (cards, prior files) keep their words, not clickable network addresses."""
    return re.sub(r"\b(https?|ftp)://", r"\1[:]//", text)


def break_at_underscores(value):
    """A table cell's text, escaped, with a line-break opportunity (``<wbr>``) after each
    underscore: a narrow column breaks ``contact_area_no_levitation`` between its words, not
    inside one."""
    return escape(value).replace("_", Markup("_<wbr>"))


def ranking_note(table):
    """A sentence when log evidence and LOO rank the models differently, else None.

    ``table`` as :func:`skinfit.compare` returns it (columns ``model`` or index, ``log_z``,
    ``elpd_loo``)."""
    if not {"log_z", "elpd_loo"} <= set(table.columns):
        return None
    t = table.set_index("model") if "model" in table.columns else table
    by_z = list(t["log_z"].sort_values(ascending=False).index)
    by_loo = list(t["elpd_loo"].sort_values(ascending=False).index)
    if by_z == by_loo:
        return None
    return (f"Evidence and LOO rank these models differently: by log Z {' > '.join(map(str, by_z))}; "
            f"by ELPD (LOO) {' > '.join(map(str, by_loo))}. The evidence Z = p(data | model) averages the "
            "likelihood over the prior, so it rewards a model whose priors put mass where the data are and "
            "penalises wide priors; LOO's ELPD scores how well the fitted posterior predicts each left-out row, "
            "whatever the prior. Where they disagree, the winner by evidence is favoured as a whole-model "
            "explanation under these priors, the winner by LOO as a predictor of new rows like these; "
            "check the standard errors before reading either difference.")


def unit_cell(unit):
    """A unit as a table cell: as a physicist writes it (``N·s/m``, ``m²/N<sup>m</sup>``),
    markup for the page (:func:`skinfit.io.units.pretty_unit`)."""
    return Markup(pretty_unit(unit, html=True)) if isinstance(unit, str) and unit else unit


def shown_unit(parameter, display, si_units):
    """(factor, unit): the unit a parameter's values are shown in (``parameter`` a summary row's
    name, ``gamma[0.5]`` read as ``gamma``), the card's display unit where ``display`` names one,
    else its SI unit from ``si_units`` ('' when unknown), and the factor SI values are divided by."""
    base = base_name(str(parameter))
    shown = display.get(base)
    return (to_si(shown), shown) if shown else (1.0, si_units.get(base, ""))


def unit_or_dash(unit):
    """A unit cell (:func:`unit_cell`), ``-`` for a dimensionless or unknown unit."""
    return "-" if unit in ("", "1", "-") else unit_cell(unit)


def display_units(shown, fit):
    """Summary rows ``shown`` (a ``unit`` column, values in SI) with each parameter that its
    model card gives a ``display_unit`` converted to it (its estimates, interval ends and sd;
    for display only: the CSV stays in SI), and every unit written by :func:`unit_cell`."""
    display = display_unit_map(fit)
    out = shown.copy()
    scaled = [out.columns.get_loc(c) for c in out.columns if c == "sd" or is_estimate_column(c)]
    out.iloc[:, scaled] = out.iloc[:, scaled].astype(float)
    units = list(out["unit"])
    for i, name in enumerate(out.index):
        factor, unit = shown_unit(name, display, {})
        if unit:  # the card names a display unit: else the row keeps its own unit
            out.iloc[i, scaled] = out.iloc[i, scaled] / factor
            units[i] = unit
    out["unit"] = [unit_cell(u) for u in units]
    return out


def population_units(hyper, display, si_units):
    """A population's hyper-parameter rows ``hyper`` (indexed by parameter; ``quantity``,
    ``coordinate``, ``estimate``, ``sd``, ``lower``, ``upper`` in SI) with a ``unit`` column after
    ``quantity``, for display (the CSV stays in SI). A row in natural units (mean, sd, median;
    mu and tau of a normal family) is shown in the card's ``display_unit`` (``display``:
    parameter -> unit) where it names one, else in its SI unit (``si_units``). ``mu`` of a log
    coordinate is the natural log of the value in that unit, ``ln(kPa)`` (shifted by
    ``-ln(to_si(display_unit))``), so that ``exp(mu)`` is the median in it; ``tau`` of a log
    coordinate (an sd of that log) and correlations are dimensionless, ``-``."""
    out = hyper.copy()
    for c in ("estimate", "lower", "upper", "sd"):
        out[c] = out[c].astype(float)
    units = []
    ends = [out.columns.get_loc(c) for c in ("estimate", "lower", "upper")]
    sd = out.columns.get_loc("sd")
    for i, (name, row) in enumerate(zip(out.index, out.itertuples(index=False))):
        factor, unit = shown_unit(name, display, si_units)
        dimensionless = unit in ("", "1", "-")
        if row.quantity == "corr" or (row.coordinate == "log" and (row.quantity == "tau" or dimensionless)):
            units.append("-")
        elif row.coordinate == "log":
            out.iloc[i, ends] = out.iloc[i, ends] - math.log(factor)
            units.append(Markup("ln(") + unit_cell(unit) + Markup(")"))
        else:
            out.iloc[i, [*ends, sd]] = out.iloc[i, [*ends, sd]] / factor
            units.append(unit_or_dash(unit))
    out.insert(list(out.columns).index("quantity") + 1, "unit", units)
    return out


def in_display_unit(table, parameter, display, si_units):
    """(table, unit cell): a table of one parameter's values in SI (estimate and interval
    columns, ``sd``) converted to the card's ``display_unit`` where it names one, for display
    (the CSV stays in SI), and the unit its values are now in."""
    factor, unit = shown_unit(parameter, display, si_units)
    table = table.assign(**{c: table[c] / factor for c in table.columns if c == "sd" or is_estimate_column(c)})
    return table, unit_cell(unit)


def effect_units(effects, display, si_units):
    """A population's effects table (:meth:`PopulationResult.effects`, values in SI) for display,
    with a ``unit`` column after ``question``: a population value or a difference of means in
    the parameter's display unit (estimate, sd and interval ends converted) or SI unit, a ratio
    of medians dimensionless (``-``)."""
    out = effects.copy()
    values = [out.columns.get_loc(c) for c in out.columns if c == "sd" or is_estimate_column(c)]
    units = []
    for i, (parameter, question) in enumerate(zip(out["parameter"], out["question"])):
        if question == "ratio of medians":
            units.append("-")
            continue
        factor, unit = shown_unit(str(parameter).split(" vs ")[0], display, si_units)
        out.iloc[i, values] = out.iloc[i, values].astype(float) / factor
        units.append(unit_or_dash(unit))
    out.insert(list(out.columns).index("question") + 1, "unit", units)
    return out
