"""``skinfit priors [MODEL]``: a model's priors with their literature sources, or the prior
files on the search path."""

import json

from skinfit.apps.cli.listing import from_line, origin, search_entries
from skinfit.errors import InputError
from skinfit.io.models import load_model
from skinfit.io.priors import load_priors
from skinfit.io.references import cite
from skinfit.io.user_priors import as_written

__all__ = ["run"]


def run(args):
    if args.model is None:  # list the prior files on the search path
        rows = [{"id": pid, **origin(e), "model": load_priors(str(e.path)).model}
                for pid, e in search_entries("priors", args).items()]
        if args.json:
            return print(json.dumps(rows, indent=2))
        for r in rows:
            print(f"{r['id']} (for model {r['model']}){from_line(r, args)}")
        return 0
    priors = load_priors(args.model)
    units = {}
    try:
        m = load_model(priors.model)
        units = {p.name: p.unit for p in m.parameters}
    except InputError:
        pass
    noise_unit = {n: "1 (Student-t degrees of freedom)" if n == "nu" or n.startswith("nu_")
                  else "(noise, observable's unit)"
                  for n in priors.priors}
    rows = [{"parameter": n, "unit": units.get(n, noise_unit[n]), "prior": p.describe(),
             "file": as_written(p)[0], "python": as_written(p)[1],
             "source": p.source, "cited": cite(p.source)} for n, p in priors.priors.items()]
    if args.json:
        return print(json.dumps(rows, indent=2))
    print(f"priors for {priors.model} ({priors.path}), SI units, each truncated to its bounds, as a prior file "
          "writes them and as Python (import scipy.stats as st) gives them:\n")
    for r in rows:
        print(f"{r['parameter']} [{r['unit']}]: {r['file']}"
              f"\n    in Python: {r['python']}\n    source: {r['cited']}")
