"""Figures kept by content across report folders, so each is drawn once per input.

A report's figures are reused within its own folder (``figures/.figures.json``); this store
keeps every drawn figure's PNG and PDF under a key made of everything the figure is drawn
from: the fits' content (:meth:`skinfit.results.fit.Fit.content_hash`), the plot function and its
arguments, the source of the skinfit package and the versions of the plotting libraries.
A later report into another folder copies the files instead of drawing them again.

Only fits of a shipped model card, unchanged and with shipped physics, are stored: their
predictive draws follow from the fit's content and the package source alone. A fit of a
user's own model (whose forward function may change without the fit changing) is drawn as
before. Every stored file is checked against its recorded sha256 before it is used; a
missing, partial or altered entry is drawn again. The store lives in the user cache folder
(``$SKINFIT_FIGURE_STORE`` to move it; empty or ``off`` to turn it off) and is trimmed to
``$SKINFIT_FIGURE_STORE_MB`` MiB (default 512), least recently used first.

The store removes only what it wrote and can prove it wrote. Its files live in a folder of its
own, :data:`FOLDER` under the folder named, claimed by the marker file :data:`MARKER` when it
was new or empty; a folder of that name holding other files and no marker is not the store's,
and the store is then off (a warning says so). Each entry's ``<digest>.json`` lists its PNG
and PDF with their sha256 and size; trimming removes a listed file only while its content
still matches, and nothing else: files the user keeps beside or inside the store survive
every operation, trimming to 0 MiB included.
"""

import hashlib
import json
import os
import re
import warnings
from pathlib import Path

__all__ = ["store_dir", "own_folder", "code_hash", "storable", "fetch", "put", "trim"]

#: The suffixes of a stored figure: the PNG shown in the report and its PDF for papers.
SUFFIXES = (".png", ".pdf")
#: The store's own folder under the folder named, and the marker file that makes it the store's.
FOLDER = "skinfit-figure-store"
MARKER = ".skinfit-figure-store"
_DIGEST = re.compile(r"^[0-9a-f]{64}$")
_SIGNATURE = "skinfit figure store"
_WARNED: set[str] = set()
_LIBRARIES = ("matplotlib", "numpy", "scipy", "pandas", "xarray", "arviz-base", "arviz-stats", "arviz-plots",
              "pillow", "pypdfium2")


def store_dir():
    """The store's folder, or None when ``$SKINFIT_FIGURE_STORE`` turns it off."""
    value = os.environ.get("SKINFIT_FIGURE_STORE")
    if value is not None:
        return None if value.strip().lower() in ("", "off", "0", "none") else Path(value).expanduser()
    from skinfit.io.paths import user_cache_root

    return user_cache_root() / "figures"


def _limit_bytes():
    try:
        return max(0, int(float(os.environ.get("SKINFIT_FIGURE_STORE_MB", 512)) * 2**20))
    except ValueError:
        return 512 * 2**20


def code_hash():
    """sha256 of the skinfit package's source and of the plotting libraries' versions
    (:func:`skinfit.io.paths.code_hash`): a figure drawn by other code is not reused."""
    from skinfit.io.paths import code_hash as hash_of

    return hash_of(_LIBRARIES)


def storable(fit):
    """True when ``fit`` is of a shipped model card, unchanged since the fit, whose functions are
    all skinfit's own: then what is computed from it (its figures, a population) follows from
    its content and skinfit's source (:func:`skinfit.io.paths.source_hash`)."""
    from skinfit.io.models import load_model
    from skinfit.io.paths import locate, shipped_root
    from skinfit.io.registry import resolve

    try:
        model = load_model(fit.model_id)
        shipped = shipped_root()
        if shipped is None or model.sha256 != fit.attrs.get("model_sha256"):
            return False
        if Path(locate("models", fit.model_id)).resolve().parent != (Path(shipped) / "models").resolve():
            return False  # a card of the user's that shadows a shipped one
        refs = [("forward", model.forward_ref), *(("shear", r) for r in model.shear.values()),
                *(("shift", r) for r in model.shift.values())]
        if model.derived.get("function"):
            refs.append(("derived", model.derived["function"]))
        return all(resolve(role, ref, model.path).__module__.startswith("skinfit.physics.") for role, ref in refs)
    except Exception:  # noqa: BLE001 - a model that cannot be checked is simply not stored
        return False


