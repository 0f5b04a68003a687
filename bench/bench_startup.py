"""Whole-process wall and CPU times of skinfit's commands beside a bare ``python -c pass``.

Each command runs ``--repeats`` times as a fresh process, the commands interleaved (so a
burst of load from other jobs hits all of them alike); the table gives the median and the
minimum wall time, the median CPU time (user + sys, steadier than wall time on a shared
machine), and the largest cumulative imports of each (``python -X importtime``).

    .venv/bin/python bench/bench_startup.py [--repeats 7] [--out bench/results/startup.md] [--source OLD]

``--source OLD`` adds the same fit run from an older checkout's package (``git archive COMMIT |
tar -x -C OLD``, put first on PYTHONPATH), interleaved with the rest: a back-to-back comparison.

``without dask installed`` runs the same fit with ``dask`` made unimportable, as on an
installation without the ``dask`` extra (the fit imports neither: the row checks that).
``libraries only`` imports the third-party packages a fit imports, and nothing of skinfit: the
floor under ``skinfit fit`` with these dependencies.
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from common import machine_info, machine_text, user_env

PY = sys.executable
NO_DASK = "import sys; sys.modules['dask'] = None; "
#: the third-party packages ``skinfit fit`` imports (emcee and arviz_stats import scipy.stats;
#: xarray imports dask.array and pint, when installed, on the first array it builds)
LIBRARIES = ("numpy", "pandas", "xarray", "scipy.stats", "emcee", "nlopt", "h5py", "h5netcdf", "arviz_base",
             "arviz_stats")


def commands(tmp, source=None):
    fit = ["fit", "electroadhesion", "electroadhesion_synthetic", "--out", str(Path(tmp) / "run"), "--seed", "1",
           "--quiet", "--overwrite"]  # repeated into one folder: each run replaces the last
    older = [*fit[:3], "--out", str(Path(tmp) / "run_older"), *fit[5:-1]]  # code from before --overwrite
    cli = "from skinfit.apps.cli import main; sys.exit(main({!r}))"
    return [
        ("python -c pass", [PY, "-c", "pass"], None),
        ("import skinfit", [PY, "-c", "import skinfit"], "< 1 s"),
        ("skinfit models", [PY, "-m", "skinfit", "models"], "< 0.5 s"),
        ("skinfit fit electroadhesion electroadhesion_synthetic --out X (summary and saved file)",
         [PY, "-m", "skinfit", *fit], "< 2 s"),
        ("the same fit, without dask installed", [PY, "-c", "import sys; " + NO_DASK + cli.format(fit)], "< 2 s"),
        ("libraries only: import " + ", ".join(LIBRARIES), [PY, "-c", "import " + ", ".join(LIBRARIES)], None),
    ] + ([] if source is None else [
        (f"the same fit, the code in {source}",
         ["env", f"PYTHONPATH={Path(source).resolve()}", PY, "-m", "skinfit", *older], None)])


def importtime(cmd, cwd, top=6):
    """The largest cumulative top-level imports of a command (``-X importtime``), in ms."""
    out = subprocess.run([cmd[0], "-X", "importtime", *cmd[1:]], capture_output=True, text=True, cwd=cwd,
                         env=user_env()).stderr
    rows = []
    for line in out.splitlines():
        parts = line.split("|")
        if len(parts) == 3 and parts[1].strip().isdigit():
            name = parts[2].rstrip()
            depth = (len(name) - len(name.lstrip())) // 2
            if depth <= 1:
                rows.append((int(parts[1]) / 1000, name.strip()))
    return sorted(rows, reverse=True)[:top]


def run(cmd, cwd):
    """(wall s, CPU s = user + sys) of one run of ``cmd`` as a child process in folder ``cwd``
    (not this checkout, whose ``skinfit`` folder ``-m``/``-c`` would put first on the path)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=cwd, env=user_env())
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise RuntimeError(f"{cmd} failed: {proc.stderr.read().decode()[-2000:]}")
    proc.stderr.close()
    return wall, usage.ru_utime + usage.ru_stime


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "startup.md"))
    ap.add_argument("--source", help="an older checkout whose fit to time beside this one's")
    args = ap.parse_args()
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        cmds = commands(tmp, args.source)
        # write the .pyc files, warm the disk cache
        subprocess.run(cmds[3][1], capture_output=True, check=True, cwd=tmp, env=user_env())
        times = {name: [] for name, _, _ in cmds}
        cpu = {name: [] for name, _, _ in cmds}
        for _ in range(args.repeats):
            for name, cmd, _ in cmds:
                wall, used = run(cmd, tmp)
                times[name].append(wall)
                cpu[name].append(used)
        imports = {name: importtime(cmd, tmp) for name, cmd, _ in cmds[1:4]}
    bare = statistics.median(times["python -c pass"])
    stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    flags = f" --source {args.source}" if args.source else ""
    lines = ["# Start-up: whole-process wall times of skinfit's commands", "",
             f"`.venv/bin/python bench/bench_startup.py --repeats {args.repeats}{flags}` - {stamp}", "",
             machine_text(machine_info()), "",
             f"Load average (1, 5, 15 min) at the start: {', '.join(f'{v:.2f}' for v in load_before)}.", "",
             f"Each command run {args.repeats} times as a new process, the commands interleaved; median and "
             "minimum wall time, the median less the bare interpreter's, and the median CPU time (user + sys).", "",
             "| command | median s | min s | median - python -c pass s | median CPU s | target |",
             "|---|---|---|---|---|---|"]
    for name, _, target in cmds:
        t = times[name]
        lines.append(f"| {name} | {statistics.median(t):.2f} | {min(t):.2f} | "
                     f"{statistics.median(t) - bare:.2f} | {statistics.median(cpu[name]):.2f} | {target or ''} |")
    lines += ["", "Largest imports (`python -X importtime`, cumulative ms, top level and one below):", ""]
    for name, rows in imports.items():
        lines.append(f"- {name}: " + ", ".join(f"{mod} {ms:.0f}" for ms, mod in rows))
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
