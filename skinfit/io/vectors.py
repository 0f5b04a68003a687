"""Named vectors in MATLAB ``.mat`` files (v5 through scipy.io, v7.3 through h5py) and HDF5
files (h5py): the columns of a lab table kept as one vector per quantity.

A table is a MATLAB struct of equal-length vectors (``data.normal_force``, ...), a struct array
of scalars (``table2struct(T)``), or vectors at the top level of the file; in HDF5, a group of
equal-length 1-D datasets (a ``unit``/``units`` attribute gives a dataset's unit).  Which one
is read is ``variable`` (a struct's name or a group's path, ``/`` for the top level), found when
the file holds one candidate only; several are an error listing them.  A MATLAB ``table`` object
cannot be read outside MATLAB: the error says how to save it as a struct.
"""

from __future__ import annotations

import io

import h5py
import numpy as np
import scipy.io

from skinfit.errors import InputError

__all__ = ["read_mat", "read_hdf5"]

_NOT_READABLE = ("a MATLAB object (a table?) that only MATLAB can read: save its columns as a struct, "
                 "s = table2struct(T, 'ToScalar', true); save(FILE, 's') (or writetable(T, 'FILE.csv'))")


def _text(value):
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    return str(value)


def _column(value):
    """A list of cell texts from a MATLAB/HDF5 value that is a vector (numbers or strings), or
    None with why it is not one."""
    if isinstance(value, str):
        return [value], None
    if isinstance(value, (list, tuple)):
        if all(isinstance(v, (str, bytes)) for v in value):
            return [_text(v).strip() for v in value], None
        return None, "a cell array that is not of strings"
    if isinstance(value, (int, float, np.number)) and not isinstance(value, bool):
        return [repr(float(value))], None
    if not isinstance(value, np.ndarray):
        return None, f"a {type(value).__name__}"
    arr = np.squeeze(value)
    if arr.ndim > 1:
        return None, f"a {'x'.join(map(str, value.shape))} matrix (no column names: a raw recording is read by " \
                     "skinfit ingest)"
    arr = np.atleast_1d(arr)
    if arr.dtype.kind in "biuf":
        return [repr(float(v)) for v in arr.astype(float)], None
    if arr.dtype.kind in "SU" or (arr.dtype.kind == "O" and all(isinstance(v, (str, bytes)) for v in arr)):
        return [_text(v).strip() for v in arr], None
    if arr.dtype.kind == "c":
        return None, "complex numbers"
    return None, f"values of type {arr.dtype}"


def _table(fields, where, what):
    """Columns (name -> texts) from a mapping of vectors, and what was skipped; lengths must agree
    (scalars beside longer vectors are skipped: a sample rate is not a column)."""
    columns, skipped = {}, []
    for name, value in fields.items():
        col, why = _column(value)
        if col is None:
            skipped.append(f"{name}: {why}")
        else:
            columns[name] = col
    if not columns:
        raise InputError(where, f"{what} holds no vectors of numbers or strings"
                         + (f" ({'; '.join(skipped)})" if skipped else ""), field="variable")
    n = max(len(c) for c in columns.values())
    for name in [k for k, c in columns.items() if len(c) == 1 and n > 1]:
        skipped.append(f"{name}: a scalar")
        del columns[name]
    lengths = {k: len(c) for k, c in columns.items()}
    if len(set(lengths.values())) > 1:
        (a, na), (b, nb) = sorted(lengths.items(), key=lambda t: t[1])[0], max(lengths.items(), key=lambda t: t[1])
        raise InputError(where, f"vectors of different lengths in {what}: {a!r} has {na} values, {b!r} has {nb} "
                                "(a table's columns must have one value per row)", field=f"column {a!r}")
    return columns, skipped


def _records(array):
    """Columns from a struct array of scalar fields (``table2struct(T)``)."""
    keys = list(array.flat[0])
    return {k: np.array([r[k] for r in array.flat], dtype=object if isinstance(array.flat[0][k], str) else float)
            for k in keys}


def _select(variables, where, variable):
    """(variable, columns, skipped) of the one table among the top-level ``variables`` (name ->
    struct dict, struct array, vector...), or the one named ``variable``."""
    structs = {k: v for k, v in variables.items() if isinstance(v, dict)
               or (isinstance(v, np.ndarray) and v.dtype == object and v.size and isinstance(v.flat[0], dict))}
    opaque = [k for k, v in variables.items() if v is _OPAQUE]
    if variable not in (None, "/"):
        if variable not in variables:
            raise InputError(where, f"no variable {variable!r} (the file has {', '.join(map(repr, variables))})",
                             field="variable")
        if variables[variable] is _OPAQUE:
            raise InputError(where, _NOT_READABLE.replace("FILE", repr(where)), field=f"variable {variable!r}")
        if variable not in structs:
            raise InputError(where, f"{variable!r} is not a struct of named vectors: name a struct (or '/' for "
                                    "the vectors at the top level of the file)", field="variable")
        value = structs[variable]
        fields = value if isinstance(value, dict) else _records(value)
        return (variable, *_table(fields, where, f"struct {variable!r}"))
    vectors = {k: v for k, v in variables.items() if k not in structs and k not in opaque}
    if variable == "/":
        return ("/", *_table(vectors, where, "the top level of the file"))
    usable = [k for k, v in vectors.items() if _column(v)[0] is not None and len(_column(v)[0]) > 1]
    candidates = list(structs) + (["/ (the vectors at the top level)"] if usable else [])
    if len(candidates) == 1:
        return _select(variables, where, next(iter(structs)) if structs else "/")
    if not candidates and opaque:
        raise InputError(where, _NOT_READABLE.replace("FILE", repr(where)), field=f"variable {opaque[0]!r}")
    if not candidates:
        raise InputError(where, "holds no table (a struct of named vectors, or named vectors at the top level; "
                                f"variables: {', '.join(map(repr, variables)) or 'none'})", field="variable")
    raise InputError(where, f"holds {len(candidates)} tables ({', '.join(candidates)}): name one (--variable, "
                            "or variable in [read])", field="variable")


