"""The subjects of a population: the fits of a ``skinfit fit --by`` run or a campaign, or fits
and draws given in Python, each checked to be the subject it is listed as."""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
import xarray as xr

from skinfit.analysis.groups import index_document, index_drift, listed_problem, missing_groups, read_index, reading
from skinfit.analysis.population.result import PopulationWarning
from skinfit.errors import InputError
from skinfit.results.fit import Fit, load_fit

__all__ = ["load_run", "DrawsFit", "subject_fits", "subject_digest"]


def load_run(path, model=None):
    """``{label: Fit}`` of a ``skinfit fit --by`` run directory or a campaign out directory
    (its ``index.json``).  Labels as the user wrote them: ``S01`` for a single grouping column
    (``subject=S01`` in the index), the full ``col=a,col2=b`` otherwise; a campaign with
    several datasets adds ``dataset/``.  ``model`` picks one model of a campaign.

    Read while no writer holds the run (:func:`skinfit.analysis.groups.reading`); each fit must be the
    one its index lists (its recorded group and data: :func:`skinfit.analysis.groups.listed_problem`),
    and a fit ``--by`` run's data file unchanged since (else an InputError naming the subject
    and what is wrong).  A campaign's fits of the model that are not complete (failed or
    pending), and groups of a ``--by`` run's data its index does not list, are named in a
    :class:`PopulationWarning`."""
    path = Path(path)
    if path.is_dir() and not (path / "index.json").exists() and (path / "fit.nc").exists():
        raise InputError(path, "holds a single fit (fit.nc), not fits of several subjects: give the folder of "
                               "`skinfit fit ... --by subject` or of a campaign")
    index = path / "index.json" if path.is_dir() else path
    with reading(index.parent):
        rows, _ = read_index(index)
        kind, doc = index_document(index)
        if not rows:
            raise InputError(index, "lists no completed fit: nothing to pool")
        models = sorted({str(r.get("model")) for r in rows})
        if model is None and len(models) > 1:
            raise InputError(index, f"fits of several models ({', '.join(models)}): choose one with --model "
                                    "(Python: model=)", field="model")
        rows = [r for r in rows if model is None or r.get("model") == model]
        if not rows:
            raise InputError(index, f"no completed fit of model {model!r} (models: {', '.join(models)})", field="model")
        datasets = {r.get("dataset") for r in rows}
        fits, where = {}, {}
        for r in rows:
            label = _label(r, len(datasets) > 1)
            if label in fits:
                raise InputError(index, f"lists subject {label!r} twice ({where[label]} and {r['path']})")
            f = _load_light(r["path"])
            problem = listed_problem(f.attrs, r.get("group") or "", r.get("dataset_sha256"))
            if problem:
                raise InputError(r["path"], f"listed for subject {label} in {index} but {problem}")
            fits[label], where[label] = f, r["path"]
        names = ", ".join(list(fits)[:5]) + (f" and {len(fits) - 5} more" if len(fits) > 5 else "")
        drift = index_drift(index, doc, f"the fits of {names}") if kind == "by" else None
    if drift:
        raise InputError(index, drift[len(f"{index}: "):] + " (they are stale)")
    if kind == "by" and (missing := missing_groups(doc)):  # e.g. a `fit --by` killed part-way
        shown = [_label({"group": g}, False) for g in missing]
        warnings.warn(f"the run's data hold {len(missing)} group(s) its index does not list "
                      f"({', '.join(shown[:5])}{' ...' if len(shown) > 5 else ''}: a `skinfit fit --by` that did not "
                      f"finish?): the population is of the other {len(fits)} subjects only", PopulationWarning,
                      stacklevel=2)
    if kind == "campaign":
        chosen = model or rows[0].get("model")
        missing = [f"{_label(r, len(datasets) > 1)} ({r.get('status')})" for r in doc
                   if isinstance(r, dict) and r.get("model") == chosen
                   and r.get("status", "done") not in ("done", "complete")]
        if missing:
            warnings.warn(f"the campaign lists {len(missing)} fit(s) of {chosen} that are not complete "
                          f"({', '.join(missing[:5])}{' ...' if len(missing) > 5 else ''}): the population is of "
                          f"the other {len(fits)} subjects only", PopulationWarning, stacklevel=2)
    return fits


def _label(row, several_datasets):
    """A subject's label as the user wrote it (see :func:`load_run`)."""
    label = str(row.get("group") or row.get("dataset"))
    if label.count("=") == 1 and "," not in label:
        label = label.split("=", 1)[1]
    if several_datasets and row.get("group"):
        label = f"{row.get('dataset')}/{label}"
    return label


