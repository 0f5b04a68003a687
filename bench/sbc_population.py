"""Simulation-based calibration of the population sampler (skinfit.population, Gibbs):
ranks of the true population mean and sd of the Coulomb friction coefficient among 99
posterior draws, over N simulated populations (tests/popsim.py: 8 subjects x 2 normal-force
levels x 2 presses), for the normal and log-normal families, plus a negative control whose
simulator draws the population sd from a 3x wider half-t than the sampler's hyper-prior
(it must fail).  Uniformity: chi-square over 10 bins, pass at p > 0.01.

    .venv/bin/python bench/sbc_population.py [--sims 100] [--seed 1]   -> bench/results/population_sbc.json
"""

import argparse
import json
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from popsim import run_sbc


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sims", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default=str(ROOT / "bench/results/population_sbc.json"))
    ap.add_argument("--only", action="append", help="run only these (normal, lognormal, control)")
    ap.add_argument("--rhat", type=float, default=1.05, help="R-hat of each population's stopping rule")
    args = ap.parse_args()
    out = {"machine": f"{platform.node()} {platform.processor() or platform.machine()}",
           "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "sims": args.sims, "seed": args.seed,
           "runs": {}}
    if Path(args.out).exists():
        out["runs"] = json.loads(Path(args.out).read_text()).get("runs", {})
    for name, family in [("normal", "normal"), ("lognormal", "lognormal")]:
        if args.only and name.split(":")[0] not in args.only:
            continue
        t0 = time.perf_counter()
        ranks, p = run_sbc(family, args.sims, args.seed, rhat_max=args.rhat)
        out["runs"][name] = {"pvalues": p, "ranks": ranks, "seconds": round(time.perf_counter() - t0, 1),
                             "rhat_max": args.rhat, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
        print(name, p, f"{time.perf_counter() - t0:.0f} s", flush=True)
        Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
