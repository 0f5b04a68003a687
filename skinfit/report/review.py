"""The review page of ``skinfit ingest --review``: per trial a figure of its traces, filtered
signals, strokes found, kept windows and dropped strokes with their reasons, and a table of
every trial's status, so a person checks the segmentation before fitting."""

import re
from pathlib import Path

import jinja2

from skinfit import __version__
from skinfit.plots.recording import plot_trial

__all__ = ["write_review"]


def write_review(ingestion, folder):
    """Write ``folder/index.html`` and one PNG per trial for an
    :class:`skinfit.io.recordings.ingest.Ingestion` made with ``traces=True``; returns the page's path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
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
    page = env.get_template("review.html.j2").render(
        title=f"Review of skinfit ingest ({Path(rig.path).name})", version=__version__, trials=trials,
        n_rows=len(ingestion.dataset), n_rejected=sum(not t["kept"] for t in trials),
        dataset=str(ingestion.folder) if ingestion.folder else ingestion.dataset.id, settings=rig.settings(),
        rig=rig.path, rig_sha256=rig.sha256)
    index = folder / "index.html"
    index.write_text(page, encoding="utf-8")
    return index
