"""Metropolis-within-Gibbs for a population of subjects: the sampler behind
:func:`skinfit.population.population` (``method="gibbs"``).

State per chain: every subject's full sampled vector ``z_i`` (its Posterior's sampling
coordinates: population parameters, noise scales and any parameter left per subject) and the
hyper-parameters ``mu``, ``Sigma`` of the population parameters in their population coordinate
``u`` (``log theta`` for log-normal families, ``theta`` for normal and Student-t).  One sweep:

1. **Subjects** (one vectorised likelihood call per subject for all chains): independence
   Metropolis-Hastings from a multivariate t (5 d.o.f.) whose precision and location are the
   Gaussian approximation of the subject's separate fit (mean, covariance of its draws), with
   the prior of the population parameters divided out and the current population multiplied
   in (information form; a delta-method step where ``u`` and ``z`` differ).  The proposal
   depends on the hyper-parameters only, so it is a valid Gibbs-block proposal; the exact
   target (likelihood x population density x the prior of the other parameters x Jacobian)
   enters through the acceptance ratio.
2. **Hyper-parameters**, exact conditionals: ``mu | Sigma, u`` normal (prior
   ``Normal(c, 2 s)`` per parameter); ``Sigma`` with the prior of Huang & Wand (2013,
   "Simple marginally noninformative prior distributions for covariance matrices", Bayesian
   Analysis 8, 439), ``Sigma | a ~ InvWishart(nu + p - 1, 2 nu diag(1 / a))``,
   ``a_k ~ InvGamma(1/2, 1 / s_k^2)``, with ``nu = 2``: each population sd is half-t(2, s_k)
   and, when correlated, every correlation is uniform on (-1, 1).  Independent populations
   use the same half-t(2, s_k) through its inverse-gamma pair.  Student-t populations
   (``nu_t = 4``) add per-subject precision weights ``w ~ Gamma`` (scale-mixture form).
3. **Scale move** (independent populations): ``tau_j -> tau_j e^eps`` with every subject's
   ``u_ij`` moved along ``mu_j + tau_j eta_ij`` (the non-centred coordinates held fixed), a
   Metropolis step that needs one more likelihood call per subject; it crosses the funnel
   between ``tau`` and the subjects when their data are weak (few presses), where the
   centred Gibbs updates alone move ``tau`` slowly.

The population density is not renormalised inside a parameter's prior bounds (which stay
hard): exact when the population puts negligible mass outside them.
"""

import math

import numpy as np
from scipy.special import gammaln

from .priors import _LOGPDF

__all__ = ["Spec", "run_gibbs", "NU_HYPER", "NU_T"]

NU_HYPER = 2.0  # Huang-Wand nu: half-t(2) population sds, uniform correlations
NU_T = 4.0  # degrees of freedom of a Student-t population
NU_PROPOSAL = 5.0  # degrees of freedom of the subjects' independence proposals


class Spec:
    """What the sampler needs to know of the population parameters (p of them).

    ``index`` (p,) slot indices in each subject's Posterior; ``log`` (p,) population coordinate
    is log theta; ``student`` (p,) Student-t population; ``centre``, ``scale`` (p,) hyper-prior
    ``mu ~ Normal(centre, 2 scale)``, ``sd ~ half-t(2, scale)``; ``correlated``.
    """

    def __init__(self, index, log, student, centre, scale, correlated):
        self.index = np.asarray(index, dtype=int)
        self.log = np.asarray(log, dtype=bool)
        self.student = np.asarray(student, dtype=bool)
        self.centre = np.asarray(centre, dtype=float)
        self.scale = np.asarray(scale, dtype=float)
        self.correlated = bool(correlated)
        self.p = len(self.index)


