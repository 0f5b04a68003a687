"""Population inference over per-subject fits: Metropolis-within-Gibbs (default) or importance
reweighting of the separate fits (``method="reweight"``).

The Gibbs sampler of :mod:`skinfit.analysis.population.hierarchical` is the default: each
subject's full parameter vector by independence Metropolis-Hastings from its own fit's Gaussian
approximation times the current population, all subjects and chains in one likelihood call;
hyper-parameters from their exact conditionals; location and scale moves along the non-centred
coordinates for weakly informed parameters.  It converges (R-hat <= 1.01, bulk and tail ESS >=
400 for every hyper-parameter) where emcee over the reweighted draws does not for more than a
few parameters (bench/results/population.md).  Reweighting (``method="reweight"``,
:mod:`skinfit.analysis.population.reweight`) is kept for one or two parameters with many draws
per subject, where it agrees with Gibbs within Monte Carlo error
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

import os
import time
import tomllib
import warnings
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from skinfit.analysis.population.cache import cache_key, cacheable, read_cache, write_cache
from skinfit.analysis.population.checks import FAMILIES, check_arguments, check_size, check_subjects, not_converged
from skinfit.analysis.population.hierarchical import NU_HYPER, NU_T, Spec, run_gibbs
from skinfit.analysis.population.inputs import subject_digest, subject_fits
from skinfit.analysis.population.result import WEAK_DATA, PopulationResult, PopulationWarning
from skinfit.analysis.population.reweight import reweight
from skinfit.errors import InputError
from skinfit.io.arguments import as_generator
from skinfit.results.fit import Fit
from skinfit.results.intervals import CI_PROB
from skinfit.results.summary import priors_from_attrs, slot_values

__all__ = ["population", "population_tables", "BURN"]


BURN = 300  # Gibbs sweeps discarded as burn-in (population's default)


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
    return {p["name"] for p in tomllib.loads(fit.attrs["model_card"]).get("parameters", [])}


def population_tables(result, prob=CI_PROB):
    """Tables for a report: ``hyper`` (population mean / sd / median with intervals, family,
    R-hat, ESS), ``subjects`` (separate vs shrunk per subject and parameter), ``effects``
    (conditions as effects: probabilities and intervals), ``hyperpriors`` and ``warnings``."""
    hp = pd.DataFrame([{"parameter": k, **v} for k, v in result.hyperpriors.items() if not k.startswith("_")])
    return {"hyper": result.summary(prob), "subjects": result.subject_summary(prob), "effects": result.effects(prob),
            "hyperpriors": hp, "warnings": pd.DataFrame({"warning": result.warnings})}


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
        user's own forward function may change without the fits changing).  A call with the same
        inputs reads the same result from
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
        fits = subject_fits(fits, model)
    notes = [str(w.message) for w in read if issubclass(w.category, PopulationWarning)]
    for w in read:
        if not issubclass(w.category, PopulationWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    digests = {s: subject_digest(f) for s, f in fits.items() if isinstance(f, Fit)}
    check_subjects(fits, digests)
    key = None
    if (cache is not None and isinstance(seed, (int, np.integer)) and all(isinstance(f, Fit) for f in fits.values())
            and all(cacheable(f) for f in fits.values())):  # a user's model code is not in the key: not kept
        key = cache_key(fits, {"parameters": parameters, "family": family, "correlated": correlated,
                                "method": method, "seed": int(seed), "chains": chains, "ess_target": ess_target,
                                "rhat_max": rhat_max, "max_sweeps": max_sweeps, "burn": burn,
                                "min_contraction": min_contraction, "n_draws": n_draws, "max_steps": max_steps})
        result = read_cache(cache, key)
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
        mu, sd, corr, shrunk, sampler = reweight(fits, subjects, parameters, slots, priors, logs, centre, scale,
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
            warn.append(f"{n}: the data of {len(weak)} subject(s) ({', '.join(weak)}) {WEAK_DATA} "
                        f"(contraction < {min_contraction:g}): their shrunk {n} is mostly the population's")
    for w in warn:
        warnings.warn(w, PopulationWarning, stacklevel=2)
    if key is not None:
        write_cache(cache, key, result)
    return result
