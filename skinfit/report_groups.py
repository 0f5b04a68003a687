"""The report's sections on many fits of one model: subjects, their population, contrasts.

:func:`subjects_section` tabulates each parameter per subject (labels as the user wrote them
in the data, e.g. ``S01`` of ``subject=S01``); :func:`population_section` shows a population
result (hyper-parameters, shrunk beside separate estimates) through :class:`PopulationView`,
the one adapter that knows the population result's accessors; :func:`contrast_section`
shows contrast tables (:mod:`skinfit.contrasts`) with each pair's probability of direction.
Each section returns plain dicts of tables and figure jobs for :mod:`skinfit.report`.
"""

import re
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["subject_label", "PopulationView", "subjects_section", "population_section", "contrast_section",
           "population_parameters", "group_analyses"]


def subject_label(fit):
    """The group a fit was made on, as written in the data: ``S01`` for a dataset id
    ``contact_area_synthetic[subject=S01]`` (``subject=S01, session=2`` -> ``S01, 2``); the
    dataset id itself when the fit used a whole dataset."""
    m = re.search(r"\[(.*)\]$", fit.dataset_id)
    if not m:
        return fit.dataset_id
    parts = [p.split("=", 1)[-1] for p in m.group(1).split(",")]
    return ", ".join(parts)


def population_parameters(fit, limit=4):
    """Default parameters of a population: the scalar (not split) physical parameters, noise
    scales left out, in the model card's order, at most ``limit``."""
    names = [s["name"] for s in fit.attr("slots") if s["level"] is None]
    return [n for n in names if not re.match(r"^(sigma|nu)(_|$)", n)][:limit]


class PopulationView:
    """What the report reads from a population result, in one place.

    Works with :class:`skinfit.population.PopulationResult` (``parameters``, ``subjects``,
    ``summary()``, ``subject_summary()``, ``hyperpriors``, ``sampler``); a result type with
    other accessors needs only this class changed.
    """

    def __init__(self, result):
        self.result = result

    @property
    def parameters(self):
        return list(self.result.parameters)

    @property
    def subjects(self):
        return list(self.result.subjects)

    def hyper_table(self):
        """Per parameter and quantity (population mean, sd, median; mu, tau in the sampling
        coordinate; correlations): estimate (median) and 95% interval."""
        return self.result.summary()

    def subject_table(self):
        """Per subject and parameter: separate-fit and shrunk median and 95% interval."""
        return self.result.subject_summary()

    def hyperpriors(self):
        return {k: v for k, v in dict(getattr(self.result, "hyperpriors", {}) or {}).items() if not k.startswith("_")}

    def effects(self):
        """Conditions as effects (a slope with a condition against 0, split levels against the
        first): probabilities and intervals; None when the result has no such questions."""
        effects = getattr(self.result, "effects", None)
        table = effects() if callable(effects) else None
        return table if table is not None and len(table) else None

    def warnings(self):
        return list(getattr(self.result, "warnings", []) or [])

    def sampler(self):
        return dict(getattr(self.result, "sampler", {}) or {})

    def population_interval(self, parameter):
        """The population distribution of ``parameter`` (natural units) at the posterior medians
        of its hyper-parameters: median and central 94% range, ``mu -+ 1.881 tau`` in the
        sampling coordinate (exponentiated for a log coordinate), i.e. where 94% of subjects
        are expected to lie; None when the result has no such rows."""
        t = self.hyper_table()
        rows = t[t["parameter"] == parameter].set_index("quantity")
        if not {"mu", "tau"} <= set(rows.index):
            return None
        mu, tau = float(rows.loc["mu", "estimate"]), float(rows.loc["tau", "estimate"])
        back = np.exp if rows.loc["mu", "coordinate"] == "log" else (lambda v: v)
        return {"median": float(back(mu)), "lo": float(back(mu - 1.881 * tau)), "hi": float(back(mu + 1.881 * tau))}


def subjects_section(fits):
    """Per parameter, a table of each subject's posterior (mean, sd, 94% HDI, R-hat, ESS).

    ``fits``: {key: Fit} of one model. Returns {"labels": {key: label}, "tables": {parameter:
    DataFrame indexed by subject label}}.
    """
    labels = {key: subject_label(f) for key, f in fits.items()}
    summaries = {key: f.summary() for key, f in fits.items()}
    first = next(iter(fits.values()))
    tables = {}
    for s in first.attr("slots"):
        name = s["name"]
        rows = {}
        for key, table in summaries.items():
            if name in table.index:
                r = table.loc[name]
                rows[labels[key]] = {"mean": r["mean"], "sd": r["sd"], "hdi_3%": r["hdi_3%"],
                                     "hdi_97%": r["hdi_97%"], "r_hat": r["r_hat"], "ess_bulk": r["ess_bulk"]}
        if rows:
            frame = pd.DataFrame.from_dict(rows, orient="index")
            frame.index.name = "subject"
            tables[name] = frame
    return {"labels": labels, "tables": tables}


