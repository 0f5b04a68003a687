"""Contrasts: a split fit whose truth differs by condition, and separate fits of two subjects."""

import warnings

import numpy as np
import pytest
from popdata import write_population
from scipy import stats

import skinfit
from skinfit.analysis.contrasts import contrast, fit_contrasts, hdi, level_contrasts
from skinfit.analysis.groups import fit_by, load_groups

TRUTHS = {"S01": 0.40, "S02": 0.55, "S03": 0.56}


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    folder = tmp_path_factory.mktemp("contrasts")
    path, _ = write_population(folder, truths=TRUTHS, rows=8, name="conditions")
    return folder, path


def test_split_fit_paired_levels(data):
    _, path = data
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        fit = skinfit.fit("electroadhesion_coulomb", str(path), split={"mu": "subject"}, rng=2, ess_target=200)
    table = level_contrasts(fit, "mu").set_index(["A", "B"])
    big = table.loc[("mu[S01]", "mu[S02]")]
    assert big["p_greater"] < 0.01  # truth differs by 0.15: the data say so
    assert big["diff_lower"] < TRUTHS["S01"] - TRUTHS["S02"] < big["diff_upper"] < 0
    assert big["ratio_lower"] < TRUTHS["S01"] / TRUTHS["S02"] < big["ratio_upper"]
    close = table.loc[("mu[S02]", "mu[S03]")]  # truths 0.01 apart: undecided
    assert 0.02 < close["p_greater"] < 0.98 and close["diff_lower"] < 0 < close["diff_upper"]
    # paired from the same draws: identical to contrast() on the raw slot draws
    post = fit.idata["posterior"]["mu"]
    direct = contrast(post.sel({post.dims[-1]: "S01"}).values.ravel(), post.sel({post.dims[-1]: "S02"}).values.ravel())
    assert direct["p_greater"] == big["p_greater"]
    with pytest.raises(skinfit.InputError, match="not split"):
        level_contrasts(fit, "E_star")


def test_separate_fits_resampled_and_paired(data):
    folder, path = data
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        fit_by("electroadhesion_coulomb", str(path), "subject", folder / "sep", seed=5, ess_target=200)
    fits = load_groups(folder / "sep")
    table = fit_contrasts(fits, "mu", rng=1).set_index(["A", "B"])
    assert len(table) == 3
    row = table.loc[("subject=S01", "subject=S02")]
    assert row["p_greater"] < 0.01
    assert row["diff_lower"] < TRUTHS["S01"] - TRUTHS["S02"] < row["diff_upper"]
    again = fit_contrasts(folder / "sep", "mu", rng=1).set_index(["A", "B"])
    assert again.equals(table)  # one rng: reproducible
    # independent posteriors: the difference's variance is the sum of the two variances
    a, b = (fits[f"subject={s}"].idata["posterior"]["mu"].values.ravel() for s in ("S01", "S02"))
    rng = np.random.default_rng(0)
    n = min(len(a), len(b))
    diff = rng.permutation(a)[:n] - rng.permutation(b)[:n]
    assert np.var(diff) == pytest.approx(np.var(a) + np.var(b), rel=0.1)


def test_contrast_closed_form():
    rng = np.random.default_rng(1)
    a, b = rng.normal(1.0, 0.1, 20000), rng.normal(0.9, 0.1, 20000)
    out = contrast(a, b)
    # A - B ~ N(0.1, 0.1*sqrt 2): P(A > B) = Phi(0.1 / 0.1414) = 0.760, 94% HDI = 0.1 -+ 1.881 * 0.1414
    assert out["p_greater"] == pytest.approx(0.760, abs=0.01)
    assert out["diff_lower"] == pytest.approx(0.1 - 0.2660, abs=0.01)
    assert out["diff_upper"] == pytest.approx(0.1 + 0.2660, abs=0.01)
    wide = contrast(a, b, prob=0.95)  # the probability set by the caller: 0.1 -+ 1.96 * 0.1414
    assert wide["diff_lower"] == pytest.approx(0.1 - 0.2772, abs=0.01)
    with pytest.raises(ValueError, match="paired"):
        contrast(a, b[:10])


