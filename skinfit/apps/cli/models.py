"""``skinfit models``: the model cards on the search path, with units and sources."""

import json

from skinfit.apps.cli.listing import from_line, origin, search_entries
from skinfit.io.models import load_model
from skinfit.io.references import cite

__all__ = ["run"]


def run(args):
    rows = []
    for _mid, entry in search_entries("models", args).items():
        m = load_model(str(entry.path))
        rows.append({"id": m.id, **origin(entry), "title": m.title, "source": m.source, "cited": cite(m.source),
                     "observables": [f"{o.name} [{o.unit}]" for o in m.observables],
                     "covariates": [f"{c.name} [{c.unit}]" for c in m.covariates],
                     "parameters": [f"{p.name} [{p.unit}]" for p in m.parameters],
                     "variants": list(m.variants)})
    if args.json:
        return print(json.dumps(rows, indent=2))
    for r in rows:
        print(f"{r['id']}: {r['title']}{from_line(r, args)}\n  source: {r['cited']}"
              f"\n  observes: {', '.join(r['observables'])}"
              f"\n  covariates: {', '.join(r['covariates'])}\n  parameters: {', '.join(r['parameters'])}"
              + (f"\n  competes with: {', '.join(r['variants'])}" if r["variants"] else "") + "\n")
