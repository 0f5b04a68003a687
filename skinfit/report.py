"""``skinfit report``: a self-contained static report of saved fits.

:func:`write_report` writes, into one directory, ``index.html`` (opens from disk: inline CSS,
figures as PNG files beside it, no script, no network URL), ``summary.md`` with the same
tables, and CSV tables: ``<fit>_summary.csv`` (exactly :meth:`Fit.summary`),
``<fit>_diagnostics.csv`` and ``comparison.csv``. Diagnostics failures are listed at the top.
Every section names the model card, prior file and dataset (with hashes) and the skinfit
version that produced it. Reads only saved results.
"""

import json
import math
import re
import sys
from importlib import metadata
from pathlib import Path

import numpy as np
import pandas as pd

from . import plots
from .errors import InputError
from .fit import _wall_time_text
from .guardrails import BOUND_SHARE, BOUND_WINDOW, STUCK_ACCEPTANCE

__all__ = ["write_report", "fit_diagnostics", "cli_report"]

#: Thresholds of the warnings at the top of a report.
MIN_ACCEPTANCE_MEAN = 0.1
MAX_OUTSIDE_SUPPORT = 0.05  # share of log-density evaluations
MAX_RHAT = 1.05  # over walkers: a secondary check

_FIGURES = (
    ("ppc", plots.plot_ppc, "Posterior predictive: the data over the 50% and 90% posterior-predictive "
                            "bands and the posterior median curve, in the units the data came in"),
    ("prior_posterior", plots.plot_prior_posterior, "Prior (line) against posterior (filled) per parameter: "
                                                    "what the data determined"),
    ("pair", plots.plot_pair, "Pairwise posterior draws and marginals (corner plot); MAP in red"),
    ("trace", plots.plot_trace, "Walker traces and rank histograms by walker group"),
)


def _fmt(value):
    """Table cell text: 6 significant digits for floats (enough to check against the CSV)."""
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return "nan" if math.isnan(value) else f"{value:.6g}"
    return "" if value is None else str(value)


def _table(df, index_name):
    """A DataFrame as {columns, rows} of formatted cells, the index as first column."""
    return {"columns": [index_name] + [str(c) for c in df.columns],
            "rows": [[_fmt(i)] + [_fmt(v) for v in row] for i, row in zip(df.index, df.itertuples(index=False))]}


def _markdown(table):
    def esc(text):
        return text.replace("|", "\\|")

    lines = ["| " + " | ".join(esc(c) for c in table["columns"]) + " |",
             "|" + "|".join("---" for _ in table["columns"]) + "|"]
    lines += ["| " + " | ".join(esc(c) for c in row) + " |" for row in table["rows"]]
    return "\n".join(lines)


def _key(fit, taken):
    base = re.sub(r"[^A-Za-z0-9_.-]+", "_", f"{fit.model_id}__{fit.dataset_id}").strip("_.")
    key, k = base, 2
    while key in taken:
        key, k = f"{base}_{k}", k + 1
    taken.add(key)
    return key


def _defang(text):
    """Embedded texts (cards, prior files) keep their words, not clickable network addresses."""
    return re.sub(r"\b(https?|ftp)://", r"\1[:]//", text)


# ---- diagnostics ----------------------------------------------------------------------------
def fit_diagnostics(fit, summary=None):
    """Diagnostics of a saved fit as a table and the list of problems to show at the top.

    Returns ``(table, issues)``: ``table`` a DataFrame indexed by check with columns
    ``value, criterion, status`` (status ``ok``, ``info``, ``WARN`` or ``FAIL``); ``issues``
    a list of ``(status, message)`` for every WARN and FAIL.
    """
    fit = plots._as_fit(fit)
    summary = fit.summary() if summary is None else summary
    s = fit.attr("sampler")
    c = fit.attr("support_counts")
    t = fit.attr("timings")
    rows, issues = [], []

    def add(check, value, criterion, status, message=None):
        rows.append((check, value, criterion, status))
        if status in ("WARN", "FAIL"):
            issues.append((status, message or f"{check} = {_fmt(value)} (expected {criterion})"))

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
    # the fit's own guard rails (skinfit.guardrails), as stored in the file; their messages are
    # the issues, the bound row above them only summarises
    bounds = [w["parameter"] for w in fit.warnings if w["check"] == "bound"]
    add("posterior mass on a prior bound", "; ".join(bounds) or "none",
        f"<= {BOUND_SHARE:.0%} of draws within {BOUND_WINDOW} sd of a bound", "WARN" if bounds else "ok")
    for w in fit.warnings:
        if w["check"] not in ("convergence", "acceptance"):  # already rows above
            add(f"guard rail: {w['check']}" + (f" ({w['parameter']})" if w["parameter"] else ""),
                "tripped", "see skinfit.guardrails", w["status"], w["message"])
    starts = fit.attr("optimizer").get("starts", [])
    add("MAP log density", float(fit.attrs.get("map_log_density", float("nan"))),
        f"best of {len(starts)} optimiser runs, final status {starts[-1]['status'] if starts else 'n/a'}", "info")
    add("wall time [s]", float(t["total_s"]), _wall_time_text(t, fit.pending), "info")
    table = pd.DataFrame(rows, columns=["check", "value", "criterion", "status"]).set_index("check")
    return table, issues


