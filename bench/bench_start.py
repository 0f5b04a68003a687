"""Fit time and posterior quantiles of the demo's 15 model x dataset fits, for comparing two
versions of the sampler's start.

    .venv/bin/python bench/bench_start.py --json /tmp/after.json [--label after] [--seeds 1 2 ...] [--models M ...]
    .venv/bin/python bench/bench_start.py --compare BEFORE.json[,MORE.json] AFTER.json[,MORE.json] [--md bench/results/start.md]

The first form runs each fit of ``skinfit demo`` for each demo seed (its seed, rows and split;
the fits of further contact_area subjects left out) in this process, one after another, after an untimed warm-up
fit, and writes per fit: wall and CPU seconds of ``skinfit.fit`` (MAP to result tree, without
the deferred pointwise groups), the fit's own timings, steps, refits, the importance start's
rounds, and the 5/50/95% quantiles of every sampled parameter with their Monte Carlo standard
errors (``arviz_stats.mcse(method="quantile")``, walkers as chains).  The second form writes
the Markdown tables of both: times side by side (demo seed 1; then per pair over further seeds), and
per fit the largest |z| of the quantile differences, z = (after - before) / sqrt(mcse_before^2 +
mcse_after^2).
"""

import argparse
import json
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import skinfit
from skinfit.apps.demo import _select, demo_plan
from skinfit.io.data import load_dataset

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info

PROBS = (0.05, 0.5, 0.95)


def _slot_draws(fit):
    """(name, (walkers, draws) array) of every sampled scalar, in slot order."""
    from skinfit.results.summary import slot_values

    ds = fit.group("posterior")
    shape = (ds.sizes["chain"], ds.sizes["draw"])
    return [(s["name"], slot_values(ds, s).astype(float).reshape(shape)) for s in fit.attr("slots")]


def run_one(item):
    from arviz_stats import mcse

    ds = _select(load_dataset(item["dataset"]), item["rows"])
    t0, c0 = time.perf_counter(), time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = skinfit.fit(item["model"], ds, rng=item["seed"], split=item["split"] or None, complete=False)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    s, t = fit.attr("sampler"), fit.attr("timings")
    quantiles = {}
    for name, x in _slot_draws(fit):
        quantiles[name] = [[float(np.quantile(x, p)), float(mcse(x, method="quantile", prob=p))] for p in PROBS]
    return {"model": item["model"], "dataset": item["dataset"], "seed": item["seed"], "wall_s": wall, "cpu_s": cpu,
            "timings": t, "n_steps": s["n_steps"], "nwalkers": s["nwalkers"], "converged": s["converged"],
            "refits": [a["step"] for a in s.get("adaptation", []) if a["refit"]],
            "importance": s.get("importance", []), "evaluations": fit.attr("support_counts")["evaluations"],
            "quantiles": quantiles}


