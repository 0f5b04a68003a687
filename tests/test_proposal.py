"""The mixture-of-Student-t proposal: its density against scipy.stats, its draws against its
density, and EM recovering a known mixture."""

import numpy as np
import pytest
from scipy import stats
from scipy.special import logsumexp

from skinfit.inference.proposal import MixtureT, fit_mixture


def _two_components():
    means = np.array([[0.0, 1.0, -1.0], [2.0, -0.5, 0.5]])
    a = np.array([[1.0, 0.3, 0.0], [0.3, 0.5, 0.1], [0.0, 0.1, 2.0]])
    covs = np.stack([a, np.diag([0.2, 1.5, 0.7])])
    return np.array([0.3, 0.7]), means, covs


@pytest.mark.parametrize("nu", [5.0, 3.0, np.inf])
def test_logpdf_matches_scipy(nu, rng):
    w, m, c = _two_components()
    mix = MixtureT(w, m, c, nu)
    x = rng.normal(size=(50, 3)) * 2
    if np.isinf(nu):
        parts = [stats.multivariate_normal(m[k], c[k]).logpdf(x) for k in range(2)]
    else:
        parts = [stats.multivariate_t(m[k], c[k], df=nu).logpdf(x) for k in range(2)]
    ref = logsumexp(np.log(w)[:, None] + np.array(parts), axis=0)
    np.testing.assert_allclose(mix.logpdf(x), ref, rtol=1e-12)


def test_draws_have_the_mixture_moments(rng):
    """Mean sum_k w_k m_k and covariance sum_k w_k (nu/(nu-2) S_k + m_k m_k^T) - mean mean^T."""
    w, m, c = _two_components()
    nu, n = 7.0, 200_000
    x = MixtureT(w, m, c, nu).draw(np.random.RandomState(3), n)
    mean = w @ m
    cov = sum(wk * (nu / (nu - 2) * ck + np.outer(mk, mk)) for wk, mk, ck in zip(w, m, c)) - np.outer(mean, mean)
    sd = np.sqrt(np.diag(cov))
    assert np.all(np.abs(x.mean(axis=0) - mean) < 5 * sd / np.sqrt(n))
    # variance of a sample variance of a t mixture: generous 5% (kurtosis of nu = 7)
    np.testing.assert_allclose(np.cov(x.T), cov, atol=0.05 * sd.max() ** 2)


def test_fit_mixture_recovers_two_components(rng):
    w, m, c = _two_components()
    x = MixtureT(w, m * 3, c, np.inf).draw(rng, 6000)  # well separated
    fit = fit_mixture(x, 2, np.random.default_rng(0), nu=np.inf)
    order = np.argsort(fit.means[:, 0])
    np.testing.assert_allclose(fit.weights[order], w, atol=0.03)
    np.testing.assert_allclose(fit.means[order], m * 3, atol=0.1)
    covs = fit.chol @ np.swapaxes(fit.chol, 1, 2)
    np.testing.assert_allclose(covs[order], c, atol=0.15)


def test_fit_mixture_uses_fewer_components_for_few_samples(rng):
    """Fewer than 10 (d + 1) samples per component: fewer components are fitted."""
    x = rng.normal(size=(130, 5))
    assert len(fit_mixture(x, 6, rng).weights) <= 2
    single = fit_mixture(x[:20], 6, rng)
    np.testing.assert_allclose(single.means[0], x[:20].mean(axis=0))
