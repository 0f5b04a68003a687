"""Which measurement next: Bayesian experimental design over a model's covariates.

Ranks candidate measurement conditions (loads, voltages, ...) by the expected information gain
(EIG) about chosen parameters, proposes a batch of ``n`` measurements, compares it with a
baseline design, and (``discriminate``) finds the batch that best separates competing models.

Estimators (every random draw from the one ``rng``):

* One candidate at a time: nested Monte Carlo (Ryan 2003, "Estimating expected information
  gains for experimental designs with application to the random fatigue-limit model";
  Rainforth et al. 2018, "On nesting Monte Carlo estimators"), vectorised over candidates and
  inner draws.  The outer draws, their simulated observations and the ``M`` inner draws are
  shared by every candidate (common random numbers: differences between candidates are
  estimated much better than the values).  The reported error is the outer standard error;
  the inner estimate adds a bias of order 1/M upwards (Rainforth et al. 2018).
  For a subset of parameters the nuisance parameters are marginalised by swapping the outer
  draw's target values into each inner draw, exact when the target and nuisance parameters are
  independent (as the prior files make them; an approximation from a fit's posterior).
* Batches: greedy selection on the Laplace / Fisher-information approximation
  EIG ~ E_theta[0.5 log det Sigma0_psi - 0.5 log det Sigma_post_psi(theta)], Sigma_post^-1 =
  Sigma0^-1 + sum of the points' Fisher information (a Bayesian D_s-optimal criterion, Chaloner
  & Verdinelli 1995, "Bayesian experimental design: a review"), with the current distribution
  approximated by a Gaussian in the coordinate u (log of parameters with a positive lower
  bound, else natural).  It is approximate for non-linear models and exact for a linear-Gaussian
  one.  The EIG of the whole batch is then estimated jointly by nested Monte Carlo with
  Laplace-based importance sampling of the inner draws (Beck et al. 2018, "Fast Bayesian
  experimental design: Laplace-based importance sampling for the expected information gain"),
  which stays accurate where plain inner sampling from the prior saturates.
* Discrimination: greedy on the expected log Bayes factor of the generating model against its
  best competitor (capped at +-6 nats), each model's marginal likelihood of the simulated batch
  by nested Monte Carlo over its own prior (or fit) draws at the fixed noise sd; these are
  biased low once a batch determines the parameters, so they only rank candidates.  The
  plan's and the baseline's median ln BF and P(ln BF > 3) come from Laplace evidences of every
  model for each simulated batch, the noise sd integrated over its prior (a misfitting model
  inflates its noise, as a fit does).  bench/bench_design.py checks them against full fits.

The noise model of each observable is the model card's (or the fit's); its scale is fixed at
the fit's posterior median, else the prior's median, unless ``noise_scale`` is given.
Parameters whose prediction leaves the model's physical support at a candidate are dropped from
the draws (the support is part of the model; how many is reported).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # names used only in annotations
    import os
    from collections.abc import Mapping, Sequence
    from .fit import Fit
    from .models import Model

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import special, stats

from .errors import InputError
from .outputs import check_outputs
from .units import UNITS, dimension, to_si

__all__ = ["DesignProblem", "DesignResult", "design", "gaussian_problem", "read_candidates", "eig_nmc", "laplace_gains",
           "greedy_plan", "batch_eig", "discrimination_plan", "plot_eig", "design_section_html", "load_design", "cli_design"]

_LOG_2PI = math.log(2.0 * math.pi)
#: (outer x inner x candidate) cells per vectorised block of the nested estimators
_CELLS = 4_000_000


# ---- the problem: draws, a mean function and the noise --------------------------------------
@dataclass(frozen=True)
class DesignProblem:
    """What the estimators need, in a coordinate ``u`` of the parameters (d of them).

    ``mean(u, X)``: u (k, d), X a mapping covariate -> (C,) SI array; returns (k, C, r), the
    expected observation of each of r observables in the space where the noise is additive
    (log of the observable for a log-normal likelihood; NaN outside the physical support).
    ``sigma`` (r,) the noise sd there; ``nu`` (r,) Student-t degrees of freedom (inf = normal).
    ``draws`` (D, d) of the current distribution (prior or posterior) in u; ``loc``, ``cov`` its
    Gaussian approximation; ``log_density(u)`` (k,) its log density for importance sampling and
    ``log_marginal(u, idx)`` (k,) that of the coordinates ``idx`` alone.
    """

    names: tuple
    mean: object
    sigma: np.ndarray
    nu: np.ndarray
    draws: np.ndarray
    loc: np.ndarray
    cov: np.ndarray
    log_density: object
    log_marginal: object
    observables: tuple = ("y",)
    noise_priors: tuple | None = None  # per observable, the prior of its noise sd (discrimination)

    @property
    def d(self):
        return len(self.names)

    def focus_index(self, params):
        """Indices of the target parameters ``params`` (None = all)."""
        if params is None:
            return np.arange(self.d)
        return np.array([self.names.index(p) for p in params])


def gaussian_problem(names, mean, sigma, loc, cov, draws, *, nu=None, observables=("y",)):
    """A :class:`DesignProblem` whose current distribution is the Gaussian N(loc, cov)."""
    loc, cov = np.asarray(loc, float), np.atleast_2d(np.asarray(cov, float))
    dist = stats.multivariate_normal(loc, cov)

    def log_marginal(u, idx):
        return np.atleast_1d(stats.multivariate_normal(loc[idx], cov[np.ix_(idx, idx)]).logpdf(u[..., idx]))

    sigma = np.atleast_1d(np.asarray(sigma, float))
    return DesignProblem(tuple(names), mean, sigma, np.full(len(sigma), np.inf) if nu is None else np.asarray(nu, float),
                         np.asarray(draws, float), loc, cov, lambda u: np.atleast_1d(dist.logpdf(u)), log_marginal,
                         tuple(observables))


def _log_lik(y, mu, sigma, nu):
    """log p(y | mu) summed over the last axis (observables): normal or Student-t, broadcasting;
    -inf where mu is NaN (outside the support)."""
    z = (y - mu) / sigma
    if np.all(np.isinf(nu)):
        ll = -0.5 * z * z - np.log(sigma) - 0.5 * _LOG_2PI
    else:
        ll = np.where(np.isinf(nu), stats.norm.logpdf(z), stats.t.logpdf(z, np.where(np.isinf(nu), 1.0, nu))) - np.log(sigma)
    return np.where(np.isnan(ll), -np.inf, ll).sum(axis=-1)


def _log_sum_lik(y, mu, sigma, nu, offset=None):
    """log sum_m exp(offset[n, m]) p(y_n | mu_m) for y (N, C, r), mu (M, C, r), offset (N, M)
    or None -> (N, C): the hot loop of the nested estimators, in place for a normal likelihood
    (NaN predictions count as zero likelihood)."""
    if not np.all(np.isinf(nu)):
        ll = _log_lik(y[:, None], mu[None], sigma, nu)
        return special.logsumexp(ll if offset is None else ll + offset[:, :, None], axis=1)
    mu = np.where(np.isnan(mu), np.inf, mu) / sigma
    y = y / sigma
    q = np.zeros((len(y), len(mu), y.shape[1]))
    for r in range(y.shape[2]):
        d = np.subtract(y[:, None, :, r], mu[None, :, :, r])
        d *= d
        q += d
    q *= -0.5
    if offset is not None:
        q += offset[:, :, None]
    top = q.max(axis=1)
    top = np.where(np.isfinite(top), top, 0.0)
    q -= top[:, None]
    np.exp(q, out=q)
    with np.errstate(divide="ignore"):
        return np.log(q.sum(axis=1)) + top - np.log(sigma).sum() - 0.5 * _LOG_2PI * y.shape[2]


def _noise(rng, shape, nu):
    """Standardised noise draws of shape (..., r)."""
    eps = rng.standard_normal(shape)
    if not np.all(np.isinf(nu)):
        df = np.broadcast_to(np.where(np.isinf(nu), 1.0, nu), shape)
        eps = np.where(np.isinf(nu), eps, rng.standard_t(df))
    return eps


def _t_weight(nu):
    """sqrt of the Fisher information of a Student-t location relative to a normal's,
    (nu + 1) / (nu + 3); 1 for a normal likelihood (nu = inf)."""
    finite = np.where(np.isinf(nu), 1.0, nu)
    return np.where(np.isinf(nu), 1.0, np.sqrt((finite + 1) / (finite + 3)))


def _take_x(X, idx):
    return {k: np.asarray(v)[idx] for k, v in X.items()}


def _n_candidates(X):
    return len(next(iter(X.values())))


def _split_draws(problem, rng, n_outer, n_inner):
    """Disjoint outer and inner draws (shuffled); fewer when the draws run short."""
    D = len(problem.draws)
    perm = rng.permutation(D)
    n_outer = min(n_outer, D // 2)
    n_inner = min(n_inner, D - n_outer)
    return problem.draws[perm[:n_outer]], problem.draws[perm[n_outer:n_outer + n_inner]]


# ---- nested Monte Carlo, one candidate at a time ----------------------------------------------
def eig_nmc(problem, X, rng, *, params=None, n_outer=500, n_inner=500, upper=False):
    """Expected information gain of one measurement at each candidate, by nested Monte Carlo.

    Returns (eig, se), each (C,) in nats: the mean over outer draws n of
    log p^(y_n|psi_n) - log p^(y_n), and its standard error over the outer draws.  The
    evidence p^(y_n) averages p(y_n|u) over the M inner draws *and the outer draw itself*
    (the prior contrastive estimate of Foster et al. 2019, "Variational Bayesian optimal
    experimental design"): a lower bound of the EIG in expectation, each term at most
    log(M + 1), so a measurement whose outcome the inner draws miss cannot blow the mean up.
    ``upper=True`` leaves the outer draw out (Ryan 2003's estimator, an upper bound in
    expectation; heavy-tailed when the prior predictive is); the two bracket the EIG.
    """
    u_out, u_in = _split_draws(problem, rng, n_outer, n_inner)
    N, M, C = len(u_out), len(u_in), _n_candidates(X)
    mu_out = problem.mean(u_out, X)  # (N, C, r)
    y = mu_out + problem.sigma * _noise(rng, mu_out.shape, problem.nu)
    mu_in = problem.mean(u_in, X)  # (M, C, r)
    focus = problem.focus_index(params)
    log_true = _log_lik(y, mu_out, problem.sigma, problem.nu)  # (N, C)
    log_evid = np.empty((N, C))
    block = max(1, _CELLS // max(N * M, 1))
    for c in range(0, C, block):
        s = slice(c, c + block)
        log_evid[:, s] = _log_sum_lik(y[:, s], mu_in[:, s], problem.sigma, problem.nu)
    if len(focus) == problem.d:
        log_num = log_true
    else:  # p(y | psi_n): inner draws with the outer draw's target values swapped in
        log_num = np.empty((N, C))
        rows = max(1, _CELLS // max(M * C, 1))
        for i in range(0, N, rows):
            part = u_out[i:i + rows]
            u = np.broadcast_to(u_in, (len(part), M, problem.d)).copy()
            u[:, :, focus] = part[:, None, focus]
            mu = problem.mean(u.reshape(-1, problem.d), X).reshape(len(part), M, C, -1)
            log_num[i:i + rows] = special.logsumexp(_log_lik(y[i:i + rows, None], mu, problem.sigma, problem.nu), axis=1)
        if not upper:
            log_num = np.logaddexp(log_num, log_true) - math.log(M + 1)
        else:
            log_num = log_num - math.log(M)
    log_evid = log_evid - math.log(M) if upper else np.logaddexp(log_evid, log_true) - math.log(M + 1)
    terms = log_num - log_evid
    return terms.mean(axis=0), terms.std(axis=0, ddof=1) / math.sqrt(N)


# ---- Laplace / Fisher information --------------------------------------------------------------
def fisher_factors(problem, u, X):
    """Per draw and candidate, G (k, C, d, r) with Fisher information G G^T: d mean / du
    (central differences, steps 1e-4 of each coordinate's sd) scaled by 1/sigma, and by
    sqrt((nu+1)/(nu+3)) for a Student-t likelihood."""
    k, d = u.shape
    h = 1e-4 * np.sqrt(np.diag(problem.cov))
    steps = np.concatenate([u[None] + np.diag(h)[:, None, :], u[None] - np.diag(h)[:, None, :]])  # (2d, k, d)
    mu = problem.mean(steps.reshape(-1, d), X).reshape(2, d, k, _n_candidates(X), -1)
    jac = (mu[0] - mu[1]) / (2 * h[:, None, None, None])  # (d, k, C, r)
    w = _t_weight(problem.nu) / problem.sigma
    G = np.moveaxis(jac, 0, 2) * w  # (k, C, d, r)
    return np.where(np.isfinite(G), G, 0.0)


def _logdet_focus(S, focus):
    return np.linalg.slogdet(S[..., focus[:, None], focus[None, :]])[1]


def _update(S, G):
    """Posterior covariance after adding Fisher information G G^T: S (..., d, d), G (..., d, r)."""
    U = S @ G
    K = np.eye(G.shape[-1]) + np.swapaxes(G, -1, -2) @ U
    return S - U @ np.linalg.solve(K, np.swapaxes(U, -1, -2))


def laplace_gains(S, G, focus):
    """Laplace information gain of adding each candidate: S (N, d, d), G (N, C, d, r) ->
    (N, C) nats, 0.5 log det S_psi - 0.5 log det S'_psi."""
    base = _logdet_focus(S, focus)[:, None]
    out = np.empty(G.shape[:2])
    block = max(1, 2_000_000 // max(G.shape[0] * S.shape[-1] ** 2, 1))
    for c in range(0, G.shape[1], block):
        S_new = _update(S[:, None], G[:, c:c + block])
        out[:, c:c + block] = 0.5 * (base - _logdet_focus(S_new, focus))
    return out


def greedy_plan(problem, X, n, rng, *, params=None, n_outer=200, u_outer=None):
    """Greedy batch of ``n`` candidate indices (repeats allowed) maximising the Laplace EIG.

    Each step adds the candidate with the largest mean (over outer draws) Laplace gain given
    the points chosen so far.  Returns (indices (n,), gains (n,), S (N, d, d) the Laplace
    posterior covariances at the outer draws after the plan, outer draws).
    """
    if u_outer is None:
        u_outer = problem.draws[rng.choice(len(problem.draws), min(n_outer, len(problem.draws)), replace=False)]
    focus = problem.focus_index(params)
    G = fisher_factors(problem, u_outer, X)
    S = np.broadcast_to(problem.cov, (len(u_outer), problem.d, problem.d)).copy()
    chosen, gains = [], []
    for _ in range(n):
        g = laplace_gains(S, G, focus).mean(axis=0)
        best = int(np.argmax(g))
        chosen.append(best)
        gains.append(float(g[best]))
        S = _update(S, G[:, best])
    return np.array(chosen, dtype=int), np.array(gains), S, u_outer


def laplace_design(problem, X, u_outer, params=None):
    """Laplace EIG of the design X (all its points together) and the predicted posterior sd of
    each coordinate (root mean square over the outer draws), (eig, sd (d,))."""
    focus = problem.focus_index(params)
    G = fisher_factors(problem, u_outer, X)  # (N, B, d, r)
    P = np.linalg.inv(problem.cov) + np.einsum("nbir,nbjr->nij", G, G)
    S = np.linalg.inv(P)
    eig = 0.5 * (_logdet_focus(problem.cov[None], focus)[0] - _logdet_focus(S, focus))
    return float(eig.mean()), np.sqrt(np.mean(np.diagonal(S, axis1=1, axis2=2), axis=0))


# ---- nested Monte Carlo of a whole batch (Laplace-based importance sampling) ------------------
def _is_log_evidence(problem, y_n, X, u_fixed, idx, loc, shape, n_inner, df, rng):
    """log of the importance-sampling estimate of the integral of p(y_n | u) p(u_idx | u_rest)
    over the coordinates ``idx`` (the rest held at ``u_fixed``), with a Student-t proposal."""
    shape = 0.5 * (shape + shape.T)
    q = stats.multivariate_t(loc, shape, df=df)
    v = np.asarray(q.rvs(n_inner, random_state=rng), dtype=float).reshape(n_inner, len(idx))
    u = np.broadcast_to(u_fixed, (n_inner, len(u_fixed))).copy()
    u[:, idx] = v
    ll = _log_lik(y_n[None], problem.mean(u, X), problem.sigma, problem.nu).sum(axis=-1)
    log_p = problem.log_density(u)
    log_w = np.where(np.isfinite(log_p) & np.isfinite(ll), ll + log_p - np.atleast_1d(q.logpdf(v)), -np.inf)
    return special.logsumexp(log_w) - math.log(n_inner)


def batch_eig(problem, X, rng, *, params=None, n_outer=200, n_inner=200, df=4.0):
    """EIG of all the points of X measured together, by nested Monte Carlo whose inner draws
    come from a Student-t (``df``) around the Gauss-Newton posterior mean and the Laplace
    covariance at each outer draw (Beck et al. 2018).  Returns (eig, se) in nats.

    The evidence p(y_n) integrates every coordinate; with ``params`` a subset, p(y_n | psi_n)
    integrates the nuisance coordinates given the outer draw's target values (the proposal's
    conditional, weighted by p(u) / p(psi_n)).  Both estimates are unbiased; their logs are
    biased by O(1/n_inner), small when the proposal is close to the posterior.
    """
    focus = problem.focus_index(params)
    nuis = np.setdiff1d(np.arange(problem.d), focus)
    u_out = problem.draws[rng.choice(len(problem.draws), min(n_outer, len(problem.draws)), replace=False)]
    N, d = u_out.shape
    mu = problem.mean(u_out, X)  # (N, B, r)
    resid = problem.sigma * _noise(rng, mu.shape, problem.nu)
    y = mu + resid
    G = fisher_factors(problem, u_out, X)  # (N, B, d, r)
    P0 = np.linalg.inv(problem.cov)
    S = np.linalg.inv(P0 + np.einsum("nbir,nbjr->nij", G, G))
    w = _t_weight(problem.nu)
    score = np.einsum("nbir,nbr->ni", G, resid / problem.sigma * w)
    centre = u_out + np.einsum("nij,nj->ni", S, score + (problem.loc - u_out) @ P0)
    all_idx = np.arange(d)
    terms = np.empty(N)
    for n in range(N):
        log_evid = _is_log_evidence(problem, y[n], X, u_out[n], all_idx, centre[n], S[n], n_inner, df, rng)
        if len(nuis) == 0:
            log_num = _log_lik(y[n], mu[n], problem.sigma, problem.nu).sum()
        else:
            Sff, Snf = S[n][np.ix_(focus, focus)], S[n][np.ix_(nuis, focus)]
            reg = np.linalg.solve(Sff, Snf.T).T
            loc = centre[n, nuis] + reg @ (u_out[n, focus] - centre[n, focus])
            shape = S[n][np.ix_(nuis, nuis)] - reg @ Snf.T
            log_num = (_is_log_evidence(problem, y[n], X, u_out[n], nuis, loc, shape, n_inner, df, rng)
                       - problem.log_marginal(u_out[n][None], focus)[0])
        terms[n] = log_num - log_evid
    return float(terms.mean()), float(terms.std(ddof=1) / math.sqrt(N))


# ---- discrimination ------------------------------------------------------------------------------
def discrimination_plan(problems, X, n, rng, *, n_outer=150, n_inner=300, plan=None, cap=6.0):
    """Greedy batch separating the models of ``problems`` (list of DesignProblem over the same
    candidates), or the evaluation of a given ``plan`` (candidate indices).

    For each generating model a: outer draws of a, observations simulated at the batch, and
    every model's log marginal likelihood log p_b(y) by nested Monte Carlo over ``n_inner`` of
    its own draws (the same draws for every candidate).  The utility of a batch is the expected
    ln BF of the generating model against its best competitor, averaged over the generating
    models (equal prior probabilities).  Returns (indices, table) where the table gives, per
    generating model, the expected ln BF, its standard error and P(ln BF > 3).
    """
    K = len(problems)
    split = [_split_draws(p, rng, n_outer, n_inner) for p in problems]
    mu_out = [p.mean(s[0], X) for p, s in zip(problems, split)]  # (N_a, C, r)
    mu_in = [p.mean(s[1], X) for p, s in zip(problems, split)]  # (M_b, C, r)
    # acc[a][b]: (N_a, M_b) log-likelihood of the batch so far under model b's inner draws
    acc = [[np.zeros((len(split[a][0]), len(split[b][1]))) for b in range(K)] for a in range(K)]
    C = _n_candidates(X)
    steps = n if plan is None else len(plan)
    chosen, measured = [], [[] for _ in range(K)]

    def log_bf(a, y, cols):
        """(N_a, C') ln BF of a vs its best competitor after measuring y (N_a, C', r) at cols."""
        lz = [_log_sum_lik(y, mu_in[b][:, cols], problems[b].sigma, problems[b].nu, acc[a][b])
              - math.log(len(mu_in[b])) for b in range(K)]
        return lz[a] - np.max([lz[b] for b in range(K) if b != a], axis=0)

    for step in range(steps):
        cand = np.arange(C) if plan is None else np.array([plan[step]])
        ys = [mu_out[a][:, cand] + problems[a].sigma * _noise(rng, mu_out[a][:, cand].shape, problems[a].nu)
              for a in range(K)]
        utility = np.zeros(len(cand))
        block = max(1, _CELLS // max(n_outer * n_inner, 1))
        for a in range(K):
            for s in range(0, len(cand), block):
                sl = slice(s, s + block)
                utility[sl] += np.clip(log_bf(a, ys[a][:, sl], cand[sl]), -cap, cap).mean(axis=0) / K
        best = int(np.argmax(utility)) if plan is None else 0
        chosen.append(int(cand[best]))
        for a in range(K):
            measured[a].append(ys[a][:, best])
            for b in range(K):
                acc[a][b] += _log_lik(ys[a][:, None, best], mu_in[b][None, :, cand[best]], problems[b].sigma,
                                      problems[b].nu)
    rows = []
    Xb = _take_x(X, np.array(chosen, dtype=int))
    log_prior_in = [problems[b].log_density(split[b][1]) for b in range(K)]
    for a in range(K):
        lz = [special.logsumexp(acc[a][b], axis=1) - math.log(acc[a][b].shape[1]) for b in range(K)]
        bf = lz[a] - np.max([lz[b] for b in range(K) if b != a], axis=0)
        capped = np.clip(bf, -cap, cap)
        y = np.stack(measured[a], axis=1)  # (N_a, B, r)
        lap = [_laplace_log_evidence(problems[b], Xb, y, split[b][1][np.argmax(acc[a][b] + log_prior_in[b], axis=1)])
               for b in range(K)]
        bf_lap = lap[a] - np.max([lap[b] for b in range(K) if b != a], axis=0)
        rows.append({"generating": a, "expected_ln_bf_capped": float(capped.mean()),
                     "se": float(capped.std(ddof=1) / math.sqrt(len(bf))), "median_ln_bf": float(np.median(bf_lap)),
                     "p_ln_bf_gt_3": float(np.mean(bf_lap > 3))})
    return np.array(chosen, dtype=int), pd.DataFrame(rows)


def _laplace_log_evidence(problem, X, y, u, iterations=30):
    """Laplace log evidence of each data set y (N, B, r) at the points X, normal noise.

    Gauss-Newton ascent of log p(y|u, s) + log p(u) from the starts u (N, d) with the noise
    sd s re-estimated from the residuals at each step (a model that misfits inflates its noise,
    as a fit does), then log p(u^) + d/2 log 2 pi - 1/2 log det H + log of p(y|u^, s)
    integrated over the problem's ``noise_priors`` (skinfit Priors of s; quadrature on 400 of
    their quantiles), or at its fixed sd when those are None.  The prior's curvature is its Gaussian
    approximation's.  Approximate, as skinfit.evidence's ``laplace``; (N,) nats.
    """
    P0 = np.linalg.inv(problem.cov)
    N, B, r = y.shape
    priors = problem.noise_priors
    if priors is not None:
        lo = np.array([pr.ppf(0.001) for pr in priors])
        hi = np.array([pr.ppf(0.999) for pr in priors])

    def residual(u):
        return np.nan_to_num(y - problem.mean(u, X), nan=1e6)

    def sd(res):
        if priors is None:
            return np.broadcast_to(problem.sigma, (len(res), r))
        return np.clip(np.sqrt((res ** 2).mean(axis=1)), lo, hi)

    def objective(u, s):
        res = residual(u)
        return (-0.5 * ((res / s[:, None]) ** 2).sum(axis=(1, 2)) - B * np.log(s).sum(axis=1)
                + problem.log_density(u))

    res = residual(u)
    s = sd(res)
    f = objective(u, s)
    for _ in range(iterations):
        G = fisher_factors(problem, u, X) * (problem.sigma / s)[:, None, None, :]
        H = P0 + np.einsum("nbir,nbjr->nij", G, G)
        g = np.einsum("nbir,nbr->ni", G, res / s[:, None]) + (problem.loc - u) @ P0
        step = np.linalg.solve(H, g[..., None])[..., 0]
        scale = np.ones(N)
        moved = np.zeros(N, dtype=bool)
        for _ in range(10):  # halve the step where it does not improve the objective
            trial = u + scale[:, None] * step
            f_trial = objective(trial, s)
            better = (f_trial > f) & (scale > 0)
            u = np.where(better[:, None], trial, u)
            moved |= better
            scale = np.where(better, 0.0, scale * 0.5)
            if not scale.any():
                break
        res = residual(u)
        s = sd(res)
        f = objective(u, s)
    G = fisher_factors(problem, u, X) * (problem.sigma / s)[:, None, None, :]
    H = P0 + np.einsum("nbir,nbjr->nij", G, G)
    rss = (res ** 2).sum(axis=1)  # (N, r)
    if priors is None:
        log_lik = (-0.5 * rss / problem.sigma ** 2 - B * np.log(problem.sigma) - 0.5 * B * _LOG_2PI).sum(axis=1)
    else:
        q = np.array([pr.ppf((np.arange(400) + 0.5) / 400) for pr in priors])  # (r, 400) quadrature nodes
        ll = -0.5 * rss[..., None] / q ** 2 - B * np.log(q) - 0.5 * B * _LOG_2PI  # (N, r, 400)
        log_lik = (special.logsumexp(ll, axis=-1) - math.log(q.shape[1])).sum(axis=1)
    return log_lik + problem.log_density(u) + 0.5 * problem.d * _LOG_2PI - 0.5 * np.linalg.slogdet(H)[1]


# ---- models, fits and candidates ---------------------------------------------------------------
def convert_units(values, unit, target_unit, where, field):
    """``values`` in ``unit`` -> SI, checking that ``unit`` measures what ``target_unit`` (the
    model card's) does.  The one place design converts units (kept small for a move to pint)."""
    if unit not in UNITS:
        raise InputError(where, f"unknown unit {unit!r} (known: {', '.join(UNITS)})", field=field)
    if target_unit in UNITS and dimension(unit) != dimension(target_unit):
        raise InputError(where, f"unit {unit!r} is a {dimension(unit)}, but the model's covariate is in "
                         f"{target_unit!r} (a {dimension(target_unit)})", field=field)
    return np.asarray(values, dtype=float) * to_si(unit)


def read_candidates(source, model):
    """Candidate measurement conditions: (SI covariates {name: (C,)}, units {name: unit}).

    ``source``: a TOML file path, or its parsed mapping, in one of two forms::

        [grid.normal_force]            # every combination of the listed values
        unit = "mN"
        values = [200, 500, 1000]      # or: from = 200, to = 2000, num = 10 (log = true)
        [grid.voltage]
        unit = "V"
        values = [0, 100, 200]

        [units]                        # or a list of points
        normal_force = "mN"
        voltage = "V"
        [[points]]
        normal_force = 200
        voltage = 0

    Every covariate of the model must be given (optional ones may be left out); values must be
    finite and, for forces, lengths, voltages and the like, >= 0.
    """
    where = str(source) if not isinstance(source, dict) else "candidates"
    if isinstance(source, dict):
        doc = source
    else:
        path = Path(source)
        if not path.exists():
            raise InputError(path, "no such candidates file")
        from ._toml import read_toml  # regular files only, bounded size and nesting, errors with the line

        doc, _ = read_toml(path, versioned=False)
    cards = {c.name: c for c in model.covariates}
    columns, units = {}, {}
    if "grid" in doc and "points" in doc:
        raise InputError(where, "give either [grid.<covariate>] tables or [[points]], not both")
    if "grid" in doc:
        for name, spec in doc["grid"].items():
            field = f"grid.{name}"
            if name not in cards:
                raise InputError(where, f"unknown covariate {name!r} of model {model.id!r} (covariates: "
                                 f"{', '.join(cards)})", field=field)
            if not isinstance(spec, dict) or "unit" not in spec:
                raise InputError(where, "expected a table with unit and values (or from, to, num)", field=field)
            if "values" in spec:
                raw = spec["values"]
            elif {"from", "to", "num"} <= set(spec):
                if not (isinstance(spec["num"], int) and spec["num"] >= 1):
                    raise InputError(where, f"num must be an integer >= 1 (got {spec['num']!r})", field=field + ".num")
                space = np.geomspace if spec.get("log", False) else np.linspace
                try:
                    raw = space(float(spec["from"]), float(spec["to"]), spec["num"]).tolist()
                except (TypeError, ValueError) as exc:
                    raise InputError(where, f"bad range ({exc})", field=field) from None
            else:
                raise InputError(where, "expected values = [...] or from, to, num", field=field)
            columns[name] = _numbers(raw, where, field + ".values")
            units[name] = spec["unit"]
        names = list(columns)
        grids = np.meshgrid(*[np.asarray(columns[k]) for k in names], indexing="ij")
        columns = {k: g.ravel() for k, g in zip(names, grids)}
    elif "points" in doc:
        units = dict(doc.get("units", {}))
        points = doc["points"]
        if not isinstance(points, list) or not points:
            raise InputError(where, "expected at least one [[points]] entry", field="points")
        for i, pt in enumerate(points, 1):
            for name in pt:
                if name not in cards:
                    raise InputError(where, f"unknown covariate {name!r} of model {model.id!r} (covariates: "
                                     f"{', '.join(cards)})", field="points", row=i)
        for name in {k for pt in points for k in pt}:
            if name not in units:
                raise InputError(where, f"no unit for {name!r}: add it under [units]", field="units")
            missing = [i for i, pt in enumerate(points, 1) if name not in pt]
            if missing:
                raise InputError(where, f"covariate {name!r} missing", field="points", row=missing[0])
            columns[name] = _numbers([pt[name] for pt in points], where, f"points.{name}")
        for name in units:
            if name not in cards:
                raise InputError(where, f"unknown covariate {name!r} of model {model.id!r}", field=f"units.{name}")
    else:
        raise InputError(where, "expected [grid.<covariate>] tables or [[points]] entries")
    missing = [c.name for c in model.covariates if c.name not in columns and not c.optional]
    if missing:
        raise InputError(where, f"no candidate values for covariate(s) {', '.join(missing)} of model "
                         f"{model.id!r}", field="grid" if "grid" in doc else "points")
    X = {}
    for name, values in columns.items():
        field = f"grid.{name}.unit" if "grid" in doc else f"units.{name}"
        X[name] = convert_units(values, units[name], cards[name].unit, where, field)
        dim = dimension(units[name])
        from .units import NONNEGATIVE

        if dim in NONNEGATIVE and (X[name] < 0).any():
            raise InputError(where, f"{name} must be >= 0 (got {float(np.min(values)):g} {units[name]})", field=field)
    for c in model.covariates:
        if c.name not in X:  # optional covariate left out: missing by design
            X[c.name] = np.full(len(next(iter(X.values()))), np.nan)
    return X, units


def _numbers(raw, where, field):
    if not isinstance(raw, list) or not raw:
        raise InputError(where, f"expected a non-empty list of numbers (got {raw!r})", field=field)
    for i, v in enumerate(raw, 1):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InputError(where, f"expected a finite number (got {v!r})", field=field, row=i)
    return np.asarray(raw, dtype=float)


def _to_u(draws, is_log):
    """Natural parameters (k, d) -> the coordinate u (log where ``is_log``)."""
    u = np.array(draws, dtype=float)
    u[:, is_log] = np.log(u[:, is_log])
    return u


def _coordinates(priors, names):
    """Per parameter: log coordinate when its prior's lower bound is > 0, else natural."""
    return np.array([priors[n].lower > 0 for n in names])


def _model_problem(model, draws, is_log, noise, sigma, constants, log_density, log_marginal, loc=None, cov=None):
    """A DesignProblem for ``model``: draws (D, d) natural parameters in card order."""
    names = model.parameter_names
    obs = model.observable_names
    log_obs = np.array([noise[o][0] == "lognormal" for o in obs])
    nu = np.array([noise[o][1] for o in obs])
    c = {**model.constants, **(constants or {})}

    def mean(u, X):
        out = np.empty((len(u), _n_candidates(X), len(obs)))
        step = max(1, 2_000_000 // max(_n_candidates(X), 1))
        for i in range(0, len(u), step):
            theta = np.array(u[i:i + step], dtype=float)
            theta[:, is_log] = np.exp(theta[:, is_log])
            p = {n: theta[:, j:j + 1] for j, n in enumerate(names)}
            with np.errstate(all="ignore"):
                y, ok = model.forward(p, X, c)
                for r, o in enumerate(obs):
                    v = np.broadcast_to(y[o], (len(theta), _n_candidates(X)))
                    v = np.log(v) if log_obs[r] else v
                    out[i:i + step, :, r] = np.where(np.broadcast_to(ok, v.shape) & np.isfinite(v), v, np.nan)
        return out

    u = _to_u(draws, is_log)
    loc = u.mean(axis=0) if loc is None else loc
    cov = np.atleast_2d(np.cov(u, rowvar=False)) if cov is None else cov
    return DesignProblem(tuple(names), mean, np.asarray(sigma, float), nu, u, loc, cov,
                         log_density, log_marginal, obs)


def _prior_problem(model, priors, rng, n_draws, noise, sigma, constants=None):
    names = model.parameter_names
    is_log = _coordinates(priors, names)
    draws = np.column_stack([priors[n].rvs(n_draws, rng) for n in names])

    def log_marginal(u, idx):
        u = np.atleast_2d(u)
        total = np.zeros(len(u))
        for j in np.atleast_1d(idx):
            theta = np.exp(u[:, j]) if is_log[j] else u[:, j]
            total += priors[names[j]].logpdf(theta) + (u[:, j] if is_log[j] else 0.0)
        return total

    return _model_problem(model, draws, is_log, noise, sigma, constants,
                          lambda u: log_marginal(u, np.arange(len(names))), log_marginal)


def _gaussian_density(loc, cov):
    dist = stats.multivariate_normal(loc, cov, allow_singular=True)

    def log_marginal(u, idx):
        idx = np.atleast_1d(idx)
        return np.atleast_1d(stats.multivariate_normal(loc[idx], cov[np.ix_(idx, idx)]).logpdf(np.atleast_2d(u)[:, idx]))

    return (lambda u: np.atleast_1d(dist.logpdf(u))), log_marginal


def _noise_setup(model, priors, noise_kinds, noise_scale, fit_draws=None):
    """observable -> (kind, nu) and sigma (r,) in the likelihood's space."""
    from .labels import noise_suffix

    obs = model.observable_names
    scale = {}
    for o in obs:
        suffix = noise_suffix(obs, o)
        given = noise_scale.get(o) if isinstance(noise_scale, dict) else noise_scale
        if given is not None:
            scale[o] = float(given)
        elif fit_draws is not None:
            scale[o] = float(np.median(fit_draws[f"sigma{suffix}"]))
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


# ---- the user-facing call ------------------------------------------------------------------------
@dataclass
class DesignResult:
    """What :func:`design` found.

    ``table``: one row per candidate (covariates in the user's units), ``eig`` and ``eig_se``
    (nats, nested Monte Carlo, one measurement), ``eig_laplace`` (the approximation), ``in_plan``
    (times the plan uses it).  ``plan``: the n measurements to run, user units, in the order
    chosen.  ``comparison``: plan vs baseline (EIG of the whole batch by nested Monte Carlo with
    its error, Laplace EIG; with ``discriminate``, expected ln BF and P(ln BF > 3)).  ``sd``:
    per target parameter, the sd now and predicted after the plan and after the baseline, in
    the coordinate u (``log`` = sd of the natural log, i.e. a relative sd).  ``settings``: the
    estimators, draw counts, noise, seed and what was dropped.
    """

    model_id: str
    covariates: tuple
    units: dict
    table: pd.DataFrame
    plan: pd.DataFrame
    baseline: pd.DataFrame
    comparison: pd.DataFrame
    sd: pd.DataFrame
    settings: dict
    discrimination: pd.DataFrame | None = None
    plot: dict = field(default_factory=dict)

    def text(self):
        lines = [f"design for {self.model_id}: {len(self.plan)} measurements chosen from {len(self.table)} "
                 f"candidates ({self.settings['selection']})",
                 f"starting from {self.settings['start']}; targets: {', '.join(self.settings['params'])}; "
                 f"seed {self.settings['seed']}", "", "plan vs baseline:", self.comparison.to_string(), "",
                 "predicted posterior sd (coordinate: log = sd of the natural log):", self.sd.to_string(), "",
                 "plan (user units):", self.plan.to_string(index=False)]
        if self.discrimination is not None:
            lines += ["", "discrimination (per generating model):", self.discrimination.to_string(index=False)]
        return "\n".join(lines)

    def write(self, out, *, overwrite=False):
        """plan.csv (ready to run), candidates.csv, baseline.csv, comparison.csv, sd.csv,
        design.json (settings and what :func:`load_design` needs), eig.png (:data:`FILES`). A
        folder holding an earlier design's files is refused unless ``overwrite``."""
        check_outputs(out, FILES, command="skinfit design", overwrite=overwrite)
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        self.plan.to_csv(out / "plan.csv", index=False)
        self.table.to_csv(out / "candidates.csv", index=False)
        self.baseline.to_csv(out / "baseline.csv", index=False)
        self.comparison.to_csv(out / "comparison.csv")
        self.sd.to_csv(out / "sd.csv")
        if self.discrimination is not None:
            self.discrimination.to_csv(out / "discrimination.csv", index=False)
        doc = {**self.settings, "_result": {"model_id": self.model_id, "covariates": list(self.covariates),
                                            "units": self.units, "plot": self.plot}}
        (out / "design.json").write_text(json.dumps(doc, indent=2, default=str))
        plot_eig(self, out / "eig.png")
        return out


def _user_frame(X, units, idx, covariates):
    return pd.DataFrame({f"{c} [{units[c]}]": np.asarray(X[c])[idx] / to_si(units[c]) for c in covariates if c in units})


def _baseline_design(model, fit, baseline, n, units):
    """SI covariates of the baseline plan: ``n`` rows evenly spaced over the fit's own dataset,
    the model's shipped dataset, or ``baseline`` (a dataset id / path)."""
    from .data import load_dataset
    from .sbc import design_dataset

    if baseline is None and fit is not None:
        x, label = fit.posterior.x, f"fit's dataset {fit.dataset_id}"
    else:
        ds = load_dataset(baseline) if baseline is not None else design_dataset(model)
        missing = [c.name for c in model.covariates if c.name not in ds.frame.columns and not c.optional]
        if missing:
            raise InputError(ds.path, f"baseline dataset has no covariate {missing[0]!r} of model {model.id!r}")
        x = {c.name: ds.frame[c.name].to_numpy(float) if c.name in ds.frame.columns else
             np.full(len(ds.frame), np.nan) for c in model.covariates}
        label = f"dataset {ds.id}"
    rows = len(next(iter(x.values())))
    idx = np.unique(np.linspace(0, rows - 1, min(n, rows)).round().astype(int))
    return {k: np.asarray(v, float)[idx] for k, v in x.items()}, f"{label}: {len(idx)} of {rows} rows, evenly spaced"


def design(fit_or_model: str | Model | Fit, candidates: str | os.PathLike | Mapping, n: int = 24,
           params: Sequence[str] | None = None, rng: int | np.random.Generator | None = None, *,
           discriminate: Sequence[str | Model] = (), baseline: str | None = None, noise_scale: float | None = None,
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
    baseline : dataset id or path, optional
        Design to compare with (default: the fit's dataset, else the model's shipped dataset),
        ``n`` rows evenly spaced.
    noise_scale : float or mapping observable -> float, optional
        Noise sd in the likelihood's space (N for a normal tangential force, log units for a
        log-normal one); default the fit's posterior median, else the prior's median.

    Returns
    -------
    DesignResult
    """
    import time

    from .fit import Fit, as_generator
    from .models import Model, load_model
    from .priors import load_priors

    t0 = time.perf_counter()
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n <= 0:
        raise InputError("--n", f"the number of measurements must be an integer > 0 (got {n!r})")
    seed = int(rng) if isinstance(rng, (int, np.integer)) else None
    rng = as_generator(rng)
    fit = fit_or_model if isinstance(fit_or_model, Fit) else None
    if fit is not None:
        post = fit.posterior
        model = post.model
        if post.split:
            raise InputError(f"fit of {model.id}", f"design from a fit with split parameters "
                             f"({', '.join(post.split)}) is not supported: fit them shared")
        priors = post.priors
        noise_kinds = dict(post.noise)
    else:
        model = fit_or_model if isinstance(fit_or_model, Model) else load_model(fit_or_model)
        priors = load_priors(model.id)
        noise_kinds = {o.name: o.noise for o in model.observables}
    names = model.parameter_names
    if params is not None:
        params = [params] if isinstance(params, str) else list(params)
        bad = [p for p in params if p not in names]
        if bad or not params:
            raise InputError("--params", f"unknown parameter {bad[0] if bad else ''!r} of model {model.id!r} "
                             f"(parameters: {', '.join(names)})")
    targets = list(names) if params is None else params
    if isinstance(candidates, (pd.DataFrame,)) or (isinstance(candidates, dict) and not
                                                   ({"grid", "points"} & set(candidates))):
        X = {k: np.asarray(v, float) for k, v in dict(candidates).items()}
        units = {k: next(c.unit for c in model.covariates if c.name == k) for k in X}
    else:
        X, units = read_candidates(candidates, model)
    C = _n_candidates(X)
    x_base, base_label = _baseline_design(model, fit, baseline, n, units)
    for k in X:
        units.setdefault(k, "1")

    if fit is not None:
        from .evidence import posterior_draws

        theta = posterior_draws(fit)
        if len(theta) > n_draws:
            theta = theta[rng.choice(len(theta), n_draws, replace=False)]
        cols = {s.name: theta[:, j] for j, s in enumerate(post.slots)}
        noise, sigma = _noise_setup(model, priors, noise_kinds, noise_scale, cols)
        draws = np.column_stack([cols[p] for p in names])
        is_log = _coordinates(priors, names)
        u = _to_u(draws, is_log)
        loc, cov = u.mean(axis=0), np.atleast_2d(np.cov(u, rowvar=False))
        dens, marg = _gaussian_density(loc, cov)
        problem = _model_problem(model, draws, is_log, noise, sigma, post.constants, dens, marg, loc, cov)
        start = f"the posterior of fit {fit.model_id} on {fit.dataset_id} ({len(draws)} draws)"
    else:
        noise, sigma = _noise_setup(model, priors, noise_kinds, noise_scale)
        problem = _prior_problem(model, priors, rng, n_draws, noise, sigma)
        start = f"the priors {priors.path or priors.id} ({n_draws} draws)"
    problem, dropped = _restrict_to_support(problem, [X, x_base], gaussian=fit is not None)
    focus = problem.focus_index(targets)

    eig, eig_se = eig_nmc(problem, X, rng, params=params, n_outer=n_outer, n_inner=n_inner)
    eig_up, eig_up_se = eig_nmc(problem, X, rng, params=params, n_outer=n_outer, n_inner=n_inner, upper=True)
    disc_table = None
    if discriminate:
        from dataclasses import replace as _replace
        from .labels import noise_suffix

        obs = model.observable_names
        problems = [_replace(problem, noise_priors=tuple(priors[f"sigma{noise_suffix(obs, o)}"] for o in obs))]
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
            nz, _ = _noise_setup(m, pr, kinds, 1.0)
            prob = _prior_problem(m, pr, rng, n_draws, nz, sigma)
            prob = _replace(prob, noise_priors=tuple(pr[f"sigma{noise_suffix(obs, o)}"] for o in obs))
            problems.append(_restrict_to_support(prob, [X, x_base])[0])
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
    X_plan = _take_x(X, idx)
    rows = {}
    sds = {}
    for label, Xd in (("plan", X_plan), ("baseline", x_base)):
        e, se = batch_eig(problem, Xd, rng, params=params, n_outer=n_batch, n_inner=n_batch)
        e_lap, sd = laplace_design(problem, Xd, u_outer, params)
        rows[label] = {"n": _n_candidates(Xd), "eig_nmc": e, "eig_nmc_se": se, "eig_laplace": e_lap}
        sds[label] = sd
    if disc_table is not None:
        for label in rows:
            part = disc_table[disc_table["design"] == label]
            rows[label]["expected_ln_bf_capped"] = float(part["expected_ln_bf_capped"].mean())
            rows[label]["p_ln_bf_gt_3"] = float(part["p_ln_bf_gt_3"].mean())
    comparison = pd.DataFrame.from_dict(rows, orient="index")
    now_sd = np.sqrt(np.diag(problem.cov))
    is_log = _coordinates(priors, names)
    sd = pd.DataFrame({"coordinate": ["log" if is_log[j] else "natural" for j in focus],
                       "now": now_sd[focus], "plan": sds["plan"][focus], "baseline": sds["baseline"][focus]},
                      index=[names[j] for j in focus])
    sd["plan/baseline"] = sd["plan"] / sd["baseline"]
    covs = [c.name for c in model.covariates if c.name in units and not np.all(np.isnan(X[c.name]))]
    table = _user_frame(X, units, np.arange(C), covs)
    table["eig"] = eig
    table["eig_se"] = eig_se
    table["eig_upper"] = eig_up
    table["eig_upper_se"] = eig_up_se
    table["eig_laplace"] = single
    table["in_plan"] = np.bincount(idx, minlength=C)
    plan = _user_frame(X, units, idx, covs)
    plan.insert(0, "order", np.arange(1, len(idx) + 1))
    if not discriminate:
        plan["laplace_gain"] = gains
    baseline_frame = _user_frame(x_base, units, np.arange(_n_candidates(x_base)), covs)
    settings = {"model": model.id, "start": start, "params": targets, "n": int(n), "seed": seed,
                "selection": selection,
                "eig_single": f"nested Monte Carlo (Ryan 2003; Rainforth et al. 2018), {n_outer} outer x "
                              f"{n_inner} inner draws shared by all candidates; eig with the outer draw among the "
                              f"inner ones (lower bound, Foster et al. 2019), eig_upper without (upper bound); "
                              f"se = outer standard error",
                "eig_batch": f"nested Monte Carlo with Laplace-based importance sampling (Beck et al. 2018), "
                             f"{n_batch} outer x {n_batch} inner draws",
                "laplace": "approximate: Gaussian current distribution in u, Fisher information at each outer draw",
                "noise": {o: {"model": k, "scale": float(s), **({"nu": v} if math.isfinite(v) else {})}
                          for (o, (k, v)), s in zip(noise.items(), sigma)},
                "baseline": base_label, "discriminate": list(discriminate),
                "draws_dropped_outside_support": dropped, "candidates": C, "seconds": time.perf_counter() - t0}
    plot = {"x": model.plot.get("x") if model.plot.get("x") in covs else (covs[0] if covs else None),
            "xscale": model.plot.get("xscale", "linear")}
    return DesignResult(model.id, tuple(covs), units, table, plan, baseline_frame, comparison, sd, settings,
                        disc_table, plot)


def _restrict_to_support(problem, designs, gaussian=False):
    """Condition the current distribution on predictions inside the physical support at every
    point of ``designs``: draws outside are dropped, the Gaussian approximation is refitted to
    the rest and the densities for importance sampling become the restricted ones, p(u) 1[valid]
    / Z with Z the kept fraction (a refitted Gaussian when ``gaussian``, for a fit's posterior).
    The marginal of a target subset psi picks up P(valid | psi) / Z, estimated over the kept
    fraction of the draws' nuisance values.  Returns (problem, number dropped)."""
    from dataclasses import replace

    X_all = {k: np.concatenate([np.asarray(X[k], float) for X in designs]) for k in designs[0]}

    def valid(u):
        return np.isfinite(problem.mean(np.atleast_2d(u), X_all)).all(axis=(1, 2))

    ok = valid(problem.draws)
    if ok.sum() < 50:
        raise InputError("candidates", f"only {int(ok.sum())} of {len(ok)} parameter draws give predictions inside "
                         f"the model's physical support at every candidate: narrow the candidate range")
    if ok.all():
        return problem, 0
    draws = problem.draws[ok]
    loc, cov = draws.mean(axis=0), np.atleast_2d(np.cov(draws, rowvar=False))
    log_z = math.log(ok.mean())
    if gaussian:
        base, base_marginal = _gaussian_density(loc, cov)
        log_z = 0.0
    else:
        base, base_marginal = problem.log_density, problem.log_marginal
    all_draws = problem.draws

    def log_density(u):
        u = np.atleast_2d(u)
        return np.where(valid(u), base(u) - log_z, -np.inf)

    def log_marginal(u, idx):
        u = np.atleast_2d(u)
        out = base_marginal(u, idx) - log_z
        sample = all_draws[:200]
        for i, row in enumerate(u):
            swapped = sample.copy()
            swapped[:, idx] = row[idx]
            frac = valid(swapped).mean()
            out[i] += math.log(frac) if frac > 0 else -np.inf
        return out

    return replace(problem, draws=draws, loc=loc, cov=cov, log_density=log_density,
                   log_marginal=log_marginal), int((~ok).sum())


# ---- figure, report section, command line -------------------------------------------------------
def plot_eig(result, path=None):
    """EIG of one measurement (nats, with +-2 MC standard errors) against the model's natural x
    axis (the card's ``[plot] x``, else the first covariate), one line per value of the other
    covariates (at most 8 shown); the plan's points marked with how often each is used."""
    from .plots import _finish, _new_figure

    t = result.table
    xname = result.plot.get("x")
    fig = _new_figure(6.4, 4.0)
    ax = fig.add_subplot()
    xcol = f"{xname} [{result.units[xname]}]" if xname else None
    others = [c for c in t.columns if c.endswith("]") and c != xcol]
    groups = list(t.groupby(others, sort=True)) if others else [((), t)]
    if len(groups) > 8:
        keep = np.unique(np.linspace(0, len(groups) - 1, 8).round().astype(int))
        groups = [groups[i] for i in keep]
    for key, g in groups:
        key = key if isinstance(key, tuple) else (key,)
        label = ", ".join(f"{c.split(' [')[0]} {v:g} {c.split('[')[1][:-1]}" for c, v in zip(others, key)) or None
        x = g[xcol].to_numpy() if xcol else np.arange(len(g))
        order = np.argsort(x, kind="stable")
        x, e, se = x[order], g["eig"].to_numpy()[order], g["eig_se"].to_numpy()[order]
        line, = ax.plot(x, e, marker=".", label=label)
        ax.fill_between(x, e - 2 * se, e + 2 * se, color=line.get_color(), alpha=0.2, linewidth=0)
        used = g["in_plan"].to_numpy()[order] > 0
        ax.scatter(x[used], e[used], s=30 + 20 * g["in_plan"].to_numpy()[order][used], facecolors="none",
                   edgecolors="k", zorder=3)
    if result.plot.get("xscale") == "log":
        ax.set_xscale("log")
    ax.set_xlabel(xcol or "candidate")
    ax.set_ylabel("expected information gain of one measurement [nats]")
    ax.set_title(f"{result.model_id}: targets {', '.join(result.settings['params'])}; circles = plan "
                 f"(size = repeats)", fontsize=9)
    if len(groups) > 1:
        ax.legend(fontsize=7)
    return _finish(fig, path)


def load_design(out):
    """The :class:`DesignResult` that :meth:`DesignResult.write` wrote into folder ``out``."""
    out = Path(out)
    try:
        doc = json.loads((out / "design.json").read_text())
        meta = doc.pop("_result")
        tables = {name: pd.read_csv(out / f"{name}.csv") for name in ("plan", "candidates", "baseline")}
        comparison = pd.read_csv(out / "comparison.csv", index_col=0)
        sd = pd.read_csv(out / "sd.csv", index_col=0)
    except (OSError, KeyError, ValueError) as exc:
        raise InputError(out, f"not a folder written by `skinfit design --out` ({type(exc).__name__}: {exc})") from None
    disc = pd.read_csv(out / "discrimination.csv") if (out / "discrimination.csv").is_file() else None
    return DesignResult(meta["model_id"], tuple(meta["covariates"]), meta["units"], tables["candidates"],
                        tables["plan"], tables["baseline"], comparison, sd, doc, disc, meta.get("plot") or {})


def design_section_html(result, figdir):
    """A self-contained HTML section (string) for a report: the EIG figure (written to
    ``figdir/design_<model>.png``), plan vs baseline, predicted sds and the plan."""
    import html

    figdir = Path(figdir)
    figdir.mkdir(parents=True, exist_ok=True)
    name = f"design_{result.model_id}.png"
    plot_eig(result, figdir / name)
    s = result.settings
    parts = [f"<section id=\"design-{html.escape(result.model_id)}\"><h2>Design the next experiment: "
             f"{html.escape(result.model_id)}</h2>",
             f"<p>{len(result.plan)} measurements chosen from {s['candidates']} candidates by "
             f"{html.escape(s['selection'])}, starting from {html.escape(s['start'])}; targets "
             f"{html.escape(', '.join(s['params']))}; seed {s['seed']}. Baseline: {html.escape(s['baseline'])}. "
             f"Single-candidate EIG: {html.escape(s['eig_single'])}; batch EIG: {html.escape(s['eig_batch'])}. "
             f"Laplace values are {html.escape(s['laplace'])}.</p>",
             f"<img src=\"{html.escape(figdir.name)}/{name}\" alt=\"expected information gain over the candidates\">",
             "<h3>Plan vs baseline</h3>", result.comparison.to_html(float_format=lambda v: f"{v:.3g}"),
             "<h3>Predicted posterior sd</h3>", result.sd.to_html(float_format=lambda v: f"{v:.3g}")]
    if result.discrimination is not None:
        parts += ["<h3>Discrimination</h3>", result.discrimination.to_html(index=False, float_format=lambda v: f"{v:.3g}")]
    parts += ["<h3>Plan (user units)</h3>", result.plan.to_html(index=False, float_format=lambda v: f"{v:.4g}"),
              "</section>"]
    return "\n".join(parts)


#: The files :meth:`DesignResult.write` writes.
FILES = ("plan.csv", "candidates.csv", "baseline.csv", "comparison.csv", "sd.csv", "discrimination.csv",
         "design.json", "eig.png")


def cli_design(args):
    """``skinfit design MODEL --candidates FILE --n N [--from FIT] [--params A,B] [--discriminate M ...]
    [--sigma S] [--seed S] [--out DIR]``."""
    from .fit import load_fit
    from .models import load_model

    if args.n <= 0:
        raise InputError("--n", f"the number of measurements must be > 0 (got {args.n})")
    if args.out:  # an earlier design there: refused before the work, unless --overwrite
        check_outputs(args.out, FILES, command="skinfit design", overwrite=args.overwrite)
    params = [p.strip() for p in args.params.split(",")] if args.params else None
    if args.from_fit:
        source = load_fit(args.from_fit)
        if source.model_id != load_model(args.model).id:
            raise InputError("--from", f"fit {args.from_fit} is of model {source.model_id!r}, not {args.model!r}")
    else:
        source = args.model
    result = design(source, args.candidates, n=args.n, params=params, rng=args.seed,
                    discriminate=args.discriminate or (), baseline=args.baseline, noise_scale=args.sigma,
                    n_outer=args.outer, n_inner=args.inner)
    print(result.text())
    if args.out:
        out = result.write(args.out, overwrite=args.overwrite)
        print(f"\nwritten: {out / 'plan.csv'} (user units), candidates.csv, comparison.csv, sd.csv, eig.png")
    return 0
