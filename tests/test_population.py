"""Population inference: recovery of known hyper-parameters from 13 simulated subjects,
shrinkage towards the truth, the LKJ construction, and the small-ESS warning."""

import warnings

import numpy as np
import pytest
from scipy import stats

import skinfit
from popdata import MU_MEDIAN, TAU, write_population
from skinfit.groups import fit_by, load_groups
from skinfit.population import PopulationWarning, _cholesky_corr, population


@pytest.fixture(scope="module")
def thirteen(tmp_path_factory):
    folder = tmp_path_factory.mktemp("population")
    path, truths = write_population(folder, n_subjects=13)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        fit_by("electroadhesion_coulomb", str(path), "subject", folder / "fits", seed=21, ess_target=100)
    fits = load_groups(folder / "fits")
    return fits, {f"subject={s}": mu for s, mu in truths.items()}


def test_hyper_truths_in_95_intervals_and_shrinkage_helps(thirteen):
    fits, truths = thirteen
    result = population(fits, "mu", rng=3)
    assert result.sampler["converged"]
    table = result.summary().set_index("quantity")
    for qty, truth in [("mu", np.log(MU_MEDIAN)), ("tau", TAU), ("median", MU_MEDIAN),
                       ("mean", MU_MEDIAN * np.exp(TAU**2 / 2))]:
        row = table.loc[qty]
        assert row["lower"] < truth < row["upper"], f"{qty}: truth {truth:.4g} outside [{row['lower']:.4g}, {row['upper']:.4g}]"
    subjects = result.subject_summary()
    truth = np.log([truths[s] for s in subjects["subject"]])
    mse_separate = np.mean((np.log(subjects["separate"]) - truth) ** 2)
    mse_shrunk = np.mean((np.log(subjects["shrunk"]) - truth) ** 2)
    assert mse_shrunk < mse_separate
    # shrinkage pulls every subject towards the population median, never past it beyond the
    # Monte Carlo error of the medians (1.25 sd / sqrt(ESS); a subject whose separate median sits
    # on the centre may land on either side of it)
    centre = table.loc["median", "estimate"]
    sd = (subjects["shrunk_upper"] - subjects["shrunk_lower"]) / 3.92
    mcse = 1.2533 * sd / np.sqrt(subjects["ess"])
    assert np.all(np.abs(subjects["shrunk"] - centre) <= np.abs(subjects["separate"] - centre) + 3 * mcse)
    assert np.sum(np.abs(subjects["shrunk"] - centre) < np.abs(subjects["separate"] - centre)) >= 10
    assert min(result.ess.values()) > 50
    tree = result.to_datatree()
    assert tree["posterior"]["theta"].shape[-2:] == (13, 1)
    assert "halfnormal" in tree.attrs["hyperpriors"]


def test_correlated_and_ess_warning(thirteen):
    fits, _ = thirteen
    small = dict(list(fits.items())[:5])
    with pytest.warns(PopulationWarning, match=r"effective sample size .* < 100000"):
        result = population(small, ["mu", "sigma"], correlated=True, rng=4, n_draws=200, min_ess=100000,
                            ess_target=100)
    corr = result.corr
    np.testing.assert_allclose(np.diagonal(corr, axis1=1, axis2=2), 1.0, atol=1e-12)
    assert np.all(np.abs(corr[:, 0, 1]) < 1)
    assert "corr" in set(result.summary()["quantity"])


def test_lkj_construction_matches_closed_form_marginal():
    # LKJ(eta) in d dimensions: every correlation is marginally Beta(eta - 1 + d/2, same) on (-1, 1)
    # (Lewandowski, Kurowicka & Joe 2009).  Draw the canonical partial correlations from their
    # Beta distributions and map them through the Cholesky construction used by the sampler.
    rng = np.random.default_rng(0)
    d, eta, n = 3, 2.0, 20000
    cpc = [2 * rng.beta(eta + (d - 2 - j) / 2, eta + (d - 2 - j) / 2, n) - 1 for i in range(1, d) for j in range(i)]
    L, _ = _cholesky_corr(np.arctanh(np.column_stack(cpc)), d)
    omega = L @ np.swapaxes(L, 1, 2)
    a = eta - 1 + d / 2
    for i, j in [(1, 0), (2, 0), (2, 1)]:
        assert stats.kstest((omega[:, i, j] + 1) / 2, stats.beta(a, a).cdf).pvalue > 0.01
    # negative control: the naive Beta(eta, eta) for every CPC gives wrong marginals
    naive = [2 * rng.beta(eta, eta, n) - 1 for _ in range(3)]
    L, _ = _cholesky_corr(np.arctanh(np.column_stack(naive)), d)
    omega = (L @ np.swapaxes(L, 1, 2))[:, 1, 0]
    assert stats.kstest((omega + 1) / 2, stats.beta(a, a).cdf).pvalue < 1e-3
