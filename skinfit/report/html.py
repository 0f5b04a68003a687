"""``skinfit report``: a self-contained static report of saved fits.

:func:`write_report` writes, into one directory, ``index.html`` (opens from disk: inline CSS,
figures as PNG files beside it, no script, no network URL), ``summary.md`` with the same
tables, and CSV tables: ``<fit>_summary.csv`` (exactly :meth:`Fit.summary`),
``<fit>_diagnostics.csv`` and ``comparison.csv``. Every failed check of every section (fits,
populations, comparisons, contrasts, designs: :mod:`skinfit.report.checks`) is listed at the
top, linked to its section.
Every section names the model card, prior file and dataset (with hashes) and the skinfit
version that produced it. Reads only saved results.

The page's parts come from :mod:`skinfit.report.tables` (cells and Markdown),
:mod:`skinfit.report.checks` (the diagnostics), :mod:`skinfit.report.groups` (the sections
across fits) and :mod:`skinfit.report.figures` (the figures, kept in the folder while unchanged).
"""

import hashlib
import json
import sys
import time
import tomllib
from pathlib import Path

import jinja2
import numpy as np

from skinfit import __version__
from skinfit.analysis.design import load_design
from skinfit.analysis.groups import data_drift
from skinfit.errors import InputError
from skinfit.inference.checkpoint import CheckpointLock
from skinfit.io.labels import derived_units, parameter_units
from skinfit.io.paths import package_version
from skinfit.io.references import cite_long
from skinfit.report.checks import (
    checked_text,
    comparison_issues,
    contrast_issues,
    design_issues,
    fit_diagnostics,
    section_issues,
)
from skinfit.report.design import design_section
from skinfit.report.figures import fit_figure_jobs, render_figures
from skinfit.report.groups import (
    CONTRAST_ROWS,
    across_fits,
    contrast_display,
    contrast_section,
    contrast_sentence,
    group_analyses,
)
from skinfit.report.runs import collect_runs, comparison_tables, saved_populations
from skinfit.report.tables import (
    base_name,
    break_at_underscores,
    cells,
    defang,
    display_units,
    file_part,
    level_names,
    markdown,
    not_applicable,
    ranking_note,
    unique_name,
)
from skinfit.results.fit import as_fit, load_fit
from skinfit.results.intervals import CI_PROB, check_ci, interval_name
from skinfit.results.run_labels import run_labels

__all__ = ["write_report", "cli_report", "claim_report_folder", "REPORT_MARKER"]

#: Subjects (or levels) of a parameter from which its contrasts are also drawn as a matrix
MATRIX_LABELS = 6

#: A file in each report folder: the folder is the report's, to rewrite on the next report into it.
REPORT_MARKER = ".skinfit-report"


def _key(fit, taken, label=None):
    """File-name key of a fit: model and dataset, and the options that tell two runs of them
    apart (``label`` from :func:`skinfit.results.run_labels.run_labels`)."""
    return unique_name(file_part(f"{label or fit.model_id}__{fit.dataset_id}").strip("_."), taken)


def _provenance(fit):
    """What produced a fit's section: its model card, prior file, dataset, versions and seed."""
    attrs = fit.attrs
    card = tomllib.loads(attrs["model_card"])
    versions = json.loads(attrs.get("versions", "{}"))
    dprov = json.loads(attrs.get("dataset_provenance", "{}"))
    created = fit.group("posterior").attrs.get("created_at", "")
    return {"model_id": attrs["model_id"], "model_sha": attrs["model_sha256"], "model_title": card.get("title", ""),
            "model_source": _cited(card.get("source", "")), "priors_id": attrs["priors_id"],
            "priors_sha": attrs["priors_sha256"], "dataset_id": attrs["dataset_id"],
            "dataset_sha": attrs["dataset_sha256"], "dataset_path": attrs.get("dataset_path", ""),
            "dataset_kind": dprov.get("kind", "unknown"), "skinfit": versions.get("skinfit", "unknown"),
            "versions": ", ".join(f"{k} {v}" for k, v in versions.items()),
            "seed": attrs.get("seed", -1), "created": created,
            "setup": json.loads(attrs.get("setup", "{}")),
            "card_text": defang(attrs["model_card"]), "priors_text": defang(attrs["priors_text"])}


