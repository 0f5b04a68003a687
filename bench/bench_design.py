"""Experimental design (skinfit.design, issue 24): speed, and simulation studies with full fits.

Speed: the expected information gain (EIG) of one measurement at each of 1000 electroadhesion
candidates (50 normal forces 0.2-2 N x 20 voltages 0-200 V), nested Monte Carlo with 400 outer
x 400 inner prior draws, its Monte Carlo error per candidate; and a whole ``skinfit.design`` call
on them.

Simulation study (EIG): the recommended 24-point plan from the priors (noise sd 0.02 N, the
shipped dataset's) against 24 rows of the shipped dataset's design (evenly spaced).  For each
experiment a truth is drawn from the prior (conditioned on the physical support at both
designs), data simulated at both designs, both fitted with ``skinfit.fit`` (defaults, sigma
fitted); the posterior sd of each parameter (log coordinate for positive ones) is compared with
the sd the tool predicted, as the root mean square over experiments, and the ratio plan / baseline.

Simulation study (discrimination): electroadhesion vs electroadhesion_coulomb, the plan of
``design(..., discriminate=[...])`` against the same baseline; truths drawn from each model's
prior in turn; both models fitted to each data set, ln BF by bridge sampling (skinfit.evidence);
the share of experiments in which the generating model wins with ln BF > 3.

Usage: ``.venv/bin/python bench/bench_design.py [--experiments 24] [--seed 1]``; writes
bench/results/design.md.
"""

import argparse
import hashlib
import sys
import time
import warnings
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

import skinfit
from skinfit.data import Dataset
from skinfit.units import to_si

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import RESULTS, machine_info, machine_text  # noqa: E402

design_mod = sys.modules["skinfit.design"]
SIGMA = 0.02
GRID = {"grid": {"normal_force": {"unit": "mN", "from": 200, "to": 2000, "num": 10},
                 "voltage": {"unit": "V", "from": 0, "to": 200, "num": 9}}}
TEMPLATE = skinfit.load_dataset("electroadhesion_synthetic")


def speed(seed):
    model, priors = skinfit.load_model("electroadhesion"), skinfit.load_priors("electroadhesion")
    grid = {"grid": {"normal_force": {"unit": "mN", "from": 200, "to": 2000, "num": 50},
                     "voltage": {"unit": "V", "from": 0, "to": 200, "num": 20}}}
    X, _ = design_mod.read_candidates(grid, model)
    rng = np.random.default_rng(seed)
    noise, sigma = design_mod._noise_setup(model, priors, {"tangential_force": "normal"}, SIGMA)
    problem = design_mod._prior_problem(model, priors, rng, 4000, noise, sigma)
    problem, dropped = design_mod._restrict_to_support(problem, [X])
    rows = []
    for upper in (False, True):
        t0, c0 = time.perf_counter(), time.process_time()
        eig, se = design_mod.eig_nmc(problem, X, rng, n_outer=400, n_inner=400, upper=upper)
        rows.append({"estimator": "NMC, outer draw among inner (lower)" if not upper else "NMC, Ryan 2003 (upper)",
                     "candidates": len(eig), "draws": "400 x 400", "seconds": time.perf_counter() - t0,
                     "CPU seconds": time.process_time() - c0,
                     "EIG min-max": f"{eig.min():.2f}-{eig.max():.2f}", "se median": np.median(se),
                     "se max": se.max()})
    t0 = time.perf_counter()
    result = skinfit.design("electroadhesion", grid, n=24, rng=seed, noise_scale=SIGMA)
    whole = time.perf_counter() - t0
    return pd.DataFrame(rows), whole, dropped, result


def _si(frame, units):
    return {c.split(" [")[0]: frame[c].to_numpy(float) * to_si(c.split("[")[1][:-1]) for c in frame.columns
            if c.endswith("]")}


def _dataset(X, y, label):
    frame = pd.DataFrame({"subject": "S01", "voltage": X["voltage"], "normal_force": X["normal_force"],
                          "tangential_force": y})
    digest = hashlib.sha256(label.encode() + frame.to_numpy(str).tobytes()).hexdigest()
    return Dataset(f"design_sim[{label}]", "simulated for bench_design", frame, TEMPLATE.columns, TEMPLATE.groups,
                   TEMPLATE.provenance, TEMPLATE.model, TEMPLATE.path, digest)


def _truths(model_id, designs, n, rng):
    """n prior draws whose predictions are inside the support at every design."""
    model, priors = skinfit.load_model(model_id), skinfit.load_priors(model_id)
    out = []
    while len(out) < n:
        draws = {p: priors[p].rvs(500, rng) for p in model.parameter_names}
        ok = np.ones(500, dtype=bool)
        for X in designs:
            y, valid = model.predict(draws, X, return_valid=True)
            ok &= valid.all(axis=1)
        out += [{p: float(v[i]) for p, v in draws.items()} for i in np.flatnonzero(ok)]
    return out[:n]


def _simulate(model_id, truth, X, rng):
    mu = skinfit.load_model(model_id).predict(truth, X)
    return mu + SIGMA * rng.standard_normal(len(mu))


