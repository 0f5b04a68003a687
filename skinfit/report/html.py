"""``skinfit report``: a self-contained static report of saved fits.

:func:`write_report` writes, into one directory, ``index.html`` (opens from disk: inline CSS,
figures as PNG files beside it, no script, no network URL), ``summary.md`` with the same
tables, and CSV tables: ``<fit>_summary.csv`` (exactly :meth:`Fit.summary`),
``<fit>_diagnostics.csv`` and ``comparison.csv``. Every failed check of every section (fits,
populations, comparisons, contrasts, designs: :mod:`skinfit.report.checks`) is listed at the
top, linked to its section.
Every section names the model card, prior file and dataset (with hashes) and the skinfit
version that produced it. Reads only saved results.
"""

import contextlib
import gc
import hashlib
import json
import math
import re
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from skinfit.errors import InputError
from skinfit.results.fit import as_fit
from skinfit.results.summary import wall_time_text
from skinfit.io.labels import derived_units, parameter_units
from skinfit.io.paths import package_version
from skinfit.inference.guardrails import BOUND_ALPHA, BOUND_SHARE, BOUND_WINDOW, STUCK_ACCEPTANCE
from skinfit.report.checks import comparison_issues, contrast_issues, design_issues, population_issues

__all__ = ["write_report", "fit_diagnostics", "cli_report", "claim_report_folder"]


def _lazy_module(name):
    """Module ``name``, executed on first attribute access (importlib's LazyLoader): the
    plotting module and matplotlib (~0.6 s) are imported only when a figure is drawn."""
    import importlib.util

    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    spec.loader = importlib.util.LazyLoader(spec.loader)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


plots = _lazy_module("skinfit.plots.figures")

#: Thresholds of the warnings at the top of a report.
MIN_ACCEPTANCE_MEAN = 0.1
MAX_OUTSIDE_SUPPORT = 0.05  # share of log-density evaluations
MAX_RHAT = 1.05  # over walkers: a secondary check

_FIGURES = (  # (file name, skinfit.plots.figures function, caption)
    ("ppc", "plot_ppc", "Posterior predictive: the data over the 50% and 90% posterior-predictive "
                        "bands and the posterior median curve, in the units the data came in"),
    ("prior_posterior", "plot_prior_posterior", "Prior (line) against posterior (filled) per parameter: "
                                                "what the data determined"),
    ("pair", "plot_pair", "Pairwise posterior draws and marginals (corner plot); MAP in red"),
    ("trace", "plot_trace", "Walker traces and rank histograms by walker group"),
)


