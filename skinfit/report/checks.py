"""What the top of a report lists: every failed check of every section, each linked to its section.

A fit's checks are :func:`fit_diagnostics`' (convergence, acceptance, physical support, prior
bounds, the guard rails and misfit checks the fit recorded). The sections across fits have
their own: a population its convergence (the sampler's verdict, R-hat and ESS of its
hyper-parameters) and its warnings; a model comparison the fits it ranks (converged), its LOO
(rows with Pareto k > 0.7, where PSIS-LOO is unreliable; Vehtari, Gelman & Gabry 2017) and its
evidence (finite; an approximation flagged); contrasts the fits they are drawn from
(converged); a design its expected information gains (never negative: an estimate below zero
by more than 2 standard errors, or an upper bound below its lower one, failed) and the warnings
it records. Each of their functions returns ``[(status, text)]`` with status ``FAIL`` or ``WARN``;
:func:`section_issues` gathers them for the top of the page.
"""

import json
import math

import numpy as np
import pandas as pd

from skinfit.inference.guardrails import BOUND_ALPHA, BOUND_SHARE, BOUND_WINDOW, STUCK_ACCEPTANCE
from skinfit.report.tables import cell_text
from skinfit.results.fit import as_fit
from skinfit.results.summary import wall_time_text

__all__ = ["fit_diagnostics", "population_issues", "comparison_issues", "contrast_issues", "design_issues",
           "section_issues", "checked_text", "NOT_CONVERGED_ATTR"]

#: ``DataFrame.attrs`` key of a contrast table: the labels of the fits it is drawn from that did
#: not converge (set by :func:`skinfit.report.groups.group_analyses`).
NOT_CONVERGED_ATTR = "not_converged"
#: PSIS-LOO is unreliable for a row whose Pareto k exceeds this (Vehtari, Gelman & Gabry 2017).
PARETO_K = 0.7
#: An EIG estimate more than this many standard errors below zero failed (an EIG is >= 0).
EIG_SE = 2.0
#: Thresholds of a fit's checks (:func:`fit_diagnostics`).
MIN_ACCEPTANCE_MEAN = 0.1
MAX_OUTSIDE_SUPPORT = 0.05  # share of log-density evaluations
MAX_RHAT = 1.05  # over walkers: a secondary check


def fit_diagnostics(fit, summary=None):
    """Diagnostics of a saved fit as a table and the list of problems to show at the top.

    Returns ``(table, issues)``: ``table`` a DataFrame indexed by check with columns
    ``value, criterion, status`` (status ``ok``, ``info``, ``WARN`` or ``FAIL``); ``issues``
    a list of ``(status, message)`` for every WARN and FAIL.
    """
    fit = as_fit(fit)
    summary = fit.summary() if summary is None else summary
    s = fit.attr("sampler")
    c = fit.attr("support_counts")
    t = fit.attr("timings")
    rows, issues = [], []

    def add(check, value, criterion, status, message=None):
        rows.append((check, value, criterion, status))
        if status in ("WARN", "FAIL"):
            issues.append((status, message or f"{check} = {cell_text(value)} (expected {criterion})"))

    converged = bool(s["converged"])
    add("converged", "yes" if converged else "no", "kept chain >= 50 tau and ESS target met",
        "ok" if converged else "FAIL",
        None if converged else "not converged: " + "; ".join(s.get("reasons", [])))
    add("walkers", int(s["nwalkers"]), "", "info")
    add("steps", int(s["n_steps"]), "", "info")
    add("burn-in steps", int(s["burn"]), "", "info")
    add("thin", int(s["thin"]), "", "info")
    tau_max = max(s["tau"].values()) if s["tau"] else float("nan")
    add("max autocorrelation time tau [steps]", float(tau_max), "", "info")
    kept = (s["n_steps"] - s["burn"]) / tau_max if tau_max > 0 else float("nan")
    # when the run says it did not converge, its reasons (above) already say this
    add("kept steps / max tau", float(kept), ">= 50", "ok" if kept >= 50 else ("WARN" if converged else "info"))
    add("min ESS bulk", float(summary["ess_bulk"].min()), "", "info")
    add("min ESS tail", float(summary["ess_tail"].min()), "", "info")
    rhat = float(summary["r_hat"].max())
    add("max R-hat over walkers", rhat, f"< {MAX_RHAT} (secondary: walkers are not independent chains)",
        "ok" if rhat < MAX_RHAT else "WARN")
    acc = float(s["acceptance_mean"])
    add("acceptance mean", acc, f">= {MIN_ACCEPTANCE_MEAN}", "ok" if acc >= MIN_ACCEPTANCE_MEAN else "WARN",
        None if acc >= MIN_ACCEPTANCE_MEAN else f"low acceptance: mean {acc:.3f} < {MIN_ACCEPTANCE_MEAN}")
    acc_min = float(s["acceptance_min"])
    add("acceptance min (one walker)", acc_min, f">= {STUCK_ACCEPTANCE}",
        "ok" if acc_min >= STUCK_ACCEPTANCE else "WARN",
        None if acc_min >= STUCK_ACCEPTANCE else f"a walker accepted only {acc_min:.3f} of its moves (stuck?)")
    n_eval = max(int(c["evaluations"]), 1)
    add("evaluations", int(c["evaluations"]), "", "info")
    add("evaluations outside the prior bounds", int(c["outside_prior"]), "rejected proposals", "info")
    share = c["outside_support"] / n_eval
    condition = fit.attrs.get("support_condition", "")
    add("evaluations outside the physical support", int(c["outside_support"]),
        f"< {MAX_OUTSIDE_SUPPORT:.0%} of evaluations" + (f" ({condition})" if condition else ""),
        "ok" if share < MAX_OUTSIDE_SUPPORT else "WARN",
        f"{c['outside_support']} of {n_eval} log-density evaluations ({share:.1%}) fell outside the physical "
        f"support ({condition}): the posterior presses against the model's limit")
    # the fit's own guard rails (skinfit.inference.guardrails), as stored in the file; their messages are
    # the issues, the bound row above them only summarises
    bounds = [w.get("parameter") or "" for w in fit.warnings if w.get("check") == "bound"]
    add("posterior mass on a prior bound", "; ".join(bounds) or "none",
        f"no pile-up (> {BOUND_SHARE:.0%} of draws within {BOUND_WINDOW} sd of a bound) that the data push past "
        f"(likelihood-ratio p < {BOUND_ALPHA})", "WARN" if bounds else "ok")
    for w in fit.warnings:  # whatever the fit recorded: guard rails, model-fit (misfit) checks...
        if w.get("check") not in ("convergence", "acceptance"):  # already rows above
            add(f"guard rail: {w.get('check', 'unnamed')}" + (f" ({w['parameter']})" if w.get("parameter") else ""),
                "tripped", "recorded with the fit (Fit.warnings)", w.get("status", "WARN"),
                w.get("message", json.dumps(w, default=str)))
    for n in fit.notes:  # information the guard rails recorded, not failures (--strict ignores them)
        add(f"note: {n.get('check', 'unnamed')}" + (f" ({n['parameter']})" if n.get("parameter") else ""),
            n.get("message", ""), "information, not a failure", "info")
    if "misfit" in fit.attrs:  # skinfit.inference.misfit; its warnings are issues through the rows above
        r = fit.attr("misfit")
        bad = any(c["warn"] for c in r["checks"]) or bool(r.get("pareto_k") and r["pareto_k"]["warn"])
        rows.append(("fit to the data: smallest posterior-predictive p", min(c["p"] for c in r["checks"]),
                     f">= {r['alpha']:g} / {r['m']} checks (skinfit.inference.misfit), {r['draws']} draws",
                     "WARN" if bad else "ok"))
    starts = fit.attr("optimizer").get("starts", [])
    add("MAP log density", float(fit.attrs.get("map_log_density", float("nan"))),
        f"best of {len(starts)} optimiser runs, final status {starts[-1]['status'] if starts else 'n/a'}", "info")
    add("wall time [s]", float(t["total_s"]), wall_time_text(t, fit.pending), "info")
    table = pd.DataFrame(rows, columns=["check", "value", "criterion", "status"]).set_index("check")
    return table, issues


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


