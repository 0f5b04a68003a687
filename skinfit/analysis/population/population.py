"""Population inference over per-subject fits: Metropolis-within-Gibbs (default) or importance
reweighting of the separate fits (``method="reweight"``).

Choice, by measurement (bench/bench_population.py, bench/results/population.md): the Gibbs
sampler of :mod:`skinfit.analysis.population.hierarchical` (each subject's full parameter vector by independence
Metropolis-Hastings from its own fit's Gaussian approximation times the current population,
all subjects and chains in one likelihood call; hyper-parameters from their exact
conditionals; location and scale moves along the non-centred coordinates for weakly informed
parameters) converges (R-hat <= 1.01, bulk and tail ESS >= 400 for every hyper-parameter)
for 13 contact_area subjects x 8 parameters in about 10 s and for 100 simulated subjects x
10 in about 180 s (2-core machine), where the emcee hyper-posterior over reweighted draws took 80-84 s for 4
parameters and did not converge for 8 (3-18 effective draws per subject).  Reweighting is kept
(``method="reweight"``) for one or two parameters with many draws per subject, where it agrees
with Gibbs within Monte Carlo error
(tests/test_population.py::test_gibbs_and_reweighting_agree_on_the_hyper_posterior).

Model, per population parameter ``j`` (a sampled slot: a parameter, one level of a split
parameter, or a slope with a condition such as ``m1`` of contact_area) in its population
coordinate ``u`` (``log theta`` for the log-normal family, else ``theta``)::

    u_ij ~ Normal(mu_j, sd_j)   (normal, lognormal)   or   Student-t(4, mu_j, sd_j)
    mu_j ~ Normal(c_j, 2 s_j),  sd_j ~ half-t(2, s_j)  (Huang & Wand 2013; with --correlated,
                                                        uniform marginal correlations)

with ``c_j``, ``s_j`` the mean and sd of the parameter's prior in the prior file (in ``u``),
recorded in the result.  The family is the user's (``family={"E_star": "normal"}``); the
default is log-normal for a parameter whose prior bounds are >= 0, else normal, and the
result says which was used.  The population replaces the subject prior of these parameters;
other parameters (noise scales, parameters not asked for) keep their prior per subject.

Questions of conditions: :meth:`PopulationResult.effect` (``"m1"``: does levitation lower the
area exponent? P(population mean < 0) and its interval) and :meth:`PopulationResult.contrast`
(two levels of a split parameter, ``"alpha[200]"`` vs ``"alpha[0]"``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # names used only in annotations
    from collections.abc import Sequence

import json
import math
import os
import sys
import time
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from skinfit.errors import InputError
from skinfit.report.figure_store import storable
from skinfit.inference.checkpoint import replace_atomic
from skinfit.io.arguments import as_generator
from skinfit.results.fit import Fit, load_fit, plain_json
from skinfit.results.summary import priors_from_attrs, slot_values
from skinfit.io import integrity
from skinfit.analysis.population.hierarchical import NU_HYPER, NU_T, Spec, run_gibbs
from skinfit.io.outputs import check_outputs
from skinfit.analysis.population.checks import FAMILIES, check_arguments, check_prob, check_size, check_subjects, not_converged

__all__ = ["population", "PopulationResult", "PopulationWarning", "population_tables", "load_population", "subject_digest",
           "load_run", "DrawsFit", "FAMILIES"]

#: The population quantities :meth:`PopulationResult.summary` computes from mu and tau (natural
#: units): the R-hat and ESS that describe them are those of mu and tau, on their own rows.
DERIVED = ("mean", "sd", "median")
#: the words of the note that a subject's data barely move a parameter's prior (information,
#: not a problem of the result: :attr:`PopulationResult.problems`)
_WEAK_DATA = "barely move the prior"
BURN = 300  # Gibbs sweeps discarded as burn-in (population's default)
_LKJ_ETA = 2.0


class PopulationWarning(UserWarning):
    """A population result that cannot be trusted as it stands (not converged, subjects whose
    data barely move their prior, a proposal that rarely moves)."""


# ---- inputs -------------------------------------------------------------------------------
def load_run(path, model=None):
    """``{label: Fit}`` of a ``skinfit fit --by`` run directory or a campaign out directory
    (its ``index.json``).  Labels as the user wrote them: ``S01`` for a single grouping column
    (``subject=S01`` in the index), the full ``col=a,col2=b`` otherwise; a campaign with
    several datasets adds ``dataset/``.  ``model`` picks one model of a campaign.

    Read while no writer holds the run (:func:`skinfit.analysis.groups.reading`); each fit must be the
    one its index lists (its recorded group and data: :func:`skinfit.analysis.groups.listed_problem`),
    and a fit ``--by`` run's data file unchanged since (else an InputError naming the subject
    and what is wrong).  A campaign's fits of the model that are not complete (failed or
    pending), and groups of a ``--by`` run's data its index does not list, are named in a
    :class:`PopulationWarning`."""
    from skinfit.analysis.groups import index_document, index_drift, listed_problem, missing_groups, read_index, reading

    path = Path(path)
    if path.is_dir() and not (path / "index.json").exists() and (path / "fit.nc").exists():
        raise InputError(path, "holds a single fit (fit.nc), not fits of several subjects: give the folder of "
                               "`skinfit fit ... --by subject` or of a campaign")
    index = path / "index.json" if path.is_dir() else path
    with reading(index.parent):
        rows, _ = read_index(index)
        kind, doc = index_document(index)
        if not rows:
            raise InputError(index, "lists no completed fit: nothing to pool")
        models = sorted({str(r.get("model")) for r in rows})
        if model is None and len(models) > 1:
            raise InputError(index, f"fits of several models ({', '.join(models)}): choose one with --model "
                                    "(Python: model=)", field="model")
        rows = [r for r in rows if model is None or r.get("model") == model]
        if not rows:
            raise InputError(index, f"no completed fit of model {model!r} (models: {', '.join(models)})", field="model")
        datasets = {r.get("dataset") for r in rows}
        fits, where = {}, {}
        for r in rows:
            label = _label(r, len(datasets) > 1)
            if label in fits:
                raise InputError(index, f"lists subject {label!r} twice ({where[label]} and {r['path']})")
            f = _load_light(r["path"])
            problem = listed_problem(f.attrs, r.get("group") or "", r.get("dataset_sha256"))
            if problem:
                raise InputError(r["path"], f"listed for subject {label} in {index} but {problem}")
            fits[label], where[label] = f, r["path"]
        names = ", ".join(list(fits)[:5]) + (f" and {len(fits) - 5} more" if len(fits) > 5 else "")
        drift = index_drift(index, doc, f"the fits of {names}") if kind == "by" else None
    if drift:
        raise InputError(index, drift[len(f"{index}: "):] + " (they are stale)")
    if kind == "by" and (missing := missing_groups(doc)):  # e.g. a `fit --by` killed part-way
        shown = [_label({"group": g}, False) for g in missing]
        warnings.warn(f"the run's data hold {len(missing)} group(s) its index does not list "
                      f"({', '.join(shown[:5])}{' ...' if len(shown) > 5 else ''}: a `skinfit fit --by` that did not "
                      f"finish?): the population is of the other {len(fits)} subjects only", PopulationWarning,
                      stacklevel=2)
    if kind == "campaign":
        chosen = model or rows[0].get("model")
        missing = [f"{_label(r, len(datasets) > 1)} ({r.get('status')})" for r in doc
                   if isinstance(r, dict) and r.get("model") == chosen
                   and r.get("status", "done") not in ("done", "complete")]
        if missing:
            warnings.warn(f"the campaign lists {len(missing)} fit(s) of {chosen} that are not complete "
                          f"({', '.join(missing[:5])}{' ...' if len(missing) > 5 else ''}): the population is of "
                          f"the other {len(fits)} subjects only", PopulationWarning, stacklevel=2)
    return fits


def _label(row, several_datasets):
    """A subject's label as the user wrote it (see :func:`load_run`)."""
    label = str(row.get("group") or row.get("dataset"))
    if label.count("=") == 1 and "," not in label:
        label = label.split("=", 1)[1]
    if several_datasets and row.get("group"):
        label = f"{row.get('dataset')}/{label}"
    return label


