"""Datasets (datasets/<id>/dataset.toml + a CSV, a CSV with units in its header, or a pandas
DataFrame): loaded, validated and converted to SI.

This is the data boundary: every unit conversion in skinfit happens here (:mod:`skinfit.io.units`),
and every problem with a user's data is reported with the file, column, row and what was
expected.  Nothing ambiguous is guessed: a row with more or fewer fields than the header, a
header naming a column twice, two columns read as one name, a unit of the wrong dimension for
the model are errors.  Only regular files inside the card's folder (or named explicitly) are
read, up to ``$SKINFIT_MAX_DATA_MB``.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pandas as pd

from skinfit.errors import InputError, InputTypeError
from skinfit.io import tables
from skinfit.io.arguments import check_path, frame_type_error
from skinfit.io.models import Model, check_id, load_model
from skinfit.io.paths import display
from skinfit.io.toml import available, find_file, read_regular, read_toml, require
from skinfit.io.units import NONNEGATIVE, parse_unit

__all__ = ["Dataset", "Column", "load_dataset", "list_datasets", "from_frame", "as_dataset", "check_units",
           "write_card", "validate_table", "max_data_bytes", "PROVENANCE_KINDS"]

PROVENANCE_KINDS = ("measured", "digitised", "simulated")


@dataclass(frozen=True)
class Column:
    header: str  # as in the CSV
    name: str  # skinfit name
    unit: str | None  # unit in the CSV; None for categories
    kind: str  # "quantity" | "category"
    optional: bool = False
    signed: bool = False
    missing_when: tuple | None = None  # (header, label): missing by design exactly on those rows
    allowed: tuple | None = None  # the only values a row may take (card units), e.g. (-1, 1)
    positive: bool = False  # values must be > 0 (e.g. a wavelength)


@dataclass(frozen=True, eq=False)
class Dataset:
    """A validated dataset: a tidy frame in SI units plus its card.

    ``frame`` columns carry the skinfit names (docs/models/); quantities are float64 in SI,
    categories are strings.  ``units`` gives, per column, the unit the data came in.
    """

    id: str
    title: str
    frame: pd.DataFrame
    columns: tuple
    groups: tuple
    provenance: MappingProxyType
    model: str | None
    path: str
    sha256: str  # of the card and the data file together
    card_file: str = ""  # absolute path of the card read ("" for a CSV without one or a DataFrame)
    data_file: str = ""  # absolute path of the data file read ("" when the values come from elsewhere)
    data_sha256: str = ""  # sha256 of the data file's bytes

    @property
    def units(self):
        return {c.name: c.unit for c in self.columns if c.unit}

    def column(self, name):
        for c in self.columns:
            if c.name == name:
                return c
        raise KeyError(name)

    def subset(self, mask, suffix):
        """A new Dataset holding the rows selected by boolean ``mask`` (for per-group fits)."""
        frame = self.frame.loc[np.asarray(mask)].reset_index(drop=True)
        digest = hashlib.sha256((self.sha256 + suffix).encode()).hexdigest()
        return Dataset(f"{self.id}[{suffix}]", self.title, frame, self.columns, self.groups,
                       self.provenance, self.model, self.path, digest, card_file=self.card_file,
                       data_file=self.data_file, data_sha256=self.data_sha256)

    def with_observations(self, values, label):
        """A copy whose observable columns hold ``values`` (column -> (n,) array, SI units), e.g.
        data simulated on this dataset's design; ``label`` is appended to the id and hashed."""
        frame = self.frame.copy()
        h = hashlib.sha256((self.sha256 + label).encode())
        for col, v in values.items():
            frame[col] = np.asarray(v, dtype=float)
            h.update(frame[col].to_numpy().tobytes())
        return Dataset(f"{self.id}[{label}]", self.title, frame, self.columns, self.groups,
                       self.provenance, self.model, self.path, h.hexdigest(), card_file=self.card_file)

    @classmethod
    def from_frame(cls, frame: pd.DataFrame, *, units: Mapping[str, str] | None = None,
                   columns: Mapping[str, str] | None = None, model: str | Model | None = None, id: str = "frame",
                   title: str = "") -> Dataset:
        """A Dataset from a pandas DataFrame: see :func:`skinfit.io.data.from_frame`."""
        return from_frame(frame, units=units, columns=columns, model=model, id=id, title=title)

    def __len__(self):
        return len(self.frame)

    def __repr__(self):
        return f"Dataset({self.id!r}, rows={len(self.frame)}, columns={list(self.frame.columns)})"


