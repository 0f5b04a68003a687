"""The arguments of :func:`skinfit.analysis.design.design` checked, and its cost estimated, before
any work; the baseline design it is compared with."""

from __future__ import annotations

import math
import time
from collections.abc import Mapping

import numpy as np

from skinfit.analysis.design.problem import n_candidates, take_x
from skinfit.analysis.sbc import design_dataset
from skinfit.errors import InputError
from skinfit.io.data import as_dataset
from skinfit.io.models import Model

__all__ = ["baseline_design", "MIN_DRAWS", "MAX_BYTES", "MAX_SECONDS", "check_counts", "check_params",
           "check_discriminate", "check_noise_scale", "check_cost"]


def baseline_design(model, fit, baseline, n, units):
    """SI covariates of the baseline plan: ``n`` rows evenly spaced over the fit's own dataset,
    the model's shipped dataset, or ``baseline`` (a dataset id / path, a DataFrame)."""
    if baseline is None and fit is not None:
        x, label = fit.posterior.x, f"fit's dataset {fit.dataset_id}"
    else:
        try:
            ds = as_dataset(baseline, model=model) if baseline is not None else design_dataset(model)
        except InputError as exc:
            if baseline is not None or exc.field != "dataset":
                raise
            raise InputError(f"model {model.id}", "no shipped dataset for this model or its variants to take the "
                             "baseline design from: give one with --baseline DATASET (baseline= in Python), a "
                             "dataset id or path, or a DataFrame in Python", field="baseline") from None
        missing = [c.name for c in model.covariates if c.name not in ds.frame.columns and not c.optional]
        if missing:
            raise InputError(ds.path, f"baseline dataset has no covariate {missing[0]!r} of model {model.id!r}")
        x = {c.name: ds.frame[c.name].to_numpy(float) if c.name in ds.frame.columns else
             np.full(len(ds.frame), np.nan) for c in model.covariates}
        label = f"dataset {ds.id}"
    rows = len(next(iter(x.values())))
    idx = np.unique(np.linspace(0, rows - 1, min(n, rows)).round().astype(int))
    return {k: np.asarray(v, float)[idx] for k, v in x.items()}, f"{label}: {len(idx)} of {rows} rows, evenly spaced"


#: fewest outer / inner / batch draws an estimate takes (its standard error needs a sample, its
#: bias estimate halves of the inner draws)
MIN_DRAWS = 20


#: a design refuses, before any work, to need more memory for its largest arrays (bytes) or an
#: estimated longer time (seconds) than this
MAX_BYTES, MAX_SECONDS = 4 * 2**30, 3600.0


_COUNT_NAMES = {"n": "--n", "n_outer": "--outer", "n_inner": "--inner", "n_batch": "n_batch", "n_draws": "n_draws"}


def check_counts(**counts):
    """Each count an integer (not a bool): ``n`` >= 1, draw counts >= MIN_DRAWS, and the
    outer plus inner draws at most ``n_draws`` (they are taken from them without repeats)."""
    for key, value in counts.items():
        low = 1 if key == "n" else 5 * MIN_DRAWS if key == "n_draws" else MIN_DRAWS
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            what = "the number of measurements" if key == "n" else "the number of draws"
            raise InputError(_COUNT_NAMES[key], f"{what} must be an integer >= {low} (got {value!r})")
    if counts["n_outer"] + counts["n_inner"] > counts["n_draws"] or counts["n_batch"] > counts["n_draws"]:
        raise InputError("n_draws", f"{counts['n_draws']} draws cannot give {counts['n_outer']} outer and "
                         f"{counts['n_inner']} inner ones (nor {counts['n_batch']} batch ones): raise n_draws")


def check_params(params, model):
    """Target parameters: None (all), a name or a list of distinct names of ``model``."""
    names = model.parameter_names
    if params is None:
        return None
    params = [params] if isinstance(params, str) else params
    if not isinstance(params, (list, tuple)) or not params or not all(isinstance(p, str) for p in params):
        raise InputError("--params", f"expected parameter names of model {model.id!r} (got {params!r})")
    bad = [p for p in params if p not in names]
    if bad:
        raise InputError("--params", f"unknown parameter {bad[0]!r} of model {model.id!r} "
                         f"(parameters: {', '.join(names)})")
    twice = sorted({p for p in params if params.count(p) > 1})
    if twice:
        raise InputError("--params", f"parameter {twice[0]!r} given twice")
    return list(params)


