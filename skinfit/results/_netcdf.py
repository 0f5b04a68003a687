"""The groups of a saved fit read with h5py directly, as h5netcdf and xarray would read them.

h5netcdf finds each variable's dimensions by dereferencing HDF5 object references and reads
every attribute twice; for the plain layout :meth:`skinfit.results.fit.Fit.save` writes (groups of
numeric or string variables, every axis named by a dimension scale in the same group, no
variable shorter than its dimensions) reading the datasets directly gives the same Datasets
in half the time (bench/results/report_commands.md). Anything else raises :class:`NotPlain`,
and the caller reads the file with h5netcdf as before.
"""

import h5py
import numpy as np
import xarray as xr
from h5py import h5, h5a, h5p, h5r, h5t

#: HDF5 attributes that carry netCDF-4's structure, not the user's attributes (as h5netcdf hides them).
HIDDEN = frozenset(("REFERENCE_LIST", "CLASS", "DIMENSION_LIST", "NAME", "_Netcdf4Dimid",
                    "_Netcdf4Coordinates", "_nc3_strict", "_NCProperties"))
#: Those of :data:`HIDDEN` this reader does not use (a dimension scale's back references, the
#: file's provenance), so not read.
_UNUSED = frozenset(("REFERENCE_LIST", "_nc3_strict", "_NCProperties"))
_NOT_A_VARIABLE = b"This is a netCDF dimension but not a netCDF variable"


class NotPlain(Exception):
    """The file is not of the plain layout read here (read it with h5netcdf)."""


def _attributes(obj):
    """``{name: (value, dtype)}`` of the attributes of HDF5 group or dataset ``obj`` in h5py's
    order, but those of :data:`_UNUSED`; each value as ``obj.attrs[name]`` gives it, each
    attribute opened once (h5py's ``attrs[name]`` and ``attrs.get_id(name)`` open it once each,
    ``attrs.get`` once more)."""
    oid = obj.id
    cpl = oid.get_create_plist()
    tracked = cpl.get_attr_creation_order() & h5p.CRT_ORDER_TRACKED
    cpl.close()
    names = []
    h5a.iterate(oid, lambda name, *_: names.append(name),
                index_type=h5.INDEX_CRT_ORDER if tracked else h5.INDEX_NAME)
    out = {}
    for name in names:  # named as h5py names them (UTF-8, else the bytes), each read as its attrs[name] reads it
        try:
            key = name.decode("utf-8")
        except UnicodeDecodeError:
            key = name
        if key in _UNUSED:
            continue
        attr = h5a.open(oid, name)
        dtype, shape = attr.dtype, attr.shape
        if shape is None:
            out[key] = (h5py.Empty(dtype), dtype)
            continue
        memory, mtype = dtype, h5t.py_create(dtype)
        if dtype.subdtype is not None:  # an array type: read as its elements' type, its shape appended
            memory, sub = dtype.subdtype
            shape = shape + sub
        value = np.zeros(shape, dtype=memory)
        attr.read(value, mtype=mtype)
        info = h5t.check_string_dtype(memory)
        if info is not None and info.length is None:
            value = np.array([b.decode("utf-8", "surrogateescape") for b in value.flat],
                             dtype=memory).reshape(value.shape)
        out[key] = (value[()] if value.ndim == 0 else value, dtype)
    return out


def attribute(value, dtype):
    """An HDF5 attribute (``value``, ``dtype`` as :func:`_attributes` gives them) as h5netcdf
    returns it: fixed-length strings decoded, string arrays as lists, a one-element array as its
    element, an empty string attribute as b""."""
    if isinstance(value, h5py.Empty):
        info = h5py.check_string_dtype(value.dtype)
        return b"" if info and info.length == 1 else np.array([], dtype=dtype)
    info = h5py.check_string_dtype(dtype)
    if info is not None:
        if info.length is not None and info.length > 1:
            value = (value.decode(info.encoding, "surrogateescape") if np.isscalar(value)
                     else [b.decode(info.encoding, "surrogateescape") for b in value.flat])
        elif not np.isscalar(value):
            value = value.tolist()
    if not np.isscalar(value) and len(value) == 1:
        return value[0]
    return value


def _user(raw):
    """The user's attributes of :func:`_attributes`' ``raw`` (netCDF-4's structure left out) as
    h5netcdf returns them."""
    return {k: attribute(*v) for k, v in raw.items() if k not in HIDDEN}