def test_contrast_effect_is_a_difference_with_its_rope_probability():
    """Negative draws: the effect is the difference A - B ~ N(0.1, 0.1414); its probability of
    direction Phi(0.1 / 0.1414) and P(-0.05 < A - B < 0.05) from the normal cdf."""
    rng = np.random.default_rng(2)
    a, b = rng.normal(-0.4, 0.1, 40000), rng.normal(-0.5, 0.1, 40000)
    out = contrast(a, b, rope=(-0.05, 0.05))
    s = 0.1 * np.sqrt(2)
    assert out["effect"] == "difference" and out["estimate"] == pytest.approx(0.1, abs=0.005)
    assert out["sd"] == pytest.approx(s, rel=0.02)
    assert out["prob_direction"] == pytest.approx(stats.norm.cdf(0.1 / s), abs=0.01)
    assert out["p_rope"] == pytest.approx(stats.norm.cdf(-0.05 / s) - stats.norm.cdf(-0.15 / s), abs=0.01)
    assert np.isnan(contrast(a, b)["p_rope"])  # no region given: none computed
    with pytest.raises(skinfit.InputError, match="rope"):
        contrast(a, b, rope=(0.1, -0.1))


def test_contrast_of_a_positive_parameter_is_a_ratio():
    """Log-normal draws: A / B = exp(N(0.1, 0.1414)): median e^0.1, and P(0.95 < A / B < 1.05)
    from the normal cdf of the log."""
    rng = np.random.default_rng(3)
    a, b = np.exp(rng.normal(0.1, 0.1, 40000)), np.exp(rng.normal(0.0, 0.1, 40000))
    out = contrast(a, b, rope=(0.95, 1.05))
    s = 0.1 * np.sqrt(2)
    assert out["effect"] == "ratio" and out["estimate"] == pytest.approx(np.exp(0.1), rel=0.01)
    assert out["lower"] == out["ratio_lower"] and out["upper"] == out["ratio_upper"]
    assert out["p_rope"] == pytest.approx(stats.norm.cdf((np.log(1.05) - 0.1) / s)
                                          - stats.norm.cdf((np.log(0.95) - 0.1) / s), abs=0.01)


@pytest.mark.parametrize("prob", [0.5, 0.94, 0.95, 1.0])
def test_hdi_is_arviz_stats_hdi(prob):
    """The contrasts' HDI is ArviZ's (the independent reading) to the last bit, on skewed,
    symmetric, tied and tiny samples."""
    from arviz_stats import hdi as az_hdi

    rng = np.random.default_rng(7)
    samples = [rng.lognormal(0, 1, 4000), rng.normal(0, 1, 3001), rng.integers(0, 5, 200).astype(float),
               rng.normal(size=2), np.array([3.0]), rng.standard_t(2, 10000)]
    for x in samples:
        assert hdi(x, prob) == tuple(np.asarray(az_hdi(x, prob=prob)).ravel().tolist())


def test_hdi_closed_form_and_refusals():
    # 0, 1, ..., 100: any 95-step window is 95 wide, the first one is taken
    assert hdi(np.arange(101.0)[::-1], 0.95) == (0.0, 95.0)
    # 901 draws 1 apart, then 100 draws 1000 apart: 890 steps fit only in the dense part
    x = np.concatenate([np.arange(901.0), 2000.0 + 1000.0 * np.arange(100)])
    assert hdi(x, 0.89) == (0.0, 890.0)
    for bad in (0, 1.5):
        with pytest.raises(ValueError, match="prob"):
            hdi(x, bad)
    with pytest.raises(ValueError, match="0 draws"):
        hdi([], 0.9)
