"""Fits split by group: one independent fit per level of one or more grouping columns.

``skinfit fit MODEL DATASET --by subject --out RUN`` writes, for every subject,
``RUN/<group>/fit.nc`` and ``summary.csv``, plus ``RUN/index.json`` listing every group with
its label, rows, seed, convergence and path, and the dataset's card path and sha256.  A group
whose fit fails (a MAP with no possible start, ...) fails alone: the others are fitted and
saved, and the index lists it under ``failed`` with its one-line error.  The
folder of a group is :func:`group_dir` of its label (distinct for distinct labels); each fit
records its label and data hash, which :func:`load_groups` checks.  The run holds the lock a
plain ``skinfit fit --out RUN`` takes, so two runs into one folder cannot interleave.
Parameters split by a condition column *inside* one fit (``split=``) stay available within
each group's fit.

Seeds: every group's seed is derived from the one base seed and the group's label
(:func:`derive_seed`), so a group's samples do not depend on which other groups exist or on
the order in which the groups are fitted.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import time
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pandas as pd

from skinfit.errors import InputError, error_line
from skinfit.inference.checkpoint import CheckpointLock, load_checkpoint, remove_stale_temps, replace_atomic
from skinfit.inference.run import resolve_inputs
from skinfit.io.arguments import check_input_file, check_path, size_text
from skinfit.io.data import Dataset, load_dataset
from skinfit.io.labels import level_labels
from skinfit.io.paths import shipped_root
from skinfit.io.provenance import input_lines, input_record
from skinfit.results.fit import Fit, load_fit
from skinfit.results.fitting import fit

__all__ = ["fit_by", "group_labels", "derive_seed", "load_groups", "group_dir", "inside", "check_out_dir",
           "read_index", "index_document", "read_inputs",
           "record_source", "source_problem", "data_drift", "listed_problem", "reading", "index_drift",
           "missing_groups", "write_json"]


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
    parts = [[f"{c}={v}" for v in level_labels(frame, [c], dataset)] for c in by]
    labels = [",".join(t) for t in zip(*parts)]
    return labels, list(dict.fromkeys(labels))


def group_dir(label):
    """The folder of one group: a readable slug plus 8 hex of the sha256 of the exact label.

    ``subject=S01`` -> ``subject-S01-<hash>``.  Labels that differ only in characters a folder
    name cannot hold (``a/b``, ``a b``, ``a_b``) or only in case get distinct folders, and the
    name is a plain name (never ``..``, never a path), at most ~70 characters.
    """
    slug = re.sub(r"[^A-Za-z0-9._-]", "_", label.replace("=", "-"))[:60].lstrip("._-") or "g"
    return f"{slug}-{hashlib.sha256(label.encode()).hexdigest()[:8]}"


def inside(out, path):
    """``path`` resolved, after checking that it stays under ``out`` (InputError otherwise)."""
    root, target = Path(out).resolve(), Path(path).resolve()
    if not target.is_relative_to(root):
        raise InputError(path, f"would be written outside the output folder {root}")
    return target


def record_source(result, dataset, label, by):
    """Record in a fit's attrs what it was fitted to: the exact group label and the whole
    dataset's card path and sha256 (card + data file), checked when the result is reused."""
    result.idata.attrs["group"] = label
    result.idata.attrs["group_by"] = json.dumps(list(by))
    result.idata.attrs["source"] = json.dumps({"path": card_path(dataset), "sha256": dataset.sha256})


def card_path(dataset):
    """The absolute path of a dataset's card (``Dataset.path`` is shown relative to the checkout)."""
    return _absolute(dataset.path)


def _absolute(card):
    """A card path as recorded (a shipped card relative to the shipped folder) made absolute."""
    p, shipped = Path(card), shipped_root()
    return str((p if p.is_absolute() or shipped is None or not (shipped / p).exists() else shipped / p).resolve())


