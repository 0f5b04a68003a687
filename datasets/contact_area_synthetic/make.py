"""Regenerate data.csv of the simulated contact-area / impedance dataset from its card.

    python datasets/contact_area_synthetic/make.py [OUTPUT.csv]

Reads each subject's generating parameters, the noise and the seed from dataset.toml beside
this file, so the card is the single record of how the data were made; the output is
byte-for-byte repeatable.
"""

import sys
import tomllib
from pathlib import Path

import numpy as np

from skinfit.physics.contact_area import contact_area

HERE = Path(__file__).resolve().parent
ACTUATION_N = np.arange(0.0, 31.0, 5.0)
NORMAL_N = np.array([0.25, 0.5, 1.0, 1.5, 2.0, 3.0])
REPEATS = 3


def main(out=HERE / "data.csv"):
    card = tomllib.loads((HERE / "dataset.toml").read_text())
    prov = card["provenance"]
    rng = np.random.default_rng(prov["seed"])
    fa, fn, _ = (a.ravel() for a in np.meshgrid(ACTUATION_N, NORMAL_N, np.arange(REPEATS), indexing="ij"))
    lines = ["subject,actuation_force,normal_force,contact_area,impedance"]
    for subject, truth in prov["subjects"].items():
        params = {k: np.float64(v) for k, v in truth.items()}
        y, ok = contact_area(params, {"normal_force": fn, "actuation_force": fa}, {})
        if not np.all(ok):
            raise SystemExit(f"{subject}: generating parameters leave the physical support")
        area = y["contact_area"][0] * np.exp(rng.normal(0.0, prov["noise"]["sigma_contact_area"], fn.size))
        imp = y["impedance"][0] * np.exp(rng.normal(0.0, prov["noise"]["sigma_impedance"], fn.size))
        lines += [f"{subject},{a:.0f},{b:.2f},{c * 1e6:.4f},{d:.5f}" for a, b, c, d in zip(fa, fn, area, imp)]
    Path(out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main(*sys.argv[1:])
