"""Figures kept by content across report folders, so each is drawn once per input.

A report's figures are reused within its own folder (``figures/.figures.json``); this store
keeps every drawn figure's PNG and PDF under a key made of everything the figure is drawn
from: the fits' content (:func:`skinfit.report.fit_hash`), the plot function and its
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
import shutil
import tempfile
from functools import lru_cache
from importlib import metadata
from pathlib import Path

__all__ = ["store_dir", "code_hash", "storable", "fetch", "put", "trim"]

#: The suffixes of a stored figure: the PNG shown in the report and its PDF for papers.
SUFFIXES = (".png", ".pdf")
_LIBRARIES = ("matplotlib", "numpy", "scipy", "pandas", "xarray", "arviz-base", "arviz-stats", "arviz-plots",
              "pillow")


def store_dir():
    """The store's folder, or None when ``$SKINFIT_FIGURE_STORE`` turns it off."""
    value = os.environ.get("SKINFIT_FIGURE_STORE")
    if value is not None:
        return None if value.strip().lower() in ("", "off", "0", "none") else Path(value).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("skinfit", appauthor=False)) / "figures"


def _limit_bytes():
    try:
        return int(float(os.environ.get("SKINFIT_FIGURE_STORE_MB", 512)) * 2**20)
    except ValueError:
        return 512 * 2**20


def _version(pkg):
    try:
        return metadata.version(pkg)
    except metadata.PackageNotFoundError:
        return "-"


@lru_cache(maxsize=1)
def code_hash():
    """sha256 of the skinfit package's source (:func:`skinfit.paths.source_hash`) and of the
    plotting libraries' versions: a figure drawn by other code is not reused."""
    from .paths import source_hash

    doc = {"source": source_hash(), "versions": {pkg: _version(pkg) for pkg in _LIBRARIES}}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


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


def _sha256(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def fetch(digest, png):
    """Copy the stored figure ``digest`` to ``png`` and its PDF beside it; True when done, False
    (and nothing written) when the store has no intact entry."""
    entry = _entry(digest)
    if entry is None:
        return False
    try:
        meta = json.loads(entry.with_suffix(".json").read_text())
        sources = [entry.with_suffix(s) for s in SUFFIXES]
        if any(_sha256(src) != meta.get(s) for src, s in zip(sources, SUFFIXES)):
            return False
        for src, s in zip(sources, SUFFIXES):
            _copy_atomic(src, Path(png).with_suffix(s))
        os.utime(entry.with_suffix(".json"))  # recently used: kept longest when trimming
    except (OSError, ValueError, AttributeError):
        return False
    return True


def put(digest, png):
    """Keep the figure just drawn at ``png`` (and its PDF) under ``digest``; silent when the
    store cannot be written (a read-only or full disk costs only the reuse)."""
    entry = _entry(digest)
    if entry is None:
        return
    try:
        entry.parent.mkdir(parents=True, exist_ok=True)
        meta = {}
        for s in SUFFIXES:
            src = Path(png).with_suffix(s)
            meta[s] = _sha256(src)
            _copy_atomic(src, entry.with_suffix(s))
        _write_atomic(entry.with_suffix(".json"), json.dumps(meta).encode())  # last: marks the entry whole
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


def _copy_atomic(src, dst):
    dst = Path(dst)
    fd, tmp = tempfile.mkstemp(dir=dst.parent, prefix=f".{dst.name}.", suffix=".part")
    os.close(fd)
    try:
        shutil.copyfile(src, tmp)
        os.replace(tmp, dst)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _write_atomic(dst, data):
    fd, tmp = tempfile.mkstemp(dir=dst.parent, prefix=f".{dst.name}.", suffix=".part")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, dst)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
