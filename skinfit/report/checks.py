"""What the top of a report lists besides the fits' own checks: every failed check of the
sections across fits, each linked to its section.

A fit's checks are :func:`skinfit.report.html.fit_diagnostics`'. The sections across fits have
their own: a population its convergence (the sampler's verdict, R-hat and ESS of its
hyper-parameters) and its warnings; a model comparison the fits it ranks (converged), its LOO
(rows with Pareto k > 0.7, where PSIS-LOO is unreliable; Vehtari, Gelman & Gabry 2017) and its
evidence (finite; an approximation flagged); contrasts the fits they are drawn from
(converged); a design its expected information gains (never negative: an estimate below zero
by more than 2 standard errors, or an upper bound below its lower one, failed) and the warnings
it records. Each function returns ``[(status, text)]`` with status ``FAIL`` or ``WARN``.
"""

import math

import numpy as np
import pandas as pd

__all__ = ["population_issues", "comparison_issues", "contrast_issues", "design_issues", "NOT_CONVERGED_ATTR"]

#: ``DataFrame.attrs`` key of a contrast table: the labels of the fits it is drawn from that did
#: not converge (set by :func:`skinfit.report.groups.group_analyses`).
NOT_CONVERGED_ATTR = "not_converged"
#: PSIS-LOO is unreliable for a row whose Pareto k exceeds this (Vehtari, Gelman & Gabry 2017).
PARETO_K = 0.7
#: An EIG estimate more than this many standard errors below zero failed (an EIG is >= 0).
EIG_SE = 2.0


def population_issues(result):
    """A population result's failed checks: FAIL when its sampler did not converge (or a warning
    says so), naming the worst R-hat and ESS and the hyper-parameters behind them; WARN for
    each of its other warnings (subjects whose data barely move the prior, a chain that rarely
    moves, another prior file, a saved result not shown)."""
    sampler = dict(getattr(result, "sampler", {}) or {})
    warnings = [str(w) for w in (getattr(result, "warnings", []) or [])]
    said = [w for w in warnings if "not converged" in w]
    out = []
    if "converged" not in sampler:
        out.append(("WARN", "its convergence is not recorded (a result of an older skinfit): R-hat and ESS of its "
                            "hyper-parameters unchecked"))
    elif not sampler["converged"] or said:
        out.append(("FAIL", "the population did not converge" + _worst(result, sampler)
                    + ": its hyper-parameters and shrunk estimates are not to be trusted"))
    out += [("WARN", w) for w in warnings if w not in said]
    return out


def _worst(result, sampler):
    """``: max R-hat 1.65, min ESS 10; worst: tau of m1 (R-hat 1.65, ESS 10), ...`` from the
    result's per-hyper-parameter diagnostics, else from its sampler record."""
    parts = []
    if "rhat_max" in sampler:
        parts.append(f"max R-hat {float(sampler['rhat_max']):.3f}")
    if "ess_min" in sampler:
        parts.append(f"min ESS {float(sampler['ess_min']):.0f}")
    text = (": " + ", ".join(parts)) if parts else ""
    try:
        table = result.summary()
    except (AttributeError, ValueError, KeyError, TypeError):
        return text
    if not {"parameter", "quantity", "r_hat", "ess_bulk", "ess_tail"} <= set(table.columns):
        return text
    rows = table.dropna(subset=["r_hat"]).copy()
    rows["ess"] = rows[["ess_bulk", "ess_tail"]].min(axis=1)
    worst = rows.sort_values(["r_hat", "ess"], ascending=[False, True]).head(3)
    named = [f"{r.quantity} of {r.parameter} (R-hat {r.r_hat:.3f}, ESS {r.ess:.0f})" for r in worst.itertuples()]
    return text + (f"; worst: {', '.join(named)}" if named else "")


