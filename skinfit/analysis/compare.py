"""``skinfit.compare``: fits of the same data ranked by evidence, with Bayes factors and LOO."""

from __future__ import annotations

import json
import warnings
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd
import xarray as xr
from arviz_stats import loo as az_loo

from skinfit.analysis.evidence import METHODS, bayes_factor_strength, evidence
from skinfit.errors import InputError
from skinfit.io.arguments import check_seed
from skinfit.results.fit import Fit, as_fits
from skinfit.results.run_labels import run_labels

__all__ = ["compare", "loo", "loo_record"]


def loo(fit):
    """PSIS-LOO of a fit (ArviZ); several observables are summed per data row."""
    tree = fit.idata
    ll = tree["log_likelihood"].to_dataset()
    names = list(ll.data_vars)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if len(names) == 1:
            return az_loo(tree, var_name=names[0])
        total = sum(ll[n] for n in names)
        combined = tree.copy()
        combined["log_likelihood"] = xr.DataTree(xr.Dataset({"total": total}))
        return az_loo(combined, var_name="total")


def loo_record(fit: Fit) -> dict:
    """PSIS-LOO of a fit as ``{elpd, se, p, pareto_k_gt_0.7, rows}``, computed once and cached
    in ``fit.attrs["loo"]`` (save the fit to keep it), as :func:`skinfit.analysis.evidence.evidence`
    caches log Z: the pointwise log-likelihood it is computed from is a function of the saved
    draws and seed, so the cached numbers are those a recomputation gives."""
    cached = fit.attrs.get("loo")
    if cached:
        return json.loads(cached)
    lo = loo(fit)
    k = np.asarray(lo.pareto_k).ravel()
    record = {"elpd": float(lo.elpd), "se": float(lo.se), "p": float(lo.p),
              "pareto_k_gt_0.7": int((k > 0.7).sum()), "rows": int(k.size)}
    fit.attrs["loo"] = json.dumps(record)
    return record


def compare(fits: Sequence[Fit] | Mapping[str, Fit], *, method: str = "bridge",
            rng: int | np.random.Generator | None = None) -> pd.DataFrame:
    """One table ranked by log evidence: log Z +- se, log Bayes factor against the best with its
    error and strength in words (Kass & Raftery 1995), and PSIS-LOO elpd +- se with the number of
    Pareto k > 0.7.  Refuses fits made on different data.  A row per fit, named by the mapping's
    keys, else by :func:`skinfit.results.run_labels.run_labels` (model id; two fits of one model told
    apart by their options, file or content).

    An approximate estimate's caveat (Laplace: the prior bounds that cut its Gaussian, the
    bracket on log Z from the posterior draws) is in ``table.attrs["caveats"]``, model -> text.
    """
    labels = [str(k) for k in fits] if isinstance(fits, Mapping) else None
    fits = as_fits(fits, "compare")
    if len(fits) < 2:
        raise InputError("compare", "need at least two fits to compare")
    if method not in METHODS:
        raise InputError("compare", f"unknown evidence method {method!r} (expected one of {', '.join(METHODS)})",
                         field="method")
    check_seed(rng, "compare")
    hashes = {f.attrs["dataset_sha256"] for f in fits}
    if len(hashes) > 1:
        described = ", ".join(f"{f.model_id} on {f.dataset_id} ({f.attrs['dataset_sha256'][:12]})" for f in fits)
        raise InputError("compare", f"fits were made on different data and cannot be compared: {described}")
    rows, caveats = [], {}
    if labels is None or len(set(labels)) < len(labels):
        labels = run_labels(fits)  # two runs of one model: labelled by their options, file or content
    for f, label in zip(fits, labels):
        ev = evidence(f, method=method, rng=rng)
        if ev.caveat:
            caveats[label] = ev.caveat
        lo = loo_record(f)
        rows.append({"model": label, "log_z": ev.log_z, "log_z_se": ev.se, "method": ev.method,
                     "approximate": ev.approximate, "elpd_loo": lo["elpd"], "elpd_loo_se": lo["se"],
                     "p_loo": lo["p"], "pareto_k_gt_0.7": lo["pareto_k_gt_0.7"],
                     "converged": f.converged})
    table = pd.DataFrame(rows).sort_values("log_z", ascending=False).reset_index(drop=True)
    best = table.iloc[0]
    table["log_bf_vs_best"] = table["log_z"] - best["log_z"]
    table["log_bf_se"] = np.sqrt(table["log_z_se"] ** 2 + best["log_z_se"] ** 2)
    table.loc[0, "log_bf_se"] = 0.0
    table["strength"] = ["best" if i == 0 else f"{bayes_factor_strength(-lbf)} for {best['model']}"
                         for i, lbf in enumerate(table["log_bf_vs_best"])]
    table.index = table.pop("model")
    table = table[["log_z", "log_z_se", "log_bf_vs_best", "log_bf_se", "strength", "elpd_loo", "elpd_loo_se",
                   "p_loo", "pareto_k_gt_0.7", "method", "approximate", "converged"]]
    table.attrs["caveats"] = {label: caveats[label] for label in table.index if label in caveats}
    return table
