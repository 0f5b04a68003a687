"""Cost of the data boundary: `import skinfit`, `skinfit models`, loading every shipped dataset
(pint imported and its registry built on the first non-SI unit) and the registry's entry-point
scan, each in a fresh process, median of N runs.  Writes bench/results/boundary.md.

    .venv/bin/python bench/bench_boundary.py [N] [CHECKOUT_BEFORE]
"""

import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASES = {
    "import skinfit": "import skinfit",
    "load_model x 15 (skinfit models' work)": "import skinfit\nfor m in skinfit.list_models(): skinfit.load_model(m)",
    "load_dataset x 5 (pint on first use)": "import skinfit\nfor d in skinfit.list_datasets(): skinfit.load_dataset(d)",
    "import pint + UnitRegistry()": "import pint\npint.UnitRegistry()",
    "entry_points(group='skinfit.models')": "from skinfit.io import registry\nregistry.plugin_folders()",
}


def run(code, env=None):
    t = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, env=env)
    return time.perf_counter() - t


def main(n=5, before=None):
    """``before``: a checkout of the previous code (its skinfit put first on PYTHONPATH)."""
    import os

    envs = {"this": None} | ({"before": {**os.environ, "PYTHONPATH": before}} if before else {})
    base = statistics.median(run("pass") for _ in range(n))
    rows = [f"| python -c pass (subtracted below) | {base:.3f} |" + " |" * (len(envs) - 1)]
    for name, code in CASES.items():
        times = {label: [] for label in envs if label == "this" or not ("registry" in code or "pint" in code)}
        for _ in range(n):  # interleaved, so that a change in the machine's load hits both alike
            for label in times:
                times[label].append(run(code, envs[label]))
        cells = [f"{statistics.median(times[k]) - base:.3f}" if k in times else "-" for k in envs]
        rows.append(f"| {name} | " + " | ".join(cells) + " |")
    text = "\n".join([
        "# Data boundary: import and load costs", "",
        f"Machine: {platform.node()} ({platform.processor() or platform.machine()}), Python {platform.python_version()}, "
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; median of {n} fresh processes each "
        "(this checkout and the one before interleaved), seconds above a bare interpreter start. The machine was shared with other jobs.", "",
        "| what | " + " | ".join(f"{k} s" for k in envs) + " |", "|---" * (len(envs) + 1) + "|", *rows, "",
        f"Command: `.venv/bin/python bench/bench_boundary.py {n}" + (f" {before}" if before else "") + "`", ""])
    (ROOT / "bench" / "results" / "boundary.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 5, sys.argv[2] if len(sys.argv) > 2 else None)
