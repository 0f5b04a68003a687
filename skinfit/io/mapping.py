"""From a lab's table to a dataset card (``skinfit dataset init``): the mapping of the file's
headers to a model's covariates and observables is proposed, checked and written into a card
that reads the original file unchanged.

A header maps to a model's name when its normalised form equals it (``"Normal force (mN)"``
and ``"normal_force [mN]"`` -> ``normal_force``; case, spaces, punctuation and camelCase
ignored); anything else (``"Ft"``) only when the user maps it (``columns``, or ``--column
"Ft=tangential_force:mN"``).  The unit comes from the header (``(mN)``, ``[mN]``), the file
(an HDF5 ``unit`` attribute) or the user, and must be of the dimension the model card states.
A column the model needs that no header reads as, two headers read as one name, two units for
one column are errors naming the file and the columns.  The file's other columns are kept in
the card (optional; grouping columns when they hold labels).
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from skinfit.errors import InputError, InputTypeError
from skinfit.io.arguments import check_output_folder, check_path
from skinfit.io.data import Column, Dataset, load_dataset, max_data_bytes, validate_table
from skinfit.io.models import Model, check_id, load_model
from skinfit.io.paths import display
from skinfit.io.tables import READ_KEYS, Table, check_read, quote_headers, read_lab_table, split_unit
from skinfit.io.toml import read_regular
from skinfit.io.units import parse_unit

__all__ = ["Mapped", "normalise", "parse_column", "propose", "init_dataset", "card_text", "unit_source", "CARD"]

#: The card written into the output folder.
CARD = "dataset.toml"
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


@dataclass(frozen=True)
class Mapped:
    """One column of a lab table as the card reads it: the file's ``header``, the skinfit
    ``name``, its ``unit`` (None for labels), its ``role`` for the model (``covariate``,
    ``observable`` or ``kept``: not used by the model) and where the unit came from
    (``header``, ``file``, ``given``; ``""`` for labels)."""

    header: str
    name: str
    unit: str | None
    role: str
    unit_from: str
    given: bool  # mapped by the user (columns=/--column), not by its normalised name


def normalise(header):
    """The name a header reads as: its unit part dropped, camelCase split, lower case, runs of
    other characters as ``_`` (``"Normal force (mN)"`` -> ``"normal_force"``)."""
    name = split_unit(header)[0]
    name = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name)
    return re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")


def parse_column(text):
    """``"HEADER=name"`` or ``"HEADER=name:unit"`` (``--column``) -> ``(header, name, unit or
    None)``; the header is everything before the last ``=``."""
    header, sep, target = text.rpartition("=")
    name, _, unit = target.partition(":")
    if not sep or not header.strip() or not _NAME.fullmatch(name.strip()) or (_ and not unit.strip()):
        raise InputError("--column", f"expected \"HEADER=name\" or \"HEADER=name:unit\", e.g. "
                         f"\"Fn=normal_force:mN\" (got {text!r})")
    return header.strip(), name.strip(), unit.strip() or None


def _given(table, columns, units):
    """``columns`` (header -> name) and ``units`` (header or name -> unit) checked against the table."""
    where, row = table.where, table.header_row
    for arg, value in (("columns", columns), ("units", units)):
        if not isinstance(value, Mapping):
            raise InputTypeError(arg, f"expected a mapping (got {type(value).__name__})")
    seen = {}
    for h, name in columns.items():
        if h not in table.headers:
            raise InputError(where, f"no such header (the file has {', '.join(quote_headers(list(table.headers)))})",
                             field=f"column {h!r}", row=row)
        if not isinstance(name, str) or not _NAME.fullmatch(name):
            raise InputError(where, f"expected a skinfit name such as 'normal_force' for it (got {name!r})",
                             field=f"column {h!r}")
        if name in seen:
            raise InputError(where, f"both mapped to {name!r}: which one is meant is ambiguous",
                             field=f"columns {seen[name]!r} and {h!r}", row=row)
        seen[name] = h
    names = {columns.get(h, normalise(h)) for h in table.headers}
    for key, unit in units.items():
        if key not in table.headers and key not in names:
            raise InputError(where, "a unit is given for a column the file does not have", field=f"column {key!r}")
        _parse(unit, where, f"column {key!r}")


def _parse(unit, where, field):
    try:
        return parse_unit(unit)
    except (ValueError, TypeError) as exc:
        raise InputError(where, str(exc), field=field) from None


def _unit(table, header, name, units):
    """(unit, where it came from) of a column: the header's, the file's, the user's; two that
    differ are ambiguous."""
    found = [(u, src) for u, src in ((split_unit(header)[1], "header"), (table.units.get(header), "file"),
                                     (units.get(header, units.get(name)), "given")) if u is not None]
    for u, src in found[1:]:
        if u != found[0][0]:
            raise InputError(table.where, f"the {found[0][1]} says {found[0][0]!r}, the {src} says {u!r}: which "
                             "is meant is ambiguous", field=f"column {header!r}", row=table.header_row)
    return found[0] if found else (None, "")


def propose(table: Table, model: Model, columns: Mapping[str, str] | None = None,
            units: Mapping[str, str] | None = None) -> tuple[tuple[Mapped, ...], tuple[str, ...]]:
    """The mapping of ``table``'s headers to ``model``'s names: ``(mapped, ignored)``, the
    columns read (the model's first, then the others kept) and the headers not read, with why."""
    columns, units = dict(columns or {}), dict(units or {})
    _given(table, columns, units)
    where, row = table.where, table.header_row
    reads = {h: columns.get(h, normalise(h)) for h in table.headers}
    roles = {q.name: "observable" for q in model.observables} | {q.name: "covariate" for q in model.covariates}
    needed = [q for q in (*model.covariates, *model.observables[:1]) if not q.optional]
    mapped, taken = [], {}
    for q in (*model.covariates, *model.observables):
        given = [h for h in table.headers if columns.get(h) == q.name]
        found = given or [h for h in table.headers if h not in columns and reads[h] == q.name]
        if len(found) > 1:
            raise InputError(where, f"both read as {q.name!r}: which one is meant is ambiguous (map one: --column "
                             f"\"{found[0]}={q.name}\", or columns={{{found[0]!r}: {q.name!r}}})",
                             field=f"columns {found[0]!r} and {found[1]!r}", row=row)
        if not found:
            if q in needed:
                raise InputError(where, f"model {model.id!r} needs {q.name} [{q.unit}] and no header reads as it "
                                 f"(the file has {', '.join(quote_headers(list(table.headers)))}): map one with "
                                 f"--column \"HEADER={q.name}\" (Python: columns={{HEADER: {q.name!r}}})",
                                 field=f"column {q.name!r}")
            continue
        h = found[0]
        unit, src = _unit(table, h, q.name, units)
        if unit is None:
            raise InputError(where, f"no unit for {q.name} (model {model.id!r} needs it in {q.unit}): write it in "
                             f"the header ({q.name} ({q.unit})) or give it: --column \"{h}={q.name}:{q.unit}\" "
                             f"(Python: units={{{q.name!r}: {q.unit!r}}})", field=f"column {h!r}", row=row)
        got, expected = _parse(unit, where, f"column {h!r}"), parse_unit(q.unit)
        if got.dims != expected.dims:
            raise InputError(where, f"unit {unit!r} is a {got.name}; model {model.id!r} needs {q.name} as a "
                             f"{expected.name} (e.g. {q.unit})", field=f"column {h!r}", row=row)
        mapped.append(Mapped(h, q.name, unit, roles[q.name], src, h in columns))
        taken[q.name] = h
    ignored = []
    for j, h in enumerate(table.headers):
        if h in taken.values():
            continue
        name = reads[h] or f"column_{j + 1}"
        if not _NAME.fullmatch(name):
            name = f"column_{j + 1}_{name}" if name[0].isdigit() else f"column_{j + 1}"
        if name in taken:
            ignored.append(f"{h!r}: reads as {name!r}, which is read from {taken[name]!r}")
            continue
        unit, src = _unit(table, h, name, units)
        mapped.append(Mapped(h, name, unit, "kept", src, h in columns))
        taken[name] = h
    return tuple(mapped), tuple(ignored)


def _columns(mapped):
    """Columns of the Dataset the card declares: the model's as quantities, the others kept optional
    (and signed: not the model's, so no sign is assumed)."""
    return tuple(Column(m.header, m.name, m.unit, "quantity" if m.unit else "category", optional=m.role == "kept",
                        signed=m.role == "kept") for m in mapped)


def unit_source(m):
    """Where a mapped column's unit came from, for people: "from the header", "given"..."""
    return "given" if m.unit_from == "given" else f"from the {m.unit_from}"


def _numbers(cells):
    """True when every non-empty cell of a column reads as a number (labels that are numbers, a
    temperature without a unit skinfit reads, are kept but are no grouping column)."""
    values = pd.to_numeric(cells[cells.str.strip() != ""], errors="coerce")
    return bool(len(values)) and not values.isna().any()


def _toml(value):
    return json.dumps(value)  # a JSON string is a TOML basic string (the same escapes)


def _key(name):
    return name if _NAME.fullmatch(name) else _toml(name)


def card_text(*, ident, title, model, file, table, mapped, ignored, source, sha256, kind, out):
    """The text of the dataset card ``dataset init`` writes."""
    groups = [m.name for m in mapped if m.role == "kept" and m.unit is None and not _numbers(table.cells[m.header])]
    lines = ["# Written by `skinfit dataset init`: review the mapping of the file's headers below, then fit:",
             f"#   skinfit fit {model.id} {out}",
             "schema_version = 1", f"id = {_toml(ident)}", f"title = {_toml(title)}", f"model = {_toml(model.id)}",
             f"file = {_toml(file)}  # the original file, unchanged (its sha256 below)",
             f"groups = {json.dumps(groups)}", "", "[provenance]", f"kind = {_toml(kind)}",
             f"note = {_toml('written by skinfit dataset init; kind as given (default measured): edit if not')}",
             f"source_file = {_toml(source)}", f"sha256 = {_toml(sha256)}", "",
             "[read]  # how the file is read (detected or given when the card was written)"]
    lines += [f"{k} = {_toml(table.read[k])}" for k in READ_KEYS if k in table.read]
    for m in mapped:
        lines += ["", f"[columns.{_key(m.name)}]  # {m.role}" + (f", unit {unit_source(m)}" if m.unit else ""),
                  f"from = {_toml(m.header)}"]
        lines += [f"unit = {_toml(m.unit)}"] if m.unit else ['kind = "category"']
        if m.role == "kept":
            lines += ["optional = true"] + (["signed = true"] if m.unit else [])
    if ignored:
        lines += ["", "# not read: " + "; ".join(ignored)]
    return "\n".join(lines) + "\n"


def init_dataset(path, model: str | Model, out, *, columns: Mapping[str, str] | None = None,
                 units: Mapping[str, str] | None = None, read: Mapping[str, str] | None = None,
                 id: str | None = None, kind: str = "measured", overwrite: bool = False):
    """Write the dataset folder ``out`` for the lab table ``path`` fitted with ``model``: a copy
    of the file, byte for byte, and a card (:data:`CARD`) that reads it with the options
    ``read`` (others detected) and maps its headers (:func:`propose`).  Every value is checked
    before anything is written.  Returns ``(dataset, table, mapped, ignored)``."""
    model = model if isinstance(model, Model) else load_model(model)
    path = Path(check_path(path, "init_dataset", "path", "the path of a lab's table file"))
    out = check_output_folder(out, "init_dataset", "out", "out names the dataset folder written")
    where = display(path)
    raw = read_regular(path, max_data_bytes(), "data file", where=where)
    table = read_lab_table(raw, where, check_read(dict(read or {}), "reading options", prefix=""))
    mapped, ignored = propose(table, model, columns, units)
    validate_table(table.cells, _columns(mapped), where, rows=table.rows)  # every value checked before writing
    if kind not in ("measured", "digitised"):
        raise InputError("kind", f"expected 'measured' or 'digitised' (got {kind!r}; simulated data need their "
                         "generating parameters and seed in the card)")
    ident = check_id(id or (re.sub(r"[^A-Za-z0-9_.+-]", "_", path.stem).lstrip(".") or "data"), "--id")
    card, target = out / CARD, out / path.name
    if card.exists() and not overwrite:
        raise InputError(card, "exists: give another --out, or --overwrite to replace it")
    if target.exists() and not target.samefile(path) and not overwrite and target.read_bytes() != raw:
        raise InputError(target, "exists and differs from the file read: give another --out, or --overwrite")
    sha = hashlib.sha256(raw).hexdigest()
    text = card_text(ident=ident, title=f"{path.name} as exported (card by skinfit dataset init)", model=model,
                     file=path.name, table=table, mapped=mapped, ignored=ignored, source=str(path.resolve()),
                     sha256=sha, kind=kind, out=out)
    out.mkdir(parents=True, exist_ok=True)
    if not (target.exists() and target.samefile(path)):
        target.write_bytes(raw)  # the bytes read and hashed, unchanged
    card.write_text(text, encoding="utf-8")
    dataset: Dataset = load_dataset(out, model=model)  # read back through the card, as a fit will
    return dataset, table, mapped, ignored
