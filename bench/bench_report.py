"""Wall times of reports and of the whole demo, as whole processes (``skinfit ...``).

    .venv/bin/python bench/bench_report.py [--work /tmp/skinfit-bench-report] [--skip-fresh]
    .venv/bin/python bench/bench_report.py --report-only [--work DIR] [--profile FILE]

Rows (whole processes): the whole ``skinfit demo`` from nothing (27 fits: 15 compared + 12 more
contact_area subjects, the 13-subject population, contrasts, report); the demo again with every
fit reused and the report's figures emptied (every figure drawn); ``skinfit report`` of the 15
fits the demo had when the report's target was set (every figure drawn); the demo into a new
report folder (every figure drawn); again into the same folder (everything reused);
``skinfit report`` of one fit with its figures new, then reused. Written to
bench/results/report_commands.md with the machine and its load: wall, and user + sys CPU of
the process and its children.

``--report-only`` times :func:`skinfit.report.html.write_report` alone, in this process, on the
demo's saved fits (made once under ``--work`` when absent, not timed): the demo is run with
every fit reused and its ``write_report`` call timed (wall, CPU of this process and of the
figure workers), into a new report folder (every figure drawn) and again into the same
folder (every figure reused); then ``skinfit report`` of one electroadhesion fit, as a whole
process, figures drawn and reused. ``--profile FILE`` writes a cProfile of the first
write_report (one figure worker, so that the figures are in the profile).
"""

import argparse
import shutil
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from common import machine_info, machine_text, timed_skinfit


def timed(args, log, env=None):
    """(wall s, CPU s with children, load average after) of ``skinfit ARGS``."""
    import os

    wall, cpu = timed_skinfit(args, log, env)
    return wall, cpu, " ".join(f"{v:.1f}" for v in os.getloadavg())


