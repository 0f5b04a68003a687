"""The report's sections on many fits of one model: subjects, their population, contrasts.

:func:`subjects_section` tabulates each parameter per subject (labels as the user wrote them
in the data, e.g. ``S01`` of ``subject=S01``); :func:`population_section` shows a population
result (hyper-parameters, shrunk beside separate estimates) through :class:`PopulationView`,
the one adapter that knows the population result's accessors; :func:`contrast_section`
shows contrast tables (:mod:`skinfit.analysis.contrasts`) with each pair's probability of direction.
:func:`across_fits` puts them together for each model with several fits in a report, with a
forest plot of each parameter across the fits. Each section returns plain dicts of tables and
figure jobs for :mod:`skinfit.report.html`.
"""

import re
import tomllib
import warnings
from dataclasses import replace
from pathlib import Path
from statistics import NormalDist

import numpy as np
import pandas as pd

from skinfit.analysis.contrasts import fit_contrasts, level_contrasts
from skinfit.analysis.population.inputs import subject_digest
from skinfit.analysis.population.population import population as fit_population
from skinfit.analysis.population.result import DERIVED
from skinfit.errors import InputError
from skinfit.io.labels import display_unit_map, parameter_units
from skinfit.report.checks import NOT_CONVERGED_ATTR, population_issues
from skinfit.report.tables import (
    base_name,
    cells,
    effect_units,
    file_part,
    in_display_unit,
    not_applicable,
    population_units,
    unique_name,
)
from skinfit.results.intervals import CI_PROB, interval_columns, interval_name
from skinfit.results.run_labels import run_labels

__all__ = ["CONTRAST_ROWS", "contrast_display", "contrast_sentence", "shown_population_rows",
           "subject_label", "row_labels", "PopulationView", "subjects_section", "population_section",
           "contrast_section", "population_parameters", "group_analyses", "hyperprior_table", "sampler_text",
           "population_for", "across_fits", "card_ropes"]


def subject_label(fit):
    """The group a fit was made on, as written in the data: ``S01`` for a dataset id
    ``contact_area_synthetic[subject=S01]`` (``subject=S01, session=2`` -> ``S01, 2``); the
    dataset id itself when the fit used a whole dataset."""
    m = re.search(r"\[(.*)\]$", fit.dataset_id)
    if not m:
        return fit.dataset_id
    parts = [p.split("=", 1)[-1] for p in m.group(1).split(",")]
    return ", ".join(parts)


def population_parameters(fit):
    """Default parameters of a report's population: the scalar (not split) physical parameters,
    noise scales left out, in the model card's order (those of ``skinfit population``'s
    default but for the split parameters' levels)."""
    names = [s["name"] for s in fit.attr("slots") if s["level"] is None]
    return [n for n in names if not re.match(r"^(sigma|nu)(_|$)", n)]


