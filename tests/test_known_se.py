"""Known per-row standard errors in the likelihood (issue 41, point 3) and raw recordings fitted
by mistake (point 4).

A dataset column ``<observable>_se`` gives y_i ~ N(f(x_i), sigma^2 + se_i^2): checked against
scipy's densities at given parameters (normal, log-normal with se_i / y_i, Student-t), in the
replicates the fit simulates, by recovering the generating mu and extra scatter sigma of
data simulated with known se, and by the evidence against a quadrature that does not use
skinfit's likelihood.  The model is the shipped ``electroadhesion_coulomb`` at 0 V, where it is
F_t = mu F_n (E_star and d_air do not enter)."""

import json
import math
import warnings

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from scipy.special import logsumexp

import skinfit
from skinfit.analysis.design.model_problem import noise_setup
from skinfit.analysis.population.subjects import _NotStackable, _Stacked
from skinfit.apps.cli import main
from skinfit.errors import InputError
from skinfit.inference.misfit import INGEST_HINT, MisfitWarning, RawSeriesWarning, misfit_messages, raw_series
from skinfit.posterior import Posterior
from skinfit.results.fit import rebuild_posterior
from skinfit.results.tree import known_se_record

MODEL = "electroadhesion_coulomb"
MU, SIGMA = 0.55, 0.02  # generating friction coefficient and extra scatter [N]


def _frame(n, rng, mu=MU, sigma=SIGMA, se=None):
    """``n`` strokes at 0 V: normal force 0.2-2 N, a known se per row (0.005-0.06 N, or ``se``),
    tangential force mu F_n + N(0, sigma^2 + se^2); units mN like a lab's table."""
    fn = rng.uniform(0.2, 2.0, n)
    se = rng.uniform(0.005, 0.06, n) if se is None else np.broadcast_to(se, (n,))
    ft = mu * fn + rng.normal(0.0, np.sqrt(sigma**2 + se**2))
    return pd.DataFrame({"voltage [V]": np.zeros(n), "normal_force [mN]": 1e3 * fn,
                         "tangential_force [mN]": 1e3 * ft, "tangential_force_se [mN]": 1e3 * se})


def _post(frame, noise=None, priors=None):
    ds = skinfit.Dataset.from_frame(frame, model=MODEL)
    return Posterior(skinfit.load_model(MODEL), priors or skinfit.load_priors(MODEL), ds, noise=noise)


def _theta(post, **values):
    base = {"mu": MU, "E_star": 40e3, "d_air": 0.5e-6, "sigma": SIGMA, "nu": 5.0} | values
    return np.array([[base[n] for n in post.names]])


# ---- the likelihood in closed form ----------------------------------------------------------
@pytest.mark.parametrize("noise", ["normal", "lognormal", "student_t"])
def test_log_likelihood_is_the_sum_of_per_row_densities(rng, noise):
    """log L = sum_i log p(y_i | mu F_n,i, scale sqrt(sigma^2 + se_i^2)), se_i / y_i on the log
    scale for log-normal noise, at given parameters; pointwise values row by row."""
    frame = _frame(40, rng)
    post = _post(frame, noise)
    sigma = 0.3 if noise == "lognormal" else SIGMA
    theta = _theta(post, sigma=sigma)
    fn, ft = frame["normal_force [mN]"].to_numpy() / 1e3, frame["tangential_force [mN]"].to_numpy() / 1e3
    se = frame["tangential_force_se [mN]"].to_numpy() / 1e3
    mean = MU * fn
    if noise == "normal":
        expected = stats.norm.logpdf(ft, mean, np.sqrt(sigma**2 + se**2))
    elif noise == "lognormal":
        expected = stats.norm.logpdf(np.log(ft), np.log(mean), np.sqrt(sigma**2 + (se / ft) ** 2)) - np.log(ft)
    else:
        expected = stats.t.logpdf(ft, 5.0, mean, np.sqrt(sigma**2 + se**2))
    assert post.log_likelihood(theta)[0] == pytest.approx(expected.sum(), rel=1e-12)
    ll, _, _ = post.pointwise(theta)
    np.testing.assert_allclose(ll["tangential_force"][0], expected, rtol=1e-12)
    assert post.describe()["known_se"] == ["tangential_force"]


def test_zero_standard_errors_give_the_likelihood_without_them(rng):
    frame = _frame(30, rng, se=0.0)
    with_zero = _post(frame)
    without = _post(frame.drop(columns=["tangential_force_se [mN]"]))
    assert not without.se and "known_se" not in without.describe()
    theta = _theta(with_zero) * np.array([[1.0, 1.0, 1.0, 1.3]])
    assert with_zero.log_likelihood(theta)[0] == pytest.approx(without.log_likelihood(theta)[0], rel=1e-12)


