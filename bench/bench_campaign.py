"""Campaign cost against the number of subjects and of worker processes (one model, one fit
per subject): local processes (1 and 2) and a Dask LocalCluster with 2 workers; peak resident
memory per worker process.

    .venv/bin/python bench/bench_campaign.py [--subjects 4 13 26 52] [--ess 400]
    .venv/bin/python bench/bench_campaign.py --threads-study [--subjects 8] [--repeats 2]

``--threads-study``: 1 and 2 worker processes, each fit's BLAS/OpenMP threads limited to 1
(the default) or 2 (``--threads 2``, what the libraries start with on this 2-core machine, as
before the limit existed), alternating, ``--repeats`` times; the summed fit time of each run
(``seconds`` of the index: the fits themselves, not starting the workers) appended to
bench/results/campaign.md as a section.

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

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from popdata import write_population

from skinfit.apps.campaign import run_campaign


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ess", type=float, default=400)
    parser.add_argument("--subjects", type=int, nargs="+", default=[4, 13, 26, 52])
    parser.add_argument("--threads-study", action="store_true")
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    if args.threads_study:
        return threads_study(args)
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


def threads_study(args):
    """Summed fit time of 1 and 2 workers with 1 and 2 BLAS threads per fit; a section of campaign.md."""
    n = args.subjects[0]
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        data, _ = write_population(tmp, n_subjects=n, rows=12)
        for r in range(args.repeats):
            for workers, threads in [(1, 1), (2, 1), (1, 2), (2, 2)]:
                out = f"run{r}_{workers}_{threads}"
                path = tmp / f"{out}.toml"
                path.write_text(f'schema_version = 1\nseed = 1\nout = "{out}"\nmodels = ["electroadhesion_coulomb"]\n'
                                f'datasets = ["{data.name}"]\nby = ["subject"]\n[fit]\ness = {args.ess}\n')
                t0 = time.perf_counter()
                table = run_campaign(path, workers=workers, threads=threads, echo=lambda *a: None)
                wall = time.perf_counter() - t0
                assert (table["status"] == "done").all() and set(table["threads"]) == {threads}
                runs.append({"repeat": r, "workers": workers, "threads": threads, "wall_s": wall,
                             "fit_s_sum": table["seconds"].sum(), "load": os.getloadavg()[0]})
                print(runs[-1], flush=True)
    cell = {}
    for run in runs:
        cell.setdefault((run["workers"], run["threads"]), []).append(run["fit_s_sum"])
    lines = ["", f"## BLAS/OpenMP threads per worker: summed fit time of {n} fits, 1 and 2 workers", "",
             f"Machine: {platform.machine()}, {os.cpu_count()} logical CPUs, Python {platform.python_version()}; shared "
             f"with other jobs (load average {min(r['load'] for r in runs):.1f}-{max(r['load'] for r in runs):.1f} "
             f"during the runs). 16 cores were not available: the 16-worker measurement of issue 39 (each fit 54% "
             f"slower with 16 workers than with one) could not be repeated here. Command: `.venv/bin/python "
             f"bench/bench_campaign.py --threads-study --subjects {n} --repeats {args.repeats} --ess {args.ess:g}` "
             "(electroadhesion_coulomb, one fit per subject of tests/popdata.py, 12 rows each; configurations "
             "alternated). `threads` is each fit's BLAS/OpenMP limit (`--threads`; 1 is the default now, 2 is what "
             "the libraries start with on 2 cores, i.e. the behaviour before the limit).", "",
             "| workers | threads per fit | summed fit time per run [s] | mean [s] | ratio 2 workers / 1 worker |",
             "|---|---|---|---|---|"]
    for threads in (1, 2):
        for workers in (1, 2):
            values = cell[(workers, threads)]
            ratio = (f"{np.mean(values) / np.mean(cell[(1, threads)]):.2f}" if workers == 2 else "")
            lines.append(f"| {workers} | {threads} | {', '.join(f'{v:.1f}' for v in values)} | "
                         f"{np.mean(values):.1f} | {ratio} |")
    lines += ["", "The summed fit time is the sum of the index's `seconds` (each fit's own wall time in its "
              "worker), so a ratio above 1 is the slow-down of each fit when two run at once on the two cores."]
    with open(HERE / "results" / "campaign.md", "a") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
