"""Where the CPU of a whole ``skinfit demo`` from nothing goes: each fit worker's task accounted.

    MPLBACKEND=Agg .venv/bin/python bench/bench_demo_cpu.py --work /tmp/demo-cpu [--source OLD_CHECKOUT ...]

Runs the demo from nothing (fits, population, report and its figures) in a child process per
source tree (this checkout, and each ``--source`` given, e.g. a ``git
archive`` of an older commit, imported through PYTHONPATH), the sources one after another.
In the child the demo's worker tasks are wrapped before the workers fork: per fit the CPU
seconds of fit + evidence + LOO + save (``demo._run_one``) and, for an older source whose fit
workers drew the report's figures into a figure store, the CPU seconds of that drawing
(``demo._draw_one``); then the main process's CPU, its children's CPU and the wall time. Prints
one row per source.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = r'''
import json, resource, sys, time
import skinfit.apps.demo as demo

log, runs, report = sys.argv[1:4]
fit_one, draw_one = demo._run_one, getattr(demo, "_draw_one", None)  # the latter: older sources only

def record(row):
    with open(log, "a") as f:
        f.write(json.dumps(row) + "\n")

def run_one(item, path):
    t = time.process_time()
    result = fit_one(item, path)
    record({"kind": "fit", "model": item["model"], "group": item.get("group", ""), "cpu": time.process_time() - t})
    return result

def draw(path, n_of_model):
    t = time.process_time()
    n = draw_one(path, n_of_model)
    record({"kind": "draw", "path": str(path), "cpu": time.process_time() - t, "figures": n})
    return n

demo._run_one = run_one  # inherited by the forked fit workers
if draw_one is not None:
    demo._draw_one = draw
wall, cpu = time.perf_counter(), time.process_time()
demo.run_demo(runs, report, echo=lambda *a: None)
children = resource.getrusage(resource.RUSAGE_CHILDREN)
record({"kind": "total", "wall": time.perf_counter() - wall, "main": time.process_time() - cpu,
        "children": children.ru_utime + children.ru_stime})
'''


def run(source, work):
    """One demo from nothing with ``source`` first on the path; its accounting rows."""
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    log = work / "cpu.jsonl"
    env = {**os.environ, "MPLBACKEND": "Agg", "SKINFIT_FIGURE_STORE": str(work / "store")}  # older sources' store
    if source is not None:
        env["PYTHONPATH"] = str(Path(source).resolve())
    subprocess.run([sys.executable, "-c", CHILD, str(log), str(work / "runs"), str(work / "report")],
                   env=env, check=True, capture_output=True, cwd=tempfile.gettempdir())
    return [json.loads(line) for line in log.read_text().splitlines()]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--work", default="/tmp/skinfit-bench-demo-cpu")
    ap.add_argument("--source", action="append", default=[], help="another source tree to time first")
    args = ap.parse_args()
    print("| source | wall s | CPU s total | fits (fit + evidence + LOO + save) | figures drawn by the fit "
          "workers | main process |\n|---|---|---|---|---|---|")
    for i, source in enumerate([*args.source, None]):
        rows = run(source, Path(args.work) / f"run{i}")
        total = next(r for r in rows if r["kind"] == "total")
        fits = sum(r["cpu"] for r in rows if r["kind"] == "fit")
        draws = [r for r in rows if r["kind"] == "draw"]
        print(f"| {source or 'this checkout'} | {total['wall']:.1f} | {total['main'] + total['children']:.1f} "
              f"| {fits:.1f} | {sum(r['cpu'] for r in draws):.1f} ({sum(r['figures'] for r in draws)} figures) "
              f"| {total['main']:.1f} |", flush=True)


if __name__ == "__main__":
    main()
