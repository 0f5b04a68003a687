"""The model of issue 42's example, a power law with an electrostatic load term, as the plain
Python function a user writes (imported by tests/test_own_model.py, and by the processes it
starts, by module and name)."""

import numpy as np
import pandas as pd

#: Generating parameters of the simulated data [N^(1-n)], [N/V^2], [1], [N].
TRUTH = {"k": 0.5, "kappa": 2e-6, "n": 0.8, "sigma": 0.01}


def powerlaw_ea(p, x):
    """Tangential force [N] (k, n): p {k, kappa, n: (k, 1)}, x {normal_force [N], voltage [V]: (n,)}."""
    return p["k"] * (x["normal_force"] + p["kappa"] * x["voltage"] ** 2) ** p["n"]


def simulate(n_rows, seed, truth=TRUTH):
    """A DataFrame of ``n_rows`` rows in SI: normal forces 0.2-2 N, voltages 0-200 V, tangential
    forces from :func:`powerlaw_ea` at ``truth`` with normal noise of scale ``truth["sigma"]``."""
    rng = np.random.default_rng(seed)
    x = {"normal_force": rng.uniform(0.2, 2.0, n_rows), "voltage": rng.choice([0.0, 100.0, 200.0], n_rows)}
    p = {k: np.array([[v]]) for k, v in truth.items() if k != "sigma"}
    y = powerlaw_ea(p, x)[0] + rng.normal(0.0, truth["sigma"], n_rows)
    return pd.DataFrame({**x, "tangential_force": y})


def fit_medians(model, frame, priors, seed):
    """Posterior medians of ``skinfit.fit(model, frame, priors=priors, rng=seed)`` (short fits):
    run in worker processes by tests/test_own_model_workers.py, which hands them the model."""
    import skinfit

    fit = skinfit.fit(model, frame, priors=priors, rng=seed, ess_target=60, n_global=200)
    post = fit.idata["posterior"].to_dataset()
    return {name: float(np.median(post[name].values)) for name in ("k", "kappa", "n", "sigma")}


def predict_with(model, params, x):
    """``model.predict(params, x)``: run in a worker process that is handed the model."""
    return model.predict(params, x)