def _load_light(path):
    """A saved fit as :func:`skinfit.load_fit` reads it, checked against its checksums: the
    pointwise log-likelihood and predictive groups, most of a file, are not read."""
    fit = load_fit(path)
    if "posterior" not in fit.partial_tree.children:
        raise InputError(fit.path, "not a skinfit fit (no posterior group)")
    return fit


class DrawsFit:
    """A subject given as its Posterior and posterior draws instead of a saved fit (for
    simulation studies: SBC, coverage).  ``theta`` (n, d) in natural units, columns in the
    order of ``post.names``; unsplit parameters only."""

    def __init__(self, post, theta, label="subject"):
        import xarray as xr

        if any(s.level is not None for s in post.slots):
            raise InputError("DrawsFit", "split parameters need a saved fit", field="post")
        self.posterior = post
        self.model_id, self.dataset_id = post.model.id, label
        pr = post.priors
        self.attrs = {"model_id": post.model.id, "dataset_id": label, "model_card": post.model.card_text,
                      "priors_text": pr.text, "priors_sha256": pr.sha256, "priors_id": pr.id}
        self._slots = [{"name": s.name, "base": s.base, "level": None, "transform": s.transform} for s in post.slots]
        theta = np.asarray(theta, dtype=float)
        self._ds = xr.Dataset({n: (("chain", "draw"), theta[None, :, j]) for j, n in enumerate(post.names)})

    def attr(self, key):
        if key == "slots":
            return self._slots
        raise KeyError(key)

    def group(self, name):
        if name != "posterior":
            raise KeyError(name)
        return self._ds


def _as_fits(fits, model=None):
    """{label: Fit or DrawsFit} of what :func:`population` was given (a run folder read by
    :func:`load_run`); InputError for anything else, labels that collide or fewer than two."""
    if isinstance(fits, (str, os.PathLike)):
        fits = load_run(fits, model)
    elif isinstance(fits, Mapping):
        fits = dict(fits)
    elif isinstance(fits, Iterable) and not isinstance(fits, (bytes, Fit)):
        listed = list(fits)
        bad = next((i for i, f in enumerate(listed, 1) if not isinstance(f, (Fit, DrawsFit))), None)
        if bad is not None:
            raise InputError("population", f"item {bad} is a {type(listed[bad - 1]).__name__}, not a Fit", field="fits")
        fits = {}
        for i, f in enumerate(listed, 1):
            if f.dataset_id in fits:
                raise InputError("population", f"fits {list(fits).index(f.dataset_id) + 1} and {i} are both of "
                                 f"{f.dataset_id}: give a mapping label -> Fit to tell subjects apart", field="fits")
            fits[f.dataset_id] = f
    else:
        raise InputError("population", f"expected a run folder, a mapping label -> Fit or a list of Fits (got "
                         f"{type(fits).__name__})", field="fits")
    bad = next((k for k, f in fits.items() if not isinstance(f, (Fit, DrawsFit))), None)
    if bad is not None:
        raise InputError("population", f"subject {bad}: a {type(fits[bad]).__name__}, not a Fit", field="fits")
    labels = {str(k) for k in fits}
    if len(labels) < len(fits):
        raise InputError("population", "subject labels that are the same as text (e.g. 1 and '1')", field="fits")
    if len(fits) < 2:
        raise InputError("population", f"expected at least two Fit objects (got {len(fits)})", field="fits")
    models = {f.model_id for f in fits.values()}
    if len(models) > 1:
        raise InputError("population", f"fits of different models ({', '.join(sorted(models))})", field="fits")
    return {str(k): v for k, v in fits.items()}


def subject_digest(fit):
    """sha256 of what a population reads of one subject's fit: its model, prior file and data
    (ids and the sha256 the fit records of them) and its posterior draws. The same for the fit
    in memory, loaded whole or loaded light (:func:`load_run`), and unchanged by what a
    comparison or a report adds to the file (evidence, LOO, summary)."""
    import hashlib

    h = hashlib.sha256()
    attrs = fit.attrs
    h.update(json.dumps([str(attrs.get(k)) for k in ("model_id", "model_sha256", "priors_id", "priors_sha256",
                                                     "dataset_id", "dataset_sha256")]).encode())
    post = fit.group("posterior")
    for name in sorted(post.data_vars):
        values = np.ascontiguousarray(np.asarray(post[name].values, dtype=float))
        h.update(f"{name}{tuple(post[name].dims)}{values.shape}".encode())
        h.update(values.tobytes())
    return h.hexdigest()


def _prior_moments(prior, log):
    """Mean and sd of a prior in the population coordinate (2000 quantiles)."""
    q = prior.ppf((np.arange(2000) + 0.5) / 2000)
    q = np.log(q) if log else q
    return float(q.mean()), float(q.std())


def _choose(first, parameters, family):
    """Slot names, families and population coordinates; the defaults stated."""
    slots = {s["name"]: s for s in first.attr("slots")}
    priors = priors_from_attrs(first.attrs)
    if parameters is None:  # every model parameter; noise scales stay per subject
        model_params = _model_parameter_names(first)
        parameters = [n for n, s in slots.items() if s["base"] in model_params]
    parameters = [parameters] if isinstance(parameters, str) else list(parameters)
    if not parameters:
        raise InputError(f"fit of {first.model_id} on {first.dataset_id}", "the model has no parameters to pool "
                         f"(sampled: {', '.join(slots)}): name them with --params", field="parameters")
    for name in parameters:
        if name not in slots:
            raise InputError(f"fit of {first.model_id} on {first.dataset_id}", f"no sampled parameter {name!r} "
                             f"(sampled: {', '.join(slots)})", field="parameters")
    family = dict.fromkeys(parameters, family) if isinstance(family, str) else dict(family or {})
    for key, fam in family.items():
        if fam not in FAMILIES:
            raise InputError("--family", f"{key}: unknown family {fam!r} (expected one of {', '.join(FAMILIES)})")
        if key not in parameters and not any(slots[p]["base"] == key for p in parameters):
            raise InputError("--family", f"{key!r} is not a population parameter (parameters: {', '.join(parameters)})")
    fams, logs = [], []
    for name in parameters:
        prior = priors[slots[name]["base"]]
        fam = family.get(name, family.get(slots[name]["base"]))
        if fam is None:
            fam = "lognormal" if prior.lower >= 0 else "normal"
        if fam == "lognormal" and prior.lower < 0:
            raise InputError("--family", f"{name}: lognormal needs a positive parameter (its prior bounds are "
                             f"[{prior.lower:g}, {prior.upper:g}])")
        fams.append(fam)
        logs.append(fam == "lognormal")
    return parameters, fams, logs, slots, priors


