"""``skinfit datasets``: the datasets on the search path, with their columns' units."""

import json

from skinfit.apps.cli.listing import from_line, origin, search_entries
from skinfit.io.data import load_dataset

__all__ = ["run"]


def run(args):
    rows = []
    for _did, entry in search_entries("datasets", args).items():
        ds = load_dataset(str(entry.path.parent))
        rows.append({"id": ds.id, **origin(entry), "title": ds.title, "rows": len(ds), "model": ds.model,
                     "provenance": ds.provenance.get("kind"), "groups": list(ds.groups),
                     "columns": {c.name: c.unit or "category" for c in ds.columns}})
    if args.json:
        return print(json.dumps(rows, indent=2))
    for r in rows:
        cols = ", ".join(f"{k} [{v}]" for k, v in r["columns"].items())
        print(f"{r['id']} ({r['provenance']}, {r['rows']} rows, for {r['model']}): {r['title']}"
              f"{from_line(r, args)}\n"
              f"  columns (units as stored; converted to SI on load): {cols}\n")