class PopulationView:
    """What the report reads from a population result, in one place.

    Works with :class:`skinfit.analysis.population.population.PopulationResult` (``parameters``, ``subjects``,
    ``summary()``, ``subject_summary()``, ``hyperpriors``, ``sampler``); a result type with
    other accessors needs only this class changed.
    """

    def __init__(self, result, ci_prob=CI_PROB):
        self.result = result
        self.ci_prob = ci_prob
        self._hyper = None

    @property
    def parameters(self):
        return list(self.result.parameters)

    @property
    def subjects(self):
        return list(self.result.subjects)

    def hyper_table(self):
        """Per parameter and quantity (population mean, sd, median; mu, tau in the sampling
        coordinate; correlations): estimate (median), sd and HDI at the view's ``ci_prob``.
        Computed once per view (with the R-hat and ESS of every hyper-parameter): the report
        reads it per parameter."""
        if self._hyper is None:
            self._hyper = self.result.summary(self.ci_prob)
        return self._hyper.copy()

    def subject_table(self):
        """Per subject and parameter: separate-fit and shrunk median and HDI at ``ci_prob``."""
        return self.result.subject_summary(self.ci_prob)

    def hyperpriors(self):
        return {k: v for k, v in dict(getattr(self.result, "hyperpriors", {}) or {}).items() if not k.startswith("_")}

    def effects(self):
        """Conditions as effects (a slope with a condition against 0, split levels against the
        first): probabilities and intervals; None when the result has no such questions."""
        effects = getattr(self.result, "effects", None)
        table = effects(self.ci_prob) if callable(effects) else None
        return table if table is not None and len(table) else None

    def warnings(self):
        return list(getattr(self.result, "warnings", []) or [])

    def sampler(self):
        return dict(getattr(self.result, "sampler", {}) or {})

    def origin(self):
        """The file the result was read from; empty when it was computed for the report."""
        return getattr(self.result, "origin", "") or ""

    def correlation_prior(self):
        """The prior of the correlations of a correlated population; None for an independent one."""
        return (dict(getattr(self.result, "hyperpriors", {}) or {}).get("_correlation") or {}).get("prior")

    def population_interval(self, parameter):
        """The population distribution of ``parameter`` (natural units) at the posterior medians
        of its hyper-parameters: median and central range of the view's ``ci_prob`` (94%:
        ``mu -+ 1.881 tau``) in the sampling coordinate (exponentiated for a log coordinate),
        i.e. where that share of subjects is expected to lie; None when the result has no such rows."""
        t = self.hyper_table()
        rows = t[t["parameter"] == parameter].set_index("quantity")
        if not {"mu", "tau"} <= set(rows.index):
            return None
        mu, tau = float(rows.loc["mu", "estimate"]), float(rows.loc["tau", "estimate"])
        back = np.exp if rows.loc["mu", "coordinate"] == "log" else (lambda v: v)
        z = NormalDist().inv_cdf(0.5 + self.ci_prob / 2)
        return {"median": float(back(mu)), "lo": float(back(mu - z * tau)), "hi": float(back(mu + z * tau))}


def subjects_section(fits, ci_prob=CI_PROB):
    """Per parameter, a table of each subject's posterior (mean, sd, HDI at ``ci_prob``, R-hat, ESS).

    ``fits``: {key: Fit} of one model. Returns {"labels": {key: label}, "tables": {parameter:
    DataFrame indexed by subject label}}: a row per fit, fits of one subject told apart by
    :func:`row_labels`.
    """
    labels = row_labels(fits)
    summaries = {key: f.summary(ci_prob) for key, f in fits.items()}
    lower, upper = interval_columns(ci_prob)
    first = next(iter(fits.values()))
    tables = {}
    for s in first.attr("slots"):
        name = s["name"]
        rows = {}
        for key, table in summaries.items():
            if name in table.index:
                r = table.loc[name]
                rows[labels[key]] = {"mean": r["mean"], "sd": r["sd"], lower: r[lower],
                                     upper: r[upper], "r_hat": r["r_hat"], "ess_bulk": r["ess_bulk"]}
        if rows:
            frame = pd.DataFrame.from_dict(rows, orient="index")
            frame.index.name = "subject"
            tables[name] = frame
    return {"labels": labels, "tables": tables}


def row_labels(fits):
    """{key: label} of ``fits`` ({key: Fit}): each fit's :func:`subject_label`; fits of one
    label (a subject fitted twice: other seeds, priors, a split) with the options, file or
    content that tell them apart (:func:`skinfit.results.run_labels.run_labels`), e.g. ``S01 [seed 2]``;
    the same fit given twice numbered ``#2``. One row per fit, never one for two."""
    labels = {key: subject_label(f) for key, f in fits.items()}
    alike = {}
    for key, label in labels.items():
        alike.setdefault(label, []).append(key)
    for keys in (k for k in alike.values() if len(k) > 1):
        runs = run_labels([fits[k] for k in keys])
        for key, run in zip(keys, runs):
            labels[key] = f"{labels[key]} {run[len(fits[key].model_id):].strip()}".strip()
    return labels