def _model_parameter_names(fit):
    import tomllib

    return {p["name"] for p in tomllib.loads(fit.attrs["model_card"]).get("parameters", [])}


# ---- the result ---------------------------------------------------------------------------
@dataclass
class PopulationResult:
    """Hyper-posterior and shrunk subject posteriors.

    Draw arrays are (chain, draw, ...): ``mu``, ``sd`` (p,) in each parameter's population
    coordinate (``coordinates``: ``log`` or ``natural``); ``corr`` (p, p) or None; ``shrunk``
    (S, p) natural units.  ``separate``: {subject: (n, p) natural-unit draws of its own fit}.
    """

    model_id: str
    parameters: list
    families: list
    subjects: list
    mu: np.ndarray
    sd: np.ndarray
    corr: np.ndarray | None
    shrunk: np.ndarray
    separate: dict
    hyperpriors: dict
    sampler: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    contraction: dict = field(default_factory=dict)
    #: {subject label: :func:`subject_digest` of its fit}: which fits the result was made from
    #: (empty for subjects given as draws), so that a saved result is matched to fits by content.
    inputs: dict = field(default_factory=dict)
    #: The file the result was read from (:func:`load_population`); empty when computed here.
    origin: str = ""
    #: :meth:`diagnostics`' rows, computed once (kept in the population cache beside the draws)
    _diagnostics: list | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def log(self):
        return [f == "lognormal" for f in self.families]

    @property
    def coordinates(self):
        return ["log" if g else "natural" for g in self.log]

    @property
    def converged(self):
        return bool(self.sampler.get("converged"))

    def _flat(self, x):
        return x.reshape((-1,) + x.shape[2:])

    def population_draws(self):
        """Population mean, sd and median in natural units: dict -> (chain, draw, p)."""
        lg = np.array(self.log)
        st = np.array([f == "student_t" for f in self.families])
        with np.errstate(over="ignore"):
            mean = np.where(lg, np.exp(self.mu + 0.5 * self.sd**2), self.mu)
            sd = np.where(lg, mean * np.sqrt(np.expm1(self.sd**2)),
                          np.where(st, self.sd * math.sqrt(NU_T / (NU_T - 2)), self.sd))
        return {"mean": mean, "sd": sd, "median": np.where(lg, np.exp(self.mu), self.mu)}

    def predictive(self, rng=0):
        """Draws (chain*draw, p) of a new subject's parameters in natural units."""
        rng = as_generator(rng)
        mu, sd = self._flat(self.mu), self._flat(self.sd)
        n, p = mu.shape
        if self.corr is not None:
            cov = self._flat(self.corr) * sd[:, :, None] * sd[:, None, :]
            e = np.einsum("kij,kj->ki", np.linalg.cholesky(cov), rng.standard_normal((n, p)))
        else:
            e = sd * rng.standard_normal((n, p))
            st = np.array([f == "student_t" for f in self.families])
            e = np.where(st, e / np.sqrt(rng.chisquare(NU_T, (n, p)) / NU_T), e)
        u = mu + e
        return np.where(self.log, np.exp(u), u)

    def diagnostics(self):
        """R-hat and bulk / tail ESS of every hyper-parameter (ArviZ): a table indexed like
        summary(). Computed once; a result read from the population cache has them already."""
        if self._diagnostics is None:
            self._diagnostics = self._diagnostic_rows()
        return pd.DataFrame(self._diagnostics)

    def _diagnostic_rows(self):
        import arviz as az

        rows = []
        items = [("mu", self.mu), ("sd", self.sd)]
        for q, x in items:
            for j, name in enumerate(self.parameters):
                rows.append(_diag(name, q, x[:, :, j], az))
        if self.corr is not None:
            for j, k in self._pairs():
                rows.append(_diag(f"{self.parameters[j]},{self.parameters[k]}", "corr", self.corr[:, :, j, k], az))
        return rows

    def _pairs(self):
        p = len(self.parameters)
        return [(j, k) for j in range(p) for k in range(j + 1, p)]

    def summary(self, prob=0.95):
        """Per parameter: population mean, sd and median (natural units), ``mu`` and ``sd`` in
        the population coordinate, correlations: median and central ``prob`` interval, with the
        family, R-hat and ESS of ``mu`` / ``sd``."""
        a = 0.5 * (1 - check_prob(prob, "summary"))
        rows = []
        draws = self.population_draws()
        diag = self.diagnostics().set_index(["parameter", "quantity"])
        for j, name in enumerate(self.parameters):
            coord = self.coordinates[j]
            items = [*((q, draws[q], "natural") for q in DERIVED), ("mu", self.mu, coord), ("tau", self.sd, coord)]
            for qty, x, c in items:
                lo, med, hi = np.quantile(x[:, :, j], [a, 0.5, 1 - a])
                d = diag.loc[(name, "sd" if qty == "tau" else "mu")] if qty in ("mu", "tau") else None
                rows.append({"parameter": name, "family": self.families[j], "quantity": qty, "estimate": med,
                             "lower": lo, "upper": hi, "coordinate": c,
                             "r_hat": np.nan if d is None else d["r_hat"],
                             "ess_bulk": np.nan if d is None else d["ess_bulk"],
                             "ess_tail": np.nan if d is None else d["ess_tail"]})
        if self.corr is not None:
            for j, k in self._pairs():
                lo, med, hi = np.quantile(self.corr[:, :, j, k], [a, 0.5, 1 - a])
                key = f"{self.parameters[j]},{self.parameters[k]}"
                d = diag.loc[(key, "corr")]
                rows.append({"parameter": key, "family": "", "quantity": "corr", "estimate": med, "lower": lo,
                             "upper": hi, "coordinate": "population", "r_hat": d["r_hat"],
                             "ess_bulk": d["ess_bulk"], "ess_tail": d["ess_tail"]})
        return pd.DataFrame(rows)

    def subject_summary(self, prob=0.95):
        """Per subject and parameter: separate-fit and shrunk posterior median and interval, and
        the contraction of the subject's own fit (1 - var posterior / var prior, sampling
        coordinate: near 0 the subject's data barely moved its prior)."""
        a = 0.5 * (1 - check_prob(prob, "subject_summary"))
        rows = []
        for i, s in enumerate(self.subjects):
            for j, name in enumerate(self.parameters):
                sep = np.quantile(self.separate[s][:, j], [a, 0.5, 1 - a])
                shr = np.quantile(self.shrunk[:, :, i, j], [a, 0.5, 1 - a])
                rows.append({"subject": s, "parameter": name, "separate": sep[1], "separate_lower": sep[0],
                             "separate_upper": sep[2], "shrunk": shr[1], "shrunk_lower": shr[0],
                             "shrunk_upper": shr[2], "contraction": self.contraction.get(s, {}).get(name, np.nan)})
        return pd.DataFrame(rows)

    def effect(self, parameter, prob=0.95, reference=0.0):
        """Is a population parameter (a slope with a condition, e.g. contact_area's ``m1``)
        below or above ``reference``?  Posterior probabilities and central ``prob`` interval of
        the population mean (of ``mu`` in the population coordinate, i.e. of the median for a
        log-normal family), and of a new subject's value."""
        j = self._index(parameter)
        check_prob(prob, "effect")
        if isinstance(reference, bool) or not isinstance(reference, (int, float, np.number)) or not np.isfinite(
                reference):
            raise InputError("effect", f"expected a finite number (got {reference!r})", field="reference")
        if self.log[j] and reference <= 0:
            raise InputError("effect", f"{parameter} has a log-normal population (every value > 0): expected a "
                             f"reference > 0 (got {reference:g})", field="reference")
        ref = math.log(reference) if self.log[j] else reference
        m = self.mu[:, :, j].ravel()
        new = self.predictive()[:, j]
        new_u = np.log(new) if self.log[j] else new
        a = 0.5 * (1 - prob)
        lo, med, hi = np.quantile(m, [a, 0.5, 1 - a])
        nlo, nhi = np.quantile(new, [a, 1 - a])
        centre = "median" if self.log[j] else "mean"
        tr = (lambda x: math.exp(x)) if self.log[j] else (lambda x: x)
        return {"parameter": parameter, "question": f"population {centre} of {parameter} vs {reference:g}",
                "estimate": tr(med), "lower": tr(lo), "upper": tr(hi),
                "p_below": float(np.mean(m < ref)), "p_above": float(np.mean(m > ref)),
                "new_subject_lower": float(nlo), "new_subject_upper": float(nhi),
                "p_new_subject_below": float(np.mean(new_u < ref))}

    def contrast(self, a, b, prob=0.95):
        """Population-level contrast of two parameters (e.g. two levels of a split parameter):
        posterior of the difference of their population means (natural, or for log-normal
        families the ratio of medians), interval and P(A > B)."""
        ja, jb = self._index(a), self._index(b)
        check_prob(prob, "contrast")
        if self.log[ja] != self.log[jb]:
            raise InputError("contrast", f"{a} and {b} have different population coordinates")
        d = (self.mu[:, :, ja] - self.mu[:, :, jb]).ravel()
        q = 0.5 * (1 - prob)
        lo, med, hi = np.quantile(d, [q, 0.5, 1 - q])
        kind = "ratio of medians" if self.log[ja] else "difference of means"
        tr = np.exp if self.log[ja] else (lambda x: x)
        return {"A": a, "B": b, "quantity": kind, "estimate": float(tr(med)), "lower": float(tr(lo)),
                "upper": float(tr(hi)), "p_greater": float(np.mean(d > 0))}

    def effects(self, prob=0.95):
        """The default questions: every population parameter whose prior allows both signs
        (a slope with a condition) against 0, and each level of a split parameter against its
        first level.  A table."""
        check_prob(prob, "effects")
        rows = []
        bounds = self.hyperpriors.get("_bounds", {})
        for name in self.parameters:
            lo, hi = bounds.get(name, (0.0, 0.0))
            if lo < 0 < hi and not self.log[self._index(name)]:
                rows.append(self.effect(name, prob))
        levels = {}
        for name in self.parameters:
            if "[" in name:
                levels.setdefault(name.split("[", 1)[0], []).append(name)
        for names in levels.values():
            for other in names[1:]:
                c = self.contrast(other, names[0], prob)
                rows.append({"parameter": f"{other} vs {names[0]}", "question": c["quantity"],
                             "estimate": c["estimate"], "lower": c["lower"], "upper": c["upper"],
                             "p_above": c["p_greater"], "p_below": 1 - c["p_greater"]})
        return pd.DataFrame(rows)

    def _index(self, name):
        if not isinstance(name, str) or name not in self.parameters:
            raise InputError("population", f"no population parameter {name!r} (parameters: "
                             f"{', '.join(self.parameters)})", field="parameter")
        return self.parameters.index(name)

    # mapping interface for skinfit.report.html.write_report(population=...): a parameter's
    # population distribution as draws of a new subject's value
    def __contains__(self, name):
        return name in self.parameters

    def get(self, name, default=None):
        return self.predictive()[:, self.parameters.index(name)] if name in self.parameters else default

    def to_datatree(self):
        """An ArviZ DataTree: ``posterior`` (hyper-parameters, dims chain, draw, parameter),
        ``subjects`` (shrunk subject posteriors, dims chain, draw, subject, parameter),
        ``separate`` (the separate fits' draws, thinned to 1000 a subject) and the
        families, hyper-priors, sampler record and warnings as root attributes."""
        import arviz as az

        draws = self.population_draws()
        post = {"mu": self.mu, "sd": self.sd, "pop_mean": draws["mean"], "pop_sd": draws["sd"],
                "pop_median": draws["median"]}
        dims = {k: ["parameter"] for k in post}
        if self.corr is not None:
            post["corr"] = self.corr
            dims["corr"] = ["parameter", "parameter_b"]
        coords = {"parameter": self.parameters, "parameter_b": self.parameters, "subject": self.subjects}
        attrs = {"kind": "skinfit.population", integrity.SCHEMA_ATTR: integrity.CHECKED_SCHEMA, "model_id": self.model_id,
                 "families": json.dumps(dict(zip(self.parameters, self.families))),
                 # not "coordinates": netCDF readers take that for CF's list of coordinate variables and drop it
                 "population_coordinates": json.dumps(dict(zip(self.parameters, self.coordinates))),
                 "hyperpriors": json.dumps(self.hyperpriors), "sampler": json.dumps(self.sampler, default=float),
                 "warnings": json.dumps(self.warnings), "contraction": json.dumps(self.contraction),
                 "inputs": json.dumps(self.inputs)}
        tree = az.from_dict({"posterior": post}, dims=dims, coords=coords, attrs={"/": attrs})
        import xarray as xr

        ds = xr.Dataset({"theta": (("chain", "draw", "subject", "parameter"), self.shrunk)},
                        coords={"chain": np.arange(self.shrunk.shape[0]), "draw": np.arange(self.shrunk.shape[1]),
                                "subject": self.subjects, "parameter": self.parameters})
        tree["subjects"] = xr.DataTree(ds)
        n = min(len(v) for v in self.separate.values())
        pick = {s: np.linspace(0, len(v) - 1, min(n, 1000)).astype(int) for s, v in self.separate.items()}
        sep = np.stack([self.separate[s][pick[s]] for s in self.subjects])
        tree["separate"] = xr.DataTree(xr.Dataset({"theta": (("subject", "sample", "parameter"), sep)},
                                                  coords={"subject": self.subjects, "parameter": self.parameters}))
        return tree

    def save(self, path):
        """Write :meth:`to_datatree` as NetCDF (h5netcdf), with the sha256 of each group and of
        the root attributes (:mod:`skinfit.io.integrity`), which :func:`load_population` checks."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tree = self.to_datatree()
        integrity.stamp(tree)
        replace_atomic(path, integrity.seal(tree.to_netcdf(engine="h5netcdf")))
        return path

    @property
    def problems(self):
        """The warnings that mean the result cannot be reported as it stands (not converged, a
        sampler that rarely moved, incomplete inputs): all but the notes that a subject's data
        barely move a parameter's prior, which is information about the data."""
        return [w for w in self.warnings if _WEAK_DATA not in w]