def file_part(text):
    """``text`` with every run of characters other than letters, digits, ``_``, ``.`` and ``-``
    replaced by ``_``: safe inside a file name on every platform."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text)


def _fmt(value, na=False):
    """Table cell text: 6 significant digits for floats (enough to check against the CSV); a NaN
    is ``n/a`` in a cell that has no value by construction (``na``), else ``nan``."""
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return ("n/a" if na else "nan") if math.isnan(value) else f"{value:.6g}"
    return "" if value is None else str(value)


def _table(df, index_name, na=None):
    """A DataFrame as {columns, rows, text} of formatted cells, the index as first column;
    ``text[k]`` is True for a column of words (left-aligned and wrapped in the page). ``na``:
    a boolean array (rows, columns) of the cells that have no value by construction (see
    :func:`_not_applicable`), shown as ``n/a`` rather than ``nan`` (a number not computed)."""
    na = np.zeros(df.shape, dtype=bool) if na is None else np.asarray(na, dtype=bool)
    return {"columns": [index_name] + [str(c) for c in df.columns],
            "rows": [[_fmt(i)] + [_fmt(v, a) for v, a in zip(row, flags)]
                     for i, row, flags in zip(df.index, df.itertuples(index=False), na)],
            "text": [True] + [not (pd.api.types.is_numeric_dtype(df[c]) and not pd.api.types.is_bool_dtype(df[c]))
                              for c in df.columns]}


def _not_applicable(df, columns, rows=None):
    """(rows, columns) mask of ``df``: True in ``columns`` on the rows where ``rows`` (a boolean
    array; every row when None) holds, the cells that have no value by construction: a derived
    quantity's MAP, tau and contraction (it has no prior), a population's derived rows' R-hat
    and ESS (those of ``mu`` and ``tau``, from which they are computed, are on their own rows),
    a contrast's ratio A / B where B's draws change sign."""
    rows = np.ones(len(df), dtype=bool) if rows is None else np.asarray(rows, dtype=bool)
    return rows[:, None] & np.isin(np.asarray(df.columns, dtype=object), columns)[None, :]


def level_names(fit):
    """Summary row name -> the same name with its condition spelled out, for every parameter or
    derived quantity indexed by a condition: ``gamma[0.5]`` -> ``gamma[actuation_force=0.5 N]``,
    ``beta_h[M10]`` -> ``beta_h[material=M10]`` (levels in the units the data came in)."""
    units = fit.attr("units")
    out = {}
    for group in ("posterior", "derived"):
        try:
            ds = fit.group(group)
        except (KeyError, ValueError):
            continue
        for var in ds.data_vars:
            dims = [d for d in ds[var].dims if d not in ("chain", "draw")]
            if len(dims) != 1:
                continue
            cols = dims[0].split(",")
            for level in ds[dims[0]].values:
                parts = str(level).split(",")
                if len(parts) != len(cols):
                    continue
                named = ", ".join(f"{c}={v}" + (f" {units[c]}" if units.get(c) not in (None, "1", "-") else "")
                                  for c, v in zip(cols, parts))
                out[f"{var}[{level}]"] = f"{var}[{named}]"
    return out


def _markdown(table):
    def esc(text):
        return text.replace("|", "\\|")

    lines = ["| " + " | ".join(esc(c) for c in table["columns"]) + " |",
             "|" + "|".join("---" for _ in table["columns"]) + "|"]
    lines += ["| " + " | ".join(esc(c) for c in row) + " |" for row in table["rows"]]
    return "\n".join(lines)


def _key(fit, taken, label=None):
    """File-name key of a fit: model and dataset, and the options that tell two runs of them
    apart (``label`` from :func:`skinfit.results.run_labels.run_labels`)."""
    return _unique(file_part(f"{label or fit.model_id}__{fit.dataset_id}").strip("_."), taken)


def _unique(base, taken):
    """``base``, or ``base_2``, ``base_3``... the first not in ``taken`` (which it joins): one
    file name per fit or table of a report, also for names that differ only in characters
    :func:`file_part` replaces (``d[subject=Zoë]``, ``d[subject=Zoé]``; model ids ``a+b``, ``a_b``)."""
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
    fit = as_fit(fit)
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


# ---- provenance -----------------------------------------------------------------------------
def _provenance(fit):
    import tomllib

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
            "card_text": _defang(attrs["model_card"]), "priors_text": _defang(attrs["priors_text"])}


def _provenance_line(p):
    return (f"model card {p['model_id']} (sha256 {p['model_sha'][:12]}), prior file {p['priors_id']} "
            f"(sha256 {p['priors_sha'][:12]}), dataset {p['dataset_id']} (sha256 {p['dataset_sha'][:12]}, "
            f"{p['dataset_kind']}), skinfit {p['skinfit']}, seed {p['seed'] if p['seed'] != -1 else 'none'}")


# ---- the report -----------------------------------------------------------------------------
def _as_fits(fits):
    if isinstance(fits, dict):
        taken = set()
        return [(_unique(file_part(str(k)).strip("_.") or "fit", taken), as_fit(v)) for k, v in fits.items()]
    from skinfit.results.run_labels import run_labels

    fits = [as_fit(f) for f in ([fits] if not isinstance(fits, (list, tuple)) else fits)]
    taken = set()
    return [(_key(f, taken, label), f) for f, label in zip(fits, run_labels(fits))]


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


#: From this many fits of one model on, each fit's section draws only its predictive check.
MANY_FITS = 4
#: Processes that draw a report's figures (at most; one per core).
MAX_FIGURE_WORKERS = 4
#: Rough relative cost of each figure kind (the demo's: predictive check 0.84 s, trace 0.49, corner
#: plot 0.32, prior against posterior 0.21, forest 0.06): the costliest are started first, so that
#: the workers finish together.
_COST = {"plot_ppc": 4, "plot_trace": 3, "plot_pair": 2, "plot_prior_posterior": 1.5, "plot_forest": 1}
_FITS, _JOBS = [], []  # the fits and figure jobs being drawn, inherited by forked worker processes
_STORED = {}  # job index -> its digest in the figure store (:mod:`skinfit.report.figure_store`), inherited too


def _code_key(func):
    """What draws a figure: the package source and plotting libraries' versions
    (:func:`skinfit.report.figure_store.code_hash`) and, when ``skinfit.plots.<func>`` is not skinfit's
    own function (a test's or a user's replacement), that function's code: a replaced plot
    draws again. Does not import skinfit.plots.figures (nothing is replaced in a module not loaded)."""
    import types

    from skinfit.report.figure_store import code_hash

    def text(code):  # its bytecode, names and constants, nested functions included
        consts = [text(c) if hasattr(c, "co_code") else repr(c) for c in code.co_consts]
        return repr((code.co_code, code.co_names, code.co_varnames, consts))

    own = ""
    module = sys.modules.get("skinfit.plots.figures")
    if type(module) is types.ModuleType:  # loaded (the lazy module is a subclass until then)
        f = getattr(module, func)
        if getattr(f, "__module__", None) != "skinfit.plots.figures" or getattr(f, "__qualname__", None) != func:
            own = "." + hashlib.sha256((text(f.__code__) if hasattr(f, "__code__") else repr(f)).encode()
                                       ).hexdigest()[:16]
    return f"{code_hash()[:16]}{own}"


def _job_args(job):
    """The positional arguments of a job's plot function: one fit, or {label: fit} across fits,
    before the job's ``args`` (none for a figure drawn from its ``args`` alone)."""
    if job["fit"] is None:
        return tuple(job["args"])
    if isinstance(job["fit"], dict):
        return {label: _FITS[i] for label, i in job["fit"].items()}, *job["args"]
    return _FITS[job["fit"]], *job["args"]


def _render_one(i):
    """Draw figure job ``i`` of :data:`_JOBS` into its PNG and PDF, and keep it in the figure
    store when :data:`_STORED` has its digest (top level: runs in a forked worker, which
    inherits the fits and jobs, so nothing is pickled but the index)."""
    job = _JOBS[i]
    if not gc.isenabled():  # a figure worker (_init_worker): the last figure's garbage, collected once
        gc.collect(1)  # (before the next figure, not after: a worker's last figure is not worth it)
    error = _figure(lambda: getattr(plots, job["func"])(*_job_args(job), **job.get("kwargs", {})), job["path"])
    if error is None and i in _STORED:
        from skinfit.report import figure_store

        figure_store.put(_STORED[i], job["path"])
    return error


@contextlib.contextmanager
def _frozen_heap():
    """While figure workers are forked and drawing: the objects this process holds (fits,
    modules) moved out of the garbage collector's view (``gc.freeze``), so that the workers'
    collections do not walk them again and again, copying the pages they touch (measured in
    bench/results/report.md). Put back afterwards, unless the caller had frozen objects itself
    (then its own choice is kept)."""
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def _init_worker(parent):
    """A figure worker ends when the report process that forked it dies (even by SIGKILL). Its
    garbage collector runs once per figure (:func:`_render_one`) instead of on every few
    thousand objects made, which a figure's artists triggered ~60 times each (2.5% of the
    figures' time, bench/results/report_commands.md). Its heap keeps the memory figures free
    (:func:`_keep_freed_memory`)."""
    from skinfit.inference.checkpoint import watch_parent  # not campaign's: that imports the fitting machinery

    watch_parent(parent)
    gc.disable()
    _keep_freed_memory()


