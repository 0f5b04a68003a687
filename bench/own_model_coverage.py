"""Coverage of a model defined by a Python function (issue 42): data sets simulated from
tests/own_model_function.py's ``powerlaw_ea`` at its TRUTH (300 rows each, seeds 0..N-1), each
fitted with ``Model.from_function`` and the issue's scipy.stats priors; the share of data sets
whose central 95% interval holds each generating value, against the Binomial(N, 0.95) band.

    .venv/bin/python bench/own_model_coverage.py [N]      # results: bench/results/own_model.md
"""

import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import scipy.stats as st

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from own_model_function import TRUTH, powerlaw_ea, simulate

import skinfit


def main(n_sets=60):
    model = skinfit.Model.from_function(powerlaw_ea, observable=("tangential_force", "N"),
                                        covariates={"normal_force": "N", "voltage": "V"},
                                        parameters={"k": "N^(1-n)", "kappa": "N/V^2", "n": "1"})
    priors = {"k": st.lognorm(s=1.0, scale=0.5), "kappa": st.halfnorm(scale=1e-5), "n": st.uniform(0.3, 1.0),
              "sigma": st.halfnorm(scale=0.1)}
    inside = {name: 0 for name in TRUTH}
    seconds, unconverged = [], 0
    for seed in range(n_sets):
        data = simulate(300, seed=seed)
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = skinfit.fit(model, data, priors=priors, rng=seed)
        seconds.append(time.perf_counter() - t)
        unconverged += not fit.converged
        post = fit.idata["posterior"].to_dataset()
        for name, value in TRUTH.items():
            lo, hi = np.quantile(post[name].values.ravel(), [0.025, 0.975])
            inside[name] += bool(lo < value < hi)
        print(seed, f"{seconds[-1]:.1f} s", dict(inside), flush=True)
    lo, hi = st.binom.ppf([0.005, 0.995], n_sets, 0.95)
    lines = ["# Coverage of a model defined by a Python function (issue 42)", "",
             f"`{' '.join(['python', *sys.argv])}` on {os.cpu_count()} CPUs, load average "
             f"{os.getloadavg()[0]:.1f} at the end; skinfit.fit defaults (ess_target 400), seeds 0..{n_sets - 1}.",
             "", f"{n_sets} data sets of 300 rows simulated from `powerlaw_ea` at {TRUTH}; the issue's priors.",
             f"Binomial(N={n_sets}, 0.95) 99% band for the count inside: [{lo:.0f}, {hi:.0f}].", "",
             "| parameter | truth | inside 95% interval | rate | in band |", "|---|---|---|---|---|"]
    for name, count in inside.items():
        lines.append(f"| {name} | {TRUTH[name]:g} | {count}/{n_sets} | {count / n_sets:.3f} | "
                     f"{'yes' if lo <= count <= hi else 'NO'} |")
    lines += ["", f"Fit time per data set: median {np.median(seconds):.1f} s, max {max(seconds):.1f} s; "
                  f"not converged: {unconverged}."]
    out = Path(__file__).resolve().parent / "results" / "own_model.md"
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 60)
