"""``skinfit models``: the model cards on the search path, with units and sources.

A card that cannot be read (a broken plug-in's, a user's with a mistake) is named with the
reason on stderr, after the cards that can: exit status 0, or 1 with ``--strict``; so is a
plug-in whose entry point is broken."""

import json
import sys

from skinfit.apps.cli.listing import from_line, origin, search_entries
from skinfit.errors import InputError
from skinfit.io.models import load_model
from skinfit.io.references import cite
from skinfit.io.registry import plugin_problems

__all__ = ["run"]


def run(args):
    rows, unreadable = [], []
    for _mid, entry in search_entries("models", args).items():
        try:
            m = load_model(str(entry.path))
        except InputError as exc:
            unreadable.append(f"cannot read {entry.path} ({entry.root.origin}): {exc}")
            continue
        rows.append({"id": m.id, **origin(entry), "title": m.title, "source": m.source, "cited": cite(m.source),
                     "observables": [f"{o.name} [{o.unit}]" for o in m.observables],
                     "covariates": [f"{c.name} [{c.unit}]" for c in m.covariates],
                     "parameters": [f"{p.name} [{p.unit}]" for p in m.parameters],
                     "variants": list(m.variants)})
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        for r in rows:
            print(f"{r['id']}: {r['title']}{from_line(r, args)}\n  source: {r['cited']}"
                  f"\n  observes: {', '.join(r['observables'])}"
                  f"\n  covariates: {', '.join(r['covariates'])}\n  parameters: {', '.join(r['parameters'])}"
                  + (f"\n  competes with: {', '.join(r['variants'])}" if r["variants"] else "") + "\n")
    problems = [*plugin_problems(), *unreadable]
    for line in problems:
        print(f"skinfit models: warning: {line}", file=sys.stderr)
    return 1 if problems and args.strict else 0
