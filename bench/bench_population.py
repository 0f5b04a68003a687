"""Population step after the per-subject fits: cost, convergence, coverage.

1. Sizes (contact_area model, 126 presses a subject as in datasets/contact_area_synthetic):
   the 13 shipped subjects with 4 and 8 population parameters, and 13, 50, 100 subjects
   simulated from a known population (below) with all 10 sampled parameters (the 8 model
   parameters and the 2 noise scales).  Per size: wall and CPU seconds of
   ``skinfit.analysis.population.population.population`` on saved fits (loading the fits included), sweeps,
   worst R-hat and ESS over the hyper-parameters.  ``--reweight`` also times the importance
   reweighting path on 13 x 4.
2. Coverage: 20 simulated Coulomb populations of 13 subjects (tests/popsim.py, log-normal,
   median 0.5, sd 0.05 in log) at 2 and 6 presses per normal-force level: coverage of the
   shrunk and separate 50/90/95% intervals of the subjects' friction coefficients and their
   mean squared error in log.

    .venv/bin/python bench/bench_population.py [--work DIR] [--skip-sizes] [--skip-coverage] [--reweight]
    -> bench/results/population.json (and the numbers for bench/results/population.md)
"""

import argparse
import json
import os
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from skinfit.analysis.groups import fit_by
from skinfit.analysis.population.inputs import load_run
from skinfit.analysis.population.population import population
from skinfit.analysis.population.result import PopulationWarning
from skinfit.physics.contact_area import contact_area

# the simulated population of the 50/100-subject sizes: log-normal (median, sd of log) for the
# positive parameters, normal (mean, sd) for the slopes with actuation force
POP = {"alpha_a0": ("log", 35e-6, 0.3), "alpha_a1": ("lin", -0.01, 0.004), "m0": ("log", 0.65, 0.2),
       "m1": ("lin", -0.004, 0.0012), "beta_z0": ("log", 3.8, 0.35), "beta_z1": ("lin", -0.012, 0.004),
       "n_z0": ("log", 0.65, 0.25), "n_z1": ("lin", 0.014, 0.003)}
FA = np.arange(0.0, 31.0, 5.0)
FN = np.array([0.25, 0.5, 1.0, 1.5, 2.0, 3.0])


def simulate_contact(folder, n, seed=20261125):
    """A contact_area dataset of ``n`` subjects drawn from POP (3 repeats of 7 x 6 forces)."""
    rng = np.random.default_rng(seed)
    card = (ROOT / "datasets/contact_area_synthetic/dataset.toml").read_text()
    head, _, _ = card.partition("[provenance.subjects]")
    cols = card[card.index("[columns.subject]"):]
    head = head.replace('id = "contact_area_synthetic"', f'id = "contact_area_pop{n}"')
    fa, fn, _ = (a.ravel() for a in np.meshgrid(FA, FN, np.arange(3), indexing="ij"))
    lines = ["subject,actuation_force,normal_force,contact_area,impedance"]
    for i in range(n):
        while True:
            p = {k: (np.exp(np.log(a) + b * rng.standard_normal()) if kind == "log" else a + b * rng.standard_normal())
                 for k, (kind, a, b) in POP.items()}
            y, ok = contact_area({k: np.float64(v) for k, v in p.items()}, {"normal_force": fn, "actuation_force": fa}, {})
            if np.all(ok):
                break
        area = y["contact_area"][0] * np.exp(rng.normal(0.0, 0.12, fn.size))
        imp = y["impedance"][0] * np.exp(rng.normal(0.0, 0.10, fn.size))
        lines += [f"P{i + 1:03d},{a:.0f},{b:.2f},{c * 1e6:.4f},{d:.5f}" for a, b, c, d in zip(fa, fn, area, imp)]
    out = folder / f"contact_area_pop{n}"
    out.mkdir(parents=True, exist_ok=True)
    (out / "dataset.toml").write_text(head + "\n" + cols)
    (out / "data.csv").write_text("\n".join(lines) + "\n")
    return out


