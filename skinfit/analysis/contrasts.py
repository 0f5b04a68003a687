"""Contrasts between subjects and conditions: differences, ratios and P(theta_A > theta_B).

Two sources of pairs of draws:

* **levels of a split parameter within one fit** (e.g. ``alpha[0]`` vs ``alpha[200]`` of
  ``fit(..., split={"alpha": "voltage"})``): the draws are paired as sampled (same chain,
  same draw), so the contrast keeps their posterior correlation;
* **separate fits** (one per subject, e.g. from ``skinfit fit --by subject``): the posteriors
  are independent, so each is resampled without replacement (``rng``) to a common length
  and the draws are paired by index.

For each pair: the posterior of ``A - B`` and of ``A / B`` (mean and highest-density interval,
computed as ArviZ's ``hdi`` computes it by default), and ``P(A > B)`` (the fraction of paired
draws with A > B).
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Mapping

import numpy as np
import pandas as pd

from skinfit.analysis.groups import load_groups
from skinfit.analysis.population.checks import check_prob, check_subjects
from skinfit.analysis.population.inputs import subject_digest
from skinfit.errors import InputError, InputTypeError
from skinfit.io.arguments import as_generator, shown
from skinfit.results.fit import Fit, as_fit
from skinfit.results.summary import slot_values

__all__ = ["draws", "contrast", "level_contrasts", "fit_contrasts"]


def draws(fit, name):
    """Posterior draws (chain-major, flattened) of one sampled slot, e.g. ``"alpha[25]"``."""
    slots = {s["name"]: s for s in fit.attr("slots")}
    if name not in slots:
        raise InputError(f"fit of {fit.model_id} on {fit.dataset_id}", f"no sampled parameter {name!r} "
                         f"(sampled: {', '.join(slots)})", field="parameter")
    return slot_values(fit.group("posterior"), slots[name])


def hdi(x, prob):
    """Highest-density interval of 1-D draws ``x``: the narrowest interval between two sorted
    draws holding ``floor(prob * n)`` steps of them, ``(lower, upper)``, as
    ``arviz_stats.hdi(x, prob)`` ("nearest" method) gives it (tests/test_contrasts.py checks
    that)."""
    x = np.sort(np.asarray(x, dtype=float).ravel())
    if not 0 < prob <= 1 or len(x) == 0:
        raise ValueError(f"expected draws and 0 < prob <= 1 (got {len(x)} draws, prob {prob})")
    steps = min(int(np.floor(prob * len(x))), len(x) - 1)
    lo = int(np.argmin(x[steps:] - x[:len(x) - steps]))
    return float(x[lo]), float(x[lo + steps])


def contrast(a, b, prob=0.95):
    """Contrast of paired draws ``a`` and ``b`` (equal length): a dict of summary numbers.

    Keys: ``diff_mean``, ``diff_lower``, ``diff_upper`` (HDI of A - B at ``prob``),
    ``ratio_median``, ``ratio_lower``, ``ratio_upper`` (HDI of A / B; NaN when B changes
    sign), ``p_greater`` = P(A > B).
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"expected paired 1-D draws of equal length (got {a.shape} and {b.shape})")
    diff = a - b
    lo, hi = hdi(diff, prob)
    out = {"diff_mean": float(diff.mean()), "diff_lower": float(lo), "diff_upper": float(hi),
           "ratio_median": np.nan, "ratio_lower": np.nan, "ratio_upper": np.nan,
           "p_greater": float(np.mean(a > b))}
    if np.all(b > 0) or np.all(b < 0):
        ratio = a / b
        rlo, rhi = hdi(ratio, prob)
        out.update(ratio_median=float(np.median(ratio)), ratio_lower=float(rlo), ratio_upper=float(rhi))
    return out


def _table(named, prob):
    rows = []
    for (na, a), (nb, b) in itertools.combinations(named.items(), 2):
        rows.append({"A": na, "B": nb, **contrast(a, b, prob)})
    return pd.DataFrame(rows)


def _check_parameter(parameter, prob, where):
    check_prob(prob, where)
    if not isinstance(parameter, str):
        raise InputTypeError(where, f"expected the name of a sampled parameter (got {shown(parameter)})",
                             field="parameter")


def level_contrasts(fit: Fit, parameter: str, prob: float = 0.95) -> pd.DataFrame:
    """All pairwise contrasts between the levels of a split ``parameter`` within one fit.

    Paired draws (same chain and draw).  Returns a table with one row per pair (A, B).
    """
    fit = as_fit(fit, "level_contrasts", "fit")
    _check_parameter(parameter, prob, "level_contrasts")
    slots = [s["name"] for s in fit.attr("slots") if s["base"] == parameter and s["level"] is not None]
    if len(slots) < 2:
        raise InputError(f"fit of {fit.model_id} on {fit.dataset_id}", f"parameter {parameter!r} is not split "
                         "into levels in this fit (fit with --split PARAMETER=COLUMN; Python: "
                         "split={parameter: [column]})", field="parameter")
    return _table({s: draws(fit, s) for s in slots}, prob)


def fit_contrasts(fits: Mapping[str, Fit], parameter: str, rng: int | np.random.Generator | None = None,
                  prob: float = 0.95) -> pd.DataFrame:
    """All pairwise contrasts of ``parameter`` between separate fits (independent posteriors).

    Parameters
    ----------
    fits : mapping label -> Fit, or the folder of a ``fit --by`` run (:func:`skinfit.load_groups`)
        Distinct subjects of the data as they are now: the same fit under two labels, or fits
        of a data file edited since, are an InputError.
    parameter : str
        A sampled slot name present in every fit.
    rng : int, None or numpy.random.Generator
        Used to resample every posterior to the shortest length before pairing by index.
    """
    if rng is not None and (not isinstance(rng, (int, np.integer, np.random.Generator)) or isinstance(rng, bool) or (
            isinstance(rng, (int, np.integer)) and rng < 0)):
        raise InputError("fit_contrasts", f"expected a seed >= 0, None or a numpy Generator (got {rng!r})",
                         field="rng")
    rng = as_generator(rng)
    _check_parameter(parameter, prob, "fit_contrasts")
    if isinstance(fits, (str, os.PathLike)):
        fits = load_groups(fits)
    if not isinstance(fits, Mapping):
        raise InputTypeError("fit_contrasts", f"expected a mapping label -> Fit or a `fit --by` run folder (got "
                             f"{type(fits).__name__})", field="fits")
    fits = {label: f if callable(getattr(f, "attr", None)) and callable(getattr(f, "group", None))  # a Fit or
            else as_fit(f, "fit_contrasts", f"fits[{label!r}]") for label, f in fits.items()}  # population.DrawsFit
    if len(fits) < 2:
        raise InputError("fit_contrasts", f"expected at least two fits (got {len(fits)})", field="fits")
    # the same subject twice, or fits of a data file edited since: refused, as for a population
    check_subjects(fits, {label: subject_digest(f) for label, f in fits.items()})
    values = {label: draws(f, parameter) for label, f in fits.items()}
    n = min(len(v) for v in values.values())
    return _table({label: rng.permutation(v)[:n] for label, v in values.items()}, prob)