# ---- provenance -----------------------------------------------------------------------------
def _provenance(fit):
    import tomllib

    attrs = fit.attrs
    card = tomllib.loads(attrs["model_card"])
    versions = json.loads(attrs.get("versions", "{}"))
    dprov = json.loads(attrs.get("dataset_provenance", "{}"))
    created = fit.group("posterior").attrs.get("created_at", "")
    return {"model_id": attrs["model_id"], "model_sha": attrs["model_sha256"], "model_title": card.get("title", ""),
            "model_source": card.get("source", ""), "priors_id": attrs["priors_id"],
            "priors_sha": attrs["priors_sha256"], "dataset_id": attrs["dataset_id"],
            "dataset_sha": attrs["dataset_sha256"], "dataset_path": attrs.get("dataset_path", ""),
            "dataset_kind": dprov.get("kind", "unknown"), "skinfit": versions.get("skinfit", "unknown"),
            "versions": ", ".join(f"{k} {v}" for k, v in versions.items()),
            "seed": attrs.get("seed", -1), "created": created,
            "setup": json.loads(attrs.get("setup", "{}")),
            "card_text": _defang(attrs["model_card"]), "priors_text": _defang(attrs["priors_text"])}


def _provenance_line(p):
    return (f"model card {p['model_id']} (sha256 {p['model_sha'][:12]}), prior file {p['priors_id']} "
            f"(sha256 {p['priors_sha'][:12]}), dataset {p['dataset_id']} (sha256 {p['dataset_sha'][:12]}, "
            f"{p['dataset_kind']}), skinfit {p['skinfit']}, seed {p['seed'] if p['seed'] != -1 else 'none'}")


# ---- the report -----------------------------------------------------------------------------
def _as_fits(fits):
    if isinstance(fits, dict):
        items = [(str(k), plots._as_fit(v)) for k, v in fits.items()]
        taken, out = set(), []
        for name, f in items:
            key = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_.") or "fit"
            while key in taken:
                key += "_"
            taken.add(key)
            out.append((key, f))
        return out
    fits = [fits] if not isinstance(fits, (list, tuple)) else list(fits)
    taken = set()
    return [(_key(f, taken), f) for f in map(plots._as_fit, fits)]


def _population_for(population, model_id, parameter):
    if population is None:
        return None
    if isinstance(population, pd.DataFrame):
        return population.loc[parameter].to_dict() if parameter in population.index else None
    if model_id in population and isinstance(population[model_id], dict):
        return population[model_id].get(parameter)
    return population.get(parameter)


def _figure(make, path):
    """Draw one figure into a compact PNG; returns None, or the error text to show at the top.

    Any exception is caught on purpose: one figure must not cost the whole report, and the
    failure is listed among the diagnostics, never hidden.
    """
    try:
        _write_png(make(), path)
    except Exception as exc:  # noqa: BLE001 - reported, not swallowed
        return f"figure {path.name} could not be drawn ({type(exc).__name__}: {exc})"
    return None


def _write_png(fig, path):
    """PNG quantised to 256 colours: a third of the size, no visible change for line art."""
    import io

    from PIL import Image

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=plots._DPI)
    image = Image.open(io.BytesIO(buffer.getvalue())).convert("RGB")
    image.quantize(colors=256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE).save(
        path, format="PNG", optimize=True)