def fitted(work, name, dataset):
    run = work / name
    if not (run / "index.json").exists():
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit_by("contact_area", str(dataset), "subject", run, seed=1)
        print(f"fits {name}: {time.perf_counter() - t0:.0f} s", flush=True)
    return run


def timed(fits, params, **kw):
    """Time the population step on loaded fits (loading, ~0.2 s a fit, is not included)."""
    load0 = os.getloadavg()[0]
    t0, c0 = time.perf_counter(), time.process_time()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", PopulationWarning)
        r = population(fits, params, rng=1, **kw)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    d = r.diagnostics()
    return r, {"subjects": len(r.subjects), "parameters": len(r.parameters), "wall_s": round(wall, 1),
               "cpu_s": round(cpu, 1), "load_average": [round(load0, 2), round(os.getloadavg()[0], 2)],
               "sweeps": r.sampler.get("sweeps"), "converged": r.converged,
               "rhat_max": round(float(d["r_hat"].max()), 4),
               "ess_bulk_min": round(float(d["ess_bulk"].min())), "ess_tail_min": round(float(d["ess_tail"].min())),
               "warnings": [str(w.message) for w in caught]}


SIZES = ("13x4", "13x8", "13x10", "50x10", "100x10", "13x4c", "13x8c")


def sizes(work, reweight, only=None):
    """The timing table; ``only`` (labels of SIZES) picks rows.  The simulated sizes are the
    first 13 / 50 subjects of one 100-subject run (fitted once, cached in ``work``)."""
    four = ["alpha_a0", "m0", "beta_z0", "n_z0"]
    eight = four + ["alpha_a1", "m1", "beta_z1", "n_z1"]
    ten = eight + ["sigma_contact_area", "sigma_impedance"]
    only = set(only or SIZES)
    shipped = fitted(work, "ca13", "contact_area_synthetic")
    sim = None
    if only & {"13x10", "50x10", "100x10"}:
        sim = load_run(fitted(work, "pop100", simulate_contact(work, 100)))
    table = [("13x4", "13 shipped x 4", shipped, four, {}), ("13x8", "13 shipped x 8", shipped, eight, {}),
             ("13x10", "13 sim x 10", 13, ten, {}), ("50x10", "50 sim x 10", 50, ten, {}),
             ("100x10", "100 sim x 10", 100, ten, {}),
             ("13x4c", "13 shipped x 4, correlated", shipped, four, {"correlated": True}),
             ("13x8c", "13 shipped x 8, correlated", shipped, eight, {"correlated": True})]
    rows = []
    for key, label, run, params, kw in table:
        if key not in only:
            continue
        fits = dict(list(sim.items())[:run]) if isinstance(run, int) else load_run(run)
        r, row = timed(fits, params, **kw)
        row["size"] = label
        if key == "13x8":
            row["effects"] = r.effects().to_dict("records")
        rows.append(row)
        print(row, flush=True)
    if reweight:
        _, row = timed(load_run(shipped), four, method="reweight")
        row["size"] = "13 shipped x 4, method=reweight"
        rows.append(row)
        print(row, flush=True)
    return rows


_HYPER = (np.log(0.5), 0.05)  # the fixed (mu, tau) of log mu of coverage()


