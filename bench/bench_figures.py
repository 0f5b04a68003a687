"""CPU seconds to draw and save every figure of the demo's report, one figure at a time.

    MPLBACKEND=Agg .venv/bin/python bench/bench_figures.py --work /tmp/figs-demo [--json out.json]

Runs ``skinfit demo`` with every fit reused (the demo's fits under ``--work``/runs, made
first when absent, not timed) and, in place of the report's parallel figure workers, draws
the report's figure jobs one by one in this process as a worker does: per figure the CPU seconds
(``time.process_time``) to build the Figure, to draw the PDF (``Figure.savefig`` to PDF), and the
rest of ``skinfit.plots.write_figure_files`` (the "PNG" column: the layout and the PNG drawn by
Agg, quantised and written). Prints the total, the total per plot function and the costliest
figures; ``--json`` keeps every row (for a before/after comparison). The figures are written under
``--work``/report/figures, to be looked at.
"""

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--work", default="/tmp/skinfit-bench-figures")
    ap.add_argument("--json", help="write every figure's row here")
    ap.add_argument("--top", type=int, default=12)
    args = ap.parse_args()
    work = Path(args.work)
    runs, rep = work / "runs", work / "report"
    if not (runs / "electroadhesion_synthetic" / "electroadhesion" / "fit.nc").exists():
        subprocess.run([sys.executable, "-m", "skinfit", "demo", "--out", str(runs), "--report",
                        str(work / "first_report")], check=True, capture_output=True)
    shutil.rmtree(rep, ignore_errors=True)

    from matplotlib.figure import Figure

    import skinfit.report.html as report
    from skinfit import plots
    from skinfit.apps.demo import run_demo
    from skinfit.report import figures

    rows = []
    pdf_time = [0.0]
    real_savefig = Figure.savefig

    def savefig(self, fname, *a, **kw):  # the PDF step of plots.write_figure_files
        t0 = time.process_time()
        try:
            return real_savefig(self, fname, *a, **kw)
        finally:
            if kw.get("format") == "pdf":
                pdf_time[0] += time.process_time() - t0

    def render_figures(fits, jobs, figdir, workers=None, meanwhile=None):
        if meanwhile is not None:  # the page's other sections, computed while the workers draw: their figures too
            jobs = list(jobs) + list(meanwhile())

        for f in fits:  # as render_figures does before it forks its workers: not figure time
            f.complete()
            f.summary()
        figures._FITS, figures._JOBS = fits, jobs
        errors = []
        for job in jobs:
            t0 = time.process_time()
            fig = getattr(plots, job["func"])(*figures._job_args(job), **job.get("kwargs", {}))
            t1 = time.process_time()
            n_axes, size = len(fig.axes), [round(v, 2) for v in fig.get_size_inches()]
            pdf_time[0] = 0.0
            Figure.savefig = savefig
            try:
                plots.write_figure_files(fig, job["path"])
            finally:
                Figure.savefig = real_savefig
            del fig
            t2 = time.process_time()
            rows.append({"figure": job["path"].name, "func": job["func"], "build": t1 - t0,
                         "png": t2 - t1 - pdf_time[0], "pdf": pdf_time[0], "axes": n_axes, "size": size})
            errors.append(None)
        figures._FITS, figures._JOBS = [], []
        return errors

    real = report.render_figures
    report.render_figures = render_figures
    try:
        run_demo(runs, rep, echo=lambda *a: None)
    finally:
        report.render_figures = real
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.split("load average:")[-1].strip()
    total = {k: sum(r[k] for r in rows) for k in ("build", "png", "pdf")}
    print(f"{len(rows)} figures; CPU s build {total['build']:.1f} + PNG {total['png']:.1f} + PDF {total['pdf']:.1f}"
          f" = {sum(total.values()):.1f}; load average after: {load}")
    by = {}
    for r in rows:
        b = by.setdefault(r["func"], [0, 0.0, 0.0, 0.0])
        b[0] += 1
        b[1] += r["build"]
        b[2] += r["png"]
        b[3] += r["pdf"]
    print("| function | figures | build | PNG | PDF | total CPU s |\n|---|---|---|---|---|---|")
    for func, (n, b, p, d) in sorted(by.items(), key=lambda kv: -sum(kv[1][1:])):
        print(f"| {func} | {n} | {b:.1f} | {p:.1f} | {d:.1f} | {b + p + d:.1f} |")
    print("\n| figure | axes | size in | build | PNG | PDF |\n|---|---|---|---|---|---|")
    for r in sorted(rows, key=lambda r: -(r["build"] + r["png"] + r["pdf"]))[:args.top]:
        print(f"| {r['figure']} | {r['axes']} | {r['size'][0]} x {r['size'][1]} | {r['build']:.2f} | {r['png']:.2f} "
              f"| {r['pdf']:.2f} |")
    if args.json:
        Path(args.json).write_text(json.dumps({"load": load, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
