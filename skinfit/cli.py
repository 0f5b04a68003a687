"""The ``skinfit`` command line: a thin layer over the library."""

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

from .errors import InputError

__all__ = ["main"]


def _cmd_models(args):
    from .models import list_models, load_model

    rows = []
    for mid in list_models():
        m = load_model(mid)
        rows.append({"id": m.id, "title": m.title, "source": m.source,
                     "observables": [f"{o.name} [{o.unit}]" for o in m.observables],
                     "covariates": [f"{c.name} [{c.unit}]" for c in m.covariates],
                     "parameters": [f"{p.name} [{p.unit}]" for p in m.parameters],
                     "variants": list(m.variants)})
    if args.json:
        return print(json.dumps(rows, indent=2))
    for r in rows:
        print(f"{r['id']}: {r['title']}\n  source: {r['source']}\n  observes: {', '.join(r['observables'])}"
              f"\n  covariates: {', '.join(r['covariates'])}\n  parameters: {', '.join(r['parameters'])}"
              + (f"\n  competes with: {', '.join(r['variants'])}" if r["variants"] else "") + "\n")


def _cmd_priors(args):
    from .models import load_model
    from .priors import load_priors

    priors = load_priors(args.model)
    units = {}
    try:
        m = load_model(priors.model)
        units = {p.name: p.unit for p in m.parameters}
    except InputError:
        pass
    rows = [{"parameter": n, "unit": units.get(n, "(noise, observable's unit)"), "prior": p.describe(),
             "source": p.source} for n, p in priors.priors.items()]
    if args.json:
        return print(json.dumps(rows, indent=2))
    print(f"priors for {priors.model} ({priors.path}), SI units, each truncated to its bounds:\n")
    for r in rows:
        print(f"{r['parameter']} [{r['unit']}]: {r['prior']}\n    source: {r['source']}")


def _cmd_datasets(args):
    from .data import list_datasets, load_dataset

    rows = []
    for did in list_datasets():
        ds = load_dataset(did)
        rows.append({"id": ds.id, "title": ds.title, "rows": len(ds), "model": ds.model,
                     "provenance": ds.provenance.get("kind"), "groups": list(ds.groups),
                     "columns": {c.name: c.unit or "category" for c in ds.columns}})
    if args.json:
        return print(json.dumps(rows, indent=2))
    for r in rows:
        cols = ", ".join(f"{k} [{v}]" for k, v in r["columns"].items())
        print(f"{r['id']} ({r['provenance']}, {r['rows']} rows, for {r['model']}): {r['title']}\n"
              f"  columns (units as stored; converted to SI on load): {cols}\n")


def _parse_split(items):
    out = {}
    for item in items or []:
        name, sep, cols = item.partition("=")
        if not sep or not cols:
            raise InputError("--split", f"expected PARAMETER=COLUMN[,COLUMN] (got {item!r})")
        out[name] = cols.split(",")
    return out


def _cmd_fit(args):
    from .fit import fit

    out = Path(args.out)
    split = _parse_split(args.split) or None
    if args.by:
        from .groups import fit_by

        if args.resume:
            raise InputError("--resume", "not supported with --by yet: resume each group's run directory")

        index = fit_by(args.model, args.dataset, args.by, out, priors=args.priors, seed=args.seed,
                       split=split, noise=args.noise, progress=not args.quiet,
                       ess_target=args.ess, max_steps=args.max_steps)
        print(index.to_string(index=False) + f"\n\nwritten: {out / 'index.json'}")
        return 0 if index["converged"].all() or not args.strict else 3
    from .checkpoint import CheckpointLock

    t0 = time.perf_counter()
    checkpoint = out / "checkpoint.h5"
    if args.resume and not checkpoint.exists():
        print(f"skinfit: no checkpoint {checkpoint} to resume: starting afresh", file=sys.stderr)
    with CheckpointLock(checkpoint):
        result = fit(args.model, args.dataset, priors=args.priors, rng=args.seed, split=split,
                     noise=args.noise, progress=not args.quiet,
                     ess_target=args.ess, max_steps=args.max_steps, checkpoint=checkpoint,
                     resume=args.resume, checkpoint_every=args.checkpoint_every)
    path = result.save(out / "fit.nc")
    (out / "summary.csv").write_text(result.summary().to_csv())
    print(result.report_text())
    print(f"\nwritten: {path} and {out / 'summary.csv'}  ({time.perf_counter() - t0:.1f} s)")
    if args.strict and result.warnings:  # failed or warned (skinfit.guardrails): result kept, exit 3
        print(f"skinfit: --strict: {len(result.warnings)} guard-rail problem(s), see above", file=sys.stderr)
        return 3
    return 0


def _lazy(module, function):
    """A command implemented in another module, imported only when it runs."""

    def run(args):
        import importlib

        return getattr(importlib.import_module(module), function)(args)

    return run