def _columns(doc, where):
    table = require(doc, "columns", dict, where)
    cols = []
    for key, spec in table.items():
        prefix = f"columns.{key}."
        if not isinstance(spec, dict):
            raise InputError(where, "expected a table (unit = ..., or kind = \"category\")",
                             field=f"columns.{key}")
        header = require(spec, "from", str, where, field_prefix=prefix, default=key)
        if "from" in spec and "name" in spec:
            raise InputError(where, "give the file's header as `from` and the skinfit name as the key, not also "
                             "`name`", field=prefix + "name")
        kind = require(spec, "kind", str, where, field_prefix=prefix, default="quantity")
        if kind not in ("quantity", "category"):
            raise InputError(where, f"expected kind 'quantity' or 'category' (got {kind!r})",
                             field=prefix + "kind")
        unit = None
        if kind == "quantity":
            unit = require(spec, "unit", str, where, field_prefix=prefix)
            _unit(unit, where, prefix + "unit")
        cols.append(Column(header, require(spec, "name", str, where, field_prefix=prefix, default=key),
                           unit, kind, require(spec, "optional", bool, where, field_prefix=prefix, default=False),
                           require(spec, "signed", bool, where, field_prefix=prefix, default=False),
                           _missing_when(spec, where, prefix, table), _allowed(spec, where, prefix),
                           require(spec, "positive", bool, where, field_prefix=prefix, default=False)))
    _unique_names(cols, where)
    return tuple(cols)


def _unique_names(cols, where):
    """Two columns read into one skinfit name would let one overwrite the other: refused."""
    seen = {}
    for c in cols:
        if c.name in seen:
            raise InputError(where, f"columns {seen[c.name]!r} and {c.header!r} are both read as {c.name!r} "
                             "(each skinfit name can come from one column only)", field=f"columns.{c.header}.name")
        seen[c.name] = c.header


def _unit(unit, where, field):
    try:
        return parse_unit(unit)
    except ValueError as exc:
        raise InputError(where, str(exc), field=field) from None


def _allowed(spec, where, prefix):
    """``allowed = [-1, 1]``: the only values the column may take."""
    values = require(spec, "allowed", list, where, field_prefix=prefix, default=None)
    if values is None:
        return None
    if not values or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        raise InputError(where, f"expected a non-empty list of numbers (got {values!r})", field=prefix + "allowed")
    return tuple(float(v) for v in values)


def _missing_when(spec, where, prefix, table):
    """``missing_when = {column = "texture", equals = "flat"}``: blank exactly on those rows."""
    cond = require(spec, "missing_when", dict, where, field_prefix=prefix, default=None)
    if cond is None:
        return None
    column = require(cond, "column", str, where, field_prefix=prefix + "missing_when.")
    equals = require(cond, "equals", str, where, field_prefix=prefix + "missing_when.")
    if column not in table:
        raise InputError(where, f"names column {column!r}, which is not declared under [columns]",
                         field=prefix + "missing_when.column")
    other = table[column]
    return (other.get("from", column) if isinstance(other, dict) else column, equals)


def max_data_bytes():
    """Largest data file read [bytes]: ``$SKINFIT_MAX_DATA_MB`` MiB, default 64 MiB (~2.5 M rows of
    four numbers; the pointwise groups of a fit hold draws x rows values each)."""
    try:
        return int(float(os.environ.get("SKINFIT_MAX_DATA_MB", 64)) * 2**20)
    except ValueError:
        raise InputError("SKINFIT_MAX_DATA_MB", f"expected a number of MiB (got "
                         f"{os.environ['SKINFIT_MAX_DATA_MB']!r})") from None