def _diag(name, qty, x, az):
    return {"parameter": name, "quantity": qty, "r_hat": float(az.rhat(x)) if x.shape[0] > 1 else np.nan,
            "ess_bulk": float(az.ess(x)), "ess_tail": float(az.ess(x, method="tail", prob=(0.05, 0.95)))}


def load_population(path):
    """A :class:`PopulationResult` from the NetCDF written by :meth:`PopulationResult.save`
    (the separate fits' draws thinned to at most 1000 a subject), with ``origin`` the path;
    ``inputs`` is empty for a file written before skinfit recorded them."""
    import arviz as az

    if not Path(path).is_file():
        raise InputError(path, "no such population file (expected the population.nc of `skinfit population`)")
    try:
        sealed = integrity.check_file(path)  # its bytes, before HDF5 parses any of them
        tree = az.from_netcdf(path).load()
    except InputError:
        raise
    except (OSError, ValueError, KeyError, TypeError, IndexError, RuntimeError, MemoryError) as exc:
        raise InputError(path, f"not a readable skinfit population result ({type(exc).__name__}: "
                               f"{' '.join(str(exc).split())[:200]})") from None
    if tree.attrs.get("kind") != "skinfit.population" and integrity.RECORD not in tree.attrs:
        raise InputError(path, "not a skinfit population result")
    record = integrity.take(path, tree.attrs, list(tree.children), sealed=sealed,
                            unversioned=1)  # a result written before checksums has no schema: 1
    integrity.verify(path, record, groups=integrity.groups_of(tree))
    if tree.attrs.get("kind") != "skinfit.population":
        raise InputError(path, "not a skinfit population result")
    try:  # an old file (no checksums) damaged where an attribute or group was: one line, not a traceback
        post = tree["posterior"].to_dataset()
        attrs = tree.attrs
        fam = json.loads(attrs["families"])
        params = [str(p) for p in post["parameter"].values]
        subjects = [str(s) for s in tree["subjects"].to_dataset()["subject"].values]
        sep_ds = tree["separate"].to_dataset()["theta"].values
        sep = {s: sep_ds[i] for i, s in enumerate(subjects)}
        return PopulationResult(attrs["model_id"], params, [fam[p] for p in params], subjects, post["mu"].values,
                                post["sd"].values, post["corr"].values if "corr" in post else None,
                                tree["subjects"].to_dataset()["theta"].values, sep, json.loads(attrs["hyperpriors"]),
                                json.loads(attrs["sampler"]), json.loads(attrs["warnings"]),
                                json.loads(attrs["contraction"]), json.loads(attrs.get("inputs", "{}")), str(path))
    except (KeyError, ValueError, TypeError, IndexError) as exc:
        raise InputError(path, f"not a complete skinfit population result ({type(exc).__name__}: "
                               f"{' '.join(str(exc).split())[:200]})") from None


