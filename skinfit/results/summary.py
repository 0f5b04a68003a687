"""A fit's summary table (:meth:`skinfit.Fit.summary`), its stored copy, and the lines of
:meth:`skinfit.Fit.report_text` about the fit's check and timings.

The table is computed from the tree with arviz_stats (imported when a table is computed: a
report whose fits carry their stored tables imports no statistics), and stored in a saved fit's
root attribute :data:`SUMMARY_ATTR` with the sha256 of what it was computed from.
"""

import json
import tomllib
import warnings

import numpy as np
import pandas as pd

from skinfit.io.labels import round_to_sd
from skinfit.io.priors import parse_prior
from skinfit.results.intervals import CI_KIND, CI_PROB, check_ci, interval_columns

__all__ = ["SUMMARY_ATTR", "SUMMARY_FORMAT", "SUMMARY_COLUMNS", "compute_summary", "summary_to_attr",
           "summary_from_attr", "slot_values", "priors_from_attrs", "misfit_line", "wall_time_text",
           "summary_columns", "format_numbers", "ESTIMATE_COLUMNS", "is_estimate_column"]

#: Root attribute holding a fit's summary table (:meth:`skinfit.Fit.summary`), and the table's
#: format: raise it when the table's columns or their computation change, so older stored tables
#: are computed again.
SUMMARY_ATTR = "summary"
SUMMARY_FORMAT = 1
SUMMARY_COLUMNS = ("unit", "mean", "sd", "hdi_3%", "hdi_97%", "r_hat", "ess_bulk", "ess_tail", "map", "tau",
                   "contraction", "note")


def summary_columns(ci_prob=CI_PROB):
    """The columns of a summary table whose intervals are HDIs at ``ci_prob``
    (:data:`SUMMARY_COLUMNS` at the default 0.94)."""
    lower, upper = interval_columns(ci_prob)
    return tuple({"hdi_3%": lower, "hdi_97%": upper}.get(c, c) for c in SUMMARY_COLUMNS)


