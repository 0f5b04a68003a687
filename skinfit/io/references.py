"""The works the model cards and prior files cite (``skinfit/references.toml``, plus a
``references.toml`` in any folder of the search path, for a user's own cards: skinfit.io.paths).

A shipped card's ``source`` is one or more citations joined by ``"; "``, each ``KEY`` or
``KEY, where`` (``"fujii_wavy, eq. 13"``); :func:`check_source` refuses an unknown key at load
time (a user's own file may give free text: :func:`check_file_source`) and :func:`cite` renders
a source for readers (``Fujii, Okamoto & Yamada, eq. 13``).
"""

import re
import tomllib
from functools import cache
from importlib import resources
from pathlib import Path
from types import MappingProxyType

from skinfit.errors import InputError
from skinfit.io.paths import search_path, shipped_root

__all__ = ["references", "full", "cite_long", "parse_source", "check_source", "check_file_source", "cite"]

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


def cite(source):
    """A source as readers see it: each key replaced by the work's short name; unknown text kept."""
    known = references()
    out = []
    for key, loc in parse_source(source):
        ref = known.get(key)
        if ref is None:
            out.append(loc if key is None else f"{key}, {loc}" if loc else key)
            continue
        name = ref.get("short", ref["title"])
        out.append(f"{name}, {loc}" if loc else name)
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
    """:func:`cite` followed by the full reference of each work cited, for reports."""
    known = references()
    keys = [k for k, _ in parse_source(source) if k in known]
    works = "; ".join(full(k) for k in dict.fromkeys(keys))
    return f"{cite(source)} ({works})" if works else cite(source)
