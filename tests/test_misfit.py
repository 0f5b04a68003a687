"""Issue 21, class 8: a fit checks its own fit to the data (skinfit.inference.misfit) and says so in its
report text, its saved file and the HTML report; two runs of one model on one dataset are told
apart by their options in compare and report.  Issue 39 point 3: the check looks at every
column of the dataset and at the order of the rows, not only at the model's covariates."""

import importlib
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from recordings import power_law_recording

import skinfit
from skinfit.analysis.misfit import simulated_check
from skinfit.inference.misfit import ALPHA, MisfitWarning, check_fit
from skinfit.posterior import Posterior
from skinfit.report.checks import fit_diagnostics
from skinfit.report.html import _as_fits
from skinfit.results.run_labels import run_labels

#: electroadhesion_coulomb parameters for the issue's case (mu, E_star, d_air, sigma), near
#: the shipped electroadhesion data's: friction 0.6, 35 kPa, 0.19 um air gap, 20 mN noise
TRUTH = np.array([0.6, 35e3, 0.19e-6, 0.02])


def _coulomb_data(seed, contaminate):
    """Data simulated from electroadhesion_coulomb at the shipped electroadhesion design (216
    rows); with ``contaminate``, 26 rows multiplied by factors uniform in 3-6 (the issue's case)."""
    ds = skinfit.load_dataset("electroadhesion_synthetic")
    model = skinfit.load_model("electroadhesion_coulomb")
    post = Posterior(model, skinfit.load_priors(model.id), ds)
    rng = np.random.default_rng(seed)
    y = post.simulate(TRUTH[None], rng)["tangential_force"][0]
    if contaminate:
        rows = rng.choice(len(y), size=26, replace=False)
        y[rows] *= rng.uniform(3.0, 6.0, size=26)
    return ds.with_observations({"tangential_force": y}, f"coulomb seed {seed} contaminated {contaminate}")


def _misfits(fit):
    return [w for w in fit.warnings if w["check"] == "misfit"]


def test_class8_contaminated_coulomb_data_warns_in_text_file_and_report(tmp_path):
    fit = skinfit.fit("electroadhesion_coulomb", _coulomb_data(3, True), rng=2, complete=False)
    assert fit.pending and "checked when the pointwise draws are computed" in fit.report_text()
    with pytest.warns(MisfitWarning, match=r"evidence of misfit \(posterior-predictive p"):
        fit.complete()
    found = _misfits(fit)
    record = fit.attr("misfit")
    # the inflated noise hides single rows, but the tails and the overall scatter do not
    assert {"tail_count", "chi_square"} <= {c["check"] for c in record["checks"] if c["warn"]}
    assert record["pareto_k"]["count"] >= 20  # most of the 26 multiplied rows are influential
    text = fit.report_text()
    assert "fit to the data: evidence of MISFIT" in text
    assert text.count("WARN: evidence of") == len(found)
    assert [w for w in fit.summary().attrs["warnings"] if w["check"] == "misfit"] == found
    saved = skinfit.load_fit(fit.save(tmp_path / "fit.nc"))
    assert _misfits(saved) == found
    _, issues = fit_diagnostics(saved)
    assert sum(m.startswith("evidence of") for _, m in issues) == len(found)


def test_class8_data_simulated_from_the_model_does_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error", MisfitWarning)
        fit = skinfit.fit("electroadhesion_coulomb", _coulomb_data(3, False), rng=2)
    record = fit.attr("misfit")
    assert _misfits(fit) == []
    assert min(c["p"] for c in record["checks"]) > ALPHA / record["m"]
    assert record["pareto_k"]["count"] == 0
    assert "fit to the data: no misfit found" in fit.report_text()


