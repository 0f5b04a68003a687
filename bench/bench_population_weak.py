"""A small population the data cannot fully determine: 3 subjects x the 7 electroadhesion parameters.

The shipped electroadhesion data (one subject, 216 presses) dealt round-robin to three
pseudo-subjects S01-S03 (72 presses each, the same design), fitted ``--by subject`` (seed 1),
then ``skinfit.population`` over every model parameter (seed 1, 20 000 sweeps at most) and over
the parameters the non-convergence message advises keeping (``--params``).  Per run: CPU and
wall seconds, sweeps, convergence, worst R-hat and ESS, the subjects' independence-proposal
acceptance, and the non-convergence message.

    .venv/bin/python bench/bench_population_weak.py [--work DIR] [--max-sweeps N]
    -> bench/results/population_weak.json (numbers in bench/results/population.md)
"""

import argparse
import json
import platform
import re
import time
import warnings
from pathlib import Path

from skinfit.analysis.groups import fit_by
from skinfit.analysis.population.inputs import load_run
from skinfit.analysis.population.population import population

ROOT = Path(__file__).resolve().parents[1]


def three_subjects(work):
    """The shipped electroadhesion card and data with rows dealt to S01, S02, S03 in turn."""
    src = ROOT / "datasets/electroadhesion_synthetic"
    folder = Path(work) / "ea3"
    folder.mkdir(parents=True, exist_ok=True)
    card = (src / "dataset.toml").read_text()
    (folder / "dataset.toml").write_text(re.sub(r'(?m)^id = ".*"$', 'id = "ea3"', card, count=1))
    lines = (src / "data.csv").read_text().splitlines()
    rows = [f"S0{i % 3 + 1}," + line.split(",", 1)[1] for i, line in enumerate(lines[1:])]
    (folder / "data.csv").write_text("\n".join([lines[0], *rows]) + "\n")
    return folder


def run(fits, params, max_sweeps):
    t, w = time.process_time(), time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = population(fits, params, rng=1, max_sweeps=max_sweeps)
    s = r.sampler
    return {"parameters": r.parameters, "cpu_s": round(time.process_time() - t, 1),
            "wall_s": round(time.perf_counter() - w, 1), "sweeps": s["sweeps"], "converged": bool(s["converged"]),
            "rhat_max": round(s["rhat_max"], 4), "ess_min": round(s["ess_min"]),
            "acceptance": [round(a, 3) for a in s["acceptance"].values()], "problems": r.problems,
            "warnings_seen": len(caught)}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--work", default="/tmp/skinfit_bench_population_weak")
    ap.add_argument("--max-sweeps", type=int, default=20000)
    ap.add_argument("--out", default=str(ROOT / "bench/results/population_weak.json"))
    args = ap.parse_args()
    data = three_subjects(args.work)
    runs = Path(args.work) / "runs"
    if not (runs / "index.json").exists():
        fit_by("electroadhesion", str(data), "subject", runs, seed=1)
    fits = load_run(runs)
    rows = [run(fits, None, args.max_sweeps)]
    advised = re.search(r"--params (\S+) ", " ".join(rows[0]["problems"]))
    if advised:
        rows.append(run(fits, advised.group(1).split(","), args.max_sweeps))
    doc = {"machine": platform.node(), "python": platform.python_version(), "max_sweeps": args.max_sweeps,
           "runs": rows}
    Path(args.out).write_text(json.dumps(doc, indent=1))
    print(json.dumps(doc, indent=1))


if __name__ == "__main__":
    main()