#: glibc's ``mallopt`` parameters (malloc.h) and the values a figure worker sets: blocks up to
#: 256 MiB from the heap, not mapped for each; the heap's free top returned to the system only
#: beyond 512 MiB.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_WORKER_MALLOC = ((_M_MMAP_THRESHOLD, 256 << 20), (_M_TRIM_THRESHOLD, 512 << 20))


def _keep_freed_memory():
    """In a figure worker (a process that ends with the report) on glibc: large blocks (a
    figure's ~7 MB bitmaps and their copies) come from the heap and what is freed stays in it
    for the next figure, instead of being returned to the system and each of its pages faulted
    in and zeroed again (~21 000 page faults a 21-panel check; bench/results/report_commands.md).
    Returns whether it was set; elsewhere (no ``mallopt``) nothing changes."""
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (AttributeError, OSError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return all(mallopt(param, value) == 1 for param, value in _WORKER_MALLOC)


def render_figures(fits, jobs, figdir, workers=None, meanwhile=None):
    """Draw figure ``jobs`` ({fit: index into fits, or {label: index} for a figure across fits,
    or None for one drawn from its args alone, whose content ``inputs`` then names (a sha256);
    func: plots function name; args; optional kwargs; path}), each once per input: a figure
    whose fits' content (:meth:`~skinfit.results.fit.Fit.content_hash`), function, arguments and plotting code are those
    recorded in ``figdir/.figures.json`` beside an existing PNG and PDF is kept. The rest are
    drawn in up to :data:`MAX_FIGURE_WORKERS` forked processes (in this one where fork is
    unavailable or other threads run here, :func:`skinfit.inference.workers.forkable`; at most
    ``workers``), costliest first, unless :mod:`skinfit.report.figure_store` holds them from an
    earlier drawing of the same content. ``meanwhile``, when given, is called once while the
    workers draw and returns more jobs (drawn from what it computed, in this process, after it
    returns). figures/ is left holding only these jobs' figures.
    Returns one error text or None per job, ``jobs`` then meanwhile's."""
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor

    from skinfit.report import figure_store
    from skinfit.inference.workers import forkable

    global _FITS, _JOBS, _STORED
    manifest = _manifest(figdir)
    every, keys, hashes, storable, stored, fetched = [], [], {}, {}, {}, set()  # every: given, then meanwhile's jobs

    def by_cost(indices):  # costliest first, so that the workers finish together; stable within a kind
        return sorted(indices, key=lambda i: -_COST.get(every[i]["func"], 1))

    def plan(new):  # the indices of ``new`` jobs neither in the folder nor in the store, costliest first
        first = len(every)
        every.extend(new)
        keys.extend(_job_keys(fits, new, hashes))
        todo = [i for i in range(first, len(every)) if not _in_folder(manifest, every[i]["path"], keys[i])]
        for i in todo:
            for j in _fit_indices(every[i]):
                if j not in storable:
                    storable[j] = figure_store.storable(fits[j])
            if all(storable[j] for j in _fit_indices(every[i])):
                stored[i] = hashlib.sha256(keys[i].encode()).hexdigest()
        fetched.update(i for i in todo if i in stored and figure_store.fetch(stored[i], every[i]["path"]))
        todo = [i for i in todo if i not in fetched]
        return by_cost(todo)

    todo = plan(jobs)
    jobs = every
    errors = {}
    workers = min(workers or MAX_FIGURE_WORKERS, os.cpu_count() or 1)
    fork = forkable()  # never from a process with other threads (a notebook's): its child may deadlock
    if meanwhile is not None and (not fork or min(workers, len(todo)) < 2):  # no workers drawing meanwhile:
        todo = by_cost(todo + plan(meanwhile()))  # its jobs drawn with the rest
        meanwhile = None
    workers = min(workers, len(todo))
    _FITS, _JOBS, _STORED = fits, jobs, stored  # the same list and dict: jobs planned later are drawn here
    try:
        if workers > 1 and fork:
            for i in {i for j in todo for i in _fit_indices(jobs[j])}:
                if fits[i].pending:  # computed once here; a saved fit's are read by the worker drawing it
                    fits[i].complete()
                fits[i].summary()  # inherited by the workers
            plots._DPI  # noqa: B018  the plotting module and matplotlib imported once, before the fork
            import matplotlib.backends.backend_pdf  # noqa: F401
            import PIL.PngImagePlugin  # noqa: F401

            from skinfit.plots._pdf_font import derived

            derived()  # the figures' font found (derived, the first time) once, before the fork

            with _frozen_heap(), ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork"),
                                                     initializer=_init_worker, initargs=(os.getpid(),)) as pool:
                futures = {i: pool.submit(_render_one, i) for i in todo}
                try:
                    more = plan(meanwhile()) if meanwhile is not None else []
                except BaseException:  # the figures drawn by then recorded (reused next time), the rest cancelled
                    pool.shutdown(cancel_futures=True)  # waits for those running: every future done or cancelled
                    for i, f in futures.items():
                        if not f.cancelled() and f.exception() is None and f.result() is None:
                            manifest[jobs[i]["path"].name] = keys[i]
                    _write_manifest(figdir, manifest)
                    raise
                for i in more:
                    errors[i] = _render_one(i)
                todo += more
                errors.update((i, f.result()) for i, f in futures.items())
        else:
            for i in todo:
                errors[i] = _render_one(i)
    finally:
        _FITS, _JOBS, _STORED = [], [], {}
    if any(i in stored for i in todo):
        figure_store.trim()
    for i in [*todo, *fetched]:
        if errors.get(i) is None:
            manifest[jobs[i]["path"].name] = keys[i]
        else:  # not the figure an earlier report drew there, nor a part of this one's
            manifest.pop(jobs[i]["path"].name, None)
            _remove_figure(figdir, jobs[i]["path"].name)
    shown = {job["path"].name for job in jobs}
    for name in [n for n in manifest if n not in shown]:  # an earlier report's, not shown by this one
        manifest.pop(name)
        _remove_figure(figdir, name)
    _write_manifest(figdir, manifest)
    return [errors.get(i) for i in range(len(jobs))]


