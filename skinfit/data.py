"""Datasets (datasets/<id>/dataset.toml + a CSV): loaded, validated and converted to SI.

This is the data boundary: every unit conversion in skinfit happens here, and every problem
with a user's data is reported with the file, column, row and what was expected.
"""

import hashlib
import io
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pandas as pd

from ._toml import available, find_file, read_toml, require
from .errors import InputError
from .models import _display
from .units import NONNEGATIVE, UNITS, dimension, to_si

__all__ = ["Dataset", "load_dataset", "list_datasets", "PROVENANCE_KINDS"]

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
                       self.provenance, self.model, self.path, digest)

    def with_observations(self, values, label):
        """A copy whose observable columns hold ``values`` (column -> (n,) array, SI units), e.g.
        data simulated on this dataset's design; ``label`` is appended to the id and hashed."""
        frame = self.frame.copy()
        h = hashlib.sha256((self.sha256 + label).encode())
        for col, v in values.items():
            frame[col] = np.asarray(v, dtype=float)
            h.update(frame[col].to_numpy().tobytes())
        return Dataset(f"{self.id}[{label}]", self.title, frame, self.columns, self.groups,
                       self.provenance, self.model, self.path, h.hexdigest())

    def __len__(self):
        return len(self.frame)

    def __repr__(self):
        return f"Dataset({self.id!r}, rows={len(self.frame)}, columns={list(self.frame.columns)})"


def _columns(doc, where):
    table = require(doc, "columns", dict, where)
    cols = []
    for header, spec in table.items():
        prefix = f"columns.{header}."
        if not isinstance(spec, dict):
            raise InputError(where, "expected a table (unit = ..., or kind = \"category\")",
                             field=f"columns.{header}")
        kind = require(spec, "kind", str, where, field_prefix=prefix, default="quantity")
        if kind not in ("quantity", "category"):
            raise InputError(where, f"expected kind 'quantity' or 'category' (got {kind!r})",
                             field=prefix + "kind")
        unit = None
        if kind == "quantity":
            unit = require(spec, "unit", str, where, field_prefix=prefix)
            if unit not in UNITS:
                raise InputError(where, f"unknown unit {unit!r} (known: {', '.join(UNITS)})",
                                 field=prefix + "unit")
        cols.append(Column(header, require(spec, "name", str, where, field_prefix=prefix, default=header),
                           unit, kind, require(spec, "optional", bool, where, field_prefix=prefix, default=False),
                           require(spec, "signed", bool, where, field_prefix=prefix, default=False),
                           _missing_when(spec, where, prefix, table), _allowed(spec, where, prefix),
                           require(spec, "positive", bool, where, field_prefix=prefix, default=False)))
    return tuple(cols)


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
    return (column, equals)


def load_dataset(name):
    """Load a dataset by id (``datasets/<id>/``) or by the path of its folder or card."""
    card = find_file("datasets", name)
    doc, text = read_toml(card)
    where = _display(card)
    columns = _columns(doc, where)
    data_path = card.parent / require(doc, "file", str, where)
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
    try:
        raw = data_path.read_bytes()
    except FileNotFoundError:
        raise InputError(where, f"data file {data_path.name!r} not found beside the card", field="file") from None
    frame = read_table(raw, columns, _display(data_path))
    digest = hashlib.sha256(text.encode() + b"\0" + raw).hexdigest()
    return Dataset(id=require(doc, "id", str, where, default=card.parent.name),
                   title=require(doc, "title", str, where, default=""), frame=frame,
                   columns=columns, groups=groups, provenance=MappingProxyType(provenance),
                   model=doc.get("model"), path=where, sha256=digest)


def read_table(raw, columns, where):
    """Parse CSV bytes against the declared columns; returns the SI frame."""
    try:
        table = pd.read_csv(io.BytesIO(raw), dtype=str, keep_default_na=False, skipinitialspace=True)
    except pd.errors.EmptyDataError:
        raise InputError(where, "the file is empty (expected a header row and data rows)") from None
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise InputError(where, f"not a readable CSV file ({str(exc).strip()})") from None
    if len(table) == 0:
        raise InputError(where, "no data rows (expected at least one row below the header)")
    out = {}
    for col in columns:
        if col.header not in table.columns:
            raise InputError(where, f"missing column (the card declares it; the file has "
                             f"{', '.join(map(repr, table.columns))})", field=f"column {col.header!r}")
        text = table[col.header].str.strip()
        blank = text.eq("") | text.str.lower().isin(["nan", "na", "n/a", "null", "none"])
        field = f"column {col.header!r}"
        if col.kind == "category":
            if blank.any() and not col.optional:
                raise InputError(where, "empty group label (expected a name for every row)",
                                 field=field, row=int(np.argmax(blank.to_numpy())) + 1)
            out[col.name] = text.astype(object)
            continue
        values = pd.to_numeric(text.where(~blank, "nan"), errors="coerce").to_numpy(dtype=float)
        bad = np.isnan(values) & ~blank.to_numpy()
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(where, f"expected a number in {col.unit} (got {text.iloc[i]!r})",
                             field=field, row=i + 1)
        if col.missing_when:
            other, label = col.missing_when
            if other not in table.columns:
                raise InputError(where, "missing column (the card declares it)", field=f"column {other!r}")
            by_design = (table[other].str.strip() == label).to_numpy()
            absent = np.isnan(values)
            if (absent & ~by_design).any():
                i = int(np.argmax(absent & ~by_design))
                raise InputError(where, f"missing value (expected a number in {col.unit}; only rows with "
                                 f"{other} = {label!r} leave it empty by design)", field=field, row=i + 1)
            if (~absent & by_design).any():
                i = int(np.argmax(~absent & by_design))
                raise InputError(where, f"expected no value on a row with {other} = {label!r} (missing "
                                 f"by design; got {text.iloc[i]!r})", field=field, row=i + 1)
        elif np.isnan(values).any() and not col.optional:
            i = int(np.argmax(np.isnan(values)))
            raise InputError(where, f"missing value (expected a number in {col.unit}; declare "
                             f"`optional = true` if it is missing by design)", field=field, row=i + 1)
        if np.isinf(values).any():
            i = int(np.argmax(np.isinf(values)))
            raise InputError(where, f"expected a finite number (got {text.iloc[i]!r})", field=field, row=i + 1)
        dim = dimension(col.unit)
        if dim in NONNEGATIVE and not col.signed and (values < 0).any():
            i = int(np.argmax(values < 0))
            raise InputError(where, f"expected a {dim} >= 0 (got {values[i]:g} {col.unit}; declare "
                             f"`signed = true` if negative values are meaningful)", field=field, row=i + 1)
        present = ~np.isnan(values)
        if col.positive and (present & (values <= 0)).any():
            i = int(np.argmax(present & (values <= 0)))
            raise InputError(where, f"expected a value > 0 (got {values[i]:g} {col.unit})", field=field, row=i + 1)
        if col.allowed and (present & ~np.isin(values, col.allowed)).any():
            i = int(np.argmax(present & ~np.isin(values, col.allowed)))
            raise InputError(where, f"expected one of {', '.join(f'{v:g}' for v in col.allowed)} "
                             f"(got {text.iloc[i]!r})", field=field, row=i + 1)
        out[col.name] = values * to_si(col.unit)
    return pd.DataFrame(out)


def list_datasets():
    return sorted(available("datasets"))