def build_parser():
    p = argparse.ArgumentParser(prog="skinfit", description="Bayesian inference for published "
                                "skin-friction models: MAP (nlopt) + emcee, results as ArviZ trees.")
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("models", help="list the model cards (models/*.toml) with units and sources")
    s.add_argument("--json", action="store_true", help="machine-readable output")
    s.set_defaults(func=_cmd_models)
    s = sub.add_parser("priors", help="show a model's priors with their literature sources")
    s.add_argument("model", help="model id or path of a prior file")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_cmd_priors)
    s = sub.add_parser("datasets", help="list the shipped datasets (datasets/*/dataset.toml)")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_cmd_datasets)
    s = sub.add_parser("fit", help="fit a model to a dataset: MAP, emcee, summary, result file")
    s.add_argument("model", help="model id (models/<id>.toml) or path")
    s.add_argument("dataset", help="dataset id (datasets/<id>/) or path")
    s.add_argument("--out", required=True, help="run directory; fit.nc and summary.csv go there")
    s.add_argument("--priors", help="prior file id or path (default: priors/<model>.toml)")
    s.add_argument("--seed", type=int, default=None, help="seed: the same seed gives identical samples")
    s.add_argument("--split", action="append", metavar="PARAM=COLUMN",
                   help="fit PARAM once per level of COLUMN (repeatable), e.g. alpha=voltage")
    s.add_argument("--noise", choices=["normal", "student_t", "lognormal"], help="noise model override")
    s.add_argument("--ess", type=float, default=400, help="minimum effective sample size (default 400)")
    s.add_argument("--max-steps", type=int, default=20000, help="emcee step cap (default 20000)")
    s.add_argument("--by", action="append", metavar="COLUMN",
                   help="fit each level of COLUMN separately (repeatable, e.g. --by subject); "
                        "one result per group under --out plus index.json")
    s.add_argument("--resume", action="store_true",
                   help="continue an interrupted fit from its checkpoint in --out")
    s.add_argument("--checkpoint-every", type=float, default=30.0, metavar="SECONDS",
                   help="seconds between checkpoints (OUT/checkpoint.h5) while sampling (default 30)")
    s.add_argument("--strict", action="store_true", help="exit non-zero if not converged or warned")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_fit)
    s = sub.add_parser("compare", help="rank fits of the same data by evidence (log Z, Bayes factors) and LOO")
    s.add_argument("runs", nargs="+", help="run directories or fit.nc files")
    s.add_argument("--method", default="bridge", choices=["bridge", "laplace", "nested"],
                   help="evidence estimator (default bridge sampling)")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_lazy("skinfit.compare", "cli_compare"))
    s = sub.add_parser("report", help="write a self-contained static HTML report of fits")
    s.add_argument("runs", nargs="+", help="run directories or fit.nc files")
    s.add_argument("--out", required=True, help="report directory, e.g. reports/NAME")
    s.set_defaults(func=_lazy("skinfit.report", "cli_report"))
    s = sub.add_parser("campaign", help="run a (models x datasets x groups) matrix of fits")
    s.add_argument("campaign", help="campaign TOML file")
    s.add_argument("--scheduler", help="Dask scheduler: tcp://HOST:PORT, or 'local' for a LocalCluster")
    s.add_argument("--workers", type=int, default=None, help="local worker processes (default: cores)")
    s.set_defaults(func=_lazy("skinfit.campaign", "cli_campaign"))
    s = sub.add_parser("population", help="population distribution over per-subject fits (a --by run or a campaign)")
    s.add_argument("run", help="run directory of `skinfit fit --by` or a campaign out directory (index.json)")
    s.add_argument("--params", action="append", metavar="NAME[,NAME]", help="population parameters (default: "
                   "every model parameter; noise scales stay per subject)")
    s.add_argument("--family", action="append", metavar="PARAM=FAMILY",
                   help="normal, lognormal or student_t per parameter (default lognormal when positive)")
    s.add_argument("--correlated", action="store_true", help="correlated (multivariate normal) population")
    s.add_argument("--method", default="gibbs", choices=["gibbs", "reweight"], help="sampler (default gibbs)")
    s.add_argument("--model", help="the model to use from a campaign with several")
    s.add_argument("--seed", type=int, default=None)
    s.add_argument("--out", help="output directory (default RUN/population)")
    s.set_defaults(func=_lazy("skinfit.population", "cli_population"))
    s = sub.add_parser("sbc", help="simulation-based calibration of a model (Talts et al. 2018)")
    s.add_argument("model", help="model id")
    s.add_argument("--dataset", help="shipped dataset whose design is simulated on (default: the model's)")
    s.add_argument("--n-sims", type=int, default=100, help="number of simulated datasets (default 100)")
    s.add_argument("--draws", type=int, default=99, help="posterior draws each truth is ranked among (default 99)")
    s.add_argument("--rows", type=int, help="use at most this many rows of the design, evenly spaced")
    s.add_argument("--ess", type=float, default=100, help="minimum ESS of each fit (default 100)")
    s.add_argument("--max-steps", type=int, default=4000, help="emcee step cap of each fit (default 4000)")
    s.add_argument("--jobs", type=int, default=1, help="simulations in parallel processes (default 1)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--out", default=None, help="directory for the rank table and histogram")
    s.set_defaults(func=_lazy("skinfit.sbc", "cli_sbc"))
    s = sub.add_parser("demo", help="fit every shipped dataset with its model and variants, compare, report")
    s.add_argument("--out", default="runs/demo", help="where the fits go (default runs/demo)")
    s.add_argument("--report", help="report directory (default OUT/report)")
    s.add_argument("--seed", type=int, default=1, help="demo seed; each fit's seed derives from it")
    s.add_argument("--jobs", type=int, help="parallel fits (default: one per core)")
    s.add_argument("--dataset", action="append", help="only this shipped dataset (repeatable)")
    s.set_defaults(func=_lazy("skinfit.demo", "cli_demo"))
    return p


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    warnings.simplefilter("default")
    try:
        code = args.func(args)
    except InputError as exc:
        print(f"skinfit: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("skinfit: interrupted", file=sys.stderr)
        return 130
    return code or 0


if __name__ == "__main__":
    sys.exit(main())
