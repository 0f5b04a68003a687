"""The report on many fits of one model: subjects labelled as written, the population with
shrunk beside separate estimates, contrasts with their probability of direction, conditions
named in parameter rows, and a word when evidence and LOO disagree."""

import html as html_text
import json
import re
import warnings

import numpy as np
import pandas as pd
import pytest

import skinfit
from skinfit.io.units import pretty_unit
from skinfit.report import html as report
from skinfit.report.groups import contrast_section, group_analyses, subject_label
from skinfit.report.tables import level_names, ranking_note

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
    # cells without a value by construction read n/a, and only those: the population's mean, sd
    # and median rows have no R-hat or ESS of their own (mu's and tau's are on their rows), a
    # derived quantity (gamma, p) no MAP, tau or contraction; no other cell is nan
    from test_report import _frame, _parse

    page = _parse(index)
    diag = ["r_hat", "ess_bulk", "ess_tail"]
    (hyper,) = [_frame(t) for (kind, _), t in page.tables.items() if kind == "population"]
    derived_rows = hyper["quantity"].isin(["mean", "sd", "median"])
    assert derived_rows.any() and (~derived_rows).any()
    assert (hyper.loc[derived_rows.to_numpy(), diag] == "n/a").all().all()
    assert not hyper.loc[(~derived_rows).to_numpy(), diag].isin(["n/a", "nan"]).any().any()
    # each population row names its unit as a physicist writes it; mu of a log coordinate: ln(unit)
    from test_report_numbers import ascii_units

    (raw,) = [t for (kind, _), t in page.tables.items() if kind == "population"]
    assert "unit" in raw["rows"][0] and ascii_units([raw]) == []
    a0 = hyper.loc["alpha_a0"].set_index("quantity")["unit"]
    assert a0["median"] == "m²/Nm" and a0["mu"] == "ln(m²/Nm)" and a0["tau"] == "-"  # the cells' text
    assert "ln(m²/N<sup>m</sup>)" in html  # the exponent set as one
    summaries = [_frame(t) for (kind, _), t in page.tables.items() if kind == "summary"]
    assert len(summaries) == len(SUBJECTS)
    for table in summaries:
        derived = table["note"].str.startswith("derived").to_numpy()
        assert derived.any() and (~derived).any()
        assert (table.loc[derived, ["map", "tau", "contraction"]] == "n/a").all().all()
        # a derived quantity's unit in the unit column, as its note and the card state it
        card_units = json.loads(next(iter(subject_fits.values())).attrs["derived"])["quantities"]
        assert [re.sub("<[^>]+>", "", pretty_unit(card_units[n.split("[")[0]], html=True))
                for n in table.index[derived]] == list(table.loc[derived, "unit"])
        assert (table.loc[derived, "note"] == "derived").all()  # its unit in the unit column, written once
        assert not table.loc[derived, diag + ["mean"]].isin(["n/a", "nan"]).any().any()
        assert not table.loc[~derived].isin(["n/a", "nan"]).any().any()
    # a ratio A / B where B's draws change sign (m1, a slope about 0) is undefined, its CSV cell
    # empty: the effect shown is the difference
    (key, shown_contrasts), = [(k, _frame(t)) for k, t in page.tables.items() if k[0] == "contrasts"]
    csv = pd.read_csv(tmp_path / "r" / key[1])
    undefined = csv["ratio_median"].isna().to_numpy()
    assert undefined.any() and (~undefined).any()
    assert (csv.loc[undefined, "effect"] == "difference").all()
    assert list(shown_contrasts["effect"]) == list(csv["effect"].head(len(shown_contrasts)))
    nans = [(k, row) for k, t in page.tables.items() for row in t["rows"] if "nan" in row]
    assert not nans, nans[:3]


def test_a_parameter_indexed_by_a_condition_names_it(subject_fits):
    names = level_names(subject_fits["S01"])
    assert names["gamma[0]"] == "gamma[actuation_force=0 N]"
    assert names["gamma[30]"] == "gamma[actuation_force=30 N]"