def _arviz_summary(tree, ci_prob=CI_PROB, **kwargs):
    """arviz_stats' summary of ``tree`` with HDIs at ``ci_prob``, labelled by
    :func:`skinfit.results.intervals.interval_columns` (``hdi_3%``, ``hdi_97%`` at 0.94), and
    the rows named as skinfit names the sampled slots (``alpha[75]``)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # imported here, not with the module: arviz_stats (and the scipy.stats it imports, ~1 s)
        # is needed only when a table is computed, not by a report that reads the stored ones
        from arviz_stats import summary

        table = summary(tree, ci_kind=CI_KIND, ci_prob=ci_prob, round_to="none", **kwargs)
    lower, upper = interval_columns(ci_prob)
    table = table.rename(columns={table.columns[2]: lower, table.columns[3]: upper})
    table.index = [label.replace("'", "") for label in table.index]
    return table


def compute_summary(fit, ci_prob=CI_PROB):
    """The summary table of :class:`skinfit.Fit` ``fit`` (its columns :func:`summary_columns`;
    see :meth:`skinfit.Fit.summary`), from its tree as held (never its pointwise groups), with
    HDIs at ``ci_prob``."""
    ci_prob = check_ci(ci_prob, "summary")
    tree = fit.partial_tree
    table = _arviz_summary(tree, ci_prob, var_names=list(tree["posterior"].data_vars))
    sampler = fit.attr("sampler")
    post_ds = tree["posterior"].to_dataset()
    priors = priors_from_attrs(fit.attrs)
    rows = {s["name"]: s for s in fit.attr("slots")}
    contraction, notes = [], []
    for name in table.index:
        slot = rows[name]
        c = np.nan
        if slot["base"] in priors:
            prior = priors[slot["base"]]
            q = prior.ppf((np.arange(4000) + 0.5) / 4000)
            values = slot_values(post_ds, slot)
            if prior.lower >= 0:  # the sampling coordinate: log for positive parameters
                q, values = np.log(q), np.log(values)
            c = 1.0 - float(np.var(values)) / float(np.var(q))
        contraction.append(c)
        notes.append("; ".join(["mostly prior: the data barely determine it"] * (c < 0.5)
                               + [f"ON A BOUND: {w['message']}" for w in fit.warnings
                                  if w["check"] == "bound" and w["parameter"] == name]
                               + [f"at a bound (note): {w['message']}" for w in fit.notes
                                  if w["parameter"] == name and w.get("check", "bound") == "bound"]
                               + ["extra scatter beyond the per-row standard errors in the data" for w in fit.notes
                                  if w["parameter"] == name and w.get("check") == "known_se"]))
    table["map"] = [fit.map[n] for n in table.index]
    table["tau"] = [sampler["tau"][n] for n in table.index]
    table["contraction"] = contraction
    table["note"] = notes
    table = pd.concat([table, _derived_summary(tree, ci_prob)])
    table["unit"] = [_unit(tree, n) for n in table.index]
    table = table[list(summary_columns(ci_prob))]
    table.attrs.update(ci_prob=ci_prob, ci_kind=CI_KIND)
    return table


def _derived_summary(tree, ci_prob):
    """Rows of the summary for the ``derived`` group (no MAP, tau or contraction)."""
    if "derived" not in tree.children:
        return None
    table = _arviz_summary(tree, ci_prob, group="derived")
    units = json.loads(tree.attrs["derived"])["quantities"]
    table["note"] = [f"derived [{units[i.split('[')[0]]}]" for i in table.index]
    return table


def _unit(tree, name):
    """SI unit of a summary row (``E_star``, ``alpha[75]``, a derived quantity), from the
    ``units`` attr of its variable in the tree ('' for fits saved without them)."""
    base = name.split("[")[0]
    for group in ("posterior", "derived"):
        if group in tree.children and base in tree[group].data_vars:
            return tree[group][base].attrs.get("units", "")
    return ""


#: Columns of skinfit's tables that are estimates of a quantity, in its unit: shown at the
#: precision its posterior sd allows (:func:`format_numbers`); interval ends are found by name
ESTIMATE_COLUMNS = ("mean", "median", "map", "estimate", "lower", "upper", "separate", "shrunk", "effect")


def is_estimate_column(column):
    """True for a column of estimates or interval ends of a quantity, in its unit (see
    :data:`ESTIMATE_COLUMNS`; ``hdi_3%``, ``diff_lower``, ``shrunk_upper``...)."""
    c = str(column)
    return (c in ESTIMATE_COLUMNS or c.startswith(("hdi_", "eti_", "effect_", "separate_", "shrunk_", "diff_",
                                                   "ratio_", "new_subject_")))


def format_numbers(table, sd=None):
    """The numbers of ``table`` (a DataFrame) as a reader needs them, as text (other cells as
    they are): estimates and interval ends (:data:`ESTIMATE_COLUMNS`, ``hdi_*``...) rounded to
    the decimal place of the second significant digit of their row's posterior sd
    (:func:`skinfit.io.labels.round_to_sd`), the sd to two significant digits; a column ``X``
    beside a column ``X_se`` (``log_z``, ``log_z_se``) to its standard error the same way;
    R-hat and contraction to two decimals, probabilities to two decimals (``>0.99``, ``<0.01``
    beyond), effective sample sizes as integers, other numbers to four significant digits.
    ``sd``: the sd of each row (default: the table's ``sd`` column; without one, estimates get
    three significant digits). The CSV written beside a table keeps every digit."""
    sd = (table["sd"] if "sd" in table.columns else None) if sd is None else sd
    sd = np.full(len(table), np.nan) if sd is None else np.asarray(sd, dtype=float)
    names = [str(c) for c in table.columns]
    out = table.astype(object).copy()
    for j, c in enumerate(names):
        se = table.iloc[:, names.index(f"{c}_se")].to_numpy() if f"{c}_se" in names else None
        for i, value in enumerate(table.iloc[:, j]):
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (float, np.floating)):
                continue
            if np.isnan(value):
                text = "nan"
            elif se is not None:
                text = round_to_sd(value, se[i])
            elif c.endswith("_se"):
                text = round_to_sd(value, value)
            elif c == "sd" or is_estimate_column(c):
                text = round_to_sd(value, sd[i])
            elif c.startswith(("p_", "prob_")):
                text = ">0.99" if value > 0.995 else "<0.01" if value < 0.005 else f"{value:.2f}"
            elif c in ("r_hat", "contraction"):
                text = f"{value:.2f}"
            elif c == "tau":  # autocorrelation time, in steps
                text = f"{value:.2g}" if value < 10 else f"{value:.0f}"
            elif c.startswith("ess") or 1e3 <= abs(value) < 1e9:
                text = f"{value:.0f}"
            else:
                text = f"{value:.4g}"
            out.iat[i, j] = text
    return out


def summary_to_attr(table, key):
    """The summary table as JSON text, with the sha256 ``key`` of its inputs; floats as
    Python writes them (repr: exact round trip), NaN as NaN."""
    columns = [{"name": c, "dtype": str(table[c].dtype), "values": table[c].tolist()} for c in table.columns]
    return json.dumps({"key": key, "index": [str(i) for i in table.index], "columns": columns})


def summary_from_attr(text, key, slots):
    """The table stored by :func:`summary_to_attr` when its key is ``key`` and it has the
    columns of :data:`SUMMARY_COLUMNS` and a row for each of ``slots`` (the sampled parameters'
    names), a value per row in each column; None when absent, of other inputs, or damaged
    (then it is computed again, and the next save rewrites it)."""
    if not isinstance(text, str) or not text:
        return None
    try:
        doc = json.loads(text)
        index, columns = doc["index"], doc["columns"]
        if (doc.get("key") != key or [c["name"] for c in columns] != list(SUMMARY_COLUMNS)
                or not set(slots) <= set(index) or len(set(index)) != len(index)
                or any(len(c["values"]) != len(index) for c in columns)):
            return None
        return pd.DataFrame({c["name"]: pd.Series(c["values"], dtype=c["dtype"], index=index) for c in columns},
                            index=index)
    except (ValueError, TypeError, KeyError, AttributeError):
        return None


def slot_values(posterior, slot):
    """The draws of one sampled slot, flat (chain x draw,): ``posterior`` is a fit's posterior
    group (an xarray Dataset) and ``slot`` an entry of its ``slots`` attribute (``name``,
    ``base``, ``level``); a split parameter's slot selects its level."""
    da = posterior[slot["base"]]
    if slot["level"] is not None:
        dim = next(d for d in da.dims if d not in ("chain", "draw"))
        da = da.sel({dim: slot["level"]})
    return da.values.ravel()