_OPAQUE = object()  # a MATLAB object that only MATLAB reads


def read_mat(raw, where, variable=None):
    """``(variable, columns, units, skipped)`` of the table in a MATLAB file (v5 or v7.3):
    columns maps each vector's name to its cell texts; a .mat states no units (``{}``)."""
    if raw[:20].startswith(b"MATLAB 7.3"):
        with h5py.File(io.BytesIO(raw), "r") as f:
            variables = {k: _from_v73(f, f[k]) for k in f if not k.startswith("#")}
        name, columns, skipped = _select(variables, where, variable)
        return name, columns, {}, skipped
    try:
        doc = scipy.io.loadmat(io.BytesIO(raw), simplify_cells=True)
    except (ValueError, TypeError, NotImplementedError, OSError) as exc:  # what scipy.io raises for a bad file
        raise InputError(where, f"not a readable MATLAB file ({exc})") from None
    variables = {k: (_OPAQUE if isinstance(v, scipy.io.matlab.MatlabOpaque) else v)
                 for k, v in doc.items() if not k.startswith("__")}
    name, columns, skipped = _select(variables, where, variable)
    return name, columns, {}, skipped


def _from_v73(f, node):
    """A v7.3 (HDF5) MATLAB variable as scipy.io's simplified one: a struct as a dict, a char
    array as a str, a cell array of strings as a list, numbers as an array (MATLAB stores them
    transposed: a column vector is (1, n))."""
    cls = node.attrs.get("MATLAB_class", b"")
    cls = cls.decode() if isinstance(cls, bytes) else str(cls)
    if isinstance(node, h5py.Group):
        if cls == "struct" or not cls:
            return {k: _from_v73(f, node[k]) for k in node}
        return _OPAQUE
    if "MATLAB_object_decode" in node.attrs or cls in ("table", "string", "datetime", "categorical"):
        return _OPAQUE
    data = node[()]
    if node.attrs.get("MATLAB_empty", 0):
        return np.zeros(0)
    if cls == "char":
        return "".join(map(chr, np.asarray(data).T.ravel()))
    if cls == "cell":
        return [_from_v73(f, f[ref]) for ref in np.asarray(data).T.ravel()]
    return np.asarray(data).T


def read_hdf5(raw, where, variable=None):
    """``(group, columns, units, skipped)`` of the table in an HDF5 file: a group of equal-length
    1-D datasets; a dataset's ``unit`` or ``units`` attribute is its unit."""
    try:
        f = h5py.File(io.BytesIO(raw), "r")
    except OSError as exc:
        raise InputError(where, f"not a readable HDF5 file ({exc})") from None
    with f:
        groups = {}
        f.visititems(lambda name, obj: groups.setdefault("/" + name, obj) if isinstance(obj, h5py.Group) else None)
        groups = {"/": f, **groups}
        tables = [g for g, obj in groups.items() if sum(isinstance(v, h5py.Dataset) for v in obj.values()) >= 2]
        if variable is None:
            if len(tables) != 1:
                raise InputError(where, f"holds {len(tables)} groups of datasets "
                                 f"({', '.join(map(repr, tables)) or 'none'}): name one (--variable, "
                                 "or variable in [read])" if tables else "holds no group of 1-D datasets",
                                 field="variable")
            variable = tables[0]
        key = "/" + variable.strip("/") if variable.strip("/") else "/"
        if key not in groups:
            raise InputError(where, f"no group {variable!r} (groups: {', '.join(map(repr, groups))})",
                             field="variable")
        fields, units = {}, {}
        for name, obj in groups[key].items():
            if isinstance(obj, h5py.Dataset):
                fields[name] = obj.asstr()[()] if h5py.check_string_dtype(obj.dtype) else obj[()]
                unit = obj.attrs.get("unit", obj.attrs.get("units"))
                if unit is not None:
                    units[name] = _text(unit).strip()
        columns, skipped = _table(fields, where, f"group {key!r}")
    return key, columns, {k: u for k, u in units.items() if k in columns}, skipped