def population_section(result):
    """Tables of a population result: hyper-parameters, and shrunk beside separate estimates.

    Returns {"parameters", "hyper": DataFrame, "subjects": {parameter: DataFrame}, "hyperpriors",
    "sampler", "effects": DataFrame or None, "warnings": [text], "intervals": {parameter: the
    population distribution's median and 94% range}}.
    """
    view = result if isinstance(result, PopulationView) else PopulationView(result)
    hyper = view.hyper_table().set_index(["parameter", "quantity"])
    per = view.subject_table()
    subjects = {}
    for name in view.parameters:
        t = per[per["parameter"] == name].drop(columns="parameter").set_index("subject")
        subjects[name] = t
    return {"parameters": view.parameters, "hyper": hyper, "subjects": subjects,
            "hyperpriors": view.hyperpriors(), "sampler": view.sampler(), "effects": view.effects(),
            "warnings": view.warnings(),
            "intervals": {p: view.population_interval(p) for p in view.parameters}}


def contrast_section(table, top=None):
    """A contrast table (:func:`skinfit.contrasts.fit_contrasts` / ``level_contrasts``) with the
    probability of direction ``pd = max(P(A > B), P(A < B))``, sorted by it; the first ``top``
    rows when given."""
    t = table.copy()
    if "parameter" in t.columns:  # first, after the pair
        t.insert(2, "parameter", t.pop("parameter"))
    t.insert(2, "prob_direction", np.maximum(t["p_greater"], 1 - t["p_greater"]))
    t.insert(3, "direction", np.where(t["p_greater"] >= 0.5, "A > B", "A < B"))
    t = t.sort_values("prob_direction", ascending=False, kind="stable").reset_index(drop=True)
    return t.head(top) if top else t


def group_analyses(fits, *, seed=0, min_fits=3, echo=None, cache_dir=None):
    """Population results and contrasts for the fits of a ``--by`` run or a campaign.

    ``fits``: {key: Fit}. For each model with at least ``min_fits`` fits on groups of one
    dataset (dataset ids ``NAME[col=value]``): the population of
    :func:`population_parameters` (:func:`skinfit.population.population`, seeded) and the
    pairwise contrasts between subjects of those parameters; for every fit with a parameter
    split by a condition, the contrasts between its levels. A failing step is reported
    through ``echo`` and left out, never a partial table.

    ``cache_dir``: where each population is kept by the content of its inputs
    (:func:`skinfit.population.population`'s ``cache``), so a report of the same fits does
    not sample it again.

    Returns ``(populations {model id: result}, contrasts {title: DataFrame})``.
    """
    import warnings

    from .contrasts import fit_contrasts, level_contrasts
    from .errors import InputError
    from .report import file_part

    by_model = {}
    for key, f in fits.items():
        base = re.sub(r"\[.*\]$", "", f.dataset_id)
        if base != f.dataset_id:
            by_model.setdefault((f.model_id, base), {})[subject_label(f)] = f
    populations, contrasts = {}, {}
    for (model_id, base), group in by_model.items():
        if len(group) < min_fits:
            continue
        names = population_parameters(next(iter(group.values())))
        try:
            from .population import population

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                stem = file_part(f"{model_id}__{base}")
                cache = None if cache_dir is None else Path(cache_dir) / f"population_{stem}.npz"
                populations[model_id] = population(group, names, rng=seed, cache=cache)
        except (InputError, ValueError, RuntimeError) as exc:
            if echo:
                echo(f"skinfit report: no population for {model_id} on {base}: {exc}")
        rows = []
        for name in names:
            try:
                rows.append(fit_contrasts(group, name, rng=seed).assign(parameter=name))
            except (InputError, ValueError) as exc:
                if echo:
                    echo(f"skinfit report: no contrasts of {name} for {model_id}: {exc}")
        if rows:
            contrasts[f"{model_id} on {base}: between subjects"] = pd.concat(rows, ignore_index=True)
    for key, f in fits.items():
        split = {s["base"] for s in f.attr("slots") if s["level"] is not None}
        rows = [level_contrasts(f, name).assign(parameter=name) for name in sorted(split)]
        if rows:
            contrasts[f"{f.model_id} on {f.dataset_id}: between conditions"] = pd.concat(rows, ignore_index=True)
    return populations, contrasts
