"""Calibration of a fit's check of its fit to the data (:mod:`skinfit.inference.misfit`) and of its
guard rails: fits of data simulated from a model, clean or with outliers, or fitted by a
competing variant (the rates in bench/results/misfit.md come from :func:`simulated_check`).
"""

import warnings

import numpy as np

from skinfit.analysis.sbc import design_dataset
from skinfit.io.models import load_model
from skinfit.io.priors import load_priors
from skinfit.posterior import Posterior
from skinfit.results.fitting import fit

__all__ = ["simulated_check"]


def _label(w):
    """'bound(tau0)': a warning's or note's check and parameter."""
    return w["check"] + (f"({w['parameter']})" if w.get("parameter") else "")


def simulated_check(model, seed, *, dataset=None, contaminate=None, fit_model=None, **fit_kwargs):
    """One fit of data simulated from ``model`` at the design of its shipped dataset
    (:func:`skinfit.analysis.sbc.design_dataset`), parameters drawn from its prior (inside the physical
    support), noise from its noise model: the check's record and warnings, for calibration.

    ``contaminate`` = (n_rows, low, high): that many rows' observables multiplied by factors
    uniform in [low, high] (outliers); ``fit_model``: fit another model (a competing variant)
    to the data simulated from ``model``.  All draws from ``numpy.random.default_rng(seed)``.
    """
    model = load_model(model)
    rng = np.random.default_rng(seed)
    design = design_dataset(model, dataset)
    post = Posterior(model, load_priors(model.id), design)
    theta = post.prior_draw_in_support(rng)
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
    record = result.attr("misfit")
    found = [w for w in result.warnings if w["check"] == "misfit"]
    return {"model": model.id, "fit_model": (fit_model or model.id), "seed": seed, "rows": post.n,
            "converged": result.converged, "warned": bool(found),
            "failed": "; ".join(c["check"] for c in record["checks"] if c["warn"])
                      + ("; pareto_k" if record["pareto_k"] and record["pareto_k"]["warn"] else ""),
            "min_p": min(c["p"] for c in record["checks"]), "m": record["m"], "draws": record["draws"],
            "pareto_k_gt_0.7": record["pareto_k"]["count"] if record["pareto_k"] else -1,
            # every warning --strict acts on, and the notes it does not (skinfit.inference.guardrails)
            "strict": bool(result.warnings),
            "guard_rails": "; ".join(_label(w) for w in result.warnings if w["check"] != "misfit"),
            "notes": "; ".join(_label(w) for w in result.notes),
            "p_values": {c["check"]: c["p"] for c in record["checks"]}, "covariates": record["covariates"],
            "seconds": result.attr("timings")["total_s"] + result.attr("timings")["pointwise_s"]
                       + result.attr("timings")["misfit_s"],
            "misfit_s": result.attr("timings")["misfit_s"]}
