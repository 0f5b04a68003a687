"""Reading the TOML files a researcher edits (model cards, prior files, dataset cards)."""

import hashlib
import os
import tomllib
from pathlib import Path

from .errors import InputError

__all__ = ["ROOT", "read_toml", "sha256_file", "require", "find_file"]

#: Directory holding models/, priors/ and datasets/ (the repository, or $SKINFIT_HOME).
ROOT = Path(os.environ.get("SKINFIT_HOME", Path(__file__).resolve().parents[1]))


def sha256_file(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def read_toml(path):
    """Parse a TOML file; syntax errors become an InputError naming the file and line."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(path, "file not found") from None
    except UnicodeDecodeError as exc:
        raise InputError(path, f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    if len(text) > MAX_TOML_CHARS:
        raise InputError(path, f"{len(text)} characters: too large for a card (at most {MAX_TOML_CHARS})")
    depth = _nesting(text) if text.count("[") + text.count("{") > MAX_TOML_DEPTH else 0
    if depth > MAX_TOML_DEPTH:
        raise InputError(path, f"arrays or tables nested {depth} deep (at most {MAX_TOML_DEPTH})")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(path, f"invalid TOML: {exc}") from None
    except RecursionError:  # nesting the bracket count above did not see (e.g. inside odd quoting)
        raise InputError(path, "arrays or tables nested too deeply to read") from None
    version = doc.get("schema_version")
    if version != 1:
        raise InputError(path, f"expected schema_version = 1 (got {version!r})", field="schema_version")
    return doc, text


#: Limits of a card read before parsing: tomllib recurses once per nesting level (thousands of
#: levels raise RecursionError) and holds the whole text; the shipped cards are under 10 kB and
#: nest at most 3 deep.
MAX_TOML_CHARS = 10_000_000
MAX_TOML_DEPTH = 64


def _nesting(text):
    """Deepest nesting of ``[`` / ``{`` outside strings and comments (an upper bound for
    TOML's arrays and inline tables; a table header ``[a]`` counts 1)."""
    depth = deepest = 0
    quote = None
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        if quote:
            if ch == "\\" and quote[0] == '"':
                i += 1
            elif text.startswith(quote, i):
                i += len(quote) - 1
                quote = None
        elif ch == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        elif text.startswith(('"""', "'''"), i):
            quote = text[i:i + 3]
            i += 2
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth = max(depth - 1, 0)
        i += 1
    return deepest


def require(doc, key, kind, where, *, field_prefix="", default=...):
    """Fetch ``doc[key]`` and check its type, or raise an InputError naming the field."""
    name = f"{field_prefix}{key}"
    if key not in doc:
        if default is not ...:
            return default
        raise InputError(where, f"missing required field (expected {_kind_name(kind)})", field=name)
    value = doc[key]
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if not isinstance(value, kind) or (kind in (int, float) and isinstance(value, bool)):
        raise InputError(where, f"expected {_kind_name(kind)} (got {value!r})", field=name)
    return value


def _kind_name(kind):
    if isinstance(kind, tuple):
        return " or ".join(_kind_name(k) for k in kind)
    return {str: "a string", float: "a number", int: "an integer", list: "a list",
            dict: "a table", bool: "true or false"}.get(kind, kind.__name__)


def find_file(kind, name, suffix=".toml"):
    """Resolve ``name`` as a path, or as an id under ROOT/<kind>/."""
    p = Path(name)
    if p.suffix == suffix and p.exists():
        return p
    if p.is_dir() and (p / "dataset.toml").exists():
        return p / "dataset.toml"
    candidate = ROOT / kind / (name + suffix) if suffix else ROOT / kind / name
    if kind == "datasets":
        candidate = ROOT / kind / name / "dataset.toml"
    if candidate.exists():
        return candidate
    known = sorted(available(kind))
    if not (ROOT / kind).is_dir():  # e.g. a non-editable install: the shipped cards stay in the checkout
        raise InputError(name, f"no such {kind[:-1]}: there is no {ROOT / kind} with the shipped {kind} "
                               "(skinfit reads them from the checkout it is installed from: install it with "
                               "`pip install -e <checkout>`, or set SKINFIT_HOME to the checkout)")
    raise InputError(name, f"no such {kind[:-1]} (known: {', '.join(known) or 'none'})")


def available(kind):
    base = ROOT / kind
    if not base.exists():
        return []
    if kind == "datasets":
        return [d.name for d in base.iterdir() if (d / "dataset.toml").exists()]
    return [f.stem for f in base.glob("*.toml")]