def read_groups(path, wanted):
    """``(order, attrs, datasets)`` of the netCDF-4 file at ``path``: the names of its groups
    in the file's order, its root attributes (bytes decoded) and, for each group name for
    which ``wanted(name)`` is true, the group as an xarray Dataset decoded by
    ``xarray.decode_cf``. Raises :class:`NotPlain` for another layout (variables at the root,
    nested groups, user types, dimensions not resolved within the group, padded variables)."""
    with h5py.File(path, "r") as f:
        order = list(f)
        if not all(isinstance(f.get(name, getlink=True), h5py.HardLink) and isinstance(f.get(name), h5py.Group)
                   for name in order):
            raise NotPlain("not only groups at the root")
        try:  # anything unexpected in the metadata: h5netcdf decides (and names the problem)
            attrs = {k: _text(v) for k, v in _user(_attributes(f["/"])).items()}
            return order, attrs, {name: _group(f[name]) for name in order if wanted(name)}
        except (TypeError, ValueError, KeyError, AttributeError, IndexError) as exc:
            raise NotPlain(f"{type(exc).__name__}: {exc}") from exc


def _text(value):
    return value.decode() if isinstance(value, bytes) else value


def _dimensions(group, name, d, raw, dims):
    """A dataset's dimension names as h5netcdf finds them: a dimension scale's from its
    dimension ids (``_Netcdf4Coordinates``) or its own name; a variable's from the dimension
    scales its ``DIMENSION_LIST`` references (the last one attached to each axis). ``raw``:
    the dataset's attributes (:func:`_attributes`)."""
    if _value(raw, "CLASS") == b"DIMENSION_SCALE":
        ids = _value(raw, "_Netcdf4Coordinates")
        if ids is None:
            return (name,)
        ids = np.atleast_1d(ids)
        if any(int(i) not in dims for i in ids):
            raise NotPlain(f"{group.name}/{name}: dimension ids not in the group")
        return tuple(dims[int(i)][0] for i in ids)
    if not d.ndim:
        return ()
    refs = _value(raw, "DIMENSION_LIST")
    if refs is None or len(refs) != d.ndim or any(len(r) == 0 for r in refs):
        raise NotPlain(f"{group.name}/{name}: not every axis has a dimension scale")
    names = []
    for r in refs:
        path = h5r.get_name(r[-1], d.id).decode("utf-8", "surrogateescape")
        if path.rpartition("/")[0] != group.name:
            raise NotPlain(f"{group.name}/{name}: a dimension outside its group ({path})")
        names.append(path.rpartition("/")[2])
    return tuple(names)


def _value(raw, key):
    """Attribute ``key``'s value in :func:`_attributes`' ``raw``, None when absent (``attrs.get``)."""
    return raw[key][0] if key in raw else None


def _group(group):
    """One group as a decoded Dataset (variables in the file's order, as h5netcdf lists them)."""
    datasets, dims = [], {}
    for name in group:
        d = group.get(name) if isinstance(group.get(name, getlink=True), h5py.HardLink) else None
        if not isinstance(d, h5py.Dataset) or name.startswith("_nc4_non_coord_"):
            raise NotPlain(f"{group.name}/{name}: not a dataset of the group")
        raw = _attributes(d)
        if _value(raw, "CLASS") == b"DIMENSION_SCALE":
            dimid = _value(raw, "_Netcdf4Dimid")
            if d.ndim != 1 or dimid is None or int(dimid) in dims:
                raise NotPlain(f"{group.name}/{name}: not a dimension scale of the plain layout")
            dims[int(dimid)] = (name, d.shape[0])
            if _NOT_A_VARIABLE in bytes(_value(raw, "NAME") or b""):
                continue
        datasets.append((name, d, raw))
    sizes = dict(dims.values())
    variables = {}
    for name, d, raw in datasets:
        names = _dimensions(group, name, d, raw, dims)
        if any(n not in sizes for n in names) or tuple(sizes[n] for n in names) != d.shape:
            raise NotPlain(f"{group.name}/{name}: dimensions not in the group, or padded")
        info = h5py.check_string_dtype(d.dtype)
        if info is not None and info.length is None:
            values = d.asstr()[...]
        elif d.dtype.kind in "biuf" and h5py.check_enum_dtype(d.dtype) is None or info is not None:
            values = d[...]
        else:
            raise NotPlain(f"{group.name}/{name}: data type {d.dtype}")
        variables[name] = xr.Variable(names, values, attrs=_user(raw))
    attrs = {k: _text(v) for k, v in _user(_attributes(group)).items()}
    return xr.decode_cf(xr.Dataset(variables, attrs=attrs))