def load_dataset(name: str | os.PathLike, *, model: str | Model | None = None, units: Mapping[str, str] | None = None,
                 columns: Mapping[str, str] | None = None, max_bytes: int | None = None) -> Dataset:
    """Load a dataset by id (``datasets/<id>/``), by the path of its folder or card (one written
    by ``skinfit dataset init`` reads a lab's file through its ``[read]`` options and column
    map), or from a table file without a card whose header gives the units (``normal_force [mN],
    voltage [V], ...``; a CSV, or an Excel, MATLAB or HDF5 file).

    ``model`` (a Model or id), ``units`` (column -> unit, for headers without one) and
    ``columns`` (header -> skinfit name) serve a file without a card: the model says which
    columns are quantities, and their units are checked against its card.  A card's data
    ``file`` must lie inside the card's folder.
    """
    max_bytes = max_data_bytes() if max_bytes is None else max_bytes
    p = Path(check_path(name, "load_dataset", None, "a dataset id, its folder or card, or a CSV file"))
    if p.suffix.lower() in (".csv", ".txt") or (p.exists() and not p.is_dir() and p.suffix != ".toml"):
        return _load_csv(p, model=model, units=units, columns=columns, max_bytes=max_bytes)
    if columns:
        raise InputError(display(p), "columns= applies to a file without a card (a card maps its columns)")
    card = find_file("datasets", name)
    doc, text = read_toml(card)
    where = display(card)
    columns = _columns(doc, where)
    data_path = _data_file(card, require(doc, "file", str, where), where)
    groups = tuple(require(doc, "groups", list, where, default=[]))
    by_name = {c.name: c for c in columns}
    for g in groups:
        if not isinstance(g, str) or g not in by_name:
            raise InputError(where, f"group column {g!r} is not declared under [columns]", field="groups")
    provenance = dict(require(doc, "provenance", dict, where))
    kind = require(provenance, "kind", str, where, field_prefix="provenance.")
    if kind not in PROVENANCE_KINDS:
        raise InputError(where, f"expected one of {', '.join(PROVENANCE_KINDS)} (got {kind!r})",
                         field="provenance.kind")
    if kind == "simulated":
        for key in ("seed", "generating_parameters"):
            if key not in provenance:
                raise InputError(where, "simulated data must record its generating parameters and seed",
                                 field=f"provenance.{key}")
    raw = read_regular(data_path, max_bytes, "data file", where=display(data_path))
    recorded = provenance.get("sha256")
    if recorded is not None and recorded != hashlib.sha256(raw).hexdigest():
        raise InputError(where, f"{data_path.name} is not the file this card was written for (its sha256 "
                         f"differs from the one recorded)", field="provenance.sha256")
    read = require(doc, "read", dict, where, default=None)
    if read is None:
        frame = read_table(raw, columns, display(data_path))
    else:  # a lab's file as exported, read with the card's options (skinfit dataset init)
        lab = tables.read_lab_table(raw, display(data_path), tables.check_read(read, where))
        frame = validate_table(lab.cells, columns, display(data_path), rows=lab.rows)
    digest = hashlib.sha256(text.encode() + b"\0" + raw).hexdigest()
    ds = Dataset(id=check_id(require(doc, "id", str, where, default=card.parent.name), where),
                 title=require(doc, "title", str, where, default=""), frame=frame,
                 columns=columns, groups=groups, provenance=MappingProxyType(provenance),
                 model=doc.get("model"), path=where, sha256=digest, card_file=str(Path(card).resolve()),
                 data_file=str(Path(data_path).resolve()), data_sha256=hashlib.sha256(raw).hexdigest())
    if model is None and isinstance(ds.model, str):
        try:
            model = _as_model(ds.model)
        except InputError:  # a card naming a model not installed here: checked when fitted
            model = None
    if model is not None:
        check_units(ds, model)
    return ds


def _data_file(card, file, where):
    """The card's data ``file``, which must name a file inside the card's folder."""
    folder = card.parent.resolve()
    path = (folder / file).resolve()
    if Path(file).is_absolute() or not path.is_relative_to(folder):
        raise InputError(where, "must name a file inside the dataset's folder (to fit a file elsewhere, "
                         "pass its path: skinfit fit MODEL path/to/data.csv)", field="file")
    return path


