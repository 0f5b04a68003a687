"""Where skinfit finds model cards, prior files and datasets.

A search path of folders, first match wins: folders given explicitly (``skinfit --path DIR``,
:func:`set_search_path`) > the folders in ``$SKINFIT_PATH`` (``os.pathsep``-separated) > the
user folder (``platformdirs.user_data_dir("skinfit")``) > the card folders of installed plug-ins
(``skinfit.models`` entry points, :mod:`skinfit.io.registry`) > the files shipped with skinfit. Each
folder holds the repository's layout: ``models/<id>.toml``, ``priors/<id>.toml``,
``datasets/<id>/dataset.toml``; a missing sub-folder is skipped.

The shipped files are the repository's top-level ``models/``, ``priors/`` and ``datasets/``,
packed into the wheel as ``skinfit/_shipped/`` and read with :mod:`importlib.resources`; in a
source checkout (``pip install -e .``) they are read in place.
"""

import hashlib
import json
import os
from dataclasses import dataclass
from functools import cache
from importlib import metadata, resources
from pathlib import Path

import platformdirs

from skinfit.errors import InputError
from skinfit.io import registry
from skinfit.io.arguments import check_path

__all__ = ["KINDS", "Entry", "Root", "entries", "locate", "search_path", "set_search_path", "explicit_search_path",
           "check_search_path", "where_from", "shipped_root", "user_root", "user_cache_root"]

KINDS = ("models", "priors", "datasets")
ENV = "SKINFIT_PATH"
_EXPLICIT: list[Path] = []


@dataclass(frozen=True)
class Root:
    """One folder of the search path and where it came from (``--path``, ``$SKINFIT_PATH``,
    ``user`` or ``shipped``)."""

    path: Path
    origin: str


@dataclass(frozen=True)
class Entry:
    """One model card, prior file or dataset found on the search path."""

    id: str
    path: Path  # the card file (datasets: datasets/<id>/dataset.toml)
    root: Root
    shadows: tuple[Root, ...] = ()  # later folders on the path holding the same id


def set_search_path(folders) -> None:
    """Put ``folders`` (paths) first on the search path, for this process."""
    _EXPLICIT[:] = [Path(f).expanduser() for f in folders]


def explicit_search_path() -> list[Path]:
    """The folders :func:`set_search_path` put first: what a worker process started by spawn
    or forkserver (which inherits no module state) must be given to find the same cards."""
    return list(_EXPLICIT)


def shipped_root() -> Path | None:
    """The folder holding the shipped models/, priors/, datasets/ (None if neither the wheel's
    ``skinfit/_shipped`` nor a source checkout's top level has them)."""
    package = resources.files("skinfit")
    shipped = package / "_shipped"
    if shipped.is_dir() and isinstance(shipped, Path):
        return shipped
    checkout = Path(os.fspath(package)).resolve().parent if isinstance(package, Path) else None
    if checkout is not None and (checkout / "models").is_dir() and (checkout / "pyproject.toml").is_file():
        return checkout
    return None


def user_root() -> Path:
    """The per-user folder (e.g. ``~/.local/share/skinfit`` on Linux)."""
    return Path(platformdirs.user_data_dir("skinfit", appauthor=False))


def user_cache_root() -> Path:
    """The per-user cache folder (e.g. ``~/.cache/skinfit`` on Linux): the figure store, the
    figures' font."""
    return Path(platformdirs.user_cache_dir("skinfit", appauthor=False))


#: What a folder of the search path holds (at least one of them).
_LAYOUT = (*KINDS, "references.toml")


def _given(root):
    """``root`` (a ``--path`` or ``$SKINFIT_PATH`` folder) if it is a folder of the search path's
    layout; else an InputError naming it: a mistyped folder would otherwise be skipped in
    silence, and the files it was meant to supply taken from later folders (the shipped ones)."""
    if not root.path.exists():
        raise InputError(root.origin, f"{root.path}: no such folder")
    if not root.path.is_dir():
        raise InputError(root.origin, f"{root.path}: not a folder (expected one holding models/, priors/, datasets/)")
    if not any((root.path / name).exists() for name in _LAYOUT):
        inside = " (give the folder above it)" if root.path.name in KINDS else ""
        raise InputError(root.origin, f"{root.path}: holds none of models/, priors/, datasets/, references.toml"
                         + inside)
    return root


def check_search_path() -> None:
    """InputError (one line) when a ``--path`` or ``$SKINFIT_PATH`` folder does not exist or does
    not have the search path's layout: ``skinfit`` checks this before any command runs."""
    search_path()


def search_path() -> list[Root]:
    """The folders searched, first match wins (see the module docstring). A ``--path`` or
    ``$SKINFIT_PATH`` folder that does not exist, is not a folder or holds none of models/,
    priors/, datasets/ and references.toml is an InputError."""
    roots = [_given(Root(p, "--path")) for p in _EXPLICIT]
    roots += [_given(Root(Path(p).expanduser(), f"${ENV}")) for p in os.environ.get(ENV, "").split(os.pathsep) if p]
    roots.append(Root(user_root(), "user"))
    roots += [Root(Path(p), "plug-in") for p in registry.plugin_folders()]  # card folders of installed plug-ins
    shipped = shipped_root()
    if shipped is not None:
        roots.append(Root(shipped, "shipped"))
    return roots