def _provenance_line(p):
    """:func:`_provenance` in one sentence."""
    return (f"model card {p['model_id']} (sha256 {p['model_sha'][:12]}), prior file {p['priors_id']} "
            f"(sha256 {p['priors_sha'][:12]}), dataset {p['dataset_id']} (sha256 {p['dataset_sha'][:12]}, "
            f"{p['dataset_kind']}), skinfit {p['skinfit']}, seed {p['seed'] if p['seed'] != -1 else 'none'}")


def _cited(source):
    """A card's source with each reference key spelled out (authors, title, venue, year)."""
    return cite_long(source)


def _as_fits(fits):
    """[(file-name key, Fit)] of the fits given to :func:`write_report`: a dict's keys made safe
    and unique, else each fit's :func:`_key`."""
    if isinstance(fits, dict):
        taken = set()
        return [(unique_name(file_part(str(k)).strip("_.") or "fit", taken), as_fit(v)) for k, v in fits.items()]
    fits = [as_fit(f) for f in ([fits] if not isinstance(fits, (list, tuple)) else fits)]
    taken = set()
    return [(_key(f, taken, label), f) for f, label in zip(fits, run_labels(fits))]


def write_report(fits, out_dir, *, title=None, comparison=None, population=None, populations=None,
                 contrasts=None, designs=(), analyses=None, notes=None, ci_prob=None):
    """Write a self-contained static report of ``fits`` into ``out_dir``.

    Parameters
    ----------
    fits : Fit, or a list of fits (DataTrees or paths accepted), or a dict name -> fit
    out_dir : path
        Created if needed; holds index.html, summary.md, the CSV tables and figures/. A folder
        holding other files than an earlier report's is refused (:class:`InputError`).
    title : str, optional
    comparison : pandas.DataFrame or dict name -> DataFrame, optional
        A model-comparison table (e.g. :func:`skinfit.compare`): shown as a table and a chart,
        written as ``comparison.csv`` (``comparison_<name>.csv`` for several).
    population : mapping parameter -> distribution, optional
        Population distributions drawn on the forest plots (see :func:`skinfit.plots.plot_forest`);
        also keyed by model id first, or a DataFrame indexed by parameter, or a
        :class:`skinfit.analysis.population.population.PopulationResult` (a new subject's predictive draws).
    populations : dict model id -> population result, optional
        Population results (:func:`skinfit.analysis.population.population.population`) of the fits of a model,
        shown with their hyper-parameters and shrunk beside separate estimates
        (:func:`skinfit.report.groups.population_section`); their population medians are
        drawn on the forest plots.
    contrasts : dict title -> DataFrame, optional
        Contrast tables (:mod:`skinfit.analysis.contrasts`), shown with each pair's probability of direction.
    notes : list of (where, text), optional
        Analyses that could not be made (a population, a comparison, contrasts): listed at the
        top of the report with the failed checks.
    analyses : callable, optional
        Called once, without arguments, while the fits' figures are drawn; returns a dict of
        any of ``comparison``, ``population``, ``populations``, ``contrasts`` and ``notes``, used
        as those arguments: a caller's comparisons and populations computed while the figures
        are drawn (``skinfit demo``).
    ci_prob : float, optional
        Probability of every interval of the report's tables, highest-density intervals
        (default :data:`skinfit.results.intervals.CI_PROB`, 94%); named in each table's header
        and recorded at the top of the page.

    Returns
    -------
    pathlib.Path of index.html
    """
    out = Path(out_dir)
    figdir = out / "figures"
    items = _as_fits(fits)
    if not items:
        raise InputError("skinfit report", "no fits given")
    claim_report_folder(out)
    with CheckpointLock(out / "report"):  # two reports into one folder never interleave their files
        for name in _recorded_outputs(out):  # the previous report's tables and pages: none left stale
            (out / name).unlink(missing_ok=True)
        before, start = {p.name for p in out.iterdir()}, time.time_ns()
        index = _write_contents(items, out, figdir, title=title, comparison=comparison, population=population,
                                populations=populations, contrasts=contrasts, designs=designs, analyses=analyses,
                                notes=notes, ci_prob=CI_PROB if ci_prob is None else check_ci(ci_prob, "write_report"))
        _record_outputs(out, before, start)
    return index


