"""Does the fitted model describe the data?  Posterior-predictive checks a fit runs on itself.

A converged posterior of the wrong model is still a converged posterior: outliers, a missing
effect or a competing model's data give tidy intervals around wrong values.  These checks
compare the data with data the fitted model simulates (Gelman, Meng & Stern 1996, "Posterior
predictive assessment of model fitness via realized discrepancies"): for posterior draws
theta_s and one replicated data set y_rep_s per draw, a discrepancy T(y, theta_s) against
T(y_rep_s, theta_s); the p-value is the share of draws where the replicate is at least as
extreme, (1 + #{T_rep >= T_obs}) / (1 + S).  The discrepancies use the standardised residuals
r = (g(y) - g(mu)) / sigma (g = log for log-normal noise, the identity otherwise; Student-t
residuals are compared with Student-t replicates), all observables together:

* ``chi_square``: sum of r^2 (too much scatter overall);
* ``max_residual``: max |r| (one wild row);
* ``tail_count``: the number of rows with |r| > ``TAIL_Z`` (2) (a cluster of outliers: with
  the noise scale inflated by them, no single row stands out but too many sit in the tails);
* ``trend[observable, covariate]``: sum over ``TREND_BINS`` (8) quantile bins of the covariate
  of n_b * mean_b(r)^2 (residuals that drift with the covariate: the wrong functional form),
  for every covariate with at least 3 distinct values;

and PSIS-LOO (Vehtari, Gelman & Gabry 2017) Pareto k > ``PARETO_K`` (0.7): rows whose left-out
posterior the full posterior cannot stand in for.  A p-value warns below ``ALPHA`` / m, m the
number of p-values (Bonferroni: at most ``ALPHA`` of fits of a correct model warn, fewer since
posterior-predictive p-values are conservative; measured in bench/results/misfit.md).  The Pareto
k check (on the ``LOO_ROWS`` (500) rows whose log-likelihood varies most, ``LOO_DRAWS`` (1000)
draws) warns when at least 2 rows, and ``PARETO_SHARE`` (1%) of the rows checked, exceed 0.7
(a single influential row occurs in fits of a correct model: 1 of the bench's 105).

Where it runs: with the pointwise groups (:meth:`skinfit.fit.Fit.complete`, so ``skinfit fit``,
``Fit.save``, reports and compare), not in :func:`skinfit.fit`, which returns at the converged
posterior.  Cost: ``PPC_DRAWS`` (400, or 3 m / ``ALPHA`` if more) draws' predictions plus PSIS
on at most 500 rows (see the wall-time figures in bench/results/misfit.md).
"""

import math
import warnings

import numpy as np

__all__ = ["ALPHA", "PARETO_K", "PARETO_SHARE", "TAIL_Z", "TREND_BINS", "PPC_DRAWS", "LOO_DRAWS", "LOO_ROWS",
           "MisfitWarning", "check_fit", "misfit_messages", "simulated_check"]

ALPHA = 0.05
PARETO_K = 0.7
PARETO_SHARE = 0.01
TAIL_Z = 2.0
TREND_BINS = 8
PPC_DRAWS = 400
#: (draw, row) cells held at once while computing the discrepancies (8 MB per float array).
BLOCK_CELLS = 1 << 20
#: fewer posterior draws than this in the log-likelihood group: no Pareto k check (too noisy).
MIN_LOO_DRAWS = 200
#: the Pareto k check's draws and rows (see :func:`_pareto`)
LOO_DRAWS = 1000
LOO_ROWS = 500


class MisfitWarning(UserWarning):
    """The fitted model does not describe the data (see :mod:`skinfit.misfit`)."""


def _bins(x, n_bins):
    """Row -> bin code of ``x`` by rank (ties kept together), at most ``n_bins`` bins; None
    when ``x`` has fewer than 3 distinct finite values."""
    x = np.asarray(x, dtype=float)
    if not np.isfinite(x).all():
        return None
    values, inverse = np.unique(x, return_inverse=True)
    if len(values) < 3:
        return None
    if len(values) <= n_bins:
        return inverse
    counts = np.bincount(inverse)
    edges = np.searchsorted(np.cumsum(counts) / len(x), np.arange(1, n_bins) / n_bins, side="left")
    return np.searchsorted(edges, inverse, side="left")


def _bin_stat(r, order, starts, counts):
    """sum_b (sum of r in bin b)^2 / n_b for each row of ``r`` (k, n)."""
    sums = np.add.reduceat(r[:, order], starts, axis=1)
    return (sums * sums / counts).sum(axis=1)