def write_table(out, title, command, header, rows):
    """A markdown file: title, command and time, the machine, one table of ``rows``."""
    stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    lines = [f"# {title}", "", f"`{command}` - {stamp}", "", machine_text(machine_info()), "",
             "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(v) for v in row) + " |" for row in rows]
    Path(out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def _report_only(work, profile):
    """Rows (what, target, wall s, CPU text, load) of write_report on the demo's fits."""
    import resource

    import skinfit.report.figures as figures
    import skinfit.report.html as report
    from skinfit.apps.demo import run_demo

    runs = work / "runs"
    if not (runs / "electroadhesion_synthetic" / "electroadhesion" / "fit.nc").exists():
        timed(["demo", "--out", str(runs), "--report", str(work / "first_report")], work / "fits.log")
    real = report.write_report
    times = []

    def timed_write(*args, **kwargs):
        c0, w0 = time.process_time(), time.perf_counter()
        k0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        if profile and not times:
            import cProfile

            workers, figures.MAX_FIGURE_WORKERS = figures.MAX_FIGURE_WORKERS, 1
            prof = cProfile.Profile()
            try:
                out = prof.runcall(real, *args, **kwargs)
            finally:
                figures.MAX_FIGURE_WORKERS = workers
            prof.dump_stats(profile)
        else:
            out = real(*args, **kwargs)
        k1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        times.append((time.perf_counter() - w0, time.process_time() - c0,
                      k1.ru_utime + k1.ru_stime - k0.ru_utime - k0.ru_stime))
        return out

    report.write_report = timed_write
    rep = work / "report"
    rows = []
    try:
        for what, target in (("write_report of the demo (27 fits), fits reused, every figure drawn", "< 20 s"),
                             ("the same again, every figure reused", "")):
            if not times:
                shutil.rmtree(rep, ignore_errors=True)
            run_demo(runs, rep, echo=lambda *a: None)
            wall, cpu, children = times[-1]
            load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.split("load average:")[-1]
            rows.append((what, target, wall, f"{cpu:.1f} + {children:.1f} workers", load.strip()))
    finally:
        report.write_report = real
    one = runs / "electroadhesion_synthetic" / "electroadhesion"
    shutil.rmtree(work / "one", ignore_errors=True)
    for what, target in (("`skinfit report` of one fit (electroadhesion), figures drawn, whole process", "< 3 s"),
                         ("the same again, figures reused", "")):
        wall, cpu, load = timed(["report", str(one), "--out", str(work / "one")], work / "one.log")
        rows.append((what, target, wall, f"{cpu:.1f} (whole process)", load))
    return rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--report-only", action="store_true", help="time write_report alone (see the module text)")
    ap.add_argument("--profile", help="with --report-only: cProfile of the first write_report, one worker")
    ap.add_argument("--work", default="/tmp/skinfit-bench-report")
    ap.add_argument("--skip-fresh", action="store_true", help="reuse the fits already under --work")
    ap.add_argument("--out", default=None, help="default: bench/results/report.md with --report-only, "
                                                "else bench/results/report_commands.md")
    args = ap.parse_args()
    work = Path(args.work)
    args.out = args.out or str(Path(__file__).parent / "results" / ("report.md" if args.report_only
                                                                     else "report_commands.md"))
    if args.report_only:
        work.mkdir(parents=True, exist_ok=True)
        rows = _report_only(work, args.profile)
        write_table(args.out, "The report alone: write_report on the demo's saved fits, and a one-fit report",
                    ".venv/bin/python bench/bench_report.py --report-only",
                    ("what", "target", "wall s", "CPU s (this process + figure workers)", "load average after"),
                    [(w, t, f"{wall:.1f}", cpu, load) for w, t, wall, cpu, load in rows])
        return
    if not args.skip_fresh:
        shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True, exist_ok=True)
    import os

    runs, rep = work / "runs", work / "report"
    env = {**os.environ, "MPLBACKEND": "Agg"}
    demo = ["demo", "--out", str(runs), "--report"]
    rows = []
    if not args.skip_fresh:
        rows.append(("whole `skinfit demo` from nothing (27 fits, population, contrasts, report)",
                     "< 60 s", *timed(demo + [str(rep)], work / "fresh.log", env)))
    else:
        timed(demo + [str(rep)], work / "warmup.log", env)
    shutil.rmtree(rep / "figures", ignore_errors=True)
    rows.append(("`skinfit demo`, every fit reused, every figure drawn (report figures emptied)", "< 20 s",
                 *timed(demo + [str(rep)], work / "reused.log", env)))
    fifteen = sorted(str(p) for p in runs.rglob("fit.nc") if not p.parent.name.startswith("subject-"))
    shutil.rmtree(work / "report15", ignore_errors=True)
    rows.append((f"`skinfit report` of the demo's {len(fifteen)} fits but the 12 more contact_area subjects (the "
                 "demo when the target was set), every figure drawn", "< 20 s",
                 *timed(["report", *fifteen, "--out", str(work / "report15")], work / "report15.log", env)))
    shutil.rmtree(work / "report2", ignore_errors=True)
    rows.append(("`skinfit demo`, every fit reused, into a new report folder (every figure drawn)",
                 "< 20 s", *timed(demo + [str(work / "report2")], work / "report2.log", env)))
    rows.append(("`skinfit demo`, fits and figures reused (same report folder)", "",
                 *timed(demo + [str(rep)], work / "cached.log", env)))
    one = runs / "electroadhesion_synthetic" / "electroadhesion"
    shutil.rmtree(work / "one", ignore_errors=True)
    rows.append(("`skinfit report` of one fit (electroadhesion), figures drawn", "< 3 s",
                 *timed(["report", str(one), "--out", str(work / "one")], work / "one.log", env)))
    rows.append(("the same again, figures reused", "< 3 s",
                 *timed(["report", str(one), "--out", str(work / "one")], work / "one2.log", env)))
    write_table(args.out, "Reports and the demo: whole-process times",
                f".venv/bin/python bench/bench_report.py{' --skip-fresh' if args.skip_fresh else ''}",
                ("command", "target", "wall s", "CPU s (with children)", "load average after (1, 5, 15 min)"),
                [(name, target, f"{wall:.1f}", f"{cpu:.1f}", load) for name, target, wall, cpu, load in rows])


if __name__ == "__main__":
    main()
