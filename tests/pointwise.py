"""Checks of a fit's pointwise groups (``log_likelihood``, ``posterior_predictive``), computed
on first use, against numbers from outside the code that made them."""

import numpy as np

from skinfit.analysis.evidence import posterior_draws
from skinfit.io.labels import noise_suffix


def check_pointwise_groups(fit):
    """Shapes (chain, draw, obs_id); the pointwise log-likelihood summed over rows and
    observables against ``sample_stats.lp`` - log prior (``lp`` is the chain's own log
    density less the sampling map's Jacobian, evaluated on distinct rows by sufficient
    statistics: another code path), rtol 1e-9; and the predictive
    draws against ``Model.predict`` at every posterior draw: for normal noise y_rep - mu, for
    log-normal log y_rep - log mu, is sigma times independent standard normals, so its mean
    over the N draws has standard error sqrt(sum sigma^2) / N in each row (5 standard errors
    allowed), and divided by sigma it has mean 0 and variance 1 (5 standard errors of each
    over all draws x rows)."""
    tree = fit.idata
    post = fit.posterior
    nwalkers, ndraws, n = fit.attr("sampler")["nwalkers"], tree["posterior"].sizes["draw"], post.n
    theta = posterior_draws(fit)
    ll = tree["log_likelihood"].to_dataset()
    ppc = tree["posterior_predictive"].to_dataset()
    for ds in (ll, ppc):
        assert sorted(ds.data_vars) == sorted(post.observables)
        for v in ds.data_vars.values():
            assert v.dims == ("chain", "draw", "obs_id") and v.shape == (nwalkers, ndraws, n)
    total = sum(ll[o].values.sum(axis=-1) for o in post.observables).reshape(-1)
    lp = tree["sample_stats"]["lp"].values.reshape(-1)
    np.testing.assert_allclose(total, lp - post.log_prior(theta), rtol=1e-9)

    params = {p: tree["posterior"][p].values.reshape(-1) for p in post.model.parameter_names}
    mu = post.model.predict(params, post.dataset.frame)
    mu = mu if isinstance(mu, dict) else {post.observables[0]: mu}
    for o in post.observables:
        assert post.noise[o] in ("normal", "lognormal")
        scale = np.log if post.noise[o] == "lognormal" else np.asarray
        sigma = tree["posterior"][f"sigma{noise_suffix(post.observables, o)}"].values.reshape(-1, 1)
        d = scale(ppc[o].values.reshape(-1, n)) - scale(mu[o])
        se = np.sqrt((sigma ** 2).sum()) / len(sigma)
        assert np.abs(d.mean(axis=0)).max() < 5 * se, o
        r = d / sigma
        assert abs(r.mean()) < 5 / np.sqrt(r.size) and abs(r.var() - 1) < 5 * np.sqrt(2 / r.size), o