def _remove_figure(figdir, name):
    """Remove figure ``name`` (a PNG file name, as the manifest records it) and its PDF from
    ``figdir``: figures/ holds only the figures its page shows, so none of an earlier report
    (a fit no longer reported, a figure that could not be drawn this time) is taken for one of
    this report. A name that is not a plain PNG file name (a damaged manifest) removes nothing."""
    if not isinstance(name, str) or name != Path(name).name or not name.endswith(".png") or name.startswith("."):
        return
    for suffix in (".png", ".pdf"):
        (figdir / name).with_suffix(suffix).unlink(missing_ok=True)


def _fit_indices(job):
    """The indices into the fits of the fits a figure job is drawn from."""
    if job["fit"] is None:
        return []
    return list(job["fit"].values()) if isinstance(job["fit"], dict) else [job["fit"]]


def _job_keys(fits, jobs, hashes=None):
    """Each job's key: everything its figure is drawn from (its fits' content or its named
    ``inputs``, the plot function, its arguments, the plotting code; see :func:`render_figures`).
    ``hashes``: fit index -> content hash, filled as computed (shared between calls)."""
    hashes = {} if hashes is None else hashes

    def content(i):
        if i not in hashes:
            hashes[i] = fits[i].content_hash()
        return hashes[i]

    def inputs(job):
        if job["fit"] is None:
            return job["inputs"]
        which = job["fit"].items() if isinstance(job["fit"], dict) else [("", job["fit"])]
        return ",".join(f"{label}={content(i)}" for label, i in which)

    return [f"{inputs(job)}:{job['func']}:{json.dumps([job['args'], job.get('kwargs', {})], default=str)}:"
            f"{_code_key(job['func'])}" for job in jobs]


def _in_folder(manifest, path, key):
    """True when ``path`` and its PDF exist and the folder's manifest records them as drawn
    from ``key``."""
    return manifest.get(path.name) == key and path.exists() and path.with_suffix(".pdf").exists()


def _manifest(figdir):
    """Figure file name -> the key of what it was drawn from (``figdir/.figures.json``); an
    unreadable manifest is empty (every figure drawn again)."""
    try:
        manifest = json.loads((figdir / ".figures.json").read_text())
    except (OSError, ValueError):
        return {}
    return manifest if isinstance(manifest, dict) else {}


def _write_manifest(figdir, manifest):
    from skinfit.inference.checkpoint import replace_atomic

    replace_atomic(figdir / ".figures.json", json.dumps(manifest, indent=0, sort_keys=True).encode())


def _write_png(fig, path):
    """The figure as a vector PDF (dense scatter rasterised; TrueType fonts, :data:`plots.SAVE_RC`),
    for papers, and as a PNG of that PDF rendered by PDFium at :data:`plots._DPI`, quantised to
    256 colours (a third of the size, no visible change for line art). The layout is computed
    once (:func:`plots._fix_layout`) and the figure drawn once, into the PDF, which PDFium
    rasterises (bench/results/report.md)."""
    import io

    import pypdfium2
    from PIL import Image

    fig.set_dpi(plots._DPI)
    plots._fix_layout(fig)
    buffer = io.BytesIO()
    plots.save_figure(fig, buffer, format="pdf", metadata={"CreationDate": None})  # the same figure, the same bytes
    pdf = _stable_font_tags(buffer.getvalue())
    document = pypdfium2.PdfDocument(pdf)
    page = document[0]
    try:  # in RGB byte order, no alpha (the page is filled white): no conversion of PDFium's BGRA
        image = page.render(scale=plots._DPI / 72, rev_byteorder=True, prefer_bgrx=True).to_pil()
        image = image.convert("RGB")  # a copy, independent of PDFium's bitmap (RGBX from pypdfium2 4)
    finally:
        page.close()
        document.close()
    image.quantize(colors=256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE).save(
        path, format="PNG", compress_level=6)
    Path(path).with_suffix(".pdf").write_bytes(pdf)


_SUBSET_TAG = re.compile(rb"(/(?:BaseFont|FontName|Name) /)([A-Z]{6})(?=\+)")


def _stable_font_tags(pdf):
    """``pdf`` with its font-subset tags (``/BaseFont /GXDUII+DejaVuSans``) made independent of
    the process: matplotlib derives them from ``hash()`` of the subset's glyphs, which Python
    salts per process, so the same figure gave other bytes in each. Each distinct tag becomes,
    in order of first appearance, AAAAAA, AAAAAB, ...: the same length, so every byte offset and
    the cross-reference table stay valid (PDF reference 1.7, 5.5.3: the tag is arbitrary)."""
    tags = {}

    def fixed(match):
        if match.group(2) not in tags:
            n, letters = len(tags), []
            for _ in range(6):
                n, r = divmod(n, 26)
                letters.append(chr(65 + r))
            tags[match.group(2)] = "".join(reversed(letters)).encode()
        return match.group(1) + tags[match.group(2)]

    return _SUBSET_TAG.sub(fixed, pdf)


