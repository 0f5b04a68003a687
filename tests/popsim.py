"""Simulated populations for calibration of :mod:`skinfit.population` (tests and bench).

Coulomb friction at 0 V (models/electroadhesion_coulomb.toml, priors/electroadhesion_coulomb.toml):
``Ft = mu_i Fn + sigma_i eps`` at two normal-force levels (0.3 and 1 N) with ``presses``
presses each.  A population is drawn from the hyper-prior the sampler uses (or from given
hyper-parameters), every subject's noise scale from its prior; a whole simulation is redrawn
when a subject's ``mu`` leaves its prior bounds (the population is not renormalised inside
them, so this is exactly the model's joint prior).  Each subject's "separate fit" is an
importance sample of its posterior under its own prior (4000 prior draws, resampled to
``n_draws``): exact in the limit, and 2 parameters make it cheap.
"""

from types import MappingProxyType

import numpy as np
import pandas as pd

from skinfit.analysis.population.hierarchical import NU_HYPER
from skinfit.analysis.population.inputs import DrawsFit
from skinfit.analysis.population.population import _prior_moments
from skinfit.io.data import Column, Dataset
from skinfit.io.models import load_model
from skinfit.io.priors import load_priors
from skinfit.posterior import Posterior

MODEL = "electroadhesion_coulomb"
LEVELS = (0.3, 1.0)  # normal forces [N]
_COLUMNS = (Column("voltage", "voltage", "V", "quantity"), Column("normal_force", "normal_force", "N", "quantity"),
            Column("tangential_force", "tangential_force", "N", "quantity", signed=True))


def hyperprior(family):
    """(centre, scale) of the hyper-prior of mu in the family's coordinate, from the prior file."""
    prior = load_priors(MODEL)["mu"]
    return _prior_moments(prior, family == "lognormal")


def draw_population(rng, family, n_subjects, *, hyper=None):
    """(mu, tau, theta (S,)) drawn from the hyper-prior or from ``hyper=(mu, tau)``; redrawn
    until every subject lies inside the prior bounds of mu."""
    prior = load_priors(MODEL)["mu"]
    c, s = hyperprior(family)
    while True:
        if hyper is None:
            m = c + 2 * s * rng.standard_normal()
            tau = abs(s * rng.standard_t(NU_HYPER))
        else:
            m, tau = hyper
        u = m + tau * rng.standard_normal(n_subjects)
        theta = np.exp(u) if family == "lognormal" else u
        if np.all((theta > prior.lower) & (theta < prior.upper)):
            return m, tau, theta


def subject_fits(rng, theta, presses, *, n_draws=1000, n_prior=4000):
    """{label: DrawsFit} of simulated subjects with true friction coefficients ``theta``."""
    model, priors = load_model(MODEL), load_priors(MODEL)
    sigma_prior = priors["sigma"]
    fits = {}
    fn = np.repeat(LEVELS, presses)
    for i, mu in enumerate(theta):
        sigma = float(sigma_prior.rvs(1, rng)[0])
        ft = mu * fn + sigma * rng.standard_normal(len(fn))
        frame = pd.DataFrame({"voltage": np.zeros(len(fn)), "normal_force": fn, "tangential_force": ft})
        label = f"S{i + 1:02d}"
        ds = Dataset(label, "simulated", frame, _COLUMNS, (), MappingProxyType({"kind": "simulated"}), None, "", label)
        post = Posterior(model, priors, ds)
        fits[label] = DrawsFit(post, _importance_draws(post, rng, n_draws, n_prior), label)
    return fits


def _importance_draws(post, rng, n_draws, n_prior):
    """Posterior draws by two rounds of importance sampling: from the prior, then from a
    Student-t (5 d.o.f., covariance x2) fitted to the weighted first round (sampling
    coordinates); resampled to ``n_draws``."""
    from skinfit.inference.proposal import MixtureT

    z = post.to_z(post.sample_prior(n_prior, rng))
    logw = post(z) - _prior_logpdf_z(post, z)
    for _ in range(2):
        w = np.exp(logw - logw.max())
        w /= w.sum()
        mean = w @ z
        cov = ((z - mean).T * w) @ (z - mean) + 1e-8 * np.eye(post.ndim)
        g = MixtureT([1.0], mean[None], (2.0 * cov)[None], 5.0)
        z = g.draw(rng, n_prior)
        logw = post(z) - g.logpdf(z)
    w = np.exp(logw - logw.max())
    return post.to_theta(z[rng.choice(n_prior, n_draws, p=w / w.sum())])


def _prior_logpdf_z(post, z):
    theta, log_jac = post._transform(z)
    return post.log_prior(theta) + log_jac


def rank(draws, truth, n=99):
    """Rank of ``truth`` among ``n`` evenly thinned ``draws`` (flattened chain-major): 0..n."""
    flat = np.asarray(draws).ravel()
    pick = flat[np.linspace(0, len(flat) - 1, n).astype(int)]
    return int(np.sum(pick < truth))


