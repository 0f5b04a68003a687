"""``skinfit.design``: which measurements next, from a fit or a model's priors."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np
import pandas as pd

from skinfit.analysis.design.candidates import read_candidates, si_candidates
from skinfit.analysis.design.checks import (
    baseline_design,
    check_cost,
    check_counts,
    check_discriminate,
    check_noise_scale,
    check_params,
)
from skinfit.analysis.design.discrimination import discrimination_plan
from skinfit.analysis.design.laplace import batch_eig, fisher_factors, greedy_plan, laplace_design, laplace_gains
from skinfit.analysis.design.model_problem import (
    fit_density,
    gaussian_density,
    log_coordinates,
    model_problem,
    noise_setup,
    prior_problem,
    to_u,
)
from skinfit.analysis.design.nested import eig_nmc
from skinfit.analysis.design.problem import n_candidates, restrict_to_support, take_x
from skinfit.analysis.design.result import DesignResult, user_frame
from skinfit.analysis.evidence import posterior_draws
from skinfit.errors import InputError, InputTypeError
from skinfit.io.arguments import as_generator
from skinfit.io.data import Dataset
from skinfit.io.labels import noise_suffix
from skinfit.io.models import Model, load_model
from skinfit.io.priors import PriorSet, list_priors, load_priors
from skinfit.io.user_priors import as_prior_set
from skinfit.results.fit import Fit

__all__ = ["design", "model_priors"]


def design(fit_or_model: str | Model | Fit, candidates: str | os.PathLike | Mapping, n: int = 24,
           params: Sequence[str] | None = None, rng: int | np.random.Generator | None = None, *,
           discriminate: Sequence[str | Model] = (), baseline: str | os.PathLike | pd.DataFrame | None = None,
           noise_scale: float | None = None, priors: str | os.PathLike | PriorSet | Mapping | None = None,
           n_outer: int = 400, n_inner: int = 400, n_batch: int = 200, n_draws: int = 4000) -> DesignResult:
    """Which ``n`` measurements to make next, from the candidates, to learn most about ``params``.

    Parameters
    ----------
    fit_or_model : Fit, Model or model id
        A fit (its posterior draws, noise model and noise scale; sequential design) or a model
        (its prior file's priors, the card's noise model).
    candidates : path of a TOML file, its mapping (see :func:`read_candidates`), or a mapping /
        DataFrame of SI covariate arrays.
    n : int
        Measurements in the plan (repeats of a candidate allowed).
    params : list of parameter names, optional
        Target parameters (default all of the model's); the others are nuisance.
    rng : int, None or numpy.random.Generator
        The one source of every random draw.
    discriminate : list of model ids
        Competing models: the plan then maximises the expected ln Bayes factor of the generating
        model against its best competitor (see :func:`discrimination_plan`).
    baseline : dataset id or path, or a DataFrame (SI), optional
        Design to compare with (default: the fit's dataset, else the model's shipped dataset),
        ``n`` rows evenly spaced.  A model of one's own (:meth:`~skinfit.Model.from_function`)
        has no shipped dataset: give its data here.
    noise_scale : float or mapping observable -> float, optional
        Noise sd in the likelihood's space (N for a normal tangential force, log units for a
        log-normal one); default the fit's posterior median, else the prior's median.
    priors : PriorSet, prior file id or path, or mapping name -> scipy.stats distribution, optional
        A model's priors (as :func:`skinfit.fit` takes them; default its prior file); a model
        made from a Python function has none, so needs them here.  Not with a fit (its own).

    Returns
    -------
    DesignResult
    """
    t0 = time.perf_counter()
    check_counts(n=n, n_outer=n_outer, n_inner=n_inner, n_batch=n_batch, n_draws=n_draws)
    if isinstance(rng, bool) or not (rng is None or isinstance(rng, (int, np.integer, np.random.Generator))) \
            or (isinstance(rng, (int, np.integer)) and rng < 0):
        raise InputError("--seed", f"expected an integer seed >= 0, None or a numpy Generator (got {rng!r})")
    seed = int(rng) if isinstance(rng, (int, np.integer)) else None
    rng = as_generator(rng)
    fit = fit_or_model if isinstance(fit_or_model, Fit) else None
    if fit is not None:
        post = fit.posterior
        model = post.model
        if post.split:
            raise InputError(f"fit of {model.id}", f"design from a fit with split parameters "
                             f"({', '.join(post.split)}) is not supported: fit them shared")
        if priors is not None:
            raise InputError("design", "priors= applies to a model; a fit's priors are those it was fitted with",
                             field="priors")
        priors = post.priors
        noise_kinds = dict(post.noise)
    else:
        if not isinstance(fit_or_model, (Model, str, os.PathLike)):
            raise InputTypeError("fit_or_model", f"expected a Fit, a Model or a model id (got "
                                 f"{type(fit_or_model).__name__})")
        model = fit_or_model if isinstance(fit_or_model, Model) else load_model(fit_or_model)
        priors = model_priors(model, priors)
        noise_kinds = {o.name: o.noise for o in model.observables}
    names = model.parameter_names
    params = check_params(params, model)
    discriminate = check_discriminate(discriminate, model)
    check_noise_scale(noise_scale, model)
    if baseline is not None and not isinstance(baseline, (str, os.PathLike, pd.DataFrame, Dataset)):
        raise InputError("--baseline", f"expected a dataset id or path, or a DataFrame (got {type(baseline).__name__})")
    targets = list(names) if params is None else params
    if isinstance(candidates, (str, os.PathLike)) or (
            isinstance(candidates, dict) and {"grid", "points"} & set(candidates)):
        X, units = read_candidates(candidates, model)
    elif isinstance(candidates, (pd.DataFrame, Mapping)):
        X, units = si_candidates(candidates, model)
    else:
        raise InputError("--candidates", f"expected a candidates file, its mapping or a table of SI covariates "
                         f"(got {type(candidates).__name__})")
    C = n_candidates(X)
    x_base, base_label = baseline_design(model, fit, baseline, n, units)
    for k in X:
        units.setdefault(k, "1")

    if fit is not None:
        theta = posterior_draws(fit)
        if len(theta) > n_draws:
            theta = theta[rng.choice(len(theta), n_draws, replace=False)]
        cols = {s.name: theta[:, j] for j, s in enumerate(post.slots)}
        typical_se = {o: float(np.median(se / post.y[o] if post.noise[o] == "lognormal" else se))
                      for o, se in post.se.items()}  # the fit's sigma is the scatter beyond them
        noise, sigma = noise_setup(model, priors, noise_kinds, noise_scale, cols, typical_se)
        draws = np.column_stack([cols[p] for p in names])
        is_log = log_coordinates(priors, names)
        u = to_u(draws, is_log)
        loc, cov = u.mean(axis=0), np.atleast_2d(np.cov(u, rowvar=False))
        dens, marg = gaussian_density(loc, cov)
        problem = model_problem(model, draws, is_log, noise, sigma, post.constants, dens, marg, loc, cov)
        problem = replace(problem, **fit_density(post, names, theta))
        start = f"the posterior of fit {fit.model_id} on {fit.dataset_id} ({len(draws)} draws)"
    else:
        noise, sigma = noise_setup(model, priors, noise_kinds, noise_scale)
        problem = prior_problem(model, priors, rng, n_draws, noise, sigma)
        start = f"the priors {priors.path or priors.id} ({n_draws} draws)"
    estimate = check_cost(problem, X, x_base, n=n, n_outer=min(n_outer, len(problem.draws) // 2),
                           n_inner=n_inner, n_batch=n_batch, params=params, fit=fit, discriminate=discriminate,
                           rows=fit.posterior.n if fit is not None else 0)
    problem, dropped = restrict_to_support(problem, [X, x_base])
    focus = problem.focus_index(targets)
    n_out = min(n_outer, len(problem.draws) // 2)  # what eig_nmc takes of the draws left
    n_in = min(n_inner, len(problem.draws) - n_out)

    rivals = []  # the competing models, their priors and noise kinds: read and checked before the work
    for other in discriminate:
        m = load_model(other)
        missing = [c.name for c in m.covariates if c.name not in X and not c.optional]
        if missing:
            raise InputError("--discriminate", f"model {m.id!r} needs covariate {missing[0]!r}, which the "
                             f"candidates do not give")
        pr = load_priors(m.id)
        kinds = {o.name: o.noise for o in m.observables}
        if set(kinds) != set(noise):
            raise InputError("--discriminate", f"model {m.id!r} observes {sorted(kinds)}, not {sorted(noise)}")
        rivals.append((m, pr, kinds))

    single_nmc = eig_nmc(problem, X, rng, params=params, n_outer=n_outer, n_inner=n_inner)
    disc_table = None
    if discriminate:
        obs = model.observable_names
        problems = [replace(problem, noise_priors=tuple(priors[f"sigma{noise_suffix(obs, o)}"] for o in obs))]
        for m, pr, kinds in rivals:
            nz, _ = noise_setup(m, pr, kinds, 1.0)
            prob = prior_problem(m, pr, rng, n_draws, nz, sigma)
            prob = replace(prob, noise_priors=tuple(pr[f"sigma{noise_suffix(obs, o)}"] for o in obs))
            problems.append(restrict_to_support(prob, [X, x_base])[0])
        idx, disc_plan = discrimination_plan(problems, X, n, rng, n_outer=min(n_outer, 150), n_inner=n_inner)
        Xb = {k: np.concatenate([X[k], x_base[k]]) for k in X}
        _, disc_base = discrimination_plan(problems, Xb, len(x_base[next(iter(x_base))]), rng,
                                           n_outer=min(n_outer, 150), n_inner=n_inner,
                                           plan=C + np.arange(len(x_base[next(iter(x_base))])))
        ids = [model.id, *discriminate]
        disc_table = pd.concat([disc_plan.assign(design="plan"), disc_base.assign(design="baseline")])
        disc_table["generating"] = [ids[a] for a in disc_table["generating"]]
        disc_table = disc_table[["design", "generating", "expected_ln_bf_capped", "se", "median_ln_bf",
                                 "p_ln_bf_gt_3"]]
        _, _, _, u_outer = greedy_plan(problem, X, 0, rng, params=params, n_outer=n_batch)
        selection = ("greedy on the expected ln Bayes factor (capped at +-6) of the generating model against its "
                     "best competitor (nested Monte Carlo marginal likelihoods over each model's draws)")
    else:
        idx, gains, _, u_outer = greedy_plan(problem, X, n, rng, params=params, n_outer=n_batch)
        selection = "greedy on the Laplace (Fisher-information) EIG, Bayesian D_s-optimal"
    single = laplace_gains(np.broadcast_to(problem.cov, (len(u_outer), problem.d, problem.d)).copy(),
                           fisher_factors(problem, u_outer, X), focus).mean(axis=0)
    X_plan = take_x(X, idx)
    rows = {}
    sds = {}
    for label, Xd in (("plan", X_plan), ("baseline", x_base)):
        if fit is None:  # the prior's density is exact: Laplace-based importance sampling
            e, se, bias = batch_eig(problem, Xd, rng, params=params, n_outer=n_batch, n_inner=n_batch)
        else:  # the posterior's own draws and density (its Gaussian approximation can be far off)
            got = eig_nmc(problem, Xd, rng, params=params, n_outer=n_outer, n_inner=n_inner, batch=True)
            e, se, bias = (float(got[k][0]) for k in ("eig", "eig_se", "eig_bias"))
        e_lap, sd = laplace_design(problem, Xd, u_outer, params)
        rows[label] = {"n": n_candidates(Xd), "eig_nmc": e, "eig_nmc_se": se, "eig_nmc_bias": bias,
                       "eig_laplace": e_lap}
        sds[label] = sd
    if disc_table is not None:
        for label in rows:
            part = disc_table[disc_table["design"] == label]
            rows[label]["expected_ln_bf_capped"] = float(part["expected_ln_bf_capped"].mean())
            rows[label]["p_ln_bf_gt_3"] = float(part["p_ln_bf_gt_3"].mean())
    comparison = pd.DataFrame.from_dict(rows, orient="index")
    now_sd = np.sqrt(np.diag(problem.cov))
    is_log = log_coordinates(priors, names)
    sd = pd.DataFrame({"coordinate": ["log" if is_log[j] else "natural" for j in focus],
                       "now": now_sd[focus], "plan": sds["plan"][focus], "baseline": sds["baseline"][focus]},
                      index=[names[j] for j in focus])
    sd["plan/baseline"] = sd["plan"] / sd["baseline"]
    covs = [c.name for c in model.covariates if c.name in units and not np.all(np.isnan(X[c.name]))]
    table = user_frame(X, units, np.arange(C), covs)
    for key, value in single_nmc.items():
        table[key] = value
    table["eig_laplace"] = single
    table["in_plan"] = np.bincount(idx, minlength=C)
    plan = user_frame(X, units, idx, covs)
    plan.insert(0, "order", np.arange(1, len(idx) + 1))
    if not discriminate:
        plan["laplace_gain"] = gains
    baseline_frame = user_frame(x_base, units, np.arange(n_candidates(x_base)), covs)
    over = int(np.sum(np.abs(table["eig_bias"]) > table["eig_se"]))
    nuisance = ("none (all parameters are targets)" if len(focus) == problem.d else
                "drawn from their priors (independent of the targets)" if fit is None else
                "drawn given the targets, weighted by the fit's posterior density")
    settings = {"model": model.id, "start": start, "params": targets, "n": int(n), "seed": seed,
                "selection": selection,
                "eig_single": f"nested Monte Carlo (Ryan 2003; Rainforth et al. 2018), {n_out} outer x "
                              f"{n_in} inner draws shared by all candidates; read eig (the outer draw among the "
                              f"inner ones, Foster et al. 2019; about all parameters a lower bound) +- eig_se "
                              f"(outer draws plus a jackknife over blocks of inner draws), eig_bias its estimated "
                              f"bias (half the inner draws vs all); eig_upper an upper bound (Ryan 2003); "
                              f"nuisance parameters {nuisance}",
                "eig_batch": (f"nested Monte Carlo with Laplace-based importance sampling (Beck et al. 2018), "
                              f"{n_batch} outer x {n_batch} inner draws" if fit is None else
                              f"nested Monte Carlo over the fit's posterior draws, {n_out} outer x {n_in} "
                              f"inner, as for one measurement"),
                "eig_bias_over_se": int(over),
                "laplace": "approximate: Gaussian current distribution in u, Fisher information at each outer draw",
                "noise": {o: {"model": k, "scale": float(s), **({"nu": v} if math.isfinite(v) else {})}
                          for (o, (k, v)), s in zip(noise.items(), sigma)},
                "baseline": base_label, "discriminate": list(discriminate),
                "draws_dropped_outside_support": dropped, "candidates": C, "estimated_seconds": round(estimate, 1),
                "seconds": time.perf_counter() - t0}
    plot = {"x": model.plot.get("x") if model.plot.get("x") in covs else (covs[0] if covs else None),
            "xscale": model.plot.get("xscale", "linear")}
    return DesignResult(model.id, tuple(covs), units, table, plan, baseline_frame, comparison, sd, settings,
                        disc_table, plot)


def model_priors(model, priors):
    """The PriorSet :func:`design` draws a model's parameters from: ``priors`` as
    :func:`skinfit.fit` takes them, else the model's prior file; a model made from a Python
    function without one is an InputError saying to pass ``priors=``."""
    if isinstance(priors, Mapping):
        return as_prior_set(priors, model, "design")
    if priors is None and model.user_function and model.id not in list_priors():
        raise InputError("design", f"model {model.id!r} was made from a Python function and has no prior file: pass "
                                   "priors={name: scipy.stats distribution} (sigma for the noise too)", field="priors")
    return priors if isinstance(priors, PriorSet) else load_priors(model.id if priors is None else priors)