def fit_figure_jobs(fit, index, key, figdir, n_of_model=1, where=""):
    """The figure jobs (see :func:`render_figures`) of one fit's section, each with its report
    ``entry`` (file, PDF, caption, alt text): ``fit`` is fit number ``index``, its files named
    ``key``; ``n_of_model`` fits of its model in the report (from :data:`MANY_FITS` on, each
    fit's section draws only its predictive check: the parameters are compared across the fits
    in one forest plot each)."""
    jobs = []
    for name, make, caption in _FIGURES if n_of_model < MANY_FITS else _FIGURES[:1]:
        path = figdir / f"{key}_{name}.png"
        entry = {"file": f"figures/{path.name}", "caption": caption, "alt": f"{caption} ({where})",
                 "pdf": f"figures/{path.stem}.pdf"}
        jobs.append({"fit": index, "func": make, "args": (), "path": path, "entry": entry})
    for pname, dims in _split_parameters(fit).items():
        path = figdir / f"{key}_forest_{pname}.png"
        entry = {"file": f"figures/{path.name}", "pdf": f"figures/{path.stem}.pdf",
                 "caption": f"{pname} per {dims}: posterior mean and 94% HDI",
                 "alt": f"forest plot of {pname} per {dims} ({where})"}
        jobs.append({"fit": index, "func": "plot_forest", "args": (pname,), "path": path, "entry": entry})
    return jobs


def store_fit_figures(path, n_of_model=1):
    """Draw the section figures of the fit saved at ``path`` into the figure store
    (:mod:`skinfit.report.figure_store`), ahead of a report that will copy them (``skinfit demo``
    draws them in its fit workers while other fits run). Nothing when the store is off or the
    fit is not storable; one process, no figure workers. Returns the number of figures drawn."""
    import tempfile

    from skinfit.report import figure_store
    from skinfit.results.fit import load_fit

    if figure_store.store_dir() is None:
        return 0
    fit = load_fit(path)
    if not figure_store.storable(fit):
        return 0
    with tempfile.TemporaryDirectory(prefix="skinfit-figures-") as tmp:
        jobs = fit_figure_jobs(fit, 0, "fit", Path(tmp), n_of_model)
        errors = render_figures([fit], jobs, Path(tmp), workers=1)
    return sum(e is None for e in errors)


def write_report(fits, out_dir, *, title=None, comparison=None, population=None, populations=None,
                 contrasts=None, designs=(), analyses=None, notes=None):
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
        Population distributions drawn on the forest plots (see :func:`skinfit.plots.figures.plot_forest`);
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
    from skinfit.inference.checkpoint import CheckpointLock

    with CheckpointLock(out / "report"):  # two reports into one folder never interleave their files
        for name in _recorded_outputs(out):  # the previous report's tables and pages: none left stale
            (out / name).unlink(missing_ok=True)
        before, start = {p.name for p in out.iterdir()}, time.time_ns()
        index = _write_contents(items, out, figdir, title=title, comparison=comparison, population=population,
                                populations=populations, contrasts=contrasts, designs=designs, analyses=analyses,
                                notes=notes)
        _record_outputs(out, before, start)
    return index