def run(args):
    plan = [dict(p, demo_seed=seed) for seed in args.seeds for p in demo_plan(seed)
            if not p.get("group") and (not args.models or p["model"] in args.models)]
    with warnings.catch_warnings():  # imports and lazily loaded modules, outside every timing
        warnings.simplefilter("ignore")
        skinfit.fit("electroadhesion", "electroadhesion_synthetic", rng=0, max_steps=100)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    results = {"label": args.label, "commit": commit, "command": " ".join(sys.argv),
               "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "uptime_start": _uptime(), "fits": []}
    for item in plan:
        r = dict(run_one(item), demo_seed=item["demo_seed"])
        results["fits"].append(r)
        print(f"{r['model']:28s} {r['dataset']:24s} wall {r['wall_s']:6.2f} s cpu {r['cpu_s']:6.2f} s "
              f"steps {r['n_steps']:5d} refits {r['refits']} importance ESS "
              f"{[round(x['ess']) for x in r['importance']]}", flush=True)
        Path(args.json).write_text(json.dumps(results, indent=1))
    results["machine"] = machine_info()
    Path(args.json).write_text(json.dumps(results, indent=1))


def _uptime():
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def _load(paths):
    """Runs from comma-separated JSON files, merged: (first run's header, {(model, dataset, demo seed): fit})."""
    runs = [json.loads(Path(p).read_text()) for p in paths.split(",")]
    return runs, {(f["model"], f["dataset"], f.get("demo_seed", 1)): f for r in runs for f in r["fits"]}


def _z(f, g):
    """Quantile differences of two fits in Monte Carlo standard errors (0 where bit-identical)."""
    z = []
    for name, qs in f["quantiles"].items():
        for (q1, s1), (q0, s0) in zip(qs, g["quantiles"][name]):
            z.append(0.0 if q1 == q0 else (q1 - q0) / np.hypot(s0, s1))
    return np.array(z)


def compare(args):
    (ra, a), (rb, b) = (_load(p) for p in args.compare)
    la, lb = ra[0]["label"], rb[0]["label"]
    runs = "; ".join(f"`{r['command']}` ({r['label']}, commit {r['commit'] or '?'}, {r['date']}, load "
                     f"`{r['uptime_start'].split('load average:')[-1].strip()}` -> "
                     f"`{r.get('machine', {}).get('uptime', '?').split('load average:')[-1].strip()}`)"
                     for r in ra + rb)
    m = rb[0]["machine"]
    lines = [f"# The sampler's start: demo fit times and posterior quantiles, {la} vs {lb}", "",
             f"Runs: {runs}. Table: `.venv/bin/python bench/bench_start.py --compare {' '.join(args.compare)}"
             + (f" --md {args.md}" if args.md else "") + "`.", "",
             f"Machine: {m['nproc']} CPUs ({m['cpu']}), shared with other jobs (wall times inflated by the load "
             f"shown; compare CPU); Python {m['python']}.", "",
             "Each fit: the demo's seed, rows and split; wall and CPU seconds of `skinfit.fit` (MAP, start, "
             "sampling, result tree; not the deferred pointwise groups), one run each, in one process after a "
             "warm-up fit. Importance ESS: effective sample size of each importance round (2000 draws a round). "
             "Quantiles: 5/50/95% of every sampled parameter; z = difference / sqrt(mcse_1^2 + mcse_2^2) (ArviZ "
             "quantile MCSE, walkers as chains); `identical` where every quantile is bit-identical.", "",
             "## Demo seed 1, every model x dataset pair of the demo", "",
             f"| model | dataset | wall s {la} | wall s {lb} | CPU s {la} | CPU s {lb} | steps | refits at "
             f"| importance ESS {la} | importance ESS {lb} | max abs z (n) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    keys = [k for k in b if k in a]
    for key in (k for k in keys if k[2] == 1):
        f, g = b[key], a[key]
        z = _z(f, g)
        ess = [", ".join(f"{x['ess']:.0f}" for x in r["importance"]) for r in (g, f)]
        lines.append(f"| {key[0]} | {key[1]} | {g['wall_s']:.2f} | {f['wall_s']:.2f} | {g['cpu_s']:.2f} "
                     f"| {f['cpu_s']:.2f} | {g['n_steps']} -> {f['n_steps']} | {g['refits']} -> {f['refits']} "
                     f"| {ess[0]} | {ess[1]} | "
                     + ("identical" if not z.any() else f"{np.max(np.abs(z)):.2f} ({len(z)})") + " |")
    one = [k for k in keys if k[2] == 1]
    tot = [sum(x[k][c] for k in one) for x in (a, b) for c in ("wall_s", "cpu_s")]
    lines += [f"| total | | {tot[0]:.1f} | {tot[2]:.1f} | {tot[1]:.1f} | {tot[3]:.1f} | | | | | |", ""]
    pairs = sorted({k[:2] for k in keys if k[2] != 1})
    if pairs:
        lines += ["## Further demo seeds, the pairs whose start changes", "",
                  f"| model | dataset | demo seeds | CPU s {la} | CPU s {lb} | median CPU s {la} -> {lb} | steps {la} "
                  f"| steps {lb} | max abs z (n) |", "|---|---|---|---|---|---|---|---|---|"]
        for pair in pairs:
            ks = sorted(k for k in keys if k[:2] == pair)
            z = np.concatenate([_z(b[k], a[k]) for k in ks])
            cpu = [[x[k]["cpu_s"] for k in ks] for x in (a, b)]
            lines.append(f"| {pair[0]} | {pair[1]} | {', '.join(str(k[2]) for k in ks)} "
                         f"| {', '.join(f'{c:.2f}' for c in cpu[0])} | {', '.join(f'{c:.2f}' for c in cpu[1])} "
                         f"| {np.median(cpu[0]):.2f} -> {np.median(cpu[1]):.2f} "
                         f"| {', '.join(str(a[k]['n_steps']) for k in ks)} | {', '.join(str(b[k]['n_steps']) for k in ks)} "
                         f"| {np.max(np.abs(z)):.2f} ({len(z)}) |")
        lines.append("")
    z = np.abs(np.concatenate([_z(b[k], a[k]) for k in keys]))
    changed = [k for k in keys if _z(b[k], a[k]).any()]
    zc = np.abs(np.concatenate([_z(b[k], a[k]) for k in changed])) if changed else np.zeros(0)
    lines.append(f"Quantile z-scores: {len(z)} over {len(keys)} fits; {len(keys) - len(changed)} fits bit-identical. "
                 f"Of the {len(zc)} of the {len(changed)} fits that differ: |z| > 2: {int(np.sum(zc > 2))} "
                 f"(normal: {0.0455 * len(zc):.1f}), |z| > 3: {int(np.sum(zc > 3))} (normal: {0.0027 * len(zc):.1f}), "
                 f"largest {zc.max() if len(zc) else 0:.2f}.")
    text = "\n".join(lines) + "\n"
    if args.md:
        Path(args.md).write_text(text)
    print(text)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", help="write this run's results here")
    ap.add_argument("--label", default="run")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1], help="demo seeds (each fit's seed derives from it)")
    ap.add_argument("--models", nargs="*")
    ap.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"))
    ap.add_argument("--md", help="with --compare: write the table here")
    args = ap.parse_args()
    if args.compare:
        compare(args)
    elif args.json:
        run(args)
    else:
        ap.error("give --json (run) or --compare")


if __name__ == "__main__":
    main()
