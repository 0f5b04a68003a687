"""Coverage of fits with known per-row standard errors (issue 41, point 3).

    MPLBACKEND=Agg .venv/bin/python bench/known_se.py [--experiments 60] [--rows 200]

Each experiment simulates a per-stroke dataset the way ``skinfit ingest`` writes one: at 0 V
the shipped ``electroadhesion_coulomb`` model is F_t = mu F_n; normal forces uniform on
0.5-2 N, a known se per stroke uniform on 0.005-0.04 N (``tangential_force_se``), and
F_t ~ N(mu F_n, sigma^2 + se^2) with mu and sigma drawn from the flat priors it is fitted with
(tests/test_known_se.py's, narrowed: mu uniform on 0.4-1.2, sigma on 0.005-0.04 N). Each is fitted
(seed = experiment number, with the check of the fit to the data), and the central 50%, 90% and 95% intervals of mu
and sigma are checked for the truth: at the nominal rate the hit counts are
Binomial(experiments, level). For contrast, the same data fitted without the se column (sigma
then absorbs the se: its interval misses the generating extra scatter). Writes
``bench/results/known_se.md``.
"""

import argparse
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

import skinfit
from skinfit.inference.misfit import MisfitWarning

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from test_known_se import MODEL, PRIORS  # the test's flat priors: one definition

LEVELS = (0.5, 0.9, 0.95)
REDRAWN = []


def simulate(rng, n):
    """(truth, frame) of one experiment; drawn again (counted) in the rare case a force comes out < 0."""
    while True:
        mu, sigma = rng.uniform(0.4, 1.2), rng.uniform(0.005, 0.04)
        fn = rng.uniform(0.5, 2.0, n)
        se = rng.uniform(0.005, 0.04, n)
        ft = mu * fn + rng.normal(0.0, np.sqrt(sigma**2 + se**2))
        if (ft >= 0).all():
            break
        REDRAWN.append(1)
    frame = pd.DataFrame({"voltage [V]": np.zeros(n), "normal_force [mN]": 1e3 * fn,
                          "tangential_force [mN]": 1e3 * ft, "tangential_force_se [mN]": 1e3 * se})
    return {"mu": mu, "sigma": sigma}, frame


def hits(fit, truth):
    post = fit.group("posterior")
    out = {}
    for name, value in truth.items():
        draws = post[name].values.ravel()
        out[name] = [bool(np.quantile(draws, (1 - p) / 2) <= value <= np.quantile(draws, (1 + p) / 2)) for p in LEVELS]
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--experiments", type=int, default=60)
    ap.add_argument("--rows", type=int, default=200)
    args = ap.parse_args()
    folder = Path(tempfile.mkdtemp())
    # the truths are drawn from the priors fitted with: calibrated intervals cover at the nominal rate
    (folder / "flat.toml").write_text(PRIORS.replace("bounds = [0.0, 2.0]", "bounds = [0.4, 1.2]")
                                      .replace("bounds = [0.001, 0.2]", "bounds = [0.005, 0.04]"))
    priors = skinfit.load_priors(folder / "flat.toml")
    rng = np.random.default_rng(41)
    counts = {"with se": {"mu": np.zeros(3), "sigma": np.zeros(3)},
              "se column dropped": {"mu": np.zeros(3), "sigma": np.zeros(3)}}
    seconds, unconverged, misfit = [], 0, {label: 0 for label in counts}
    t0 = time.perf_counter()
    for i in range(args.experiments):
        truth, frame = simulate(rng, args.rows)
        for label, data in (("with se", frame), ("se column dropped", frame.drop(columns=["tangential_force_se [mN]"]))):
            ds = skinfit.Dataset.from_frame(data, model=MODEL, id=f"exp{i}")
            t = time.perf_counter()
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                fit = skinfit.fit(MODEL, ds, priors=priors, rng=i)
            misfit[label] += any(issubclass(w.category, MisfitWarning) for w in caught)
            if label == "with se":
                seconds.append(time.perf_counter() - t)
                unconverged += not fit.converged
            for name, h in hits(fit, truth).items():
                counts[label][name] += h
        print(f"{i + 1}/{args.experiments} {time.perf_counter() - t0:.0f} s", flush=True)
    n = args.experiments
    lines = ["# Coverage with known per-row standard errors (issue 41, point 3)", "",
             f"`MPLBACKEND=Agg .venv/bin/python bench/known_se.py --experiments {n} --rows {args.rows}`; "
             f"skinfit {skinfit.__version__}, {os.cpu_count()} CPUs (2 cores shared with other jobs; load "
             f"{os.getloadavg()[0]:.1f} at the end).", "",
             __doc__.split("\n\n")[2].replace("\n", " "), "",
             f"{n} experiments of {args.rows} strokes; fits with se: median {np.median(seconds):.1f} s, "
             f"{unconverged} not converged; {len(REDRAWN)} experiment(s) drawn again for a force < 0.", "",
             "| data | parameter | " + " | ".join(f"{p:.0%} interval: hits (expected; 95% band)" for p in LEVELS) + " |",
             "|---|---|" + "---|" * len(LEVELS)]
    for label, table in counts.items():
        for name, c in table.items():
            cells = []
            for p, k in zip(LEVELS, c):
                lo, hi = stats.binom.ppf([0.025, 0.975], n, p)
                cells.append(f"{int(k)}/{n} ({p * n:.0f}; {lo:.0f}-{hi:.0f})")
            lines.append(f"| {label} | {name} | " + " | ".join(cells) + " |")
    lines += ["", "Fits with a MisfitWarning (the check of the fit to the data, skinfit.inference.misfit; at most "
              "about 2-5% of fits of a correct model, bench/results/misfit.md): "
              + ", ".join(f"{label} {k}/{n}" for label, k in misfit.items()) + ".",
              "", "With the se column the hit counts lie in their binomial bands (calibrated); without it sigma "
              "is the total scatter sqrt(sigma^2 + se^2) and its intervals miss the generating extra scatter."]
    out = ROOT / "bench" / "results" / "known_se.md"
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
