"""Speed and memory of ``skinfit ingest`` on one hour of 10 kHz x 5 channels (issue 41).

Writes (once, by one-minute chunks through h5py) an HDF5 file ``/trials/hour/{fx, fy, fz,
voltage, position}`` of 36 M float32 samples a channel: a finger stroking back and forth
(2 s strokes at 40 mm/s, 0.4 s dwell), forces with noise, a 50 Hz hum and a 1 kHz carrier.
Then ingests it in a fresh process and reports wall time and that process's peak resident
memory (``resource.getrusage(RUSAGE_CHILDREN).ru_maxrss``).  Target: < 60 s, memory bounded
(a chunk at a time, not the 1.4 GB of the recording as float64).

    .venv/bin/python bench/bench_ingest.py [--folder /tmp/skinfit_ingest_bench] [--minutes 60]
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np

RATE = 10_000.0
RIG = """schema_version = 1
format = "hdf5"
[channels.tangential_force]
dataset = "fx"
unit = "V"
gain = { value = 0.4444, unit = "N/V" }
bias = { first = { value = 0.5, unit = "s" } }
rectify = true
[channels.lateral_force]
dataset = "fy"
unit = "V"
gain = { value = 0.4444, unit = "N/V" }
bias = { first = { value = 0.5, unit = "s" } }
[channels.normal_force]
dataset = "fz"
unit = "V"
gain = { value = 0.31, unit = "N/V" }
bias = { first = { value = 0.5, unit = "s" } }
[channels.voltage]
dataset = "voltage"
unit = "V"
[channels.position]
dataset = "position"
unit = "mm"
[filter]
lowpass = { value = 100, unit = "Hz" }
notch = { value = 50, unit = "Hz" }
[strokes]
speed_above = { value = 20, unit = "mm/s" }
normal_force_above = { value = 0.05, unit = "N" }
trim = { value = 0.1, unit = "s" }
min_duration = { value = 0.3, unit = "s" }
"""


def _velocity(t):
    """Periodic stroke velocity [m/s]: 1 s at rest, then 2 s strokes at 40 mm/s alternating, 0.4 s dwell."""
    period = 2.4
    phase = np.mod(t - 1.0, 2 * period)
    v = np.where(phase < 2.0, 0.04, np.where((phase >= period) & (phase < period + 2.0), -0.04, 0.0))
    return np.where(t < 1.0, 0.0, v)


def write(path, minutes):
    n = int(minutes * 60 * RATE)
    chunk = int(60 * RATE)
    rng = np.random.default_rng(1)
    with h5py.File(path, "w") as fh:
        g = fh.create_group("trials/hour")
        g.attrs["sample_rate_hz"] = RATE
        g.attrs["subject"] = "S01"
        d = {k: g.create_dataset(k, shape=(n,), dtype="f4", chunks=(min(chunk, n),))
             for k in ("fx", "fy", "fz", "voltage", "position")}
        x0 = 0.0
        for a in range(0, n, chunk):
            b = min(a + chunk, n)
            t = np.arange(a, b) / RATE
            v = _velocity(t)
            x = x0 + np.cumsum(v) / RATE
            x0 = x[-1]
            fn = np.where(t < 0.8, 0.0, 0.5)
            hum = 0.01 * np.sin(2 * np.pi * 50 * t) + 0.02 * np.sin(2 * np.pi * 1000 * t)
            d["fx"][a:b] = (np.sign(v) * 0.35 + rng.normal(0, 0.005, b - a) + hum) / 0.4444 + 0.2
            d["fy"][a:b] = (rng.normal(0, 0.005, b - a) + hum) / 0.4444 + 0.1
            d["fz"][a:b] = (fn + rng.normal(0, 0.005, b - a) + hum) / 0.31 + 0.3
            d["voltage"][a:b] = 100.0 + rng.normal(0, 0.1, b - a)
            d["position"][a:b] = x * 1e3
    return n


def ingest(path, folder):
    import skinfit

    rig = Path(folder) / "rig.toml"
    rig.write_text(RIG)
    t0, c0 = time.perf_counter(), time.process_time()
    ds = skinfit.ingest([path], rig, out=Path(folder) / "dataset")
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(json.dumps({"wall_s": wall, "cpu_s": cpu, "rows": len(ds), "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
                      / 1024}))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--folder", default="/tmp/skinfit_ingest_bench")
    p.add_argument("--minutes", type=float, default=60.0)
    p.add_argument("--step", choices=["all", "write", "ingest"], default="all")
    args = p.parse_args()
    folder = Path(args.folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"hour_{args.minutes:g}min.h5"
    if args.step == "write":
        return write(path, args.minutes)
    if args.step == "ingest":
        out = folder / "dataset"
        if out.exists():
            for f in out.iterdir():
                f.unlink()
        return ingest(path, folder)
    if not path.exists():
        t0 = time.perf_counter()
        subprocess.run([sys.executable, __file__, "--folder", str(folder), "--minutes", str(args.minutes),
                        "--step", "write"], check=True)
        print(f"wrote {path} ({path.stat().st_size / 2**20:.0f} MiB) in {time.perf_counter() - t0:.1f} s")
    out = subprocess.run([sys.executable, __file__, "--folder", str(folder), "--minutes", str(args.minutes),
                          "--step", "ingest"], check=True, capture_output=True, text=True)
    child = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    result = json.loads(out.stdout.strip().splitlines()[-1])
    print(json.dumps({**result, "children_maxrss_mb": child, "load": os.getloadavg()}, indent=1))


if __name__ == "__main__":
    main()
