"""The design problem of a model: its priors' draws or a fit's posterior draws, in the coordinate
u (log of positive parameters), with the noise of the card or the fit."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import stats

from skinfit.analysis.design.problem import DesignProblem, n_candidates
from skinfit.errors import InputError
from skinfit.io.labels import noise_suffix

__all__ = ["to_u", "log_coordinates", "model_problem", "prior_problem", "fit_density", "gaussian_density",
           "noise_setup"]


def to_u(draws, is_log):
    """Natural parameters (k, d) -> the coordinate u (log where ``is_log``)."""
    u = np.array(draws, dtype=float)
    u[:, is_log] = np.log(u[:, is_log])
    return u


def log_coordinates(priors, names):
    """Per parameter: log coordinate when its prior's lower bound is > 0, else natural."""
    return np.array([priors[n].lower > 0 for n in names])


def model_problem(model, draws, is_log, noise, sigma, constants, log_density, log_marginal, loc=None, cov=None):
    """A DesignProblem for ``model``: draws (D, d) natural parameters in card order."""
    names = model.parameter_names
    obs = model.observable_names
    log_obs = np.array([noise[o][0] == "lognormal" for o in obs])
    nu = np.array([noise[o][1] for o in obs])
    c = {**model.constants, **(constants or {})}

    def mean(u, X):
        out = np.empty((len(u), n_candidates(X), len(obs)))
        step = max(1, 2_000_000 // max(n_candidates(X), 1))
        for i in range(0, len(u), step):
            theta = np.array(u[i:i + step], dtype=float)
            theta[:, is_log] = np.exp(theta[:, is_log])
            p = {n: theta[:, j:j + 1] for j, n in enumerate(names)}
            with np.errstate(all="ignore"):
                y, ok = model.forward(p, X, c)
                for r, o in enumerate(obs):
                    v = np.broadcast_to(y[o], (len(theta), n_candidates(X)))
                    v = np.log(v) if log_obs[r] else v
                    out[i:i + step, :, r] = np.where(np.broadcast_to(ok, v.shape) & np.isfinite(v), v, np.nan)
        return out

    u = to_u(draws, is_log)
    loc = u.mean(axis=0) if loc is None else loc
    cov = np.atleast_2d(np.cov(u, rowvar=False)) if cov is None else cov
    return DesignProblem(tuple(names), mean, np.asarray(sigma, float), nu, u, loc, cov,
                         log_density, log_marginal, obs)


def prior_problem(model, priors, rng, n_draws, noise, sigma, constants=None):
    names = model.parameter_names
    is_log = log_coordinates(priors, names)
    draws = np.column_stack([priors[n].rvs(n_draws, rng) for n in names])

    def log_marginal(u, idx):
        u = np.atleast_2d(u)
        total = np.zeros(len(u))
        for j in np.atleast_1d(idx):
            theta = np.exp(u[:, j]) if is_log[j] else u[:, j]
            total += priors[names[j]].logpdf(theta) + (u[:, j] if is_log[j] else 0.0)
        return total

    problem = model_problem(model, draws, is_log, noise, sigma, constants,
                             lambda u: log_marginal(u, np.arange(len(names))), log_marginal)
    # independent by construction: nuisance given the targets is a plain swap (B = 0 exactly)
    return replace(problem, base_cov=np.diag(np.diag(problem.cov)))


def fit_density(post, names, theta):
    """A fit's posterior for :func:`eig_nmc`'s conditional draws: ``log_joint`` (its log
    density, prior times likelihood of its data, unnormalised, in v = (u of ``names``, the other
    slots: noise parameters, log where their prior is positive), Jacobian included) and the
    draws' extra coordinates ``extra_draws`` (D, e); ``theta`` (D, slots) natural, slot order."""
    slots = [s.name for s in post.slots]
    order = [slots.index(n) for n in names] + [j for j, n in enumerate(slots) if n not in names]
    is_log = np.array([post.priors[slots[j]].lower > 0 for j in order])

    def log_joint(v):
        v = np.atleast_2d(v)
        theta_v = np.where(is_log, np.exp(np.where(is_log, v, 0.0)), v)
        natural = np.empty_like(theta_v)
        natural[:, order] = theta_v
        out = post.log_prior(natural)
        inside = np.isfinite(out)
        if inside.any():
            out[inside] += post.log_likelihood(natural[inside])
        return out + (v * is_log).sum(axis=1)

    extra = to_u(theta[:, order], is_log)[:, len(names):]
    return {"log_joint": log_joint, "extra_draws": extra if extra.shape[1] else None}


def gaussian_density(loc, cov):
    dist = stats.multivariate_normal(loc, cov, allow_singular=True)

    def log_marginal(u, idx):
        idx = np.atleast_1d(idx)
        return np.atleast_1d(
            stats.multivariate_normal(loc[idx], cov[np.ix_(idx, idx)]).logpdf(np.atleast_2d(u)[:, idx]))

    return (lambda u: np.atleast_1d(dist.logpdf(u))), log_marginal


def noise_setup(model, priors, noise_kinds, noise_scale, fit_draws=None, known_se=None):
    """observable -> (kind, nu) and sigma (r,) in the likelihood's space.

    ``known_se`` (observable -> a typical per-row standard error in the likelihood's space, e.g.
    the median of a fit's data): a fit whose data gave their standard errors estimated sigma as
    the scatter beyond them, so a new measurement's noise sd is sqrt(sigma^2 + se^2) (unless
    ``noise_scale`` gives it)."""
    obs = model.observable_names
    scale = {}
    for o in obs:
        suffix = noise_suffix(obs, o)
        given = noise_scale.get(o) if isinstance(noise_scale, dict) else noise_scale
        if given is not None:
            scale[o] = float(given)
        elif fit_draws is not None:
            scale[o] = float(np.hypot(np.median(fit_draws[f"sigma{suffix}"]), (known_se or {}).get(o, 0.0)))
        else:
            scale[o] = float(priors[f"sigma{suffix}"].ppf(0.5))
        if not (math.isfinite(scale[o]) and scale[o] > 0):
            raise InputError("noise_scale", f"noise scale of {o} must be > 0 (got {scale[o]!r})")
    nu = {}
    for o in obs:
        if noise_kinds[o] == "student_t":
            key = f"nu{noise_suffix(obs, o)}"
            nu[o] = float(np.median(fit_draws[key])) if fit_draws is not None else float(priors[key].ppf(0.5))
        else:
            nu[o] = np.inf
    return {o: (noise_kinds[o], nu[o]) for o in obs}, np.array([scale[o] for o in obs])