def test_replicates_scatter_by_sigma_and_se(rng):
    """The predictive draws (Posterior.simulate / replicate: the posterior_predictive group)
    scatter about the prediction with sd sqrt(sigma^2 + se_i^2): z-scores of sd 1 in rows of
    small and of large se alike (Monte Carlo error of an sd of 4000 draws: 1.1%)."""
    frame = _frame(6, rng, se=np.array([0.0, 0.0, 0.0, 0.08, 0.08, 0.08]))
    post = _post(frame)
    theta = np.repeat(_theta(post), 4000, axis=0)
    fn = frame["normal_force [mN]"].to_numpy() / 1e3
    se = frame["tangential_force_se [mN]"].to_numpy() / 1e3
    for y in (post.simulate(theta, np.random.default_rng(1))["tangential_force"],
              post.replicate(theta, np.random.default_rng(1))[1]["tangential_force"]):
        z = (y - MU * fn) / np.sqrt(SIGMA**2 + se**2)
        np.testing.assert_allclose(z.std(axis=0), 1.0, atol=0.05)
        assert y[:, 3:].std(axis=0).min() > 3 * y[:, :3].std(axis=0).max()  # se 0.08 N against sigma 0.02 N


# ---- the data boundary --------------------------------------------------------------------
def test_standard_error_columns_are_checked(rng):
    frame = _frame(10, rng)
    bad = frame.copy()
    bad.loc[3, "tangential_force_se [mN]"] = -2.0
    with pytest.raises(InputError, match=r"column 'tangential_force_se \[mN\]', row 4: expected a force >= 0"):
        _post(bad)
    wrong = frame.rename(columns={"tangential_force_se [mN]": "tangential_force_se [mm]"})
    with pytest.raises(InputError, match=r"tangential_force_se \[mm\]'.*is a length; the standard error of "
                                         r"observable 'tangential_force' must be a force"):
        _post(wrong)
    bare = frame.rename(columns={"tangential_force_se [mN]": "tangential_force_se"})
    with pytest.raises(InputError, match="needs a unit of force"):
        _post(bare)
    gap = frame.copy()
    gap.loc[6, "tangential_force_se [mN]"] = np.nan
    with pytest.raises(InputError, match=r"tangential_force_se \[mN\]', row 7: missing value"):
        _post(gap)


def test_covariate_standard_errors_are_reported_not_modelled(rng):
    frame = _frame(20, rng)
    frame["normal_force_se [mN]"] = 0.02 * frame["normal_force [mN]"]
    frame.loc[5, "normal_force_se [mN]"] = 0.1 * frame.loc[5, "normal_force [mN]"]
    post = _post(frame)
    assert post.covariate_se["normal_force"]["max_relative"] == pytest.approx(0.1)
    assert post.covariate_se["normal_force"]["row"] == 6
    same = _post(frame.drop(columns=["normal_force_se [mN]"]))
    theta = _theta(post)
    assert post.log_likelihood(theta)[0] == same.log_likelihood(theta)[0]  # not modelled
    notes = [n["message"] for n in known_se_record(post)["notes"]]
    assert notes[1] == ("normal_force: standard errors in the dataset (normal_force_se) reported, not modelled: "
                        "normal_force is treated as known (errors-in-variables not modelled); largest relative "
                        "standard error 0.1 (row 6)")
    assert known_se_record(same)["covariates"] == {} and "normal_force" not in known_se_record(same)


# ---- a fit: recovery, what it records, the evidence ---------------------------------------
PRIORS = """schema_version = 1
model = "electroadhesion_coulomb"
[mu]
dist = "uniform"
bounds = [0.0, 2.0]
source = "electroadhesion_friction"
[E_star]
dist = "uniform"
bounds = [2e3, 100e3]
source = "electroadhesion_friction, test: ignored by the likelihood at 0 V"
[d_air]
dist = "loguniform"
bounds = [1e-9, 5e-6]
source = "electroadhesion_friction, test: ignored by the likelihood at 0 V"
[sigma]
dist = "uniform"
bounds = [0.001, 0.2]
source = "electroadhesion_friction"
"""


@pytest.fixture(scope="module")
def se_fit(tmp_path_factory):
    """300 strokes with known per-row se (0.005-0.06 N, most of the scatter) and extra scatter
    sigma 0.02 N, fitted with flat priors (seed 3): (fit, frame, priors)."""
    path = tmp_path_factory.mktemp("priors") / "flat.toml"
    path.write_text(PRIORS)
    priors = skinfit.load_priors(path)
    frame = _frame(300, np.random.default_rng(2026))
    ds = skinfit.Dataset.from_frame(frame, model=MODEL, id="strokes")
    with warnings.catch_warnings():
        warnings.simplefilter("error", MisfitWarning)  # a well-specified fit: no misfit
        fit = skinfit.fit(MODEL, ds, priors=priors, rng=3, max_steps=4000)
    return fit, frame, priors


