"""Wall times of reports and of the whole demo, as whole processes (``skinfit ...``).

    .venv/bin/python bench/bench_report.py [--work /tmp/skinfit-bench-report] [--skip-fresh]

Rows: the whole ``skinfit demo`` from nothing (28 fits: 15 compared + 12 more contact_area
subjects, the 13-subject population, contrasts, report); the demo again with every fit reused
and the report's figure cache emptied (every figure drawn, in parallel processes); the demo
again with fits and figures reused; ``skinfit report`` of one fit (its figures new). Written
to bench/results/report.md with the machine and its load.
"""

import argparse
import shutil
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from common import machine_info, machine_text  # noqa: E402

SKINFIT = [sys.executable, "-m", "skinfit"]


def timed(args, log):
    t0 = time.perf_counter()
    out = subprocess.run(SKINFIT + args, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    log.write_text(out.stdout + out.stderr)
    if out.returncode:
        raise SystemExit(f"{' '.join(args)} failed ({out.returncode}); see {log}")
    return wall, subprocess.run(["uptime"], capture_output=True, text=True).stdout.split("load average:")[-1].strip()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--work", default="/tmp/skinfit-bench-report")
    ap.add_argument("--skip-fresh", action="store_true", help="reuse the fits already under --work")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "report.md"))
    args = ap.parse_args()
    work = Path(args.work)
    if not args.skip_fresh:
        shutil.rmtree(work, ignore_errors=True)
    runs, rep = work / "runs", work / "report"
    rows = []
    if not args.skip_fresh:
        rows.append(("whole `skinfit demo` from nothing (28 fits, population, contrasts, report)", "< 60 s",
                     *timed(["demo", "--out", str(runs), "--report", str(rep)], work / "fresh.log")))
    else:
        timed(["demo", "--out", str(runs), "--report", str(rep)], work / "warmup.log")
    shutil.rmtree(rep / "figures", ignore_errors=True)
    rows.append(("`skinfit demo` with every fit reused, every figure drawn (empty figure cache)", "< 20 s",
                 *timed(["demo", "--out", str(runs), "--report", str(rep)], work / "reused.log")))
    rows.append(("`skinfit demo` with fits and figures reused", "", *timed(["demo", "--out", str(runs), "--report",
                                                                        str(rep)], work / "cached.log")))
    one = runs / "electroadhesion_synthetic" / "electroadhesion"
    rows.append(("`skinfit report` of one fit (electroadhesion), figures new", "< 3 s",
                 *timed(["report", str(one), "--out", str(work / "one")], work / "one.log")))
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = ["# Reports and the demo: whole-process wall times", "",
             f"`.venv/bin/python bench/bench_report.py{' --skip-fresh' if args.skip_fresh else ''}` - {stamp}", "",
             machine_text(machine_info()), "",
             "| command | target | wall s | load average after (1, 5, 15 min) |", "|---|---|---|---|"]
    lines += [f"| {name} | {target} | {wall:.1f} | {load} |" for name, target, wall, load in rows]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