class _Subjects:
    """All S subjects: their Posteriors (the same slots), the Gaussian summaries of their
    separate fits in sampling coordinates (stacked), and the prior pieces the population
    replaces.  Everything but the likelihood is evaluated for all (chain, subject) at once."""

    def __init__(self, posts, moments, spec):
        self.posts = posts
        self.S = len(posts)
        first = posts[0]
        self.d = d = first.ndim
        covs = np.stack([np.atleast_2d(c) for _, c in moments])
        covs = covs + 1e-9 * np.einsum("sii->si", covs)[:, :, None] * np.eye(d)[None]
        self.A = np.linalg.inv(covs)  # (S, d, d)
        self.b = np.einsum("sij,sj->si", self.A, np.stack([m for m, _ in moments]))
        self.lo = np.array([s.lo for s in first.slots])
        self.hi = np.array([s.hi for s in first.slots])
        pop = set(spec.index.tolist())
        self.rest = [j for j in range(d) if j not in pop]
        self.zlog = np.array([first.slots[j].transform in ("log", "shift_log") for j in spec.index])
        # one transform for all subjects when their sampling maps are the same (same constants)
        self.shared_map = all(p.constants == first.constants and p.names == first.names for p in posts)
        # prior of the population slots in z coordinates (moments of 2000 prior quantiles)
        u = (np.arange(2000) + 0.5) / 2000
        pm, pv = np.empty((self.S, spec.p)), np.empty((self.S, spec.p))
        for i, post in enumerate(posts):
            for k, (j, lg) in enumerate(zip(spec.index, self.zlog)):
                q = post.slots[j].prior.ppf(u)
                q = np.log(q) if lg else q
                pm[i, k], pv[i, k] = q.mean(), q.var()
        self.prior_prec, self.prior_mean = 1.0 / pv, pm
        self.rest_priors = [[(_LOGPDF[post.slots[j].prior.dist], post.slots[j].prior.args) for j in self.rest]
                            for post in posts]

    def transform(self, z):
        """Natural parameters and log-Jacobian of z (..., S, d) -> ((..., S, d), (..., S))."""
        shape = z.shape
        if self.shared_map:
            theta, lj = self.posts[0]._transform(z.reshape(-1, self.d))
            return theta.reshape(shape), lj.reshape(shape[:-1])
        zs = z.reshape(-1, self.S, self.d)
        out = [self.posts[i]._transform(zs[:, i]) for i in range(self.S)]
        theta = np.stack([o[0] for o in out], axis=1).reshape(shape)
        return theta, np.stack([o[1] for o in out], axis=1).reshape(shape[:-1])

    def to_z(self, theta):
        shape = theta.shape
        if self.shared_map:
            return self.posts[0].to_z(theta.reshape(-1, self.d)).reshape(shape)
        ts = theta.reshape(-1, self.S, self.d)
        return np.stack([self.posts[i].to_z(ts[:, i]) for i in range(self.S)], axis=1).reshape(shape)

    def inside(self, theta):
        return np.all((theta >= self.lo) & (theta <= self.hi), axis=-1)

    def log_likelihood(self, theta):
        """theta (C, S, d) -> (C, S); -inf outside the prior bounds, one call per subject."""
        inside = self.inside(theta)
        ll = np.full(theta.shape[:2], -np.inf)
        for i, post in enumerate(self.posts):
            ok = inside[:, i]
            if ok.any():
                with np.errstate(all="ignore"):
                    ll[ok, i] = post.log_likelihood(theta[ok, i])
        if np.isnan(ll).any():
            c, i = np.argwhere(np.isnan(ll))[0]
            post = self.posts[i]
            raise FloatingPointError(f"{post.model.id}: NaN log-likelihood at {dict(zip(post.names, theta[c, i]))}")
        return ll

    def log_prior_part(self, theta, log_jac, mu, prec, spec):
        """Everything in a subject's conditional but the likelihood (up to a constant):
        theta (..., C, S, d), log_jac (..., C, S); mu (C, p), prec (C, S, p, p) -> (..., C, S)."""
        with np.errstate(all="ignore"):
            tp = theta[..., spec.index]
            u = np.where(spec.log, np.log(tp), tp)
            r = u - mu[:, None, :]
            quad = np.einsum("...csi,csij,...csj->...cs", r, prec, r)
            lp = -0.5 * quad - np.where(spec.log, u, 0.0).sum(axis=-1) + log_jac  # du/dtheta = 1/theta
            for i, pri in enumerate(self.rest_priors):
                for j, (logpdf, args) in zip(self.rest, pri):
                    lp[..., i] += logpdf(theta[..., i, j], args, None, None)
        return np.where(self.inside(theta) & np.isfinite(lp), lp, -np.inf)