def _fit(model_id, ds, seed):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return skinfit.fit(model_id, ds, rng=seed)


def study_eig(n_exp, seed):
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    result = skinfit.design("electroadhesion", GRID, n=24, rng=rng, noise_scale=SIGMA)
    t_design = time.perf_counter() - t0
    designs = {"plan": _si(result.plan, result.units), "baseline": _si(result.baseline, result.units)}
    truths = _truths("electroadhesion", list(designs.values()), n_exp, rng)
    priors = skinfit.load_priors("electroadhesion")
    names = list(result.sd.index)
    is_log = design_mod._coordinates(priors, names)
    var = {k: [] for k in designs}
    nonconv = {k: 0 for k in designs}
    t0 = time.perf_counter()
    for i, truth in enumerate(truths):
        for label, X in designs.items():
            fit = _fit("electroadhesion", _dataset(X, _simulate("electroadhesion", truth, X, rng), f"{label}{i}"),
                       int(rng.integers(2**31)))
            nonconv[label] += not fit.converged
            post = fit.group("posterior")
            var[label].append([np.var(np.log(post[p].values) if lg else post[p].values) for p, lg in zip(names, is_log)])
    t_fits = time.perf_counter() - t0
    var = {k: np.array(v) for k, v in var.items()}  # (experiments, params)
    obs = {k: np.sqrt(v.mean(axis=0)) for k, v in var.items()}
    # the ratio's error over experiments: bootstrap of the experiments
    boot = []
    for _ in range(2000):
        j = rng.integers(n_exp, size=n_exp)
        boot.append(np.sqrt(var["plan"][j].mean(axis=0) / var["baseline"][j].mean(axis=0)))
    boot = np.array(boot)
    table = pd.DataFrame({"coordinate": result.sd["coordinate"], "prior sd": result.sd["now"],
                          "predicted plan": result.sd["plan"], "observed plan": obs["plan"],
                          "predicted baseline": result.sd["baseline"], "observed baseline": obs["baseline"],
                          "predicted ratio": result.sd["plan/baseline"],
                          "observed ratio": obs["plan"] / obs["baseline"],
                          "observed ratio 90% (bootstrap)": [f"{lo:.3f}-{hi:.3f}" for lo, hi in
                                                             zip(*np.percentile(boot, [5, 95], axis=0))]},
                         index=names)
    lo, hi = np.percentile(boot, [5, 95], axis=0)
    table["predicted ratio inside"] = np.where((result.sd["plan/baseline"] >= lo) & (result.sd["plan/baseline"] <= hi),
                                               "yes", "no")
    return result, table, {"design_s": t_design, "fits_s": t_fits, "nonconverged": nonconv, "n": len(truths)}