def _columns_from_header(headers, where, model, units, columns=None, file_units=None, si=False):
    """Columns of a table without a card: units from ``name [unit]`` headers, ``units``
    (header or name -> unit) or the file (``file_units``, header -> unit); ``columns`` (header ->
    skinfit name) renames headers, whose ``(unit)`` is then read too.  Columns without a unit are
    categories, except the model's covariates and observables (an error, or with ``si`` in the
    model's SI unit: a model made from a Python function, whose covariates are SI by its contract)."""
    units, columns, file_units = dict(units or {}), dict(columns or {}), dict(file_units or {})
    quantities = set()
    if model is not None:
        quantities = {q.name for q in (*model.covariates, *model.observables)}
    cols, used = [], set()
    for h in headers:
        name, unit = tables.split_unit(h) if h in columns else tables.split_header(h)
        name = columns.get(h, name)
        if h in file_units and unit is None:
            unit = file_units[h]
        for key in dict.fromkeys((h, name)):
            if key in units:
                if unit is not None and units[key] != unit:
                    raise InputError(where, f"the header says [{unit}] and units= says {units[key]!r}: "
                                     "give one", field=f"column {h!r}")
                unit = units[key]
                used.add(key)
        if unit is not None:
            _unit(unit, where, f"column {h!r}")
            cols.append(Column(h, name, unit, "quantity"))
        elif name in quantities and si:
            cols.append(Column(h, name, _example_unit(model, name), "quantity"))
        elif name in quantities:
            raise InputError(where, f"no unit for {name!r}, which model {model.id!r} needs as a quantity: write "
                             f"'{name} [unit]' in the header (e.g. [{_example_unit(model, name)}]) or pass "
                             f"units={{{name!r}: ...}}", field=f"column {h!r}")
        else:
            cols.append(Column(h, name, None, "category"))
    unknown = set(units) - used
    if unknown:
        raise InputError(where, f"units= names columns the file does not have: {sorted(unknown)}")
    if model is not None:
        missing = [q.name for q in (*model.covariates, *model.observables[:1])
                   if not q.optional and q.name not in {c.name for c in cols}]
        if missing:
            raise InputError(where, f"model {model.id!r} needs a column {missing[0]!r} "
                             f"[{_example_unit(model, missing[0])}] (the file has "
                             f"{', '.join(tables.quote_headers(headers))}; map a header to it with columns=, or for a "
                             "file with skinfit dataset init --column)", field=f"column {missing[0]!r}")
    _unique_names(cols, where)
    return tuple(cols)


def _check_columns(columns, headers, where):
    """``columns=`` (header -> skinfit name) checked: headers the table has, names skinfit can
    hold, no name given twice."""
    if columns is None:
        return {}
    if not isinstance(columns, Mapping):
        raise InputTypeError(where, f"expected a mapping header -> skinfit name (got {type(columns).__name__})",
                             field="columns")
    seen = {}
    for h, name in columns.items():
        if h not in headers:
            raise InputError(where, f"columns= names a header the table does not have (it has "
                             f"{', '.join(tables.quote_headers(list(headers)))})", field=f"column {h!r}")
        if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
            raise InputError(where, f"expected a skinfit name such as 'normal_force' (got {name!r})",
                             field=f"columns[{h!r}]")
        if name in seen:
            raise InputError(where, f"columns= maps {seen[name]!r} and {h!r} both to {name!r} (one column each)",
                             field=f"column {h!r}")
        seen[name] = h
    return dict(columns)


def _example_unit(model, name):
    return next(q.unit for q in (*model.covariates, *model.observables) if q.name == name)


def _as_model(model):
    if model is None or not isinstance(model, str):
        return model
    return load_model(model)