def population_tables(result, prob=0.95):
    """Tables for a report: ``hyper`` (population mean / sd / median with intervals, family,
    R-hat, ESS), ``subjects`` (separate vs shrunk per subject and parameter), ``effects``
    (conditions as effects: probabilities and intervals), ``hyperpriors`` and ``warnings``."""
    hp = pd.DataFrame([{"parameter": k, **v} for k, v in result.hyperpriors.items() if not k.startswith("_")])
    return {"hyper": result.summary(prob), "subjects": result.subject_summary(prob), "effects": result.effects(prob),
            "hyperpriors": hp, "warnings": pd.DataFrame({"warning": result.warnings})}


# ---- the entry point ----------------------------------------------------------------------
def population(fits: Mapping[str, Fit] | Sequence[Fit] | str | os.PathLike, parameters: Sequence[str] | None = None,
               *, family: str | Mapping[str, str] | None = None, correlated: bool = False, method: str = "gibbs",
               rng: int | np.random.Generator | None = None, model: str | None = None, chains: int = 8,
               ess_target: float = 400, rhat_max: float = 1.01, max_sweeps: int = 20000, burn: int = BURN,
               min_contraction: float = 0.5, n_draws: int = 1000, max_steps: int = 20000,
               cache: str | os.PathLike | None = None) -> PopulationResult:
    """Infer the population distribution of ``parameters`` from separate per-subject fits.

    Parameters
    ----------
    fits : mapping label -> Fit, list of Fit, or a ``fit --by`` run / campaign out directory
    parameters : str or list of str, optional
        Sampled slot names (``"m0"``, ``"alpha[25]"``); default every model parameter's slot
        (noise scales stay per subject).
    family : mapping name -> "normal" | "lognormal" | "student_t", optional
        Per parameter (slot or base name); default lognormal for parameters with prior bounds
        >= 0, else normal.
    correlated : bool
        Multivariate normal population (Huang-Wand prior: uniform marginal correlations);
        normal / lognormal families only.
    method : "gibbs" (default) or "reweight"
        ``reweight``: emcee over the hyper-posterior estimated from ``n_draws`` draws per
        subject (the earlier method; adequate for one or two parameters).
    rng : int, None or numpy.random.Generator
        The seed, recorded in ``sampler["seed"]`` (drawn and recorded when None).
    chains, ess_target, rhat_max, max_sweeps, burn : Gibbs chains, the stopping rule (bulk and
        tail ESS >= ess_target and R-hat <= rhat_max for every hyper-parameter), sweep cap and
        burn-in.
    min_contraction : float
        Warn for subjects whose own fit contracted a population parameter's prior by less.
    cache : path-like, optional
        A file that keeps the result (NumPy ``.npz``, written atomically) with the sha256 of
        its inputs: every subject's label and fit content (:meth:`~skinfit.results.fit.Fit.content_hash`),
        the arguments above, the seed (an int ``rng`` only) and the code of skinfit and the
        versions of numpy and scipy; used only for fits of shipped, unchanged model cards (a
        user's own forward function may change without the fits changing).  A call with the same inputs reads the same result from
        it instead of sampling (its warnings are warned again); other inputs, or an unreadable
        file, sample and rewrite it.

    Returns
    -------
    PopulationResult
        Its ``warnings`` (also warned as :class:`PopulationWarning`) and ``problems`` (those
        that mean it cannot be reported as it stands): a hyper-posterior that did not converge
        is said with the population parameters the data cannot determine, why, and the options
        that would help (:func:`skinfit.analysis.population.checks.not_converged`).

    Raises
    ------
    InputError
        Before any sampling, for a bad argument (:func:`skinfit.analysis.population.checks.check_arguments`),
        fits that are not distinct subjects of the data as they are now (a fit filed under
        another subject, one fit under two labels, a data file edited since:
        :func:`skinfit.analysis.population.checks.check_subjects`), or a run being written.
    """
    parameters, family = check_arguments(parameters, family, correlated, method, rng, model, chains, ess_target,
                                         rhat_max, max_sweeps, burn, min_contraction, n_draws, max_steps, cache)
    if rng is None:  # a seed drawn here, recorded in the result's sampler record like a given one
        rng = int(np.random.SeedSequence().entropy % 2**63)  # as fit(): one --seed accepts
    seed, rng = rng, as_generator(rng)
    with warnings.catch_warnings(record=True) as read:  # a run's notes (a campaign's incomplete fits) are kept
        warnings.simplefilter("always", PopulationWarning)
        fits = _as_fits(fits, model)
    notes = [str(w.message) for w in read if issubclass(w.category, PopulationWarning)]
    for w in read:
        if not issubclass(w.category, PopulationWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    digests = {s: subject_digest(f) for s, f in fits.items() if isinstance(f, Fit)}
    check_subjects(fits, digests)
    key = None
    if (cache is not None and isinstance(seed, (int, np.integer)) and all(isinstance(f, Fit) for f in fits.values())
            and all(storable(f) for f in fits.values())):  # a user's model code is not in the key: not kept
        key = _cache_key(fits, {"parameters": parameters, "family": family, "correlated": correlated,
                                "method": method, "seed": int(seed), "chains": chains, "ess_target": ess_target,
                                "rhat_max": rhat_max, "max_sweeps": max_sweeps, "burn": burn,
                                "min_contraction": min_contraction, "n_draws": n_draws, "max_steps": max_steps})
        result = _read_cache(cache, key)
        if result is not None:
            for w in result.warnings:
                warnings.warn(w, PopulationWarning, stacklevel=2)
            return result
    subjects = list(fits)
    first = fits[subjects[0]]
    parameters, fams, logs, slots, priors = _choose(first, parameters, family)
    if correlated and "student_t" in fams:
        raise InputError("--family", "student_t populations are independent only (drop --correlated; Python: "
                               "correlated=False)")
    if method == "reweight" and (fams != ["lognormal" if priors[slots[n]["base"]].lower >= 0 else "normal"
                                          for n in parameters]):
        raise InputError("population", "method='reweight' supports only the default families", field="method")
    if method == "gibbs":
        check_size(chains, len(subjects), len(slots), len(parameters))
    warn = list(notes)
    for s in subjects[1:]:
        if fits[s].attrs.get("priors_sha256") != first.attrs.get("priors_sha256"):
            warn.append(f"subject {s} was fitted under another prior file than {subjects[0]}: the hyper-priors "
                        f"come from {subjects[0]}'s ({first.attrs.get('priors_id')})")
        names = [x["name"] for x in fits[s].attr("slots")]
        if names != list(slots):
            raise InputError("population", f"subject {s} has other sampled parameters ({', '.join(names)}) than "
                             f"{subjects[0]} ({', '.join(slots)}): fit all subjects with the same --split "
                             "(Python: split=)", field="fits")
    hyper, centre, scale = {}, [], []
    for name, fam, lg in zip(parameters, fams, logs):
        prior = priors[slots[name]["base"]]
        c, s_ = _prior_moments(prior, lg)
        centre.append(c)
        scale.append(s_)
        hyper[name] = {"family": fam, "coordinate": "log" if lg else "natural",
                       "mu": f"normal(loc={c:.4g}, scale={2 * s_:.4g})",
                       "sd": f"half-t(nu={NU_HYPER:g}, scale={s_:.4g})",
                       "from": f"prior file {first.attrs.get('priors_id')}: {prior.describe()}"}
        if fam == "student_t":
            hyper[name]["nu"] = NU_T
    if correlated and len(parameters) > 1:
        hyper["_correlation"] = {"prior": "Huang-Wand (nu=2): uniform marginal correlations"}
    hyper["_bounds"] = {n: (priors[slots[n]["base"]].lower, priors[slots[n]["base"]].upper) for n in parameters}

    separate, contraction, zdraws, posts = {}, {}, [], []
    for s in subjects:
        f = fits[s]
        post_ds = f.group("posterior")
        theta = np.column_stack([slot_values(post_ds, slots[n]) for n in slots])
        separate[s] = theta[:, [list(slots).index(n) for n in parameters]]
        contraction[s] = {}
        for n in parameters:
            prior = priors[slots[n]["base"]]
            q = prior.ppf((np.arange(2000) + 0.5) / 2000)
            v = slot_values(post_ds, slots[n])
            if prior.lower >= 0:
                q, v = np.log(q), np.log(v)
            contraction[s][n] = float(1 - np.var(v) / np.var(q))
        if method == "gibbs":
            post = f.posterior
            posts.append(post)
            zdraws.append(post.to_z(theta))
    if method == "gibbs":
        index = [list(slots).index(n) for n in parameters]
        spec = Spec(index, logs, [f == "student_t" for f in fams], centre, scale, correlated and len(parameters) > 1)
        moments = [(z.mean(axis=0), np.cov(z.T)) for z in zdraws]
        t0 = time.perf_counter()
        out = run_gibbs(posts, moments, zdraws, spec, rng, chains=chains, burn=burn, ess_target=ess_target,
                        rhat_max=rhat_max, max_sweeps=max_sweeps)
        sampling_seconds = time.perf_counter() - t0
        shrunk = out["theta"][..., index]
        sampler = {"method": "gibbs (Metropolis-within-Gibbs)", "chains": chains, "sweeps": out["sweeps"],
                   "burn": out["burn"], "thin": out["thin"], "converged": out["converged"], "checks": out["checks"],
                   "acceptance": dict(zip(subjects, out["acceptance"])), "scale_acceptance": out["scale_acceptance"]}
        mu, sd, corr = out["mu"], out["sd"], out.get("corr")
        for s, acc in zip(subjects, out["acceptance"]):
            if acc < 0.05:
                warn.append(f"subject {s}: independence proposal accepted in {acc:.1%} of sweeps: its chain moves "
                            f"rarely (its separate fit is far from its population-conditional posterior)")
    else:
        sampling_seconds = 0.0
        mu, sd, corr, shrunk, sampler = _reweight(fits, subjects, parameters, slots, priors, logs, centre, scale,
                                                  correlated, rng, n_draws, ess_target, max_steps, warn)
    inputs = digests if len(digests) == len(fits) else {}
    result = PopulationResult(first.model_id, parameters, fams, subjects, mu, sd, corr, shrunk, separate, hyper,
                              sampler, warn, contraction, inputs)
    diag = result.diagnostics()
    worst_rhat, worst_ess = diag["r_hat"].max(), diag[["ess_bulk", "ess_tail"]].min().min()
    result.sampler.update(rhat_max=float(worst_rhat), ess_min=float(worst_ess),
                          seed=int(seed) if isinstance(seed, (int, np.integer)) else "a numpy Generator given")
    if not result.converged or (np.isfinite(worst_rhat) and worst_rhat > rhat_max) or worst_ess < ess_target:
        warn.append(not_converged(result, (rhat_max, ess_target), min_contraction, sampling_seconds))
    for n in parameters:
        weak = [s for s in subjects if contraction[s][n] < min_contraction]
        if weak:
            warn.append(f"{n}: the data of {len(weak)} subject(s) ({', '.join(weak)}) {_WEAK_DATA} "
                        f"(contraction < {min_contraction:g}): their shrunk {n} is mostly the population's")
    for w in warn:
        warnings.warn(w, PopulationWarning, stacklevel=2)
    if key is not None:
        _write_cache(cache, key, result)
    return result


# ---- the result kept by its inputs (population(cache=...)) -------------------------------
def _cache_key(fits, settings):
    """sha256 of a population's inputs: subjects (label, fit content), settings, skinfit's code
    and the numpy, scipy and arviz-stats (its diagnostics) versions (:func:`skinfit.io.paths.code_hash`)."""
    import hashlib

    from skinfit.io.paths import code_hash

    doc = {"format": 1, "subjects": [[label, f.content_hash()] for label, f in fits.items()],
           "settings": settings, "code": code_hash(("numpy", "scipy", "arviz-stats"))}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def _write_cache(path, key, result):
    """Write ``result`` with its input ``key`` into ``path`` (npz, no pickle), atomically."""
    import io

    from skinfit.inference.checkpoint import replace_atomic

    meta = {"key": key, "model_id": result.model_id, "parameters": result.parameters, "families": result.families,
            "subjects": result.subjects, "hyperpriors": result.hyperpriors, "sampler": result.sampler,
            "warnings": result.warnings, "contraction": result.contraction, "corr": result.corr is not None,
            "inputs": result.inputs, "diagnostics": result.diagnostics().to_dict("records")}
    arrays = {"mu": result.mu, "sd": result.sd, "shrunk": result.shrunk,
              **({"corr": result.corr} if result.corr is not None else {}),
              **{f"separate_{i}": result.separate[s] for i, s in enumerate(result.subjects)}}
    buf = io.BytesIO()
    np.savez(buf, meta=np.array(json.dumps(meta, default=plain_json)), **arrays)
    replace_atomic(path, buf.getvalue())


def _read_cache(path, key):
    """The result kept in ``path`` for input ``key``; None when absent, of other inputs or
    unreadable (a partial or corrupt file: sampled again and rewritten)."""
    import zipfile

    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            if meta.get("key") != key:
                return None
            hyper = dict(meta["hyperpriors"])
            if "_bounds" in hyper:
                hyper["_bounds"] = {k: tuple(v) for k, v in hyper["_bounds"].items()}
            result = PopulationResult(meta["model_id"], meta["parameters"], meta["families"], meta["subjects"],
                                      z["mu"], z["sd"], z["corr"] if meta["corr"] else None, z["shrunk"],
                                      {s: z[f"separate_{i}"] for i, s in enumerate(meta["subjects"])}, hyper,
                                      meta["sampler"], meta["warnings"], meta["contraction"], meta["inputs"])
            result._diagnostics = meta["diagnostics"]
            return result
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):
        return None


