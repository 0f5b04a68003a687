"""Regenerate data.csv of the simulated wavy-surface dataset from its card.

    python datasets/wavy_synthetic/make.py [OUTPUT.csv]

Reads the generating parameters, noise, design and seed from dataset.toml beside this file;
the output is byte-for-byte repeatable.
"""

import sys
import tomllib
from pathlib import Path

import numpy as np

from skinfit.physics.wavy import two_point_ratio

HERE = Path(__file__).resolve().parent
AMPLITUDES_MM = (0.5, 1.5, 2.5)
WAVELENGTHS_MM = (20, 30, 40, 50)
LOAD_RANGES_N = ((0.6, 1.2), (1.2, 1.8), (1.8, 3.0))
SUBJECTS = ("A", "B", "C")
PER_CELL = 10


def main(out=HERE / "data.csv"):
    prov = tomllib.loads((HERE / "dataset.toml").read_text())["provenance"]
    truth = prov["generating_parameters"]
    rng = np.random.default_rng(prov["seed"])
    lines = ["subject,load_range,position,amplitude,wavelength,direction,normal_force,force_ratio"]
    cell = 0
    for a in AMPLITUDES_MM:
        for lam in WAVELENGTHS_MM:
            for lo, hi in LOAD_RANGES_N:
                for direction in (1, -1):
                    x = rng.uniform(-30.0, 30.0, PER_CELL)
                    fy = rng.uniform(lo, hi, PER_CELL)
                    ratio, ok = two_point_ratio(x * 1e-3, a * 1e-3, lam * 1e-3, direction, fy, truth["R"],
                                                truth["r"][str(lam)], truth["s"][str(lam)], truth["mu"], truth["n"])
                    if not np.all(ok):
                        raise SystemExit(f"generating parameters leave the support at a={a} mm, lambda={lam} mm")
                    y = ratio + rng.normal(0.0, prov["noise"]["sigma"], PER_CELL)
                    subject = SUBJECTS[cell % len(SUBJECTS)]
                    cell += 1
                    lines += [f"{subject},{lo:g}-{hi:g} N,{xi:.3f},{a:g},{lam:g},{direction},{f:.4f},{yi:.5f}"
                              for xi, f, yi in zip(x, fy, y)]
    Path(out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main(*sys.argv[1:])