def _pop_in_z(subs, mu, prec, spec):
    """The population of the population slots in the subjects' z coordinates (delta method
    where they differ from u): location (C, p) and precision (C, S, p, p)."""
    mz = mu.copy()
    scale = np.ones_like(mu)  # du/dz
    to_log = subs.zlog & ~spec.log  # u = theta, z = log theta: u ~ e^z
    to_lin = ~subs.zlog & spec.log  # u = log theta, z = theta
    if to_log.any():
        m = mu[:, to_log]
        ok = m > 0
        mz[:, to_log] = np.log(np.where(ok, m, 1.0))
        scale[:, to_log] = np.where(ok, m, 0.0)
    if to_lin.any():
        e = np.exp(np.clip(mu[:, to_lin], -700, 700))
        mz[:, to_lin] = e
        scale[:, to_lin] = 1.0 / e
    return mz, prec * scale[:, None, :, None] * scale[:, None, None, :]


def _proposal(subs, mu, prec, spec):
    """Location (C, S, d) and Cholesky factor (C, S, d, d) of the precision of the independence
    proposals: the separate fit's Gaussian, its own prior of the population slots divided out
    (where that leaves a positive-definite precision) and the population multiplied in."""
    mz, prec_z = _pop_in_z(subs, mu, prec, spec)
    idx = spec.index
    C, S, d = len(mu), subs.S, subs.d
    Q = np.broadcast_to(subs.A, (C, S, d, d)).copy()
    h = np.broadcast_to(subs.b, (C, S, d)).copy()
    Q[:, :, idx[:, None], idx[None, :]] += prec_z
    h[:, :, idx] += np.einsum("csij,cj->csi", prec_z, mz)
    Qd, hd = Q.copy(), h.copy()
    Qd[:, :, idx, idx] -= subs.prior_prec
    hd[:, :, idx] -= subs.prior_prec * subs.prior_mean
    try:
        L = np.linalg.cholesky(Qd)
        Q, h = Qd, hd
    except np.linalg.LinAlgError:
        ok = np.linalg.eigvalsh(Qd)[..., 0] > 1e-9 * np.linalg.eigvalsh(Q)[..., -1]
        Q = np.where(ok[..., None, None], Qd, Q)
        h = np.where(ok[..., None], hd, h)
        try:
            L = np.linalg.cholesky(Q)
        except np.linalg.LinAlgError:  # round-off (a population far narrower than the fit): clip
            lam, vec = np.linalg.eigh(Q)
            lam = np.maximum(lam, 1e-12 * lam[..., -1:])
            Q = np.einsum("...ij,...j,...kj->...ik", vec, lam, vec)
            L = np.linalg.cholesky(Q)
    loc = np.linalg.solve(Q, h[..., None])[..., 0]
    return loc, L


def _t_logpdf(x, loc, L, nu):
    """Multivariate t log-density with location ``loc`` and precision ``L L^T``: x (..., d)."""
    d = x.shape[-1]
    y = np.einsum("...ji,...j->...i", L, x - loc)  # L^T (x - loc)
    q = (y * y).sum(axis=-1)
    logdet = np.log(np.diagonal(L, axis1=-2, axis2=-1)).sum(axis=-1)
    return (gammaln(0.5 * (nu + d)) - gammaln(0.5 * nu) - 0.5 * d * math.log(nu * math.pi) + logdet
            - 0.5 * (nu + d) * np.log1p(q / nu))


def _t_draw(loc, L, nu, rng):
    e = rng.standard_normal(loc.shape)
    y = np.linalg.solve(np.swapaxes(L, -1, -2), e[..., None])[..., 0]  # L^-T e: covariance Q^-1
    return loc + y / np.sqrt(rng.chisquare(nu, loc.shape[:-1]) / nu)[..., None]


def _inv_gamma(shape, rate, rng):
    return rate / rng.gamma(shape)


def _inv_wishart(df, psi, rng):
    """Draws (k, p, p) of InvWishart(df, psi[k]) by Bartlett's decomposition of the Wishart."""
    k, p, _ = psi.shape
    Lw = np.linalg.cholesky(np.linalg.inv(psi))
    A = np.zeros((k, p, p))
    A[:, np.arange(p), np.arange(p)] = np.sqrt(rng.chisquare(df - np.arange(p), (k, p)))
    low = np.tril_indices(p, -1)
    A[:, low[0], low[1]] = rng.standard_normal((k, len(low[0])))
    LA = Lw @ A
    return np.linalg.inv(LA @ np.swapaxes(LA, 1, 2))