def coverage(n_pop=20, seed=7, presses_list=(2, 6), hyper=_HYPER):
    """Coverage and squared error of the shrunk and separate subject intervals over ``n_pop``
    simulated populations of 13 Coulomb subjects.  ``hyper``: the fixed (mu, tau) of log mu,
    or None to draw each population from the sampler's hyper-prior (then the shrunk intervals
    must cover at their nominal rates on average: per-subject calibration).  The spread of
    the coverage is a cluster bootstrap over populations (the 13 subjects of a population
    share its hyper-posterior, so the binomial sd understates it)."""
    from popsim import draw_population, subject_fits

    rng = np.random.default_rng(seed)
    boot = np.random.default_rng(seed + 1)
    out = {}
    for presses in presses_list:
        hits = {k: {50: [], 90: [], 95: []} for k in ("shrunk", "separate")}
        err = {"shrunk": [], "separate": []}
        t0 = time.process_time()
        for _ in range(n_pop):
            _, _, theta = draw_population(rng, "lognormal", 13, hyper=hyper)
            fits = subject_fits(rng, theta, presses)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r = population(fits, ["mu"], rng=rng)
            for prob in (50, 90, 95):
                t = r.subject_summary(prob=prob / 100)
                for k in hits:
                    hits[k][prob].append(int(np.sum((t[f"{k}_lower"] < theta) & (theta < t[f"{k}_upper"]))))
            for k in err:
                err[k].append(float(np.mean((np.log(t[k]) - np.log(theta)) ** 2)))
        row = {"populations": n_pop, "truths": 13 * n_pop, "coverage": {}, "cluster_bootstrap_95": {},
               "binomial_sd": {}, "mse_log": {k: float(np.mean(v)) for k, v in err.items()},
               "hits_per_population": hits, "cpu_s": round(time.process_time() - t0)}
        for k, h in hits.items():
            row["coverage"][k], row["cluster_bootstrap_95"][k], row["binomial_sd"][k] = {}, {}, {}
            for prob, v in h.items():
                v = np.asarray(v) / 13
                pick = boot.integers(0, n_pop, (4000, n_pop))
                row["coverage"][k][prob] = float(v.mean())
                row["cluster_bootstrap_95"][k][prob] = [float(q) for q in np.quantile(v[pick].mean(axis=1), [0.025, 0.975])]
                row["binomial_sd"][k][prob] = float(np.sqrt(prob / 100 * (1 - prob / 100) / (13 * n_pop)))
        out[presses] = row
        print(presses, {k: row[k] for k in ("coverage", "cluster_bootstrap_95", "mse_log", "cpu_s")}, flush=True)
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--work", default="/tmp/skinfit_bench_population")
    ap.add_argument("--skip-sizes", action="store_true")
    ap.add_argument("--skip-coverage", action="store_true")
    ap.add_argument("--reweight", action="store_true")
    ap.add_argument("--only", nargs="+", choices=SIZES, help="rows of the timing table to run (default all)")
    ap.add_argument("--populations", type=int, default=20, help="simulated populations per coverage run")
    ap.add_argument("--hyper-prior", action="store_true",
                    help="coverage with each population drawn from the hyper-prior (per-subject calibration)")
    ap.add_argument("--presses", type=int, nargs="+", default=[2, 6])
    ap.add_argument("--seed", type=int, default=7, help="seed of the coverage simulations")
    ap.add_argument("--fits-only", action="store_true", help="only fit (and cache) the subjects")
    ap.add_argument("--out", default=str(ROOT / "bench/results/population.json"))
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    path = Path(args.out)
    res = json.loads(path.read_text()) if path.exists() else {}
    res["machine"] = f"{platform.node()} {platform.machine()}, {os.cpu_count()} cores"
    res["date"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    res["load_average_at_start"] = os.getloadavg()
    if args.fits_only:
        fitted(work, "ca13", "contact_area_synthetic")
        fitted(work, "pop100", simulate_contact(work, 100))
        return
    if not args.skip_sizes:
        new = sizes(work, args.reweight, args.only)
        keep = [r for r in res.get("sizes", []) if r["size"] not in {n["size"] for n in new}]
        res["sizes"] = keep + new
        path.write_text(json.dumps(res, indent=1, default=str))
    if not args.skip_coverage:
        key = "coverage_hyper_prior" if args.hyper_prior else "coverage"
        res[key] = coverage(args.populations, args.seed, presses_list=args.presses,
                            hyper=None if args.hyper_prior else (np.log(0.5), 0.05))
        path.write_text(json.dumps(res, indent=1, default=str))


if __name__ == "__main__":
    main()