def check_discriminate(discriminate, model):
    """Competing models: a model id or Model, or a list of them, none of them ``model`` itself."""
    items = [discriminate] if isinstance(discriminate, (str, Model)) else discriminate
    if not isinstance(items, (list, tuple)) or not all(isinstance(m, (str, Model)) for m in items):
        raise InputError("--discriminate", f"expected model ids (got {discriminate!r})")
    ids = [m.id if isinstance(m, Model) else m for m in items]
    if model.id in ids:
        raise InputError("--discriminate", f"{model.id!r} is the model being designed for: name its competitors")
    twice = sorted({m for m in ids if ids.count(m) > 1})
    if twice:
        raise InputError("--discriminate", f"model {twice[0]!r} given twice")
    return list(items)


def check_noise_scale(noise_scale, model):
    """None, a noise sd > 0, or a mapping observable -> sd > 0 over the model's observables."""
    obs = model.observable_names
    given = noise_scale if isinstance(noise_scale, Mapping) else {o: noise_scale for o in obs}
    unknown = [k for k in given if k not in obs]
    if unknown:
        raise InputError("--sigma", f"unknown observable {unknown[0]!r} of model {model.id!r} "
                         f"(observables: {', '.join(obs)})")
    for o, v in given.items():
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or \
                not (math.isfinite(v) and v > 0):
            raise InputError("--sigma", f"noise sd of {o} must be a number > 0 (got {v!r})")


def check_cost(problem, X, x_base, *, n, n_outer, n_inner, n_batch, params, fit, discriminate, rows):
    """Refuse, before the work starts, a design whose largest arrays need more than
    :data:`MAX_BYTES` or whose estimated time exceeds :data:`MAX_SECONDS`, with the estimate and
    what to reduce.  The forward model's cost per (parameter vector x point) is timed here on a
    small block; the other constants are this code's, measured in bench/results/design.md."""
    C, B = n_candidates(X), n + n_candidates(x_base)
    d, r = problem.d, len(problem.sigma)
    N, M = n_outer, n_inner
    subset = params is not None and len(params) < d
    K = 10
    sample = problem.draws[:32]
    Xs = take_x(X, np.arange(min(C, 64)))
    t = time.perf_counter()
    problem.mean(sample, Xs)
    forward = (time.perf_counter() - t) / (len(sample) * n_candidates(Xs))
    likelihood, greedy = 5e-8, 2e-6 * (d / 7) ** 2  # s per cell; s per (step x outer draw x candidate)
    seconds = {
        "support": len(problem.draws) * (C + n_candidates(x_base)) * forward,
        "one measurement": N * M * C * r * likelihood * (2 if subset else 1)
        + (N * M * (C + rows) * forward if subset else 0.0),
        "plan": n * n_batch * C * greedy + 2 * d * n_batch * C * forward
        + (len(discriminate) + 1) ** 2 * n * min(N, 150) * M * C * likelihood,
        "batch": 2 * (N * M * B * r * likelihood + (N * M * (B + rows) * forward if subset else 0.0)
                      if fit is not None else n_batch * n_batch * B * forward * (2 if subset else 1)),
    }
    total = sum(seconds.values())
    memory = 8 * max(N * C * (K * (2 if subset else 1) + 2 * r) + M * C * r, 2 * d * n_batch * C * r * 3,
                     (len(discriminate) + 1) * (N + M) * C * r * 3)
    if memory > MAX_BYTES or total > MAX_SECONDS:
        worst = max(seconds, key=seconds.get)
        raise InputError("design", f"too big: {C:,} candidates, --n {n}, {N} outer x {M} inner draws would need "
                         f"about {memory / 2**30:.1f} GiB and {total / 60:.0f} min (most for {worst}); the limits are "
                         f"{MAX_BYTES / 2**30:.0f} GiB and {MAX_SECONDS / 60:.0f} min: use fewer candidates, a smaller "
                         f"--n or fewer --outer/--inner draws")
    return total