def check_fit(post, theta, y_rep, *, log_lik=None, reff=1.0, alpha=ALPHA, n_draws=PPC_DRAWS):
    """Posterior-predictive and LOO checks of one fit.

    Parameters
    ----------
    post : Posterior
    theta : (S, d) array
        Posterior draws, natural parameters, in the order of ``y_rep``'s first axis.
    y_rep : mapping observable -> (S, n) array
        One replicated data set per draw (the fit's ``posterior_predictive`` group).
    log_lik : (chain, draw, n) array, optional
        The pointwise log-likelihood summed over observables, for the Pareto k check.
    reff : float
        Relative efficiency of the draws for PSIS.

    Returns
    -------
    dict
        ``checks`` (list of {check, statistic, p, threshold, warn}), ``pareto_k``
        ({count, rows, threshold, warn} or None), ``draws``, ``alpha``, ``m``; and
        ``worst_rows`` (1-based rows with the largest posterior-mean |r|, with r).
    """
    S = len(theta)
    obs = list(post.observables)
    trends = []
    for o in obs:
        for c, x in post.x.items():
            codes = _bins(x, TREND_BINS)
            if codes is None:
                continue
            order = np.argsort(codes, kind="stable")
            counts = np.bincount(codes)
            trends.append((o, c, order, np.concatenate([[0], np.cumsum(counts)[:-1]]), counts.astype(float)))
    names = ["chi_square", "max_residual", "tail_count"] + [f"trend[{o}, {c}]" for o, c, *_ in trends]
    # enough draws that the smallest p-value, 1 / (1 + k), is a third of the threshold
    k = min(S, max(n_draws, math.ceil(3 * len(names) / alpha)))
    idx = np.unique(np.linspace(0, S - 1, k).round().astype(int))
    k, n = len(idx), post.n
    t_obs, t_rep = np.empty((len(names), k)), np.empty((len(names), k))
    r_sum = {o: np.zeros(n) for o in obs}
    step = max(1, min(k, BLOCK_CELLS // max(n * len(obs), 1)))
    for i in range(0, k, step):
        sel = idx[i:i + step]
        th = theta[sel]
        _, pred, _ = post._evaluate(th, False)
        res = {}
        for o in obs:
            log = post.noise[o] == "lognormal"
            g = np.log if log else np.asarray
            with np.errstate(divide="ignore", invalid="ignore"):
                mu = g(pred[o])
                sigma = post._noise_param(th, "sigma", o)
                res[o] = ((g(post.y[o]) - mu) / sigma, (g(y_rep[o][sel]) - mu) / sigma)
            r_sum[o] += res[o][0].sum(axis=0)
        for which, out in ((0, t_obs), (1, t_rep)):
            r = np.concatenate([res[o][which] for o in obs], axis=1)
            a = np.abs(r)
            out[0, i:i + step] = (r * r).sum(axis=1)
            out[1, i:i + step] = a.max(axis=1)
            out[2, i:i + step] = (a > TAIL_Z).sum(axis=1)
            for j, (o, _c, order, starts, counts) in enumerate(trends):
                out[3 + j, i:i + step] = _bin_stat(res[o][which], order, starts, counts)
    with np.errstate(invalid="ignore"):
        p = (1 + (t_rep >= t_obs).sum(axis=1)) / (1 + k)
    p = np.where(np.isfinite(t_obs).all(axis=1), p, 0.0)  # a non-finite residual: the data are impossible
    pareto = _pareto(log_lik, reff, n) if log_lik is not None else None
    m = len(names)
    threshold = alpha / m
    checks = [{"check": name, "statistic": float(np.median(t_obs[j])), "replicated": float(np.median(t_rep[j])),
               "p": float(p[j]), "threshold": threshold, "warn": bool(p[j] < threshold)}
              for j, name in enumerate(names)]
    r_mean = np.concatenate([r_sum[o] / k for o in obs])
    top = np.argsort(-np.abs(np.nan_to_num(r_mean, nan=np.inf)))[:5]
    worst = [{"row": int(t % n) + 1, "observable": obs[t // n], "r": float(r_mean[t])} for t in top]
    trend_means = {}
    for o, c, order, starts, counts in trends:
        rm = r_sum[o][order] / k
        trend_means[f"trend[{o}, {c}]"] = (np.add.reduceat(rm, starts) / counts).round(2).tolist()
    return {"checks": checks, "pareto_k": pareto, "draws": int(k), "alpha": alpha, "m": m,
            "worst_rows": worst, "trend_means": trend_means,
            # too few draws (memory thinning) for any p-value to reach the threshold
            "underpowered": bool(1 / (1 + k) >= threshold)}


def _pareto(log_lik, reff, n):
    """Rows with PSIS Pareto k > PARETO_K, or None when there are too few draws.

    PSIS fits a generalised Pareto tail per row (~1-3 ms a row here): on at most
    ``LOO_DRAWS`` draws (evenly spaced) of the ``LOO_ROWS`` rows whose log-likelihood varies most
    over the draws (the importance ratios of a row are exp(-log-likelihood): a row whose values
    barely vary has light-tailed ratios), so large data sets cost no more than 500 rows.
    """
    log_lik = np.asarray(log_lik, dtype=float)
    if log_lik.shape[0] * log_lik.shape[1] < MIN_LOO_DRAWS or not np.isfinite(log_lik).all():
        return None
    import arviz_stats  # noqa: F401 - registers the .azstats accessor
    import xarray as xr

    flat = log_lik.reshape(-1, log_lik.shape[-1])
    flat = flat[np.unique(np.linspace(0, len(flat) - 1, min(LOO_DRAWS, len(flat))).round().astype(int))]
    rows = np.sort(np.argsort(-flat.var(axis=0), kind="stable")[:LOO_ROWS])
    da = xr.DataArray(-flat[:, rows][None], dims=("chain", "draw", "obs_id"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, k = da.azstats.psislw(r_eff=reff, dim=["chain", "draw"])
    k = np.asarray(k)
    bad = np.flatnonzero(k > PARETO_K)
    return {"count": int(len(bad)), "rows": (rows[bad[np.argsort(-k[bad])]][:10] + 1).tolist(),
            "max_k": float(np.max(k)), "threshold": PARETO_K, "rows_checked": int(len(rows)),
            "warn": bool(len(bad) >= max(2, math.ceil(PARETO_SHARE * min(n, LOO_ROWS))))}


def misfit_messages(record):
    """The guard-rail warnings (dicts as :func:`skinfit.guardrails.check_run` gives) of a
    :func:`check_fit` record: one per failed check."""
    out = []
    worst = ", ".join(f"{w['row']} ({w['r']:+.1f})" for w in record["worst_rows"][:3])
    for c in record["checks"]:
        if not c["warn"]:
            continue
        p = (f"posterior-predictive p = {c['p']:.2g} < {c['threshold']:.2g} "
             f"({record['alpha']:g} over {record['m']} checks)")
        if c["check"] == "chi_square":
            what = (f"the residuals scatter more than the fitted noise allows (sum of squared standardised residuals "
                    f"{c['statistic']:.4g}, replicates {c['replicated']:.4g})")
        elif c["check"] == "max_residual":
            what = f"a residual too large for the fitted noise (max |r| {c['statistic']:.3g}; rows {worst})"
        elif c["check"] == "tail_count":
            what = (f"too many rows in the tails: {c['statistic']:.0f} with |r| > {TAIL_Z:g} where replicates have "
                    f"{c['replicated']:.0f} (outliers? rows {worst})")
        else:
            means = record["trend_means"].get(c["check"], [])
            what = (f"the residuals drift with {c['check'][6:-1].split(', ')[1]} (mean standardised residual by "
                    f"bin: {', '.join(f'{v:+.2f}' for v in means)})")
        out.append({"check": "misfit", "status": "WARN", "parameter": None,
                    "message": f"model does not describe the data: {what}; {p}"})
    pk = record.get("pareto_k")
    if pk and pk["warn"]:
        out.append({"check": "misfit", "status": "WARN", "parameter": None,
                    "message": f"model does not describe the data: {pk['count']} rows with PSIS-LOO Pareto k > "
                               f"{PARETO_K} (max {pk['max_k']:.2f}; rows {', '.join(map(str, pk['rows'][:5]))}): "
                               f"each alone moves the posterior; LOO comparisons are unreliable"})
    return out


def simulated_check(model, seed, *, dataset=None, contaminate=None, fit_model=None, **fit_kwargs):
    """One fit of data simulated from ``model`` at the design of its shipped dataset
    (:func:`skinfit.sbc.design_dataset`), parameters drawn from its prior (inside the physical
    support), noise from its noise model: the check's record and warnings, for calibration.

    ``contaminate`` = (n_rows, low, high): that many rows' observables multiplied by factors
    uniform in [low, high] (outliers); ``fit_model``: fit another model (a competing variant)
    to the data simulated from ``model``.  All draws from ``numpy.random.default_rng(seed)``.
    """
    from .fit import fit
    from .models import load_model
    from .posterior import Posterior
    from .priors import load_priors
    from .sbc import _draw_truth, design_dataset

    model = load_model(model)
    rng = np.random.default_rng(seed)
    design = design_dataset(model, dataset)
    post = Posterior(model, load_priors(model.id), design)
    theta = _draw_truth(post, rng)
    y = {o: v[0] for o, v in post.simulate(theta[None], rng).items()}
    if contaminate is not None:
        n_bad, low, high = contaminate
        rows = rng.choice(post.n, size=n_bad, replace=False)
        factors = rng.uniform(low, high, size=n_bad)
        for o in y:
            y[o] = y[o].copy()
            y[o][rows] *= factors
    ds = design.with_observations(y, f"misfit check seed {seed}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = fit(fit_model or model, ds, rng=int(rng.integers(2**63 - 1)), n_prior_draws=10, **fit_kwargs)
        result.complete()
    record = result.attr("misfit")
    found = [w for w in result.warnings if w["check"] == "misfit"]
    return {"model": model.id, "fit_model": (fit_model or model.id), "seed": seed, "rows": post.n,
            "converged": result.converged, "warned": bool(found),
            "failed": "; ".join(c["check"] for c in record["checks"] if c["warn"])
                      + ("; pareto_k" if record["pareto_k"] and record["pareto_k"]["warn"] else ""),
            "min_p": min(c["p"] for c in record["checks"]), "m": record["m"],
            "pareto_k_gt_0.7": record["pareto_k"]["count"] if record["pareto_k"] else -1,
            "seconds": result.attr("timings")["total_s"] + result.attr("timings")["pointwise_s"]
                       + result.attr("timings")["misfit_s"]}