def _load_light(path):
    """A saved fit as :func:`skinfit.load_fit` reads it, checked against its checksums: the
    pointwise log-likelihood and predictive groups, most of a file, are not read."""
    fit = load_fit(path)
    if "posterior" not in fit.partial_tree.children:
        raise InputError(fit.path, "not a skinfit fit (no posterior group)")
    return fit


class DrawsFit:
    """A subject given as its Posterior and posterior draws instead of a saved fit (for
    simulation studies: SBC, coverage).  ``theta`` (n, d) in natural units, columns in the
    order of ``post.names``; unsplit parameters only."""

    def __init__(self, post, theta, label="subject"):
        if any(s.level is not None for s in post.slots):
            raise InputError("DrawsFit", "split parameters need a saved fit", field="post")
        self.posterior = post
        self.model_id, self.dataset_id = post.model.id, label
        pr = post.priors
        self.attrs = {"model_id": post.model.id, "dataset_id": label, "model_card": post.model.card_text,
                      "priors_text": pr.text, "priors_sha256": pr.sha256, "priors_id": pr.id}
        self._slots = [{"name": s.name, "base": s.base, "level": None, "transform": s.transform} for s in post.slots]
        theta = np.asarray(theta, dtype=float)
        self._ds = xr.Dataset({n: (("chain", "draw"), theta[None, :, j]) for j, n in enumerate(post.names)})

    def attr(self, key):
        if key == "slots":
            return self._slots
        raise KeyError(key)

    def group(self, name):
        if name != "posterior":
            raise KeyError(name)
        return self._ds


def subject_fits(fits, model=None):
    """{label: Fit or DrawsFit} of what :func:`population` was given (a run folder read by
    :func:`load_run`); InputError for anything else, labels that collide or fewer than two."""
    if isinstance(fits, (str, os.PathLike)):
        fits = load_run(fits, model)
    elif isinstance(fits, Mapping):
        fits = dict(fits)
    elif isinstance(fits, Iterable) and not isinstance(fits, (bytes, Fit)):
        listed = list(fits)
        bad = next((i for i, f in enumerate(listed, 1) if not isinstance(f, (Fit, DrawsFit))), None)
        if bad is not None:
            raise InputError("population", f"item {bad} is a {type(listed[bad - 1]).__name__}, not a Fit", field="fits")
        fits = {}
        for i, f in enumerate(listed, 1):
            if f.dataset_id in fits:
                raise InputError("population", f"fits {list(fits).index(f.dataset_id) + 1} and {i} are both of "
                                 f"{f.dataset_id}: give a mapping label -> Fit to tell subjects apart", field="fits")
            fits[f.dataset_id] = f
    else:
        raise InputError("population", f"expected a run folder, a mapping label -> Fit or a list of Fits (got "
                         f"{type(fits).__name__})", field="fits")
    bad = next((k for k, f in fits.items() if not isinstance(f, (Fit, DrawsFit))), None)
    if bad is not None:
        raise InputError("population", f"subject {bad}: a {type(fits[bad]).__name__}, not a Fit", field="fits")
    labels = {str(k) for k in fits}
    if len(labels) < len(fits):
        raise InputError("population", "subject labels that are the same as text (e.g. 1 and '1')", field="fits")
    if len(fits) < 2:
        raise InputError("population", f"expected at least two Fit objects (got {len(fits)})", field="fits")
    models = {f.model_id for f in fits.values()}
    if len(models) > 1:
        raise InputError("population", f"fits of different models ({', '.join(sorted(models))})", field="fits")
    return {str(k): v for k, v in fits.items()}


def subject_digest(fit):
    """sha256 of what a population reads of one subject's fit: its model, prior file and data
    (ids and the sha256 the fit records of them) and its posterior draws. The same for the fit
    in memory, loaded whole or loaded light (:func:`load_run`), and unchanged by what a
    comparison or a report adds to the file (evidence, LOO, summary)."""
    h = hashlib.sha256()
    attrs = fit.attrs
    h.update(json.dumps([str(attrs.get(k)) for k in ("model_id", "model_sha256", "priors_id", "priors_sha256",
                                                     "dataset_id", "dataset_sha256")]).encode())
    post = fit.group("posterior")
    for name in sorted(post.data_vars):
        values = np.ascontiguousarray(np.asarray(post[name].values, dtype=float))
        h.update(f"{name}{tuple(post[name].dims)}{values.shape}".encode())
        h.update(values.tobytes())
    return h.hexdigest()
