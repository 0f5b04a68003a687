"""How much of a stroke's reported standard error is the bias's, shared by all strokes of a trial?

``skinfit ingest`` adds the standard error of the bias subtracted (the mean of the first 0.5 s,
finger off) in quadrature to each stroke's own (the within-window scatter): the column
``<name>_se`` holds both, ``<name>_se_bias`` the shared part.  This script ingests recordings
simulated by tests/recordings.py (default noise: AR(1) phi 0.98 at 10 kHz, sd 5 mN, 50 Hz hum,
1 kHz carrier; strokes 0.5-1.5 s) through the issue's rig (bias from the first 0.5 s) and the
rig of tests/test_ingest.py (50 Hz notch, tangential drift from the first and last 0.5 s), and
reports the bias's share of the variance se_bias^2 / se^2 per stroke, and a check that the
shared error is real: the within-trial correlation of stroke errors.

    MPLBACKEND=Agg .venv/bin/python bench/ingest_bias_share.py [n_trials]
"""

import sys
import tempfile
from pathlib import Path

import numpy as np
import scipy.io

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from recordings import ISSUE_RIG, rig_volts, stroke_recording
from test_ingest import RIG

from skinfit.io.recordings.ingest import run_ingest


def main(n_trials=40):
    rng = np.random.default_rng(2026)
    with tempfile.TemporaryDirectory() as tmp:
        files, truth = [], {}
        for k in range(n_trials):
            sig, strokes = stroke_recording(rng, lengths=rng.uniform(0.5, 1.5, 6))
            path = Path(tmp) / f"S1_0V_{k}.mat"
            scipy.io.savemat(path, {"data": rig_volts(sig, bias=tuple(rng.uniform(0.1, 0.5, 2)))})
            files.append(path)
            truth[path.stem] = strokes
        for label, text in (("issue rig (bias: first 0.5 s, no notch)", ISSUE_RIG),
                            ("test rig (50 Hz notch; tangential bias: first and last 0.5 s)",
                             RIG.replace("[reject]\ntarget = { value = 0.5, unit = \"N\" }\n", ""))):
            rig = Path(tmp) / "rig.toml"
            rig.write_text(text)
            frame = run_ingest(files, rig).dataset.frame
            print(f"## {label}: {len(frame)} strokes of {n_trials} trials, kept windows "
                  f"{frame.duration.min():.2f}-{frame.duration.max():.2f} s")
            for name in ("normal_force", "tangential_force"):
                share = (frame[f"{name}_se_bias"] / frame[f"{name}_se"]) ** 2
                err = []
                for rec, g in frame.groupby("recording"):
                    want = np.array([s[name] for s in truth[rec]])
                    sign = np.where(g.direction == "forward", 1.0, -1.0) if name == "tangential_force" else 1.0
                    err.append(sign * (np.abs(g[name].to_numpy()) - want))  # the bias's error has one sign
                err = np.array(err)  # (trials, strokes)
                # within-trial correlation of errors: var of the trial mean vs the mean variance / m
                m = err.shape[1]
                effect = 1 + (m - 1) * share.mean()
                rho = (np.var(err.mean(axis=1), ddof=1) / np.mean(np.var(err, axis=0, ddof=1)) * m - 1) / (m - 1)
                pred = np.mean(frame[f"{name}_se_bias"] ** 2) / np.mean(frame[f"{name}_se"] ** 2)
                print(f"- {name}: bias share of se^2 median {share.median():.2f} (5-95%: {share.quantile(0.05):.2f}"
                      f"-{share.quantile(0.95):.2f}); se_bias/se median {np.sqrt(share).median():.2f}; "
                      f"within-trial error correlation measured {rho:.2f} (predicted by se_bias^2/se^2 {pred:.2f}); "
                      f"variance of a trial's {m}-stroke mean 1 + {m - 1} x share = {effect:.1f} x what independent rows give")


if __name__ == "__main__":
    main(*map(int, sys.argv[1:]))