def priors_from_attrs(attrs, check_mass=True):
    """The prior of each parameter, from the prior file's text saved in a fit's root ``attrs``
    (``check_mass``: see :func:`skinfit.io.priors.parse_prior`; without it no scipy.stats)."""
    doc = tomllib.loads(attrs["priors_text"])
    return {k: parse_prior(k, v, "saved priors", check_mass) for k, v in doc.items()
            if k not in ("schema_version", "model", "id")}


def misfit_line(fit):
    """One line on the fit's check of its fit to the data (:mod:`skinfit.inference.misfit`)."""
    if fit.pending:
        return "fit to the data: checked when the pointwise draws are computed (Fit.complete, save, skinfit fit)"
    if "misfit" not in fit.attrs:
        return "fit to the data: not checked (saved before skinfit checked it)"
    r = fit.attr("misfit")
    if r.get("underpowered"):
        return (f"fit to the data: NOT CHECKED: {r['draws']} pointwise draws (memory) cannot give p-values below "
                f"{r['alpha']:g}/{r['m']}")
    pk = r.get("pareto_k")
    bad = [c["check"] for c in r["checks"] if c["warn"]] + (["pareto_k"] if pk and pk["warn"] else [])
    return (f"fit to the data: {'evidence of MISFIT (' + ', '.join(bad) + ')' if bad else 'no misfit found'}: "
            f"{r['m']} posterior-predictive checks on {r['draws']} draws, smallest p "
            f"{min(c['p'] for c in r['checks']):.3g} (warns below {r['alpha']:g}/{r['m']}); PSIS-LOO Pareto k > 0.7 at "
            + (f"{pk['count']} rows" if pk else "- rows (not computed)"))


def wall_time_text(timings, pending=False):
    """The ``timings`` of a fit (its ``attr("timings")``, see :func:`skinfit.fit`) in one line,
    as ``skinfit fit`` and the report's diagnostics show them; with the pointwise groups' time
    once computed ('not computed yet' for a ``pending`` fit; nothing for a fit saved before they
    were timed apart, whose ``tree_s`` includes them)."""
    t = timings
    if t.get("resumed"):
        text = (f"resumed from a checkpoint (MAP {t['map_s']:.2f} s in the first run), sampling "
                f"{t['sampling_s']:.2f} s over all runs, result tree {t['tree_s']:.2f} s, "
                f"this call {t['total_s']:.2f} s")
    else:
        text = (f"MAP {t['map_s']:.2f} s, importance start {t['start_s'] - t['map_s']:.2f} s, "
                f"sampling {t['sampling_s']:.2f} s, result tree {t['tree_s']:.2f} s, total {t['total_s']:.2f} s")
    if "pointwise_s" in t:
        return f"{text}; pointwise log-likelihood and predictive draws {t['pointwise_s']:.2f} s"
    return f"{text}; pointwise log-likelihood and predictive draws not computed yet" if pending else text