def _load_csv(path, *, model=None, units=None, columns=None, max_bytes=None):
    """A dataset from a table file without a card: a CSV with units in its header (``name
    [unit]``), or an Excel, MATLAB or HDF5 file whose column names are skinfit's."""
    model = _as_model(model)
    where = display(path)
    raw = read_regular(path, max_data_bytes() if max_bytes is None else max_bytes, "data file", where=where)
    if tables.detect_format(raw, where) == "csv":
        headers, _ = tables.split_csv(raw, where)
        columns = _columns_from_header(headers, where, model, units, _check_columns(columns, headers, where))
        frame = read_table(raw, columns, where)
    else:  # read with the libraries made for the format (skinfit.io.tables)
        lab = tables.read_lab_table(raw, where)
        columns = _columns_from_header(lab.headers, where, model, units, _check_columns(columns, lab.headers, where),
                                       file_units=lab.units)
        frame = validate_table(lab.cells, columns, where, rows=lab.rows)
    sha = hashlib.sha256(raw).hexdigest()
    provenance = {"kind": "measured", "note": "read from a CSV without a dataset card (kind assumed)",
                  "source_file": str(Path(path).resolve()), "sha256": sha}
    ident = re.sub(r"[^A-Za-z0-9_.+-]", "_", Path(path).stem).lstrip(".") or "data"
    digest = hashlib.sha256(json.dumps([[c.header, c.name, c.unit] for c in columns]).encode() + b"\0"
                            + raw).hexdigest()
    ds = Dataset(id=ident, title=f"{Path(path).name} (no card)", frame=frame, columns=columns,
                 groups=tuple(c.name for c in columns if c.kind == "category"),
                 provenance=MappingProxyType(provenance), model=getattr(model, "id", None), path=where,
                 sha256=digest, data_file=str(Path(path).resolve()), data_sha256=sha)
    if model is not None:
        check_units(ds, model)
    return ds


def from_frame(frame: pd.DataFrame, *, units: Mapping[str, str] | None = None,
               columns: Mapping[str, str] | None = None, model: str | Model | None = None, id: str = "frame",
               title: str = "") -> Dataset:
    """A Dataset from a pandas DataFrame, validated as a CSV is: column names may carry their
    unit (``"normal_force [mN]"``), ``columns`` maps a header to a skinfit name (``{"Normal force
    (mN)": "normal_force"}``, the ``(mN)`` then read as its unit), ``units`` gives a unit (header
    or skinfit name -> unit); values converted to SI (a function model's unitless columns: its SI)."""
    if not isinstance(frame, pd.DataFrame):
        raise frame_type_error(frame, "DataFrame")
    model = _as_model(model)
    where = f"DataFrame {id!r}"
    check_id(id, where, field="id")
    headers = [str(c) for c in frame.columns]
    if len(set(headers)) != len(headers):
        dup = next(h for h in headers if headers.count(h) > 1)
        raise InputError(where, "column name appears twice", field=f"column {dup!r}")
    if len(frame) == 0:
        raise InputError(where, "no data rows")
    cols = _columns_from_header(headers, where, model, units, _check_columns(columns, headers, where),
                                si=getattr(model, "user_function", False))
    table = {}
    for h, (_, col) in zip(headers, frame.items()):
        if pd.api.types.is_numeric_dtype(col.dtype) and not pd.api.types.is_bool_dtype(col.dtype):
            values = col.to_numpy(dtype=float, na_value=np.nan)
            table[h] = pd.Series([repr(float(v)) for v in values], dtype=object)
        else:
            table[h] = pd.Series(["" if v is None or (isinstance(v, float) and np.isnan(v)) else str(v)
                                  for v in col.to_numpy(dtype=object)], dtype=object)
    out = validate_table(pd.DataFrame(table), cols, where)
    h = hashlib.sha256(json.dumps([[c.header, c.name, c.unit] for c in cols]).encode())
    for name in out.columns:
        h.update(name.encode() + b"\0" + (out[name].to_numpy().tobytes() if out[name].dtype.kind == "f"
                                           else "\0".join(map(str, out[name])).encode()))
    ds = Dataset(id=id, title=title, frame=out, columns=cols,
                 groups=tuple(c.name for c in cols if c.kind == "category"),
                 provenance=MappingProxyType({"kind": "measured", "note": "from a pandas DataFrame"}),
                 model=getattr(model, "id", None), path=where, sha256=h.hexdigest())
    if model is not None:
        check_units(ds, model)
    return ds


