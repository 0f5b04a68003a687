"""Coverage of fits to ingested data (issue 41): raw recordings simulated from the empirical power
law (tests/recordings.py: Ft = b Fn^c + d Fn per stroke plus a stroke-to-stroke scatter sigma,
AR(1) noise, 50 Hz hum, 1 kHz carrier, bias drift, strokes of random length, one trial in six
loaded 40% off its target), written as MATLAB v5 files, ingested with a rig file, fitted with
the shipped ``electroadhesion_empirical`` model; how often each generating parameter lies in its
central 95% interval over N experiments.  Also the z-scores (stroke mean - generating value) / se.

    .venv/bin/python bench/ingest_coverage.py [--n 50] [--seed 0]
"""

import argparse
import json
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import scipy.io

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from recordings import rig_volts, stroke_recording

import skinfit

TRUTH = {"b": 0.3, "c_exp": 0.67, "d": 0.3, "sigma": 0.01}
LOADS = (0.2, 0.5, 0.8, 1.2, 1.6, 2.0)
RIG = """schema_version = 1
format = "mat"
variable = "data"
sample_rate = { value = 10000, unit = "Hz" }
pattern = "{subject}_{load}N_{trial}.mat"
[metadata.load]
unit = "N"
[channels.tangential_force]
column = 0
unit = "V"
gain = { value = 0.4444, unit = "N/V" }
bias = { first = { value = 0.5, unit = "s" }, last = { value = 0.5, unit = "s" } }
rectify = true
[channels.normal_force]
column = 1
unit = "V"
gain = { value = 0.31, unit = "N/V" }
bias = { first = { value = 0.5, unit = "s" } }
[channels.position]
column = 2
unit = "count"
gain = { value = 0.0005, unit = "mm/count" }
[filter]
lowpass = { value = 100, unit = "Hz" }
notch = { value = 50, unit = "Hz" }
[strokes]
speed_above = { value = 20, unit = "mm/s" }
normal_force_above = { value = 0.05, unit = "N" }
trim = { value = 0.1, unit = "s" }
min_duration = { value = 0.3, unit = "s" }
[reject]
target = "load"
tolerance = 0.15
"""


def experiment(seed, folder, fit_kwargs):
    rng = np.random.default_rng(seed)
    files, truth = [], {}
    off = int(rng.integers(len(LOADS)))
    for k, load in enumerate(LOADS):
        normal = load * (1.4 if k == off else 1.0)
        sig, strokes = stroke_recording(rng, lengths=rng.uniform(0.5, 1.5, 6), normal=normal,
                                        law=(TRUTH["b"], TRUTH["c_exp"], TRUTH["d"]), scatter=TRUTH["sigma"])
        path = folder / f"S01_{load:g}N_{k}.mat"
        scipy.io.savemat(path, {"data": rig_volts(sig)})
        files.append(path)
        truth[path.stem] = strokes
    (folder / "rig.toml").write_text(RIG)
    ds = skinfit.ingest(files, folder / "rig.toml", out=folder / "dataset")
    z = []
    for name, group in ds.frame.groupby("recording"):
        for col in ("normal_force", "tangential_force"):
            z += list((group[col].to_numpy() - [s[col] for s in truth[name]]) / group[f"{col}_se"].to_numpy())
    rejected = [f.stem for f in files if f.stem not in set(ds.frame.recording)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = skinfit.fit("electroadhesion_empirical", folder / "dataset", rng=seed, **fit_kwargs)
    post = fit.idata["posterior"]
    inside = {}
    for name, value in TRUTH.items():
        draws = post[name].to_numpy().ravel()
        lo, hi = np.quantile(draws, [0.025, 0.975])
        inside[name] = bool(lo <= value <= hi)
    return {"seed": seed, "rows": len(ds), "rejected_ok": rejected == [files[off].stem], "inside": inside,
            "z": z}


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--n", type=int, default=50)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--ess", type=float, default=200)
    p.add_argument("--truth", default="", help="generating values, e.g. b=0.25,c_exp=0.8,d=0.2 (default: "
                   "b=0.3, c_exp=0.67, d=0.3, sigma=0.01, the prior centres of c_exp and d)")
    args = p.parse_args()
    for item in filter(None, args.truth.split(",")):
        key, value = item.split("=")
        TRUTH[key] = float(value)
    results, t0 = [], time.perf_counter()
    for i in range(args.n):
        with tempfile.TemporaryDirectory() as tmp:
            r = experiment(args.seed + i, Path(tmp), {"ess_target": args.ess})
        results.append(r)
        cover = {k: np.mean([x["inside"][k] for x in results]) for k in TRUTH}
        print(json.dumps({"i": i, "rows": r["rows"], "rejected_ok": r["rejected_ok"], "inside": r["inside"],
                          "coverage_so_far": cover, "elapsed_s": round(time.perf_counter() - t0)}), flush=True)
    z = np.concatenate([r["z"] for r in results])
    summary = {"truth": TRUTH, "experiments": len(results), "coverage": {k: float(np.mean([x["inside"][k] for x in results]))
                                                          for k in TRUTH},
               "rejected_correctly": int(sum(r["rejected_ok"] for r in results)),
               "z_mean": float(z.mean()), "z_sd": float(z.std()), "z_n": len(z)}
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