def source_problem(attrs, label, sha256):
    """Why a saved fit (its root ``attrs``) is not the fit of group ``label`` of the data with
    ``sha256``, or None.  Fits written before these records existed are judged by their ids."""
    if "source" in attrs:
        saved = json.loads(attrs["source"])["sha256"]
        if saved != sha256:
            return f"fitted to data with sha256 {saved[:12]}.., the data now have {sha256[:12]}.."
        if attrs.get("group", "") != label:
            return f"holds the fit of group {attrs.get('group')!r}, not {label!r}"
        return None
    return "records no data hash (written by an older skinfit)"


def listed_problem(attrs, label, sha256):
    """Why a saved fit (its root ``attrs``) listed in a run's index for group ``label`` of the
    data with ``sha256`` (None where the index records none) is not that fit, or None."""
    if sha256 is not None:
        return source_problem(attrs, label, sha256)
    if attrs.get("group", label) != label:  # an index written before the data hash was
        return f"holds the fit of group {attrs.get('group')!r}, not {label!r}"
    return None


@contextmanager
def reading(folder):
    """Read a run folder (a ``fit --by`` run or a campaign's out) while no writer holds it:
    the reader's side of the lock its writer takes (:class:`~skinfit.inference.checkpoint.CheckpointLock`
    ``shared=True`` on ``checkpoint.h5`` and ``campaign``).  A run being written (its index
    listing only the groups done so far) is an InputError naming the writer's pid."""
    folder = Path(folder)
    with CheckpointLock(folder / "checkpoint.h5", shared=True), CheckpointLock(folder / "campaign", shared=True):
        yield


def fit_by(model, dataset, by, out_dir, *, priors=None, seed=None, split=None, noise=None,
           progress=False, ess_target=400, max_steps=20000, overwrite=False, writes_card=False, **fit_options):
    """Fit ``model`` separately to each group of ``dataset`` and write one result per group.

    Parameters
    ----------
    model, dataset, priors, split, noise, ess_target, max_steps
        As for :func:`skinfit.fit`; ``fit_options`` are passed on to it too.
    by : str or list of str
        Grouping column(s), e.g. ``"subject"`` or ``["subject", "material"]``.
    out_dir : path
        Gets ``<group>/fit.nc``, ``<group>/summary.csv`` and ``index.json``; one holding a run
        by groups is refused unless ``overwrite`` (:func:`check_out_dir`), as is one holding
        another kind of result. ``writes_card``: the caller writes the dataset's card to
        ``out_dir/dataset`` afterwards (that folder is then checked too).
    seed : int, optional
        Base seed; group ``g`` is fitted with ``derive_seed(seed, g)``.  None draws fresh
        entropy, recorded in the index so the run can be repeated.

    Returns
    -------
    pandas.DataFrame
        The index: one row per group (label, rows, seed, converged, seconds, path, status):
        ``status`` is ``done``, or ``failed: Class: message`` for a group whose fit raised (its
        other columns empty), which the others do not wait for.  When every group fails, the
        first group's exception is raised (after the index lists them all).
    """
    from_file = not isinstance(dataset, Dataset)  # else it may be a subset: its hash is not the file's
    dataset = load_dataset(dataset) if from_file else dataset
    model, dataset, priors = resolve_inputs(model, dataset, priors)
    by = [by] if isinstance(by, str) else list(by)
    check_out_dir(out_dir, model, priors, dataset, by, overwrite=overwrite, writes_card=writes_card)
    labels, levels = group_labels(dataset, by)
    base = int(np.random.SeedSequence().entropy) if seed is None else int(seed)
    out_dir = Path(out_dir)
    labels = np.array(labels, dtype=object)
    rows, failed, first = [], [], None
    header = {"model": model.id, "dataset": dataset.id, "by": by, "seed": base,
              "dataset_path": card_path(dataset), "dataset_sha256": dataset.sha256, "dataset_is_file": from_file,
              "model_sha256": model.sha256, "priors_sha256": priors.sha256,
              "inputs": input_record(model, priors, dataset)}
    # the lock a plain `skinfit fit --out` takes: two runs on one folder never interleave
    with CheckpointLock(out_dir / "checkpoint.h5"):
        # again, holding the lock: a run into this folder that ended since the check above
        check_out_dir(out_dir, model, priors, dataset, by, overwrite=overwrite, writes_card=writes_card)
        remove_stale_temps(out_dir, recursive=False)  # a killed run's half-written index (writer pid dead)
        for label in levels:
            remove_stale_temps(out_dir / group_dir(label), recursive=False)  # and group files: only in its folders
            sub = dataset.subset(labels == label, label)
            group_seed = derive_seed(base, label)
            t0 = time.perf_counter()
            try:
                result = fit(model, sub, priors=priors, rng=group_seed, split=split, noise=noise,
                             progress=progress, ess_target=ess_target, max_steps=max_steps, **fit_options)
            except Exception as exc:  # this group's fit fails alone: listed with its error, the others go on
                failed.append({"group": label, "rows": len(sub), "seed": group_seed, "error": error_line(exc)})
                write_json(out_dir / "index.json", {**header, "groups": rows, "failed": failed})
                first = first or exc
                continue
            record_source(result, dataset, label, by)
            rel = Path(group_dir(label)) / "fit.nc"
            result.save(inside(out_dir, out_dir / rel))
            (out_dir / rel.parent / "summary.csv").write_text(result.summary().to_csv())
            rows.append({"group": label, "rows": len(sub), "seed": group_seed, "converged": result.converged,
                         "warnings": len(result.warnings), "seconds": round(time.perf_counter() - t0, 3),
                         "path": rel.as_posix()})
            write_json(out_dir / "index.json", {**header, "groups": rows, "failed": failed})
    if not rows and first is not None:  # every group failed (a bad option fails them all): the first error
        raise first
    table = pd.DataFrame([{**r, "status": "done"} for r in rows] + [
        {"group": f["group"], "rows": f["rows"], "seed": f["seed"], "converged": False, "warnings": 0,
         "seconds": np.nan, "path": None, "status": f"failed: {f['error']}"} for f in failed],
        columns=["group", "rows", "seed", "converged", "warnings", "seconds", "path", "status"])
    return table


