"""Wall time of a report written from a process that runs another thread (as a notebook kernel
or a Dask client does) and from one that does not, for two checkouts alternately.

    .venv/bin/python bench/bench_report_fork.py --fits A/fit.nc B/fit.nc --old OLD_SRC [--repeats 3]

Each timing is a new interpreter that loads the fits, optionally starts one idle thread, and
times :func:`skinfit.report.html.write_report` into a new folder (every figure drawn; an older
checkout's figure store turned off). ``OLD_SRC`` is a folder holding an earlier ``skinfit`` package (e.g. from ``git
archive``), put first on ``PYTHONPATH``; the new code is this checkout's. Printed as a markdown
table (bench/results/report_commands.md).
"""

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CHILD = """
import sys, threading, time, warnings
import skinfit
from skinfit.report.html import write_report
fits = [skinfit.load_fit(p) for p in sys.argv[3:]]
if sys.argv[1] == "thread":
    stop = threading.Event()
    threading.Thread(target=stop.wait, daemon=True).start()
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    t0 = time.perf_counter()
    write_report(fits, sys.argv[2])
    wall = time.perf_counter() - t0
forks = sum("use of fork()" in str(w.message) for w in caught)
print(f"{wall:.2f} {forks} {skinfit.__file__}")
"""


def one(src, mode, fits, out):
    fits = [Path(f).resolve() for f in fits]
    env = {**os.environ, "MPLBACKEND": "Agg", "SKINFIT_FIGURE_STORE": "off", "PYTHONPATH": str(src)}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    text = subprocess.run([sys.executable, "-c", CHILD, mode, str(out), *map(str, fits)], env=env, check=True,
                          capture_output=True, text=True, cwd=out.parent).stdout.split()  # not this checkout's folder
    assert Path(text[2]).resolve().is_relative_to(Path(src).resolve()), text
    return float(text[0]), int(text[1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fits", nargs="+", required=True)
    parser.add_argument("--old", required=True)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    cells = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            for mode in ("thread", "plain"):
                for name, src in (("old", args.old), ("new", ROOT)):
                    wall, forks = one(src, mode, args.fits, Path(tmp) / f"{name}{mode}{r}")
                    cells.setdefault((mode, name), []).append((wall, forks))
                    print(mode, name, wall, forks, f"load {os.getloadavg()[0]:.1f}", flush=True)
    print("\n| caller | old: wall s (fork warnings) | new: wall s (fork warnings) |\n|---|---|---|")
    for mode, label in (("thread", "a process with another thread"), ("plain", "a process without other threads")):
        row = [", ".join(f"{w:.1f} ({f})" for w, f in cells[(mode, name)]) for name in ("old", "new")]
        print(f"| {label} | {row[0]} | {row[1]} |")


if __name__ == "__main__":
    main()
