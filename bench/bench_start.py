"""Fit time and posterior quantiles of the demo's 15 model x dataset fits, for comparing two
versions of the sampler's start.

    .venv/bin/python bench/bench_start.py --json /tmp/after.json [--label after] [--models wavy_surface ...]
    .venv/bin/python bench/bench_start.py --compare /tmp/before.json /tmp/after.json [--md bench/results/start.md]

The first form runs each fit of ``skinfit demo`` (its seed, rows and split; the fits of further
contact_area subjects left out) in this process, one after another, after an untimed warm-up
fit, and writes per fit: wall and CPU seconds of ``skinfit.fit`` (MAP to result tree, without
the deferred pointwise groups), the fit's own timings, steps, refits, the importance start's
rounds, and the 5/50/95% quantiles of every sampled parameter with their Monte Carlo standard
errors (``arviz_stats.mcse(method="quantile")``, walkers as chains).  The second form writes
the Markdown table of both runs: times side by side, and per fit the largest |z| of the quantile
differences, z = (after - before) / sqrt(mcse_before^2 + mcse_after^2).
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
from skinfit.data import load_dataset
from skinfit.demo import _select, demo_plan

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info  # noqa: E402

PROBS = (0.05, 0.5, 0.95)


def _slot_draws(fit):
    """(name, (walkers, draws) array) of every sampled scalar, in slot order."""
    tree = fit.group("posterior")
    out = []
    for s in fit.posterior.slots:
        v = tree[s.base]
        if s.level is not None:
            v = v.sel({next(d for d in v.dims if d not in ("chain", "draw")): s.level})
        out.append((s.name, np.asarray(v, dtype=float)))
    return out


def run_one(item):
    from arviz_stats import mcse

    ds = _select(load_dataset(item["dataset"]), item["rows"])
    t0, c0 = time.perf_counter(), time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = skinfit.fit(item["model"], ds, rng=item["seed"], split=item["split"] or None)
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


def compare(args):
    a, b = (json.loads(Path(p).read_text()) for p in args.compare)
    before = {(f["model"], f["dataset"]): f for f in a["fits"]}
    lines = [f"# The sampler's start: demo fit times and posterior quantiles, {a['label']} vs {b['label']}", "",
             f"Commands: `{a['command']}` ({a['label']}, commit {a['commit']}, {a['date']}) and "
             f"`{b['command']}` ({b['label']}, commit {b['commit']}, {b['date']}); compared with "
             f"`.venv/bin/python bench/bench_start.py --compare {' '.join(args.compare)}`.", "",
             f"Machine: {b['machine']['nproc']} CPUs ({b['machine']['cpu']}), shared with other jobs; Python "
             f"{b['machine']['python']}. Load: {a['label']} `{a['uptime_start']}` -> `{a['machine']['uptime']}`; "
             f"{b['label']} `{b['uptime_start']}` -> `{b['machine']['uptime']}`.", "",
             "Each fit: the demo's seed (demo seed 1), rows and split; wall and CPU seconds of `skinfit.fit` "
             "(MAP, start, sampling, result tree; not the deferred pointwise groups), one run each in one process. "
             "Importance ESS: effective sample size of each importance round (2000 draws a round). Quantile "
             "agreement: the largest |z| over the 5/50/95% quantiles of every sampled parameter, "
             "z = difference / sqrt(mcse_1^2 + mcse_2^2) (ArviZ quantile MCSE, walkers as chains); "
             "n params x 3 quantiles z-scores per fit.", "",
             f"| model | dataset | wall s {a['label']} | wall s {b['label']} | CPU s {a['label']} | CPU s {b['label']} "
             f"| steps | refits | importance ESS {a['label']} | importance ESS {b['label']} | max abs z (n) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    all_z = []
    for f in b["fits"]:
        g = before.get((f["model"], f["dataset"]))
        if g is None:
            continue
        z = []
        for name, qs in f["quantiles"].items():
            for (q1, s1), (q0, s0) in zip(qs, g["quantiles"][name]):
                z.append((q1 - q0) / np.hypot(s0, s1) if np.hypot(s0, s1) > 0 else (0.0 if q1 == q0 else np.inf))
        all_z += z
        same = all(f["quantiles"][n] == g["quantiles"][n] for n in f["quantiles"])
        ess = [", ".join(f"{x['ess']:.0f}" for x in r["importance"]) for r in (g, f)]
        lines.append(f"| {f['model']} | {f['dataset']} | {g['wall_s']:.2f} | {f['wall_s']:.2f} | {g['cpu_s']:.2f} "
                     f"| {f['cpu_s']:.2f} | {g['n_steps']} -> {f['n_steps']} | {len(g['refits'])} -> "
                     f"{len(f['refits'])} | {ess[0]} | {ess[1]} | "
                     + ("identical" if same else f"{np.max(np.abs(z)):.2f} ({len(z)})") + " |")
    tot = [sum(r[k] for r in x["fits"]) for x in (a, b) for k in ("wall_s", "cpu_s")]
    lines += [f"| total | | {tot[0]:.1f} | {tot[2]:.1f} | {tot[1]:.1f} | {tot[3]:.1f} | | | | | |", ""]
    all_z = np.abs(np.array(all_z))
    lines.append(f"All quantile z-scores: {len(all_z)}, |z| > 2: {int(np.sum(all_z > 2))}, |z| > 3: "
                 f"{int(np.sum(all_z > 3))}, largest {all_z.max():.2f} (identical fits count z = 0).")
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
