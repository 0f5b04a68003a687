"""Simulation-based calibration (Talts et al. 2018): the rank statistics and their uniformity
tests, a small calibrated run of the whole pipeline, and a negative control it must flag.

The full run per model family (100 simulations each) is ``bench/sbc_full.py``."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import skinfit
from skinfit.analysis.sbc import n_bins, run_sbc, uniformity
from skinfit.apps.cli import main

ROOT = Path(skinfit.__file__).resolve().parents[1]
MODEL = "electroadhesion_coulomb"  # 4 parameters, ~3 s per fit on 40 rows
SMALL = dict(n_draws=19, n_rows=40, seed=5)


def test_bins_divide_the_rank_range():
    assert n_bins(100, 99) == 20  # 100 ranks: 20 bins of 5 expected each
    assert n_bins(20, 19) == 4
    assert n_bins(10, 19) == 2


def test_uniform_ranks_pass_and_skewed_ranks_fail():
    exact = pd.DataFrame({"a": np.tile(np.arange(20), 5)})  # every rank 0..19 five times
    row = uniformity(exact, 19).loc["a"]
    assert row["p_chi2"] == pytest.approx(1.0) and row["pass"]
    high = pd.DataFrame({"a": np.repeat([17, 18, 19], 10)})  # an overconfident, biased fit
    assert not uniformity(high, 19).loc["a", "pass"]
    u_shape = pd.DataFrame({"a": np.r_[np.zeros(25, int), np.full(25, 19)]})  # posterior too narrow
    assert uniformity(u_shape, 19).loc["a", "p_chi2"] < 1e-6


def test_false_alarm_rate_on_uniform_ranks():
    """Ranks drawn uniformly on 0..99 (what a calibrated pipeline gives): each parameter fails at
    most at rate 2 * alpha (two tests, each exact or asymptotically of level alpha)."""
    rng = np.random.default_rng(11)
    ranks = pd.DataFrame(rng.integers(0, 100, size=(100, 500)))
    fail = 1.0 - uniformity(ranks, 99, alpha=0.01, rng=rng)["pass"].mean()
    assert fail <= 0.02 + 3 * np.sqrt(0.02 * 0.98 / 500)  # 2 alpha + 3 binomial sd


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """``skinfit sbc`` on the Coulomb model: 20 simulations on 40 rows of the shipped design, two
    processes."""
    out = tmp_path_factory.mktemp("sbc")
    code = main(["sbc", MODEL, "--n-sims", "20", "--draws", "19", "--rows", "40", "--seed", "5",
                 "--jobs", "2", "--out", str(out)])
    return code, out


def test_small_sbc_is_uniform(calibrated):
    code, out = calibrated
    table = pd.read_csv(out / "sbc.csv", index_col="parameter")
    assert code == 0 and table["pass"].all()
    assert list(table.index) == ["mu", "E_star", "d_air", "sigma"]
    ranks = pd.read_csv(out / "ranks.csv", index_col="sim")
    assert ranks.shape == (20, 4) and ranks.min().min() >= 0 and ranks.max().max() <= 19
    runs = pd.read_csv(out / "runs.csv")
    assert runs["min_ess"].min() >= 19  # draws close to independent: ESS above L
    assert json.loads((out / "sbc.json").read_text())["passed"] is True
    assert (out / "ranks.png").stat().st_size > 10_000


def test_same_seed_same_ranks_whatever_the_processes(calibrated):
    """Simulation i uses child i of the seed's SeedSequence: 3 simulations in one process give the
    first 3 rows of the 20-simulation run made in two processes."""
    _, out = calibrated
    ranks = pd.read_csv(out / "ranks.csv", index_col="sim")
    again = run_sbc(MODEL, n_sims=3, jobs=1, **SMALL)
    np.testing.assert_array_equal(again.ranks.to_numpy(), ranks.to_numpy()[:3])


def test_wrong_prior_is_flagged(tmp_path):
    """Negative control: the data are simulated with mu ~ normal(0.5, 0.3) but fitted with a prior
    confidently at mu = 1.5 +- 0.05: the posteriors sit above the truths and SBC fails for mu."""
    text = (ROOT / "priors" / f"{MODEL}.toml").read_text()
    wrong = text.replace('loc = 0.5\nscale = 0.3\nbounds = [0.0, 2.0]', 'loc = 1.5\nscale = 0.05\nbounds = [0.0, 2.0]')
    assert wrong != text
    path = tmp_path / f"{MODEL}.toml"
    path.write_text(wrong)
    result = run_sbc(MODEL, fit_priors=path, n_sims=10, jobs=2, **SMALL)
    assert not result.table.loc["mu", "pass"] and not result.passed
    assert result.ranks["mu"].mean() < 5  # posterior above the truth: few draws below it


def test_fork_from_a_threaded_process_never_happens_simulations_run_here():
    """run_sbc(jobs=2) from a process that runs other threads (a notebook kernel): forking it
    could deadlock a worker, and Python warns. The simulations run in this process instead,
    with a warning saying so, and give the ranks of the same seed run one at a time."""
    import threading
    import warnings

    stop = threading.Event()
    other = threading.Thread(target=stop.wait, daemon=True)
    other.start()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            threaded = run_sbc(MODEL, n_sims=2, jobs=2, **SMALL)
    finally:
        stop.set()
        other.join()
    messages = [str(w.message) for w in caught]
    assert not [m for m in messages if "use of fork()" in m], messages
    assert any("the 2 simulations run here one at a time" in m for m in messages), messages
    np.testing.assert_array_equal(threaded.ranks.to_numpy(), run_sbc(MODEL, n_sims=2, jobs=1, **SMALL).ranks.to_numpy())
