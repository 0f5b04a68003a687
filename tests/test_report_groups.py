"""The report on many fits of one model: subjects labelled as written, the population with
shrunk beside separate estimates, contrasts with their probability of direction, conditions
named in parameter rows, and a word when evidence and LOO disagree."""

import warnings

import numpy as np
import pandas as pd
import pytest

import skinfit
from skinfit import report
from skinfit.report_groups import contrast_section, group_analyses, subject_label

SUBJECTS = ("S01", "S02", "S03")


@pytest.fixture(scope="module")
def subject_fits():
    ds = skinfit.load_dataset("contact_area_synthetic")
    fits = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for k, s in enumerate(SUBJECTS):
            sub = ds.subset(ds.frame["subject"].astype(str).to_numpy() == s, f"subject={s}")
            fits[s] = skinfit.fit("contact_area", sub, rng=10 + k, max_steps=600, ess_target=100, n_global=300)
    return fits


def test_subject_label_is_the_value_the_user_wrote(subject_fits):
    assert [subject_label(f) for f in subject_fits.values()] == list(SUBJECTS)


def test_report_on_subjects_shows_tables_population_and_contrasts(subject_fits, tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        populations, contrasts = group_analyses({f"k{i}": f for i, f in enumerate(subject_fits.values())})
    assert list(populations) == ["contact_area"]
    (between,) = [v for k, v in contrasts.items() if "between subjects" in k]
    index = report.write_report(list(subject_fits.values()), tmp_path / "r", populations=populations,
                                contrasts=contrasts)
    html = index.read_text()
    # per-subject table of a parameter: one row per subject, the summary's numbers
    table = pd.read_csv(tmp_path / "r" / "subjects_contact_area_alpha_a0.csv", index_col="subject")
    assert list(table.index) == list(SUBJECTS)
    for s, f in subject_fits.items():
        assert table.loc[s, "mean"] == pytest.approx(f.summary().loc["alpha_a0", "mean"])
    assert 'data-table="subjects"' in html and 'data-table="population"' in html and 'data-table="shrunk"' in html
    # population: the hyper-parameter table holds the population result's own summary
    pop = pd.read_csv(tmp_path / "r" / "population_contact_area.csv")
    expected = populations["contact_area"].summary()
    np.testing.assert_allclose(pop["estimate"], expected["estimate"])
    # contrasts: probability of direction = max(P(A > B), 1 - P(A > B)), from the draws
    shown = contrast_section(between)
    assert (shown["prob_direction"] >= 0.5).all()
    row = shown[(shown["A"] == "S01") & (shown["B"] == "S02") & (shown["parameter"] == "alpha_a0")].iloc[0]
    assert row["prob_direction"] == pytest.approx(max(row["p_greater"], 1 - row["p_greater"]))
    assert "Contrasts: contact_area on contact_area_synthetic: between subjects" in html


def test_a_parameter_indexed_by_a_condition_names_it(subject_fits):
    names = report.level_names(subject_fits["S01"])
    assert names["gamma[0]"] == "gamma[actuation_force=0 N]"
    assert names["gamma[30]"] == "gamma[actuation_force=30 N]"


def test_the_report_says_when_evidence_and_loo_rank_models_differently():
    agree = pd.DataFrame({"model": ["a", "b"], "log_z": [-1.0, -5.0], "elpd_loo": [3.0, 1.0]})
    assert report.ranking_note(agree) is None
    disagree = pd.DataFrame({"model": ["a", "b"], "log_z": [-1.0, -5.0], "elpd_loo": [1.0, 3.0]})
    note = report.ranking_note(disagree)
    assert "by log Z a > b" in note and "by ELPD (LOO) b > a" in note and "prior" in note


def test_population_band_is_where_94_percent_of_subjects_lie():
    """Log-normal population exp(Normal(mu, tau)): median exp(mu), 94% range exp(mu -+ 1.881 tau)."""
    from skinfit.report_groups import PopulationView

    class Result:
        parameters, subjects = ["E"], ["S01"]

        def summary(self):
            return pd.DataFrame([{"parameter": "E", "quantity": "mu", "estimate": np.log(2e4), "lower": 0.0,
                                  "upper": 0.0, "coordinate": "log"},
                                 {"parameter": "E", "quantity": "tau", "estimate": 0.5, "lower": 0.0,
                                  "upper": 0.0, "coordinate": "log"}])

    band = PopulationView(Result()).population_interval("E")
    from scipy import stats

    lo, hi = stats.lognorm(0.5, scale=2e4).ppf([0.03, 0.97])
    assert band["median"] == pytest.approx(2e4)
    assert band["lo"] == pytest.approx(lo, rel=1e-3) and band["hi"] == pytest.approx(hi, rel=1e-3)
