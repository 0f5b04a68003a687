"""Checksums of the results skinfit saves: a damaged file is refused, never read as other numbers.

Two checks. The bytes: :func:`seal` appends to a netCDF file's bytes their sha256
(:data:`TRAILER`, 81 bytes past HDF5's end of file, which HDF5 readers ignore), and
:func:`check_file` compares them before any library parses the file, because HDF5 itself
hangs reading a text attribute whose heap was zeroed (h5py 3.16, HDF5 2.0.0;
bench/results/integrity.md). The content: :func:`stamp` records in a root attribute
(:data:`RECORD`) the sha256 of the root attributes (provenance, records, the caches of
evidence, LOO and summary) and of each group (its attributes, and each variable's name,
dimensions, shape, type, attributes and values), as decoded, so that any reader giving the
same Datasets (skinfit's, h5netcdf, ``xarray.open_datatree``) can check them with
:func:`take` and :func:`verify`; skinfit does so for a file without the trailer (its end lost,
or written by another tool), each group as it is read.

A file of a schema (:data:`SCHEMA_ATTR`) from before the checksums is read with an
:class:`~skinfit.errors.IntegrityWarning`: refusing it would strand every result saved
before, and nothing in it can tell damage from an edit. A later one without the record lost
it to damage, and is refused.
"""

import hashlib
import json
import warnings

import numpy as np

from skinfit.errors import InputError, IntegrityWarning

__all__ = ["RECORD", "SCHEMA_ATTR", "CHECKED_SCHEMA", "TRAILER", "seal", "check_file",
           "digest_attrs", "digest_group", "groups_of", "stamp", "take", "verify"]

#: Root attribute holding the checksums (JSON: ``{"algorithm", "root", "groups": {name: hex}}``).
RECORD = "skinfit_checksums"
#: Root attribute with the file's schema version: from :data:`CHECKED_SCHEMA` on, the file
#: carries :data:`RECORD`.
SCHEMA_ATTR = "skinfit_schema"
CHECKED_SCHEMA = 2
_ALGORITHM = "sha256 of the decoded content, format 1"
#: The start of the last bytes of a sealed file: this, the sha256 (hex) of every byte before it, a newline.
TRAILER = b"\nskinfit sha256 "
_TRAILER_SIZE = len(TRAILER) + 64 + 1


def seal(data):
    """The bytes of a netCDF file (``data``, bytes-like) followed by their sha256 (:data:`TRAILER`)."""
    return bytes(data) + TRAILER + hashlib.sha256(data).hexdigest().encode() + b"\n"


def check_file(path):
    """Compare the bytes of the file at ``path`` with the sha256 its :data:`TRAILER` records,
    reading it as plain bytes (no HDF5). Returns True when they match, False for a file without
    the trailer; raises :class:`InputError` (one line) when they differ."""
    with open(path, "rb") as f:
        size = f.seek(0, 2)
        if size < _TRAILER_SIZE:
            return False
        f.seek(size - _TRAILER_SIZE)
        tail = f.read(_TRAILER_SIZE)
        if not tail.startswith(TRAILER):
            return False
        expected = tail[len(TRAILER):-1]
        h, left = hashlib.sha256(), size - _TRAILER_SIZE
        f.seek(0)
        while left:
            block = f.read(min(left, 1 << 22))
            if not block:
                break
            h.update(block)
            left -= len(block)
    if h.hexdigest().encode() != expected:
        raise InputError(path, "damaged: its bytes differ from what skinfit wrote (sha256 recorded in its last "
                               f"{_TRAILER_SIZE} bytes): the file changed after it was saved (a disk or copy error, "
                               "or an edit); restore it from a copy or fit again")
    return True


