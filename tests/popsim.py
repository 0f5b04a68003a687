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

from skinfit.data import Column, Dataset
from skinfit.hierarchical import NU_HYPER
from skinfit.models import load_model
from skinfit.population import DrawsFit, _prior_moments
from skinfit.posterior import Posterior
from skinfit.priors import load_priors

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
    from skinfit.proposal import MixtureT

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

    from skinfit.population import population

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
