"""Does the fitted model describe the data?  Posterior-predictive checks a fit runs on itself.

A converged posterior of the wrong model is still a converged posterior: outliers, a missing
effect or a competing model's data give tidy intervals around wrong values.  These checks
compare the data with data the fitted model simulates (Gelman, Meng & Stern 1996, "Posterior
predictive assessment of model fitness via realized discrepancies"): for posterior draws
theta_s and one replicated data set y_rep_s per draw, a discrepancy T(y, theta_s) against
T(y_rep_s, theta_s); the p-value is the share of draws where the replicate is at least as
extreme, (1 + #{T_rep >= T_obs}) / (1 + S).  The discrepancies use the standardised residuals
r = (g(y) - g(mu)) / sigma (g = log for log-normal noise, the identity otherwise; sigma the
row's noise sd sqrt(sigma^2 + se_i^2) where the data give known standard errors; Student-t
residuals are compared with Student-t replicates), all observables together:

* ``chi_square``: sum of r^2 (too much scatter overall);
* ``max_residual``: max |r| (one wild row);
* ``tail_count``: the number of rows with |r| > ``TAIL_Z`` (2) (a cluster of outliers: with
  the noise scale inflated by them, no single row stands out but too many sit in the tails);
* ``trend[observable, column]``: sum over ``TREND_BINS`` (8) quantile bins of a quantity of
  n_b * mean_b(r)^2 (residuals that drift with it: the wrong functional form of a covariate, or
  an effect of a quantity the model does not use at all, e.g. the voltage of data fitted by a
  model without one), rows where the quantity is missing in a bin of their own;
* ``levels[observable, column]``: the same statistic over the levels of a category (subject,
  session, surface...) with 2 to n/2 levels: residuals that differ between groups;
* ``serial[observable, row order]``: the lag-1 autocorrelation sum r_i r_(i+1) / sum r_i^2 of
  the residuals in row order, and ``serial[observable, <time> order]`` in the order of a column
  with a unit of time (within the dataset's category columns) where that differs: rows that
  are not independent, e.g. a raw recording fitted as independent rows, whose posterior is
  too narrow (by about sqrt((1 + rho) / (1 - rho)) for AR(1) noise of lag-1 correlation rho);

the trend and levels checks on every column of the dataset but the observables (they reach the
check as ``Posterior.dataset.frame``; covariates first, a column that partitions the rows as an
earlier one left out); and PSIS-LOO (Vehtari, Gelman & Gabry 2017) Pareto k > ``PARETO_K``
(0.7): rows whose left-out posterior the full posterior cannot stand in for.

A p-value warns below ``ALPHA`` / m, m the number of p-values (Bonferroni: at most ``ALPHA`` of
fits of a correct model warn).  ``ALPHA`` is 0.02, not 0.05: posterior-predictive p-values of
statistics the fitted parameters barely move (serial correlation, groups and quantities the model
does not use) are near uniform on data from the fitted model, so Bonferroni's bound is nearly
reached, and a fit's warnings together (the sampling guard rails too) must stay under 5% of
fits of a correct model (measured per model family in bench/results/misfit.md).  The
Pareto k check (on the ``LOO_ROWS`` (500) rows whose log-likelihood varies most, ``LOO_DRAWS``
(1000) draws) warns when at least 2 rows, and ``PARETO_SHARE`` (1%) of the rows checked,
exceed 0.7 (a single influential row occurs in fits of a correct model: 1 of the bench's 105).

Where it runs: on the pointwise groups, when a fit is completed (:func:`skinfit.fit` by default,
else :meth:`skinfit.Fit.complete` or ``Fit.save``): a guard rail on the run, beside
:mod:`skinfit.inference.guardrails`.  Its calibration on simulated data is
:func:`skinfit.analysis.misfit.simulated_check`.  Cost: the predictions and statistics of
``PPC_DRAWS`` (400, or 3 m / ``ALPHA`` if more, so that p-values reach a third of the threshold)
draws on every row, and PSIS on at most 500 rows: linear in draws x rows (wall times in
bench/results/misfit.md).
"""

import math
import warnings

import arviz_stats  # noqa: F401 - registers the .azstats accessor (PSIS, _pareto)
import numpy as np
import xarray as xr
from scipy import sparse

from skinfit.io.units import dimension

__all__ = ["ALPHA", "PARETO_K", "PARETO_SHARE", "TAIL_Z", "TREND_BINS", "PPC_DRAWS", "LOO_DRAWS", "LOO_ROWS",
           "MisfitWarning", "RawSeriesWarning", "check_fit", "misfit_messages", "raw_series", "INGEST_HINT",
           "RAW_ROWS", "TIME_COLUMNS"]

