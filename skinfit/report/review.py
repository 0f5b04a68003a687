"""The review page of ``skinfit ingest --review``: per trial a figure of its traces, filtered
signals, strokes found, kept windows and dropped strokes with their reasons, and a table of
every trial's status, so a person checks the segmentation before fitting; and
:func:`ingest` (``skinfit.ingest``), which writes it.  The page is written when every trial is
rejected too (no dataset then): that is when it helps most."""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path

import jinja2

from skinfit import __version__
from skinfit.errors import InputError
from skinfit.io.data import Dataset
from skinfit.io.paths import display
from skinfit.io.recordings.ingest import run_ingest
from skinfit.plots.recording import plot_trial

__all__ = ["ingest", "ingest_with_review", "write_review"]


def write_review(ingestion, folder):
    """Write ``folder/index.html`` and one PNG per trial for an
    :class:`skinfit.io.recordings.ingest.Ingestion` made with ``traces=True`` (its dataset may be
    None: every trial rejected); returns the page's path.  PNGs of an earlier run are removed."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for old in folder.glob("trial_*.png"):  # figures of an earlier run
        old.unlink()
    trials = []
    for i, r in enumerate(ingestion.trials):
        png = f"trial_{i:03d}.png"
        plot_trial(r, ingestion.rig, folder / png)
        trials.append({"name": r.name, "file": Path(r.file).name, "kept": r.kept, "reason": r.reason,
                       "found": len(r.strokes), "n_kept": len(r.rows), "png": png,
                       "anchor": re.sub(r"[^A-Za-z0-9_-]", "_", r.name),
                       "dropped": [f"{s['direction']} stroke at {s['start'] / r.rate:.2f} s: {s['reason']}"
                                   for s in r.strokes if s["reason"]]})
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(Path(__file__).parent / "templates"), autoescape=True,
                             undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True)
    rig = ingestion.rig
    ds = ingestion.dataset
    page = env.get_template("review.html.j2").render(
        title=f"Review of skinfit ingest ({Path(rig.path).name})", version=__version__, trials=trials,
        n_rows=len(ds) if ds is not None else 0, n_rejected=sum(not t["kept"] for t in trials),
        dataset=str(ingestion.folder) if ingestion.folder else (ds.id if ds is not None else ""),
        settings=rig.settings(), rig=rig.path, rig_sha256=rig.sha256)
    index = folder / "index.html"
    index.write_text(page, encoding="utf-8")
    return index


def ingest_with_review(files, rig, out, *, review=False):
    """(:class:`~skinfit.io.recordings.ingest.Ingestion`, path of the review page or None) of
    :func:`ingest`; with ``review`` the page ``out/review/index.html`` is written before the
    InputError of an ingestion that kept no trial is raised, that error then naming the page."""
    if review and out is None:
        raise InputError("review", "the review page is written into the dataset folder: give out= (a folder)")
    ing = run_ingest(files, rig, out, traces=review, strict=not review)
    page = write_review(ing, Path(out) / "review") if review else None
    if ing.error is not None:
        rejected = ing.trials[0]
        raise InputError(display(ing.rig.path), f"no trial kept, no dataset written: {len(ing.trials)} of "
                         f"{len(ing.trials)} trial(s) rejected (first: {rejected.name}: {rejected.reason}); each "
                         f"trial's traces and reason on the review page {display(page)} and in "
                         f"{display(Path(out) / 'trials.csv')}")
    return ing, page


def ingest(files: str | os.PathLike | Sequence[str | os.PathLike], rig: str | os.PathLike,
           out: str | os.PathLike | None = None, *, review: bool = False) -> Dataset:
    """Raw recordings -> a per-stroke :class:`~skinfit.Dataset`.

    ``files``: a path or paths of raw recordings (MATLAB v5/v7.3, HDF5, CSV); ``rig``: the rig
    file (TOML, docs/from-your-rig.md) stating the channels, units, gains or calibration
    matrix, bias windows, filters, stroke detection and rejection rule.  Each row is one stroke's
    kept window: the mean of each channel in SI with ``<name>_se`` (its standard error from the
    within-window scatter, corrected for autocorrelation, and from the bias subtracted),
    ``<name>_se_bias`` (the bias's part, shared by the strokes of one recording) and ``n_eff``,
    the direction, start time and duration [s], and the trial's metadata.  ``out``: a folder to
    write the dataset into (``data.csv``, ``dataset.toml``, ``trials.csv``), fitted with
    ``skinfit fit MODEL OUT``.  ``review``: also write ``out/review/index.html`` (each trial's
    traces, strokes and reason; needs ``out``).  When every trial is rejected: InputError
    (one line, each trial's reason, or with ``review`` the page's path), no dataset written, but
    ``out/trials.csv`` and the review page are.
    """
    return ingest_with_review(files, rig, out, review=review)[0].dataset