def study_discrimination(n_exp, seed):
    rng = np.random.default_rng(seed + 1000)
    models = ["electroadhesion", "electroadhesion_coulomb"]
    t0 = time.perf_counter()
    result = skinfit.design("electroadhesion", GRID, n=24, rng=rng, noise_scale=SIGMA, discriminate=models[1:])
    t_design = time.perf_counter() - t0
    designs = {"plan": _si(result.plan, result.units), "baseline": _si(result.baseline, result.units)}
    rows = []
    t0 = time.perf_counter()
    for g, gen in enumerate(models):
        truths = _truths(gen, list(designs.values()), n_exp // 2, rng)
        for i, truth in enumerate(truths):
            for label, X in designs.items():
                ds = _dataset(X, _simulate(gen, truth, X, rng), f"{gen}{label}{i}")
                logz = {}
                for m in models:
                    for _attempt in range(3):  # a MAP start can fail on data the model cannot fit: new seed
                        try:
                            fit = _fit(m, ds, int(rng.integers(2**31)))
                        except RuntimeError as exc:
                            fit, failure = None, str(exc)
                            continue
                        break
                    logz[m] = (skinfit.evidence(fit, rng=int(rng.integers(2**31))).log_z if fit is not None
                               else np.nan)
                    if fit is None:
                        print(f"{m} on {gen} {label} {i}: fit failed 3 times ({failure})")
                other = models[1 - g]
                rows.append({"design": label, "generating": gen, "ln_bf": logz[gen] - logz[other],
                             "failed": int(np.isnan(logz[gen] - logz[other]))})
    t_fits = time.perf_counter() - t0
    obs = pd.DataFrame(rows)
    summary = obs.groupby(["design", "generating"], sort=False).agg(
        experiments=("ln_bf", "size"), fits_failed=("failed", "sum"),
        wins_ln_bf_gt_3=("ln_bf", lambda v: int((v > 3).sum())), median_ln_bf=("ln_bf", "median")).reset_index()
    pred = result.discrimination.rename(columns={"median_ln_bf": "predicted median ln BF",
                                                 "p_ln_bf_gt_3": "predicted P(ln BF > 3)"})
    summary = summary.merge(pred[["design", "generating", "predicted median ln BF", "predicted P(ln BF > 3)"]],
                            on=["design", "generating"])
    summary["observed share ln BF > 3"] = summary["wins_ln_bf_gt_3"] / (summary["experiments"] - summary["fits_failed"])
    return result, summary, obs, {"design_s": t_design, "fits_s": t_fits}


def _md(frame, index=True):
    """A markdown table (numbers to 3 significant digits)."""
    frame = frame.reset_index() if index else frame
    cells = [[f"{v:.3g}" if isinstance(v, (float, np.floating)) else str(v) for v in row]
             for row in frame.itertuples(index=False)]
    head = ["" if str(c) == "index" else str(c) for c in frame.columns]
    return "\n".join(["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
                     + ["| " + " | ".join(r) + " |" for r in cells])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--experiments", type=int, default=24)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--skip-discrimination", action="store_true")
    ap.add_argument("--speed-only", action="store_true", help="only the speed section, to design_speed.md")
    args = ap.parse_args(argv)
    started = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    speed_table, whole, dropped, speed_result = speed(args.seed)
    print(speed_table, whole)
    if args.speed_only:
        out = RESULTS / "design_speed.md"
        out.write_text("\n".join([
            "# Experimental design: speed of the single-measurement EIG (skinfit.design)", "",
            f"`.venv/bin/python bench/bench_design.py --speed-only --seed {args.seed}` - started {started}", "",
            machine_text(machine_info()), "",
            f"As in design.md's speed section ({dropped} of 4000 prior draws dropped outside the support); "
            "CPU seconds (process time) alongside wall seconds, since the 2 cores are shared.", "",
            _md(speed_table, index=False), "", f"Whole `skinfit.design` call on the 1000 candidates: {whole:.1f} s."])
            + "\n")
        return print(f"written: {out}")
    eig_result, eig_table, eig_info = study_eig(args.experiments, args.seed)
    print(eig_table, eig_info)
    disc = None if args.skip_discrimination else study_discrimination(args.experiments, args.seed)
    if disc is not None:
        print(disc[1], disc[3])
    lines = ["# Experimental design (skinfit.design, issue 24)", "",
             f"`.venv/bin/python bench/bench_design.py --experiments {args.experiments} --seed {args.seed}` - "
             f"started {started}", "", machine_text(machine_info()), "",
             "## Speed: EIG of one measurement at 1000 candidates", "",
             "Electroadhesion priors, noise sd 0.02 N, 50 normal forces (0.2-2 N) x 20 voltages (0-200 V); "
             f"{dropped} of 4000 prior draws dropped (prediction outside the physical support, sliding area "
             "A0 - eta Ft^2 <= 0, at some candidate). The Monte Carlo error (se) is the standard error over the "
             "outer draws, reported for each candidate.", "", _md(speed_table, index=False), "",
             f"A whole `skinfit.design` call on these 1000 candidates (both single-point estimators, greedy "
             f"24-point plan, batch EIG of plan and baseline by importance-sampled nested MC, Laplace sds): "
             f"{whole:.1f} s.", "",
             "## Simulation study: posterior sd under the recommended plan vs the shipped design", "",
             f"Candidates: 10 normal forces 0.2-2 N x 9 voltages 0-200 V (90). Plan: 24 points, greedy on the "
             f"Laplace EIG about all seven parameters. Baseline: {eig_result.settings['baseline']}. "
             f"{eig_info['n']} experiments, truths from the prior conditioned on the support; each data set "
             f"fitted by `skinfit.fit` (sigma fitted). Sd in the log coordinate for positive parameters "
             f"(a relative sd), natural for alpha; observed = root mean square over experiments of the fits' "
             f"posterior sd; predicted = the tool's Laplace sd (root mean square over prior draws). "
             f"Design {eig_info['design_s']:.1f} s; fits {eig_info['fits_s']:.0f} s; not converged: "
             f"{eig_info['nonconverged']}.", "",
             "Plan vs baseline as the tool reports it (EIG about all parameters, nats):", "",
             _md(eig_result.comparison), "", "Plan (user units):", "",
             _md(eig_result.plan.iloc[:, 1:3].value_counts().rename("repeats").reset_index(), index=False), "",
             _md(eig_table)]
    if disc is not None:
        result, summary, obs, info = disc
        lines += ["", "## Simulation study: telling electroadhesion from electroadhesion_coulomb", "",
                  f"Plan: greedy on the expected ln BF of the generating model against the other (nested-MC "
                  f"marginal likelihoods over each model's prior draws); baseline as above. "
                  f"{args.experiments // 2} experiments per generating model, truths from its prior "
                  f"(conditioned on the support); both models fitted to every data set, ln BF by bridge sampling "
                  f"(a fit whose start fails is retried with a new seed, twice; experiments still failing are "
                  f"counted in fits_failed and left out of the share). "
                  f"Design {info['design_s']:.1f} s; fits and evidences {info['fits_s']:.0f} s.", "",
                  "Plan (user units):", "",
                  _md(result.plan.iloc[:, 1:3].value_counts().rename("repeats").reset_index(), index=False), "",
                  _md(summary, index=False)]
    out = RESULTS / "design.md"
    out.write_text("\n".join(lines) + "\n")
    print(f"written: {out}")


if __name__ == "__main__":
    main()