def _plain(value):
    """An attribute value as the same JSON-able value whichever reader gave it: numpy scalars
    and arrays as Python values, bytes decoded, a one-element list as its element (h5netcdf
    returns a one-element array attribute as its element)."""
    if isinstance(value, dict):
        return {_text(k): _plain(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        value = value.tolist()
    elif isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bytes):
        return _text(value)
    if isinstance(value, (list, tuple)):
        items = [_plain(v) for v in value]
        return items[0] if len(items) == 1 else items
    return value


def _text(value):
    return value.decode("utf-8", "surrogateescape") if isinstance(value, bytes) else str(value)


def digest_attrs(attrs):
    """sha256 (hex) of a mapping of attributes, :data:`RECORD` left out."""
    plain = {_text(k): _plain(v) for k, v in attrs.items() if k != RECORD}
    return hashlib.sha256(json.dumps(plain, sort_keys=True, default=str).encode()).hexdigest()


def digest_group(ds):
    """sha256 (hex) of an xarray Dataset: its attributes and, per variable (coordinates
    included, by name), its dimensions, shape, type (text as text: a str array in memory, an
    object array from a file), attributes and values (numbers as little-endian bytes)."""
    h = hashlib.sha256()
    h.update(json.dumps(_plain({k: v for k, v in ds.attrs.items() if k != RECORD}), sort_keys=True,
                        default=str).encode())  # (the root's attributes hold the record itself)
    for name in sorted(ds.variables, key=str):
        var = ds.variables[name]
        values = np.asarray(var.values)
        kind = values.dtype.kind
        if kind in "OUS":
            tag, payload = "text", json.dumps([_text(v) for v in values.ravel().tolist()]).encode()
        elif kind in "biufc":
            tag = f"{kind}{values.dtype.itemsize}"
            payload = np.ascontiguousarray(values, dtype=values.dtype.newbyteorder("<")).tobytes()
        elif kind in "mM":
            tag, payload = values.dtype.str[1:], np.ascontiguousarray(values.view("<i8")).tobytes()
        else:
            raise TypeError(f"variable {name!r}: data type {values.dtype} cannot be checksummed")
        head = [_text(name), [_text(d) for d in var.dims], list(values.shape), tag, _plain(dict(var.attrs))]
        h.update(json.dumps(head, sort_keys=True, default=str).encode())
        h.update(len(payload).to_bytes(8, "little"))
        h.update(payload)
    return h.hexdigest()


def stamp(tree):
    """Record in ``tree``'s root attributes (an ``xarray.DataTree`` about to be written, whose
    :data:`SCHEMA_ATTR` the caller set) the checksums of its root attributes and groups.
    Returns the record (a dict)."""
    record = {"algorithm": _ALGORITHM, "root": digest_attrs(tree.attrs),
              "groups": {name: digest_group(ds) for name, ds in groups_of(tree).items()}}
    tree.attrs[RECORD] = json.dumps(record)
    return record


def groups_of(tree):
    """{name: Dataset} of every node of ``tree`` (an ``xarray.DataTree``) below its root, named by
    their path from it (``posterior``, ``prior/nested``), and the root's own variables as ``/``
    when it has any."""
    out = {node.relative_to(tree): node.to_dataset(inherit=False) for node in tree.subtree if node is not tree}
    if tree.to_dataset(inherit=False).variables:
        out["/"] = tree.to_dataset(inherit=False)
    return out


def take(path, attrs, groups, *, sealed=False, unversioned=None):
    """The checksum record of a file read from ``path``: read from its root ``attrs``, parsed,
    and checked against them and the names of the file's ``groups``. Returns the record; None
    for a file whose bytes :func:`check_file` found as written (``sealed``: nothing more to
    check), and for a file of a schema before checksums (read with an
    :class:`~skinfit.errors.IntegrityWarning`; ``unversioned``: the schema of a file without
    :data:`SCHEMA_ATTR`, None when every file of its kind has one). Raises
    :class:`InputError` (one line: the file and what failed) when the record is missing,
    unreadable or does not match."""
    if sealed:
        return None
    text = attrs.get(RECORD)
    schema = attrs.get(SCHEMA_ATTR, unversioned)
    if text is None:
        if _schema(schema) is not None and _schema(schema) < CHECKED_SCHEMA:
            warnings.warn(f"{path}: written before skinfit recorded checksums: read without a check for damage "
                          "(save it again with this skinfit to add one)", IntegrityWarning, stacklevel=3)
            return None
        raise InputError(path, f"damaged: its checksum record (root attribute {RECORD}) is missing"
                               + ("" if schema is not None else f", and so is its schema ({SCHEMA_ATTR})")
                               + ": restore the file from a copy or fit again")
    try:
        record = json.loads(text)
        if not (isinstance(record, dict) and isinstance(record.get("root"), str)
                and isinstance(record.get("groups"), dict) and record.get("algorithm") == _ALGORITHM):
            raise ValueError("not a checksum record")
    except (ValueError, TypeError):
        raise InputError(path, f"damaged: its checksum record (root attribute {RECORD}) cannot be read: restore "
                               "the file from a copy or fit again") from None
    missing = [g for g in record["groups"] if g != "/" and "/" not in g and g not in groups]
    extra = [g for g in groups if g not in record["groups"]]
    if missing or extra:
        what = "; ".join(filter(None, [f"group(s) {', '.join(missing)} missing" if missing else "",
                                       f"group(s) {', '.join(extra)} not written by skinfit" if extra else ""]))
        raise InputError(path, f"damaged: {what}: restore the file from a copy or fit again")
    verify(path, record, attrs=attrs)
    return record


def verify(path, record, *, attrs=None, groups=None):
    """Check root ``attrs`` and ``groups`` ({name: Dataset}) read from ``path`` against
    ``record`` (from :func:`take`; nothing is checked when it is None). Raises
    :class:`InputError` naming the file and the part whose content differs."""
    if record is None:
        return
    if attrs is not None and digest_attrs(attrs) != record["root"]:
        _damaged(path, "its root attributes (provenance, sampler and misfit records, cached evidence, LOO and "
                       "summary)")
    for name, ds in (groups or {}).items():
        expected = record["groups"].get(name)
        if expected is None:
            raise InputError(path, f"damaged: group {name} is not in its checksum record: restore the file from a "
                                   "copy or fit again")
        try:
            found = digest_group(ds)
        except TypeError as exc:
            raise InputError(path, f"damaged: group {name}: {exc}") from None
        if found != expected:
            _damaged(path, f"group {name}")


def _damaged(path, what):
    raise InputError(path, f"damaged: the content of {what} differs from what skinfit wrote (sha256 mismatch): "
                           "the file changed after it was saved (a disk or copy error, or an edit); restore it "
                           "from a copy or fit again")


def _schema(value):
    try:
        return int(value)
    except (TypeError, ValueError):
        return None