def _write_contents(items, out, figdir, *, title, comparison, population, populations, contrasts, designs,
                    analyses=None, notes=None, ci_prob=CI_PROB):
    """The report's files (see :func:`write_report`), in a folder already claimed and locked.
    The fits' figures are drawn while the sections, ``analyses`` and the figures across fits
    are computed (:func:`render_figures`' ``meanwhile``)."""
    figdir.mkdir(parents=True, exist_ok=True)
    issues_all, sections, more, contrast_tables = [], [], [], []
    per_model = {}
    for _, fit in items:
        per_model[fit.model_id] = per_model.get(fit.model_id, 0) + 1
    # two runs of one model on one dataset: named by the options that differ
    labels = dict(zip([k for k, _ in items], run_labels([f for _, f in items])))
    wheres = {key: f"{labels[key]} on {fit.dataset_id}" for key, fit in items}
    fit_jobs = [fit_figure_jobs(fit, n, key, figdir, per_model[fit.model_id], wheres[key], ci_prob)
                for n, (key, fit) in enumerate(items)]
    given = {"comparison": comparison, "population": population, "populations": populations, "contrasts": contrasts,
             "notes": notes}
    across, comparisons = [], []  # the page's sections across fits and of comparisons, made meanwhile
    stems = set()  # the file names of the comparison and contrast tables, one per table

    def meanwhile():  # while the fits' figures are drawn: everything else the page shows
        if analyses is not None:
            found = analyses()
            unknown = set(found) - set(given)
            if unknown:
                raise TypeError(f"write_report: analyses() returned {', '.join(sorted(unknown))}")
            given.update(found)
        for (key, fit), section_jobs in zip(items, fit_jobs):
            summary = fit.summary(ci_prob)
            diag, issues = fit_diagnostics(fit, fit.summary())
            summary.to_csv(out / f"{key}_summary.csv")
            diag.to_csv(out / f"{key}_diagnostics.csv")
            units = parameter_units(fit)
            shown = summary.drop(columns="unit", errors="ignore")
            shown.insert(0, "unit", [units.get(base_name(n), "") for n in shown.index])
            numbers = shown.select_dtypes("number")
            shown = shown[numbers.notna().any(axis=1).to_numpy()]  # a row of n/a only: in the CSV alone
            shown = display_units(shown, fit)
            shown["note"] = shown["note"].str.replace(r"^derived \[.*\]$", "derived", regex=True)  # unit: its column
            derived = np.isin([base_name(n) for n in shown.index], list(derived_units(fit)))  # no MAP, tau, prior
            named = level_names(fit)
            shown.index = [named.get(n, n) for n in shown.index]
            where = wheres[key]
            issues_all.extend({"status": st, "anchor": key, "where": where, "text": msg} for st, msg in issues)
            prov = _provenance(fit)
            sections.append({"key": key, "where": where, "converged": fit.converged, "issues": issues,
                             "prov": prov, "prov_line": _provenance_line(prov),
                             "summary": cells(shown, "parameter",
                                              not_applicable(shown, ["map", "tau", "contraction"], derived)),
                             "diagnostics": cells(diag, "check"), "figures": [job["entry"] for job in section_jobs],
                             "csv": [f"{key}_summary.csv", f"{key}_diagnostics.csv"]})
        across.extend(across_fits(items, figdir, given["population"], given["populations"] or {}, out, more,
                                  ci_prob=ci_prob))
        tables = given["comparison"]
        tables = tables if isinstance(tables, dict) else ({"": tables} if tables is not None else {})
        for name, table in tables.items():
            stem = unique_name("comparison" + (f"_{file_part(name)}" if name else ""), stems)
            table.to_csv(out / f"{stem}.csv")
            path = figdir / f"{stem}.png"
            entry = {"name": name or "models", "table": cells(table, table.index.name or "model"),
                     "csv": f"{stem}.csv", "note": ranking_note(table), "id": f"comparison-{len(comparisons) + 1}",
                     "issues": comparison_issues(table),
                     "figure": {"file": f"figures/{path.name}", "alt": f"model comparison chart ({name or 'models'})"}}
            comparisons.append(entry)
            # drawn from the table alone: kept in the folder while the table is the same
            more.append({"fit": None, "inputs": hashlib.sha256(table.to_csv().encode()).hexdigest(),
                         "func": "plot_comparison", "args": (table,), "path": path, "comparison": entry})
        for name, table in (given["contrasts"] or {}).items():
            stem = unique_name("contrasts_" + file_part(name).strip("_"), stems)
            full = contrast_section(table)
            full.to_csv(out / f"{stem}.csv", index=False)
            top = contrast_display(full.head(CONTRAST_ROWS))
            entry = {"name": name, "csv": f"{stem}.csv", "n": len(full), "shown": len(top), "figures": [],
                     "ci": interval_name(table.attrs.get("ci_prob", ci_prob)), "rope": table.attrs.get("rope"),
                     "sentence": contrast_sentence(full), "id": f"contrasts-{len(contrast_tables) + 1}",
                     "issues": contrast_issues(table), "table": cells(top, "A")}
            contrast_tables.append(entry)
            order = list(dict.fromkeys([*table["A"], *table["B"]]))  # subjects or levels as the table lists them
            for pname, rows in (full.groupby("parameter", sort=False) if "parameter" in full.columns else ()):
                if len(set(rows["A"]) | set(rows["B"])) < MATRIX_LABELS:  # a few pairs: the table says it all
                    continue
                path = figdir / f"{stem}_{file_part(str(pname))}.png"
                entry["figures"].append({"file": f"figures/{path.name}", "alt": f"matrix of the contrasts of {pname}",
                                         "caption": f"{pname}: the effect of each row's subject against each "
                                                    f"column's ({len(rows)} pairs); dots: probability of direction "
                                                    "above 0.95"})
                # drawn from the pairs' rows alone: kept in the folder while they are the same
                more.append({"fit": None, "inputs": hashlib.sha256(rows.to_csv().encode()).hexdigest(),
                             "func": "plot_contrast_matrix", "args": (rows, pname), "kwargs": {"order": order},
                             "path": path, "contrast": entry, "entry": entry["figures"][-1]})
        return more

    for _, fit in items:  # its checks of the fit to the data need the deferred groups, its figures' keys
        if fit.pending:  # the attributes these add; once, before the figure workers start
            fit.complete()
    jobs = [job for section_jobs in fit_jobs for job in section_jobs]
    errors = render_figures([fit for _, fit in items], jobs, figdir, meanwhile=meanwhile)
    for job, error in zip(jobs + more, errors):
        if not error:
            continue
        if "comparison" in job:  # listed at the top, the chart left out (its table stays)
            job["comparison"]["figure"] = None
            issues_all.append({"status": "WARN", "anchor": job["comparison"]["id"], "where": "model comparison",
                               "text": error})
        elif "contrast" in job:  # listed at the top, the figure left out (its table stays)
            job["contrast"]["figures"].remove(job["entry"])
            issues_all.append({"status": "WARN", "anchor": job["contrast"]["id"],
                               "where": f"contrasts: {job['contrast']['name']}", "text": error})
        elif "across" in job:  # listed at the top, the figure left out
            job["across"]["figures"].remove(job["entry"])
            issues_all.append({"status": "WARN", "anchor": job["across"]["id"],
                               "where": f"{job['across']['model_id']} across fits", "text": error})
        else:  # listed at the top and in its section, the figure left out
            section = sections[job["fit"]]
            section["figures"].remove(job["entry"])
            section["issues"].append(("WARN", error))
            issues_all.append({"status": "WARN", "anchor": section["key"], "where": section["where"], "text": error})
    design_sections = []
    if designs:  # skinfit design results (DesignResult): the next experiment's plan, its figure in figures/
        design_sections = [{**design_section(d, figdir), "issues": design_issues(d)} for d in designs]
    issues_all.extend(section_issues(across, comparisons, contrast_tables, design_sections, given))
    issues_all.sort(key=lambda i: i["status"] != "FAIL")  # failures first, then warnings (stable)
    n_fail = sum(i["status"] == "FAIL" for i in issues_all)
    context = {"title": title or "skinfit report", "version": __version__, "sections": sections,
               "ci": interval_name(ci_prob), "ci_prob": ci_prob,
               "issues": issues_all, "n_fail": n_fail, "n_warn": len(issues_all) - n_fail,
               "checked": checked_text(sections, across, comparisons, contrast_tables, design_sections),
               "comparisons": comparisons, "across": across, "contrasts": contrast_tables,
               "designs": design_sections,
               "n_fits": len(sections), "n_converged": sum(s["converged"] for s in sections),
               "matplotlib": package_version("matplotlib"), "arviz": package_version("arviz")}
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(Path(__file__).parent / "templates"),
                             autoescape=True, undefined=jinja2.StrictUndefined, trim_blocks=True,
                             lstrip_blocks=True, keep_trailing_newline=True)
    env.filters["wbr"] = break_at_underscores
    index = out / "index.html"
    index.write_text(env.get_template("report.html.j2").render(**context), encoding="utf-8")
    (out / "summary.md").write_text(_summary_md(context), encoding="utf-8")
    return index