def own_folder(create=False):
    """The store's own folder (:data:`FOLDER` under :func:`store_dir`) when it is the store's: it
    holds :data:`MARKER`, or (``create``) it is new or empty and is claimed now. None when the
    store is off, cannot be created, or the folder holds files the store did not write (warned
    once: such a folder is never written into nor trimmed)."""
    root = store_dir()
    if root is None:
        return None
    folder = root / FOLDER
    marker = folder / MARKER
    try:
        if marker.is_file():
            return folder
        if not create and not folder.exists():
            return None
        claiming = f".{MARKER}."  # another process's marker being written (checkpoint.temp_file) is no other file
        if folder.exists() and (not folder.is_dir() or any(not p.name.startswith(claiming) for p in folder.iterdir())):
            if str(folder) not in _WARNED:
                _WARNED.add(str(folder))
                warnings.warn(f"{folder}: holds files the figure store did not write (no {MARKER}): figures are "
                              "neither stored there nor removed; point $SKINFIT_FIGURE_STORE at another folder",
                              UserWarning, stacklevel=3)
            return None
        from skinfit.inference.checkpoint import replace_atomic

        folder.mkdir(parents=True, exist_ok=True)
        replace_atomic(marker, json.dumps({"written_by": _SIGNATURE, "format": 1}).encode())
        return folder
    except OSError:  # an unwritable or odd location costs only the reuse
        return None


def _entry(digest, create=False):
    if not isinstance(digest, str) or not _DIGEST.match(digest):
        return None
    folder = own_folder(create)
    return None if folder is None else folder / digest[:2] / digest


def _meta(path):
    """The entry record at ``path`` (``<digest>.json``: {suffix: {"sha256", "size"}}) when it is
    one the store wrote, else None."""
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    files = doc.get("files") if isinstance(doc, dict) and doc.get("written_by") == _SIGNATURE else None
    if not isinstance(files, dict) or set(files) != set(SUFFIXES) or doc.get("digest") != path.stem:
        return None
    if not all(isinstance(f, dict) and isinstance(f.get("sha256"), str) and isinstance(f.get("size"), int)
               for f in files.values()):
        return None
    return files


def _matches(path, record):
    """True when the file at ``path`` is the one ``record`` lists (its size and sha256)."""
    try:
        if path.stat().st_size != record["size"]:
            return False
        return hashlib.sha256(path.read_bytes()).hexdigest() == record["sha256"]
    except OSError:
        return False


def fetch(digest, png):
    """Copy the stored figure ``digest`` to ``png`` and its PDF beside it; True when done, False
    (and nothing written) when the store has no intact entry."""
    from skinfit.inference.checkpoint import replace_atomic

    entry = _entry(digest)
    if entry is None:
        return False
    try:
        files = _meta(entry.with_suffix(".json"))
        if files is None:
            return False
        data = {s: entry.with_suffix(s).read_bytes() for s in SUFFIXES}
        if any(hashlib.sha256(b).hexdigest() != files[s]["sha256"] for s, b in data.items()):
            return False
        for s, b in data.items():
            replace_atomic(Path(png).with_suffix(s), b)
        os.utime(entry.with_suffix(".json"))  # recently used: kept longest when trimming
    except OSError:
        return False
    return True


def put(digest, png):
    """Keep the figure just drawn at ``png`` (and its PDF) under ``digest``; silent when the
    store cannot be written (a read-only or full disk costs only the reuse)."""
    from skinfit.inference.checkpoint import replace_atomic

    entry = _entry(digest, create=True)
    if entry is None:
        return
    try:
        files = {}
        for s in SUFFIXES:
            data = Path(png).with_suffix(s).read_bytes()
            files[s] = {"sha256": hashlib.sha256(data).hexdigest(), "size": len(data)}
            replace_atomic(entry.with_suffix(s), data)
        doc = {"written_by": _SIGNATURE, "digest": entry.name, "files": files}
        replace_atomic(entry.with_suffix(".json"), json.dumps(doc).encode())  # last: marks the entry whole
    except OSError:
        return


def trim():
    """Remove the least recently used entries until the store is within its size limit.

    Only entries the store wrote count and go: a ``<digest>.json`` record of the store's, in
    its own folder, and the files it lists while their content matches the record (removed
    before the record, so an interrupted trim leaves a record that the next one finishes)."""
    folder = own_folder()
    if folder is None:
        return
    entries = []
    for record in folder.glob("??/*.json"):
        if not _DIGEST.match(record.stem) or record.parent.name != record.stem[:2]:
            continue
        files = _meta(record)
        if files is None:
            continue
        try:
            st = record.stat()
        except OSError:
            continue
        entries.append((st.st_mtime, record, files, st.st_size + sum(_size(record.with_suffix(s), r)
                                                                      for s, r in files.items())))
    total, limit = sum(e[3] for e in entries), _limit_bytes()
    for _, record, files, size in sorted(entries, key=lambda e: e[0]):
        if total <= limit:
            break
        try:
            for s, r in files.items():
                path = record.with_suffix(s)
                if _matches(path, r):
                    path.unlink()
            if _meta(record) == files:  # still the record read above
                record.unlink()
        except OSError:
            continue
        total -= size


def _size(path, record):
    """The size of the listed file at ``path`` when it has the listed size (else 0: not counted)."""
    try:
        return record["size"] if path.stat().st_size == record["size"] else 0
    except OSError:
        return 0
