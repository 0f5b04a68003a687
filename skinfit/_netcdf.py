"""The groups of a saved fit read with h5py directly, as h5netcdf and xarray would read them.

h5netcdf finds each variable's dimensions by dereferencing HDF5 object references and reads
every attribute twice; for the plain layout :meth:`skinfit.fit.Fit.save` writes (groups of
numeric or string variables, every axis named by a dimension scale in the same group, no
variable shorter than its dimensions) reading the datasets directly gives the same Datasets
in half the time (bench/results/report_commands.md). Anything else raises :class:`NotPlain`,
and the caller reads the file with h5netcdf as before.
"""

import h5py
import numpy as np
import xarray as xr

#: HDF5 attributes that carry netCDF-4's structure, not the user's attributes (as h5netcdf hides them).
HIDDEN = frozenset(("REFERENCE_LIST", "CLASS", "DIMENSION_LIST", "NAME", "_Netcdf4Dimid",
                    "_Netcdf4Coordinates", "_nc3_strict", "_NCProperties"))
_NOT_A_VARIABLE = b"This is a netCDF dimension but not a netCDF variable"


class NotPlain(Exception):
    """The file is not of the plain layout read here (read it with h5netcdf)."""


def attribute(attrs, key):
    """HDF5 attribute ``key`` as h5netcdf returns it: fixed-length strings decoded, string
    arrays as lists, a one-element array as its element, an empty string attribute as b""."""
    value = attrs[key]
    if isinstance(value, h5py.Empty):
        info = h5py.check_string_dtype(value.dtype)
        return b"" if info and info.length == 1 else np.array([], dtype=attrs.get_id(key).dtype)
    info = h5py.check_string_dtype(attrs.get_id(key).dtype)
    if info is not None:
        if info.length is not None and info.length > 1:
            value = (value.decode(info.encoding, "surrogateescape") if np.isscalar(value)
                     else [b.decode(info.encoding, "surrogateescape") for b in value.flat])
        elif not np.isscalar(value):
            value = value.tolist()
    if not np.isscalar(value) and len(value) == 1:
        return value[0]
    return value


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
            attrs = {k: _text(attribute(f.attrs, k)) for k in f.attrs if k not in HIDDEN}
            return order, attrs, {name: _group(f[name]) for name in order if wanted(name)}
        except (TypeError, ValueError, KeyError, AttributeError, IndexError) as exc:
            raise NotPlain(f"{type(exc).__name__}: {exc}") from exc


def _text(value):
    return value.decode() if isinstance(value, bytes) else value


def _dimensions(group, name, d, dims):
    """A dataset's dimension names as h5netcdf finds them: a dimension scale's from its
    dimension ids (``_Netcdf4Coordinates``) or its own name; a variable's from the dimension
    scales its ``DIMENSION_LIST`` references (the last one attached to each axis)."""
    if d.attrs.get("CLASS") == b"DIMENSION_SCALE":
        ids = d.attrs.get("_Netcdf4Coordinates")
        if ids is None:
            return (name,)
        ids = np.atleast_1d(ids)
        if any(int(i) not in dims for i in ids):
            raise NotPlain(f"{group.name}/{name}: dimension ids not in the group")
        return tuple(dims[int(i)][0] for i in ids)
    if not d.ndim:
        return ()
    refs = d.attrs.get("DIMENSION_LIST")
    if refs is None or len(refs) != d.ndim or any(len(r) == 0 for r in refs):
        raise NotPlain(f"{group.name}/{name}: not every axis has a dimension scale")
    names = []
    for r in refs:
        path = group.file[r[-1]].name
        if path.rpartition("/")[0] != group.name:
            raise NotPlain(f"{group.name}/{name}: a dimension outside its group ({path})")
        names.append(path.rpartition("/")[2])
    return tuple(names)


def _group(group):
    """One group as a decoded Dataset (variables in the file's order, as h5netcdf lists them)."""
    datasets, dims = [], {}
    for name in group:
        d = group.get(name) if isinstance(group.get(name, getlink=True), h5py.HardLink) else None
        if not isinstance(d, h5py.Dataset) or name.startswith("_nc4_non_coord_"):
            raise NotPlain(f"{group.name}/{name}: not a dataset of the group")
        if d.attrs.get("CLASS") == b"DIMENSION_SCALE":
            dimid = d.attrs.get("_Netcdf4Dimid")
            if d.ndim != 1 or dimid is None or int(dimid) in dims:
                raise NotPlain(f"{group.name}/{name}: not a dimension scale of the plain layout")
            dims[int(dimid)] = (name, d.shape[0])
            if _NOT_A_VARIABLE in bytes(d.attrs.get("NAME", b"")):
                continue
        datasets.append((name, d))
    sizes = dict(dims.values())
    variables = {}
    for name, d in datasets:
        names = _dimensions(group, name, d, dims)
        if any(n not in sizes for n in names) or tuple(sizes[n] for n in names) != d.shape:
            raise NotPlain(f"{group.name}/{name}: dimensions not in the group, or padded")
        info = h5py.check_string_dtype(d.dtype)
        if info is not None and info.length is None:
            values = d.asstr()[...]
        elif d.dtype.kind in "biuf" and h5py.check_enum_dtype(d.dtype) is None or info is not None:
            values = d[...]
        else:
            raise NotPlain(f"{group.name}/{name}: data type {d.dtype}")
        variables[name] = xr.Variable(names, values, attrs={k: attribute(d.attrs, k) for k in d.attrs
                                                            if k not in HIDDEN})
    attrs = {k: _text(attribute(group.attrs, k)) for k in group.attrs if k not in HIDDEN}
    return xr.decode_cf(xr.Dataset(variables, attrs=attrs))
