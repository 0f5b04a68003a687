"""``skinfit dataset init FILE --model MODEL --out DIR``: a lab's table as exported (CSV,
Excel, MATLAB, HDF5) mapped to a model's names, checked, and written as a dataset folder that
``skinfit fit MODEL DIR`` reads (:func:`skinfit.io.mapping.init_dataset`)."""

import json

from skinfit.errors import InputError
from skinfit.io.mapping import CARD, init_dataset, parse_column, unit_source
from skinfit.io.tables import format_read

__all__ = ["run"]

_READ = ("sep", "decimal", "comment", "encoding", "sheet", "variable")


def _columns(items):
    """``--column`` flags -> (header -> name, header -> unit)."""
    columns, units = {}, {}
    for item in items or []:
        header, name, unit = parse_column(item)
        if header in columns:
            raise InputError("--column", f"header {header!r} is mapped twice")
        columns[header] = name
        if unit is not None:
            units[header] = unit
    return columns, units


def run(args):
    columns, units = _columns(args.column)
    read = {k: getattr(args, k) for k in _READ if getattr(args, k) is not None}
    dataset, table, mapped, ignored = init_dataset(args.file, args.model, args.out, columns=columns, units=units,
                                                   read=read, id=args.id, kind=args.kind, overwrite=args.overwrite)
    card = f"{args.out}/{CARD}"
    if args.json:
        return print(json.dumps({
            "card": card, "dataset": dataset.id, "rows": len(dataset), "read": dict(table.read),
            "detected": list(table.detected), "data_file": dataset.data_file, "sha256": dataset.data_sha256,
            "columns": [{"from": m.header, "name": m.name, "unit": m.unit, "role": m.role, "unit_from": m.unit_from,
                         "given": m.given} for m in mapped],
            "not_read": list(ignored), "skipped": list(table.skipped)}, indent=2))
    print(f"read {table.where} as {format_read(table)}")
    print(f"{len(dataset)} rows; columns (file header -> skinfit name [unit]; converted to SI when read):")
    width = max(len(repr(m.header)) for m in mapped)
    for m in mapped:
        target = f"{m.name} [{m.unit}]" if m.unit else m.name
        how = "--column" if m.given else "by its name"
        note = (f"{m.role}, {how}" + (f", unit {unit_source(m)}" if m.unit else ", labels")
                + (", a group" if m.name in dataset.groups else ""))
        print(f"  {m.header!r:<{width}} -> {target:<28} {note}")
    for line in ignored:
        print(f"  not read: {line}")
    for line in table.skipped:
        print(f"  skipped in the file: {line}")
    print(f"written: {card} (review it) and {dataset.data_file} (the original file, sha256 "
          f"{dataset.data_sha256[:16]}...)")
    print(f"fit it: skinfit fit {dataset.model} {args.out} --out runs/{dataset.id}")
    return 0