def _write_contents(items, out, figdir, *, title, comparison, population, populations, contrasts, designs,
                    analyses=None, notes=None):
    """The report's files (see :func:`write_report`), in a folder already claimed and locked.
    The fits' figures are drawn while the sections, ``analyses`` and the figures across fits
    are computed (:func:`render_figures`' ``meanwhile``)."""
    import jinja2

    from skinfit import __version__

    figdir.mkdir(parents=True, exist_ok=True)
    issues_all, sections, more = [], [], []
    per_model = {}
    for _, fit in items:
        per_model[fit.model_id] = per_model.get(fit.model_id, 0) + 1
    from skinfit.results.run_labels import run_labels

    # two runs of one model on one dataset: named by the options that differ
    labels = dict(zip([k for k, _ in items], run_labels([f for _, f in items])))
    wheres = {key: f"{labels[key]} on {fit.dataset_id}" for key, fit in items}
    fit_jobs = [fit_figure_jobs(fit, n, key, figdir, per_model[fit.model_id], wheres[key])
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
            summary = fit.summary()
            diag, issues = fit_diagnostics(fit, summary)
            summary.to_csv(out / f"{key}_summary.csv")
            diag.to_csv(out / f"{key}_diagnostics.csv")
            units = parameter_units(fit)
            shown = summary.drop(columns="unit", errors="ignore")
            shown.insert(0, "unit", [units.get(_base(n), "") for n in shown.index])
            derived = np.isin([_base(n) for n in shown.index], list(derived_units(fit)))  # no MAP, tau, prior
            named = level_names(fit)
            shown.index = [named.get(n, n) for n in shown.index]
            where = wheres[key]
            issues_all.extend({"status": st, "anchor": key, "where": where, "text": msg} for st, msg in issues)
            prov = _provenance(fit)
            sections.append({"key": key, "where": where, "converged": fit.converged, "issues": issues,
                             "prov": prov, "prov_line": _provenance_line(prov),
                             "summary": _table(shown, "parameter",
                                               _not_applicable(shown, ["map", "tau", "contraction"], derived)),
                             "diagnostics": _table(diag, "check"), "figures": [job["entry"] for job in section_jobs],
                             "csv": [f"{key}_summary.csv", f"{key}_diagnostics.csv"]})
        across.extend(_across_fits(items, figdir, given["population"], given["populations"] or {}, out, more))
        tables = given["comparison"]
        tables = tables if isinstance(tables, dict) else ({"": tables} if tables is not None else {})
        for name, table in tables.items():
            stem = _unique("comparison" + (f"_{file_part(name)}" if name else ""), stems)
            table.to_csv(out / f"{stem}.csv")
            path = figdir / f"{stem}.png"
            entry = {"name": name or "models", "table": _table(table, table.index.name or "model"),
                     "csv": f"{stem}.csv", "note": ranking_note(table), "id": f"comparison-{len(comparisons) + 1}",
                     "issues": comparison_issues(table),
                     "figure": {"file": f"figures/{path.name}", "alt": f"model comparison chart ({name or 'models'})"}}
            comparisons.append(entry)
            # drawn from the table alone: kept (in the folder and the figure store) while it is the same
            more.append({"fit": None, "inputs": hashlib.sha256(table.to_csv().encode()).hexdigest(),
                         "func": "plot_comparison", "args": (table,), "path": path, "comparison": entry})
        return more

    for _, fit in items:  # its checks of the fit to the data need the deferred groups, its figures' keys
        if fit.pending:  # the attributes these add; once, before the figure workers start
            fit.complete()
    jobs = [job for section_jobs in fit_jobs for job in section_jobs]
    errors = render_figures([fit for _, fit in items], jobs, figdir, meanwhile=meanwhile)
    contrasts = given["contrasts"]
    for job, error in zip(jobs + more, errors):
        if not error:
            continue
        if "comparison" in job:  # listed at the top, the chart left out (its table stays)
            job["comparison"]["figure"] = None
            issues_all.append({"status": "WARN", "anchor": job["comparison"]["id"], "where": "model comparison",
                               "text": error})
        elif "across" in job:  # listed at the top, the figure left out
            job["across"]["figures"].remove(job["entry"])
            issues_all.append({"status": "WARN", "anchor": job["across"]["id"],
                               "where": f"{job['across']['model_id']} across fits", "text": error})
        else:  # listed at the top and in its section, the figure left out
            section = sections[job["fit"]]
            section["figures"].remove(job["entry"])
            section["issues"].append(("WARN", error))
            issues_all.append({"status": "WARN", "anchor": section["key"], "where": section["where"], "text": error})
    contrast_tables = []
    for name, table in (contrasts or {}).items():
        from skinfit.report.groups import contrast_section

        stem = _unique("contrasts_" + file_part(name).strip("_"), stems)
        shown = contrast_section(table)
        shown.to_csv(out / f"{stem}.csv", index=False)
        top = shown.head(20).set_index("A")
        contrast_tables.append({"name": name, "csv": f"{stem}.csv", "n": len(shown),
                                "id": f"contrasts-{len(contrast_tables) + 1}", "issues": contrast_issues(table),
                                "table": _table(top, "A", _not_applicable(  # NaN where B's draws change sign
                                    top, ["ratio_median", "ratio_lower", "ratio_upper"]))})

    design_sections = []
    if designs:  # skinfit design results (DesignResult): the next experiment's plan, its figure in figures/
        from markupsafe import Markup

        from skinfit.analysis.design import design_section_html

        design_sections = [{"id": f"design-{d.model_id}", "name": d.model_id, "issues": design_issues(d),
                            "html": Markup(design_section_html(d, figdir))} for d in designs]
    issues_all.extend(_section_issues(across, comparisons, contrast_tables, design_sections, given))
    issues_all.sort(key=lambda i: i["status"] != "FAIL")  # failures first, then warnings (stable)
    n_fail = sum(i["status"] == "FAIL" for i in issues_all)
    context = {"title": title or "skinfit report", "version": __version__, "sections": sections,
               "issues": issues_all, "n_fail": n_fail, "n_warn": len(issues_all) - n_fail,
               "checked": _checked(sections, across, comparisons, contrast_tables, design_sections),
               "comparisons": comparisons, "across": across, "contrasts": contrast_tables,
               "designs": design_sections,
               "n_fits": len(sections), "n_converged": sum(s["converged"] for s in sections),
               "matplotlib": package_version("matplotlib"), "arviz": package_version("arviz")}
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(Path(__file__).parent / "templates"),
                             autoescape=True, undefined=jinja2.StrictUndefined, trim_blocks=True,
                             lstrip_blocks=True, keep_trailing_newline=True)
    env.filters["wbr"] = _break_at_underscores
    index = out / "index.html"
    index.write_text(env.get_template("report.html.j2").render(**context), encoding="utf-8")
    (out / "summary.md").write_text(_summary_md(context), encoding="utf-8")
    return index


#: A file in each report folder: the folder is the report's, to rewrite on the next report into it.
REPORT_MARKER = ".skinfit-report"


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


def _break_at_underscores(value):
    """A table cell's text, escaped, with a line-break opportunity (``<wbr>``) after each
    underscore: a narrow column breaks ``contact_area_no_levitation`` between its words, not
    inside one."""
    from markupsafe import Markup, escape

    return escape(value).replace("_", Markup("_<wbr>"))


def ranking_note(table):
    """A sentence when log evidence and LOO rank the models differently, else None.

    ``table`` as :func:`skinfit.compare` returns it (columns ``model`` or index, ``log_z``,
    ``elpd_loo``)."""
    if not {"log_z", "elpd_loo"} <= set(table.columns):
        return None
    t = table.set_index("model") if "model" in table.columns else table
    by_z = list(t["log_z"].sort_values(ascending=False).index)
    by_loo = list(t["elpd_loo"].sort_values(ascending=False).index)
    if by_z == by_loo:
        return None
    return (f"Evidence and LOO rank these models differently: by log Z {' > '.join(map(str, by_z))}; "
            f"by ELPD (LOO) {' > '.join(map(str, by_loo))}. The evidence Z = p(data | model) averages the "
            "likelihood over the prior, so it rewards a model whose priors put mass where the data are and "
            "penalises wide priors; LOO's ELPD scores how well the fitted posterior predicts each left-out row, "
            "whatever the prior. Where they disagree, the winner by evidence is favoured as a whole-model "
            "explanation under these priors, the winner by LOO as a predictor of new rows like these; "
            "check the standard errors before reading either difference.")


