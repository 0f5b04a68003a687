"""What a user waits for, as whole-process times of commands, for two installations alternated.

    python bench/bench_waits.py BEFORE_BIN AFTER_BIN [--repeats N] [--out bench/results/waits.md]

BEFORE_BIN and AFTER_BIN are the ``bin/`` folders of two virtual environments (each with skinfit
installed), e.g. a checkout of the previous release and this one.  Each command runs from an
empty working folder, alternating BEFORE and AFTER, ``--repeats`` times each; the table gives the
median and range of the wall times.  The commands:

- ``skinfit models`` (start-up and reading the cards);
- ``skinfit fit electroadhesion electroadhesion_synthetic --seed 1`` (end to end, into a new folder);
- ``skinfit demo`` with every fit already made (fits reused, report figures reused);
- ``skinfit demo`` with every fit made, its report into a new folder (every figure drawn; a
  figure store, where an installation has one, is turned off with SKINFIT_FIGURE_STORE=off).
"""

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def timed(argv, cwd, env=None):
    t0 = time.perf_counter()
    done = subprocess.run(argv, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    wall = time.perf_counter() - t0
    if done.returncode not in (0, 3):
        sys.exit(f"{' '.join(map(str, argv))} failed ({done.returncode}): {done.stderr.strip()[-500:]}")
    return wall


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="skinfit-waits-"))
    times = {}
    try:
        for label, bin_dir in (("before", args.before), ("after", args.after)):  # the demo's fits, once each
            timed([bin_dir / "skinfit", "demo", "--out", work / label / "demo", "--report", work / label / "r0"],
                  work)
        commands = {
            "skinfit models": lambda b, w, i: [b / "skinfit", "models"],
            "skinfit fit (electroadhesion, seed 1)": lambda b, w, i: [
                b / "skinfit", "fit", "electroadhesion", "electroadhesion_synthetic", "--seed", "1",
                "--out", w / f"fit{i}", "--quiet"],
            "skinfit demo, fits reused": lambda b, w, i: [b / "skinfit", "demo", "--out", w / "demo",
                                                          "--report", w / "r0"],
            "skinfit demo, fits reused, every figure drawn": lambda b, w, i: [
                b / "skinfit", "demo", "--out", w / "demo", "--report", w / f"report{i}"],
        }
        for name, make in commands.items():
            for i in range(args.repeats):
                for label, bin_dir in (("before", args.before), ("after", args.after)):
                    env = {**os.environ, "SKINFIT_FIGURE_STORE": "off", "MPLBACKEND": "Agg"}
                    times.setdefault((name, label), []).append(timed(make(bin_dir, work / label, i), work, env))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    lines = ["| command | before: median (range) | after: median (range) |", "|---|---|---|"]
    for name in dict.fromkeys(n for n, _ in times):
        cells = [f"{statistics.median(t):.2f} s ({min(t):.2f}-{max(t):.2f})"
                 for t in (times[(name, "before")], times[(name, "after")])]
        lines.append(f"| {name} | {cells[0]} | {cells[1]} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
