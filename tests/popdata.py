"""A simulated population for the group, campaign, population and contrast tests.

Coulomb friction at zero voltage, ``Ft = mu_s * Fn`` (models/electroadhesion_coulomb.toml),
with per-subject friction coefficients drawn from a known log-normal population
``log mu_s ~ N(log MU_MEDIAN, TAU)``, and normal noise of SIGMA newtons.
"""

import numpy as np

MU_MEDIAN, TAU, SIGMA = 0.5, 0.1, 0.06

CARD = """schema_version = 1
id = "{id}"
title = "SIMULATED Coulomb friction of {n} subjects at 0 V (tests/popdata.py)"
model = "electroadhesion_coulomb"
file = "data.csv"
groups = ["subject"]

[provenance]
kind = "simulated"
script = "tests/popdata.py"
seed = {seed}
generating_parameters = {{ mu_median = {median}, tau = {tau}, sigma = {sigma} }}

[columns.subject]
kind = "category"

[columns.voltage]
unit = "V"

[columns.normal_force]
unit = "mN"

[columns.tangential_force]
unit = "mN"
signed = true  # noise can push a small force below zero
"""


def write_population(folder, *, n_subjects=13, rows=4, seed=7, median=MU_MEDIAN, tau=TAU, sigma=SIGMA,
                     name="population", truths=None):
    """Write ``folder/name/{dataset.toml,data.csv}``; returns (path, {subject: true mu}).

    ``truths`` ({subject: mu}) replaces the draws from the population when given.
    """
    rng = np.random.default_rng(seed)
    truths = truths or {f"S{i + 1:02d}": float(np.exp(np.log(median) + tau * rng.standard_normal()))
                        for i in range(n_subjects)}
    fn = np.linspace(0.2, 1.0, rows)
    lines = ["subject,voltage,normal_force,tangential_force"]
    for subject, mu in truths.items():
        ft = mu * fn + sigma * rng.standard_normal(rows)
        lines += [f"{subject},0,{a * 1e3:.4f},{b * 1e3:.4f}" for a, b in zip(fn, ft)]
    path = folder / name
    path.mkdir(parents=True, exist_ok=True)
    (path / "dataset.toml").write_text(CARD.format(id=name, n=n_subjects, seed=seed, median=median, tau=tau,
                                                   sigma=sigma))
    (path / "data.csv").write_text("\n".join(lines) + "\n")
    return path, truths