def test_fit_recovers_mu_and_the_extra_scatter(se_fit):
    fit, _, _ = se_fit
    table = fit.summary()
    for name, truth in (("mu", MU), ("sigma", SIGMA)):
        assert table.loc[name, "hdi_3%"] < truth < table.loc[name, "hdi_97%"], (name, table.loc[name])
    # sigma is the scatter beyond the se, not the total (rms total ~0.039 N here)
    assert table.loc["sigma", "hdi_97%"] < 0.03


def test_fit_says_the_standard_errors_are_in_the_likelihood(se_fit):
    fit, _, _ = se_fit
    record = fit.attr("known_se")
    assert record["observables"]["tangential_force"]["column"] == "tangential_force_se"
    text = fit.report_text()
    assert "tangential_force: per-row standard errors from the dataset added in quadrature to sigma" in text
    assert "extra scatter beyond the per-row standard errors" in fit.summary().loc["sigma", "note"]
    assert json.loads(fit.attrs["setup"])["known_se"] == ["tangential_force"]
    rebuilt = rebuild_posterior(fit.idata)  # reports and populations rebuild it from the tree
    np.testing.assert_array_equal(rebuilt.se["tangential_force"], fit.posterior.se["tangential_force"])
    theta = np.array([[fit.map[n] for n in fit.posterior.names]])
    assert rebuilt.log_likelihood(theta)[0] == fit.posterior.log_likelihood(theta)[0]
    with pytest.raises(_NotStackable):  # the population's one-call likelihood has no per-row variance
        _Stacked([fit.posterior, rebuilt])


def test_predictive_group_includes_the_standard_errors(se_fit):
    fit, frame, _ = se_fit
    se = frame["tangential_force_se [mN]"].to_numpy() / 1e3
    pp = fit.group("posterior_predictive")["tangential_force"].values.reshape(-1, len(se))
    spread = pp.std(axis=0)
    expected = np.sqrt(SIGMA**2 + se**2)
    big, small = se > 0.045, se < 0.015
    assert spread[big].mean() == pytest.approx(expected[big].mean(), rel=0.1)
    assert spread[small].mean() == pytest.approx(expected[small].mean(), rel=0.1)


def _quadrature_log_z(frame):
    """log Z of the 0 V data under PRIORS with F_t ~ N(mu F_n, sigma^2 + se_i^2): mu integrated
    in closed form given sigma (a weighted Gaussian, normal CDFs over [0, 2]), sigma by the
    trapezoid rule; E_star and d_air integrate out (normalised priors, absent from the
    likelihood).  Independent of skinfit's likelihood and priors."""
    fn = frame["normal_force [mN]"].to_numpy() / 1e3
    ft = frame["tangential_force [mN]"].to_numpy() / 1e3
    se = frame["tangential_force_se [mN]"].to_numpy() / 1e3
    sigma = np.linspace(0.001, 0.2, 8001)
    v = sigma[:, None] ** 2 + se**2  # (grid, n)
    w = 1.0 / v
    S = (w * fn**2).sum(axis=1)
    mu_hat = (w * fn * ft).sum(axis=1) / S
    rss = (w * (ft - mu_hat[:, None] * fn) ** 2).sum(axis=1)
    mass = stats.norm.cdf((2.0 - mu_hat) * np.sqrt(S)) - stats.norm.cdf(-mu_hat * np.sqrt(S))
    log_f = -0.5 * np.log(2 * np.pi * v).sum(axis=1) - 0.5 * rss + 0.5 * np.log(2 * np.pi / S) + np.log(mass)
    dw = np.full(sigma.size, sigma[1] - sigma[0])
    dw[[0, -1]] /= 2
    return logsumexp(log_f + np.log(dw)) - math.log(2.0) - math.log(0.2 - 0.001)


def test_bridge_evidence_agrees_with_quadrature(se_fit):
    fit, frame, _ = se_fit
    truth = _quadrature_log_z(frame)
    est = skinfit.evidence(fit, rng=4)
    assert abs(est.log_z - truth) < max(0.05, 4 * est.se), (est, truth)


def test_design_noise_adds_the_typical_standard_error():
    model, priors = skinfit.load_model(MODEL), skinfit.load_priors(MODEL)
    draws = {"sigma": np.array([0.02, 0.03, 0.04])}
    _, sigma = noise_setup(model, priors, {"tangential_force": "normal"}, None, draws, {"tangential_force": 0.04})
    assert sigma[0] == pytest.approx(0.05)
    _, plain = noise_setup(model, priors, {"tangential_force": "normal"}, None, draws)
    assert plain[0] == pytest.approx(0.03)