def claim_report_folder(out):
    """Make ``out`` a report folder: a new or empty one, or one a report wrote (it holds
    :data:`REPORT_MARKER`, or the index.html of a report written before the marker). A folder
    of other files is refused before anything is written, so that a careless ``--out .`` never
    overwrites the user's own index.html, summary.md or CSV tables."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(out, "is a file: --out names the folder the report is written into")
    if out.is_dir() and not (out / REPORT_MARKER).exists() and any(out.iterdir()):
        index = out / "index.html"
        try:
            with open(index, "rb") as f:
                ours = b'<meta name="generator" content="skinfit ' in f.read(4096)
        except OSError:
            ours = False
        if not ours:
            raise InputError(out, "holds files a skinfit report did not write: give a new or empty folder, e.g. "
                                  f"{out / 'report'} (nothing was written)")
    out.mkdir(parents=True, exist_ok=True)
    if not (out / REPORT_MARKER).exists():
        _record_outputs(out, None, None)


def _recorded_outputs(out):
    """The files the previous report into ``out`` wrote at its top level (from its marker) and
    still holding what it wrote (their sha256 as recorded): a file the user has put in its place
    since is not the report's to remove."""
    try:
        doc = json.loads((out / REPORT_MARKER).read_text(encoding="utf-8"))
        names, sha256 = doc.get("files", []), doc.get("sha256")
    except (OSError, ValueError, AttributeError):
        return []
    names = [n for n in names if isinstance(n, str) and n == Path(n).name and not n.startswith(".")]
    if not isinstance(sha256, dict):  # a marker of an older skinfit: its names alone
        return names
    return [n for n in names if sha256.get(n) is not None and _sha256_of(out / n) == sha256[n]]


