"""``skinfit compare RUN...``: fits of the same data ranked by evidence and LOO
(:func:`skinfit.analysis.compare.compare`)."""

import json
from pathlib import Path

import pandas as pd

from skinfit.analysis.compare import compare
from skinfit.results.fit import load_fit

__all__ = ["run"]


def run(args):
    paths = [Path(r) / "fit.nc" if Path(r).is_dir() else Path(r) for r in args.runs]
    fits = [load_fit(p) for p in paths]
    table = compare(fits, method=args.method)
    if args.save_evidence:  # keep the evidence with the fit for reports and campaigns (asked for)
        for f, p in zip(fits, paths):
            f.save(p)
    caveats = table.attrs.get("caveats", {})
    if args.json:
        records = json.loads(table.reset_index().to_json(orient="records"))
        for record in records:
            record["caveat"] = caveats.get(record["model"], "")
        print(json.dumps(records, indent=2))
    else:
        with pd.option_context("display.width", 200, "display.max_columns", 20,
                               "display.float_format", "{:.4g}".format):
            print(table.to_string())
        print("\nlog Z: natural-log evidence +- standard error; log_bf_vs_best = ln(Z/Z_best); "
              "strength on 2 ln BF (Kass & Raftery 1995); elpd_loo: PSIS-LOO (ArviZ)")
        for label, text in caveats.items():
            print(f"{label}: log Z {text}")
    return 0
