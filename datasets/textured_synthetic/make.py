"""Regenerate data.csv of the simulated textured-silicone dataset from its card.

    python datasets/textured_synthetic/make.py [OUTPUT.csv]

Reads the generating parameters (with the per-material ``beta_h``), noise and seed from
dataset.toml beside this file; the sample geometry is the Biotribology 2019 paper's Table 1.  The output is
byte-for-byte repeatable.
"""

import sys
import tomllib
from pathlib import Path

import numpy as np

from skinfit.physics.textured import textured_surface

HERE = Path(__file__).resolve().parent
MODULUS_MPA = {"M10": 0.20, "M30": 0.75, "M40": 1.30, "M60": 2.30}  # the Biotribology 2019 paper Table 1
# the Biotribology 2019 paper Table 1: (asperity tip radius um, asperity height um, spacing um); flat: none
GEOMETRY_UM = {
    ("L200", "M10"): (18.8, 27.9, 200.0), ("L200", "M30"): (18.8, 28.9, 200.0),
    ("L200", "M40"): (18.4, 28.8, 200.0), ("L200", "M60"): (18.4, 27.1, 200.0),
    ("L100", "M10"): (20.4, 27.7, 100.0), ("L100", "M30"): (20.1, 28.1, 100.0),
    ("L100", "M40"): (19.7, 28.3, 100.0), ("L100", "M60"): (19.9, 28.0, 100.0),
}
LOADS_N = np.round(np.concatenate([np.arange(1, 7) * 0.1, np.arange(4, 11) * 0.2, np.arange(5, 11) * 0.5]), 1)
REPEATS = 2


def main(out=HERE / "data.csv"):
    card = tomllib.loads((HERE / "dataset.toml").read_text())
    prov = card["provenance"]
    rng = np.random.default_rng(prov["seed"])
    rows = [(t, m, f) for t in ("flat", "L200", "L100") for m in MODULUS_MPA for f in LOADS_N
            for _ in range(REPEATS)]
    texture, material, load = (np.array(v) for v in zip(*rows))
    geo = np.array([GEOMETRY_UM.get((t, m), (np.nan,) * 3) for t, m in zip(texture, material)])
    x = {"normal_force": load.astype(float), "sample_modulus": np.array([MODULUS_MPA[m] for m in material]) * 1e6,
         "asperity_radius": geo[:, 0] * 1e-6, "asperity_height": geo[:, 1] * 1e-6,
         "asperity_spacing": geo[:, 2] * 1e-6}
    params = {k: np.float64(v) for k, v in prov["generating_parameters"].items()}
    params["beta_h"] = np.array([prov["generating_split"]["beta_h"][m] for m in material])
    y, ok = textured_surface(params, x, prov["constants"])
    if not np.all(ok):
        raise SystemExit("generating parameters leave the physical support")
    mu = y["friction_coefficient"][0] + rng.normal(0.0, prov["noise"]["sigma"], size=len(rows))

    def um(v):
        return "" if np.isnan(v) else f"{v:.1f}"

    lines = ["subject,texture,material,sample_modulus,asperity_radius,asperity_height,asperity_spacing,"
             "normal_force,friction_coefficient"]
    lines += [f"S01,{t},{m},{MODULUS_MPA[m]:.2f},{um(g[0])},{um(g[1])},{um(g[2])},{f:.1f},{v:.4f}"
              for t, m, g, f, v in zip(texture, material, geo, load, mu)]
    Path(out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main(*sys.argv[1:])