def _sha256_of(path):
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None


def _record_outputs(out, before, start):
    """Write :data:`REPORT_MARKER`: the folder is a report's, and the top-level files this report
    wrote (new since ``before``, or changed since ``start`` ns), which the next report into it
    removes before writing its own: a table of a fit no longer reported never stays beside the
    new page. Figures are kept by :func:`render_figures`: reused by content, removed when the
    new page does not show them."""
    files = []
    if before is not None:
        files = sorted(p.name for p in out.iterdir() if p.is_file() and not p.name.startswith(".")
                       and (p.name not in before or p.stat().st_mtime_ns >= start))
    doc = {"written_by": "skinfit report: the next report into this folder rewrites it", "files": files,
           "sha256": {name: _sha256_of(out / name) for name in files}}
    (out / REPORT_MARKER).write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")


def _unit_suffix(tb):
    """`` [unit]`` after a table's heading, as the page's ``unit_suffix`` macro writes it; empty
    for a table without a unit or of a dimensionless parameter."""
    return f" [{tb['unit']}]" if tb.get("unit") not in (None, "", "1") else ""


def _summary_md(ctx):
    lines = [f"# {ctx['title']}", "",
             f"Written by skinfit {ctx['version']} from {ctx['n_fits']} saved fit(s); "
             f"{ctx['n_converged']} converged. Figures are in `figures/`; tables also as CSV (every digit). "
             f"Every interval is a {ctx['ci']} (highest-density interval); numbers are rounded to the second "
             "significant digit of their posterior sd.", "",
             "## Diagnostics", ""]
    if ctx["issues"]:
        lines += [f"{ctx['n_fail']} failure{'s' if ctx['n_fail'] != 1 else ''} and {ctx['n_warn']} "
                  f"warning{'s' if ctx['n_warn'] != 1 else ''}: read these before the numbers below.", ""]
        lines += [f"- **{i['status']}** {i['where']}: {i['text']}"
                  + (f" ([its section](index.html#{i['anchor']}))" if i["anchor"] else "") for i in ctx["issues"]]
    else:
        lines.append(f"Every check passed: {ctx['checked']}.")
    for c in ctx["comparisons"]:
        lines += ["", f"## Model comparison: {c['name']}", "", markdown(c["table"]), "", f"CSV: `{c['csv']}`"]
        if c["note"]:
            lines += ["", f"**{c['note']}**"]
        if c["figure"]:
            lines += ["", f"![{c['figure']['alt']}]({c['figure']['file']})"]
    for a in ctx["across"]:
        lines += ["", f"## {a['model_id']} across fits: {', '.join(a['fits'])}", ""]
        for tb in a["tables"]:
            lines += ["", f"### {tb['parameter']} per subject{_unit_suffix(tb)}", "", markdown(tb["table"])]
        if a["population"]:
            lines += ["", "### Population", "", markdown(a["population"]["hyper"])]
            if a["population"]["effects"]:
                lines += ["", "#### Conditions as effects", "", markdown(a["population"]["effects"])]
            for tb in a["population"]["subjects"]:
                lines += ["", f"#### {tb['parameter']}{_unit_suffix(tb)}: separate and shrunk", "",
                          markdown(tb["table"])]
        lines += [f"![{f['alt']}]({f['file']})" for f in a["figures"]]
    for c in ctx["contrasts"]:
        lines += ["", f"## Contrasts: {c['name']}", "", c["sentence"], ""]
        lines += [f"![{f['alt']}]({f['file']})" for f in c["figures"]]
        lines += ["", markdown(c["table"]), "", f"CSV: `{c['csv']}` (all {c['n']} comparisons)"]
    for d in ctx["designs"]:
        lines += ["", f"## Design the next experiment: {d['name']}", "", d["sentence"], "",
                  f"![{d['figure']['alt']}]({d['figure']['file']})"]
        for t in d["tables"]:
            lines += ["", f"### {t['title']}", "", markdown(t["table"])]
    for s in ctx["sections"]:
        lines += ["", f"## {s['where']}", "", f"Produced by {s['prov_line']}.", "",
                  f"Model: {s['prov']['model_title']} ({s['prov']['model_source']}).", "",
                  f"### Posterior summary (mean, sd and {ctx['ci']})", "", markdown(s["summary"]), "",
                  "### Diagnostics", "", markdown(s["diagnostics"]), "", "### Figures", ""]
        lines += [f"![{f['alt']}]({f['file']})" for f in s["figures"]]
        lines += ["", "CSV: " + ", ".join(f"`{c}`" for c in s["csv"])]
    return "\n".join(lines) + "\n"