def test_the_report_says_when_evidence_and_loo_rank_models_differently():
    agree = pd.DataFrame({"model": ["a", "b"], "log_z": [-1.0, -5.0], "elpd_loo": [3.0, 1.0]})
    assert ranking_note(agree) is None
    disagree = pd.DataFrame({"model": ["a", "b"], "log_z": [-1.0, -5.0], "elpd_loo": [1.0, 3.0]})
    note = ranking_note(disagree)
    assert "by log Z a > b" in note and "by ELPD (LOO) b > a" in note and "prior" in note


def test_population_band_is_where_94_percent_of_subjects_lie():
    """Log-normal population exp(Normal(mu, tau)): median exp(mu), 94% range exp(mu -+ 1.881 tau)."""
    from skinfit.report.groups import PopulationView

    class Result:
        parameters, subjects = ["E"], ["S01"]

        def summary(self, prob=0.94):
            return pd.DataFrame([{"parameter": "E", "quantity": "mu", "estimate": np.log(2e4), "lower": 0.0,
                                  "upper": 0.0, "coordinate": "log"},
                                 {"parameter": "E", "quantity": "tau", "estimate": 0.5, "lower": 0.0,
                                  "upper": 0.0, "coordinate": "log"}])

    band = PopulationView(Result()).population_interval("E")
    from scipy import stats

    lo, hi = stats.lognorm(0.5, scale=2e4).ppf([0.03, 0.97])
    assert band["median"] == pytest.approx(2e4)
    assert band["lo"] == pytest.approx(lo, rel=1e-3) and band["hi"] == pytest.approx(hi, rel=1e-3)


def test_a_report_section_computes_the_population_summary_once():
    """The hyper-parameters' summary (with R-hat and ESS of each, ~50 ms) is read per parameter
    by the report: computed once per section, each parameter's band still its own."""
    from skinfit.report.groups import population_section

    class Result:
        parameters, subjects, calls = ["E", "F", "G"], ["S01"], 0

        def summary(self, prob=0.94):
            Result.calls += 1
            return pd.DataFrame([{"parameter": p, "quantity": q, "estimate": v, "lower": 0.0, "upper": 0.0,
                                  "coordinate": "log"}
                                 for p, mu in zip(self.parameters, (1e3, 2e4, 3e5))
                                 for q, v in (("mu", np.log(mu)), ("tau", 0.5))])

        def subject_summary(self, prob=0.94):
            return pd.DataFrame([{"parameter": p, "subject": "S01", "estimate": 1.0} for p in self.parameters])

    section = population_section(Result())
    assert Result.calls == 1
    assert [section["intervals"][p]["median"] for p in "EFG"] == pytest.approx([1e3, 2e4, 3e5])


def _by_run(fits, folder):
    """``fits`` {subject: Fit} saved as a ``skinfit fit --by subject`` run directory."""
    folder.mkdir(parents=True)
    groups = []
    for s, f in fits.items():
        f.save(folder / s / "fit.nc")
        groups.append({"group": f"subject={s}", "path": f"{s}/fit.nc"})
    (folder / "index.json").write_text(json.dumps({"model": "contact_area", "dataset": "contact_area_synthetic",
                                                   "by": ["subject"], "groups": groups}))
    return folder


def _population_note(index):
    html = index.read_text()
    start = html.index('data-note="population-origin">') + len('data-note="population-origin">')
    return re.sub(r"<[^>]+>", "", html[start:html.index("</p>", start)]), html


