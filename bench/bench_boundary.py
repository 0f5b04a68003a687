"""Cost of the data boundary: `import skinfit`, `skinfit models`, loading every shipped dataset
(pint imported and its registry built on the first non-SI unit) and the registry's entry-point
scan, each in a fresh process, median of N runs.  Writes bench/results/boundary.md.

    .venv/bin/python bench/bench_boundary.py [N]
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
    "entry_points(group='skinfit.models')": "from skinfit import registry\nregistry.plugin_folders()",
}


def run(code):
    t = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)
    return time.perf_counter() - t


def main(n=5):
    base = statistics.median(run("pass") for _ in range(n))
    rows = [f"| python -c pass (subtracted below) | {base:.3f} |"]
    for name, code in CASES.items():
        rows.append(f"| {name} | {statistics.median(run(code) for _ in range(n)) - base:.3f} |")
    text = "\n".join([
        "# Data boundary: import and load costs", "",
        f"Machine: {platform.node()} ({platform.processor() or platform.machine()}), Python {platform.python_version()}, "
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; median of {n} fresh processes each, "
        "seconds above a bare interpreter start. The machine was shared with other jobs.", "",
        "| what | s |", "| --- | --- |", *rows, "",
        f"Command: `.venv/bin/python bench/bench_boundary.py {n}`", ""])
    (ROOT / "bench" / "results" / "boundary.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 5)