def _base(slot_name):
    return slot_name.split("[", 1)[0]


def _split_parameters(fit):
    """Split parameter -> the name of its grouping dimension."""
    post = fit.group("posterior")
    return {v: ", ".join(d for d in post[v].dims if d not in ("chain", "draw")) for v in post.data_vars
            if set(post[v].dims) - {"chain", "draw"}}


def _across_fits(items, figdir, population, populations, out_dir, jobs):
    """Per model with several fits (subjects, conditions): a table and a forest plot of each
    parameter across the fits, labelled by subject as written in the data, and the model's
    population result when given. The forest plots are appended to ``jobs`` (drawn with the
    fits' own figures by :func:`render_figures`)."""
    from skinfit.report.groups import population_section, subjects_section

    by_model = {}
    index = {key: i for i, (key, _) in enumerate(items)}
    for key, fit in items:
        by_model.setdefault(fit.model_id, []).append((key, fit))
    out, taken = [], set()
    for model_id, group in by_model.items():
        if len(group) < 2:
            continue
        safe = _unique(file_part(model_id), taken)
        subj = subjects_section(dict(group))
        labelled = {subj["labels"][k]: f for k, f in group}
        if len(labelled) < len(group):  # the same subject label twice: keep the unique keys
            labelled = dict(group)
        tables = []
        for pname, table in subj["tables"].items():
            stem = f"subjects_{safe}_{file_part(pname)}"
            table.to_csv(out_dir / f"{stem}.csv")
            tables.append({"parameter": pname, "csv": f"{stem}.csv", "table": _table(table, "subject")})
        pop_result = populations.get(model_id)
        pop_info = population_section(pop_result) if pop_result is not None else None
        if pop_info is not None:
            from skinfit.analysis.population.population import DERIVED

            pop_info["hyper"].to_csv(out_dir / f"population_{safe}.csv")
            if pop_info["effects"] is not None:
                pop_info["effects"].to_csv(out_dir / f"population_effects_{safe}.csv", index=False)
            hyper = pop_info["hyper"].reset_index().set_index("parameter")
            derived = hyper["quantity"].isin(DERIVED)  # computed from mu and tau
            pop_tables = {"hyper": _table(hyper, "parameter",
                                          _not_applicable(hyper, ["r_hat", "ess_bulk", "ess_tail"], derived)),
                          "csv": f"population_{safe}.csv",
                          "subjects": [{"parameter": k, "table": _table(v, "subject")}
                                       for k, v in pop_info["subjects"].items()],
                          "hyperpriors": _table(pop_info["hyperprior_table"], "parameter"),
                          "effects": None if pop_info["effects"] is None else
                          _table(pop_info["effects"].set_index(pop_info["effects"].columns[0]),
                                 pop_info["effects"].columns[0]),
                          "warnings": pop_info["warnings"], "origin": pop_info["origin"],
                          "issues": population_issues(pop_result), "converged": bool(pop_result.converged),
                          "correlation": pop_info["correlation"], "sampler": pop_info["sampler_text"]}
        else:
            pop_tables = None
        figures = []
        entry = {"model_id": model_id, "fits": list(labelled), "figures": figures, "tables": tables,
                 "population": pop_tables, "id": f"across-{len(out) + 1}"}
        labels = {label: index[k] for label, (k, _) in zip(labelled, group)}
        for pname in group[0][1].group("posterior").data_vars:
            path = figdir / f"across_{safe}_{pname}.png"
            pop = _population_for(population, model_id, pname)
            if pop is None and pop_info is not None:
                pop = pop_info["intervals"].get(pname)
            caption = f"{pname} across {len(group)} fits" + (" with the population distribution" if pop is not None
                                                              else "")
            figures.append({"file": f"figures/{path.name}", "caption": caption,
                            "alt": f"forest plot of {pname} across the fits of {model_id}"})
            jobs.append({"fit": labels, "func": "plot_forest", "args": (pname,), "kwargs": {"population": pop},
                         "path": path, "entry": figures[-1], "across": entry})
        out.append(entry)
    return out


