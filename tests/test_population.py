"""Population inference: recovery of known hyper-parameters from 13 simulated subjects, the
Gibbs sampler against the reweighting path, calibration (small SBC with a negative control),
shrinkage with few presses, the CLI and its files, effects, warnings and input errors."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from popdata import MU_MEDIAN, TAU, write_population
from popsim import draw_population, quadrature, run_sbc, subject_fits
from scipy import stats

import skinfit
from skinfit.analysis.groups import fit_by
from skinfit.analysis.population.inputs import load_run
from skinfit.analysis.population.population import population, population_tables
from skinfit.analysis.population.result import PopulationResult, PopulationWarning, load_population
from skinfit.analysis.population.reweight import _cholesky_corr
from skinfit.apps.cli import main
from skinfit.errors import InputError


@pytest.fixture(scope="module")
def thirteen(tmp_path_factory):
    folder = tmp_path_factory.mktemp("population")
    path, truths = write_population(folder, n_subjects=13)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        fit_by("electroadhesion_coulomb", str(path), "subject", folder / "fits", seed=21, ess_target=100)
    return folder / "fits", load_run(folder / "fits"), truths


@pytest.fixture(scope="module")
def cli_result(thirteen, tmp_path_factory):
    """``skinfit population RUN --params mu --seed 1``: its printout, output folder and result."""
    run, _, _ = thirteen
    out = tmp_path_factory.mktemp("population_out")
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), warnings.catch_warnings():
        warnings.simplefilter("ignore", PopulationWarning)
        code = main(["population", str(run), "--params", "mu", "--seed", "1", "--out", str(out)])
    assert code == 0
    return buf.getvalue(), out, load_population(out / "population.nc")


def _quiet(*args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PopulationWarning)
        return population(*args, **kw)


def test_hyper_truths_in_95_intervals_and_shrinkage_helps(thirteen, cli_result):
    _, fits, truths = thirteen
    assert list(fits) == list(truths)  # labels as written in the data (S01, not subject=S01)
    result = cli_result[2]  # saved and loaded back
    assert result.subjects == list(truths)
    assert result.converged
    assert result.families == ["lognormal"]  # the default for a positive parameter
    table = result.summary(0.95).set_index("quantity")
    for qty, truth in [("mu", np.log(MU_MEDIAN)), ("tau", TAU), ("median", MU_MEDIAN),
                       ("mean", MU_MEDIAN * np.exp(TAU**2 / 2))]:
        row = table.loc[qty]
        assert row["lower"] < truth < row["upper"], f"{qty}: truth {truth:.4g} outside [{row['lower']:.4g}, {row['upper']:.4g}]"
    assert table.loc["mu", "r_hat"] <= 1.01 and table.loc["tau", "ess_bulk"] >= 400
    subjects = result.subject_summary()
    truth = np.log([truths[s] for s in subjects["subject"]])
    mse_separate = np.mean((np.log(subjects["separate"]) - truth) ** 2)
    mse_shrunk = np.mean((np.log(subjects["shrunk"]) - truth) ** 2)
    assert mse_shrunk < mse_separate
    centre = table.loc["median", "estimate"]
    assert np.sum(np.abs(subjects["shrunk"] - centre) < np.abs(subjects["separate"] - centre)) >= 11
    tree = result.to_datatree()
    assert tree["subjects"]["theta"].shape[-2:] == (13, 1)
    assert "half-t" in json.loads(tree.attrs["hyperpriors"])["mu"]["sd"]


def test_gibbs_and_reweighting_agree_on_the_hyper_posterior(thirteen, cli_result):
    """Same model and hyper-priors, two samplers: posterior means of mu and tau agree within
    4 Monte Carlo standard errors (sd / sqrt(ESS) of each, combined), and sds within 15%.
    (A 10,400-sweep Gibbs run on these data gives E[tau] = 0.1027 +- 0.0007; quadrature on a
    (mu, tau) grid with each subject's likelihood summed over sigma, 0.1043.)"""
    _, fits, _ = thirteen
    gibbs = _quiet(fits, "mu", rng=5, ess_target=1000)
    reweight = _quiet(fits, "mu", rng=6, method="reweight", n_draws=1000, ess_target=400)
    for name in ("mu", "sd"):
        a, b = getattr(gibbs, name)[..., 0], getattr(reweight, name)[..., 0]
        ess_a = float(gibbs.diagnostics().set_index("quantity").loc[name, "ess_bulk"])
        ess_b = float(reweight.diagnostics().set_index("quantity").loc[name, "ess_bulk"])
        mcse = np.hypot(a.std() / np.sqrt(ess_a), b.std() / np.sqrt(ess_b))
        assert abs(a.mean() - b.mean()) < 4 * mcse, f"{name}: {a.mean():.4g} vs {b.mean():.4g} (mcse {mcse:.2g})"
        assert abs(a.std() / b.std() - 1) < 0.15


def test_small_sbc_passes_and_its_negative_control_fails():
    """12 simulated log-normal populations: the mean rank of the true mu and tau among 99
    draws is within 3.3 standard errors of 49.5 (uniform ranks: sd 28.87 / sqrt(12)); the
    same tau draws times 0.25 (a sampler that under-states the spread) put the truths high, more
    than 3.3 standard errors above (the full 100-population chi-square run with both families
    is bench/sbc_population.py)."""
    ranks, _ = run_sbc("lognormal", 12, seed=11, n_subjects=5, ess_target=40, rhat_max=1.1, control=0.25)
    z = {k: (np.mean(v) - 49.5) / (28.87 / np.sqrt(len(v))) for k, v in ranks.items()}
    assert abs(z["mu"]) < 3.3 and abs(z["tau"]) < 3.3, ranks
    assert z["tau_control"] > 3.3, ranks


def test_shrunk_estimates_beat_separate_fits_with_two_presses():
    """13 subjects from a known log-normal population (median 0.5, sd 0.05 in log), 2 presses
    per normal-force level: the shrunk medians have a lower squared error than the separate
    fits', and the 90% intervals cover at least 9 of 13 truths (binomial 2.5% quantile: 9)."""
    rng = np.random.default_rng(2)
    _, _, theta = draw_population(rng, "lognormal", 13, hyper=(np.log(0.5), 0.05))
    fits = subject_fits(rng, theta, 2)
    result = _quiet(fits, ["mu"], rng=rng, ess_target=200, rhat_max=1.05)
    table = result.subject_summary(prob=0.9)
    err_shrunk = np.mean((np.log(table["shrunk"]) - np.log(theta)) ** 2)
    err_separate = np.mean((np.log(table["separate"]) - np.log(theta)) ** 2)
    assert err_shrunk < 0.7 * err_separate
    covered = np.sum((table["shrunk_lower"] < theta) & (theta < table["shrunk_upper"]))
    assert covered >= stats.binom(13, 0.9).ppf(0.025)


def test_gibbs_with_its_non_centred_moves_matches_quadrature():
    """13 subjects with 2 presses per level from a narrow population (sd 0.05 in log): the
    data are weak against the spread, so the location and scale moves along the non-centred
    coordinates are used (their acceptance is recorded).  The hyper-posterior means of mu and
    tau agree with quadrature (tests/popsim.py: no chain, no proposal) within 4 Monte Carlo
    standard errors, and every subject's shrunk 2.5 / 50 / 97.5% quantiles within 4 Monte
    Carlo se of a normal's 2.5% quantile (2.7 sd / sqrt(ESS)) plus 0.002 for the grid.
    A wrong Jacobian in the scale move (e^eps for e^2eps) puts E[tau] 4.4 se low: it fails."""
    rng = np.random.default_rng(3)
    _, _, theta = draw_population(rng, "lognormal", 13, hyper=(np.log(0.5), 0.05))
    fits = subject_fits(rng, theta, 2)
    ref = quadrature(fits, n_u=800, n_sigma=60, n_m=120, n_tau=120)
    result = _quiet(fits, ["mu"], rng=4, ess_target=800)
    assert result.sampler["scale_acceptance"] > 0.1  # the moves ran and moved
    diag = result.diagnostics().set_index("quantity")
    for name, draws, q in [("mu", result.mu, ref["m"]), ("sd", result.sd, ref["tau"])]:
        x = draws[..., 0]
        mcse = x.std() / np.sqrt(diag.loc[name, "ess_bulk"])
        assert abs(x.mean() - q[0]) < 4 * mcse, f"{name}: {x.mean():.5f} vs quadrature {q[0]:.5f} (mcse {mcse:.2g})"
        assert x.std() == pytest.approx(q[1], rel=0.1)
    table = result.subject_summary()  # its median; the quantiles of the draws against quadrature
    ess = float(diag["ess_bulk"].min())
    for i, s in enumerate(result.subjects):
        draws = result.shrunk[:, :, i, 0]
        sd = np.std(draws)
        tol = 4 * 2.7 * sd / np.sqrt(ess) + 0.002
        assert table.iloc[i]["shrunk"] == np.median(draws)
        for qq in (0.025, 0.5, 0.975):
            got = np.quantile(draws, qq)
            assert abs(got - ref["subjects"][s](qq)) < tol, (s, qq, got, ref["subjects"][s](qq))


def test_cli_writes_tree_tables_and_states_the_family(cli_result):
    out, folder, back = cli_result
    assert "families: mu lognormal (default)" in out and "half-t" in out
    assert back.families == ["lognormal"] and back.subjects[0] == "S01"
    assert (folder / "population_summary.csv").exists() and (folder / "population_subjects.csv").exists()
    tables = population_tables(back)
    assert set(tables) >= {"hyper", "subjects", "effects", "hyperpriors"}
    # the report's forest plot reads a parameter's population as draws of a new subject
    draws = back.get("mu")
    assert draws.ndim == 1 and 0.3 < np.median(draws) < 0.7 and back.get("E_star") is None


def test_campaign_index_is_read_with_labels_as_written(thirteen, tmp_path):
    """A campaign's index.json (a list of rows with model, dataset, group, status, path)."""
    run, fits, _ = thirteen
    groups = json.loads((run / "index.json").read_text())["groups"][:3]
    rows = [{"model": "electroadhesion_coulomb", "dataset": "population", "group": g["group"], "status": "done",
             "path": str(run / g["path"])} for g in groups]
    rows.append({"model": "electroadhesion_coulomb", "dataset": "population", "group": "subject=S99",
                 "status": "failed", "path": str(run / "missing.nc")})
    (tmp_path / "index.json").write_text(json.dumps(rows))
    loaded = load_run(tmp_path)
    assert list(loaded) == ["S01", "S02", "S03"]
    assert loaded["S02"].attrs["dataset_sha256"] == fits["S02"].attrs["dataset_sha256"]


def test_cli_rejects_a_bad_family(thirteen, capsys):
    run, _, _ = thirteen
    assert main(["population", str(run), "--params", "mu", "--family", "mu=gamma"]) == 2
    assert "unknown family 'gamma'" in capsys.readouterr().err


def test_unknown_parameter_refused_naming_the_sampled_ones(thirteen):
    _, fits, _ = thirteen
    with pytest.raises(InputError, match=r"no sampled parameter 'slope' \(sampled: mu, E_star, d_air, sigma\)"):
        population(fits, ["slope"])


def _result(mu_draws, family="normal"):
    n = len(mu_draws)
    return PopulationResult("m", ["a1"], [family], ["S1", "S2"], mu_draws.reshape(1, n, 1), np.full((1, n, 1), 0.5),
                            None, np.zeros((1, n, 2, 1)), {"S1": np.zeros((5, 1)), "S2": np.zeros((5, 1))},
                            {"_bounds": {"a1": (-1.0, 1.0)}})


def test_effect_probability_and_interval_match_the_normal_closed_form():
    """Population mean draws N(-1, 1): P(mean < 0) = Phi(1) = 0.841 and the 95% interval
    -1 -+ 1.96, within Monte Carlo error of 200,000 draws."""
    rng = np.random.default_rng(12345)  # not predictive()'s own stream
    eff = _result(-1 + rng.standard_normal(200_000)).effect("a1", prob=0.95)
    assert eff["p_below"] == pytest.approx(stats.norm.cdf(1), abs=0.004)
    assert eff["lower"] == pytest.approx(-2.96, abs=0.03) and eff["upper"] == pytest.approx(0.96, abs=0.03)
    # a new subject adds the population sd 0.5: N(-1, sqrt(1.25))
    assert eff["p_new_subject_below"] == pytest.approx(stats.norm.cdf(1 / np.sqrt(1.25)), abs=0.004)


def test_contrast_of_split_levels_is_the_ratio_of_population_medians():
    """Log-normal levels alpha[0], alpha[200] with mu draws N(0, 0.1) and N(-0.2, 0.1)
    (independent): ratio of medians exp(-0.2) = 0.819, P(alpha[200] > alpha[0]) = Phi(-0.2 / 0.1414)."""
    rng = np.random.default_rng(1)
    n = 200_000
    mu = np.stack([0.1 * rng.standard_normal(n), -0.2 + 0.1 * rng.standard_normal(n)], axis=-1)[None]
    r = PopulationResult("m", ["alpha[0]", "alpha[200]"], ["lognormal"] * 2, ["S1"], mu, np.full_like(mu, 0.3), None,
                         np.ones((1, n, 1, 2)), {"S1": np.ones((5, 2))}, {})
    c = r.contrast("alpha[200]", "alpha[0]")
    assert c["quantity"] == "ratio of medians"
    assert c["estimate"] == pytest.approx(np.exp(-0.2), rel=0.005)
    assert c["p_greater"] == pytest.approx(stats.norm.cdf(-0.2 / np.sqrt(0.02)), abs=0.004)
    assert list(r.effects()["parameter"]) == ["alpha[200] vs alpha[0]"]


def test_warnings_for_weak_data_and_an_unconverged_hyper_posterior(thirteen):
    _, fits, _ = thirteen
    small = dict(list(fits.items())[:4])
    with pytest.warns(PopulationWarning) as record:
        population(small, "mu", rng=4, min_contraction=0.9999, max_sweeps=320, burn=300)
    text = " ".join(str(w.message) for w in record)
    assert "barely move the prior" in text and "not converged" in text


def test_a_cached_population_is_the_same_result_and_only_for_the_same_inputs(thirteen, tmp_path, monkeypatch):
    """population(cache=...): the same fits, settings and seed read the result sampled first
    (every array and table equal, nothing sampled); another seed, a subject's changed draws or
    a damaged cache file sample again (equal to an uncached run) and rewrite the file."""
    import importlib

    import pandas as pd
    import xarray as xr

    module = importlib.import_module("skinfit.analysis.population.population")
    _, fits, _ = thirteen
    small = dict(list(fits.items())[:4])
    cache = tmp_path / "cache" / "population.npz"
    options = {"rng": 4, "ess_target": 100, "rhat_max": 1.05}
    first = _quiet(small, "mu", cache=cache, **options)
    sampled, real = [], module.run_gibbs
    monkeypatch.setattr(module, "run_gibbs", lambda *a, **k: sampled.append(1) or real(*a, **k))

    def same(a, b):
        for name in ("mu", "sd", "shrunk"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert a.separate.keys() == b.separate.keys()
        for s in a.separate:
            np.testing.assert_array_equal(a.separate[s], b.separate[s])
        assert (a.parameters, a.families, a.subjects, a.warnings, a.contraction, a.hyperpriors, a.inputs) == \
            (b.parameters, b.families, b.subjects, b.warnings, b.contraction, b.hyperpriors, b.inputs)
        for table in ("summary", "subject_summary", "effects"):
            pd.testing.assert_frame_equal(getattr(a, table)(), getattr(b, table)(), check_exact=True)

    same(_quiet(small, "mu", cache=cache, **options), first)
    assert not sampled
    other = _quiet(small, "mu", cache=cache, **(options | {"rng": 5}))
    assert len(sampled) == 1
    same(other, _quiet(small, "mu", **(options | {"rng": 5})))
    changed = dict(small)
    label, fit = next(iter(small.items()))
    ds = fit.group("posterior")
    ds["mu"] = ds["mu"] * 1.01
    tree = fit.partial_tree.copy()
    tree["posterior"] = xr.DataTree(ds)
    changed[label] = skinfit.Fit(tree)
    sampled.clear()
    moved = _quiet(changed, "mu", cache=cache, **options)
    assert sampled and not np.array_equal(moved.separate[label], first.separate[label])
    cache.write_bytes(cache.read_bytes()[:200])  # a partial file
    sampled.clear()
    same(_quiet(small, "mu", cache=cache, **options), first)
    assert sampled
    sampled.clear()
    same(_quiet(small, "mu", cache=cache, **options), first)  # rewritten: read again
    assert not sampled
    # fits of a card other than the shipped one (a user's model, whose code the key does not hold)
    tree = fit.partial_tree.copy()
    tree.attrs["model_sha256"] = "0" * 64
    foreign, kept = {**small, label: skinfit.Fit(tree)}, tmp_path / "foreign.npz"
    _quiet(foreign, "mu", cache=kept, **options)
    assert not kept.exists()


_CACHED_POPULATION = """
import json, sys, warnings
from skinfit.analysis.population.inputs import load_run
from skinfit.analysis.population.population import population

fits = dict(list(load_run(sys.argv[1]).items())[:4])
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    result = population(fits, "mu", cache=sys.argv[2], rng=4, ess_target=100, rhat_max=1.05)
print(json.dumps({"summary": result.summary().to_json()}))
"""


def test_a_cached_population_keeps_its_diagnostics(thirteen, tmp_path):
    """The population cache keeps the hyper-parameters' R-hat and ESS (ArviZ's) beside the draws:
    read back they equal those ArviZ computes again from the draws, and a new process that reads
    the cached result tabulates the same summary."""
    import dataclasses
    import io
    import subprocess
    import sys

    import pandas as pd

    run, fits, _ = thirteen
    small = dict(list(fits.items())[:4])
    cache = tmp_path / "population.npz"
    first = _quiet(small, "mu", cache=cache, rng=4, ess_target=100, rhat_max=1.05)
    cached = _quiet(small, "mu", cache=cache, rng=4, ess_target=100, rhat_max=1.05)
    assert cached is not first and cached._diagnostics is not None
    again = dataclasses.replace(cached)  # the same draws, diagnostics not carried over: ArviZ's again
    assert again._diagnostics is None
    pd.testing.assert_frame_equal(cached.diagnostics(), again.diagnostics(), check_exact=True)
    assert np.isfinite(cached.diagnostics()[["r_hat", "ess_bulk", "ess_tail"]].to_numpy()).all()
    out = subprocess.run([sys.executable, "-c", _CACHED_POPULATION, str(run), str(cache)], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    child = json.loads(out.stdout.strip().splitlines()[-1])
    pd.testing.assert_frame_equal(pd.read_json(io.StringIO(child["summary"])), first.summary(),
                                  check_exact=False, rtol=1e-12, check_dtype=False)


def test_a_population_records_its_fits_by_content_and_its_seed(thirteen, cli_result):
    """The saved result names each subject's fit by :func:`subject_digest`: the same for the
    fit loaded whole or light, unchanged by an evidence a comparison caches in the file,
    changed by any posterior draw. A population run without a seed records the one drawn,
    which reproduces it."""
    import xarray as xr

    from skinfit.analysis.population.inputs import subject_digest
    from skinfit.results.fit import load_fit

    run, fits, _ = thirteen
    back = cli_result[2]
    assert back.sampler["seed"] == 1
    index = json.loads((run / "index.json").read_text())
    whole = {g["group"].split("=")[1]: load_fit(run / g["path"]) for g in index["groups"]}
    assert back.inputs == {s: subject_digest(f) for s, f in whole.items()} == \
        {s: subject_digest(f) for s, f in fits.items()}
    fit = whole["S01"]
    tree = fit.partial_tree.copy()
    tree.attrs["evidence"] = json.dumps({"log_z": -12.0})
    assert subject_digest(skinfit.Fit(tree)) == back.inputs["S01"]
    ds = fit.group("posterior").copy()
    ds["mu"] = ds["mu"].copy(data=ds["mu"].values.copy())
    ds["mu"].values[0, 0] *= 1.000001
    tree["posterior"] = xr.DataTree(ds)
    assert subject_digest(skinfit.Fit(tree)) != back.inputs["S01"]

    small = dict(list(fits.items())[:3])
    drawn = _quiet(small, "mu", ess_target=50, rhat_max=1.1)
    seed = drawn.sampler["seed"]
    assert isinstance(seed, int) and seed > 2**32  # drawn from fresh entropy, not a fixed default
    again = _quiet(small, "mu", rng=seed, ess_target=50, rhat_max=1.1)
    np.testing.assert_array_equal(again.mu, drawn.mu)


def test_correlated_population_gives_valid_correlations(thirteen):
    _, fits, _ = thirteen
    result = _quiet(dict(list(fits.items())[:6]), ["mu", "sigma"], correlated=True, rng=4, ess_target=100,
                    rhat_max=1.05)
    corr = result.corr
    np.testing.assert_allclose(np.diagonal(corr, axis1=-2, axis2=-1), 1.0, atol=1e-12)
    assert np.all(np.abs(corr[..., 0, 1]) < 1)
    assert "corr" in set(result.summary()["quantity"])


def test_inverse_wishart_draws_match_the_closed_form_mean():
    """Bartlett's construction of InvWishart(df, Psi): mean Psi / (df - p - 1)."""
    from skinfit.analysis.population.hierarchical import _inv_wishart

    rng = np.random.default_rng(1)
    psi = np.array([[2.0, 0.5], [0.5, 1.0]])
    draws = _inv_wishart(8.0, np.broadcast_to(psi, (100_000, 2, 2)), rng)
    np.testing.assert_allclose(draws.mean(axis=0), psi / (8 - 2 - 1), rtol=0.02)


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


@pytest.mark.slow
def test_sbc_of_100_populations_normal_and_lognormal_with_a_failing_control():
    """The full calibration (bench/sbc_population.py writes the same to bench/results):
    100 populations per family, chi-square p > 0.01 for mu and tau; the tau draws times 0.7
    fail (p < 0.01)."""
    for family in ("normal", "lognormal"):
        _, p = run_sbc(family, 100, seed=1)
        assert min(p["mu"], p["tau"]) > 0.01, (family, p)
        assert p["tau_control"] < 0.01, (family, p)


def test_a_run_is_read_from_its_own_folder_whatever_the_working_folder(thirteen, tmp_path, monkeypatch):
    """The paths in index.json are relative to the run's folder: a same-named file under the
    working folder (another run's S01) is never read in its place."""
    import shutil

    run, fits, _ = thirteen
    groups = json.loads((run / "index.json").read_text())["groups"]
    s01, s02 = (next(g["path"] for g in groups if g["group"] == f"subject={s}") for s in ("S01", "S02"))
    (tmp_path / s01).parent.mkdir(parents=True)
    shutil.copy(run / s02, tmp_path / s01)  # S02's fit where the working folder would find S01's path
    monkeypatch.chdir(tmp_path)
    np.testing.assert_array_equal(load_run(run)["S01"].group("posterior")["mu"].values,
                                  fits["S01"].group("posterior")["mu"].values)


@pytest.mark.slow
def test_gibbs_hyper_posterior_is_the_same_in_product_shift_and_shear_coordinates(tmp_path):
    """The population of beta0 over 3 electroadhesion subjects (the shipped data dealt to three,
    bench/bench_population_weak.py), sampled from the same fits' draws with the card's sampling
    coordinates (beta0 as beta0 tau0 E_star^(-2/3), d_air shifted, phi sheared) and with plain
    log coordinates (the card without its [sampling] tables, the draws given as DrawsFit): the
    hyper-posterior is one distribution, so mu and log tau agree within 4 combined Monte Carlo
    standard errors (measured: -5.862 / -5.848 and -0.412 / -0.431, se ~0.02-0.03)."""
    import sys as _sys

    import arviz as az

    from skinfit.analysis.groups import group_labels
    from skinfit.analysis.population.inputs import DrawsFit
    from skinfit.io.data import load_dataset
    from skinfit.io.models import load_model
    from skinfit.io.paths import shipped_root
    from skinfit.io.priors import load_priors
    from skinfit.posterior import Posterior
    from skinfit.results.summary import slot_values

    _sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
    from bench_population_weak import three_subjects

    data = three_subjects(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        fit_by("electroadhesion", str(data), "subject", tmp_path / "run", seed=1)
    fits = load_run(tmp_path / "run")
    text = (shipped_root() / load_model("electroadhesion").path).read_text()  # the shipped card
    (tmp_path / "electroadhesion.toml").write_text(text[:text.index("[sampling.")])
    model, priors, ds = load_model(str(tmp_path / "electroadhesion.toml")), load_priors("electroadhesion"), \
        load_dataset(str(data))
    labels = np.array(group_labels(ds, ["subject"])[0], dtype=object)
    plain = {}
    for s, f in fits.items():
        post = Posterior(model, priors, ds.subset(labels == f"subject={s}", f"subject={s}"))
        assert {sl.transform for sl in post.slots} == {"log"}
        slots = {x["name"]: x for x in f.attr("slots")}
        plain[s] = DrawsFit(post, np.column_stack([slot_values(f.group("posterior"), slots[n]) for n in post.names]),
                            s)
    out = []
    for given in (fits, plain):
        r = _quiet(given, ["beta0"], rng=7, ess_target=2000, max_sweeps=150000)
        assert r.converged
        out.append([(x.mean(), x.std() / np.sqrt(float(az.ess(x)))) for x in (r.mu[:, :, 0], np.log(r.sd[:, :, 0]))])
    for (a, sa), (b, sb) in zip(*out):
        assert abs(a - b) < 4 * np.hypot(sa, sb), (a, b, sa, sb)
