"""Commands whose inputs have not changed, as whole processes: the demo with every fit and
figure reused, ``skinfit report`` of one fit with its figures reused, ``skinfit compare``.

    MPLBACKEND=Agg .venv/bin/python bench/bench_reuse.py --demo /tmp/demoQ [--work DIR] [--repeat 3]
    MPLBACKEND=Agg .venv/bin/python bench/bench_reuse.py --demo /tmp/demoQ --source OLD_CHECKOUT --label before

``--demo`` is a folder made by ``skinfit demo --out`` (never written: it is copied to
``WORK/LABEL`` once).  Each command runs once untimed (it draws what its code has not drawn
yet, and stores what it keeps, e.g. the fits' summaries), then ``--repeat`` times timed: wall,
user + sys CPU of the process and its children, and the load average before each run.
``--source`` runs another checkout's ``skinfit`` package (put first on PYTHONPATH) with this
interpreter, for a before/after comparison on the same machine.  Prints one markdown table.
"""

import argparse
import os
import shutil
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from common import timed_skinfit


def run(args, env, log):
    """(wall s, CPU s of the children, load average before) of ``python -m skinfit ARGS``."""
    load = os.getloadavg()[0]
    # not a checkout's folder: `-m` puts the working folder first on sys.path
    return (*timed_skinfit(args, log, env, cwd=log.parent), load)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--demo", required=True, help="a folder written by `skinfit demo --out` (read only)")
    ap.add_argument("--work", default="/tmp/skinfit-bench-reuse")
    ap.add_argument("--label", default="after")
    ap.add_argument("--source", help="a checkout whose skinfit package is run instead of the installed one")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    work = Path(args.work)
    demo = work / args.label
    if not demo.exists():
        work.mkdir(parents=True, exist_ok=True)
        shutil.copytree(args.demo, demo)
    env = dict(os.environ, MPLBACKEND="Agg")
    if args.source:
        env["PYTHONPATH"] = str(Path(args.source).resolve())
    fits = demo / "electroadhesion_synthetic"
    commands = {
        "`skinfit demo`, every fit and figure reused (27 fits, population, contrasts, report)":
            ["demo", "--out", str(demo)],
        "`skinfit report` of one electroadhesion fit, figures reused":
            ["report", str(fits / "electroadhesion"), "--out", str(work / f"{args.label}-one")],
        "`skinfit compare` of the 3 electroadhesion fits (evidence and LOO cached in the files)":
            ["compare", *(str(fits / m) for m in ("electroadhesion", "electroadhesion_coulomb",
                                                  "electroadhesion_empirical"))],
    }
    print(f"| what ({args.label}) | wall s | CPU s (user + sys, with children) | load before |")
    print("|---|---|---|---|")
    for what, cmd in commands.items():
        log = work / f"{args.label}-{cmd[0]}.log"
        run(cmd, env, log)  # untimed: draws and stores what this code has not yet
        rows = [run(cmd, env, log) for _ in range(args.repeat)]
        print(f"| {what} | {', '.join(f'{w:.1f}' for w, _, _ in rows)} | "
              f"{', '.join(f'{c:.1f}' for _, c, _ in rows)} | {', '.join(f'{ld:.1f}' for _, _, ld in rows)} |",
              flush=True)


if __name__ == "__main__":
    main()