def population_section(result, ci_prob=CI_PROB):
    """Tables of a population result: hyper-parameters, and shrunk beside separate estimates.

    Returns {"parameters", "hyper": DataFrame, "subjects": {parameter: DataFrame}, "hyperpriors",
    "hyperprior_table": DataFrame, "sampler", "sampler_text", "effects": DataFrame or None,
    "warnings": [text], "origin": the file read or "", "correlation": the correlation prior or
    None, "intervals": {parameter: the population distribution's median and central ``ci_prob`` range}}.
    """
    view = result if isinstance(result, PopulationView) else PopulationView(result, ci_prob)
    hyper = view.hyper_table().set_index(["parameter", "quantity"])
    per = view.subject_table()
    subjects = {}
    for name in view.parameters:
        t = per[per["parameter"] == name].drop(columns="parameter").set_index("subject")
        subjects[name] = t
    return {"parameters": view.parameters, "hyper": hyper, "subjects": subjects,
            "hyperpriors": view.hyperpriors(), "hyperprior_table": hyperprior_table(view.hyperpriors()),
            "sampler": view.sampler(), "sampler_text": sampler_text(view.sampler()), "effects": view.effects(),
            "warnings": view.warnings(), "origin": view.origin(), "correlation": view.correlation_prior(),
            "intervals": {p: view.population_interval(p) for p in view.parameters}}


def hyperprior_table(hyperpriors):
    """The hyper-priors as a table, a row per parameter: family, coordinate, the priors of the
    population location ``mu`` and scale ``tau`` (``sd``), and the prior file's prior they were
    derived from; other entries (``nu`` of a Student-t family) as further columns."""
    named = {"family": "family", "coordinate": "coordinate", "mu": "prior of mu", "sd": "prior of tau",
             "from": "derived from"}
    entries = {name: h for name, h in hyperpriors.items() if isinstance(h, dict)}
    extra = list(dict.fromkeys(k for h in entries.values() for k in h if k not in named))  # nu: Student-t only
    return pd.DataFrame([{**{shown: h.get(key, "") for key, shown in named.items()},
                          **{k: h.get(k, "") for k in extra}} for h in entries.values()],
                        index=pd.Index(list(entries), name="parameter"))


def _range(values):
    values = [float(v) for v in values]
    lo, hi = min(values), max(values)
    return f"{lo:.2f}" if round(lo, 2) == round(hi, 2) else f"{lo:.2f}-{hi:.2f}"


def sampler_text(sampler):
    """One sentence on how a population was sampled, from its sampler record: method, chains,
    sweeps, burn-in and thinning (Gibbs) or steps (reweighting), convergence with the worst
    R-hat and ESS, and per-subject rates as their range; the record's convergence history
    (``checks``) is left to the saved result."""
    if not sampler:
        return ""
    parts = [str(sampler.get("method", "sampler not recorded"))]
    if "chains" in sampler:
        parts.append(f"{sampler['chains']} chains")
    if "sweeps" in sampler:
        parts.append(f"{sampler['sweeps']} sweeps (burn-in {sampler.get('burn', '?')}, thinned by "
                     f"{sampler.get('thin', '?')})")
    if "n_steps" in sampler:
        parts.append(f"{sampler['n_steps']} steps")
    if "draws_per_subject" in sampler:
        parts.append(f"{sampler['draws_per_subject']} draws a subject")
    text = ", ".join(parts)
    if "converged" in sampler:
        text += "; " + ("converged" if sampler["converged"] else "NOT converged")
    worst = [f"max R-hat {float(sampler['rhat_max']):.4f}" if "rhat_max" in sampler else "",
             f"min ESS {float(sampler['ess_min']):.0f}" if "ess_min" in sampler else ""]
    if any(worst):
        text += f" ({', '.join(w for w in worst if w)})"
    rates = []
    if isinstance(sampler.get("acceptance"), dict) and sampler["acceptance"]:
        rates.append(f"acceptance per subject {_range(sampler['acceptance'].values())}")
    if isinstance(sampler.get("scale_acceptance"), (int, float)):  # None: no scale moves (correlated)
        rates.append(f"of the scale moves {float(sampler['scale_acceptance']):.2f}")
    if isinstance(sampler.get("importance_ess"), dict) and sampler["importance_ess"]:
        rates.append(f"importance ESS per subject {_range(sampler['importance_ess'].values())}")
    if rates:
        text += "; " + ", ".join(rates)
    if "seed" in sampler:
        text += f"; seed {sampler['seed']}"
    return text + "."


