"""Other model families: skinfit vs the bare emcee loop vs dynesty, one process, one run each.

    /work/venv/bin/python bench/bench_models.py [--models textured_surface contact_area wavy_surface
        ultrasonic] [--seed 1] [--skip-dynesty] [--dynesty-maxcall 2000000] [--out bench/results/models.md]

Each model on its shipped dataset with its shipped priors (``priors/<model>.toml``); the same
harness and convergence criterion as bench/bench_electroadhesion.py (see bench/common.py).
Writes bench/results/models.md.
"""

import argparse
import time
from pathlib import Path

import skinfit
from common import RESULTS, machine_info, machine_text, posterior_for, run_bare_emcee, run_dynesty, run_skinfit, table

DATASETS = {"textured_surface": "textured_synthetic", "contact_area": "contact_area_synthetic",
            "wavy_surface": "wavy_synthetic", "ultrasonic": "ultrasonic_synthetic"}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", nargs="+", default=list(DATASETS), choices=list(DATASETS))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--skip-dynesty", action="store_true")
    ap.add_argument("--dynesty-maxcall", type=int, default=2_000_000)
    ap.add_argument("--out", default=str(RESULTS / "models.md"))
    args = ap.parse_args()
    sections = []
    for model in args.models:
        data, priors = DATASETS[model], skinfit.load_priors(model)
        rows = [run_skinfit(model, data, priors, args.seed)]
        print(rows[-1].method, rows[-1].wall_s, rows[-1].note, flush=True)
        post = posterior_for(model, data, priors)
        rows.append(run_bare_emcee(post, args.seed))
        print(rows[-1].method, rows[-1].wall_s, rows[-1].note, flush=True)
        if not args.skip_dynesty:
            rows.append(run_dynesty(posterior_for(model, data, priors), args.seed, maxcall=args.dynesty_maxcall))
            print(rows[-1].method, rows[-1].wall_s, rows[-1].note, flush=True)
        sections += [f"## {model} on {data} ({post.n} rows, {post.ndim} sampled parameters, priors/{model}.toml)",
                     "", table(rows), ""]
    lines = ["# Other models: skinfit vs bare emcee vs dynesty (issue 7)", "",
             f"`/work/venv/bin/python bench/bench_models.py --models {' '.join(args.models)} --seed {args.seed}"
             f"{' --skip-dynesty' * args.skip_dynesty}{f' --dynesty-maxcall {args.dynesty_maxcall}' * (not args.skip_dynesty)}"
             f"` - {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}", "",
             machine_text(machine_info()), "",
             "Converged = ArviZ rank R-hat <= 1.01 and min bulk ESS >= 400 over all parameters (see "
             "bench/README.md). PyMC is not run for these models.", ""] + sections
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
