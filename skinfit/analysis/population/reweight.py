"""Importance reweighting of the separate fits (``population(method="reweight")``; Hogg, Myers
& Bovy 2010): the hyper-posterior sampled with emcee over each subject's reweighted draws."""

from __future__ import annotations

import numpy as np

from skinfit.analysis.population.hierarchical import NU_HYPER
from skinfit.inference.sampling import run_emcee
from skinfit.results.summary import slot_values

__all__ = ["reweight"]


_LKJ_ETA = 2.0


def reweight(fits, subjects, parameters, slots, priors, logs, centre, scale, correlated, rng, n_draws,
              ess_target, max_steps, warn):
    """Hogg, Myers & Bovy (2010, ApJ 725, 2166, eq. 9): the hyper-likelihood estimated from each
    subject's draws ``z_is`` reweighted by population / own prior, sampled with emcee; shrunk
    draws by resampling one draw per hyper draw.  Same hyper-priors as Gibbs (independent); LKJ(2)
    correlations when correlated."""
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
