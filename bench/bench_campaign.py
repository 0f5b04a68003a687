"""Campaign cost against the number of subjects and of worker processes (one model, one fit
per subject): local processes (1 and 2) and a Dask LocalCluster with 2 workers; peak resident
memory per worker process.

    .venv/bin/python bench/bench_campaign.py [--subjects 4 13 26 52] [--ess 400]

The data are the simulated Coulomb population of tests/popdata.py (N subjects x 12 rows at
0 V); each configuration runs the same campaign (same seed, hence identical fits) into a fresh
folder.  Results: bench/results/campaign.md.
"""

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from popdata import write_population  # noqa: E402

from skinfit.campaign import run_campaign  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ess", type=float, default=400)
    parser.add_argument("--subjects", type=int, nargs="+", default=[4, 13, 26, 52])
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for n in args.subjects:
            data, _ = write_population(tmp, n_subjects=n, rows=12, name=f"population{n}")
            for name, scheduler, workers in [("processes", None, 1), ("processes", None, 2),
                                             ("dask LocalCluster", "local", 2)]:
                out = f"run{n}_{name.split()[0]}_{workers}"
                path = tmp / f"{out}.toml"
                path.write_text(f'schema_version = 1\nseed = 1\nout = "{out}"\nmodels = ["electroadhesion_coulomb"]\n'
                                f'datasets = ["{data.name}"]\nby = ["subject"]\n[fit]\ness = {args.ess}\n')
                t0 = time.perf_counter()
                table = run_campaign(path, scheduler=scheduler, workers=workers, echo=lambda *a: None)
                wall = time.perf_counter() - t0
                assert (table["status"] == "done").all()
                peak = table.groupby("worker")["peak_rss_mb"].max()
                rows.append({"subjects": n, "executor": name, "workers": workers, "wall_s": wall,
                             "fit_s_sum": table["seconds"].sum(), "peak_mb": peak.max(), "n_processes": len(peak)})
                print(rows[-1], flush=True)
    base = {r["subjects"]: r["wall_s"] for r in rows if r["workers"] == 1}
    load = os.getloadavg()
    lines = ["# Campaign benchmark: electroadhesion_coulomb, one fit per subject, ess target "
             f"{args.ess:g}", "",
             f"Machine: {platform.machine()}, {os.cpu_count()} logical CPUs (shared with other jobs while this "
             f"ran: load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} at the end), Python "
             f"{platform.python_version()}. Command: `.venv/bin/python bench/bench_campaign.py --ess {args.ess:g} "
             f"--subjects {' '.join(map(str, args.subjects))}`.",
             "", "| subjects | executor | workers | wall time [s] | per subject [s] | speed-up vs 1 process | "
             "sum of fit times [s] | peak RSS per worker [MB] |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['subjects']} | {r['executor']} | {r['workers']} | {r['wall_s']:.1f} | "
                     f"{r['wall_s'] / r['subjects']:.2f} | {base[r['subjects']] / r['wall_s']:.2f} | "
                     f"{r['fit_s_sum']:.1f} | {r['peak_mb']:.0f} |")
    lines += ["", "Wall time includes starting the worker processes (spawn) or the LocalCluster. Peak RSS is "
              "`ru_maxrss` of each worker process after its last fit (max over workers)."]
    (HERE / "results").mkdir(exist_ok=True)
    (HERE / "results" / "campaign.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
