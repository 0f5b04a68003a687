"""Behaviour unchanged by a refactoring (issue 40): the sha256 of every seed-1 posterior draw of
each shipped model on its dataset (the demo's splits) and the bridge evidence of six of them,
printed for the skinfit this interpreter imports. Run it once per checkout and diff the output:

    PYTHONPATH=/path/to/old/checkout .venv/bin/python bench/bench_rebuild_identity.py > before.txt
    .venv/bin/python bench/bench_rebuild_identity.py > after.txt
    diff before.txt after.txt
"""

import hashlib
import sys
import warnings

import numpy as np

import skinfit

PAIRS = [("contact_area", "contact_area_synthetic", {}), ("contact_area_hertz", "contact_area_synthetic", {}),
         ("contact_area_no_levitation", "contact_area_synthetic", {}),
         ("electroadhesion", "electroadhesion_synthetic", {}), ("electroadhesion_coulomb", "electroadhesion_synthetic", {}),
         ("electroadhesion_empirical", "electroadhesion_synthetic", {}),
         ("textured_surface", "textured_synthetic", {"beta_h": "material"}),
         ("textured_no_transition", "textured_synthetic", {"beta_h": "material"}),
         ("textured_no_hysteresis", "textured_synthetic", {}), ("ultrasonic", "ultrasonic_synthetic", {}),
         ("ultrasonic_projected", "ultrasonic_synthetic", {}), ("ultrasonic_constant_mu", "ultrasonic_synthetic", {}),
         ("wavy_surface", "wavy_synthetic", {"r": "wavelength", "s": "wavelength"}),
         ("wavy_ball_bearing", "wavy_synthetic", {}),
         ("wavy_two_point_coulomb", "wavy_synthetic", {"r": "wavelength", "s": "wavelength"})]
EVIDENCE = {"electroadhesion", "electroadhesion_coulomb", "electroadhesion_empirical", "ultrasonic",
            "ultrasonic_projected", "ultrasonic_constant_mu"}


def main():
    warnings.simplefilter("ignore")
    print("skinfit from", skinfit.__file__, file=sys.stderr)
    for model, data, split in PAIRS:
        fit = skinfit.fit(model, data, rng=1, split=split or None)
        post = fit.idata["posterior"]
        h = hashlib.sha256()
        for name in sorted(post.data_vars):
            h.update(name.encode() + np.ascontiguousarray(post[name].values, dtype=np.float64).tobytes())
        line = f"{model:28s} {data:26s} draws {h.hexdigest()[:16]}"
        if model in EVIDENCE:
            ev = skinfit.evidence(fit)
            line += f"  log_z {ev.log_z!r} se {ev.se!r}"
        print(line, flush=True)


if __name__ == "__main__":
    main()
