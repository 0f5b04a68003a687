"""Fits split by group: one independent fit per level of one or more grouping columns.

``skinfit fit MODEL DATASET --by subject --out RUN`` writes, for every subject,
``RUN/<group>/fit.nc`` and ``summary.csv``, plus ``RUN/index.json`` listing every group with
its label, rows, seed, convergence and path.  Parameters split by a condition column *inside*
one fit (``split=``) stay available within each group's fit.

Seeds: every group's seed is derived from the one base seed and the group's label
(:func:`derive_seed`), so a group's samples do not depend on which other groups exist or on
the order in which the groups are fitted.
"""

import hashlib
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from .data import Dataset, load_dataset
from .errors import InputError
from .fit import fit, load_fit
from .models import Model, load_model
from .posterior import _level_labels

__all__ = ["fit_by", "group_labels", "derive_seed", "load_groups"]


def derive_seed(seed, *key):
    """A 63-bit seed for one fit, from a base seed and a key of strings.

    ``numpy.random.SeedSequence(seed, spawn_key=sha256(key))``: stable across runs, machines
    and executors, and independent of every other key.
    """
    words = np.frombuffer(hashlib.sha256("\x1f".join(map(str, key)).encode()).digest(), dtype="<u4")
    ss = np.random.SeedSequence(int(seed), spawn_key=tuple(int(w) for w in words))
    return int(ss.generate_state(1, np.uint64)[0] >> np.uint64(1))


def group_labels(dataset, by, where="--by"):
    """Per row, the group label ``"col=value[,col=value]"`` (values in the data's own units).

    Returns
    -------
    labels : list of str, one per row of ``dataset.frame``
    levels : list of str, the distinct labels in order of appearance
    """
    by = [by] if isinstance(by, str) else list(by)
    if not by:
        raise InputError(where, "expected at least one grouping column")
    frame = dataset.frame
    for c in by:
        if c not in frame.columns:
            raise InputError(where, f"no column {c!r} in {dataset.path} (columns: "
                             f"{', '.join(frame.columns)}; declared groups: {', '.join(dataset.groups) or 'none'})")
    parts = [[f"{c}={v}" for v in _level_labels(frame, [c], dataset)] for c in by]
    labels = [",".join(t) for t in zip(*parts)]
    return labels, list(dict.fromkeys(labels))


def group_dir(label):
    """A file-system-safe folder name for a group label (``subject=S01`` -> ``subject-S01``)."""
    safe = "".join(ch if ch.isalnum() or ch in "._-" else "_" for ch in label.replace("=", "-"))
    return safe if label.isascii() else f"{safe}-{hashlib.sha256(label.encode()).hexdigest()[:8]}"


def fit_by(model, dataset, by, out_dir, *, priors=None, seed=None, split=None, noise=None,
           progress=False, ess_target=400, max_steps=20000, **fit_options):
    """Fit ``model`` separately to each group of ``dataset`` and write one result per group.

    Parameters
    ----------
    model, dataset, priors, split, noise, ess_target, max_steps
        As for :func:`skinfit.fit`; ``fit_options`` are passed on to it too.
    by : str or list of str
        Grouping column(s), e.g. ``"subject"`` or ``["subject", "material"]``.
    out_dir : path
        Gets ``<group>/fit.nc``, ``<group>/summary.csv`` and ``index.json``.
    seed : int, optional
        Base seed; group ``g`` is fitted with ``derive_seed(seed, g)``.  None draws fresh
        entropy, recorded in the index so the run can be repeated.

    Returns
    -------
    pandas.DataFrame
        The index: one row per group (label, rows, seed, converged, seconds, path).
    """
    model = model if isinstance(model, Model) else load_model(model)
    dataset = dataset if isinstance(dataset, Dataset) else load_dataset(dataset)
    by = [by] if isinstance(by, str) else list(by)
    labels, levels = group_labels(dataset, by)
    base = int(np.random.SeedSequence().entropy) if seed is None else int(seed)
    out_dir = Path(out_dir)
    labels = np.array(labels, dtype=object)
    rows = []
    for label in levels:
        sub = dataset.subset(labels == label, label)
        group_seed = derive_seed(base, label)
        t0 = time.perf_counter()
        result = fit(model, sub, priors=priors, rng=group_seed, split=split, noise=noise,
                     progress=progress, ess_target=ess_target, max_steps=max_steps, **fit_options)
        rel = Path(group_dir(label)) / "fit.nc"
        result.save(out_dir / rel)
        (out_dir / rel.parent / "summary.csv").write_text(result.summary().to_csv())
        rows.append({"group": label, "rows": len(sub), "seed": group_seed, "converged": result.converged,
                     "warnings": len(result.warnings),  # guard rails and misfit (the save completed it)
                     "seconds": round(time.perf_counter() - t0, 3), "path": rel.as_posix()})
        _write_json(out_dir / "index.json", {"model": model.id, "dataset": dataset.id, "by": by,
                                             "seed": base, "groups": rows})
    return pd.DataFrame(rows)


def load_groups(path):
    """The fits of a :func:`fit_by` run directory (its ``index.json``): ``{label: Fit}``."""
    path = Path(path)
    index = path / "index.json" if path.is_dir() else path
    if not index.exists():
        raise InputError(index, "no such index (expected the index.json written by `skinfit fit --by`)")
    doc = json.loads(index.read_text())
    return {g["group"]: load_fit(index.parent / g["path"]) for g in doc["groups"]}


def _write_json(path, doc):
    """Write JSON atomically (temporary file + rename)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".json.tmp")
    with os.fdopen(fd, "w") as fh:
        json.dump(doc, fh, indent=1, default=str)
    os.replace(tmp, path)
