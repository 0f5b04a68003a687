"""The expected information gain of each candidate by nested Monte Carlo (Ryan 2003; Rainforth
et al. 2018; Foster et al. 2019), vectorised over candidates and inner draws."""

from __future__ import annotations

import math

import numpy as np
from scipy import special

from skinfit.analysis.design.problem import (
    CELLS,
    conditional_gain,
    log_lik,
    log_sum_lik,
    n_candidates,
    noise_draws,
    take_x,
)

__all__ = ["eig_nmc"]


def _extra_support(problem, X):
    """The support points of ``problem`` that are not candidates of X (covariate -> (E,) SI),
    or None: a draw of the current distribution predicts inside the support at all of them."""
    if not problem.support:
        return None
    keys = list(X)

    def rows(Z):
        return [tuple(np.nan_to_num(np.asarray(Z[k], float)[i], nan=np.inf) for k in keys)
                for i in range(n_candidates(Z))]

    have = set(rows(X))
    extra = [i for i, row in enumerate(rows(problem.support)) if row not in have]
    return take_x(problem.support, np.array(extra, dtype=int)) if extra else None


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
    C = n_candidates(X)
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
    y = mu_out + sigma * noise_draws(rng, mu_out.shape, nu)
    mu_in = fold(problem.mean(u_in, X))
    log_true = log_lik(y, mu_out, sigma, nu)  # (N, C)
    C = y.shape[1]
    den = np.empty((K, N, C))  # log sum over each block of inner draws of p(y_n | u_m)
    step = max(1, CELLS * K // max(N * M * y.shape[2], 1))
    for c in range(0, C, step):
        s = slice(c, c + step)
        for k, b in enumerate(blocks):
            den[k, :, s] = log_sum_lik(y[:, s], mu_in[b][:, s], sigma, nu)
    num = None
    if len(focus) < problem.d:
        draw = _nuisance_sampler(problem, rng, out_idx, focus, M)
        extra = _extra_support(problem, X)
        Xe = X if extra is None else {k: np.concatenate([np.asarray(X[k], float), extra[k]]) for k in X}
        # per block: log sum of w p(y_n | psi_n, eta), log sum of w, log sum of w^2
        num, wsum, w2sum = np.empty((K, N, C)), np.empty((K, N)), np.empty((K, N))
        rows = max(1, CELLS // max(M * n_candidates(Xe), 1))
        for i in range(0, N, rows):
            v, log_w = draw(u_out[i:i + rows, focus])
            R = len(v)
            mu = problem.mean(v[:, :, :problem.d].reshape(R * M, problem.d), Xe)
            mu = mu.reshape(R, M, *mu.shape[1:])
            log_w = np.where(np.isfinite(mu).all(axis=(2, 3)), log_w, -np.inf)
            ll = log_lik(y[i:i + rows, None], fold(mu[:, :, :n_candidates(X)]), sigma, nu) + log_w[..., None]
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
