"""A report folder's figures/ and its record of the figures it drew: unchanged ones are kept.

``figures/.figures.json`` records, for each figure the report drew (its PNG file name), the
key of what it was drawn from (the fits' content, the plot function and its arguments, the
skinfit source and plotting libraries: :func:`skinfit.report.figures.job_keys`) and the sha256
and size of its PNG and PDF as written. A report into the same folder keeps a figure whose key
is the same and whose two files still hold what was written; any other is drawn again (a
damaged or edited figure included). Nothing is written outside figures/.

A file is removed only when the record lists it and it still holds what the record says was
written: a file the user put in figures/ (any name), or a figure edited since, is never removed.
"""

import hashlib
import json
from pathlib import Path

from skinfit.inference.checkpoint import replace_atomic

__all__ = ["FigureFolder", "MANIFEST", "SUFFIXES"]

#: The record's file name in figures/.
MANIFEST = ".figures.json"
#: A figure's files: the PNG shown in the page and its PDF for papers.
SUFFIXES = (".png", ".pdf")
_SIGNATURE = "skinfit report: the figures this folder's report drew"


def file_record(path):
    """{"sha256", "size"} of the file at ``path``; None when it cannot be read."""
    try:
        data = Path(path).read_bytes()
    except OSError:
        return None
    return {"sha256": hashlib.sha256(data).hexdigest(), "size": len(data)}


def _holds(path, record):
    """True when the file at ``path`` holds what ``record`` (:func:`file_record`) says."""
    try:
        if Path(path).stat().st_size != record["size"]:
            return False
    except OSError:
        return False
    return file_record(path) == record


def _valid(name, entry):
    """True for a record entry the report wrote: a plain PNG file name, a key, both files' records."""
    if not isinstance(name, str) or name != Path(name).name or name.startswith(".") or not name.endswith(".png"):
        return False
    if not isinstance(entry, dict) or not isinstance(entry.get("key"), str) or not isinstance(entry.get("files"), dict):
        return False
    files = entry["files"]
    return set(files) == set(SUFFIXES) and all(
        isinstance(r, dict) and set(r) == {"sha256", "size"} and isinstance(r["sha256"], str)
        and isinstance(r["size"], int) for r in files.values())


class FigureFolder:
    """The figures/ folder ``figdir`` of a report and its record (:data:`MANIFEST`), read once;
    :meth:`write` saves the record after the figures are drawn."""

    def __init__(self, figdir):
        self.figdir = Path(figdir)
        try:
            doc = json.loads((self.figdir / MANIFEST).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            doc = None
        figures = doc.get("figures") if isinstance(doc, dict) and doc.get("written_by") == _SIGNATURE else None
        # an unreadable or foreign record is empty: every figure drawn again, nothing removed
        self.records = {n: e for n, e in (figures or {}).items() if _valid(n, e)}

    def unchanged(self, path, key):
        """True when figure ``path`` (its PNG) and its PDF hold what was drawn from ``key``."""
        entry = self.records.get(Path(path).name)
        return (entry is not None and entry["key"] == key
                and all(_holds(Path(path).with_suffix(s), entry["files"][s]) for s in SUFFIXES))

    def record(self, path, key):
        """Record figure ``path`` (and its PDF) as just drawn from ``key``; a file that cannot be
        read leaves the figure unrecorded (drawn again next time)."""
        files = {s: file_record(Path(path).with_suffix(s)) for s in SUFFIXES}
        if all(files.values()):
            self.records[Path(path).name] = {"key": key, "files": files}
        else:
            self.records.pop(Path(path).name, None)

    def remove(self, name):
        """Remove figure ``name`` (a PNG file name) and its PDF where they hold what the record
        says was written, and its record: a file edited since stays."""
        entry = self.records.pop(name, None)
        if entry is None:
            return
        for s in SUFFIXES:
            path = (self.figdir / name).with_suffix(s)
            if _holds(path, entry["files"][s]):
                path.unlink(missing_ok=True)

    def keep_only(self, names):
        """Remove the recorded figures not in ``names`` (those of an earlier report that this one
        does not show: a fit no longer reported), as :meth:`remove` does."""
        keep = set(names)
        for name in [n for n in self.records if n not in keep]:
            self.remove(name)

    def write(self):
        """Save the record (atomically)."""
        doc = {"written_by": _SIGNATURE, "format": 1, "figures": self.records}
        replace_atomic(self.figdir / MANIFEST, json.dumps(doc, indent=0, sort_keys=True).encode())