def write_report(fits, out_dir, *, title=None, comparison=None, population=None):
    """Write a self-contained static report of ``fits`` into ``out_dir``.

    Parameters
    ----------
    fits : Fit, or a list of fits (DataTrees or paths accepted), or a dict name -> fit
    out_dir : path
        Created if needed; holds index.html, summary.md, the CSV tables and figures/.
    title : str, optional
    comparison : pandas.DataFrame or dict name -> DataFrame, optional
        A model-comparison table (e.g. :func:`skinfit.compare`): shown as a table and a chart,
        written as ``comparison.csv`` (``comparison_<name>.csv`` for several).
    population : mapping parameter -> distribution, optional
        Population distributions drawn on the forest plots (see :func:`skinfit.plots.plot_forest`);
        also keyed by model id first, or a DataFrame indexed by parameter, or a
        :class:`skinfit.population.PopulationResult` (a new subject's predictive draws).

    Returns
    -------
    pathlib.Path of index.html
    """
    import jinja2

    from . import __version__

    out = Path(out_dir)
    figdir = out / "figures"
    figdir.mkdir(parents=True, exist_ok=True)
    items = _as_fits(fits)
    if not items:
        raise InputError("skinfit report", "no fits given")
    issues_all, sections = [], []
    for key, fit in items:
        fit.complete()  # its predictive checks need the deferred groups; the diagnostics then give their time
        summary = fit.summary()
        diag, issues = fit_diagnostics(fit, summary)
        summary.to_csv(out / f"{key}_summary.csv")
        diag.to_csv(out / f"{key}_diagnostics.csv")
        units = plots.parameter_units(fit)
        shown = summary.copy()
        shown.insert(0, "unit", [units.get(_base(n), "") for n in shown.index])
        where = f"{fit.model_id} on {fit.dataset_id}"
        figures = []
        for name, make, caption in _FIGURES:
            path = figdir / f"{key}_{name}.png"
            error = _figure(lambda make=make: make(fit), path)
            if error:
                issues.append(("WARN", error))
            else:
                figures.append({"file": f"figures/{path.name}", "caption": caption, "alt": f"{caption} ({where})"})
        for pname, dims in _split_parameters(fit).items():
            path = figdir / f"{key}_forest_{pname}.png"
            error = _figure(lambda pname=pname: plots.plot_forest(fit, pname), path)
            if error:
                issues.append(("WARN", error))
            else:
                figures.append({"file": f"figures/{path.name}",
                                "caption": f"{pname} per {dims}: posterior mean and 94% HDI",
                                "alt": f"forest plot of {pname} per {dims} ({where})"})
        issues_all += [{"status": st, "fit": key, "where": where, "text": msg} for st, msg in issues]
        prov = _provenance(fit)
        sections.append({"key": key, "where": where, "converged": fit.converged, "issues": issues,
                         "prov": prov, "prov_line": _provenance_line(prov), "summary": _table(shown, "parameter"),
                         "diagnostics": _table(diag, "check"), "figures": figures,
                         "csv": [f"{key}_summary.csv", f"{key}_diagnostics.csv"]})

    across = _across_fits(items, figdir, population, issues_all)
    comparisons = []
    tables = comparison if isinstance(comparison, dict) else ({"": comparison} if comparison is not None else {})
    for name, table in tables.items():
        stem = "comparison" + (f"_{re.sub(r'[^A-Za-z0-9_.-]+', '_', name)}" if name else "")
        table.to_csv(out / f"{stem}.csv")
        entry = {"name": name or "models", "table": _table(table, table.index.name or "model"),
                 "csv": f"{stem}.csv", "figure": None}
        path = figdir / f"{stem}.png"
        error = _figure(lambda table=table: plots.plot_comparison(table), path)
        if error:
            issues_all.append({"status": "WARN", "fit": "", "where": "model comparison", "text": error})
        else:
            entry["figure"] = {"file": f"figures/{path.name}", "alt": f"model comparison chart ({name or 'models'})"}
        comparisons.append(entry)

    issues_all.sort(key=lambda i: i["status"] != "FAIL")  # failures first, then warnings (stable)
    n_fail = sum(i["status"] == "FAIL" for i in issues_all)
    context = {"title": title or "skinfit report", "version": __version__, "sections": sections,
               "issues": issues_all, "n_fail": n_fail, "n_warn": len(issues_all) - n_fail,
               "comparisons": comparisons, "across": across,
               "n_fits": len(sections), "n_converged": sum(s["converged"] for s in sections),
               "matplotlib": _version("matplotlib"), "arviz": _version("arviz")}
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(Path(__file__).parent / "templates"),
                             autoescape=True, undefined=jinja2.StrictUndefined, trim_blocks=True,
                             lstrip_blocks=True, keep_trailing_newline=True)
    index = out / "index.html"
    index.write_text(env.get_template("report.html.j2").render(**context), encoding="utf-8")
    (out / "summary.md").write_text(_summary_md(context), encoding="utf-8")
    return index


def _version(pkg):
    try:
        return metadata.version(pkg)
    except metadata.PackageNotFoundError:
        return "not installed"


def _base(slot_name):
    return slot_name.split("[", 1)[0]


def _split_parameters(fit):
    """Split parameter -> the name of its grouping dimension."""
    post = fit.group("posterior")
    return {v: ", ".join(d for d in post[v].dims if d not in ("chain", "draw")) for v in post.data_vars
            if set(post[v].dims) - {"chain", "draw"}}


