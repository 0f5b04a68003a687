"""Evidence of every model family on its shipped dataset, by each of skinfit's three methods.

    skinfit demo --out runs/demo            # the fits (15: five families x model + variants)
    python bench/evidence_table.py runs/demo [--nlive 200] [--repeats 5] [--jobs 2] [--nested DATASET ...]

For each saved fit: bridge sampling (``--repeats`` independent splits; the reported error is
Gronau et al.'s relative-MSE error of one estimate, the spread is over the repeats), the
Laplace approximation at the MAP, and dynesty nested sampling (``rslice``, ``--nlive`` live
points) on the same likelihood and prior transform; log Z +- error and wall seconds of each.
Writes ``bench/results/evidence.md``.
"""

import argparse
import os
import platform
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

import skinfit
from skinfit import __version__

RESULTS = Path(__file__).resolve().parent / "results"


def one(path, nlive, repeats, nested):
    """Rows (dataset, model, method, log Z, se, spread, seconds, evaluations or refusal) for the
    fit at ``path``; a method that refuses (e.g. Laplace with the mode on a bound) gets its reason."""
    warnings.simplefilter("ignore")
    fit = skinfit.load_fit(path)
    rows = []
    methods = [("bridge", {"n_repeats": repeats}), ("laplace", {})]
    if nested:
        methods.append(("nested", {"nlive": nlive}))
    for method, options in methods:
        t0 = time.perf_counter()
        try:
            z = skinfit.evidence(fit, method=method, refresh=True, **options)
        except ValueError as err:
            rows.append((fit.dataset_id, fit.model_id, method, np.nan, np.nan, np.nan,
                         time.perf_counter() - t0, f"refused: {err}"))
            continue
        wall = time.perf_counter() - t0
        spread = float(np.std(z.repeats, ddof=1)) if len(z.repeats) > 1 else float("nan")
        rows.append((fit.dataset_id, fit.model_id, method, z.log_z, z.se, spread, wall, z.n_evals))
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", help="directory written by `skinfit demo --out`")
    p.add_argument("--nlive", type=int, default=200)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--jobs", type=int, default=os.cpu_count())
    p.add_argument("--nested", nargs="*", metavar="DATASET",
                   help="datasets whose fits also get dynesty (default: all; it takes minutes to an hour per fit)")
    args = p.parse_args(argv)
    paths = sorted(Path(args.runs).glob("*/*/fit.nc"))
    if not paths:
        raise SystemExit(f"no */*/fit.nc under {args.runs}: run `skinfit demo --out {args.runs}` first")
    nested = [args.nested is None or p.parts[-3] in args.nested for p in paths]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = [r for rs in pool.map(one, paths, [args.nlive] * len(paths), [args.repeats] * len(paths), nested)
                for r in rs]
    lines = [f"# Evidence per model family (issue 8)\n\nskinfit {__version__}, {platform.machine()}, "
             f"{os.cpu_count()} CPUs, {args.jobs} processes; `python bench/evidence_table.py {' '.join(argv or [])}` "
             f"on the fits of `skinfit demo`. log Z in nats, every constant of the likelihood and the "
             f"prior normalisation included. bridge: {args.repeats} repeats (error: Gronau et al. 2017; "
             f"'spread': sd over the repeats); laplace: approximate; nested: dynesty rslice, "
             f"{args.nlive} live points, dlogz 0.05.\n"]
    for dataset in dict.fromkeys(r[0] for r in rows):
        lines += [f"\n## {dataset}\n", "| model | method | log Z | error | spread of repeats | wall s | evaluations |",
                  "|---|---|---|---|---|---|---|"]
        for d, m, method, lz, se, spread, wall, n in rows:
            if d == dataset:
                if isinstance(n, str):
                    lines.append(f"| {m} | {method} | - | - | - | {wall:.1f} | {n} |")
                else:
                    lines.append(f"| {m} | {method} | {lz:.2f} | {se:.3f} | "
                                 f"{'' if np.isnan(spread) else f'{spread:.3f}'} | {wall:.1f} | {n} |")
    out = RESULTS / "evidence.md"
    out.write_text("\n".join(lines) + "\n")
    print(out.read_text())


if __name__ == "__main__":
    main()
