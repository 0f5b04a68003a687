"""Regenerate data.csv of the simulated ultrasonic-friction dataset from its card.

    python datasets/ultrasonic_synthetic/make.py [OUTPUT.csv]

Reads the generating parameters, noise and seed from dataset.toml beside this file; the output
is byte-for-byte repeatable.
"""

import math
import sys
import tomllib
from pathlib import Path

import numpy as np

from skinfit.physics.ultrasonic import ultrasonic

HERE = Path(__file__).resolve().parent
VELOCITIES_MM_S = (20, 40, 60, 80, 100, 120, 140)  # Torres et al., Section III.B
AMPLITUDES_UM = (0.0, 0.8, 1.0, 1.2, 1.4, 1.6)  # Torres et al., Section III.C
ANGLES_DEG = (90, 0)
FREQUENCY_KHZ = 58.0
SUBJECTS = tuple(f"P{i}" for i in range(1, 9))
REPEATS = 3


def main(out=HERE / "data.csv"):
    prov = tomllib.loads((HERE / "dataset.toml").read_text())["provenance"]
    rng = np.random.default_rng(prov["seed"])
    rows = [(v, a, g) for g in ANGLES_DEG for a in AMPLITUDES_UM for v in VELOCITIES_MM_S for _ in range(REPEATS)]
    v, a, g = (np.array(c, dtype=float) for c in zip(*rows))
    x = {"velocity": v * 1e-3, "direction_angle": g * math.pi / 180, "amplitude_pp": a * 1e-6,
         "frequency": np.full(v.size, FREQUENCY_KHZ * 1e3)}
    params = {k: np.array([[val]]) for k, val in prov["generating_parameters"].items()}
    y = ultrasonic(params, x, {})[0]["friction_coefficient"][0] + rng.normal(0.0, prov["noise"]["sigma"], v.size)
    lines = ["subject,velocity,direction_angle,amplitude_pp,frequency,friction_coefficient"]
    lines += [f"{SUBJECTS[i % len(SUBJECTS)]},{vi:g},{gi:g},{ai:g},{FREQUENCY_KHZ:g},{yi:.5f}"
              for i, (vi, gi, ai, yi) in enumerate(zip(v, g, a, y))]
    Path(out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main(*sys.argv[1:])