def as_dataset(data, model=None, units=None, columns=None):
    """A Dataset from a Dataset, a DataFrame, a CSV path, a dataset id or card path."""
    if isinstance(data, Dataset):
        if units or columns:
            raise InputError("units" if units else "columns", "applies to a DataFrame or a file without a card, "
                             "not to a loaded Dataset")
        return data
    if isinstance(data, pd.DataFrame):
        return from_frame(data, units=units, columns=columns, model=model)
    if isinstance(data, (Mapping, np.ndarray)) or type(data).__module__.startswith("xarray"):
        raise frame_type_error(data, "dataset")
    check_path(data, "dataset", None, "a Dataset, a pandas DataFrame, a dataset id, its folder or card, or a CSV file")
    if units and Path(data).suffix.lower() not in (".csv", ".txt"):
        raise InputError("units", "units= applies to a DataFrame or a CSV; a dataset card states its units")
    return load_dataset(data, model=model, units=units, columns=columns)


def check_units(dataset, model):
    """Every model covariate and observable present in ``dataset`` has a unit of the dimension
    the model card states (a force in mm or a dimensionless force is refused, naming the column)."""
    model = _as_model(model)
    for q in (*model.covariates, *model.observables):
        for c in dataset.columns:
            if c.name != q.name:
                continue
            field = f"column {c.header!r}"
            if c.kind != "quantity":
                raise InputError(dataset.path, f"is declared a category, model {model.id!r} needs a quantity "
                                 f"in {q.unit}", field=field)
            expected = parse_unit(q.unit)
            got = _unit(c.unit, dataset.path, field)
            if got.dims != expected.dims:
                raise InputError(dataset.path, f"unit {c.unit!r} is a {got.name}; model {model.id!r} needs "
                                 f"{q.name} as a {expected.name} (e.g. {q.unit})", field=field)


def write_card(dataset, folder, data_name="data.csv"):
    """Write ``dataset`` as a dataset folder (``dataset.toml`` + the data in SI units is NOT
    written: the original CSV is copied) so that a fit made without a card can be rerun.

    Only for datasets read from a CSV without a card (their provenance names the source file).
    Returns the card's path.
    """
    src = dataset.provenance.get("source_file")
    if not src:
        raise InputError(dataset.path, "only a dataset read from a CSV file can be written as a card")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    target = folder / data_name
    if not (target.exists() and target.samefile(src)):  # the CSV given may be the copy a run wrote before
        shutil.copyfile(src, target)
    lines = ["schema_version = 1", f"id = {json.dumps(dataset.id)}",
             f"title = {json.dumps(dataset.title.replace(' (no card)', ''))}"]
    if dataset.model:
        lines.append(f"model = {json.dumps(dataset.model)}")
    lines += [f"file = {json.dumps(data_name)}", f"groups = {json.dumps(list(dataset.groups))}", "",
              "[provenance]"]
    lines += [f"{k} = {json.dumps(v)}" for k, v in dataset.provenance.items()]
    with open(target, "rb") as fh:  # a workbook, MATLAB or HDF5 file (whatever its name) is read as one
        fmt = tables.detect_format(fh.read(4096), display(target))
    lines += ["", "[read]", f'format = "{fmt}"'] if fmt != "csv" else []
    for c in dataset.columns:
        lines += ["", f"[columns.{json.dumps(c.header)}]", f"name = {json.dumps(c.name)}"]
        lines.append(f"unit = {json.dumps(c.unit)}" if c.unit else 'kind = "category"')
    path = folder / "dataset.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def read_table(raw, columns, where):
    """Parse CSV bytes against the declared columns; returns the SI frame."""
    header, rows = tables.split_csv(raw, where)
    if not rows:
        raise InputError(where, "no data rows (expected at least one row below the header)")
    table = pd.DataFrame({h: pd.Series(v, dtype=object) for h, v in zip(header, zip(*rows))})
    return validate_table(table, columns, where)


def _match(columns, table, where):
    """CSV header of each declared column: the card's key equals the header, or its name part
    (``normal_force`` matches ``normal_force [mN]``, whose unit must then agree with the card's)."""
    names = {tables.split_header(h)[0]: h for h in table.columns}
    out = {}
    for col in columns:
        h = col.header if col.header in table.columns else names.get(col.header)
        if h is None:
            raise InputError(where, f"missing column (the card declares it; the file has "
                             f"{', '.join(tables.quote_headers(list(table.columns)))})", field=f"column {col.header!r}")
        unit = tables.split_header(h)[1]
        if unit is not None and col.unit is not None and h != col.header and unit != col.unit:
            raise InputError(where, f"the header says [{unit}], the card says {col.unit!r}: which is meant "
                             "is ambiguous", field=f"column {h!r}")
        out[col.header] = h
    return out