# ---- importance reweighting of the separate fits (method="reweight") ---------------------
def _reweight(fits, subjects, parameters, slots, priors, logs, centre, scale, correlated, rng, n_draws,
              ess_target, max_steps, warn):
    """Hogg, Myers & Bovy (2010, ApJ 725, 2166, eq. 9): the hyper-likelihood estimated from each
    subject's draws ``z_is`` reweighted by population / own prior, sampled with emcee; shrunk
    draws by resampling one draw per hyper draw.  Same hyper-priors as Gibbs (independent); LKJ(2)
    correlations when correlated."""
    from skinfit.inference.sampling import run_emcee

    zs, lps = [], []
    for s in subjects:
        post = fits[s].group("posterior")
        cols, lp = [], 0.0
        for name, lg in zip(parameters, logs):
            prior = priors[slots[name]["base"]]
            theta = slot_values(post, slots[name])
            z = np.log(theta) if lg else theta
            lp = lp + prior.logpdf(theta) + (z if lg else 0.0)
            cols.append(z)
        z = np.column_stack(cols)
        pick = np.sort(rng.choice(len(z), size=min(n_draws, len(z)), replace=False))
        zs.append(z[pick])
        lps.append(np.asarray(lp)[pick])
    S = min(len(z) for z in zs)
    z = np.stack([x[:S] for x in zs])
    logprior = np.stack([x[:S] for x in lps])
    centre, scale = np.asarray(centre), np.asarray(scale)
    target = _HyperPosterior(z, logprior, centre, scale, correlated)
    p = len(parameters)
    means = z.mean(axis=1)
    tau0 = np.maximum(means.std(axis=0), 0.2 * scale)
    d = 2 * p + (p * (p - 1) // 2 if correlated else 0)
    x0 = np.concatenate([means.mean(axis=0), np.log(tau0), np.zeros(d - 2 * p)])
    nwalkers = max(32, 4 * d)
    p0 = x0 + 0.05 * rng.standard_normal((nwalkers, d))
    run = run_emcee(target, p0, rng, ess_target=ess_target, max_steps=max_steps)
    nw, nd = run.chain.shape[:2]
    h = run.chain.reshape(-1, d)  # walker-major; walkers are returned as chains
    mu, tau, L, _ = target.unpack(h)
    corr = L @ np.swapaxes(L, 1, 2) if correlated and p > 1 else None
    shrunk = np.empty((len(h), len(subjects), p))
    ess = {}
    for i, s in enumerate(subjects):
        logw = np.concatenate([target.log_normal(h[k:k + 500], z[i]) for k in range(0, len(h), 500)])
        logw = logw - logprior[i][None]
        w = np.exp(logw - logw.max(axis=1, keepdims=True))
        ess[s] = float(np.median(w.sum(1) ** 2 / (w**2).sum(1)))
        pick = np.argmax(logw + rng.gumbel(size=logw.shape), axis=1)
        shrunk[:, i] = np.where(logs, np.exp(z[i][pick]), z[i][pick])
        if ess[s] < 50:
            warn.append(f"subject {s}: importance-weight effective sample size {ess[s]:.0f} < 50 (of {S} draws): "
                        f"too few for the reweighting; use --method gibbs (Python: method='gibbs')")
    sampler = {"method": "reweight (emcee over the importance-sampled hyper-likelihood)", "converged": run.converged,
               "n_steps": run.n_steps, "reasons": list(run.reasons), "draws_per_subject": S, "importance_ess": ess}
    def chains(x):
        return x.reshape((nw, nd) + x.shape[1:])

    return chains(mu), chains(tau), None if corr is None else chains(corr), chains(shrunk), sampler


def _cholesky_corr(y, p):
    """Cholesky factors (k, p, p) of correlation matrices from unconstrained CPCs y (k, p(p-1)/2),
    and the log-density of the LKJ(eta) prior in the y coordinates (Jacobian included)."""
    k = len(y)
    L = np.zeros((k, p, p))
    L[:, 0, 0] = 1.0
    cpc = np.tanh(y)
    logd = np.zeros(k)
    m = 0
    for i in range(1, p):
        rem = np.ones(k)
        for j in range(i):
            b = _LKJ_ETA + (p - 2 - j) / 2.0
            logd += b * np.log1p(-cpc[:, m] ** 2)
            L[:, i, j] = cpc[:, m] * np.sqrt(rem)
            rem = rem - L[:, i, j] ** 2
            m += 1
        L[:, i, i] = np.sqrt(rem)
    return L, logd


class _HyperPosterior:
    """log p(mu, log tau, CPCs | all subjects), vectorised over walkers (k, d)."""

    def __init__(self, z, logprior, centre, spread, correlated):
        self.z = z  # (N, S, p)
        self.logprior = logprior  # (N, S)
        self.centre, self.spread, self.correlated = centre, spread, correlated
        self.p = z.shape[-1]

    def unpack(self, h):
        p = self.p
        mu, tau = h[:, :p], np.exp(h[:, p:2 * p])
        if self.correlated and p > 1:
            L, log_lkj = _cholesky_corr(h[:, 2 * p:], p)
        else:
            L, log_lkj = np.broadcast_to(np.eye(p), (len(h), p, p)), np.zeros(len(h))
        return mu, tau, L, log_lkj

    def log_normal(self, h, z):
        """log Normal(z; mu, Sigma) for each walker: z (..., p) -> (k, ...)."""
        mu, tau, L, _ = self.unpack(h)
        chol = tau[:, :, None] * L
        inv = np.linalg.inv(chol)
        flat = z.reshape(-1, self.p)
        y = (flat[None] - mu[:, None, :]) @ np.swapaxes(inv, 1, 2)
        logdet = np.log(np.abs(np.diagonal(chol, axis1=1, axis2=2))).sum(axis=1)
        out = -0.5 * (y**2).sum(-1) - logdet[:, None] - 0.5 * self.p * np.log(2 * np.pi)
        return out.reshape((len(h),) + z.shape[:-1])

    def log_hyperprior(self, h):
        """mu ~ Normal(centre, 2 spread); tau ~ half-t(2, spread) (+ log-Jacobian of log tau)."""
        mu, tau, _, log_lkj = self.unpack(h)
        lp = -0.5 * (((mu - self.centre) / (2 * self.spread)) ** 2).sum(1)
        lp += (-0.5 * (NU_HYPER + 1) * np.log1p((tau / self.spread) ** 2 / NU_HYPER) + np.log(tau)).sum(1)
        return lp + log_lkj

    def __call__(self, h):
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            a = self.log_normal(h, self.z) - self.logprior[None]
            m = a.max(axis=2, keepdims=True)
            ll = (m[..., 0] + np.log(np.exp(a - m).sum(axis=2))).sum(1)
            out = self.log_hyperprior(h) + ll
        return np.where(np.isfinite(out), out, -np.inf)


# ---- command line -------------------------------------------------------------------------
def _parse_family(items):
    """``--family PARAM=FAMILY`` items -> {param: family}; each parameter once."""
    out = {}
    for item in items or []:
        name, sep, fam = item.partition("=")
        name, fam = name.strip(), fam.strip()
        if not sep or not fam or not name:
            raise InputError("--family", f"expected PARAMETER=FAMILY (got {item!r}; families: {', '.join(FAMILIES)})")
        if name in out:
            raise InputError("--family", f"{name} given twice ({name}={out[name]} and {item}): give each parameter "
                                         "once")
        out[name] = fam
    return out


#: The files ``skinfit population`` writes into its --out (besides its cache, .cache/).
FILES = ("population.nc", "population_summary.csv", "population_subjects.csv", "population_effects.csv")


def _parse_params(items):
    """``--params NAME[,NAME]`` items -> a list of names (None: every model parameter)."""
    if not items:
        return None
    names = []
    for item in items:
        parts = [p.strip() for p in item.split(",")]
        if not all(parts):
            raise InputError("--params", f"expected NAME[,NAME] (got {item!r}: an empty name)")
        names += parts
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError("--params", f"{', '.join(twice)} given twice: name each population parameter once")
    return names


def cli_population(args):
    """``skinfit population RUN_DIR``: the population of a ``fit --by`` run or a campaign;
    writes ``population.nc`` (ArviZ tree) and ``population_summary.csv`` /
    ``population_subjects.csv`` / ``population_effects.csv`` to ``--out`` and prints them.

    Every option is checked before a fit is read; the run is read while no writer holds it
    and ``--out`` is held with the lock ``skinfit fit`` takes there (a second population into
    the same ``--out`` is refused, not interleaved); files are replaced atomically.  A result
    with problems (not converged, a sampler that rarely moved; :attr:`PopulationResult.problems`)
    is written and said so on stderr; with ``--strict`` the exit status is then 3."""
    from skinfit.inference.checkpoint import CheckpointLock, replace_atomic

    t0 = time.perf_counter()
    params, family = _parse_params(args.params), _parse_family(args.family)
    if args.max_sweeps <= BURN:
        raise InputError("--max-sweeps", f"expected more than the {BURN} burn-in sweeps (got {args.max_sweeps})")
    run = Path(args.run)
    if not run.exists():
        raise InputError(run, "no such run folder (expected the --out of `skinfit fit ... --by` or of a campaign)")
    out = Path(args.out) if args.out else (run if run.is_dir() else run.parent) / "population"
    check_outputs(out, FILES, command="skinfit population", overwrite=args.overwrite)  # before the sampling
    if out.resolve() == (run if run.is_dir() else run.parent).resolve():
        raise InputError(out, "is the run's own folder: give the population another --out (default RUN/population)")
    with CheckpointLock(out / "checkpoint.h5"):  # the lock of `skinfit fit --out`: one writer at a time
        # again inside the lock: a second population into this --out may have finished meanwhile
        check_outputs(out, FILES, command="skinfit population", overwrite=args.overwrite)
        with warnings.catch_warnings():  # the warnings are printed below, with the result
            warnings.simplefilter("ignore", PopulationWarning)
            result = population(args.run, params, family=family, correlated=args.correlated, method=args.method,
                                rng=args.seed, model=args.model, max_sweeps=args.max_sweeps,
                                cache=out / ".cache" / "population.npz")
        tables = population_tables(result)
        for name, table in (("summary", "hyper"), ("subjects", "subjects"), ("effects", "effects")):
            replace_atomic(out / f"population_{name}.csv", tables[table].to_csv(index=False).encode())
        path = result.save(out / "population.nc")
    s = result.sampler
    lines = [f"population of {len(result.subjects)} subjects ({result.model_id}), method {s['method']}, "
             f"seed {s.get('seed')}",
             "families: " + ", ".join(f"{p} {f}" + ("" if (p in family) else " (default)")
                                      for p, f in zip(result.parameters, result.families)),
             "hyper-priors (from the prior file): " + "; ".join(f"{p}: mu ~ {h['mu']}, sd ~ {h['sd']}"
                                                               for p, h in result.hyperpriors.items()
                                                               if not p.startswith("_")),
             f"converged: {'yes' if result.converged and not any('not converged' in w for w in result.warnings) else 'NO'}"
             f"  (max R-hat {s['rhat_max']:.4f}, min ESS {s['ess_min']:.0f}"
             + (f", {s['sweeps']} sweeps of {s['chains']} chains" if "sweeps" in s else "") + ")",
             *[f"{'WARNING' if w in result.problems else 'NOTE'}: {w}" for w in result.warnings], ""]
    with pd.option_context("display.width", 200, "display.max_columns", 20, "display.float_format", "{:.4g}".format):
        lines.append(tables["hyper"].to_string(index=False))
        if len(tables["effects"]):
            lines += ["", "conditions as effects (population level):", tables["effects"].to_string(index=False)]
    print("\n".join(lines))
    print(f"\nwritten: {path}, {out / 'population_summary.csv'}, population_subjects.csv, population_effects.csv"
          f"  ({time.perf_counter() - t0:.1f} s)")
    if result.problems:
        sys.stdout.flush()
        verdict = "NOT converged" if not result.converged or any("not converged" in w for w in result.problems) \
            else "has problems"
        print(f"skinfit: the population {verdict} ({len(result.problems)} problem(s), see WARNING above): its "
              f"numbers are not to be reported as they stand" + ("" if args.strict else
                                                                 "; --strict makes this exit with status 3"),
              file=sys.stderr)
        if args.strict:
            return 3
    return 0
