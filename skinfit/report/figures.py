"""The report's figures: the jobs that draw them, their keys, and the processes that draw them.

A figure job is a dict: ``fit`` (an index into the report's fits, ``{label: index}`` for a
figure across fits, or None for one drawn from its ``args`` alone, whose content ``inputs``
then names: a sha256), ``func`` (a :mod:`skinfit.plots` function name), ``args``,
optional ``kwargs``, ``path`` (its PNG in figures/; the PDF beside it). A figure whose key
(:func:`job_keys`) and files are those recorded in its folder is kept
(:class:`skinfit.report.figure_folder.FigureFolder`); the others are drawn in forked worker
processes, costliest first.
"""

import hashlib
import json
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from skinfit import plots
from skinfit.inference.checkpoint import watch_parent
from skinfit.inference.workers import forkable
from skinfit.io.paths import code_hash
from skinfit.report.figure_folder import SUFFIXES, FigureFolder
from skinfit.report.tables import file_part
from skinfit.results.intervals import CI_PROB, interval_name

__all__ = ["FIGURES", "MANY_FITS", "MAX_FIGURE_WORKERS", "fit_figure_jobs", "split_parameters", "job_keys",
           "render_figures", "render_one", "draw_figure"]

FIGURES = (  # (file name, skinfit.plots function, caption)
    ("ppc", "plot_ppc", "Posterior predictive: the data over the 50% and 90% posterior-predictive "
                        "bands and the posterior median curve, in the units the data came in"),
    ("prior_posterior", "plot_prior_posterior", "Prior (line) against posterior (filled) per parameter: "
                                                "what the data determined"),
    ("pair", "plot_pair", "Pairwise posterior draws and marginals (corner plot); MAP in red"),
    ("trace", "plot_trace", "Walker traces and rank histograms by walker group"),
)
#: From this many fits of one model on, each fit's section draws only its predictive check.
MANY_FITS = 4
#: Processes that draw a report's figures (at most; one per core).
MAX_FIGURE_WORKERS = 4
#: Rough relative drawing time of each figure kind: the costliest are started first, so that the
#: workers finish together.
COST = {"plot_ppc": 4, "plot_trace": 3, "plot_pair": 2, "plot_prior_posterior": 1.5, "plot_forest": 1}
#: The libraries whose versions are part of a figure's key, besides skinfit's own source.
LIBRARIES = ("matplotlib", "numpy", "scipy", "pandas", "xarray", "arviz-base", "arviz-stats", "arviz-plots",
             "pillow")
_FITS, _JOBS = [], []  # the fits and figure jobs being drawn, inherited by forked worker processes


def split_parameters(fit):
    """Split parameter -> the name of its grouping dimension."""
    post = fit.group("posterior")
    return {v: ", ".join(d for d in post[v].dims if d not in ("chain", "draw")) for v in post.data_vars
            if set(post[v].dims) - {"chain", "draw"}}


def fit_figure_jobs(fit, index, key, figdir, n_of_model=1, where="", ci_prob=CI_PROB):
    """The figure jobs of one fit's section, each with its report ``entry`` (file, PDF, caption,
    alt text): ``fit`` is fit number ``index``, its files named ``key``; ``n_of_model`` fits of
    its model in the report (from :data:`MANY_FITS` on, each fit's section draws only its
    predictive check: the parameters are compared across the fits in one forest plot each). The
    parameters split by one column share one forest figure, a panel each (named after the
    parameter when it is alone, else after the column); the forests draw and name the HDI at the
    report's ``ci_prob``, part of their jobs' keys."""
    jobs = []
    for name, make, caption in FIGURES if n_of_model < MANY_FITS else FIGURES[:1]:
        path = figdir / f"{key}_{name}.png"
        entry = {"file": f"figures/{path.name}", "caption": caption, "alt": f"{caption} ({where})",
                 "pdf": f"figures/{path.stem}.pdf"}
        jobs.append({"fit": index, "func": make, "args": (), "path": path, "entry": entry})
    by_dims = {}  # the parameters split by one column side by side, one panel each, sharing its levels' rows
    for pname, dims in split_parameters(fit).items():
        by_dims.setdefault(dims, []).append(pname)
    for dims, pnames in by_dims.items():
        path = figdir / f"{key}_forest_{file_part(pnames[0] if len(pnames) == 1 else dims)}.png"
        panels = " (a panel each)" if len(pnames) > 1 else ""
        entry = {"file": f"figures/{path.name}", "pdf": f"figures/{path.stem}.pdf",
                 "caption": f"{', '.join(pnames)} per {dims}{panels}: posterior mean and {interval_name(ci_prob)}",
                 "alt": f"forest plot of {', '.join(pnames)} per {dims} ({where})"}
        jobs.append({"fit": index, "func": "plot_forest", "args": (pnames,), "kwargs": {"ci_prob": ci_prob},
                     "path": path, "entry": entry})
    return jobs


