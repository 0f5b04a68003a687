"""The Laplace (Fisher-information) approximation of the EIG, the greedy plan chosen on it, and
the EIG of a whole batch by nested Monte Carlo with Laplace-based importance sampling (Beck
et al. 2018)."""

from __future__ import annotations

import math

import numpy as np
from scipy import special, stats

from skinfit.analysis.design.problem import log_lik, n_candidates, noise_draws, t_weight

__all__ = ["fisher_factors", "laplace_gains", "greedy_plan", "laplace_design", "batch_eig"]


def fisher_factors(problem, u, X):
    """Per draw and candidate, G (k, C, d, r) with Fisher information G G^T: d mean / du
    (central differences, steps 1e-4 of each coordinate's sd) scaled by 1/sigma, and by
    sqrt((nu+1)/(nu+3)) for a Student-t likelihood."""
    k, d = u.shape
    h = 1e-4 * np.sqrt(np.diag(problem.cov))
    steps = np.concatenate([u[None] + np.diag(h)[:, None, :], u[None] - np.diag(h)[:, None, :]])  # (2d, k, d)
    mu = problem.mean(steps.reshape(-1, d), X).reshape(2, d, k, n_candidates(X), -1)
    jac = (mu[0] - mu[1]) / (2 * h[:, None, None, None])  # (d, k, C, r)
    w = t_weight(problem.nu) / problem.sigma
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
    ll = log_lik(y_n[None], problem.mean(u, X), problem.sigma, problem.nu).sum(axis=-1)
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
    resid = problem.sigma * noise_draws(rng, mu.shape, problem.nu)
    y = mu + resid
    G = fisher_factors(problem, u_out, X)  # (N, B, d, r)
    P0 = np.linalg.inv(problem.cov)
    S = np.linalg.inv(P0 + np.einsum("nbir,nbjr->nij", G, G))
    w = t_weight(problem.nu)
    score = np.einsum("nbir,nbr->ni", G, resid / problem.sigma * w)
    centre = u_out + np.einsum("nij,nj->ni", S, score + (problem.loc - u_out) @ P0)
    all_idx = np.arange(d)
    terms = np.empty((N, 2))  # all inner draws, half of them
    for n in range(N):
        log_evid = np.array(_is_log_evidence(problem, y[n], X, u_out[n], all_idx, centre[n], S[n], n_inner, df, rng))
        if len(nuis) == 0:
            log_num = log_lik(y[n], mu[n], problem.sigma, problem.nu).sum()
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