def run_sbc(family, n_sims, seed, *, n_subjects=8, presses=2, ess_target=100, rhat_max=1.05, control=0.7):
    """Simulation-based calibration (Talts et al. 2018) of the population mean ``mu`` and sd
    ``tau`` of mu: ranks (0..99) of the truths among 99 posterior draws of each of ``n_sims``
    simulated populations, and the chi-square p-value of their uniformity over 10 bins.

    Negative control ``tau_control``: the truth ranked among the same tau draws times
    ``control`` (a sampler that under-states the population spread); it must fail."""
    import warnings

    from scipy import stats

    from skinfit.analysis.population.population import population

    rng = np.random.default_rng(seed)
    ranks = {"mu": [], "tau": [], "tau_control": []}
    for _ in range(n_sims):
        m, tau, theta = draw_population(rng, family, n_subjects)
        fits = subject_fits(rng, theta, presses)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = population(fits, ["mu"], family={"mu": family}, rng=rng, chains=4, ess_target=ess_target,
                           rhat_max=rhat_max, burn=200)
        ranks["mu"].append(rank(r.mu, m))
        ranks["tau"].append(rank(r.sd, tau))
        ranks["tau_control"].append(rank(control * r.sd, tau))
    pvalues = {k: float(stats.chisquare(np.bincount(np.asarray(v) // 10, minlength=10)).pvalue)
               for k, v in ranks.items()}
    return ranks, pvalues


def quadrature(fits, family="lognormal", n_u=1500, n_sigma=100, n_m=160, n_tau=160):
    """The population posterior of the Coulomb friction coefficient by quadrature, an
    independent reference for the sampler (no Markov chain, no proposal): each subject's
    likelihood of ``u`` (log mu for the log-normal family, else mu) summed over its noise
    scale on a grid under its prior (the other slots do not enter the 0 V likelihood), then
    ``(m, tau)`` on a grid under the hyper-prior (``tau`` log-spaced from 1e-3 s), and each
    subject's shrunk posterior of ``u`` mixed over that grid.

    Returns dict: ``m``, ``tau`` (posterior mean, sd) and ``subjects`` {label: function
    q -> quantile of the subject's mu}."""
    from scipy import stats

    c, s = hyperprior(family)
    labels = list(fits)
    posts = [fits[k].posterior for k in labels]
    names = posts[0].names
    j_mu, j_sig = names.index("mu"), names.index("sigma")
    draws = [np.asarray(fits[k].group("posterior")["mu"]).ravel() for k in labels]
    prior_mu = load_priors(MODEL)["mu"]
    lo_u, hi_u = (np.log(prior_mu.lower + 1e-12), np.log(prior_mu.upper)) if family == "lognormal" \
        else (prior_mu.lower, prior_mu.upper)
    ud = [np.log(d) if family == "lognormal" else d for d in draws]
    a, b = min(np.quantile(x, 0.0005) for x in ud), max(np.quantile(x, 0.9995) for x in ud)
    a, b = max(a - 0.3 * (b - a), lo_u), min(b + 0.3 * (b - a), hi_u)
    u = np.linspace(a, b, n_u)
    mu = np.exp(u) if family == "lognormal" else u
    logL = np.empty((len(posts), n_u))
    for i, post in enumerate(posts):
        sig_draws = np.asarray(fits[labels[i]].group("posterior")["sigma"]).ravel()
        ls = np.linspace(np.log(sig_draws.min()) - 1.5, np.log(sig_draws.max()) + 1.5, n_sigma)
        base = np.array([sl.prior.ppf(0.5) for sl in post.slots])
        theta = np.tile(base, (n_u * n_sigma, 1))
        theta[:, j_mu] = np.repeat(mu, n_sigma)
        theta[:, j_sig] = np.tile(np.exp(ls), n_u)
        ll = post.log_likelihood(theta).reshape(n_u, n_sigma)
        ll += post.slots[j_sig].prior.logpdf(np.exp(ls)) + ls  # prior of sigma, d sigma = sigma d log sigma
        m_ = ll.max()
        logL[i] = m_ + np.log(np.exp(ll - m_).sum(axis=1) * (ls[1] - ls[0]))
    L = np.exp(logL - logL.max(axis=1, keepdims=True))
    du = u[1] - u[0]
    sd_u = max(np.std(np.concatenate(ud)), 1e-3)
    m_grid = np.linspace(u.min() - 0.5 * sd_u, u.max() + 0.5 * sd_u, n_m)
    log_tau = np.linspace(np.log(1e-3 * s), np.log(5 * s), n_tau)
    tau = np.exp(log_tau)
    log_post = np.empty((n_tau, n_m))
    Z = np.empty((n_tau, n_m, len(posts)))
    for t, tv in enumerate(tau):
        N = stats.norm.pdf(u[None, :], m_grid[:, None], tv) * du  # (n_m, n_u)
        Z[t] = N @ L.T
        with np.errstate(divide="ignore"):
            log_post[t] = np.log(Z[t]).sum(axis=1)
    log_post += stats.norm.logpdf(m_grid, c, 2 * s)[None] + stats.t.logpdf(tau / s, NU_HYPER)[:, None] + log_tau[:, None]
    w = np.exp(log_post - log_post.max())
    w /= w.sum()
    mm = (w.sum(axis=0) * m_grid).sum()
    tm = (w.sum(axis=1) * tau).sum()
    out = {"m": (mm, np.sqrt((w.sum(axis=0) * (m_grid - mm) ** 2).sum())),
           "tau": (tm, np.sqrt((w.sum(axis=1) * (tau - tm) ** 2).sum()))}
    dens = np.zeros((len(posts), n_u))
    for t, tv in enumerate(tau):
        N = stats.norm.pdf(u[None, :], m_grid[:, None], tv) * du
        ratio = np.divide(w[t][:, None], Z[t], out=np.zeros_like(Z[t]), where=w[t][:, None] > 0)
        dens += ratio.T @ N  # (S, n_u): sum over m of w / Z_i N(u; m, tau)
    dens *= L
    cdf = np.cumsum(dens, axis=1)
    cdf /= cdf[:, -1:]
    out["subjects"] = {k: (lambda q, c_=cdf[i]: float(np.interp(q, c_, mu))) for i, k in enumerate(labels)}
    return out