ALPHA = 0.02
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
    """Evidence that the fitted model does not describe the data (see :mod:`skinfit.inference.misfit`)."""


class RawSeriesWarning(MisfitWarning):
    """The data look like a raw recording (samples at a uniform time step) fitted as if each
    sample were an independent measurement: reduce it to one row per stroke first
    (``skinfit ingest``); see :func:`raw_series`."""


#: What to do with a raw recording, named by every warning that suspects one.
INGEST_HINT = "reduce the raw recording to one row per stroke with `skinfit ingest RAW --rig RIG.toml`"
#: More rows than this at a uniform time step: a raw recording (:func:`raw_series`).
RAW_ROWS = 1000
#: Names (any case) of the time column of a raw recording.
TIME_COLUMNS = ("time", "t", "timestamp")


def raw_series(dataset):
    """A warning's text when ``dataset`` looks like a raw recording fitted by mistake, else None:
    more than :data:`RAW_ROWS` rows and a column named as in :data:`TIME_COLUMNS` with a unit of
    time whose consecutive differences are one positive step to 0.1% on at least 99% of the rows
    (a sampled signal; trials joined end to end keep their few jumps).  Per-stroke data (a start
    time per stroke, strokes of varying length) and designed experiments do not have one."""
    if len(dataset.frame) <= RAW_ROWS:
        return None
    for c in dataset.columns:
        if c.name.lower() not in TIME_COLUMNS or not c.unit or dimension(c.unit) != "time":
            continue
        step = np.diff(dataset.frame[c.name].to_numpy(dtype=float))
        h = float(np.median(step)) if len(step) else 0.0
        if not (h > 0 and np.mean(np.abs(step - h) <= 1e-3 * h) >= 0.99):
            continue
        return (f"{len(dataset.frame)} rows at a uniform time step of {h:.3g} s ({1 / h:.4g} Hz) in column "
                f"{c.header!r}: this looks like a raw recording whose samples are fitted as independent "
                f"measurements (they are not: the posterior would be far too narrow); {INGEST_HINT}")
    return None


def _bins(x, n_bins):
    """Row -> bin code of ``x`` by rank (ties kept together), at most ``n_bins`` bins, rows
    where ``x`` is missing (NaN: e.g. a column missing by design) in a bin of their own; None
    when that leaves fewer than 2 bins."""
    x = np.asarray(x, dtype=float)
    finite = np.isfinite(x)
    values, inverse = np.unique(x[finite], return_inverse=True)
    if len(values) + (not finite.all()) < 2:
        return None
    if len(values) > n_bins:
        counts = np.bincount(inverse)
        edges = np.searchsorted(np.cumsum(counts) / len(inverse), np.arange(1, n_bins) / n_bins, side="left")
        # a value holding more than a bin's share leaves an empty bin: number the bins kept
        inverse = np.unique(np.searchsorted(edges, inverse, side="left"), return_inverse=True)[1]
    codes = np.full(len(x), inverse.max(initial=-1) + 1)
    codes[finite] = inverse
    return codes


def _levels(values):
    """Row -> level code of a category column and the level names; None unless it has 2 to
    n/2 levels (a column with a level per row or two, an identifier, groups nothing)."""
    names, codes = np.unique(np.asarray(values, dtype=str), return_inverse=True)
    if not 2 <= len(names) <= len(codes) / 2:
        return None
    return codes, names.tolist()


def _groupings(post):
    """The partitions of the rows the residuals are checked against: (column, kind, codes,
    labels), kind "trend" (a quantity in rank bins, low to high) or "levels" (a category), for
    every column of the dataset but the observables: the model's covariates first, then every
    other column (grouping columns, quantities the model does not use).  A partition equal to
    an earlier one is left out (it would test the same thing twice)."""
    frame = post.dataset.frame
    names = [c for c in post.x if c in frame.columns]
    names += [c for c in frame.columns if c not in names and c not in post.observables]
    out, seen = [], set()
    for c in names:
        col = frame[c]
        if col.dtype.kind in "fiu":
            codes, labels, kind = _bins(col.to_numpy(dtype=float), TREND_BINS), None, "trend"
        else:
            found, kind = _levels(col.to_numpy()), "levels"
            codes, labels = found if found is not None else (None, None)
        if codes is None:
            continue
        _, first, inverse = np.unique(codes, return_index=True, return_inverse=True)
        key = first[inverse].tobytes()  # the partition, whatever its codes
        if key in seen:
            continue
        seen.add(key)
        out.append((c, kind, codes, labels))
    return out