def _other_fits(result, digests, base):
    """Why the saved population ``result`` is not the one shown for the fits of ``digests``."""
    theirs = set(result.inputs.values())
    why = (f"{len(theirs)} subjects' fits, {len(theirs & set(digests))} of them among the {len(digests)} here"
           if theirs else "it does not record its fits: written by an older skinfit")
    return (f"the population saved in {result.origin or 'a result given'} is not shown: it was made from other "
            f"{result.model_id} fits than those on {base} reported here ({why}); the one shown was computed for "
            f"this report with the defaults (run `skinfit population` again to show yours)")


#: Rows of a contrast table shown in the page (the largest effects); all are in its CSV
CONTRAST_ROWS = 20


def _effect_size(t):
    """How far each contrast's effect is from none: |log ratio| for a ratio, else the
    difference in units of its posterior sd (what sorts a table of ratios and differences)."""
    ratio = t["effect"] == "ratio"
    est = t["estimate"].to_numpy(dtype=float)
    size = np.where(ratio, np.abs(np.log(np.where(ratio, est, 1.0))), 0.0)
    return np.where(ratio, size, np.abs(t["diff_mean"].to_numpy(dtype=float)) / t["sd"].to_numpy(dtype=float))


def contrast_section(table, top=None):
    """A contrast table (:func:`skinfit.analysis.contrasts.fit_contrasts` / ``level_contrasts``)
    with the direction of each pair, sorted by the size of the effect (largest first: a ratio's
    |log|, a difference over its sd); the first ``top`` rows when given. A table of an older
    skinfit without the effect columns is sorted by its probability of direction."""
    t = table.copy()
    if "parameter" in t.columns:  # first, after the pair
        t.insert(2, "parameter", t.pop("parameter"))
    if "prob_direction" not in t.columns:
        t.insert(2, "prob_direction", np.maximum(t["p_greater"], 1 - t["p_greater"]))
    t.insert(3, "direction", np.where(t["p_greater"] >= 0.5, "A > B", "A < B"))
    if "effect" in t.columns:
        t = t.iloc[np.argsort(-_effect_size(t), kind="stable")].reset_index(drop=True)
    else:
        t = t.sort_values("prob_direction", ascending=False, kind="stable").reset_index(drop=True)
    t.attrs = dict(table.attrs)
    return t.head(top) if top else t


def contrast_display(table):
    """The columns of a sorted contrast table a reader needs: the pair, the parameter, the
    effect (ratio or difference) with its sd and HDI, the probability of direction and, with
    a region of practical equivalence, the probability in it (the rest stays in the CSV)."""
    keep = ["A", "B", "parameter", "effect", "estimate", "sd", "lower", "upper", "direction", "prob_direction"]
    if "p_rope" in table.columns and table["p_rope"].notna().any():
        keep.append("p_rope")
    keep = [c for c in keep if c in table.columns]
    return table[keep].set_index("A")


def contrast_sentence(table):
    """One sentence on a contrast table: how many comparisons, of how many parameters, how many
    with a probability of direction above 0.95 (more than one comparison makes some of those
    by chance: read the effects' sizes, not their count)."""
    n = len(table)
    params = table["parameter"].nunique() if "parameter" in table.columns else 1
    strong = int((table["prob_direction"] > 0.95).sum()) if "prob_direction" in table.columns else 0
    ci = interval_name(table.attrs.get("ci_prob", CI_PROB))
    rope = table.attrs.get("rope")
    return (f"{n} comparison{'s' if n != 1 else ''} of {params} parameter{'s' if params != 1 else ''}: the effect "
            f"of A against B (the ratio A / B for a positive parameter, else the difference A − B) with its posterior "
            f"median, sd and {ci}; the probability of direction max(P(A > B), P(A < B)) is above 0.95 in {strong} of "
            f"them. With {n} comparisons, some such probabilities are high by chance: judge the effects by their size "
            f"and interval. Sorted by effect size (|log ratio|, or |difference| / sd)"
            + (f"; region of practical equivalence {rope[0]:g} to {rope[1]:g}, P in it as p_rope" if rope else "")
            + ".")


