"""Figures kept by content across report folders, so each is drawn once per input.

A report's figures are reused within its own folder (``figures/.figures.json``); this store
keeps every drawn figure's PNG and PDF under a key made of everything the figure is drawn
from: the fits' content (:meth:`skinfit.fit.Fit.content_hash`), the plot function and its
arguments, the source of the skinfit package and the versions of the plotting libraries.
A later report into another folder copies the files instead of drawing them again.

Only fits of a shipped model card, unchanged and with shipped physics, are stored: their
predictive draws follow from the fit's content and the package source alone. A fit of a
user's own model (whose forward function may change without the fit changing) is drawn as
before. Every stored file is checked against its recorded sha256 before it is used; a
missing, partial or altered entry is drawn again. The store lives in the user cache folder
(``$SKINFIT_FIGURE_STORE`` to move it; empty or ``off`` to turn it off) and is trimmed to
``$SKINFIT_FIGURE_STORE_MB`` MiB (default 512), least recently used first.
"""

import hashlib
import json
import os
from pathlib import Path

__all__ = ["store_dir", "code_hash", "storable", "fetch", "put", "trim"]

#: The suffixes of a stored figure: the PNG shown in the report and its PDF for papers.
SUFFIXES = (".png", ".pdf")
_LIBRARIES = ("matplotlib", "numpy", "scipy", "pandas", "xarray", "arviz-base", "arviz-stats", "arviz-plots",
              "pillow", "pypdfium2")


def store_dir():
    """The store's folder, or None when ``$SKINFIT_FIGURE_STORE`` turns it off."""
    value = os.environ.get("SKINFIT_FIGURE_STORE")
    if value is not None:
        return None if value.strip().lower() in ("", "off", "0", "none") else Path(value).expanduser()
    from .paths import user_cache_root

    return user_cache_root() / "figures"


def _limit_bytes():
    try:
        return int(float(os.environ.get("SKINFIT_FIGURE_STORE_MB", 512)) * 2**20)
    except ValueError:
        return 512 * 2**20


def code_hash():
    """sha256 of the skinfit package's source and of the plotting libraries' versions
    (:func:`skinfit.paths.code_hash`): a figure drawn by other code is not reused."""
    from .paths import code_hash as hash_of

    return hash_of(_LIBRARIES)


def storable(fit):
    """True when ``fit`` is of a shipped model card, unchanged since the fit, whose functions are
    all skinfit's own: then what is computed from it (its figures, a population) follows from
    its content and skinfit's source (:func:`skinfit.paths.source_hash`)."""
    from .models import load_model
    from .paths import locate, shipped_root
    from .registry import resolve

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


def _entry(digest):
    folder = store_dir()
    return None if folder is None else folder / digest[:2] / digest


def fetch(digest, png):
    """Copy the stored figure ``digest`` to ``png`` and its PDF beside it; True when done, False
    (and nothing written) when the store has no intact entry."""
    from .checkpoint import replace_atomic

    entry = _entry(digest)
    if entry is None:
        return False
    try:
        meta = json.loads(entry.with_suffix(".json").read_text())
        files = {s: entry.with_suffix(s).read_bytes() for s in SUFFIXES}
        if any(hashlib.sha256(data).hexdigest() != meta.get(s) for s, data in files.items()):
            return False
        for s, data in files.items():
            replace_atomic(Path(png).with_suffix(s), data)
        os.utime(entry.with_suffix(".json"))  # recently used: kept longest when trimming
    except (OSError, ValueError, AttributeError):
        return False
    return True


def put(digest, png):
    """Keep the figure just drawn at ``png`` (and its PDF) under ``digest``; silent when the
    store cannot be written (a read-only or full disk costs only the reuse)."""
    from .checkpoint import replace_atomic

    entry = _entry(digest)
    if entry is None:
        return
    try:
        meta = {}
        for s in SUFFIXES:
            data = Path(png).with_suffix(s).read_bytes()
            meta[s] = hashlib.sha256(data).hexdigest()
            replace_atomic(entry.with_suffix(s), data)
        replace_atomic(entry.with_suffix(".json"), json.dumps(meta).encode())  # last: marks the entry whole
    except OSError:
        return


def trim():
    """Remove the least recently used entries until the store is within its size limit."""
    folder = store_dir()
    if folder is None or not folder.is_dir():
        return
    entries = {}
    for path in folder.glob("??/*"):
        try:
            st = path.stat()
        except OSError:
            continue
        item = entries.setdefault(path.with_suffix(""), [0, 0.0])
        item[0] += st.st_size
        if path.suffix == ".json":
            item[1] = st.st_mtime
    total, limit = sum(size for size, _ in entries.values()), _limit_bytes()
    for stem, (size, _) in sorted(entries.items(), key=lambda e: e[1][1]):
        if total <= limit:
            break
        for s in (".json", *SUFFIXES):  # the mark first: a half-removed entry is never fetched
            Path(str(stem) + s).unlink(missing_ok=True)
        total -= size