def comparison_issues(table):
    """A comparison table's failed checks (:func:`skinfit.compare`'s columns, where present): a
    ranked fit that did not converge (FAIL), a log evidence that is not a number (FAIL), rows
    whose PSIS-LOO is unreliable (Pareto k > 0.7, WARN), an evidence flagged approximate
    (WARN)."""
    out = []
    names = [str(n) for n in table.index]
    if "converged" in table.columns:
        bad = [n for n, c in zip(names, table["converged"]) if not _true(c)]
        if bad:
            out.append(("FAIL", f"ranks fit(s) that did not converge: {', '.join(bad)}: their log Z and LOO "
                                "are not to be trusted"))
    if "log_z" in table.columns:
        bad = [n for n, z in zip(names, pd.to_numeric(table["log_z"], errors="coerce")) if not math.isfinite(z)]
        if bad:
            out.append(("FAIL", f"no finite log evidence for {', '.join(bad)}"))
    if "pareto_k_gt_0.7" in table.columns:
        bad = [f"{n} ({int(k)} rows)" for n, k in zip(names, pd.to_numeric(table["pareto_k_gt_0.7"], errors="coerce"))
               if math.isfinite(k) and k > 0]
        if bad:
            out.append(("WARN", f"PSIS-LOO unreliable (Pareto k > {PARETO_K}) for {', '.join(bad)}: their "
                                "elpd_loo is not to be trusted (rank them by log Z)"))
    if "approximate" in table.columns:
        methods = table["method"] if "method" in table.columns else [""] * len(names)
        bad = [f"{n} ({m})" if m else n for n, a, m in zip(names, table["approximate"], methods) if _true(a)]
        if bad:
            out.append(("WARN", f"log evidence approximate, its error not quantified, for {', '.join(bad)}"))
    return out


def _true(value):
    """A table cell as a truth value: True, ``yes``, ``True`` (a CSV's text) are true."""
    if isinstance(value, str):
        return value.strip().lower() in ("true", "yes", "1")
    return bool(value) if value is not None and not (isinstance(value, float) and math.isnan(value)) else False


def contrast_issues(table):
    """A contrast table's failed checks: drawn from fits that did not converge (FAIL)."""
    bad = list(table.attrs.get(NOT_CONVERGED_ATTR, []) or [])
    if not bad:
        return []
    return [("FAIL", f"drawn from fit(s) that did not converge: {', '.join(map(str, bad))}: their contrasts are "
                     "not to be trusted")]


def design_issues(result):
    """A design's failed checks: single-candidate EIG estimates that are not a number or lie below
    zero by more than :data:`EIG_SE` standard errors, upper bounds below their estimate by as
    much (FAIL), and each warning the design records (``warnings`` of the result or its
    settings; WARN)."""
    out = []
    table = getattr(result, "table", None)
    if isinstance(table, pd.DataFrame) and "eig" in table.columns:
        eig = pd.to_numeric(table["eig"], errors="coerce").to_numpy(float)
        se = (pd.to_numeric(table["eig_se"], errors="coerce").to_numpy(float) if "eig_se" in table.columns
              else np.zeros_like(eig))
        n = len(eig)
        bad = ~np.isfinite(eig)
        if bad.any():
            out.append(("FAIL", f"the EIG estimate is not a number at {int(bad.sum())} of {n} candidates"))
        neg = np.isfinite(eig) & (eig + EIG_SE * np.nan_to_num(se) < 0)
        if neg.any():
            out.append(("FAIL", f"the EIG estimate is below zero by more than {EIG_SE:g} standard errors at "
                                f"{int(neg.sum())} of {n} candidates (down to {eig[neg].min():.3g} nats): an expected "
                                "information gain is never negative, so the estimate and the plan ranked by it "
                                "are wrong"))
        if "eig_upper" in table.columns:
            up = pd.to_numeric(table["eig_upper"], errors="coerce").to_numpy(float)
            up_se = (pd.to_numeric(table["eig_upper_se"], errors="coerce").to_numpy(float)
                     if "eig_upper_se" in table.columns else np.zeros_like(up))
            below = (np.isfinite(up) & np.isfinite(eig)
                     & (up < eig - EIG_SE * np.hypot(np.nan_to_num(se), np.nan_to_num(up_se))))
            if below.any():
                out.append(("FAIL", f"the EIG's upper bound lies below its estimate by more than {EIG_SE:g} standard "
                                    f"errors at {int(below.sum())} of {n} candidates"))
    settings = getattr(result, "settings", {}) or {}
    recorded = list(getattr(result, "warnings", None) or []) + list(settings.get("warnings", []) or [])
    out += [("WARN", str(w)) for w in dict.fromkeys(map(str, recorded))]
    return out