def _code_key(func):
    """What draws a figure: skinfit's source and the plotting libraries' versions
    (:func:`skinfit.io.paths.code_hash`) and, when ``skinfit.plots.<func>`` is not
    skinfit's own function (a test's or a user's replacement), that function's code: a
    replaced plot draws again."""
    def text(code):  # its bytecode, names and constants, nested functions included
        consts = [text(c) if hasattr(c, "co_code") else repr(c) for c in code.co_consts]
        return repr((code.co_code, code.co_names, code.co_varnames, consts))

    f = getattr(plots, func)
    own = ""
    mine = str(getattr(f, "__module__", "")).startswith("skinfit.plots.") and getattr(f, "__qualname__", None) == func
    if not mine:
        own = "." + hashlib.sha256((text(f.__code__) if hasattr(f, "__code__") else repr(f)).encode()).hexdigest()[:16]
    return f"{code_hash(LIBRARIES)[:16]}{own}"


def job_keys(fits, jobs, hashes=None):
    """Each job's key: everything its figure is drawn from (its fits' content,
    :meth:`~skinfit.results.fit.Fit.content_hash`, or its named ``inputs``; the plot function
    and its arguments; the plotting code, :func:`_code_key`). ``hashes``: fit index -> content
    hash, filled as computed (shared between calls)."""
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


def _fit_indices(job):
    """The indices into the fits of the fits a figure job is drawn from."""
    if job["fit"] is None:
        return []
    return list(job["fit"].values()) if isinstance(job["fit"], dict) else [job["fit"]]


def _job_args(job):
    """The positional arguments of a job's plot function: one fit, or {label: fit} across fits,
    before the job's ``args`` (none for a figure drawn from its ``args`` alone)."""
    if job["fit"] is None:
        return tuple(job["args"])
    if isinstance(job["fit"], dict):
        return {label: _FITS[i] for label, i in job["fit"].items()}, *job["args"]
    return _FITS[job["fit"]], *job["args"]


def _stat(path):
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_ino, st.st_size, st.st_mtime_ns


def draw_figure(make, path):
    """Draw one figure (``make()``) into its PNG and PDF (:func:`skinfit.plots.write_figure_files`);
    returns None, or the error text to show at the top, after removing what this attempt wrote.

    Any exception is caught on purpose: one figure must not cost the whole report, and the
    failure is listed among the diagnostics, never hidden.
    """
    before = {s: _stat(Path(path).with_suffix(s)) for s in SUFFIXES}
    try:
        plots.write_figure_files(make(), path)
    except Exception as exc:  # reported, not swallowed
        for s, stat in before.items():  # a file half-written now is no figure; one not touched stays
            if _stat(Path(path).with_suffix(s)) != stat:
                Path(path).with_suffix(s).unlink(missing_ok=True)
        return f"figure {Path(path).name} could not be drawn ({type(exc).__name__}: {exc})"
    return None