def test_report_of_a_run_shows_the_population_saved_for_its_fits_and_never_another(subject_fits, tmp_path,
                                                                                    no_figures, capsys):
    """`skinfit population RUN` (the user's choices: two parameters, correlated) then `skinfit
    report RUN`: the report shows that population, saying where it is from; once a subject is
    fitted again, the saved one is named as made from other fits and not shown."""
    from skinfit.analysis.population.result import load_population
    from skinfit.apps.cli import main

    run = _by_run(subject_fits, tmp_path / "run")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["population", str(run), "--params", "m0,n_z0", "--correlated", "--seed", "3"]) == 0
        assert main(["report", str(run), "--out", str(tmp_path / "r1")]) == 0
    saved = load_population(run / "population" / "population.nc")
    assert saved.parameters == ["m0", "n_z0"] and saved.corr is not None and saved.sampler["seed"] == 3
    shown = pd.read_csv(tmp_path / "r1" / "population_contact_area.csv")
    assert sorted(set(shown["parameter"])) == ["m0", "m0,n_z0", "n_z0"]  # the user's two, and their correlation
    np.testing.assert_allclose(shown["estimate"], saved.summary()["estimate"])
    note, html = _population_note(tmp_path / "r1" / "index.html")
    assert f"From {run / 'population' / 'population.nc'}" in note and "Correlated population" in note
    assert "seed 3" in note and "{'" not in html  # the sampler record read as a sentence, not a dict
    assert 'data-table="hyperpriors"' in html and "half-t(nu=2" in html

    # S02 fitted again (another seed): the saved population is of other fits
    again = skinfit.fit("contact_area", subject_fits["S02"].posterior.dataset, rng=99, max_steps=600,
                        ess_target=100, n_global=300)
    again.save(run / "S02" / "fit.nc")
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["report", str(run), "--out", str(tmp_path / "r2")]) == 0
    err = capsys.readouterr().err
    assert f"the population saved in {run / 'population' / 'population.nc'} is not shown" in err
    assert "3 subjects' fits, 2 of them among the 3 here" in err
    note, html = _population_note(tmp_path / "r2" / "index.html")
    assert note.startswith("Computed for this report") and "is not shown: it was made from other" in html
    shown = pd.read_csv(tmp_path / "r2" / "population_contact_area.csv")
    assert sorted(set(shown["parameter"])) == sorted(["alpha_a0", "alpha_a1", "m0", "m1", "beta_z0", "beta_z1",
                                                      "n_z0", "n_z1"])


