"""Reading the TOML files a researcher edits (model cards, prior files, dataset cards)."""

import hashlib
import tomllib
from pathlib import Path

from .errors import InputError
from .paths import entries, locate

__all__ = ["read_toml", "sha256_file", "require", "find_file"]



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
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(path, f"invalid TOML: {exc}") from None
    version = doc.get("schema_version")
    if version != 1:
        raise InputError(path, f"expected schema_version = 1 (got {version!r})", field="schema_version")
    return doc, text


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
    """Resolve ``name`` as a path, or as an id on the search path (skinfit.paths)."""
    return locate(kind, name)


def available(kind):
    return list(entries(kind))