def _orders(post):
    """The row orders checked for serial correlation: ("row order", None) and, when the
    dataset has a time column (a unit of time), the rows sorted by its category columns then
    time, where that differs from the row order."""
    out = [("row order", None)]
    frame = post.dataset.frame
    for c in post.dataset.columns:
        if c.kind != "quantity" or not c.unit or c.name in post.observables or c.name not in frame.columns:
            continue
        if dimension(c.unit) != "time":
            continue
        keys = [frame[c.name].to_numpy(dtype=float)]
        keys += [np.unique(frame[g].to_numpy(dtype=str), return_inverse=True)[1] for g in reversed(post.dataset.groups)
                 if g in frame.columns and frame[g].dtype.kind not in "fiu"]
        order = np.lexsort(keys)
        if (order != np.arange(len(order))).any():
            out.append((f"{c.name} order", order))
        break
    return out


def _indicators(groupings, n):
    """The groupings' bins and levels as one sparse (n, G) 0/1 matrix (G all their groups
    together), the start of each grouping's columns and the rows in each group: ``r @ B`` sums
    the residuals of every group of every grouping at once."""
    sizes = [int(codes.max()) + 1 for _, _, codes, _ in groupings]
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(int)
    cols = np.concatenate([codes + start for (_, _, codes, _), start in zip(groupings, starts)])
    rows = np.tile(np.arange(n), len(groupings))
    B = sparse.csc_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, int(sum(sizes))))
    return B, starts, np.bincount(cols, minlength=B.shape[1]).astype(float)


def _group_stats(r, B, starts, counts):
    """sum over the groups of each grouping of (sum of r in the group)^2 / n_group, for each
    row of ``r`` (k, n): (k, groupings)."""
    sums = np.asarray(r @ B)
    return np.add.reduceat(sums * sums / counts, starts, axis=1)


def _lag1(r, order):
    """Lag-1 autocorrelation sum_i r_i r_(i+1) / sum_i r_i^2 of each row of ``r`` (k, n), the
    columns taken in ``order`` (None: as they are)."""
    if order is not None:
        r = r[:, order]
    with np.errstate(divide="ignore", invalid="ignore"):
        return (r[:, :-1] * r[:, 1:]).sum(axis=1) / (r * r).sum(axis=1)