def test_a_report_population_has_every_parameter_but_the_noise_scales(subject_fits):
    """contact_area (Huloux, Willemet & Wiertlewski): alpha_a, m, beta_z, n_z, each with a slope
    in the actuation force, and two noise scales that stay per subject."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        populations, _ = group_analyses(dict(subject_fits))
    assert populations["contact_area"].parameters == ["alpha_a0", "alpha_a1", "m0", "m1", "beta_z0", "beta_z1",
                                                      "n_z0", "n_z1"]


def test_the_population_sampler_and_hyper_priors_read_as_text_and_a_table():
    from skinfit.report.groups import hyperprior_table, sampler_text

    gibbs = {"method": "gibbs (Metropolis-within-Gibbs)", "chains": 8, "sweeps": 2442, "burn": 300, "thin": 3,
             "converged": True, "checks": [{"sweeps": 400, "ess_bulk": 66.4}], "acceptance": {"a": 0.613, "b": 0.587},
             "scale_acceptance": 0.1993, "rhat_max": 1.009539, "ess_min": 511.9, "seed": 7}
    assert sampler_text(gibbs) == ("gibbs (Metropolis-within-Gibbs), 8 chains, 2442 sweeps (burn-in 300, thinned by "
                                   "3); converged (max R-hat 1.0095, min ESS 512); acceptance per subject 0.59-0.61, "
                                   "of the scale moves 0.20; seed 7.")
    reweight = {"method": "reweight", "converged": False, "n_steps": 900, "draws_per_subject": 500,
                "importance_ess": {"a": 120.0, "b": 80.4}}
    assert sampler_text(reweight) == ("reweight, 900 steps, 500 draws a subject; NOT converged; importance ESS per "
                                      "subject 80.40-120.00.")
    table = hyperprior_table({"E": {"family": "student_t", "coordinate": "log", "mu": "normal(loc=1, scale=2)",
                                    "sd": "half-t(nu=2, scale=1)", "from": "prior file x: ...", "nu": 4},
                              "m": {"family": "normal", "coordinate": "natural", "mu": "normal(loc=0, scale=1)",
                                    "sd": "half-t(nu=2, scale=0.5)", "from": "prior file x: ..."}})
    assert list(table.columns) == ["family", "coordinate", "prior of mu", "prior of tau", "derived from", "nu"]
    assert table.loc["m", "nu"] == "" and table.loc["E", "prior of tau"] == "half-t(nu=2, scale=1)"


def test_a_saved_population_that_does_not_record_its_fits_is_named_not_shown(subject_fits):
    from dataclasses import replace

    from skinfit.analysis.population.population import population

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mine = population(subject_fits, ["m0"], rng=1)
        assert len(mine.inputs) == 3
        populations, _ = group_analyses(dict(subject_fits), saved=[replace(mine, origin="mine.nc")])
        shown = populations["contact_area"]
        assert shown.origin == "mine.nc" and shown.parameters == ["m0"]  # the saved one, not one computed
        np.testing.assert_array_equal(shown.mu, mine.mu)
        older = replace(mine, inputs={}, origin="old/population.nc")
        populations, _ = group_analyses(dict(subject_fits), saved=[older])
    shown = populations["contact_area"]
    assert len(shown.parameters) == 8 and shown.origin == ""
    assert any("old/population.nc is not shown" in w and "written by an older skinfit" in w for w in shown.warnings)


def test_subjects_of_two_datasets_make_one_population_and_a_subject_twice_none(subject_fits):
    """A model's subjects on two datasets are pooled, labelled dataset/subject (as `skinfit
    population` labels a campaign's), never one dataset's population shown for both; the
    same subject passed twice would count as two subjects: no population, and it is said."""
    def relabelled(f, dataset_id):
        tree = f.partial_tree.copy()
        tree.attrs["dataset_id"] = dataset_id
        return skinfit.Fit(tree)

    two = dict(subject_fits) | {f"lab2-{s}": relabelled(f, f"lab2[subject={s}]") for s, f in subject_fits.items()}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        populations, contrasts = group_analyses(two)
        assert populations["contact_area"].subjects == [*(f"contact_area_synthetic/{s}" for s in SUBJECTS),
                                                        *(f"lab2/{s}" for s in SUBJECTS)]
        assert "contact_area on contact_area_synthetic, lab2: between subjects" in contrasts
        said = []
        populations, contrasts = group_analyses(dict(subject_fits) | {"again": subject_fits["S01"]}, echo=said.append)
    assert populations == {} and not any("between subjects" in k for k in contrasts)
    assert said == ["skinfit report: no population or contrasts between subjects for contact_area: fitted more than "
                    "once: S01 (report keys S01 and again)"]


def test_tables_whose_names_differ_only_in_letters_a_file_name_cannot_hold_get_their_own_files(subject_fits,
                                                                                               tmp_path):
    """Two contrast tables titled by subjects Zoë and Zoé (file_part makes both Zo_): each is
    written to its own CSV, linked from its own section, holding its own rows; nothing is
    overwritten."""
    from test_report import _parse

    from skinfit.analysis.contrasts import contrast

    rng = np.random.default_rng(3)

    def table(shift):
        rows = [{"A": "0 N", "B": "5 N", **contrast(rng.normal(shift, 1, 500), rng.normal(0, 1, 500))}]
        return pd.DataFrame(rows).assign(parameter="alpha")

    names = [f"contact_area on d[subject={s}]: between conditions" for s in ("Zoë", "Zoé")]
    tables = dict(zip(names, (table(1.0), table(-1.0))))
    index = report.write_report(list(subject_fits.values())[:1], tmp_path / "r", contrasts=tables)
    page = _parse(index)
    files = [key[1] for key in page.tables if key[0] == "contrasts"]
    assert len(files) == 2 and len(set(files)) == 2
    for name, file in zip(names, files):
        assert (tmp_path / "r" / file).exists() and file in page.links
        written = pd.read_csv(tmp_path / "r" / file)
        assert written["diff_mean"].iloc[0] == pytest.approx(tables[name]["diff_mean"].iloc[0], rel=1e-12)
    assert pd.read_csv(tmp_path / "r" / files[0])["diff_mean"].iloc[0] > 0 > \
        pd.read_csv(tmp_path / "r" / files[1])["diff_mean"].iloc[0]


def test_fits_given_by_names_a_file_name_cannot_tell_apart_get_their_own_keys(subject_fits):
    """Fits given as a mapping whose names file_part makes alike (Zoë, Zoé; an empty name) get
    one key each, by the scheme of every other file of a report (base, base_2, ...)."""
    fit = subject_fits["S01"]
    assert [k for k, _ in report._as_fits({"Zoë": fit, "Zoé": fit, "": fit, "Zo_2": fit})] == \
        ["Zo", "Zo_2", "fit", "Zo_2_2"]


# ---- the top of the report: every failed check of every section -----------------------------
def _top(index):
    """The top box of a report: its class and its items as (status, anchor, text)."""
    html = index.read_text()
    box = re.search(r'<section id="diagnostics" class="box (\w+)">(.*?)</section>', html, re.S)
    item = r'<li><span class="tag (\w+)">\w+</span> (?:<a href="#([^"]*)">)?(.*?)</li>'
    items = [(st, anchor, html_text.unescape(re.sub(r"<[^>]+>", "", text)))
             for st, anchor, text in re.findall(item, box.group(2), re.S)]
    return box.group(1), items, html


def _unconverged_population(fits):
    """The population of ``fits`` run for 30 sweeps: it cannot converge (R-hat far above 1.01)."""
    from skinfit.analysis.population.population import population

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return population(fits, rng=1, max_sweeps=30, burn=10, chains=4)


def test_top_of_report_lists_a_population_that_did_not_converge(subject_fits, tmp_path, no_figures):
    """Three converged subjects under a population that did not converge: the top of the page
    says so, with its worst R-hat and ESS and a link to the population, and nowhere that every
    check passed; summary.md says the same."""
    pop = _unconverged_population(subject_fits)
    assert not pop.converged and pop.sampler["rhat_max"] > 1.05
    index = report.write_report(list(subject_fits.values()), tmp_path / "r", populations={"contact_area": pop})
    kind, items, html = _top(index)
    assert kind == "fail" and all(f.converged for f in subject_fits.values())
    (fail,) = [i for i in items if i[0] == "FAIL"]
    assert fail[1] and f'id="{fail[1]}"' in html and "Population" in html[html.index(f'id="{fail[1]}"'):][:200]
    assert "population of contact_area" in fail[2] and "did not converge" in fail[2]
    assert f"max R-hat {pop.sampler['rhat_max']:.3f}" in fail[2] and f"min ESS {pop.sampler['ess_min']:.0f}" in fail[2]
    worst = pop.summary().dropna(subset=["r_hat"]).sort_values("r_hat").iloc[-1]
    assert f"{worst['quantity']} of {worst['parameter']} (R-hat {worst['r_hat']:.3f}" in fail[2]
    assert "passed every check" not in html and "Every check passed" not in html
    md = (tmp_path / "r" / "summary.md").read_text()
    head = md[:md.index("## contact_area across fits")]
    assert "**FAIL** population of contact_area: the population did not converge" in head
    assert f"(index.html#{fail[1]})" in head and "Every check passed" not in md


def test_top_of_report_lists_every_failed_check_of_every_section_kind(subject_fits, tmp_path, no_figures):
    """One report whose every section failed a check: a fit that did not converge, a population
    that did not converge, a comparison that ranks that fit and whose LOO is unreliable, the
    contrasts drawn from it, and a design whose EIG estimates lie below zero. Each is at the
    top, a FAIL or WARN linked to a section the page has, and in summary.md."""
    from dataclasses import replace

    ds = skinfit.load_dataset("contact_area_synthetic")
    sub = ds.subset(ds.frame["subject"].astype(str).to_numpy() == "S04", "subject=S04")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        stuck = skinfit.fit("contact_area", sub, rng=5, max_steps=300, ess_target=1e6, n_global=300)
        fits = dict(subject_fits) | {"S04": stuck}
        _, contrasts = group_analyses(fits)
        design = skinfit.design("electroadhesion", {"grid": {"normal_force": {"unit": "mN", "values": [200, 2000]},
                                                             "voltage": {"unit": "V", "values": [0, 200]}}},
                                n=2, n_outer=60, n_inner=60, rng=1, noise_scale=0.02)
    assert not stuck.converged
    table = design.table.copy()
    table.loc[[0, 1], "eig"] = -1.2  # a design whose estimate failed (as issue 39's from-a-fit design did)
    design = replace(design, table=table)
    comparison = pd.DataFrame({"log_z": [1278.8, 1201.8], "log_z_se": [0.01, 0.01], "pareto_k_gt_0.7": [0, 4],
                               "method": ["bridge", "bridge"], "approximate": [False, False],
                               "converged": [True, False]},
                              index=pd.Index(["contact_area_hertz", "contact_area"], name="model"))
    index = report.write_report(list(fits.values()), tmp_path / "r", populations={"contact_area":
                                _unconverged_population(subject_fits)}, contrasts=contrasts, comparison=comparison,
                                designs=[design])
    kind, items, html = _top(index)
    assert kind == "fail"
    ids = set(re.findall(r'id="([^"]+)"', html))
    assert all(anchor in ids for _, anchor, _ in items)  # every item links to a section of the page
    found = {(st, text.split(":")[0]) for st, _, text in items}
    assert ("FAIL", "contact_area on contact_area_synthetic[subject=S04]") in found  # the fit
    assert ("FAIL", "population of contact_area") in found
    assert ("FAIL", "model comparison") in found  # ranks a fit that did not converge
    text = " ".join(t for _, _, t in items)
    assert "ranks fit(s) that did not converge: contact_area" in text
    assert "PSIS-LOO unreliable (Pareto k > 0.7) for contact_area (4 rows)" in text
    assert "drawn from fit(s) that did not converge: S04" in text  # contrasts between subjects
    assert ("FAIL", "design") in found and "below zero by more than 2 standard errors at 2 of 4 candidates" in text
    md = (tmp_path / "r" / "summary.md").read_text()
    head = md[:md.index("## Model comparison")]
    assert head.count("**FAIL**") + head.count("**WARN**") == len(items)
    assert "Every check passed" not in md and "Every check passed" not in html


def test_top_of_report_says_every_check_passed_only_when_all_did(subject_fits, tmp_path, no_figures):
    """Converged fits, a converged population, contrasts drawn from converged fits, a comparison
    of converged fits with reliable LOO: the top says every check passed, naming what was
    checked; summary.md says the same."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        populations, contrasts = group_analyses(dict(subject_fits))
    assert populations["contact_area"].converged and all(f.converged for f in subject_fits.values())
    comparison = pd.DataFrame({"log_z": [1278.8, 1201.8], "log_z_se": [0.01, 0.01], "pareto_k_gt_0.7": [0, 0],
                               "approximate": [False, False], "converged": [True, True]},
                              index=pd.Index(["contact_area", "contact_area_hertz"], name="model"))
    index = report.write_report(list(subject_fits.values()), tmp_path / "r", populations=populations,
                                contrasts=contrasts, comparison=comparison)
    kind, items, html = _top(index)
    assert (kind, items) == ("ok", [])
    box = html[html.index('<section id="diagnostics"'):html.index("</section>")]
    assert "Every check passed: all 3 fits" in box and "the population of contact_area" in box
    assert "1 model comparison" in box and "contrast table" in box
    assert "Every check passed: all 3 fits" in (tmp_path / "r" / "summary.md").read_text()


# ---- two fits of one model on one dataset: one row each, told apart -------------------------
def test_two_fits_of_one_model_on_one_dataset_keep_their_own_rows(subject_fits, tmp_path, no_figures):
    """S01 fitted twice (seeds 10 and 99) beside S02 and S03: the tables across fits hold a row
    for each fit, labelled by what differs (the seed), each with its own fit's numbers; the
    population, which would count S01 twice, is not made, and the top of the page says why."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again = skinfit.fit("contact_area", subject_fits["S01"].posterior.dataset, rng=99, max_steps=600,
                            ess_target=100, n_global=300)
        populations, contrasts = group_analyses({"a": subject_fits["S01"], "b": again, "c": subject_fits["S02"],
                                                 "d": subject_fits["S03"]}, echo=lambda m: None)
    assert populations == {}
    report.write_report([*subject_fits.values(), again], tmp_path / "r")
    for name in ("m0", "beta_z0"):
        table = pd.read_csv(tmp_path / "r" / f"subjects_contact_area_{name}.csv", index_col="subject")
        assert sorted(table.index) == ["S01 [seed 10]", "S01 [seed 99]", "S02", "S03"]
        assert table.loc["S01 [seed 10]", "mean"] == pytest.approx(subject_fits["S01"].summary().loc[name, "mean"])
        assert table.loc["S01 [seed 99]", "mean"] == pytest.approx(again.summary().loc[name, "mean"])
    index = report.write_report([*subject_fits.values(), again], tmp_path / "r",
                                notes=[("analyses across fits", "S01 fitted more than once")])
    kind, items, _ = _top(index)
    assert ("WARN", "", "analyses across fits: S01 fitted more than once") in items


def test_fits_with_the_same_options_are_told_apart_by_their_file_then_their_content(subject_fits, tmp_path):
    """Two files of one fit's content: labelled by the shortest part of their paths that differs;
    two fits in memory with the same options but other draws (another ESS target): by their
    content's sha256; the same fit twice: numbered."""
    from skinfit.analysis.compare import compare
    from skinfit.results.run_labels import run_labels

    fit = subject_fits["S01"]
    for folder in ("a", "b"):
        fit.save(tmp_path / folder / "run" / "fit.nc")
    loaded = [skinfit.load_fit(tmp_path / folder / "run" / "fit.nc") for folder in ("a", "b")]
    assert run_labels(loaded) == ["contact_area [file a/run/fit.nc]", "contact_area [file b/run/fit.nc]"]
    keys = [k for k, _ in report._as_fits(loaded)]
    assert len(set(keys)) == 2 and "a_run" in keys[0] and "b_run" in keys[1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        longer = skinfit.fit("contact_area", fit.posterior.dataset, rng=10, max_steps=600, ess_target=300,
                             n_global=300)
    assert json.loads(longer.attrs["setup"]) == json.loads(fit.attrs["setup"]) and longer.attrs["seed"] == 10
    hashes = [fit.content_hash(), longer.content_hash()]
    assert run_labels([fit, longer]) == [f"contact_area [content {h[:8]}]" for h in hashes]
    assert run_labels([fit, fit]) == ["contact_area", "contact_area #2"]
    assert list(compare({"mine": fit, "theirs": longer}).index) in (["mine", "theirs"], ["theirs", "mine"])


def test_two_split_fits_of_one_dataset_keep_their_own_contrasts(tmp_path):
    """Two fits of electroadhesion with alpha split by voltage, differing in their seed: the
    contrasts between voltages of each are their own table, titled by the seed (one title for
    both had kept only the second)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        split = skinfit.fit("electroadhesion", "electroadhesion_synthetic", split={"alpha": "voltage"}, rng=1,
                            max_steps=300, n_global=300)
    tree = split.partial_tree.copy()
    tree.attrs["seed"] = 2
    other = skinfit.Fit(tree)
    _, contrasts = group_analyses({"one": split, "two": other})
    titles = [t for t in contrasts if "between conditions" in t]
    assert titles == ["electroadhesion [seed 1] on electroadhesion_synthetic: between conditions",
                      "electroadhesion [seed 2] on electroadhesion_synthetic: between conditions"]
