"""skinfit vs PyMC NUTS vs dynesty vs emcee loops, per model: one process, one run each.

    .venv/bin/python bench/bench_models.py [--models electroadhesion ...] [--seed 1] [--repeats 5] [--pairs 5]
        [--skip-pymc] [--skip-dynesty] [--skip-plain] [--dynesty-maxcall 3000000]

Each posterior is a model on its shipped dataset with its shipped priors, plus the posterior
of issue 7 (electroadhesion with uniform priors on the paper's Table I ranges,
bench/priors_electroadhesion_uniform.toml).  In one process, one after another:

* ``skinfit.fit`` with its defaults (MAP, sampling to its own gate, the result tree), and
  apart the pointwise log-likelihood and predictive draws (``complete=False``, then ``Fit.complete``);
* the same chain by a bare emcee loop (:func:`common.run_bare_emcee`): skinfit's overhead at
  equal ESS, from ``--pairs`` runs of both, alternating, the fastest of each (runs of
  0.2-0.3 s varied by -1% to +39% in single pairs on this shared machine);
* a plain emcee loop with DE moves (:func:`common.run_plain_emcee`), what a hand-written
  loop gets;
* dynesty, ``rslice`` with 400 live points (:func:`common.run_dynesty`);
* PyMC NUTS on the same posterior (bench/pymc_models.py), given the same distinct-row
  sufficient statistics skinfit uses (``rows="distinct"``), compile time included;
* the log-density throughput of skinfit's ``Posterior`` against one hand-fused numpy
  expression of the same posterior (bench/fused.py, values checked equal);
* ``skinfit.fit`` over ``--repeats`` further seeds (median and range of wall time).

Before anything is timed, every library is imported and an untimed short skinfit fit runs
(modules that load lazily load once per process, outside every method's timing).
Writes bench/results/<posterior>.md and the table of issue 7's targets, bench/results/summary.md
(rows of posteriors not run keep their last values).
"""

import argparse
import json
import math
import time
import warnings
from pathlib import Path

import numpy as np
from common import (
    RESULTS,
    Result,
    machine_info,
    machine_text,
    posterior_for,
    run_bare_emcee,
    run_dynesty,
    run_plain_emcee,
    run_skinfit,
    table,
    throughput,
)
from fused import check_fused, make_fused

import skinfit

HERE = Path(__file__).resolve().parent
POSTERIORS = {  # name -> (model, dataset, priors)
    "electroadhesion": ("electroadhesion", "electroadhesion_synthetic", "electroadhesion"),
    "electroadhesion_uniform": ("electroadhesion", "electroadhesion_synthetic",
                                str(HERE / "priors_electroadhesion_uniform.toml")),
    "textured_surface": ("textured_surface", "textured_synthetic", "textured_surface"),
    "contact_area": ("contact_area", "contact_area_synthetic", "contact_area"),
    "wavy_surface": ("wavy_surface", "wavy_synthetic", "wavy_surface"),
    "ultrasonic": ("ultrasonic", "ultrasonic_synthetic", "ultrasonic"),
}
TARGETS = {"pymc": 20.0, "dynesty": 10.0, "overhead": 0.15, "fused": 2.0, "ess_per_s": 100.0, "wall_s": 5.0}


def _first_draw(fit):
    """The first kept draw of every walker, (nwalkers, d) natural parameters in slot order."""
    tree = fit.group("posterior")
    cols = []
    for slot in fit.posterior.slots:
        da = tree[slot.base]
        if slot.level is not None:
            da = da.sel({next(d for d in da.dims if d not in ("chain", "draw")): slot.level})
        cols.append(da.values[:, 0])
    return np.stack(cols, axis=-1)


#: the compared methods' keys in results.json, and the first word of their table rows
COMPARED = {"plain": "plain", "dynesty": "dynesty", "pymc": "PyMC"}


def _carry(summary, old):
    """Give ``summary`` the last run's figures (``old``, its results.json entry) of every
    compared method this run skipped, dated; returns their table rows, marked (their
    'x skinfit' column is relative to that run's skinfit)."""
    rows = []
    for key in COMPARED:
        if summary.get(f"{key}_s") is None and old.get(f"{key}_s") is not None:
            summary.update({k: v for k, v in old.items() if k.startswith(f"{key}_")})
            summary.setdefault(f"{key}_carried", old["date"])
            if f"{key}_row" in old:
                rows.append(old[f"{key}_row"].rstrip(" |") + f" (not rerun: run of {summary[f'{key}_carried']}) |")
    return "".join("\n" + r for r in rows)