def _section_issues(across, comparisons, contrasts, designs, given):
    """The failed checks of the sections across fits (:mod:`skinfit.report.checks`) as issues at
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


def _checked(sections, across, comparisons, contrasts, designs):
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


def _summary_md(ctx):
    lines = [f"# {ctx['title']}", "",
             f"Written by skinfit {ctx['version']} from {ctx['n_fits']} saved fit(s); "
             f"{ctx['n_converged']} converged. Figures are in `figures/`; tables also as CSV.", "",
             "## Diagnostics", ""]
    if ctx["issues"]:
        lines += [f"{ctx['n_fail']} failure{'s' if ctx['n_fail'] != 1 else ''} and {ctx['n_warn']} "
                  f"warning{'s' if ctx['n_warn'] != 1 else ''}: read these before the numbers below.", ""]
        lines += [f"- **{i['status']}** {i['where']}: {i['text']}"
                  + (f" ([its section](index.html#{i['anchor']}))" if i["anchor"] else "") for i in ctx["issues"]]
    else:
        lines.append(f"Every check passed: {ctx['checked']}.")
    for c in ctx["comparisons"]:
        lines += ["", f"## Model comparison: {c['name']}", "", _markdown(c["table"]), "", f"CSV: `{c['csv']}`"]
        if c["note"]:
            lines += ["", f"**{c['note']}**"]
        if c["figure"]:
            lines += ["", f"![{c['figure']['alt']}]({c['figure']['file']})"]
    for a in ctx["across"]:
        lines += ["", f"## {a['model_id']} across fits: {', '.join(a['fits'])}", ""]
        for tb in a["tables"]:
            lines += ["", f"### {tb['parameter']} per subject", "", _markdown(tb["table"])]
        if a["population"]:
            lines += ["", "### Population", "", _markdown(a["population"]["hyper"])]
            for tb in a["population"]["subjects"]:
                lines += ["", f"#### {tb['parameter']}: separate and shrunk", "", _markdown(tb["table"])]
        lines += [f"![{f['alt']}]({f['file']})" for f in a["figures"]]
    for c in ctx["contrasts"]:
        lines += ["", f"## Contrasts: {c['name']}", "", _markdown(c["table"]), "", f"CSV: `{c['csv']}`"]
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
    """Run directories or fit.nc files. A directory with an index.json (a ``skinfit fit --by``
    run, a campaign) gives the fits its index lists as done, and names on stderr any fit.nc
    below it that the index does not list (another run's, not reported); another directory
    gives every fit.nc below it."""
    out = []
    for p in map(Path, paths):
        if p.is_file() or (p / "fit.nc").exists():
            out.append(p)
        elif (p / "index.json").is_file():
            listed = _indexed_fits(p / "index.json")
            known = {f.resolve() for f in listed}
            extra = [f for f in sorted(p.glob("**/fit.nc")) if f.resolve() not in known]
            if extra:
                print(f"skinfit report: warning: {len(extra)} fit file(s) below {p} are not in its index.json "
                      f"(e.g. {extra[0]}): not reported (name them to report them)", file=sys.stderr)
            out += listed
        elif p.is_dir():
            found = sorted(p.glob("**/fit.nc"))
            if not found:
                raise InputError(p, "no fit.nc in this directory or below it (run `skinfit fit ... --out` first)")
            out += found
        else:
            raise InputError(p, "no such run directory or fit file")
    return out


def _indexed_fits(index):
    """The fit files an index.json lists (:func:`skinfit.analysis.groups.read_index`), naming on stderr
    a campaign's fits that are not complete."""
    from skinfit.analysis.groups import read_index

    rows, skipped = read_index(index)
    if skipped:
        print(f"skinfit report: {skipped} fit(s) of {index} not complete (failed or pending): not reported",
              file=sys.stderr)
    if not rows:
        raise InputError(index, "lists no completed fit")
    return [r["path"] for r in rows]


def _saved_populations(paths):
    """The populations ``skinfit population RUN`` saved beside the runs given (RUN/population/
    population.nc), read; one that cannot be read is named on stderr and left out."""
    out = []
    for p in dict.fromkeys(Path(p) / "population" / "population.nc" for p in paths):
        if p.is_file():
            from skinfit.analysis.population.population import load_population  # only then: it imports scipy.stats

            try:
                out.append(load_population(p))
            except Exception as exc:  # noqa: BLE001 - a damaged file is reported; the report computes its own
                print(f"skinfit report: warning: {p} could not be read ({type(exc).__name__}: {exc}): not used",
                      file=sys.stderr)
    return out


def _comparisons(fits, echo=None):
    """Evidence/LOO tables for fits of different models (or one model under other priors, split,
    noise or constants) on the same data, if skinfit.compare exists, one per dataset content
    (sha256): two versions of a dataset are two tables, named by the data's sha256 where they
    share a name. A comparison that fails is said through ``echo`` (default: on stderr)."""
    echo = echo or (lambda message: print(message, file=sys.stderr))
    groups = {}
    for key, f in fits:
        groups.setdefault(f.attrs["dataset_sha256"], []).append((key, f))
    groups = {sha: group for sha, group in groups.items() if len({_setup(f) for _, f in group}) > 1}
    if not groups:
        return None
    try:
        from skinfit.analysis.compare import compare
    except ImportError as exc:
        if exc.name != "skinfit.analysis.compare":  # present but broken: say so, the report goes on
            echo(f"skinfit report: no model comparison ({exc})")
        return None
    tables = {}
    named = [group[0][1].dataset_id for group in groups.values()]
    for (sha, group), name in zip(groups.items(), named):
        name = name if named.count(name) == 1 else f"{name} (data {sha[:12]})"
        try:
            tables[name] = compare([f for _, f in group])
        except (ValueError, RuntimeError) as exc:  # the report still shows every fit
            echo(f"skinfit report: comparison on {name} failed: {exc}")
    if not tables:
        return None
    return next(iter(tables.values())) if len(tables) == 1 else tables


def _setup(fit):
    """What makes a fit another model of its data: the model card and prior file, the split,
    noise and constants (not the seed, walkers or file: runs of one model)."""
    return fit.model_id, fit.attrs.get("priors_sha256"), fit.attrs.get("model_sha256"), fit.attrs.get("setup")


def _cited(source):
    """A card's source with each reference key spelled out (authors, title, venue, year)."""
    from skinfit.io.references import cite_long

    return cite_long(source)


def cli_report(args):
    """``skinfit report RUN... --out DIR``."""
    from skinfit.results.fit import load_fit

    from skinfit.analysis.groups import data_drift
    from skinfit.report.groups import group_analyses

    designs = [p for p in args.runs if (Path(p) / "design.json").is_file()]
    if designs:
        from skinfit.analysis.design import load_design

        designs = [load_design(p) for p in designs]
    runs = _collect_runs([p for p in args.runs if not (Path(p) / "design.json").is_file()])
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
                                                saved=_saved_populations(args.runs))
        return {"comparison": _comparisons(items, echo), "populations": populations, "contrasts": contrasts,
                "notes": notes}

    index = write_report(dict(items), args.out, designs=designs, analyses=analyses)
    if getattr(args, "json", False):
        import json

        print(json.dumps({"report": str(index), "fits": [name for name, _ in items]}, indent=2))
        return 0
    print(f"report written: {index}  (open it in a browser; summary.md and CSV tables beside it)")
    return 0
