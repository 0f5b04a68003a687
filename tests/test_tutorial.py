"""docs/tutorials/own-data.ipynb runs as written (its code cells executed in order in one
namespace, as a kernel would), and its fit recovers the parameters it simulated from."""

import json
from pathlib import Path

import numpy as np

NOTEBOOK = Path(__file__).resolve().parents[1] / "docs" / "tutorials" / "own-data.ipynb"


def test_own_data_tutorial_runs_and_recovers_its_truth():
    cells = json.loads(NOTEBOOK.read_text())["cells"]
    ns = {}
    for cell in cells:
        if cell["cell_type"] == "code":
            exec(compile("".join(cell["source"]), str(NOTEBOOK), "exec"), ns)
    fit, truth, summary = ns["fit"], ns["truth"], ns["summary"]
    assert fit.converged
    assert summary.loc["E_star", "unit"] == "Pa" and summary.loc["sigma", "unit"] == "N"
    # the identifiable combination of the forces (alpha, the pressure coefficient) inside its 94% HDI
    assert summary.loc["alpha", "hdi_3%"] < truth["alpha"] < summary.loc["alpha", "hdi_97%"]
    # the data came in mN: stored in N
    np.testing.assert_allclose(fit.idata["observed_data"]["tangential_force"].values,
                               ns["df"]["tangential_force"].to_numpy() / 1e3, rtol=1e-15)
