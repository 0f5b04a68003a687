"""Which measurement next: Bayesian experimental design over a model's covariates.

Ranks candidate measurement conditions (loads, voltages, ...) by the expected information gain
(EIG) about chosen parameters, proposes a batch of ``n`` measurements, compares it with a
baseline design, and (``discriminate``) finds the batch that best separates competing models.

Estimators (every random draw from the one ``rng``):

* One candidate at a time: nested Monte Carlo (Ryan 2003, "Estimating expected information
  gains for experimental designs with application to the random fatigue-limit model";
  Rainforth et al. 2018, "On nesting Monte Carlo estimators"), vectorised over candidates and
  inner draws (:func:`eig_nmc`).  The outer draws, their simulated observations and the ``M``
  inner draws are shared by every candidate (common random numbers: differences between
  candidates are estimated much better than the values).  ``eig`` is the value to read: the
  outer draw counted among the inner ones (Foster et al. 2019), biased low by O(1/M), most
  where the EIG nears log M; ``eig_bias`` estimates that bias (M/2 inner draws against M) and
  ``eig_se`` includes the shared inner draws' variance (a jackknife over blocks of them).
  For a subset of parameters the nuisance parameters are drawn *given* the outer draw's
  targets: for the priors (independent) a swap, for a Gaussian the regression on the targets,
  for a fit's posterior that regression as a proposal weighted by the fit's own density.
* Batches: greedy selection on the Laplace / Fisher-information approximation
  EIG ~ E_theta[0.5 log det Sigma0_psi - 0.5 log det Sigma_post_psi(theta)], Sigma_post^-1 =
  Sigma0^-1 + sum of the points' Fisher information (a Bayesian D_s-optimal criterion, Chaloner
  & Verdinelli 1995, "Bayesian experimental design: a review"), with the current distribution
  approximated by a Gaussian in the coordinate u (log of parameters with a positive lower
  bound, else natural).  It is approximate for non-linear models and exact for a linear-Gaussian
  one.  The EIG of the whole batch is then estimated jointly by nested Monte Carlo with
  Laplace-based importance sampling of the inner draws (Beck et al. 2018, "Fast Bayesian
  experimental design: Laplace-based importance sampling for the expected information gain"),
  which stays accurate where plain inner sampling from the prior saturates; from a fit, whose
  density is known only up to a constant and whose posterior may be far from its Gaussian
  approximation, by :func:`eig_nmc` over the fit's own draws instead.
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
    from collections.abc import Sequence
    from skinfit.results.fit import Fit
    from skinfit.io.models import Model

import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import special, stats

from skinfit.errors import InputError, InputTypeError
from skinfit.io.outputs import check_outputs
from skinfit.io.units import NONNEGATIVE, dimension, same_dimension, to_si

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
    # Before :func:`_restrict_to_support` conditioned the draws on the physical support (all None
    # until it did): ``base_draws`` (D0, d) the unrestricted draws, ``in_support`` (D0,) bool the
    # ones kept as ``draws``, ``support`` the design points (covariate -> (P,) SI) at which every
    # kept draw predicts inside the support.  ``base_cov`` (d, d): the covariance whose
    # regression of nuisance on target coordinates turns a draw into one of the conditional
    # (a diagonal one for independent priors: swap, exactly); None = ``cov``.
    base_draws: np.ndarray | None = None
    in_support: np.ndarray | None = None
    support: dict | None = None
    base_cov: np.ndarray | None = None
    # A fit's posterior, whose nuisance coordinates given the targets are not Gaussian: its
    # unnormalised log density ``log_joint(v)`` (k,) in v = (u, extra) (k, d + e), the extra
    # coordinates (the fit's noise parameters, log) of each base draw in ``extra_draws`` (D0, e).
    # :func:`eig_nmc` then weights its conditional draws by it (self-normalised importance
    # sampling); None: the regression of ``base_cov`` alone (exact for a Gaussian, a prior file).
    log_joint: object = None
    extra_draws: np.ndarray | None = None

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
def conditional_gain(cov, focus):
    """B (d - f, f) = Sigma_eta,psi Sigma_psi,psi^-1 for the target coordinates ``focus`` (psi)
    and the rest (eta) of a covariance ``cov`` (d, d): for a Gaussian, eta + B (psi* - psi) of
    a joint draw (psi, eta) is a draw of eta | psi*, exactly; B = 0 (a plain swap) when the
    cross-covariance is zero, as for the independent priors of a prior file."""
    nuis = np.setdiff1d(np.arange(len(cov)), focus)
    try:
        return np.linalg.solve(cov[np.ix_(focus, focus)], cov[np.ix_(focus, nuis)]).T
    except np.linalg.LinAlgError:  # a target without spread in the draws: least squares
        return np.linalg.lstsq(cov[np.ix_(focus, focus)], cov[np.ix_(focus, nuis)], rcond=None)[0].T


def _extra_support(problem, X):
    """The support points of ``problem`` that are not candidates of X (covariate -> (E,) SI),
    or None: a draw of the current distribution predicts inside the support at all of them."""
    if not problem.support:
        return None
    keys = list(X)

    def rows(Z):
        return [tuple(np.nan_to_num(np.asarray(Z[k], float)[i], nan=np.inf) for k in keys)
                for i in range(_n_candidates(Z))]

    have = set(rows(X))
    extra = [i for i, row in enumerate(rows(problem.support)) if row not in have]
    return _take_x(problem.support, np.array(extra, dtype=int)) if extra else None


def _nuisance_sampler(problem, rng, out_idx, focus, n_draws, df=10.0):
    """A function psi (R, f) -> (v (R, M, d + e), log w (R, M)): ``n_draws`` draws of the
    nuisance coordinates given each row of target values psi, in v = (u, extra), with their
    log importance weights up to a constant per row.

    Without ``problem.log_joint``: draws of the distribution before the support restriction
    (none of them an outer draw), their nuisance coordinates moved by B (psi - their psi)
    (:func:`conditional_gain`; exact for a Gaussian, a swap for independent priors), weights 1.
    With it (a fit's posterior): draws of a Student-t (``df``) around the Gaussian regression
    of the nuisance coordinates (extra ones included) on the targets, with its residual
    covariance, weighted by log_joint / proposal density; exact whatever the posterior's shape,
    as the weights correct the proposal."""
    base = problem.draws if problem.base_draws is None else problem.base_draws
    d = problem.d
    if problem.log_joint is None:
        out_base = out_idx if problem.in_support is None else np.flatnonzero(problem.in_support)[out_idx]
        pool = base[rng.permutation(np.setdiff1d(np.arange(len(base)), out_base))[:n_draws]]
        cov = problem.cov if problem.base_cov is None else problem.base_cov
        nuis = np.setdiff1d(np.arange(d), focus)
        gain = conditional_gain(np.atleast_2d(cov), focus)

        def draw(psi):
            v = np.broadcast_to(pool, (len(psi), len(pool), d)).copy()
            v[:, :, nuis] += (psi[:, None, :] - pool[None, :, focus]) @ gain.T
            v[:, :, focus] = psi[:, None, :]
            return v, np.zeros(v.shape[:2])

        return draw
    joint = base if problem.extra_draws is None else np.hstack([base, problem.extra_draws])
    nuis = np.setdiff1d(np.arange(joint.shape[1]), focus)
    loc, cov = joint.mean(axis=0), np.atleast_2d(np.cov(joint, rowvar=False))
    gain = conditional_gain(cov, focus)
    shape = cov[np.ix_(nuis, nuis)] - gain @ cov[np.ix_(focus, nuis)]
    shape = 0.5 * (shape + shape.T)
    try:
        chol = np.linalg.cholesky(shape)
    except np.linalg.LinAlgError:  # singular to rounding (a nuisance coordinate the targets fix)
        w, V = np.linalg.eigh(shape)
        chol = V * np.sqrt(np.maximum(w, 1e-12 * max(w.max(), 1e-300)))

    def draw(psi):
        R, p = len(psi), len(nuis)
        z = rng.standard_normal((R, n_draws, p))
        maha = (z * z).sum(axis=-1)
        scale = np.sqrt(rng.chisquare(df, (R, n_draws)) / df)
        z /= scale[..., None]
        maha /= scale * scale
        v = np.empty((R, n_draws, joint.shape[1]))
        v[:, :, nuis] = (loc[nuis] + (psi - loc[focus]) @ gain.T)[:, None, :] + z @ chol.T
        v[:, :, focus] = psi[:, None, :]
        log_q = -0.5 * (df + p) * np.log1p(maha / df)  # the t density up to its constant
        with np.errstate(invalid="ignore"):
            log_w = problem.log_joint(v.reshape(-1, v.shape[-1])).reshape(R, n_draws) - log_q
        return v, np.where(np.isnan(log_w), -np.inf, log_w)

    return draw


def eig_nmc(problem, X, rng, *, params=None, n_outer=500, n_inner=500, n_blocks=10, batch=False):
    """Expected information gain (EIG) about ``params`` of one measurement at each candidate of
    X, by nested Monte Carlo (Ryan 2003, "Estimating expected information gains for experimental
    designs with application to the random fatigue-limit model"); a mapping of (C,) arrays, nats:

    ``eig``, the estimate to read: the mean over N outer draws (psi_n, eta_n, y_n) of
    log p^(y_n | psi_n) - log p^(y_n).  p^(y_n) averages p(y_n | u) over M inner draws *and the
    outer draw itself* (prior contrastive estimation, Foster et al. 2019, "Variational Bayesian
    optimal experimental design": a lower bound in expectation, each term at most log(M + 1), so
    it saturates where the EIG nears log M).  For a target subset psi, p^(y_n | psi_n) averages
    p(y_n | psi_n, eta) over M draws of the nuisance eta given psi_n (:func:`_nuisance_sampler`)
    and, likewise, the outer draw itself; then it is no bound, but its bias is smaller (bench/
    results/design.md).  ``eig_bias``: the estimate at M/2 inner draws minus the one at M, the
    bias of ``eig`` if it falls as 1/M (Rainforth et al. 2018, "On nesting Monte Carlo
    estimators"); near saturation it understates it.  ``eig_se``: the Monte Carlo standard
    error, the outer draws' plus a jackknife over ``n_blocks`` blocks of the inner draws (shared
    by every outer draw, so the outer standard error alone misses their part).

    ``eig_upper``, ``eig_upper_se``: an upper bound in expectation (about all parameters; for a
    subset as far as p^(y_n | psi_n) with the outer draw is biased up), the outer draw left out
    of p^(y_n) (Ryan 2003); heavy-tailed where the inner draws miss the outcomes: the top of a
    bracket, not an estimate.

    ``batch=True``: the EIG of all the points of X measured together instead, (1,) arrays.

    Draws predicting outside the support (at a candidate or another point of
    ``problem.support``) are not draws of the current distribution and get weight 0.  The outer,
    inner and nuisance draws are shared by every candidate (common random numbers: differences
    between candidates are estimated better than values).
    """
    focus = problem.focus_index(params)
    D = len(problem.draws)
    perm = rng.permutation(D)
    N = min(n_outer, D // 2)
    M = min(n_inner, D - N)
    out_idx, u_out, u_in = perm[:N], problem.draws[perm[:N]], problem.draws[perm[N:N + M]]
    C = _n_candidates(X)
    sigma, nu = problem.sigma, problem.nu
    if batch:  # the points of X as the observables of one candidate
        sigma, nu = np.tile(sigma, C), np.tile(nu, C)

    def fold(mu):
        return mu.reshape(*mu.shape[:-2], 1, -1) if batch else mu

    K = max(2, min(n_blocks, M // 2))
    K -= K % 2  # halves of the inner draws are whole blocks
    blocks = np.array_split(np.arange(M), K)
    size = np.array([len(b) for b in blocks], float)
    mu_out = fold(problem.mean(u_out, X))  # (N, C, r), or (N, 1, C r) for a batch
    y = mu_out + sigma * _noise(rng, mu_out.shape, nu)
    mu_in = fold(problem.mean(u_in, X))
    log_true = _log_lik(y, mu_out, sigma, nu)  # (N, C)
    C = y.shape[1]
    den = np.empty((K, N, C))  # log sum over each block of inner draws of p(y_n | u_m)
    step = max(1, _CELLS * K // max(N * M * y.shape[2], 1))
    for c in range(0, C, step):
        s = slice(c, c + step)
        for k, b in enumerate(blocks):
            den[k, :, s] = _log_sum_lik(y[:, s], mu_in[b][:, s], sigma, nu)
    num = None
    if len(focus) < problem.d:
        draw = _nuisance_sampler(problem, rng, out_idx, focus, M)
        extra = _extra_support(problem, X)
        Xe = X if extra is None else {k: np.concatenate([np.asarray(X[k], float), extra[k]]) for k in X}
        # per block: log sum of w p(y_n | psi_n, eta), log sum of w, log sum of w^2
        num, wsum, w2sum = np.empty((K, N, C)), np.empty((K, N)), np.empty((K, N))
        rows = max(1, _CELLS // max(M * _n_candidates(Xe), 1))
        for i in range(0, N, rows):
            v, log_w = draw(u_out[i:i + rows, focus])
            R = len(v)
            mu = problem.mean(v[:, :, :problem.d].reshape(R * M, problem.d), Xe)
            mu = mu.reshape(R, M, *mu.shape[1:])
            log_w = np.where(np.isfinite(mu).all(axis=(2, 3)), log_w, -np.inf)
            ll = _log_lik(y[i:i + rows, None], fold(mu[:, :, :_n_candidates(X)]), sigma, nu) + log_w[..., None]
            for k, b in enumerate(blocks):
                num[k, i:i + rows] = special.logsumexp(ll[:, b], axis=1)
                wsum[k, i:i + rows] = special.logsumexp(log_w[:, b], axis=1)
                w2sum[k, i:i + rows] = special.logsumexp(2 * log_w[:, b], axis=1)

    def terms(w):
        """Per outer draw and candidate, the eig and upper terms from the inner blocks w (K,) bool."""
        m = size[w].sum()
        tot = special.logsumexp(den[w], axis=0)
        evidence = np.logaddexp(tot, log_true) - math.log(m + 1), tot - math.log(m)
        if num is None:
            return [log_true - e for e in evidence]
        top = special.logsumexp(wsum[w], axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            ess = np.where(np.isfinite(top), np.exp(2 * top - special.logsumexp(w2sum[w], axis=0)), 0.0)[:, None]
            mean = special.logsumexp(num[w], axis=0) - top[:, None]  # self-normalised
            # the outer draw is one exact draw of eta | psi_n; the weighted average is worth ess
            cond = np.where(ess > 0, np.logaddexp(log_true, np.log(np.maximum(ess, 1e-300)) + mean)
                            - np.log1p(ess), log_true)
        return [cond - e for e in evidence]

    every = np.ones(K, bool)
    est, up = terms(every)
    first = np.arange(K) < K // 2
    half = 0.5 * (terms(first)[0].mean(axis=0) + terms(~first)[0].mean(axis=0))
    jack = np.array([[t.mean(axis=0) for t in terms(np.arange(K) != k)] for k in range(K)])  # (K, 2, C)
    var_jack = (K - 1) / K * ((jack - jack.mean(axis=0)) ** 2).sum(axis=0)  # (2, C)
    se = [np.sqrt(t.var(axis=0, ddof=1) / N + v) for t, v in zip((est, up), var_jack)]
    return {"eig": est.mean(axis=0), "eig_se": se[0], "eig_bias": half - est.mean(axis=0),
            "eig_upper": up.mean(axis=0), "eig_upper_se": se[1]}


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
    over the coordinates ``idx`` (the rest held at ``u_fixed``), with a Student-t proposal; and
    the same from the first half of the draws (for the bias estimate)."""
    w, V = np.linalg.eigh(0.5 * (shape + shape.T))  # positive definite to rounding: a data set that
    w = np.maximum(w, 1e-8 * max(w.max(), 1e-300))  # determines u finely leaves S near-singular
    q = stats.multivariate_t(loc, (V * w) @ V.T, df=df)
    v = np.asarray(q.rvs(n_inner, random_state=rng), dtype=float).reshape(n_inner, len(idx))
    u = np.broadcast_to(u_fixed, (n_inner, len(u_fixed))).copy()
    u[:, idx] = v
    ll = _log_lik(y_n[None], problem.mean(u, X), problem.sigma, problem.nu).sum(axis=-1)
    log_p = problem.log_density(u)
    log_w = np.where(np.isfinite(log_p) & np.isfinite(ll), ll + log_p - np.atleast_1d(q.logpdf(v)), -np.inf)
    half = max(1, n_inner // 2)
    return special.logsumexp(log_w) - math.log(n_inner), special.logsumexp(log_w[:half]) - math.log(half)


def batch_eig(problem, X, rng, *, params=None, n_outer=200, n_inner=200, df=4.0):
    """EIG of all the points of X measured together, by nested Monte Carlo whose inner draws
    come from a Student-t (``df``) around the Gauss-Newton posterior mean and the Laplace
    covariance at each outer draw (Beck et al. 2018).  Returns (eig, se, bias) in nats.

    The evidence p(y_n) integrates every coordinate; with ``params`` a subset, p(y_n | psi_n)
    integrates the nuisance coordinates given the outer draw's target values (the proposal's
    conditional, weighted by p(u) / p(psi_n)).  Both estimates are unbiased; their logs are
    biased by O(1/n_inner), small when the proposal is close to the posterior: ``bias`` is the
    estimate from half the inner draws minus the one from all.  Each outer draw has inner draws
    of its own, so the outer standard error is the whole Monte Carlo error.  It needs the
    current distribution's density (``problem.log_density``): exact for a prior file, only the
    Gaussian approximation for a fit's posterior, where :func:`eig_nmc` with ``batch=True``
    (the fit's own draws and density) is the estimate to use.
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
    terms = np.empty((N, 2))  # all inner draws, half of them
    for n in range(N):
        log_evid = np.array(_is_log_evidence(problem, y[n], X, u_out[n], all_idx, centre[n], S[n], n_inner, df, rng))
        if len(nuis) == 0:
            log_num = _log_lik(y[n], mu[n], problem.sigma, problem.nu).sum()
        else:
            Sff, Snf = S[n][np.ix_(focus, focus)], S[n][np.ix_(nuis, focus)]
            reg = np.linalg.solve(Sff, Snf.T).T
            loc = centre[n, nuis] + reg @ (u_out[n, focus] - centre[n, focus])
            shape = S[n][np.ix_(nuis, nuis)] - reg @ Snf.T
            log_num = (np.array(_is_log_evidence(problem, y[n], X, u_out[n], nuis, loc, shape, n_inner, df, rng))
                       - problem.log_marginal(u_out[n][None], focus)[0])
        terms[n] = log_num - log_evid
    eig, half = terms.mean(axis=0)
    return float(eig), float(terms[:, 0].std(ddof=1) / math.sqrt(N)), float(half - eig)


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
    approximation's.  Approximate, as skinfit.analysis.evidence's ``laplace``; (N,) nats.
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
    model card's) does.  Any unit the data files accept (skinfit.io.units: SI prefixes such as kN,
    uN, µN, and whatever pint reads)."""
    if not isinstance(unit, str):
        raise InputError(where, f"expected a unit text such as \"mN\" (got {unit!r})", field=field)
    try:
        factor = to_si(unit)
        same = same_dimension(unit, target_unit)
    except ValueError as exc:
        raise InputError(where, str(exc), field=field) from None
    if not same:
        raise InputError(where, f"unit {unit!r} is a {dimension(unit)}, but the model's covariate is in "
                         f"{target_unit!r} (a {dimension(target_unit)})", field=field)
    return np.asarray(values, dtype=float) * factor


#: the most candidates a design takes (its arrays grow with outer x candidates; see _check_cost)
MAX_CANDIDATES = 1_000_000
_GRID_KEYS = {"unit", "values", "from", "to", "num", "log"}


def _grid_axis(spec, where, field):
    """The values (list of numbers, user unit) of one [grid.<covariate>] table."""
    if not isinstance(spec, dict):
        raise InputError(where, f"expected a table with unit and values (or from, to, num) (got {spec!r})", field=field)
    extra = sorted(set(spec) - _GRID_KEYS)
    if extra:
        raise InputError(where, f"unexpected key(s) {', '.join(extra)} (expected unit and values, or unit, from, "
                         f"to, num and optionally log)", field=field)
    if "unit" not in spec:
        raise InputError(where, "expected a unit", field=field)
    if "values" in spec:
        if {"from", "to", "num", "log"} & set(spec):
            raise InputError(where, "give values = [...] or from, to, num, not both", field=field)
        return _numbers(spec["values"], where, field + ".values")
    if not {"from", "to", "num"} <= set(spec):
        raise InputError(where, "expected values = [...] or from, to, num", field=field)
    num, log = spec["num"], spec.get("log", False)
    if isinstance(num, bool) or not isinstance(num, int) or not 1 <= num <= MAX_CANDIDATES:
        raise InputError(where, f"expected an integer from 1 to {MAX_CANDIDATES} (got {num!r})", field=field + ".num")
    if not isinstance(log, bool):
        raise InputError(where, f"expected true or false (got {log!r})", field=field + ".log")
    ends = _numbers([spec["from"], spec["to"]], where, field + ".from/to")
    if log and not (ends[0] > 0 and ends[1] > 0):
        raise InputError(where, f"log = true needs from and to > 0 (got {ends[0]:g}, {ends[1]:g})", field=field)
    return (np.geomspace if log else np.linspace)(ends[0], ends[1], num)


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
    finite and, for forces, lengths, voltages and the like, >= 0; at most
    :data:`MAX_CANDIDATES` candidates.  Units: any the data files accept (:mod:`skinfit.io.units`).
    """
    where = str(source) if not isinstance(source, dict) else "candidates"
    if isinstance(source, dict):
        doc = source
    else:
        path = Path(source)
        if not path.exists():
            raise InputError(path, "no such candidates file")
        from skinfit.io.toml import read_toml  # regular files only, bounded size and nesting, errors with the line

        doc, _ = read_toml(path, versioned=False)
    cards = {c.name: c for c in model.covariates}
    columns, units = {}, {}
    if "grid" in doc and "points" in doc:
        raise InputError(where, "give either [grid.<covariate>] tables or [[points]], not both")
    extra = sorted(set(doc) - {"grid", "points", "units"})
    if extra:
        raise InputError(where, f"unexpected key(s) {', '.join(extra)} (expected [grid.<covariate>] tables, or "
                         f"[units] and [[points]])")
    if "grid" in doc:
        if not isinstance(doc["grid"], dict) or not doc["grid"]:
            raise InputError(where, "expected one [grid.<covariate>] table per covariate", field="grid")
        if "units" in doc:
            raise InputError(where, "a grid gives each covariate's unit in its own table, not under [units]",
                             field="units")
        for name, spec in doc["grid"].items():
            field = f"grid.{name}"
            if name not in cards:
                raise InputError(where, f"unknown covariate {name!r} of model {model.id!r} (covariates: "
                                 f"{', '.join(cards)})", field=field)
            columns[name] = _grid_axis(spec, where, field)
            units[name] = spec["unit"]
        size = math.prod(len(v) for v in columns.values())
        if size > MAX_CANDIDATES:
            shape = " x ".join(str(len(v)) for v in columns.values())
            raise InputError(where, f"the grid has {size:,} candidates ({shape}); at most {MAX_CANDIDATES:,}: use "
                             f"fewer values", field="grid")
        names = list(columns)
        grids = np.meshgrid(*[np.asarray(columns[k]) for k in names], indexing="ij")
        columns = {k: g.ravel() for k, g in zip(names, grids)}
    elif "points" in doc:
        units = doc.get("units", {})
        if not isinstance(units, dict):
            raise InputError(where, f"expected a table covariate = \"unit\" (got {units!r})", field="units")
        points = doc["points"]
        if not isinstance(points, list) or not points:
            raise InputError(where, "expected at least one [[points]] entry", field="points")
        if len(points) > MAX_CANDIDATES:
            raise InputError(where, f"{len(points):,} points; at most {MAX_CANDIDATES:,}", field="points")
        for i, pt in enumerate(points, 1):
            if not isinstance(pt, dict):
                raise InputError(where, f"expected a table covariate = value (got {pt!r})", field="points", row=i)
            for name in pt:
                if name not in cards:
                    raise InputError(where, f"unknown covariate {name!r} of model {model.id!r} (covariates: "
                                     f"{', '.join(cards)})", field="points", row=i)
        for name in units:
            if name not in cards:
                raise InputError(where, f"unknown covariate {name!r} of model {model.id!r}", field=f"units.{name}")
        for name in [c for c in cards if any(c in pt for pt in points)]:
            if name not in units:
                raise InputError(where, f"no unit for {name!r}: add it under [units]", field="units")
            missing = [i for i, pt in enumerate(points, 1) if name not in pt]
            if missing:
                raise InputError(where, f"covariate {name!r} missing", field="points", row=missing[0])
            columns[name] = _numbers([pt[name] for pt in points], where, f"points.{name}")
    else:
        raise InputError(where, "expected [grid.<covariate>] tables or [[points]] entries")
    fields = {name: f"grid.{name}.unit" if "grid" in doc else f"units.{name}" for name in columns}
    return _candidate_columns(columns, units, model, where, fields)


def _candidate_columns(columns, units, model, where, fields):
    """Check and convert candidate columns (user units) to SI: (X, units), optional covariates
    left out filled with NaN (missing by design)."""
    missing = [c.name for c in model.covariates if c.name not in columns and not c.optional]
    if missing:
        raise InputError(where, f"no candidate values for covariate(s) {', '.join(missing)} of model "
                         f"{model.id!r}")
    cards = {c.name: c for c in model.covariates}
    X = {}
    for name, values in columns.items():
        X[name] = convert_units(values, units[name], cards[name].unit, where, fields[name])
        if dimension(units[name]) in NONNEGATIVE and (X[name] < 0).any():
            raise InputError(where, f"{name} must be >= 0 (got {float(np.min(values)):g} {units[name]})",
                             field=fields[name])
    size = len(next(iter(X.values())))
    for c in model.covariates:
        if c.name not in X:  # optional covariate left out: missing by design
            X[c.name] = np.full(size, np.nan)
    return X, dict(units)


def _si_candidates(table, model):
    """Candidates given as a mapping (or DataFrame) covariate -> SI values: checked as a file's."""
    cards = {c.name: c for c in model.covariates}
    columns = {}
    for name, values in dict(table).items():
        if name not in cards:
            raise InputError("candidates", f"unknown covariate {name!r} of model {model.id!r} (covariates: "
                             f"{', '.join(cards)})", field=str(name))
        values = np.asarray(values, dtype=object).ravel().tolist()
        if len(values) > MAX_CANDIDATES:
            raise InputError("candidates", f"{len(values):,} candidates; at most {MAX_CANDIDATES:,}", field=name)
        columns[name] = _numbers(values, "candidates", name, allow_nan=cards[name].optional)
    sizes = {len(v) for v in columns.values()}
    if len(sizes) > 1:
        raise InputError("candidates", f"the covariates have different lengths "
                         f"({', '.join(f'{k}: {len(v)}' for k, v in columns.items())})")
    return _candidate_columns(columns, {k: cards[k].unit for k in columns}, model, "candidates",
                              {k: k for k in columns})


def _numbers(raw, where, field, allow_nan=False):
    if not isinstance(raw, list) or not raw:
        raise InputError(where, f"expected a non-empty list of numbers (got {raw!r})", field=field)
    for i, v in enumerate(raw, 1):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)) or \
                not (math.isfinite(v) or (allow_nan and math.isnan(v))):
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

    problem = _model_problem(model, draws, is_log, noise, sigma, constants,
                             lambda u: log_marginal(u, np.arange(len(names))), log_marginal)
    # independent by construction: nuisance given the targets is a plain swap (B = 0 exactly)
    return replace(problem, base_cov=np.diag(np.diag(problem.cov)))


def _fit_density(post, names, theta):
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

    extra = _to_u(theta[:, order], is_log)[:, len(names):]
    return {"log_joint": log_joint, "extra_draws": extra if extra.shape[1] else None}


def _gaussian_density(loc, cov):
    dist = stats.multivariate_normal(loc, cov, allow_singular=True)

    def log_marginal(u, idx):
        idx = np.atleast_1d(idx)
        return np.atleast_1d(stats.multivariate_normal(loc[idx], cov[np.ix_(idx, idx)]).logpdf(np.atleast_2d(u)[:, idx]))

    return (lambda u: np.atleast_1d(dist.logpdf(u))), log_marginal


def _noise_setup(model, priors, noise_kinds, noise_scale, fit_draws=None):
    """observable -> (kind, nu) and sigma (r,) in the likelihood's space."""
    from skinfit.io.labels import noise_suffix

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

    ``table``: one row per candidate (covariates in the user's units); the expected
    information gain of one measurement there, nats, by nested Monte Carlo (:func:`eig_nmc`):
    ``eig`` (the value to read), ``eig_se`` (its Monte Carlo error), ``eig_bias`` (its
    estimated bias), ``eig_upper`` and ``eig_upper_se`` (an upper bound); ``eig_laplace`` (the
    Laplace approximation the plan is chosen on), ``in_plan`` (times the plan uses it).
    ``plan``: the n measurements to run, user units, in the order chosen.  ``comparison``: plan
    vs baseline (EIG of the whole batch by nested Monte Carlo with its error and estimated bias,
    Laplace EIG; with ``discriminate``, expected ln BF and P(ln BF > 3)).  ``sd``: per target
    parameter, the sd now and predicted after the plan and after the baseline, in
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
                 "plan (user units):", self.plan.to_string(index=False), "", *self._single_lines()]
        if self.discrimination is not None:
            lines += ["", "discrimination (per generating model):", self.discrimination.to_string(index=False)]
        return "\n".join(lines)

    def _single_lines(self):
        """The EIG of one measurement: which column to read, the best candidates, the bias."""
        t = self.table
        covs = [c for c in t.columns if c.endswith("]")]
        shown = [c for c in ("eig", "eig_se", "eig_bias", "eig_upper") if c in t]  # a folder of an older skinfit
        best = t.sort_values("eig", ascending=False).head(5)[covs + shown]
        lines = ["one measurement (candidates.csv): read eig +- eig_se (nats); eig_bias is its estimated Monte "
                 "Carlo bias, eig_upper an upper bound. Best candidates:", best.to_string(index=False)]
        over = self.settings.get("eig_bias_over_se", 0)
        if over:
            lines.append(f"warning: at {over} of {len(t)} candidates the estimated bias of eig exceeds its se "
                         f"(the EIG nears log of the inner draws): rerun with more inner draws (--inner)")
        return lines

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
    from skinfit.io.data import load_dataset
    from skinfit.analysis.sbc import design_dataset

    if baseline is None and fit is not None:
        x, label = fit.posterior.x, f"fit's dataset {fit.dataset_id}"
    else:
        try:
            ds = load_dataset(baseline) if baseline is not None else design_dataset(model)
        except InputError as exc:
            if baseline is not None or exc.field != "dataset":
                raise
            raise InputError(f"model {model.id}", "no shipped dataset for this model or its variants to take the "
                             "baseline design from: give one with --baseline DATASET (baseline= in Python), a "
                             "dataset id or path", field="baseline") from None
        missing = [c.name for c in model.covariates if c.name not in ds.frame.columns and not c.optional]
        if missing:
            raise InputError(ds.path, f"baseline dataset has no covariate {missing[0]!r} of model {model.id!r}")
        x = {c.name: ds.frame[c.name].to_numpy(float) if c.name in ds.frame.columns else
             np.full(len(ds.frame), np.nan) for c in model.covariates}
        label = f"dataset {ds.id}"
    rows = len(next(iter(x.values())))
    idx = np.unique(np.linspace(0, rows - 1, min(n, rows)).round().astype(int))
    return {k: np.asarray(v, float)[idx] for k, v in x.items()}, f"{label}: {len(idx)} of {rows} rows, evenly spaced"


#: fewest outer / inner / batch draws an estimate takes (its standard error needs a sample, its
#: bias estimate halves of the inner draws)
MIN_DRAWS = 20
#: a design refuses, before any work, to need more memory for its largest arrays (bytes) or an
#: estimated longer time (seconds) than this
MAX_BYTES, MAX_SECONDS = 4 * 2**30, 3600.0
_COUNT_NAMES = {"n": "--n", "n_outer": "--outer", "n_inner": "--inner", "n_batch": "n_batch", "n_draws": "n_draws"}


def _check_counts(**counts):
    """Each count an integer (not a bool): ``n`` >= 1, draw counts >= MIN_DRAWS, and the
    outer plus inner draws at most ``n_draws`` (they are taken from them without repeats)."""
    for key, value in counts.items():
        low = 1 if key == "n" else 5 * MIN_DRAWS if key == "n_draws" else MIN_DRAWS
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            what = "the number of measurements" if key == "n" else "the number of draws"
            raise InputError(_COUNT_NAMES[key], f"{what} must be an integer >= {low} (got {value!r})")
    if counts["n_outer"] + counts["n_inner"] > counts["n_draws"] or counts["n_batch"] > counts["n_draws"]:
        raise InputError("n_draws", f"{counts['n_draws']} draws cannot give {counts['n_outer']} outer and "
                         f"{counts['n_inner']} inner ones (nor {counts['n_batch']} batch ones): raise n_draws")


def _check_params(params, model):
    """Target parameters: None (all), a name or a list of distinct names of ``model``."""
    names = model.parameter_names
    if params is None:
        return None
    params = [params] if isinstance(params, str) else params
    if not isinstance(params, (list, tuple)) or not params or not all(isinstance(p, str) for p in params):
        raise InputError("--params", f"expected parameter names of model {model.id!r} (got {params!r})")
    bad = [p for p in params if p not in names]
    if bad:
        raise InputError("--params", f"unknown parameter {bad[0]!r} of model {model.id!r} "
                         f"(parameters: {', '.join(names)})")
    twice = sorted({p for p in params if params.count(p) > 1})
    if twice:
        raise InputError("--params", f"parameter {twice[0]!r} given twice")
    return list(params)


def _check_discriminate(discriminate, model):
    """Competing models: a model id or Model, or a list of them, none of them ``model`` itself."""
    from skinfit.io.models import Model

    items = [discriminate] if isinstance(discriminate, (str, Model)) else discriminate
    if not isinstance(items, (list, tuple)) or not all(isinstance(m, (str, Model)) for m in items):
        raise InputError("--discriminate", f"expected model ids (got {discriminate!r})")
    ids = [m.id if isinstance(m, Model) else m for m in items]
    if model.id in ids:
        raise InputError("--discriminate", f"{model.id!r} is the model being designed for: name its competitors")
    twice = sorted({m for m in ids if ids.count(m) > 1})
    if twice:
        raise InputError("--discriminate", f"model {twice[0]!r} given twice")
    return list(items)


def _check_noise_scale(noise_scale, model):
    """None, a noise sd > 0, or a mapping observable -> sd > 0 over the model's observables."""
    obs = model.observable_names
    given = noise_scale if isinstance(noise_scale, Mapping) else {o: noise_scale for o in obs}
    unknown = [k for k in given if k not in obs]
    if unknown:
        raise InputError("--sigma", f"unknown observable {unknown[0]!r} of model {model.id!r} "
                         f"(observables: {', '.join(obs)})")
    for o, v in given.items():
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or \
                not (math.isfinite(v) and v > 0):
            raise InputError("--sigma", f"noise sd of {o} must be a number > 0 (got {v!r})")


def _check_cost(problem, X, x_base, *, n, n_outer, n_inner, n_batch, params, fit, discriminate, rows):
    """Refuse, before the work starts, a design whose largest arrays need more than
    :data:`MAX_BYTES` or whose estimated time exceeds :data:`MAX_SECONDS`, with the estimate and
    what to reduce.  The forward model's cost per (parameter vector x point) is timed here on a
    small block; the other constants are this code's, measured in bench/results/design.md."""
    import time

    C, B = _n_candidates(X), n + _n_candidates(x_base)
    d, r = problem.d, len(problem.sigma)
    N, M = n_outer, n_inner
    subset = params is not None and len(params) < d
    K = 10
    sample = problem.draws[:32]
    Xs = _take_x(X, np.arange(min(C, 64)))
    t = time.perf_counter()
    problem.mean(sample, Xs)
    forward = (time.perf_counter() - t) / (len(sample) * _n_candidates(Xs))
    likelihood, greedy = 5e-8, 2e-6 * (d / 7) ** 2  # s per cell; s per (step x outer draw x candidate)
    seconds = {
        "support": len(problem.draws) * (C + _n_candidates(x_base)) * forward,
        "one measurement": N * M * C * r * likelihood * (2 if subset else 1)
        + (N * M * (C + rows) * forward if subset else 0.0),
        "plan": n * n_batch * C * greedy + 2 * d * n_batch * C * forward
        + (len(discriminate) + 1) ** 2 * n * min(N, 150) * M * C * likelihood,
        "batch": 2 * (N * M * B * r * likelihood + (N * M * (B + rows) * forward if subset else 0.0)
                      if fit is not None else n_batch * n_batch * B * forward * (2 if subset else 1)),
    }
    total = sum(seconds.values())
    memory = 8 * max(N * C * (K * (2 if subset else 1) + 2 * r) + M * C * r, 2 * d * n_batch * C * r * 3,
                     (len(discriminate) + 1) * (N + M) * C * r * 3)
    if memory > MAX_BYTES or total > MAX_SECONDS:
        worst = max(seconds, key=seconds.get)
        raise InputError("design", f"too big: {C:,} candidates, --n {n}, {N} outer x {M} inner draws would need "
                         f"about {memory / 2**30:.1f} GiB and {total / 60:.0f} min (most for {worst}); the limits are "
                         f"{MAX_BYTES / 2**30:.0f} GiB and {MAX_SECONDS / 60:.0f} min: use fewer candidates, a smaller "
                         f"--n or fewer --outer/--inner draws")
    return total


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

    from skinfit.io.arguments import as_generator
    from skinfit.results.fit import Fit
    from skinfit.io.models import Model, load_model
    from skinfit.io.priors import load_priors

    t0 = time.perf_counter()
    _check_counts(n=n, n_outer=n_outer, n_inner=n_inner, n_batch=n_batch, n_draws=n_draws)
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
        priors = post.priors
        noise_kinds = dict(post.noise)
    else:
        if not isinstance(fit_or_model, (Model, str, os.PathLike)):
            raise InputTypeError("design", f"expected a Fit, a Model or a model id (got "
                                 f"{type(fit_or_model).__name__})", field="fit_or_model")
        model = fit_or_model if isinstance(fit_or_model, Model) else load_model(fit_or_model)
        priors = load_priors(model.id)
        noise_kinds = {o.name: o.noise for o in model.observables}
    names = model.parameter_names
    params = _check_params(params, model)
    discriminate = _check_discriminate(discriminate, model)
    _check_noise_scale(noise_scale, model)
    if baseline is not None and not isinstance(baseline, (str, os.PathLike)):
        raise InputError("--baseline", f"expected a dataset id or path (got {type(baseline).__name__})")
    targets = list(names) if params is None else params
    if isinstance(candidates, (str, os.PathLike)) or isinstance(candidates, dict) and {"grid", "points"} & set(candidates):
        X, units = read_candidates(candidates, model)
    elif isinstance(candidates, (pd.DataFrame, Mapping)):
        X, units = _si_candidates(candidates, model)
    else:
        raise InputError("--candidates", f"expected a candidates file, its mapping or a table of SI covariates "
                         f"(got {type(candidates).__name__})")
    C = _n_candidates(X)
    x_base, base_label = _baseline_design(model, fit, baseline, n, units)
    for k in X:
        units.setdefault(k, "1")

    if fit is not None:
        from skinfit.analysis.evidence import posterior_draws

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
        problem = replace(problem, **_fit_density(post, names, theta))
        start = f"the posterior of fit {fit.model_id} on {fit.dataset_id} ({len(draws)} draws)"
    else:
        noise, sigma = _noise_setup(model, priors, noise_kinds, noise_scale)
        problem = _prior_problem(model, priors, rng, n_draws, noise, sigma)
        start = f"the priors {priors.path or priors.id} ({n_draws} draws)"
    estimate = _check_cost(problem, X, x_base, n=n, n_outer=min(n_outer, len(problem.draws) // 2),
                           n_inner=n_inner, n_batch=n_batch, params=params, fit=fit, discriminate=discriminate,
                           rows=fit.posterior.n if fit is not None else 0)
    problem, dropped = _restrict_to_support(problem, [X, x_base])
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
        from dataclasses import replace as _replace
        from skinfit.io.labels import noise_suffix

        obs = model.observable_names
        problems = [_replace(problem, noise_priors=tuple(priors[f"sigma{noise_suffix(obs, o)}"] for o in obs))]
        for m, pr, kinds in rivals:
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
        if fit is None:  # the prior's density is exact: Laplace-based importance sampling
            e, se, bias = batch_eig(problem, Xd, rng, params=params, n_outer=n_batch, n_inner=n_batch)
        else:  # the posterior's own draws and density (its Gaussian approximation can be far off)
            got = eig_nmc(problem, Xd, rng, params=params, n_outer=n_outer, n_inner=n_inner, batch=True)
            e, se, bias = (float(got[k][0]) for k in ("eig", "eig_se", "eig_bias"))
        e_lap, sd = laplace_design(problem, Xd, u_outer, params)
        rows[label] = {"n": _n_candidates(Xd), "eig_nmc": e, "eig_nmc_se": se, "eig_nmc_bias": bias,
                       "eig_laplace": e_lap}
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
    for key, value in single_nmc.items():
        table[key] = value
    table["eig_laplace"] = single
    table["in_plan"] = np.bincount(idx, minlength=C)
    plan = _user_frame(X, units, idx, covs)
    plan.insert(0, "order", np.arange(1, len(idx) + 1))
    if not discriminate:
        plan["laplace_gain"] = gains
    baseline_frame = _user_frame(x_base, units, np.arange(_n_candidates(x_base)), covs)
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


def _restrict_to_support(problem, designs, chunk=None):
    """Condition the current distribution on predictions inside the physical support at every
    point of ``designs``: draws outside are dropped, the Gaussian approximation (loc, cov) is
    refitted to the rest, and the densities for importance sampling become the restricted ones,
    p(u) 1[valid] / Z, Z the kept fraction of the draws.  The marginal of a target subset psi
    picks up P(valid | psi) / Z, P(valid | psi) over 200 draws of the nuisance coordinates given
    psi (:func:`conditional_gain`).  The unrestricted draws and covariance are kept for the
    conditional draws of :func:`eig_nmc`.  Returns (problem, number dropped)."""
    X_all = {k: np.concatenate([np.asarray(X[k], float) for X in designs]) for k in designs[0]}
    chunk = chunk or max(1, _CELLS // max(_n_candidates(X_all), 1))

    def valid(u):
        u = np.atleast_2d(u)
        return np.concatenate([np.isfinite(problem.mean(u[i:i + chunk], X_all)).all(axis=(1, 2))
                               for i in range(0, len(u), chunk)]) if len(u) else np.zeros(0, bool)

    ok = valid(problem.draws)
    if ok.sum() < 50:
        raise InputError("candidates", f"only {int(ok.sum())} of {len(ok)} parameter draws give predictions inside "
                         f"the model's physical support at every candidate: narrow the candidate range")
    base_cov = np.atleast_2d(problem.cov if problem.base_cov is None else problem.base_cov)
    keep = dict(base_draws=problem.draws, in_support=ok, support=X_all, base_cov=base_cov)
    if ok.all():
        return replace(problem, **keep), 0
    draws = problem.draws[ok]
    loc, cov = draws.mean(axis=0), np.atleast_2d(np.cov(draws, rowvar=False))
    log_z = math.log(ok.mean())
    base, base_marginal = problem.log_density, problem.log_marginal
    sample = problem.draws[:200]

    def log_density(u):
        u = np.atleast_2d(u)
        return np.where(valid(u), base(u) - log_z, -np.inf)

    def log_marginal(u, idx):
        u = np.atleast_2d(u)
        idx = np.atleast_1d(idx)
        nuis = np.setdiff1d(np.arange(problem.d), idx)
        gain = conditional_gain(base_cov, idx)
        out = base_marginal(u, idx) - log_z
        for i, row in enumerate(u):
            given = sample.copy()
            given[:, nuis] += (row[idx] - sample[:, idx]) @ gain.T
            given[:, idx] = row[idx]
            frac = valid(given).mean()
            out[i] += math.log(frac) if frac > 0 else -np.inf
        return out

    return replace(problem, draws=draws, loc=loc, cov=cov, log_density=log_density, log_marginal=log_marginal,
                   **keep), int((~ok).sum())


# ---- figure, report section, command line -------------------------------------------------------
def plot_eig(result, path=None):
    """EIG of one measurement (nats, with +-2 MC standard errors) against the model's natural x
    axis (the card's ``[plot] x``, else the first covariate), one line per value of the other
    covariates (at most 8 shown); the plan's points marked with how often each is used."""
    from skinfit.plots.figures import _finish, _new_figure

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
    from skinfit.results.fit import load_fit
    from skinfit.io.models import load_model

    if args.n <= 0:
        raise InputError("--n", f"the number of measurements must be > 0 (got {args.n})")
    created = False
    if args.out:  # made (or refused: an earlier design there, unless --overwrite) before the work
        check_outputs(args.out, FILES, command="skinfit design", overwrite=args.overwrite)
        out = Path(args.out)
        if out.exists() and not out.is_dir():
            raise InputError("--out", f"{out} is a file, not a folder")
        created = not out.exists()
        try:
            out.mkdir(parents=True, exist_ok=True)
            probe = out / ".skinfit-write-test"
            probe.touch()
            probe.unlink()
        except OSError as exc:
            raise InputError("--out", f"cannot write into {out} ({exc.strerror or exc})") from None
    try:
        return _cli_design_run(args, load_fit, load_model)
    except BaseException:
        if created and not any(Path(args.out).iterdir()):  # nothing written: leave no empty folder behind
            Path(args.out).rmdir()
        raise


def _cli_design_run(args, load_fit, load_model):
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