def card_ropes(fit):
    """Parameter -> the region of practical equivalence of its contrasts the fit's model card
    gives (``rope = [low, high]`` on the effect's scale: a ratio for a positive parameter)."""
    card = tomllib.loads(fit.attrs["model_card"])
    return {p["name"]: tuple(p["rope"]) for p in card.get("parameters", []) if p.get("rope")}


def group_analyses(fits, *, seed=0, min_fits=3, echo=None, cache_dir=None, saved=(), ci_prob=None):
    """Population results and contrasts for the fits of a ``--by`` run or a campaign.

    ``fits``: {key: Fit}. For each model with at least ``min_fits`` fits on groups of datasets
    (dataset ids ``NAME[col=value]``; subjects of several datasets pooled, labelled
    ``NAME/subject`` as ``skinfit population`` labels a campaign's): a population and the
    pairwise contrasts between subjects of its parameters (none when a subject is fitted twice,
    which is said through ``echo``); for every fit with a parameter split by a condition, the
    contrasts between its levels. A failing step is reported through ``echo`` and left out,
    never a partial table. Each contrast table's ``attrs["not_converged"]`` names the fits it
    is drawn from that did not converge (:mod:`skinfit.report.checks`).

    The population is the one of ``saved`` (results of ``skinfit population``, e.g. read by
    :func:`skinfit.analysis.population.population.load_population`) made from exactly these fits, matched by
    content (:func:`skinfit.analysis.population.population.subject_digest` of every subject; labels may differ);
    else it is computed here over :func:`population_parameters` with the default families,
    seeded, and a saved result of the model made from other fits is named in its warnings
    (and through ``echo``), not shown.

    ``cache_dir``: where each computed population is kept by the content of its inputs
    (:func:`skinfit.analysis.population.population.population`'s ``cache``), so a report of the same fits does
    not sample it again.

    ``ci_prob``: probability of the contrasts' highest-density intervals (default 0.94).

    Returns ``(populations {model id: result}, contrasts {title: DataFrame})``.
    """
    prob = CI_PROB if ci_prob is None else ci_prob
    by_model = {}
    for key, f in fits.items():
        base = re.sub(r"\[.*\]$", "", f.dataset_id)
        if base != f.dataset_id:
            by_model.setdefault(f.model_id, []).append((base, key, f))
    populations, contrasts = {}, {}
    for model_id, members in by_model.items():
        bases = sorted({b for b, _, _ in members})
        base = ", ".join(bases)  # subjects of several datasets: one population, labelled dataset/subject
        group, keys, twice = {}, {}, []
        for b, key, f in members:
            label = subject_label(f) if len(bases) == 1 else f"{b}/{subject_label(f)}"
            if label in group:
                twice.append(f"{label} (report keys {keys[label]} and {key})")
            group[label], keys[label] = f, key
        if twice:  # the same subject counted twice would be two subjects to the population
            if echo:
                echo(f"skinfit report: no population or contrasts between subjects for {model_id}: fitted more "
                     f"than once: {'; '.join(twice)}")
            continue
        if len(group) < min_fits:
            continue
        digests = sorted(subject_digest(f) for f in group.values())
        mine = [r for r in saved if r.model_id == model_id]
        match = next((r for r in mine if sorted(r.inputs.values()) == digests), None)
        names = population_parameters(next(iter(group.values())))
        if match is not None:
            populations[model_id] = match
        else:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    stem = file_part(f"{model_id}__{'__'.join(bases)}")
                    cache = None if cache_dir is None else Path(cache_dir) / f"population_{stem}.npz"
                    result = fit_population(group, names, rng=seed, cache=cache)
                notes = [_other_fits(r, digests, base) for r in mine]
                for note in notes:
                    if echo:
                        echo(f"skinfit report: {note}")
                populations[model_id] = replace(result, warnings=[*result.warnings, *notes]) if notes else result
            except (InputError, ValueError, RuntimeError) as exc:
                if echo:
                    echo(f"skinfit report: no population for {model_id} on {base}: {exc}")
        rows = []
        ropes = card_ropes(next(iter(group.values())))
        for name in names:
            try:
                rows.append(fit_contrasts(group, name, rng=seed, prob=prob, rope=ropes.get(base_name(name)))
                            .assign(parameter=name))
            except (InputError, ValueError) as exc:
                if echo:
                    echo(f"skinfit report: no contrasts of {name} for {model_id}: {exc}")
        if rows:
            table = pd.concat(rows, ignore_index=True)
            table.attrs.update(ci_prob=prob, ci_kind="hdi")
            table.attrs[NOT_CONVERGED_ATTR] = [label for label, f in group.items() if not f.converged]
            contrasts[f"{model_id} on {base}: between subjects"] = table
    for (_key, f), label in zip(fits.items(), run_labels(fits.values())):  # two split fits: each its own table
        split = {s["base"] for s in f.attr("slots") if s["level"] is not None}
        ropes = card_ropes(f)
        rows = [level_contrasts(f, name, prob=prob, rope=ropes.get(name)).assign(parameter=name)
                for name in sorted(split)]
        if rows:
            table = pd.concat(rows, ignore_index=True)
            table.attrs.update(ci_prob=prob, ci_kind="hdi")
            table.attrs[NOT_CONVERGED_ATTR] = [] if f.converged else [f"{label} on {f.dataset_id}"]
            contrasts[f"{label} on {f.dataset_id}: between conditions"] = table
    return populations, contrasts


