"""Cost of the forward-contract check (skinfit.io.forward_check) each Posterior makes at construction:
per shipped model on its shipped dataset, the check (best of N) against one log-density call on
32 prior draws (best of N), both in this process.  Writes bench/results/forward_check.md.

    .venv/bin/python bench/bench_forward_check.py [N]
"""

import platform
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

import skinfit
from skinfit.posterior import Posterior

ROOT = Path(__file__).resolve().parents[1]


def best(f, n):
    times = []
    for _ in range(n):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return min(times)


def main(n=7):
    rows = []
    for m in skinfit.list_models():
        model = skinfit.load_model(m)
        ds = next((skinfit.load_dataset(d) for d in skinfit.list_datasets()
                   if skinfit.load_dataset(d).model == m), None)
        if ds is None:
            continue
        post = Posterior(model, skinfit.load_priors(m), ds)
        z = post.to_z(post.sample_prior(32, np.random.default_rng(1)))
        check, density = best(post._check_forward, n), best(lambda: post(z), n)
        rows.append(f"| {m} | {ds.id} | {post.n_unique} | {1e3 * check:.2f} | {1e3 * density:.2f} |")
    now = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    text = "\n".join([
        "# Forward-contract check: cost per Posterior", "",
        f"Machine: {platform.node()} ({platform.machine()}), Python {platform.python_version()}, {now}; best of {n} "
        "in one process. The check calls the forward function on 3 prior quantiles together and on each alone "
        "(4 calls) at the distinct rows, once per Posterior (a fit, an SBC simulation, a saved fit's rebuilt "
        "posterior); a fit makes thousands of log-density calls. The machine was shared with other jobs.", "",
        "| model | dataset | distinct rows | check ms | one log-density call, 32 draws, ms |", "|---|---|---|---|---|",
        *rows, "", f"Command: `.venv/bin/python bench/bench_forward_check.py {n}`", ""])
    (ROOT / "bench" / "results" / "forward_check.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:]))
