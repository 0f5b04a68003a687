"""The ingestion behind ``skinfit.ingest``: raw recordings + a rig file -> a dataset folder, one row per stroke.

Each trial is read and filtered by chunks (:class:`skinfit.io.recordings.signal.Chunker`);
strokes are found on the filtered velocity and normal force; a stroke still open at a chunk's
end is carried into the next (its samples only), so memory holds one chunk plus one stroke.
Each kept window becomes a row (:func:`skinfit.io.recordings.strokes.reduce_window`).  A trial
off its target (the rig's ``[reject]``) or without strokes is rejected with its reason; every
trial and every dropped stroke is listed in ``trials.csv`` and the card's provenance: nothing is
dropped silently.  When every trial is rejected no dataset is written (``data.csv`` and
``dataset.toml`` of an earlier run in the folder are removed), ``trials.csv`` still is, and the
error is raised, or with ``strict=False`` returned in :attr:`Ingestion.error` so that the caller
writes the review page first (:func:`skinfit.report.review.ingest`).  The card records each
raw file's sha256, the rig file's sha256 and text, and the pipeline's settings.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import hashlib
import json
import os
import re
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pandas as pd

from skinfit.errors import InputError
from skinfit.io.arguments import check_input_file, check_path
from skinfit.io.data import Column, Dataset, load_dataset, write_card
from skinfit.io.paths import display
from skinfit.io.recordings.read import open_trials
from skinfit.io.recordings.rig import Rig, load_rig
from skinfit.io.recordings.signal import Chunker
from skinfit.io.recordings.strokes import reduce_window, runs, window

__all__ = ["run_ingest", "Ingestion", "TrialRecord", "CHUNK_SECONDS"]

#: Seconds of samples filtered at once (60 s at 10 kHz: 600 000 samples a channel).
CHUNK_SECONDS = 60.0
_TRACE_POINTS = 6000  # samples kept per trial for the review figures (evenly spaced)


@dataclass
class TrialRecord:
    """What became of one trial: its strokes (start, stop, kept window, direction, reason) in
    base-rate samples, its status and the reason it was rejected ("" when kept)."""

    name: str
    file: str
    rate: float
    n: int
    metadata: dict
    strokes: list = field(default_factory=list)
    rows: list = field(default_factory=list)
    reason: str = ""
    traces: dict = field(default_factory=dict)  # {"t": (m,), name: (m,), "raw:" + name: (m,)} for the review

    @property
    def kept(self):
        return not self.reason


@dataclass
class Ingestion:
    """The result of :func:`run_ingest`: the dataset (kept trials' strokes) and every trial's
    record; with no trial kept (``strict=False``) ``dataset`` is None and ``error`` the
    InputError saying so, for the caller to raise once the review page is written."""

    dataset: Dataset | None
    trials: list
    rig: Rig
    folder: Path | None
    error: InputError | None = None


def _signal_names(rig):
    """The signals reduced per stroke: every channel after calibration but the position channel
    (and a channel with ``output = false``)."""
    outs = {c.name: c.output for c in rig.channels}
    return [n for n in rig.derived if n != rig.position and outs.get(n, True)]


def _trial(trial, rig, chunk_seconds, traces):
    where = f"{display(trial.file)}" + (f":{trial.name}" if rig.format == "hdf5" else "")
    ch = Chunker(trial, rig, where)
    n, rate = ch.n, ch.rate
    record = TrialRecord(trial.name, str(trial.file), rate, n, dict(trial.attrs))
    names = _signal_names(rig)
    rectify = {c.name for c in rig.channels if c.rectify}
    chunk = max(int(chunk_seconds * rate), 4 * ch.margin, 1000)
    step = max(n // _TRACE_POINTS, 1)
    kept_traces = []
    pending, pending_start = None, 0
    for start in range(0, n, chunk):
        stop = min(start + chunk, n)
        sig = ch.signals(start, stop)
        if traces:
            first = -(-start // step) * step
            idx = np.arange(first, stop, step)
            raw = ch.raw(start, stop)
            kept_traces.append({"t": idx / rate, **{k: v[idx - start] for k, v in sig.items()},
                                **{"raw:" + k: v[idx - start] for k, v in raw.items()}})
        buf, off = sig, start
        if pending is not None:
            buf, off = {k: np.concatenate([pending[k], sig[k]]) for k in sig}, pending_start
        v, fn = buf["velocity"], buf[rig.normal]
        code = np.where((np.abs(v) > rig.speed_above) & (fn > rig.normal_force_above), np.sign(v), 0)
        pending = None
        for a, b, sign in runs(code):
            if b == len(code) and stop < n:  # still sliding at the chunk's end: carried into the next
                pending, pending_start = {k: x[a:] for k, x in buf.items()}, off + a
                break
            _stroke(record, rig, buf, off, a, b, sign, names, rectify, ch)
    if traces and kept_traces:
        record.traces = {k: np.concatenate([t[k] for t in kept_traces]) for k in kept_traces[0]}
    _reject(record, rig)
    return record


def _stroke(record, rig, buf, off, a, b, sign, names, rectify, chunker):
    rate = record.rate
    ka, kb, reason = window(off + a, off + b, rate, rig.trim, rig.min_duration)
    direction = "forward" if sign > 0 else "backward"
    record.strokes.append({"start": off + a, "stop": off + b, "kept_start": ka, "kept_stop": kb,
                           "direction": direction, "reason": reason})
    if reason:
        return
    piece = {k: x[ka - off: kb - off] for k, x in buf.items()}
    row = {"direction": direction, "start_time": ka / rate, "duration": (kb - ka) / rate, "n_samples": kb - ka}
    row.update(reduce_window(piece, names, rectify, max(int(rate // (5 * rig.lowpass)), 1)))
    bias_se = chunker.bias_se((ka + kb) / 2 / rate)
    for name in names:  # the bias's part kept apart too: shared by the trial's strokes, not independent
        row[f"{name}_se_bias"] = float(bias_se.get(name, 0.0))
        row[f"{name}_se"] = float(np.hypot(row[f"{name}_se"], row[f"{name}_se_bias"]))
    record.rows.append(row)


def _reject(record, rig):
    if not record.rows:
        record.reason = "no stroke found (|v| above speed_above with the normal force above normal_force_above, " \
                        "kept window >= min_duration)"
        return
    if rig.reject is None:
        return
    channel, target, tol = rig.reject["channel"], rig.reject["target"], rig.reject["tolerance"]
    if isinstance(target, str):
        value = record.metadata.get(target)
        if not isinstance(value, (int, float)):
            raise InputError(rig.path, f"trial {record.name}: metadata {target!r} is {value!r}, expected a number "
                             "(declare it under [metadata] with its unit)", field="reject.target")
        target = float(value)
    mean = float(np.mean([r[channel] for r in record.rows]))
    if target > 0 and abs(mean - target) > tol * target:
        unit = rig.derived[channel][1]
        record.reason = (f"mean {channel} {mean:.4g} {unit} is {100 * abs(mean - target) / target:.0f}% off the "
                         f"target {target:.4g} {unit} (tolerance {100 * tol:.0f}%)")


def _frame(records, rig, names):
    meta = list(rig.metadata)
    for r in records:
        meta += [k for k in r.metadata if k not in meta]
    rows = []
    for r in records:
        if not r.kept:
            continue
        missing = [k for k in rig.metadata if k not in r.metadata]
        if missing:
            raise InputError(display(r.file), f"trial {r.name} has no value for metadata {missing[0]!r} declared in "
                             f"the rig file (expected from the file-name pattern, an HDF5 attribute of the trial, or "
                             f"metadata.{missing[0]}.value)", field=f"metadata.{missing[0]}")
        for s in r.rows:
            rows.append({"recording": r.name, **{k: r.metadata.get(k, "") for k in meta}, **s})
    order = ["recording", *meta, "direction", "start_time", "duration", "n_samples", "n_eff"]
    order += [c for n in names for c in (n, f"{n}_se", f"{n}_se_bias")] + ["speed", "speed_se"]
    return pd.DataFrame(rows, columns=order), meta


def _columns(frame, rig, meta):
    derived = rig.derived
    cols = [Column("recording", "recording", None, "category")]
    for k in meta:
        spec = rig.metadata.get(k)
        if spec and spec["unit"]:
            signed = bool((pd.to_numeric(frame[k]) < 0).any())
            cols.append(Column(k, k, spec["si_unit"], "quantity", signed=signed))
        else:
            cols.append(Column(k, k, None, "category"))
    cols += [Column("direction", "direction", None, "category"), Column("start_time", "start_time", "s", "quantity"),
             Column("duration", "duration", "s", "quantity"), Column("n_samples", "n_samples", "1", "quantity"),
             Column("n_eff", "n_eff", "1", "quantity")]
    for name in frame.columns[len(cols):]:
        base = re.sub(r"_se(_bias)?$", "", name)
        unit = "m/s" if base == "speed" else derived[base][1]
        signed = base == name and bool((frame[name] < 0).any())
        cols.append(Column(name, name, unit, "quantity", signed=signed))
    return tuple(cols)


def _sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _write(records, rig, files, folder, dataset_id):
    names = _signal_names(rig)
    frame, meta = _frame(records, rig, names)
    if frame.empty:
        return None
    cols = _columns(frame, rig, meta)
    folder.mkdir(parents=True, exist_ok=True)
    data = folder / "data.csv"
    frame.to_csv(data, index=False, float_format="%.10g")
    _write_trials(records, folder)
    provenance = {
        "kind": "measured", "note": "per-stroke means from raw recordings by skinfit ingest (rig file below)",
        "source_file": str(data.resolve()), "sha256": _sha256(data),
        "raw_files": [str(Path(f).resolve()) for f in files], "raw_sha256": [_sha256(f) for f in files],
        "rig_file": rig.path, "rig_sha256": rig.sha256, "rig_text": rig.text, "pipeline": rig.settings(),
        "rejected_trials": [f"{r.name}: {r.reason}" for r in records if not r.kept],
        "trials_file": "trials.csv",
    }
    groups = tuple(c.name for c in cols if c.kind == "category" and c.name != "direction")
    ds = Dataset(dataset_id, f"{len(frame)} strokes from {len(files)} raw file(s) ({Path(rig.path).name})", frame,
                 cols, groups, MappingProxyType(provenance), None, str(folder), "")
    write_card(ds, folder)
    card = folder / "dataset.toml"
    text = card.read_text(encoding="utf-8").replace(f"source_file = {json.dumps(str(data.resolve()))}\n", "")
    card.write_text(_signed(text, cols), encoding="utf-8")
    return load_dataset(folder)


def _write_trials(records, folder):
    """``folder/trials.csv``: every trial's status, reason, strokes found and kept, dropped strokes."""
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / "trials.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["recording", "file", "status", "reason", "strokes_found", "strokes_kept", "dropped_strokes"])
        for r in records:
            dropped = "; ".join(f"{s['direction']} stroke at {s['start'] / r.rate:.3f} s: {s['reason']}"
                                for s in r.strokes if s["reason"])
            w.writerow([r.name, Path(r.file).name, "kept" if r.kept else "rejected", r.reason, len(r.strokes),
                        len(r.rows), dropped])


def _none_kept(records, rig, folder):
    """The InputError of an ingestion that kept no trial, every trial's reason in it; with an
    output ``folder``, its ``trials.csv`` written and an earlier run's dataset removed (a stale
    dataset beside this run's trials.csv would be read as this run's)."""
    reasons = "; ".join(f"{r.name}: {r.reason}" for r in records)
    if folder is None:
        return InputError(display(rig.path), f"no trial kept, no dataset written ({reasons})")
    _write_trials(records, folder)
    for old in ("data.csv", "dataset.toml"):
        (folder / old).unlink(missing_ok=True)
    return InputError(display(rig.path), f"no trial kept, no dataset written ({reasons}; every trial in "
                      f"{display(folder / 'trials.csv')})")


def _signed(text, cols):
    """The card with ``signed = true`` under each column that holds negative values."""
    for c in cols:
        if c.signed and c.unit:
            head = f"[columns.{json.dumps(c.header)}]\nname = {json.dumps(c.name)}\nunit = {json.dumps(c.unit)}\n"
            text = text.replace(head, head + "signed = true\n")
    return text


def run_ingest(files, rig, out=None, *, traces=False, chunk_seconds=CHUNK_SECONDS, strict=True):
    """Ingest raw recordings ``files`` (paths) as the rig file ``rig`` (a path or a loaded Rig)
    describes: an :class:`Ingestion` with the dataset and every trial's record; ``traces`` keeps
    a thinned copy of each trial's signals for the review page.  With no trial kept: InputError
    (``out/trials.csv`` written first), or with ``strict=False`` that error in ``Ingestion.error``
    and ``dataset`` None."""
    if isinstance(files, (str, os.PathLike)):
        files = [files]
    files = [Path(check_input_file(check_path(f, "files", None, "paths of raw recordings"), "raw recording"))
             for f in files]
    if not files:
        raise InputError("files", "expected at least one raw recording")
    rig = rig if isinstance(rig, Rig) else load_rig(check_path(rig, "rig", None, "the path of a rig file (TOML)"))
    handles = []
    try:
        trials = open_trials(rig, files, handles)
        records = [_trial(t, rig, chunk_seconds, traces) for t in trials]
    finally:
        for h in handles:
            with contextlib.suppress(Exception):
                h.close()
    dataset_id = _id(Path(out).name if out is not None else Path(rig.path).stem)
    folder = Path(out) if out is not None else None
    if out is not None:
        ds = _write(records, rig, files, folder, dataset_id)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            ds = _write(records, rig, files, Path(tmp) / "dataset", dataset_id)
            if ds is not None:
                ds = dataclasses.replace(ds, card_file="", data_file="", path=f"ingest of {Path(rig.path).name}")
    if ds is None:
        error = _none_kept(records, rig, folder)
        if strict:
            raise error
        return Ingestion(None, records, rig, folder, error)
    return Ingestion(ds, records, rig, folder)


def _id(text):
    return re.sub(r"[^A-Za-z0-9_.+-]", "_", text).lstrip(".") or "ingested"