def population_for(population, model_id, parameter):
    """The population distribution of ``parameter`` given to a report (``write_report``'s
    ``population``: {parameter: distribution}, also keyed by model id first, or a DataFrame
    indexed by parameter) for the fits of ``model_id``; None when it has none."""
    if population is None:
        return None
    if isinstance(population, pd.DataFrame):
        return population.loc[parameter].to_dict() if parameter in population.index else None
    if model_id in population and isinstance(population[model_id], dict):
        return population[model_id].get(parameter)
    return population.get(parameter)


def shown_population_rows(hyper):
    """Which rows of a population's hyper table (index parameter, column ``quantity``) the page
    shows: a derived row (mean, median, population sd) equal to the sampled ``mu`` or ``tau``
    row of its parameter in estimate and interval (a normal family: mean = median = mu, sd =
    tau) is left to the CSV."""
    keep = np.ones(len(hyper), dtype=bool)
    for i, (name, row) in enumerate(zip(hyper.index, hyper.itertuples(index=False))):
        twin = {"mean": "mu", "median": "mu", "sd": "tau"}.get(row.quantity)
        if twin is None:
            continue
        other = hyper[(hyper.index == name) & (hyper["quantity"] == twin)]
        cols = ["estimate", "lower", "upper"]
        if len(other) and np.allclose(other[cols].to_numpy(dtype=float)[0], [getattr(row, c) for c in cols],
                                      rtol=1e-9, atol=0):
            keep[i] = False
    return keep