def render_one(i):
    """Draw figure job ``i`` of those being rendered into its PNG and PDF (top level: runs in a
    forked worker, which inherits the fits and jobs, so nothing is pickled but the index)."""
    job = _JOBS[i]
    return draw_figure(lambda: getattr(plots, job["func"])(*_job_args(job), **job.get("kwargs", {})), job["path"])


def render_figures(fits, jobs, figdir, workers=None, meanwhile=None):
    """Draw figure ``jobs`` (see the module's docstring) into ``figdir``, each once per input: a
    figure whose key and files are those recorded in ``figdir``
    (:meth:`~skinfit.report.figure_folder.FigureFolder.unchanged`) is kept. The rest are drawn in
    up to :data:`MAX_FIGURE_WORKERS` forked processes (at most ``workers``; in this one where
    fork is unavailable or other threads run here, :func:`skinfit.inference.workers.forkable`),
    costliest first. ``meanwhile``, when given, is called once while the workers draw and
    returns more jobs (drawn from what it computed, in this process, after it returns).
    figures/ is left holding, of the figures its record lists, only these jobs'.
    Returns one error text or None per job, ``jobs`` then meanwhile's."""
    global _FITS, _JOBS
    folder = FigureFolder(figdir)
    every, keys, hashes = [], [], {}  # every: the jobs given, then meanwhile's

    def by_cost(indices):  # costliest first, so that the workers finish together; stable within a kind
        return sorted(indices, key=lambda i: -COST.get(every[i]["func"], 1))

    def plan(new):  # the indices of ``new`` jobs whose figures are not in the folder, costliest first
        first = len(every)
        every.extend(new)
        keys.extend(job_keys(fits, new, hashes))
        return by_cost([i for i in range(first, len(every)) if not folder.unchanged(every[i]["path"], keys[i])])

    todo = plan(jobs)
    jobs = every
    errors = {}
    workers = min(workers or MAX_FIGURE_WORKERS, os.cpu_count() or 1)
    fork = forkable()  # never from a process with other threads (a notebook's): its child may deadlock
    if meanwhile is not None and (not fork or min(workers, len(todo)) < 2):  # no workers drawing meanwhile:
        todo = by_cost(todo + plan(meanwhile()))  # its jobs drawn with the rest
        meanwhile = None
    workers = min(workers, len(todo))
    _FITS, _JOBS = fits, jobs  # the same list: jobs planned later are drawn here
    try:
        if workers > 1 and fork:
            for i in {i for j in todo for i in _fit_indices(jobs[j])}:
                if fits[i].pending:  # computed once here; a saved fit's are read by the worker drawing it
                    fits[i].complete()
                fits[i].summary()  # inherited by the workers
            with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork"),
                                     initializer=watch_parent, initargs=(os.getpid(),)) as pool:
                futures = {i: pool.submit(render_one, i) for i in todo}
                try:
                    more = plan(meanwhile()) if meanwhile is not None else []
                except BaseException:  # the figures drawn by then recorded (kept next time), the rest cancelled
                    pool.shutdown(cancel_futures=True)  # waits for those running: every future done or cancelled
                    for i, f in futures.items():
                        if not f.cancelled() and f.exception() is None and f.result() is None:
                            folder.record(jobs[i]["path"], keys[i])
                    folder.write()
                    raise
                for i in more:
                    errors[i] = render_one(i)
                todo += more
                errors.update((i, f.result()) for i, f in futures.items())
        else:
            for i in todo:
                errors[i] = render_one(i)
    finally:
        _FITS, _JOBS = [], []
    for i in todo:
        if errors.get(i) is None:
            folder.record(jobs[i]["path"], keys[i])
        else:  # not the figure an earlier report drew there, nor a part of this one's
            folder.remove(jobs[i]["path"].name)
    folder.keep_only(job["path"].name for job in jobs)  # an earlier report's, not shown by this one
    folder.write()
    return [errors.get(i) for i in range(len(jobs))]