# ---- raw recordings fitted by mistake -------------------------------------------------------
def _raw(n, rng, step=1e-3, jitter=0.0):
    t = np.arange(n) * step + rng.uniform(0, jitter, n)
    fn = 0.5 + 0.01 * np.sin(2 * np.pi * 3 * t)
    return pd.DataFrame({"time [s]": t, "voltage [V]": np.zeros(n), "normal_force [N]": fn,
                         "tangential_force [N]": MU * fn + rng.normal(0, 0.01, n)})


def test_a_uniform_time_series_is_named_a_raw_recording(rng):
    ds = skinfit.Dataset.from_frame(_raw(1500, rng), model=MODEL)
    message = raw_series(ds)
    assert "1500 rows at a uniform time step of 0.001 s (1000 Hz) in column 'time [s]'" in message
    assert "`skinfit ingest RAW --rig RIG.toml`" in message
    in_ms = _raw(1500, rng).rename(columns={"time [s]": "t [ms]"})
    in_ms["t [ms]"] *= 1e3
    assert raw_series(skinfit.Dataset.from_frame(in_ms, model=MODEL)) is not None


def test_only_long_uniform_series_are_named(rng):
    assert raw_series(skinfit.Dataset.from_frame(_raw(1000, rng), model=MODEL)) is None  # not > 1000 rows
    jittered = _raw(1500, rng, jitter=5e-4)  # stroke start times: not one step
    assert raw_series(skinfit.Dataset.from_frame(jittered, model=MODEL)) is None
    other = _raw(1500, rng).rename(columns={"time [s]": "start_time [s]"})  # per-stroke data name it so
    assert raw_series(skinfit.Dataset.from_frame(other, model=MODEL)) is None


@pytest.mark.parametrize("name", skinfit.list_datasets())
def test_shipped_datasets_are_not_raw_recordings(name):
    assert raw_series(skinfit.load_dataset(name)) is None


def test_fitting_a_raw_recording_warns_before_sampling(rng):
    ds = skinfit.Dataset.from_frame(_raw(1500, rng), model=MODEL)
    with pytest.warns(RawSeriesWarning, match="skinfit ingest RAW --rig RIG.toml") as caught:
        fit = skinfit.fit(MODEL, ds, rng=1, max_steps=300, n_global=64, complete=False)
    assert issubclass(RawSeriesWarning, MisfitWarning)
    assert sum(w.category is RawSeriesWarning for w in caught) == 1
    assert [w["check"] for w in fit.warnings][:1] == ["raw_series"]
    assert "skinfit ingest" in fit.report_text()


def test_serial_correlation_warning_names_ingest():
    record = {"worst_rows": [], "covariates": [], "draws": 400, "alpha": 0.02, "m": 4, "pareto_k": None,
              "trend_means": {}, "group_labels": {},
              "checks": [{"check": "serial[tangential_force, row order]", "statistic": 0.9, "replicated": 0.0,
                          "p": 0.001, "threshold": 0.005, "warn": True}]}
    (message,) = misfit_messages(record)
    assert INGEST_HINT in message["message"]


# ---- the command line: printed, saved, read back ----------------------------------------------
def test_cli_fit_says_so_and_the_saved_fit_keeps_the_standard_errors(tmp_path, capsys):
    frame = _frame(120, np.random.default_rng(7))
    csv = tmp_path / "strokes.csv"
    frame.to_csv(csv, index=False)
    (tmp_path / "flat.toml").write_text(PRIORS)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = main(["fit", MODEL, str(csv), "--priors", str(tmp_path / "flat.toml"), "--out",
                     str(tmp_path / "run"), "--seed", "2", "--quiet"])
    assert code == 0
    out = capsys.readouterr().out
    assert "NOTE: tangential_force: per-row standard errors from the dataset added in quadrature to sigma" in out
    loaded = skinfit.load_fit(tmp_path / "run" / "fit.nc")
    se = frame["tangential_force_se [mN]"].to_numpy() / 1e3
    np.testing.assert_allclose(loaded.posterior.se["tangential_force"], se, rtol=1e-12)
    assert loaded.attr("known_se")["observables"]["tangential_force"]["column"] == "tangential_force_se"


def test_cli_refuses_a_negative_standard_error_in_one_line(tmp_path, refused):
    frame = _frame(12, np.random.default_rng(1))
    frame.loc[4, "tangential_force_se [mN]"] = -1.0
    frame.to_csv(tmp_path / "strokes.csv", index=False)
    refused(["fit", MODEL, str(tmp_path / "strokes.csv"), "--out", str(tmp_path / "run")],
            tmp_path / "strokes.csv",
            "column 'tangential_force_se [mN]', row 5: expected a force >= 0 (got -1 mN; declare `signed = true` "
            "if negative values are meaningful)")
