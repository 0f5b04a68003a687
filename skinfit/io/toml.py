"""Reading the TOML files a researcher edits (model cards, prior files, dataset cards)."""

import hashlib
import os
import stat
import tomllib
from pathlib import Path

from skinfit.errors import InputError
from skinfit.io.arguments import file_kind
from skinfit.io.paths import entries, locate

__all__ = ["read_toml", "read_regular", "sha256_file", "require", "find_file"]

#: Largest card or prior file read (bytes): a card is a few kB.
MAX_TOML_BYTES = 1 << 20


def sha256_file(path):
    """sha256 of a card or prior file (a regular file of at most MAX_TOML_BYTES)."""
    return hashlib.sha256(read_regular(path, MAX_TOML_BYTES)).hexdigest()


def read_regular(path, max_bytes, what="file", where=None):
    """The bytes of ``path`` if it is a regular file of at most ``max_bytes``; else InputError.

    Checked before opening: a directory, FIFO or device (``/dev/zero``) is refused rather than
    read without bound or waited on; the read itself stops at ``max_bytes + 1``.
    """
    where = path if where is None else where
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise InputError(where, f"{what} not found") from None
    except OSError as exc:
        raise InputError(where, f"cannot read the {what} ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError(where, f"is {file_kind(st.st_mode)}, not a regular file (skinfit reads only regular files)")
    too_big = (f"{what} larger than the limit of {max_bytes / 2**20:.1f} MiB "
               "(raise it with the SKINFIT_MAX_DATA_MB environment variable or max_bytes=)")
    if st.st_size > max_bytes:
        raise InputError(where, f"{st.st_size / 2**20:.1f} MiB: {too_big}")
    try:
        with open(path, "rb") as fh:
            raw = fh.read(max_bytes + 1)
    except OSError as exc:
        raise InputError(where, f"cannot read the {what} ({exc.strerror})") from None
    if len(raw) > max_bytes:
        raise InputError(where, too_big)
    return raw


def read_toml(path, *, versioned=True):
    """Parse a TOML file; syntax errors become an InputError naming the file and line.  A card
    (``versioned``) must declare ``schema_version = 1``; a plain input file (a design's
    candidates) need not."""
    path = Path(path)
    raw = read_regular(path, MAX_TOML_BYTES)
    try:
        text = raw.decode("utf-8")
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
    if versioned and version != 1:
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
    """Resolve ``name`` as a path, or as an id on the search path (skinfit.io.paths)."""
    return locate(kind, name)


def available(kind):
    return list(entries(kind))