def across_fits(items, figdir, population, populations, out_dir, jobs, ci_prob=CI_PROB):
    """Per model with several fits (subjects, conditions): a table of each parameter across the
    fits, one figure of forest plots of every parameter side by side, the fits labelled by subject
    as written in the data, and the model's population result when given. The figure's job is
    appended to ``jobs`` (drawn with the
    fits' own figures by :func:`skinfit.report.figures.render_figures`)."""
    by_model = {}
    index = {key: i for i, (key, _) in enumerate(items)}
    for key, fit in items:
        by_model.setdefault(fit.model_id, []).append((key, fit))
    out, taken = [], set()
    for model_id, group in by_model.items():
        if len(group) < 2:
            continue
        safe = unique_name(file_part(model_id), taken)
        subj = subjects_section(dict(group), ci_prob)
        display, si_units = display_unit_map(group[0][1]), parameter_units(group[0][1])
        labelled = {subj["labels"][k]: f for k, f in group}
        if len(labelled) < len(group):  # the same subject label twice: keep the unique keys
            labelled = dict(group)
        tables = []
        for pname, table in subj["tables"].items():
            stem = f"subjects_{safe}_{file_part(pname)}"
            table.to_csv(out_dir / f"{stem}.csv")
            shown, unit = in_display_unit(table, pname, display, si_units)
            tables.append({"parameter": pname, "csv": f"{stem}.csv", "table": cells(shown, "subject"), "unit": unit})
        pop_result = populations.get(model_id)
        pop_info = population_section(pop_result, ci_prob) if pop_result is not None else None
        if pop_info is not None:
            pop_info["hyper"].to_csv(out_dir / f"population_{safe}.csv")
            if pop_info["effects"] is not None:
                pop_info["effects"].to_csv(out_dir / f"population_effects_{safe}.csv", index=False)
            hyper = pop_info["hyper"].reset_index().set_index("parameter")
            hyper = hyper[shown_population_rows(hyper)]  # rows equal to another: in the CSV alone
            hyper = population_units(hyper, display, si_units)  # in the card's display units, each row's unit named
            derived = hyper["quantity"].isin(DERIVED)  # computed from mu and tau
            pop_tables = {"hyper": cells(hyper, "parameter",
                                         not_applicable(hyper, ["r_hat", "ess_bulk", "ess_tail"], derived)),
                          "csv": f"population_{safe}.csv",
                          "subjects": [{"parameter": k, "table": cells(shown, "subject"), "unit": unit}
                                       for k, v in pop_info["subjects"].items()
                                       for shown, unit in [in_display_unit(v, k, display, si_units)]],
                          "hyperpriors": cells(pop_info["hyperprior_table"], "parameter"),
                          "effects": None if pop_info["effects"] is None else
                          cells(effect_units(pop_info["effects"], display, si_units).set_index("parameter"),
                                "parameter"),
                          "warnings": pop_info["warnings"], "origin": pop_info["origin"],
                          "issues": population_issues(pop_result), "converged": bool(pop_result.converged),
                          "correlation": pop_info["correlation"], "sampler": pop_info["sampler_text"]}
        else:
            pop_tables = None
        figures = []
        entry = {"model_id": model_id, "fits": list(labelled), "figures": figures, "tables": tables,
                 "population": pop_tables, "id": f"across-{len(out) + 1}"}
        labels = {label: index[k] for label, (k, _) in zip(labelled, group)}
        pops = {}
        pnames = list(group[0][1].group("posterior").data_vars)
        for pname in pnames:
            pop = population_for(population, model_id, pname)
            if pop is None and pop_info is not None:
                pop = pop_info["intervals"].get(pname)
            if pop is not None:
                pops[pname] = pop
        path = figdir / f"across_{safe}.png"  # every parameter side by side, one panel each, the fits as rows
        caption = (f"{', '.join(pnames)} across {len(group)} fits (a panel each): posterior mean and "
                   f"{interval_name(ci_prob)}" + (f"; population distribution of {', '.join(pops)} "
                                                  f"(median, central {100 * ci_prob:g}%)" if pops else ""))
        figures.append({"file": f"figures/{path.name}", "caption": caption,
                        "alt": f"forest plots of {', '.join(pnames)} across the fits of {model_id}"})
        jobs.append({"fit": labels, "func": "plot_forest", "args": (pnames,),
                     "kwargs": {"population": pops, "ci_prob": ci_prob}, "path": path, "entry": figures[-1],
                     "across": entry})
        out.append(entry)
    return out