def test_class8_competing_variant_on_electroadhesion_data_warns():
    """The shipped data come from the electroadhesion model (sliding-area reduction): the
    Coulomb competitor leaves residuals that fall with the normal force."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = skinfit.fit("electroadhesion_coulomb", "electroadhesion_synthetic", rng=1).complete()
    failed = {c["check"] for c in fit.attr("misfit")["checks"] if c["warn"]}
    assert "trend[tangential_force, normal_force]" in failed
    means = fit.attr("misfit")["trend_means"]["trend[tangential_force, normal_force]"]
    assert means[0] > 0.3 and means[-1] < -0.3  # the drift the message shows


def test_class8_strict_cli_fails_on_a_misfit(tmp_path, capsys):
    from skinfit.apps.cli import main

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = main(["fit", "electroadhesion_coulomb", "electroadhesion_synthetic", "--out", str(tmp_path / "r"),
                     "--seed", "1", "--quiet", "--strict"])
    assert code == 3
    assert "WARN: evidence of misfit (posterior-predictive p" in capsys.readouterr().out


def test_class8_two_runs_of_one_model_told_apart_by_their_options(ea_fit):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        other = skinfit.fit("electroadhesion", "electroadhesion_synthetic", rng=2)
        coulomb = skinfit.fit("electroadhesion_coulomb", "electroadhesion_synthetic", rng=1)
    labels = run_labels([ea_fit, other, coulomb])
    assert labels == ["electroadhesion [seed 1]", "electroadhesion [seed 2]", "electroadhesion_coulomb"]
    keys = [k for k, _ in _as_fits([ea_fit, other])]
    assert len(set(keys)) == 2 and "seed_1" in keys[0] and "seed_2" in keys[1]
    table = skinfit.compare([ea_fit, other, coulomb])
    assert sorted(table.index) == sorted(labels)


@pytest.mark.slow
def test_cry_wolf_strict_rejects_at_most_5_percent_of_105_well_specified_fits():
    """7 simulated data sets per shipped model card (15 cards), each fitted with its own model:
    at most 5% carry any warning --strict acts on (misfit, bound, convergence, acceptance,
    stuck walkers); bench/results/misfit.md has 34 per card and the rates per family."""
    shipped = sorted(p.stem for p in (Path(skinfit.__file__).resolve().parents[1] / "models").glob("*.toml"))
    results = [simulated_check(model, 7_000 + 100 * i + j) for i, model in enumerate(shipped) for j in range(7)]
    assert len(results) == 105
    rejected = [r for r in results if r["strict"]]
    assert len(rejected) / len(results) <= 0.05, rejected


@pytest.mark.parametrize("warned, code", [(0, 0), (1, 3)])
def test_class8_strict_by_runs_fail_on_a_warned_group(tmp_path, monkeypatch, warned, code):
    """``--by`` with ``--strict`` exits 3 when a converged group warned, as a single fit does."""
    import pandas as pd

    command = importlib.import_module("skinfit.apps.cli.fit")
    index = pd.DataFrame({"group": ["a", "b"], "rows": [5, 5], "seed": [1, 2], "converged": [True, True],
                          "warnings": [0, warned], "seconds": [0.1, 0.1], "path": ["a/fit.nc", "b/fit.nc"],
                          "status": ["done", "done"]})
    monkeypatch.setattr(command, "fit_by", lambda *a, **k: index)
    from skinfit.apps.cli import main

    argv = ["fit", "electroadhesion", "electroadhesion_synthetic", "--out", str(tmp_path), "--by", "subject", "--strict"]
    assert main(argv) == code


# ---- issue 39 point 3: the check was blind to what the model does not use ------------------------
#: electroadhesion_coulomb parameters whose voltage effect the empirical power law (no voltage
#: input) absorbs into its noise scale (8x the truth) without a trend along normal force
COULOMB_WEAK = np.array([0.6, 35e3, 6.5e-6, 0.02])
QUICK = {"ess_target": 100, "n_global": 300}  # fit settings of these tests (a few seconds a fit)


def _voltage_data(seed, as_category=False):
    """Data simulated from electroadhesion_coulomb at COULOMB_WEAK on the shipped design (9
    voltages x 12 normal forces x 2 repeats), as a DataFrame; voltage a quantity or a category."""
    ds = skinfit.load_dataset("electroadhesion_synthetic")
    model = skinfit.load_model("electroadhesion_coulomb")
    post = Posterior(model, skinfit.load_priors(model.id), ds)
    y = post.simulate(COULOMB_WEAK[None], np.random.default_rng(seed))["tangential_force"][0]
    volts = ds.frame["voltage"].to_numpy()
    voltage = {"voltage": [f"{v:.0f} V" for v in volts]} if as_category else {"voltage [V]": volts}
    return pd.DataFrame(voltage | {"normal_force [N]": ds.frame["normal_force"].to_numpy(), "tangential_force [N]": y})


def _series(seed, n=500, phi=0.9, shuffle=False, session=False):
    """A raw 1 kHz recording fitted as rows: normal force fluctuating row to row around 1 N,
    tangential force from the empirical power law (b 0.3, c 0.67, d 0.3) plus AR(1) noise with
    lag-1 correlation ``phi`` and sd 20 mN; rows shuffled on request, an unused random
    category column ``session`` on request."""
    rng = np.random.default_rng(seed)
    t, fn, ft = power_law_recording(rng, n, phi)
    df = pd.DataFrame({"time [s]": t, "normal_force [N]": fn, "tangential_force [N]": ft})
    if session:
        df["session"] = rng.choice(["a", "b", "c", "d"], size=n)
    return df.sample(frac=1, random_state=seed).reset_index(drop=True) if shuffle else df


def _complete(model, data, seed):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return skinfit.fit(model, data, rng=seed, **QUICK).complete()


def _failed(fit):
    return {c["check"] for c in fit.attr("misfit")["checks"] if c["warn"]}


def test_misfit_blind_to_unused_column_voltage_trend_warns():
    """The issue's case: the power law fitted to data taken at 9 voltages.  Its noise scale
    absorbs the voltage effect (sigma 8x the truth); the residuals drift with the voltage column
    the model does not use (the old check looked at normal force only: 'no misfit found')."""
    fit = _complete("electroadhesion_empirical", _voltage_data(1), 1)
    assert fit.summary().loc["sigma", "mean"] > 5 * COULOMB_WEAK[3]
    assert "trend[tangential_force, voltage]" in _failed(fit)
    means = fit.attr("misfit")["trend_means"]["trend[tangential_force, voltage]"]
    assert means[0] < -0.5 and means[-1] > 1.0  # the force rises with the voltage, the fit does not
    message = next(w["message"] for w in _misfits(fit) if "voltage" in w["message"])
    assert "a column the model does not use" in message and "evidence of misfit (posterior-predictive p" in message
    assert "fit to the data: evidence of MISFIT" in fit.report_text()


def test_misfit_blind_to_unused_column_category_levels_warn():
    """The same data with the voltage as a category ('25 V'): the residual means differ between
    its levels (sum over levels of n_g mean_g(r)^2 against the replicates')."""
    fit = _complete("electroadhesion_empirical", _voltage_data(1, as_category=True), 1)
    assert "levels[tangential_force, voltage]" in _failed(fit)
    message = next(w["message"] for w in _misfits(fit) if "levels of voltage" in w["message"])
    assert "200 V +" in message and "0 V -" in message  # the levels named, with their mean residuals


def test_misfit_blind_to_autocorrelation_row_order_warns():
    """A raw 1 kHz series (AR(1) noise, lag-1 correlation 0.9) fitted as independent rows: the
    residuals' lag-1 autocorrelation in row order is far above the replicates' (~0)."""
    fit = _complete("electroadhesion_empirical", _series(1), 1)
    assert "serial[tangential_force, row order]" in _failed(fit)
    serial = next(c for c in fit.attr("misfit")["checks"] if c["check"] == "serial[tangential_force, row order]")
    assert serial["statistic"] > 0.7 and abs(serial["replicated"]) < 0.1
    assert any("not independent measurements" in w["message"] for w in _misfits(fit))


def test_misfit_blind_to_autocorrelation_time_order_warns():
    """The same series with its rows shuffled: no correlation in row order, but in the order of
    the time column (a unit of time) the residuals are correlated."""
    fit = _complete("electroadhesion_empirical", _series(1, shuffle=True), 1)
    failed = _failed(fit)
    assert "serial[tangential_force, time order]" in failed
    assert "serial[tangential_force, row order]" not in failed


def test_misfit_blind_to_unused_columns_well_specified_does_not_warn():
    """Independent noise, the model that made the data, a time column and an unused random
    category column: the extra checks (trend with time, levels of session, serial in row order)
    run and none warns."""
    fit = _complete("electroadhesion_empirical", _series(1, phi=0.0, session=True), 1)
    names = {c["check"] for c in fit.attr("misfit")["checks"]}
    assert {"trend[tangential_force, time]", "levels[tangential_force, session]",
            "serial[tangential_force, row order]"} <= names
    assert _misfits(fit) == [] and "no misfit found" in fit.report_text()


def test_misfit_trend_bins_with_a_heavily_tied_value_stay_finite():
    """A covariate whose one value holds more than a bin's share of the rows (half the rows at
    0.2 N, 12 values in all) left an empty rank bin: 0/0 in the statistic, p = 0 and a misfit
    on any data."""
    ds = skinfit.load_dataset("electroadhesion_synthetic")
    frame = ds.frame.copy()
    frame.loc[frame.index < len(frame) // 2, "normal_force"] = 0.2
    ds = skinfit.Dataset.from_frame(frame, units={"voltage": "V", "normal_force": "N", "tangential_force": "N"})
    model = skinfit.load_model("electroadhesion_coulomb")
    post = Posterior(model, skinfit.load_priors(model.id), ds)
    rng = np.random.default_rng(1)
    truth = np.array([0.6, 35e3, 3e-6, 0.02])
    y = post.simulate(truth[None], rng)["tangential_force"][0]
    post = Posterior(model, skinfit.load_priors(model.id), ds.with_observations({"tangential_force": y}, "sim"))
    theta = np.repeat(truth[None], 400, axis=0)  # the truth as the posterior: every check is exact
    record = check_fit(post, theta, post.simulate(theta, rng))
    trend = next(c for c in record["checks"] if c["check"] == "trend[tangential_force, normal_force]")
    assert np.isfinite(trend["statistic"]) and not trend["warn"]