def _across_fits(items, figdir, population, issues):
    """Forest plots of each parameter across the fits of one model (subjects, conditions)."""
    by_model = {}
    for key, fit in items:
        by_model.setdefault(fit.model_id, []).append((key, fit))
    out = []
    for model_id, group in by_model.items():
        if len(group) < 2:
            continue
        figures = []
        for pname in group[0][1].group("posterior").data_vars:
            path = figdir / f"across_{re.sub(r'[^A-Za-z0-9_.-]+', '_', model_id)}_{pname}.png"
            pop = _population_for(population, model_id, pname)
            fits = {k: f for k, f in group}
            error = _figure(lambda pname=pname, pop=pop, fits=fits: plots.plot_forest(fits, pname, population=pop),
                            path)
            if error:
                issues.append({"status": "WARN", "fit": "", "where": f"{model_id} across fits", "text": error})
                continue
            caption = f"{pname} across {len(group)} fits" + (" with the population distribution" if pop is not None
                                                              else "")
            figures.append({"file": f"figures/{path.name}", "caption": caption,
                            "alt": f"forest plot of {pname} across the fits of {model_id}"})
        out.append({"model_id": model_id, "fits": [k for k, _ in group], "figures": figures})
    return out


def _summary_md(ctx):
    lines = [f"# {ctx['title']}", "",
             f"Written by skinfit {ctx['version']} from {ctx['n_fits']} saved fit(s); "
             f"{ctx['n_converged']} converged. Figures are in `figures/`; tables also as CSV.", "",
             "## Diagnostics", ""]
    if ctx["issues"]:
        lines += [f"- **{i['status']}** {i['where']}: {i['text']}" for i in ctx["issues"]]
    else:
        lines.append("All fits passed their diagnostics.")
    for c in ctx["comparisons"]:
        lines += ["", f"## Model comparison: {c['name']}", "", _markdown(c["table"]), "", f"CSV: `{c['csv']}`"]
        if c["figure"]:
            lines += ["", f"![{c['figure']['alt']}]({c['figure']['file']})"]
    for a in ctx["across"]:
        lines += ["", f"## {a['model_id']} across fits: {', '.join(a['fits'])}", ""]
        lines += [f"![{f['alt']}]({f['file']})" for f in a["figures"]]
    for s in ctx["sections"]:
        lines += ["", f"## {s['where']}", "", f"Produced by {s['prov_line']}.", "",
                  f"Model: {s['prov']['model_title']} ({s['prov']['model_source']}).", "",
                  "### Posterior summary (SI units)", "", _markdown(s["summary"]), "",
                  "### Diagnostics", "", _markdown(s["diagnostics"]), "", "### Figures", ""]
        lines += [f"![{f['alt']}]({f['file']})" for f in s["figures"]]
        lines += ["", "CSV: " + ", ".join(f"`{c}`" for c in s["csv"])]
    return "\n".join(lines) + "\n"


# ---- command line ---------------------------------------------------------------------------
def _collect_runs(paths):
    """Run directories or fit.nc files; a directory of per-group runs gives all its fits."""
    out = []
    for p in map(Path, paths):
        if p.is_file() or (p / "fit.nc").exists():
            out.append(p)
        elif p.is_dir():
            found = sorted(p.glob("**/fit.nc"))
            if not found:
                raise InputError(p, "no fit.nc in this directory or below it (run `skinfit fit ... --out` first)")
            out += found
        else:
            raise InputError(p, "no such run directory or fit file")
    return out


def _comparisons(fits):
    """Evidence/LOO tables for fits of different models on the same data, if skinfit.compare exists."""
    try:
        from .compare import compare
    except ImportError as exc:
        if exc.name != "skinfit.compare":  # present but broken: say so, the report goes on
            print(f"skinfit report: no model comparison ({exc})", file=sys.stderr)
        return None
    groups = {}
    for key, f in fits:
        groups.setdefault(f.attrs["dataset_sha256"], []).append((key, f))
    tables = {}
    for group in groups.values():
        if len({f.model_id for _, f in group}) < 2:
            continue
        try:
            tables[group[0][1].dataset_id] = compare([f for _, f in group])
        except (ValueError, RuntimeError) as exc:  # the report still shows every fit
            print(f"skinfit report: comparison on {group[0][1].dataset_id} failed: {exc}", file=sys.stderr)
    if not tables:
        return None
    return next(iter(tables.values())) if len(tables) == 1 else tables


def cli_report(args):
    """``skinfit report RUN... --out DIR``."""
    from .fit import load_fit

    fits = [load_fit(p) for p in _collect_runs(args.runs)]
    items = _as_fits(fits)
    comparison = _comparisons(items)
    index = write_report(dict(items), args.out, comparison=comparison)
    print(f"report written: {index}  (open it in a browser; summary.md and CSV tables beside it)")
    return 0