def _shown(text):
    return repr(text if len(text) <= 24 else text[:21] + "...")


def validate_table(table, columns, where, *, rows=None):
    """Check each declared column of ``table`` (a DataFrame of cell texts, as read) and convert
    it to SI; returns the frame of skinfit names.  ``rows`` ((n,) int) numbers the rows in
    messages as the user sees the file (default: 1-based data rows)."""
    headers = _match(columns, table, where)
    numbers = np.arange(1, len(table) + 1) if rows is None else np.asarray(rows)

    def row(i):
        return int(numbers[i])

    out = {}
    for col in columns:
        text = table[headers[col.header]].astype(str).str.strip()
        blank = text.eq("") | text.str.lower().isin(["nan", "na", "n/a", "null", "none", "<na>"])
        field = f"column {headers[col.header]!r}"
        if col.kind == "category":
            if blank.any() and not col.optional:
                raise InputError(where, "empty group label (expected a name for every row)",
                                 field=field, row=row(int(np.argmax(blank.to_numpy()))))
            out[col.name] = text.astype(object)
            continue
        unit = parse_unit(col.unit)
        values = pd.to_numeric(text.where(~blank, "nan"), errors="coerce").to_numpy(dtype=float)
        bad = np.isnan(values) & ~blank.to_numpy()
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(where, f"expected a number in {col.unit} (got {_shown(text.iloc[i])})",
                             field=field, row=row(i))
        if col.missing_when:
            other, label = col.missing_when
            if other not in headers:
                raise InputError(where, "missing column (the card declares it)", field=f"column {other!r}")
            by_design = (table[headers[other]].astype(str).str.strip() == label).to_numpy()
            absent = np.isnan(values)
            if (absent & ~by_design).any():
                i = int(np.argmax(absent & ~by_design))
                raise InputError(where, f"missing value (expected a number in {col.unit}; only rows with "
                                 f"{other} = {label!r} leave it empty by design)", field=field, row=row(i))
            if (~absent & by_design).any():
                i = int(np.argmax(~absent & by_design))
                raise InputError(where, f"expected no value on a row with {other} = {label!r} (missing "
                                 f"by design; got {_shown(text.iloc[i])})", field=field, row=row(i))
        elif np.isnan(values).any() and not col.optional:
            i = int(np.argmax(np.isnan(values)))
            raise InputError(where, f"missing value (expected a number in {col.unit}; declare "
                             f"`optional = true` if it is missing by design)", field=field, row=row(i))
        if np.isinf(values).any():
            i = int(np.argmax(np.isinf(values)))
            raise InputError(where, f"expected a finite number (got {_shown(text.iloc[i])})", field=field, row=row(i))
        dim = unit.name
        if dim in NONNEGATIVE and not col.signed and (values < 0).any():
            i = int(np.argmax(values < 0))
            raise InputError(where, f"expected a {dim} >= 0 (got {values[i]:g} {col.unit}; declare "
                             f"`signed = true` if negative values are meaningful)", field=field, row=row(i))
        present = ~np.isnan(values)
        if col.positive and (present & (values <= 0)).any():
            i = int(np.argmax(present & (values <= 0)))
            raise InputError(where, f"expected a value > 0 (got {values[i]:g} {col.unit})", field=field, row=row(i))
        if col.allowed and (present & ~np.isin(values, col.allowed)).any():
            i = int(np.argmax(present & ~np.isin(values, col.allowed)))
            raise InputError(where, f"expected one of {', '.join(f'{v:g}' for v in col.allowed)} "
                             f"(got {_shown(text.iloc[i])})", field=field, row=row(i))
        si = values * unit.factor
        if not np.isfinite(si[present]).all():
            i = int(np.argmax(present & ~np.isfinite(si)))
            raise InputError(where, f"{text.iloc[i]} {col.unit} overflows in SI units", field=field, row=row(i))
        out[col.name] = si
    return pd.DataFrame(out)


def list_datasets() -> list[str]:
    return sorted(available("datasets"))