def section_issues(across, comparisons, contrasts, designs, given):
    """The failed checks of the sections across fits (the functions above) as issues at
    the top of the page, each linked to its section; then the population drawn on the forest
    plots (``population``) when it did not converge, and the ``notes`` of analyses that could
    not be made (but those a population's warnings already state)."""
    out = []
    for a in across:
        if a["population"]:
            out += [{"status": st, "anchor": f"{a['id']}-population", "where": f"population of {a['model_id']}",
                     "text": text} for st, text in a["population"]["issues"]]
    out += [{"status": st, "anchor": c["id"], "where": f"model comparison: {c['name']}", "text": text}
            for c in comparisons for st, text in c["issues"]]
    out += [{"status": st, "anchor": c["id"], "where": f"contrasts: {c['name']}", "text": text}
            for c in contrasts for st, text in c["issues"]]
    out += [{"status": st, "anchor": f"{d['id']}-checks", "where": f"design: {d['name']}", "text": text}
            for d in designs for st, text in d["issues"]]
    drawn = given["population"]
    if getattr(drawn, "converged", True) is False:
        out += [{"status": st, "anchor": "", "where": "population drawn on the forest plots", "text": text}
                for st, text in population_issues(drawn)]
    stated = {w for a in across if a["population"] for w in a["population"]["warnings"]}
    for where, text in given.get("notes") or ():
        if text not in stated:
            out.append({"status": "WARN", "anchor": "", "where": where, "text": text})
    return out


def checked_text(sections, across, comparisons, contrasts, designs):
    """What the report checked, in words, for a page where every check passed."""
    n = len(sections)
    parts = [f"{'all ' if n > 1 else ''}{n} fit{'s' if n != 1 else ''} (convergence: autocorrelation time, ESS, "
             "R-hat over walkers; acceptance, physical support, prior bounds, fit to the data)"]
    pops = [a["model_id"] for a in across if a["population"]]
    if pops:
        parts.append(f"the population{'s' if len(pops) > 1 else ''} of {', '.join(pops)} (convergence: R-hat and "
                     "ESS of every hyper-parameter)")
    if comparisons:
        parts.append(f"{len(comparisons)} model comparison{'s' if len(comparisons) > 1 else ''} (the fits ranked "
                     "converged, PSIS-LOO's Pareto k, the evidence)")
    if contrasts:
        parts.append(f"{len(contrasts)} contrast table{'s' if len(contrasts) > 1 else ''} (drawn from converged fits)")
    if designs:
        parts.append(f"{len(designs)} design{'s' if len(designs) > 1 else ''} (expected information gains "
                     "non-negative within their error)")
    return "; ".join(parts)