def _cards(kind: str, folder: Path) -> dict[str, Path]:
    base = folder / kind
    if not base.is_dir():
        return {}
    if kind == "datasets":
        return {d.name: d / "dataset.toml" for d in sorted(base.iterdir()) if (d / "dataset.toml").is_file()}
    return {f.stem: f for f in sorted(base.glob("*.toml"))}


def entries(kind: str) -> dict[str, Entry]:
    """Every id of ``kind`` on the search path -> the entry that wins, with the folders it shadows."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS} (got {kind!r})")
    found: dict[str, Entry] = {}
    for root in search_path():
        for cid, path in _cards(kind, root.path).items():
            if cid in found:
                e = found[cid]
                found[cid] = Entry(e.id, e.path, e.root, (*e.shadows, root))
            else:
                found[cid] = Entry(cid, path, root)
    return dict(sorted(found.items()))


def locate(kind: str, name) -> Path:
    """The card file for ``name``: an existing path (a ``.toml`` file, or a dataset folder) is
    taken as given; otherwise ``name`` is an id looked up on the search path."""
    what = kind[:-1]
    check_path(name, f"load_{what}", None, f"a {what} id or the path of its {'card' if what != 'prior' else 'file'}")
    p = Path(name)
    if kind == "datasets" and p.is_dir() and (p / "dataset.toml").is_file():
        return p / "dataset.toml"
    if p.suffix == ".toml" and p.exists():  # a FIFO or device is refused by the reader, not taken for an id
        return p
    if any(c in str(name) for c in "/\\") or ".." in str(name) or str(name).startswith("."):
        if p.is_dir():
            raise InputError(str(name), f"is a folder, not a {what} file" + (" (no dataset.toml in it)"
                                                                            if kind == "datasets" else ""))
        if p.exists():
            raise InputError(str(name), f"is not a {what} file (a .toml card)")
        raise InputError(str(name), f"no such {what} file, and an id is a name, not a path")
    entry = entries(kind).get(str(name))
    if entry is not None:
        return entry.path
    known = ", ".join(entries(kind)) or "none"
    searched = "; ".join(f"{r.path / kind} ({r.origin})" for r in search_path())
    raise InputError(str(name), f"no such {kind[:-1]} (known: {known}; searched: {searched})")


def where_from(kind: str, path) -> tuple[str, list[tuple[Root, Path]]]:
    """Where the card file ``path`` of ``kind`` comes from: the origin of the search-path folder
    holding it (``--path``, ``$SKINFIT_PATH``, ``user``, ``plug-in``, ``shipped``; ``file`` for
    a file named by its path outside the search path) and the files of the same id in later
    folders, which it hides (``(root, file)`` each)."""
    path = Path(path).resolve()
    cid = path.parent.name if kind == "datasets" else path.stem
    found = [(root, card) for root in search_path() for i, card in _cards(kind, root.path).items() if i == cid]
    for k, (root, card) in enumerate(found):
        if card.resolve() == path:
            return root.origin, found[k + 1:]
    return "file", []


def display(path: Path) -> str:
    """How a card is named in messages and results: a shipped one relative to the shipped
    folder (``models/electroadhesion.toml``), any other by the path as given."""
    shipped = shipped_root()
    if shipped is not None:
        try:
            return str(Path(path).resolve().relative_to(shipped.resolve()))
        except ValueError:
            pass
    return str(path)


#: The skinfit package folder (this module is skinfit/io/paths.py)
_PACKAGE = Path(__file__).parents[1]


def source_files() -> list[Path]:
    """Every .py, template and card file of the skinfit package (all its layers: the physics, the
    sampler, the plots, the report), sorted."""
    return [path for path in sorted(_PACKAGE.rglob("*"))
            if path.suffix in (".py", ".j2", ".toml") and path.is_file() and "__pycache__" not in path.parts]


@cache
def source_hash() -> str:
    """sha256 of skinfit's own source (:func:`source_files`, with their paths in the package).
    Computed once a process."""
    h = hashlib.sha256()
    for path in source_files():
        h.update(path.relative_to(_PACKAGE).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def package_version(name: str) -> str:
    """The installed version of distribution ``name``, or ``"not installed"``."""
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "not installed"


@cache
def code_hash(libraries: tuple[str, ...] = ()) -> str:
    """sha256 of skinfit's source (:func:`source_hash`) and of the installed versions of
    ``libraries``: keys results kept by content (a report's figures, the population cache), so
    that other code never reuses them."""
    doc = {"source": source_hash(), "versions": {name: package_version(name) for name in libraries}}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()