def read_inputs(run):
    """The lines that say which model card, prior file and data file the fits of the run by
    groups in folder ``run`` read (:func:`skinfit.io.provenance.input_lines` of its index.json);
    an index without them (an older skinfit's) says so."""
    try:
        doc = json.loads((Path(run) / "index.json").read_text(encoding="utf-8"))
        return input_lines({"inputs": json.dumps(doc["inputs"]), "model_sha256": doc["model_sha256"],
                            "priors_sha256": doc["priors_sha256"]})
    except (OSError, ValueError, KeyError, TypeError):
        return [f"inputs: not recorded in {Path(run) / 'index.json'}"]


#: Largest index.json read [bytes] (a campaign's of 10 000 fits is ~5 MB).
MAX_INDEX_BYTES = 256 << 20

_INDEX_KINDS = "expected a `fit --by` index (with 'groups') or a campaign index (a list)"


def index_document(index):
    """An index.json read, with its kind: ``("by", dict)`` for a ``skinfit fit --by`` run's,
    ``("campaign", list of rows)`` for a campaign's; InputError when it is not JSON or neither."""
    check_input_file(index, "index.json of a run")  # a FIFO or /dev/zero refused, not waited on or read without end
    size = os.path.getsize(index)
    if size > MAX_INDEX_BYTES:
        raise InputError(index, f"{size_text(size)}: larger than any index.json skinfit writes "
                                f"(at most {size_text(MAX_INDEX_BYTES)} are read)")
    try:
        doc = json.loads(Path(index).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(index, f"not readable as JSON ({exc})") from None
    if isinstance(doc, list):
        return "campaign", doc
    if isinstance(doc, dict):
        return "by", doc
    raise InputError(index, _INDEX_KINDS)


def read_index(path):
    """The completed fits a run's index.json lists, for readers of either kind of run: a
    ``skinfit fit --by`` run (a dict with ``groups``) or a campaign (a list of rows, of which
    those with status done or complete). ``path``: the index or its folder.

    Returns ``(rows, skipped)``: each row a dict with ``model``, ``dataset``, ``group`` (None
    for a whole dataset), ``path`` (a relative path read from the index's folder; the file
    must exist) and ``dataset_sha256`` (the data the index says it was fitted to; None where
    it records none), and the number of rows not complete (campaign rows failed or pending,
    or groups of a ``fit --by`` run whose fit failed)."""
    path = Path(check_path(path, "index", None, "a run directory or its index.json"))
    index = path / "index.json" if path.is_dir() else path
    if not index.exists():
        raise InputError(index, "no such index (expected the index.json of `skinfit fit --by` or of a campaign)")
    kind, doc = index_document(index)
    failed = 0
    header_sha256 = doc.get("dataset_sha256") if kind == "by" else None
    if kind == "campaign":
        listed = [r for r in doc if not isinstance(r, dict) or r.get("status", "done") in ("done", "complete")]
    elif isinstance(doc.get("groups"), list):
        listed = [dict(g, model=doc.get("model"), dataset=doc.get("dataset")) if isinstance(g, dict) else g
                  for g in doc["groups"]]
        failed = len(doc.get("failed") or [])
    else:
        raise InputError(index, _INDEX_KINDS)
    rows = []
    for i, r in enumerate(listed, start=1):
        if not isinstance(r, dict) or not isinstance(r.get("path"), str):
            raise InputError(index, "expected a 'path' for each fit", row=i)
        fit_path = Path(r["path"]) if Path(r["path"]).is_absolute() else index.parent / r["path"]
        if not fit_path.is_file():
            raise InputError(index, f"lists {r['path']}, which does not exist", row=i)
        rows.append({"model": r.get("model"), "dataset": r.get("dataset"), "group": r.get("group"),
                     "path": fit_path, "dataset_sha256": r.get("dataset_sha256", header_sha256)})
    return rows, (len(doc) - len(listed) if isinstance(doc, list) else failed)


def load_groups(path: str | os.PathLike) -> dict[str, Fit]:
    """The fits of a :func:`fit_by` run directory (its ``index.json``): ``{label: Fit}``.

    Each fit must hold the group it is listed under and the data the index records (its
    ``group`` and ``source`` attrs): a mixed-up or stale folder is an InputError, not a wrong
    answer.  Data edited since the fits were made gives a warning, as do groups whose fit
    failed (listed under ``failed``: they are not among the fits returned).
    """
    path = Path(check_path(path, "load_groups", None, "the run directory of `skinfit fit --by` or its index.json"))
    index = path / "index.json" if path.is_dir() else path
    with reading(index.parent):
        fits, doc = _load_listed(index)
    failed = [f.get("group") for f in doc.get("failed") or [] if isinstance(f, dict)]
    if failed:
        warnings.warn(f"{index}: the fits of {len(failed)} group(s) failed and are left out "
                      f"({', '.join(map(str, failed))}): see their errors there", UserWarning, stacklevel=2)
    message = index_drift(index, doc)
    if message:
        warnings.warn(message, UserWarning, stacklevel=2)
    return fits


def missing_groups(doc):
    """The groups of a ``fit --by`` run's data (the card its index records) that its index does
    not list, e.g. after a run was killed part-way: labels in the data's order.  Empty when the
    data cannot be found or read (results moved to another machine, or changed: see
    :func:`index_drift`)."""
    card, by = doc.get("dataset_path"), doc.get("by")
    if not (card and doc.get("dataset_is_file") and isinstance(by, list) and Path(card).exists()):
        return []
    try:
        _, levels = group_labels(load_dataset(card), by)
    except InputError:
        return []
    listed = {g.get("group") for g in doc.get("groups", []) if isinstance(g, dict)}
    return [label for label in levels if label not in listed]


def index_drift(index, doc, who="the fits"):
    """Why the fits of a ``fit --by`` run (its ``index`` path and document) are not of the data
    file now at the card the index records (its sha256 differs), or None (the same, or the
    card not found: results may be moved to another machine).  ``who`` names the fits."""
    card, recorded = doc.get("dataset_path"), doc.get("dataset_sha256")
    if not (card and recorded and doc.get("dataset_is_file") and Path(card).exists()):
        return None
    try:
        now = load_dataset(card).sha256
    except InputError as exc:
        now = f"unreadable ({exc})"
    if now == recorded:
        return None
    return (f"{index}: {who} were made from {card} with sha256 {recorded[:12]}.., which now has {now[:12]}..: "
            "fit again to use the current data")


def _load_listed(index):
    """The fits of a ``fit --by`` run's index, each checked to be the fit it is listed as."""
    if not index.exists():
        raise InputError(index, "no such index (expected the index.json written by `skinfit fit --by`)")
    kind, doc = index_document(index)
    if kind != "by" or not isinstance(doc.get("groups"), list):
        raise InputError(index, "not the index.json of `skinfit fit --by` (with 'groups')")
    fits = {}
    for i, g in enumerate(doc["groups"], start=1):
        if not isinstance(g, dict) or not isinstance(g.get("group"), str) or not isinstance(g.get("path"), str):
            raise InputError(index, "expected a 'group' and a 'path' for each group", row=i)
        label = g["group"]
        if label in fits:
            raise InputError(index, f"group {label!r} is listed twice")
        fit_path = inside(index.parent, index.parent / g["path"])
        result = load_fit(fit_path)
        problem = listed_problem(result.attrs, label, doc.get("dataset_sha256"))
        if problem:
            raise InputError(fit_path, f"listed for group {label!r} in {index} but {problem}")
        fits[label] = result
    return fits, doc


def data_drift(fits):
    """Messages for the saved fits whose data file has changed since they were made.

    ``fits`` is a list of ``(where, Fit)``; each fit's recorded card path and sha256 (its
    ``source`` attr, else its ``dataset_path`` and ``dataset_sha256`` when it was fitted to a
    whole dataset) are compared with the file now there.  Data that cannot be found are not
    reported (results may be moved to another machine); each card is read once.
    """
    current, messages = {}, []
    for where, result in fits:
        attrs = result.attrs
        if "source" in attrs:
            recorded = json.loads(attrs["source"])
            card, sha256 = recorded["path"], recorded["sha256"]
        elif "[" not in attrs.get("dataset_id", "["):  # a subset's hash is not its file's
            card, sha256 = attrs.get("dataset_path", ""), attrs.get("dataset_sha256")
            card = _absolute(card) if card else card
        else:
            continue
        if not card or not Path(card).exists():
            continue
        if card not in current:
            try:
                current[card] = load_dataset(card).sha256
            except InputError as exc:
                current[card] = f"unreadable ({exc})"
        if current[card] != sha256:
            messages.append(f"{where}: fitted to {card} with sha256 {sha256[:12]}.., which now has "
                            f"{current[card][:12]}..: this result is not of the current data")
    return messages


def check_out_dir(out_dir, model, priors, dataset, by=None, *, overwrite=False, resume=False, writes_card=False):
    """Refuse, before anything is fitted or written, an output folder whose results the fit
    would replace without being asked (one-line InputError, nothing written).

    Always refused: the other kind of run (a single fit's ``fit.nc`` for a run by groups, a run
    by groups' ``index.json`` for a single fit) and a campaign's results (its index.json a list
    of rows): the folder would hold two runs' files mixed. A folder holding this kind's result
    (``fit.nc`` or ``index.json``), its ``summary.csv``, the checkpoint of a single fit
    (``checkpoint.h5``) or, when ``writes_card`` (a CSV without a card: its card goes to
    ``OUT/dataset``), a ``dataset`` folder: refused unless ``overwrite`` (replace them) or, for a
    single fit with a checkpoint, ``resume`` (continue it; :func:`skinfit.fit` then refuses a
    checkpoint of other inputs). The message says what is there: a fit of which model on which
    data, and whether it was made from other inputs (another model card, prior file, data or
    grouping, their sha256 as recorded).
    ``model``, ``priors``, ``dataset``: the Model, PriorSet and Dataset about to be fitted."""
    out_dir = Path(out_dir)
    if overwrite and resume:
        raise InputError("--resume", "and --overwrite contradict each other: --resume continues the fit in --out, "
                                     "--overwrite replaces it")
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(out_dir, "is a file: --out names the folder the results go into (nothing was written)")
    single, index, checkpoint = out_dir / "fit.nc", out_dir / "index.json", out_dir / "checkpoint.h5"
    mine, other, held, this = ((single, index, "a run by groups (index.json)", "a single fit") if by is None else
                               (index, single, "a single fit (fit.nc)", "the run by groups"))
    if index.exists() and _is_campaign_index(index):  # neither kind of run of skinfit fit
        raise InputError(out_dir, f"holds a campaign's results (index.json of skinfit campaign): give {this} "
                                  "another --out (nothing was written)")
    if other.exists():
        raise InputError(out_dir, f"holds {held}: give {this} another --out (nothing was written)")
    ckpt = by is None and checkpoint.exists()
    if resume and by is None:
        if ckpt:
            return  # fit() continues the checkpoint, refusing one of other inputs
        if mine.exists():
            raise InputError(out_dir, "holds a finished fit (fit.nc) and no checkpoint to resume: --overwrite to "
                                      "replace it, or give another --out (nothing was written)")
    there = [p.name for p in (mine, out_dir / "summary.csv", *((checkpoint,) if by is None else ()),
                              *((out_dir / "dataset",) if writes_card else ())) if p.exists()]
    if not there or overwrite:
        return
    options = "--overwrite to replace it" + (", --resume to continue from its checkpoint" if ckpt else "")
    if not mine.exists():
        what = (f"the checkpoint of a fit not finished ({_checkpoint_text(checkpoint)})" if ckpt and
                there == ["checkpoint.h5"] else f"{', '.join(there)} (of an earlier fit)")
        raise InputError(out_dir, f"holds {what}: {options}, or give another --out (nothing was written)")
    new = {"model_id": model.id, "model_sha256": model.sha256, "priors_sha256": priors.sha256,
           "dataset_sha256": dataset.sha256}
    try:
        if by is None:
            attrs = load_fit(single).attrs
            old = {k: str(attrs[k]) for k in new if k in attrs}
            what = f"a fit of {attrs['model_id']} on {attrs.get('dataset_id', '?')}"
        else:
            doc = index_document(index)[1]
            old = {"model_id": doc["model"], "dataset_sha256": doc["dataset_sha256"], "by": doc["by"],
                   **{k: doc[k] for k in ("model_sha256", "priors_sha256") if k in doc}}
            new["by"] = list(by)
            what = f"a run of {doc['model']} by {', '.join(map(str, doc['by']))}"
    except (InputError, OSError, ValueError, KeyError, TypeError):
        article = "a" if by is None else "an"
        raise InputError(out_dir, f"holds {article} {mine.name} that skinfit cannot read: {options}, or give another "
                                  "--out (nothing was written)") from None
    differ = [k for k in new if k in old and old[k] != new[k]]  # an older index records no card / prior sha256
    made = (f", made from {_inputs_text(differ)} than this fit of {model.id} on {dataset.id}" if differ else
            ", made from the same model card, prior file and data")
    raise InputError(out_dir, f"holds {what}{made}: {options}, or give another --out (nothing was written)")


def _checkpoint_text(path):
    """How far the checkpoint at ``path`` got, in words (its iteration), or that it is unreadable."""
    try:
        return f"checkpoint.h5 at step {load_checkpoint(path).iteration}"
    except Exception:  # only said in a message: any unreadable file is just named
        return "checkpoint.h5, unreadable"


def _is_campaign_index(index):
    """True when ``index`` is a campaign's index.json (:func:`index_document`)."""
    try:
        return index_document(index)[0] == "campaign"
    except InputError:
        return False


def _inputs_text(keys):
    """What differs, in words: "another model", "another prior file and other data", ..."""
    parts = ["another model"] if "model_id" in keys else [
        *(["another " + " / ".join(n for k, n in (("model_sha256", "model card"), ("priors_sha256", "prior file"))
                                   if k in keys)] if {"model_sha256", "priors_sha256"} & set(keys) else []),
        *(["other data"] if "dataset_sha256" in keys else [])]
    return " and ".join(parts + (["another grouping"] if "by" in keys else []))


def write_json(path, doc):
    """Write JSON atomically (temporary file + rename): an index or record that readers may
    open at any time."""
    replace_atomic(path, json.dumps(doc, indent=1, default=str).encode())
