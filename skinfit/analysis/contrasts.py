"""Contrasts between subjects and conditions: differences, ratios and P(theta_A > theta_B).

Two sources of pairs of draws:

* **levels of a split parameter within one fit** (e.g. ``alpha[0]`` vs ``alpha[200]`` of
  ``fit(..., split={"alpha": "voltage"})``): the draws are paired as sampled (same chain,
  same draw), so the contrast keeps their posterior correlation;
* **separate fits** (one per subject, e.g. from ``skinfit fit --by subject``): the posteriors
  are independent, so each is resampled without replacement (``rng``) to a common length
  and the draws are paired by index.

For each pair: the effect, on the scale that means something for the parameter: the ratio
``A / B`` for a positive parameter (a modulus, a friction coefficient: "A is 1.3 times B"),
else the difference ``A - B``, with its posterior median, sd and highest-density interval at
``prob`` (:data:`skinfit.results.intervals.CI_PROB` by default, as ArviZ's ``hdi`` computes
it); ``P(A > B)`` (the fraction of paired draws with A > B) and the probability of direction
``max(P(A > B), P(A < B))``; and, given a region of practical equivalence ``rope`` (on the
effect's scale: e.g. ``(0.9, 1.1)`` for a ratio), the posterior probability that the effect
lies in it. The difference and ratio columns (``diff_*``, ``ratio_*``) are kept for both.
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
from skinfit.results.intervals import CI_PROB, hdi
from skinfit.results.summary import slot_values

__all__ = ["draws", "contrast", "level_contrasts", "fit_contrasts", "check_rope", "hdi"]


def draws(fit, name):
    """Posterior draws (chain-major, flattened) of one sampled slot, e.g. ``"alpha[25]"``."""
    slots = {s["name"]: s for s in fit.attr("slots")}
    if name not in slots:
        raise InputError(f"fit of {fit.model_id} on {fit.dataset_id}", f"no sampled parameter {name!r} "
                         f"(sampled: {', '.join(slots)})", field="parameter")
    return slot_values(fit.group("posterior"), slots[name])


def contrast(a, b, prob=CI_PROB, rope=None):
    """Contrast of paired draws ``a`` and ``b`` (equal length): a dict of summary numbers.

    Keys: ``effect`` (``"ratio"`` when every draw of A and B is > 0, else ``"difference"``),
    ``estimate``, ``sd``, ``lower``, ``upper`` (median, sd and HDI at ``prob`` of the effect),
    ``p_greater`` = P(A > B), ``prob_direction`` = max(P(A > B), P(A < B)), ``p_rope`` (the
    posterior probability of the effect within ``rope``, a (low, high) pair on the effect's
    scale; NaN without one); and ``diff_mean``, ``diff_lower``, ``diff_upper`` (HDI of A - B),
    ``ratio_median``, ``ratio_lower``, ``ratio_upper`` (HDI of A / B; NaN when B changes sign).
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"expected paired 1-D draws of equal length (got {a.shape} and {b.shape})")
    diff = a - b
    lo, hi = hdi(diff, prob)
    p_greater = float(np.mean(a > b))
    out = {"diff_mean": float(diff.mean()), "diff_lower": float(lo), "diff_upper": float(hi),
           "ratio_median": np.nan, "ratio_lower": np.nan, "ratio_upper": np.nan,
           "p_greater": p_greater}
    ratio = None
    if np.all(b > 0) or np.all(b < 0):
        ratio = a / b
        rlo, rhi = hdi(ratio, prob)
        out.update(ratio_median=float(np.median(ratio)), ratio_lower=float(rlo), ratio_upper=float(rhi))
    positive = ratio is not None and np.all(a > 0) and np.all(b > 0)
    effect = ratio if positive else diff
    elo, ehi = (out["ratio_lower"], out["ratio_upper"]) if positive else (lo, hi)
    p_rope = np.nan
    if rope is not None:
        rlo_, rhi_ = check_rope(rope, "contrast")
        p_rope = float(np.mean((effect >= rlo_) & (effect <= rhi_)))
    return {"effect": "ratio" if positive else "difference", "estimate": float(np.median(effect)),
            "sd": float(np.std(effect)), "lower": float(elo), "upper": float(ehi), "p_greater": p_greater,
            "prob_direction": max(p_greater, float(np.mean(a < b))), "p_rope": p_rope,
            **{k: v for k, v in out.items() if k != "p_greater"}}


def check_rope(rope, where):
    """``rope`` as a (low, high) pair of finite numbers with low < high, else an InputError."""
    try:
        lo, hi = (float(v) for v in rope)
    except (TypeError, ValueError):
        raise InputError(where, f"expected a region of practical equivalence (low, high), e.g. (0.9, 1.1) for a "
                         f"ratio (got {rope!r})", field="rope") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise InputError(where, f"expected finite low < high (got {rope!r})", field="rope")
    return lo, hi


def _table(named, prob, rope=None):
    rows = []
    for (na, a), (nb, b) in itertools.combinations(named.items(), 2):
        rows.append({"A": na, "B": nb, **contrast(a, b, prob, rope)})
    table = pd.DataFrame(rows)
    table.attrs.update(ci_prob=prob, ci_kind="hdi", rope=None if rope is None else list(check_rope(rope, "rope")))
    return table


def _check_parameter(parameter, prob, where):
    check_prob(prob, where)
    if not isinstance(parameter, str):
        raise InputTypeError(where, f"expected the name of a sampled parameter (got {shown(parameter)})",
                             field="parameter")


def level_contrasts(fit: Fit, parameter: str, prob: float = CI_PROB, rope=None) -> pd.DataFrame:
    """All pairwise contrasts between the levels of a split ``parameter`` within one fit.

    Paired draws (same chain and draw).  Returns a table with one row per pair (A, B) (see
    :func:`contrast`; ``rope``: a region of practical equivalence on the effect's scale).
    """
    fit = as_fit(fit, "level_contrasts", "fit")
    _check_parameter(parameter, prob, "level_contrasts")
    slots = [s["name"] for s in fit.attr("slots") if s["base"] == parameter and s["level"] is not None]
    if len(slots) < 2:
        raise InputError(f"fit of {fit.model_id} on {fit.dataset_id}", f"parameter {parameter!r} is not split "
                         "into levels in this fit (fit with --split PARAMETER=COLUMN; Python: "
                         "split={parameter: [column]})", field="parameter")
    return _table({s: draws(fit, s) for s in slots}, prob, rope)


def fit_contrasts(fits: Mapping[str, Fit], parameter: str, rng: int | np.random.Generator | None = None,
                  prob: float = CI_PROB, rope=None) -> pd.DataFrame:
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
    prob : float
        Probability of the highest-density intervals (default 0.94).
    rope : (low, high), optional
        A region of practical equivalence on the effect's scale (a ratio for a positive
        parameter, else a difference): the table's ``p_rope`` is the probability of the effect in it.
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
    return _table({label: rng.permutation(v)[:n] for label, v in values.items()}, prob, rope)
