"""Regenerate data.csv of the simulated electroadhesion dataset from its card.

    python datasets/electroadhesion_synthetic/make.py [OUTPUT.csv]

Reads the generating parameters, noise and seed from dataset.toml beside this file, so the
card is the single record of how the data were made; the output is byte-for-byte repeatable.
"""

import sys
import tomllib
from pathlib import Path

import numpy as np

from skinfit.physics.electroadhesion import electroadhesion

HERE = Path(__file__).resolve().parent
CONSTANTS = {"eps0": 8.8541878128e-12, "eps_air": 1.0005, "eps_sio2": 3.9, "eps_sc": 3000.0,
             "d_sio2": 1e-6, "d_sc": 25e-6, "R": 0.02}  # models/electroadhesion.toml


def main(out=HERE / "data.csv"):
    card = tomllib.loads((HERE / "dataset.toml").read_text())
    prov = card["provenance"]
    rng = np.random.default_rng(prov["seed"])
    voltages = np.arange(0.0, 201.0, 25.0)
    forces = np.linspace(0.2, 2.0, 12)
    v, fn, rep = (a.ravel() for a in np.meshgrid(voltages, forces, np.arange(2), indexing="ij"))
    params = {k: np.float64(val) for k, val in prov["generating_parameters"].items()}
    y, ok = electroadhesion(params, {"normal_force": fn, "voltage": v}, CONSTANTS)
    if not np.all(ok):
        raise SystemExit("generating parameters leave the physical support (A_app <= 0)")
    ft = y["tangential_force"] + rng.normal(0.0, prov["noise"]["sigma"], size=fn.size)
    lines = ["subject,voltage,normal_force,tangential_force"]
    lines += [f"S01,{a:.0f},{b * 1e3:.3f},{c * 1e3:.4f}" for a, b, c in zip(v, fn, ft)]
    Path(out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main(*sys.argv[1:])