def bench(name, args, old):
    model, data, prior_id = POSTERIORS[name]
    priors = skinfit.load_priors(prior_id)
    loaded = skinfit.load_model(model), skinfit.load_dataset(data)
    rows = [run_skinfit(*loaded, priors, args.seed)]
    print(name, rows[-1].method, f"{rows[-1].wall_s:.2f}", rows[-1].note, flush=True)
    sk = rows[0]
    rows.append(run_bare_emcee(loaded[0], loaded[1], priors, args.seed, sk.extra["sampler"]))
    print(name, rows[-1].method, f"{rows[-1].wall_s:.2f}", rows[-1].note, flush=True)
    bare = rows[1]
    fit = sk.extra["fit"]
    post = fit.posterior
    first = _first_draw(fit)
    same = bool(np.allclose(post.to_theta(bare.extra["chain"][sk.extra["sampler"]["burn"]]), first, rtol=1e-12))
    if not args.skip_plain:
        rows.append(run_plain_emcee(posterior_for(model, data, priors), args.seed))
        print(name, rows[-1].method, f"{rows[-1].wall_s:.2f}", rows[-1].note, flush=True)
    if not args.skip_dynesty:
        rows.append(run_dynesty(posterior_for(model, data, priors), args.seed, maxcall=args.dynesty_maxcall))
        print(name, rows[-1].method, f"{rows[-1].wall_s:.2f}", rows[-1].note, flush=True)
    if not args.skip_pymc:
        try:
            from pymc_models import run_pymc

            rows.append(run_pymc(posterior_for(model, data, priors), args.seed, rows="distinct"))
        except ImportError as exc:
            rows.append(Result("PyMC NUTS", math.nan, 0, math.nan, 0, 0, f"not run: {exc}"))
        print(name, rows[-1].method, f"{rows[-1].wall_s:.2f}", rows[-1].note, flush=True)

    # log-density throughput on posterior draws, checked equal first
    draws = np.stack([fit.group("posterior")[n].values.reshape(-1) for n in post.names], axis=-1)
    fused = make_fused(post)
    thr = []
    for k in (32, 128):
        z = post.to_z(draws[np.linspace(0, len(draws) - 1, k).astype(int)])
        check_fused(post, fused, z)
        thr.append((k, *throughput([post, fused], z)))

    repeats = [run_skinfit(*loaded, priors, args.seed + i) for i in range(1, args.repeats + 1)]
    walls = np.array([sk.wall_s] + [r.wall_s for r in repeats])
    per_seed = [sk] + repeats

    found = {r.method.split()[0]: r for r in rows}
    t = sk.extra["timings"]

    def pair(r, bare_s):  # to samples, with the tree and the pointwise / predictive groups, the bare loop
        return r.wall_s - r.extra["timings"]["tree_s"], r.wall_s + r.extra["pointwise_s"], bare_s

    pairs = [pair(sk, bare.wall_s)]
    for _ in range(args.pairs - 1):  # the same seed: the same chain again
        again = run_skinfit(*loaded, priors, args.seed)
        bare_again = run_bare_emcee(loaded[0], loaded[1], priors, args.seed, again.extra["sampler"])
        pairs.append(pair(again, bare_again.wall_s))
        del again
    to_samples, with_tree, bare_s = (min(p[i] for p in pairs) for i in range(3))
    table_lines = table(rows).split("\n")
    summary = {
        "posterior": name, "rows": post.n, "distinct_rows": post.n_unique, "parameters": post.ndim,
        "skinfit_s": sk.wall_s, "skinfit_tree_s": t["tree_s"], "skinfit_pointwise_s": sk.extra["pointwise_s"],
        "skinfit_converged": sk.converged,
        "ess_per_s": sk.min_ess / sk.wall_s, "min_ess": sk.min_ess, "max_rhat": sk.max_rhat,
        "bare_s": bare_s, "overhead_total": with_tree / bare_s - 1, "overhead_to_samples": to_samples / bare_s - 1,
        "overhead_pairs": [a / c - 1 for a, _, c in pairs],
        "same_chain": same,
        **{f"{key}_{field}": getattr(found[m], attr) if m in found else None for key, m in COMPARED.items()
           for field, attr in (("s", "wall_s"), ("converged", "converged"), ("note", "note"))},
        **{f"{key}_row": table_lines[2 + rows.index(found[m])] for key, m in COMPARED.items() if m in found},
        "fused_ratio": [b / a for _, a, b in thr],
        "seeds_median_s": float(np.median(walls)), "seeds_min_s": float(walls.min()), "seeds_max_s": float(walls.max()),
        "seeds_converged": sum(r.converged for r in per_seed), "seeds": len(per_seed),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
    }
    carried = _carry(summary, old)
    lines = [f"# {name}: {model} on {data} ({post.n} rows, {post.n_unique} distinct; {post.ndim} sampled parameters; "
             f"priors {Path(prior_id).name if prior_id.endswith('.toml') else 'priors/' + prior_id + '.toml'})", "",
             f"`.venv/bin/python bench/bench_models.py --models {name} --seed {args.seed} --repeats {args.repeats} --pairs {args.pairs}"
             f"{' --skip-pymc' * args.skip_pymc}{' --skip-dynesty' * args.skip_dynesty}{' --skip-plain' * args.skip_plain}` "
             f"- {summary['date']}", "", machine_text(machine_info()), "",
             "Converged = ArviZ rank R-hat <= 1.01 and min bulk ESS >= 400 over all parameters (emcee walkers as "
             "chains; dynesty: Kish ESS of its weights, R-hat over 4 random quarters of its equal-weight resample). "
             "Wall time includes the MAP search (emcee methods), compilation (PyMC) and the result tree "
             "(skinfit: to the converged posterior; its pointwise log-likelihood and predictive draws, computed "
             f"apart, took {sk.extra['pointwise_s']:.2f} s more). One process, one run, methods one after "
             "another; every library imported and a short untimed fit run first.", "", "\n".join(table_lines) + carried, "",
             "## Log-density throughput (evaluations/s; same posterior draws, values checked equal)", "",
             "| walkers | skinfit `Posterior.__call__` | one fused numpy expression | fused / skinfit |",
             "|---|---|---|---|"]
    lines += [f"| {k} | {a:.0f} | {b:.0f} | {b / a:.2f} |" for k, a, b in thr]
    lines += ["", f"## skinfit.fit over seeds {args.seed}..{args.seed + args.repeats}", "",
              "| seed | wall s | steps | refits at | max tau | min bulk ESS | max R-hat | converged |",
              "|---|---|---|---|---|---|---|---|"]
    for i, r in enumerate(per_seed):
        s = r.extra["sampler"]
        lines.append(f"| {args.seed + i} | {r.wall_s:.2f} | {s['n_steps']} | "
                     f"{', '.join(str(a['step']) for a in s['adaptation'] if a['refit'])} | "
                     f"{max(s['tau'].values()):.1f} | {r.min_ess:.0f} | {r.max_rhat:.4f} | {'yes' if r.converged else 'NO'} |")
    lines += ["", f"Median {summary['seeds_median_s']:.2f} s, range {summary['seeds_min_s']:.2f}-{summary['seeds_max_s']:.2f} s.",
              "", f"The bare loop ran the identical chain (first kept draw equal): "
              f"{'yes' if same else 'NO'}. "
              f"Over {len(pairs)} runs of each, alternating, on seed {args.seed}: skinfit's fastest wall time to the "
              f"same samples (without the result tree, {t['tree_s']:.2f} s in the first run) is "
              f"{100 * summary['overhead_to_samples']:+.0f}% of the bare loop's fastest; with the tree and the "
              f"pointwise log-likelihood and predictive draws ({sk.extra['pointwise_s']:.2f} s), "
              f"{100 * summary['overhead_total']:+.0f}% (single pairs, to samples: "
              f"{', '.join(f'{100 * o:+.0f}%' for o in summary['overhead_pairs'])})."]
    (RESULTS / f"{name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines), flush=True)
    return summary


def write_summary(results, info):
    """bench/results/summary.md: issue 7's targets per posterior, from results.json."""
    lines = ["# Issue 7 targets, per posterior", "",
             "From `bench/bench_models.py` (each row's own run: its date and machine load are in "
             "bench/results/<posterior>.md). Ratios are wall time to a converged posterior (ArviZ R-hat <= 1.01, "
             "min bulk ESS >= 400), methods in one process, one run; a method marked 'run of DATE' was skipped "
             "in the row's latest run and is that earlier run's figure, its ratio taken against the latest skinfit "
             "time. The overhead compares the fastest of `--pairs` (5) alternating runs of skinfit and of the bare loop "
             "on the same chain; fused / skinfit the best of 4 alternating throughput runs of each.", "", machine_text(info), "",
             "| posterior | rows (distinct), params | skinfit s | PyMC NUTS s (x) | dynesty s (x) | plain emcee DE s (x) "
             "| ESS/s | overhead vs bare loop: to samples / with tree | fused / skinfit (32, 128 walkers) "
             "| skinfit over seeds: median [range] s |", "|---|---|---|---|---|---|---|---|---|---|"]

    def ratio(r, key, conv=None):
        v = r.get(key)
        if v is None or not math.isfinite(v):
            return "not run"
        mark = "" if conv is None or r.get(conv) is not False else ", NOT converged"
        carried = r.get(key.replace("_s", "_carried"))
        mark += f"; run of {carried}" if carried else ""
        return f"{v:.1f} ({v / r['skinfit_s']:.3g}x{mark})"  # 3 digits: 19.8x is not 20x

    for r in results.values():
        lines.append(f"| {r['posterior']} | {r['rows']} ({r['distinct_rows']}), {r['parameters']} | {r['skinfit_s']:.2f} | "
                     f"{ratio(r, 'pymc_s', 'pymc_converged')} | {ratio(r, 'dynesty_s', 'dynesty_converged')} | "
                     f"{ratio(r, 'plain_s', 'plain_converged')} | {r['ess_per_s']:.0f} | "
                     f"{100 * r['overhead_to_samples']:+.0f}% / {100 * r['overhead_total']:+.0f}% | "
                     f"{r['fused_ratio'][0]:.2f}, {r['fused_ratio'][1]:.2f} | "
                     f"{r['seeds_median_s']:.2f} [{r['seeds_min_s']:.2f}, {r['seeds_max_s']:.2f}] "
                     f"({r['seeds_converged']}/{r['seeds']} converged) |")
    lines += ["", "## Targets", "",
              "| posterior | PyMC / skinfit >= 20 | dynesty / skinfit >= 10 | overhead <= 15% (to samples) | "
              "fused / skinfit <= 2 | >= 100 ESS/s (electroadhesion) | < 5 s (electroadhesion, shipped) |",
              "|---|---|---|---|---|---|---|"]

    def met(ok):
        return "-" if ok is None else ("yes" if ok else "**no**")

    for r in results.values():
        pymc = None if r.get("pymc_s") is None else r["pymc_s"] / r["skinfit_s"] >= TARGETS["pymc"]
        dyn = None if r.get("dynesty_s") is None else r["dynesty_s"] / r["skinfit_s"] >= TARGETS["dynesty"]
        ess = r["ess_per_s"] >= TARGETS["ess_per_s"] if r["posterior"].startswith("electroadhesion") else None
        wall = (r["seeds_max_s"] < TARGETS["wall_s"] and r["seeds_converged"] == r["seeds"]) \
            if r["posterior"] == "electroadhesion" else None
        lines.append(f"| {r['posterior']} | {met(pymc)} | {met(dyn)} | {met(r['overhead_to_samples'] <= TARGETS['overhead'])} | "
                     f"{met(max(r['fused_ratio']) <= TARGETS['fused'])} | {met(ess)} | {met(wall)} |")
    (RESULTS / "summary.md").write_text("\n".join(lines) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", nargs="+", default=list(POSTERIORS), choices=list(POSTERIORS))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--pairs", type=int, default=5, help="skinfit / bare-loop pairs for the overhead")
    ap.add_argument("--skip-pymc", action="store_true")
    ap.add_argument("--skip-dynesty", action="store_true")
    ap.add_argument("--skip-plain", action="store_true")
    ap.add_argument("--dynesty-maxcall", type=int, default=3_000_000)
    args = ap.parse_args()
    import dynesty  # noqa: F401  (imports outside every timing)
    if not args.skip_pymc:
        import pymc  # noqa: F401
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        skinfit.fit("electroadhesion", "electroadhesion_synthetic", rng=1000, max_steps=300)
    store = RESULTS / "results.json"
    results = json.loads(store.read_text()) if store.exists() else {}
    for name in args.models:
        results[name] = bench(name, args, results.get(name, {}))  # skipped methods keep their last run
        results = {k: results[k] for k in POSTERIORS if k in results}
        store.write_text(json.dumps(results, indent=1) + "\n")
        write_summary(results, machine_info())


if __name__ == "__main__":
    main()
