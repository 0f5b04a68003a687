"""The works the model cards and prior files cite (``skinfit/references.toml``, plus a
``references.toml`` in any folder of the search path, for a user's own cards: skinfit.io.paths).

A shipped card's ``source`` is one or more citations joined by ``"; "``, each ``KEY`` or
``KEY, where`` (``"fujii_wavy, eq. 13"``); :func:`check_source` refuses an unknown key at load
time (a user's own file may give free text: :func:`check_file_source`) and :func:`cite` renders
a source for readers, in one style everywhere: ``Authors (year), “title”, venue, where``
(:func:`citation`).
"""

import re
import tomllib
from functools import cache
from importlib import resources
from pathlib import Path
from types import MappingProxyType

from skinfit.errors import InputError
from skinfit.io.paths import search_path, shipped_root

__all__ = ["references", "full", "cite_long", "parse_source", "check_source", "check_file_source", "cite", "citation",
           "authors_text"]

_KEY = re.compile(r"^([a-z][a-z0-9_]*)(?:\s*[,:]\s*(.*))?$", re.S)
_FIELDS = {"title", "authors", "venue", "year", "doi", "note", "short"}


def references():
    """key -> mapping of the work's fields: the shipped references.toml, and any
    ``references.toml`` on the search path (earlier folders win on a shared key)."""
    files = tuple(str(r.path / "references.toml") for r in search_path() if (r.path / "references.toml").is_file())
    return _load(files)


@cache
def _load(files):
    out = {}
    shipped = (resources.files("skinfit") / "references.toml").read_text(encoding="utf-8")
    for where, text in [*((f, Path(f).read_text(encoding="utf-8")) for f in files),
                        ("skinfit/references.toml", shipped)]:
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(where, f"invalid TOML: {exc}") from None
        if doc.pop("schema_version", None) != 1:
            raise InputError(where, "expected schema_version = 1", field="schema_version")
        for key, entry in doc.items():
            if not isinstance(entry, dict) or not _KEY.match(key) or "title" not in entry or set(entry) - _FIELDS:
                raise InputError(where, f"expected a table with a title and only {sorted(_FIELDS)}", field=key)
            out.setdefault(key, MappingProxyType(entry))
    return MappingProxyType(out)


def parse_source(source):
    """``"k1, where; more where; k2"`` -> ``[("k1", "where; more where"), ("k2", "")]``.

    A part that does not start with ``key,`` / ``key:`` / ``key`` alone continues the previous
    citation's locator; a first part that does not is returned with key None."""
    parts = []
    for part in source.split(";"):
        part = part.strip()
        m = _KEY.match(part)
        if m:
            parts.append((m.group(1), (m.group(2) or "").strip()))
        elif parts:
            parts[-1] = (parts[-1][0], f"{parts[-1][1]}; {part}".lstrip("; "))
        else:
            parts.append((None, part))
    return parts


def check_source(source, where, field):
    """Raise an InputError unless every citation in ``source`` starts with a known key."""
    if not isinstance(source, str):
        raise InputError(where, f"expected a text \"KEY, where\" (got {type(source).__name__})", field=field)
    known = references()
    for key, _ in parse_source(source):
        if key not in known:
            cited = key if key is not None else source.split(";")[0].strip()[:40]
            raise InputError(where, f"expected a reference key (skinfit/references.toml, or a "
                             f"references.toml on the search path) then ', where' (got {cited!r}; known: "
                             f"{', '.join(known)})", field=field)
    return source


def check_file_source(source, file, where, field):
    """:func:`check_source` for a shipped card or prior file (``file`` in the shipped ``models/``
    or ``priors/``); a user's own file may give free text instead, recorded and shown as given."""
    shipped = shipped_root()
    folder = Path(file).resolve().parent
    if shipped is not None and folder in ((shipped / "models").resolve(), (shipped / "priors").resolve()):
        return check_source(source, where, field)
    if not isinstance(source, str):
        raise InputError(where, f"expected a text (got {type(source).__name__})", field=field)
    return source


def authors_text(ref):
    """The authors of a work as a citation names them: surnames, ``A``, ``A & B``,
    ``A, B & C``, ``A et al.`` beyond three (or when the list ends in ``et al.``); empty when
    the references file does not know them."""
    names = [n for n in ref.get("authors", []) if n.strip()]
    etal = bool(names) and names[-1].strip().rstrip(".").lower() == "et al"
    surnames = [n.split()[-1] for n in names if n.strip().rstrip(".").lower() != "et al"]
    if not surnames:
        return ""
    if etal or len(surnames) > 3:
        return f"{surnames[0]} et al."
    return surnames[0] if len(surnames) == 1 else f"{', '.join(surnames[:-1])} & {surnames[-1]}"


def citation(key, where=""):
    """One work as every place of skinfit cites it: ``Authors (year), “title”, venue, where``
    (``Fujii, Okamoto & Yamada, “Friction model of fingertip sliding ...”, eq. 13``), the
    fields the references file does not know left out."""
    ref = references()[key]
    authors, year, title = authors_text(ref), ref.get("year"), ref["title"]
    if authors:
        parts = [f"{authors} ({year})" if year else authors, f"\u201c{title}\u201d"]
    else:  # a work whose authors the file does not know: named by its title
        parts = [f"\u201c{title}\u201d ({year})" if year else title]
    parts += [str(ref["venue"])] if "venue" in ref else []
    parts += [where] if where else []
    return ", ".join(parts)


def cite(source):
    """A source as readers see it, in one style everywhere (report, summary.md, ``skinfit
    models`` and ``skinfit priors``): each cited work as :func:`citation` gives it, with its
    locator (equation, section); text that is not a known key kept as written."""
    known = references()
    out = []
    for key, loc in parse_source(source):
        if key not in known:
            out.append(loc if key is None else f"{key}, {loc}" if loc else key)
        else:
            out.append(citation(key, loc))
    return "; ".join(out)


def full(key):
    """The full reference line of ``key``: authors, title, venue, year, DOI (as known)."""
    ref = references()[key]
    parts = [", ".join(ref["authors"])] if "authors" in ref else []
    parts.append(f"\"{ref['title']}\"")
    parts += [str(ref[k]) for k in ("venue", "year") if k in ref]
    if "doi" in ref:
        parts.append(f"doi:{ref['doi']}")
    return ", ".join(parts)


def cite_long(source):
    """:func:`cite` with the DOI of each work that has one, for reports."""
    known = references()
    dois = [f"doi:{known[k]['doi']}" for k in dict.fromkeys(k for k, _ in parse_source(source))
            if k in known and "doi" in known[k]]
    return f"{cite(source)} ({'; '.join(dois)})" if dois else cite(source)