def run_gibbs(posts, moments, starts, spec, rng, *, chains=8, burn=300, ess_target=400, rhat_max=1.01,
              check_every=100, max_sweeps=20000, keep=1000, scale_move=True):
    """Sample the population posterior.

    Parameters
    ----------
    posts : list of S Posterior (the same slots)
    moments : list of S (mean (d,), cov (d, d)) of each separate fit in sampling coordinates
    starts : list of S arrays (n_i, d) of separate-fit draws in sampling coordinates (chain starts)
    spec : Spec
    rng : numpy Generator
    chains : parallel chains (vectorised); R-hat is computed over them
    burn, check_every, max_sweeps : sweeps discarded, sweeps between convergence checks, cap
    ess_target, rhat_max : stop when every hyper-parameter has bulk and tail ESS >= ess_target
        and R-hat <= rhat_max
    keep : draws kept per chain (the chains are thinned to at most this many)

    Returns
    -------
    dict with ``mu``, ``sd`` (chains, draws, p), ``corr`` (chains, draws, p, p), ``theta``
    (chains, draws, S, d) natural parameters of every subject slot, and diagnostics.
    """
    import arviz as az

    S, p, C = len(posts), spec.p, chains
    subs = _Subjects(posts, moments, spec)
    z = np.stack([st[rng.choice(len(st), C, replace=len(st) < C)] for st in starts], axis=1)  # (C, S, d)
    theta, lj = subs.transform(z)
    ll = subs.log_likelihood(theta)
    u = _u_of(theta, spec)
    mu = u.mean(axis=1)
    var = np.maximum(u.var(axis=1), (0.1 * spec.scale) ** 2)
    Sigma = np.zeros((C, p, p))
    Sigma[:, np.arange(p), np.arange(p)] = var
    a = np.broadcast_to(spec.scale**2, (C, p)).copy()
    w = np.ones((C, S, p))
    accept = np.zeros(S)
    scale_accept, n_scale, scale_factor, scale_base, log_sd = 0.0, 0, 0.3, np.ones(p), []
    # parameters whose subjects' data are weak against the population spread (a funnel between
    # sd and the subjects, where centred Gibbs moves sd slowly) get the scale move: median
    # within-subject variance of u against the between-subject variance of the separate means
    u_sep = [_u_of(subs.posts[i].to_theta(st), spec) for i, st in enumerate(starts)]
    within = np.median([np.var(x, axis=0) for x in u_sep], axis=0)
    between = np.var([np.mean(x, axis=0) for x in u_sep], axis=0)
    weak = within > 0.25 * np.maximum(between - within, 1e-3 * between)
    scale_total, scale_n = 0.0, 0
    draws = {"mu": [], "Sigma": [], "theta": []}
    sweeps, checks, converged = 0, [], False
    while sweeps < max_sweeps:
        # 1. every subject, all chains: independence Metropolis-Hastings
        prec = _pop_precision(Sigma, w, spec)  # (C, S, p, p)
        loc, L = _proposal(subs, mu, prec, spec)
        x = _t_draw(loc, L, NU_PROPOSAL, rng)
        both, lj2 = subs.transform(np.stack([x, z]))
        lp2 = subs.log_prior_part(both, lj2, mu, prec, spec)
        ll_x = np.full((C, S), -np.inf)
        fin = np.isfinite(lp2[0])
        if fin.any():
            ll_x = subs.log_likelihood(np.where(fin[..., None], both[0], np.nan))
        lq = _t_logpdf(np.stack([x, z]), loc, L, NU_PROPOSAL)
        log_r = (lp2[0] + ll_x) - (lp2[1] + ll) + lq[1] - lq[0]
        take = np.log(rng.random((C, S))) < np.where(np.isfinite(log_r), log_r, -np.inf)
        z = np.where(take[..., None], x, z)
        ll = np.where(take, ll_x, ll)
        theta = np.where(take[..., None], both[0], both[1])
        if sweeps >= burn:
            accept += take.mean(axis=0)
        u = _u_of(theta, spec)
        # 2. hyper-parameters from their exact conditionals
        mu, Sigma, a, w = _hyper_step(u, mu, Sigma, a, w, spec, rng)
        # 3. scale move along the non-centred coordinates
        if scale_move and not spec.correlated and weak.any():
            take, z, ll, Sigma, theta = _scale_move(subs, z, ll, theta, u, mu, Sigma, a, spec,
                                                    np.where(weak, scale_factor * scale_base, 0.0), rng)
            n_scale += 1
            scale_accept += take.mean()
            if sweeps < burn:
                log_sd.append(0.5 * np.log(np.diagonal(Sigma, axis1=1, axis2=2)))
                if sweeps == burn // 2:  # weak parameters and steps from the burn-in so far
                    recent = np.concatenate(log_sd[burn // 4:])
                    weak = within > 0.25 * np.median(np.exp(2 * recent), axis=0)
                    scale_base = np.std(recent, axis=0) + 1e-3
                    scale_factor, scale_accept, n_scale = 2.38 / math.sqrt(max(weak.sum(), 1)), 0.0, 0
                elif n_scale == 20:  # the common factor towards 25% acceptance
                    scale_factor *= math.exp(scale_accept / n_scale - 0.25)
                    scale_accept, n_scale = 0.0, 0
            if sweeps >= burn:
                scale_total += take.mean()
                scale_n += 1
        sweeps += 1
        if sweeps > burn:
            draws["mu"].append(mu.copy())
            draws["Sigma"].append(Sigma.copy())
            draws["theta"].append(theta.copy())
        n = sweeps - burn
        if n > 0 and n % check_every == 0:
            hyper = _hyper_draws(np.stack(draws["mu"], 1), np.stack(draws["Sigma"], 1), spec)
            ess_b = min(float(np.min(az.ess(v))) for v in hyper.values())
            ess_t = min(float(np.min(az.ess(v, method="tail", prob=(0.05, 0.95)))) for v in hyper.values())
            rhat = max(float(np.nanmax(az.rhat(v))) for v in hyper.values())
            checks.append({"sweeps": sweeps, "ess_bulk": ess_b, "ess_tail": ess_t, "rhat": rhat})
            if min(ess_b, ess_t) >= ess_target and rhat <= rhat_max:
                converged = True
                break
    n = sweeps - burn
    out = {k: np.stack(v, axis=1) for k, v in draws.items()}  # (C, n, ...)
    thin = max(1, math.ceil(n / keep))
    out = {k: v[:, ::thin] for k, v in out.items()}
    out.update(_hyper_draws(out.pop("mu"), out.pop("Sigma"), spec))
    out.update(converged=converged, sweeps=sweeps, burn=burn, thin=thin, checks=checks,
               acceptance=(accept / max(n, 1)).tolist(),
               scale_acceptance=(scale_total / scale_n) if scale_n else None)
    return out


def _u_of(theta, spec):
    tp = theta[..., spec.index]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(spec.log, np.log(tp), tp)


def _hyper_draws(mu, Sigma, spec):
    sd = np.sqrt(np.diagonal(Sigma, axis1=-2, axis2=-1))
    out = {"mu": mu, "sd": sd}
    if spec.correlated and spec.p > 1:
        out["corr"] = Sigma / (sd[..., :, None] * sd[..., None, :])
    return out


def _pop_precision(Sigma, w, spec):
    """Population precision for every chain and subject (C, S, p, p) (a subject's Student-t
    weights ``w`` (C, S, p) scale its variances)."""
    if spec.correlated:
        return np.broadcast_to(np.linalg.inv(Sigma)[:, None], (len(Sigma), w.shape[1], spec.p, spec.p))
    dprec = w / np.diagonal(Sigma, axis1=1, axis2=2)[:, None, :]
    return dprec[..., :, None] * np.eye(spec.p)


def _hyper_step(u, mu, Sigma, a, w, spec, rng):
    """One exact Gibbs update of (mu, Sigma, a, w) given the subjects' u (C, S, p)."""
    C, S, p = u.shape
    prior_prec = 1.0 / (2.0 * spec.scale) ** 2
    nu = NU_HYPER
    if spec.correlated:
        prec = np.linalg.inv(Sigma)
        Lam = np.diag(prior_prec)[None] + S * prec
        cov = np.linalg.inv(Lam)
        rhs = prior_prec * spec.centre + np.einsum("kij,kj->ki", prec, u.sum(axis=1))
        m = np.einsum("kij,kj->ki", cov, rhs)
        mu = m + np.einsum("kij,kj->ki", np.linalg.cholesky(cov), rng.standard_normal((C, p)))
        r = u - mu[:, None]
        psi = np.einsum("ksi,ksj->kij", r, r) + 2 * nu * (1.0 / a)[:, :, None] * np.eye(p)[None]
        Sigma = _inv_wishart(nu + p - 1 + S, psi, rng)
        a = _inv_gamma(0.5 * (nu + p), nu * np.diagonal(np.linalg.inv(Sigma), axis1=1, axis2=2)
                       + 1.0 / spec.scale**2, rng)
        return mu, Sigma, a, w
    var = np.diagonal(Sigma, axis1=1, axis2=2).copy()
    lam = prior_prec + (w / var[:, None]).sum(axis=1)
    m = (prior_prec * spec.centre + (w * u).sum(axis=1) / var) / lam
    mu = m + rng.standard_normal((C, p)) / np.sqrt(lam)
    r2 = (u - mu[:, None]) ** 2
    var = _inv_gamma(0.5 * (nu + S), nu / a + 0.5 * (w * r2).sum(axis=1), rng)
    a = _inv_gamma(0.5 * (nu + 1), nu / var + 1.0 / spec.scale**2, rng)
    if spec.student.any():
        wt = rng.gamma(0.5 * (NU_T + 1), 1.0 / (0.5 * (NU_T + r2 / var[:, None])))
        w = np.where(spec.student, wt, 1.0)
    Sigma = np.zeros((C, p, p))
    Sigma[:, np.arange(p), np.arange(p)] = var
    return mu, Sigma, a, w


def _scale_move(subs, z, ll, theta, u, mu, Sigma, a, spec, step, rng):
    """Joint Metropolis move of the population sds and every subject along the non-centred
    coordinates: sd' = sd e^eps, u' = mu + (sd'/sd)(u - mu), other slots fixed.  In the
    coordinates (mu, var, u, other z): N(u'; mu, var') / N(u; mu, var) = e^-eps per subject and
    parameter and the map (var, u) -> (var', u') has Jacobian e^(2 eps + S eps), so the ratio is
    likelihood ratio x p(var' | a) / p(var | a) x e^(2 eps).  Returns (accepted (C,), z, ll,
    Sigma, theta)."""
    C, S, p = u.shape
    var = np.diagonal(Sigma, axis1=1, axis2=2)
    eps = step * rng.standard_normal((C, p))
    u_new = mu[:, None] + np.exp(eps)[:, None] * (u - mu[:, None])
    v_new = var * np.exp(2 * eps)
    nu = NU_HYPER
    lp = lambda v: (-(0.5 * nu + 1) * np.log(v) - nu / (a * v)).sum(axis=1)  # noqa: E731  InvGamma(nu/2, nu/a)
    th = theta.copy()
    with np.errstate(over="ignore"):
        th[..., spec.index] = np.where(spec.log, np.exp(np.clip(u_new, -700, 700)), u_new)
    z_new = subs.to_z(th)
    th, _ = subs.transform(z_new)
    ok = np.all(np.isfinite(z_new), axis=-1)[..., None]
    ll_new = subs.log_likelihood(np.where(ok, th, np.nan))
    log_r = lp(v_new) - lp(var) + 2 * eps.sum(axis=1) + (ll_new - ll).sum(axis=1)
    take = np.log(rng.random(C)) < np.where(np.isfinite(log_r), log_r, -np.inf)
    z = np.where(take[:, None, None], z_new, z)
    ll = np.where(take[:, None], ll_new, ll)
    theta = np.where(take[:, None, None], th, theta)
    var = np.where(take[:, None], v_new, var)
    Sigma = var[..., :, None] * np.eye(p)
    return take, z, ll, Sigma, theta
