"""Designs that tell competing models apart: the expected log Bayes factor of the generating
model against its best competitor."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy import special

from skinfit.analysis.design.laplace import fisher_factors
from skinfit.analysis.design.problem import CELLS, LOG_2PI, log_lik, log_sum_lik, n_candidates, noise_draws, take_x

__all__ = ["discrimination_plan"]


def _split_draws(problem, rng, n_outer, n_inner):
    """Disjoint outer and inner draws (shuffled); fewer when the draws run short."""
    D = len(problem.draws)
    perm = rng.permutation(D)
    n_outer = min(n_outer, D // 2)
    n_inner = min(n_inner, D - n_outer)
    return problem.draws[perm[:n_outer]], problem.draws[perm[n_outer:n_outer + n_inner]]


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
    C = n_candidates(X)
    steps = n if plan is None else len(plan)
    chosen, measured = [], [[] for _ in range(K)]

    def log_bf(a, y, cols):
        """(N_a, C') ln BF of a vs its best competitor after measuring y (N_a, C', r) at cols."""
        lz = [log_sum_lik(y, mu_in[b][:, cols], problems[b].sigma, problems[b].nu, acc[a][b])
              - math.log(len(mu_in[b])) for b in range(K)]
        return lz[a] - np.max([lz[b] for b in range(K) if b != a], axis=0)

    for step in range(steps):
        cand = np.arange(C) if plan is None else np.array([plan[step]])
        ys = [mu_out[a][:, cand] + problems[a].sigma * noise_draws(rng, mu_out[a][:, cand].shape, problems[a].nu)
              for a in range(K)]
        utility = np.zeros(len(cand))
        block = max(1, CELLS // max(n_outer * n_inner, 1))
        for a in range(K):
            for s in range(0, len(cand), block):
                sl = slice(s, s + block)
                utility[sl] += np.clip(log_bf(a, ys[a][:, sl], cand[sl]), -cap, cap).mean(axis=0) / K
        best = int(np.argmax(utility)) if plan is None else 0
        chosen.append(int(cand[best]))
        for a in range(K):
            measured[a].append(ys[a][:, best])
            for b in range(K):
                acc[a][b] += log_lik(ys[a][:, None, best], mu_in[b][None, :, cand[best]], problems[b].sigma,
                                      problems[b].nu)
    rows = []
    Xb = take_x(X, np.array(chosen, dtype=int))
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
        log_lik = (-0.5 * rss / problem.sigma ** 2 - B * np.log(problem.sigma) - 0.5 * B * LOG_2PI).sum(axis=1)
    else:
        q = np.array([pr.ppf((np.arange(400) + 0.5) / 400) for pr in priors])  # (r, 400) quadrature nodes
        ll = -0.5 * rss[..., None] / q ** 2 - B * np.log(q) - 0.5 * B * LOG_2PI  # (N, r, 400)
        log_lik = (special.logsumexp(ll, axis=-1) - math.log(q.shape[1])).sum(axis=1)
    return log_lik + problem.log_density(u) + 0.5 * problem.d * LOG_2PI - 0.5 * np.linalg.slogdet(H)[1]