def check_fit(post, theta, y_rep, *, log_lik=None, reff=1.0, alpha=ALPHA, n_draws=PPC_DRAWS):
    """Posterior-predictive and LOO checks of one fit.

    Parameters
    ----------
    post : Posterior
        Its ``dataset.frame`` gives the columns the residuals are checked against.
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
        ``checks`` (list of {check, statistic, replicated, p, threshold, warn}), ``pareto_k``
        ({count, rows, threshold, warn} or None), ``draws``, ``alpha``, ``m``; ``worst_rows``
        (1-based rows with the largest posterior-mean |r|, with r); ``trend_means`` (per
        trend/levels check, the posterior-mean residual of each bin or level) and
        ``group_labels`` (per levels check, the level names).
    """
    S = len(theta)
    obs = list(post.observables)
    groupings = _groupings(post)
    trends = [(f"{kind}[{o}, {c}]", o, labels) for o in obs for c, kind, _, labels in groupings]
    if groupings:
        B, starts, counts = _indicators(groupings, post.n)
    serial = [(f"serial[{o}, {name}]", o, order) for o in obs for name, order in _orders(post)] if post.n > 2 else []
    names = ["chi_square", "max_residual", "tail_count"] + [t[0] for t in trends] + [s[0] for s in serial]
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
                sigma = post.noise_scale(th, o)  # sqrt(sigma^2 + se_i^2) with known per-row se
                res[o] = ((g(post.y[o]) - mu) / sigma, (g(y_rep[o][sel]) - mu) / sigma)
            r_sum[o] += res[o][0].sum(axis=0)
        for which, out in ((0, t_obs), (1, t_rep)):
            r = np.concatenate([res[o][which] for o in obs], axis=1)
            a = np.abs(r)
            out[0, i:i + step] = (r * r).sum(axis=1)
            out[1, i:i + step] = a.max(axis=1)
            out[2, i:i + step] = (a > TAIL_Z).sum(axis=1)
            for j, o in enumerate(obs if groupings else []):
                rows = slice(3 + j * len(groupings), 3 + (j + 1) * len(groupings))
                out[rows, i:i + step] = _group_stats(res[o][which], B, starts, counts).T
            for j, (_name, o, order) in enumerate(serial):
                out[3 + len(trends) + j, i:i + step] = _lag1(res[o][which], order)
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
    trend_means, labels = {}, {}
    for j, (name, o, names_) in enumerate(trends):
        means = np.asarray(r_sum[o] / k @ B) / counts
        g = j % len(groupings)
        stop = starts[g + 1] if g + 1 < len(starts) else len(counts)
        trend_means[name] = means[starts[g]:stop].round(2).tolist()
        if names_ is not None:
            labels[name] = names_
    return {"checks": checks, "pareto_k": pareto, "draws": int(k), "alpha": alpha, "m": m,
            "worst_rows": worst, "trend_means": trend_means, "group_labels": labels, "covariates": list(post.x),
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
    flat = log_lik.reshape(-1, log_lik.shape[-1])
    flat = flat[np.unique(np.linspace(0, len(flat) - 1, min(LOO_DRAWS, len(flat))).round().astype(int))]
    rows = np.sort(np.argsort(-flat.var(axis=0), kind="stable")[:LOO_ROWS])
    da = xr.DataArray(-flat[:, rows][None], dims=("chain", "draw", "obs_id"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, k = da.azstats.psislw(r_eff=reff, dim=["chain", "draw"])
    k = np.asarray(k)
    bad = np.flatnonzero(k > PARETO_K)
    return {"count": len(bad), "rows": (rows[bad[np.argsort(-k[bad])]][:10] + 1).tolist(),
            "max_k": float(np.max(k)), "threshold": PARETO_K, "rows_checked": len(rows),
            "warn": bool(len(bad) >= max(2, math.ceil(PARETO_SHARE * min(n, LOO_ROWS))))}


def _level_text(means, labels, most=8):
    """'S03 +0.82, S07 -0.61, ...': the levels with the largest |mean residual| first."""
    order = np.argsort(-np.abs(np.asarray(means)), kind="stable")[:most]
    more = f", ... ({len(means)} levels)" if len(means) > most else ""
    return ", ".join(f"{labels[i]} {means[i]:+.2f}" for i in order) + more


def misfit_messages(record):
    """The guard-rail warnings (dicts as :func:`skinfit.inference.guardrails.check_run` gives) of a
    :func:`check_fit` record: one per failed check, each worded as the evidence it is (the
    p-value against its threshold, then what the residuals show)."""
    out = []
    worst = ", ".join(f"{w['row']} ({w['r']:+.1f})" for w in record["worst_rows"][:3])
    inputs = set(record.get("covariates", ()))
    for c in record["checks"]:
        if not c["warn"]:
            continue
        smallest = 1 / (1 + record["draws"])
        p = (f"p <= {c['p']:.2g}, no replicate of {record['draws']} as extreme" if c["p"] <= smallest
             else f"p = {c['p']:.2g}")
        evidence = (f"evidence of misfit (posterior-predictive {p}; threshold {c['threshold']:.2g} = "
                    f"{record['alpha']:g} over {record['m']} checks)")
        name = c["check"]
        column = name[name.find("[") + 1:-1].split(", ", 1)[-1]
        unused = "" if column in inputs else ", a column the model does not use"
        if name == "chi_square":
            what = (f"the residuals scatter more than the fitted noise allows (sum of squared standardised residuals "
                    f"{c['statistic']:.4g}, replicates {c['replicated']:.4g})")
        elif name == "max_residual":
            what = f"a residual too large for the fitted noise (max |r| {c['statistic']:.3g}; rows {worst})"
        elif name == "tail_count":
            what = (f"too many rows in the tails: {c['statistic']:.0f} with |r| > {TAIL_Z:g} where replicates have "
                    f"{c['replicated']:.0f} (outliers? rows {worst})")
        elif name.startswith("levels["):
            means = record["trend_means"].get(name, [])
            what = (f"the residuals differ between the levels of {column}{unused} (mean standardised residual by "
                    f"level: {_level_text(means, record['group_labels'].get(name, []))})")
        elif name.startswith("serial["):
            what = (f"neighbouring rows' residuals are correlated in {column} (lag-1 autocorrelation "
                    f"{c['statistic']:.2f}, replicates {c['replicated']:.2f}): the rows are not independent "
                    f"measurements (a time series fitted as independent rows?) or drift along that order; "
                    f"the posterior is then too narrow; if the rows are samples of a recording, {INGEST_HINT}")
        else:
            means = record["trend_means"].get(name, [])
            what = (f"the residuals drift with {column}{unused} (mean standardised residual by bin, low to high: "
                    f"{', '.join(f'{v:+.2f}' for v in means)})")
        out.append({"check": "misfit", "status": "WARN", "parameter": None, "message": f"{evidence}: {what}"})
    pk = record.get("pareto_k")
    if pk and pk["warn"]:
        out.append({"check": "misfit", "status": "WARN", "parameter": None,
                    "message": f"evidence of influential rows: {pk['count']} rows with PSIS-LOO Pareto k > "
                               f"{PARETO_K} (max {pk['max_k']:.2f}; rows {', '.join(map(str, pk['rows'][:5]))}): "
                               f"each alone moves the posterior (outliers, or a model that misses them); "
                               f"LOO comparisons are unreliable"})
    return out