def cli_report(args):
    """``skinfit report RUN... --out DIR``."""
    designs = [load_design(p) for p in args.runs if (Path(p) / "design.json").is_file()]
    runs = collect_runs([p for p in args.runs if not (Path(p) / "design.json").is_file()])
    fits = [load_fit(p) for p in runs]
    for message in data_drift(list(zip(runs, fits))):  # never a stale result unannounced
        print(f"skinfit report: warning: {message}", file=sys.stderr)
    items = _as_fits(fits)

    def analyses():  # while the fits' figures are drawn; the folder claimed before the population's cache is written
        notes = []

        def echo(message):  # on stderr, and at the top of the report
            print(message, file=sys.stderr)
            notes.append(("analyses across fits", message.removeprefix("skinfit report: ")))

        populations, contrasts = group_analyses(dict(items), echo=echo, cache_dir=Path(args.out) / ".cache",
                                                saved=saved_populations(args.runs), ci_prob=getattr(args, "ci", None))
        return {"comparison": comparison_tables(items, echo), "populations": populations, "contrasts": contrasts,
                "notes": notes}

    index = write_report(dict(items), args.out, designs=designs, analyses=analyses, ci_prob=getattr(args, "ci", None))
    if getattr(args, "json", False):
        print(json.dumps({"report": str(index), "fits": [name for name, _ in items]}, indent=2))
        return 0
    print(f"report written: {index}  (open it in a browser; summary.md and CSV tables beside it)")
    return 0
