"""End to end on electroadhesion: recovery, reproducibility, MAP, likelihoods, results file."""

import importlib
import json
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pointwise import check_pointwise_groups
from scipy import optimize, stats

import skinfit
from skinfit.errors import InputError
from skinfit.inference.optimize import find_map
from skinfit.io import integrity
from skinfit.posterior import Posterior
from skinfit.report.checks import fit_diagnostics

ROOT = Path(skinfit.__file__).resolve().parents[1]
CARD = tomllib.loads((ROOT / "datasets/electroadhesion_synthetic/dataset.toml").read_text())
TRUTH = {**CARD["provenance"]["generating_parameters"], "sigma": CARD["provenance"]["noise"]["sigma"]}


def _short_fit(**kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", skinfit.ConvergenceWarning)
        return skinfit.fit("electroadhesion", "electroadhesion_synthetic", max_steps=400, n_global=300,
                           **kw)


def test_recovery_truth_in_95_interval(ea_fit):
    assert ea_fit.converged
    post = ea_fit.idata["posterior"].to_dataset()
    for name, truth in TRUTH.items():
        lo, hi = np.quantile(post[name].values, [0.025, 0.975])
        assert lo < truth < hi, f"{name}: truth {truth:g} outside 95% interval [{lo:g}, {hi:g}]"


def test_summary_columns_and_diagnostics(ea_fit):
    table = ea_fit.summary()
    assert list(table.columns) == ["unit", "mean", "sd", "hdi_3%", "hdi_97%", "r_hat", "ess_bulk", "ess_tail",
                                   "map", "tau", "contraction", "note"]
    # SI units of the stored values (the data came in mN; the card states SI)
    assert dict(table["unit"]) == {"E_star": "Pa", "tau0": "Pa", "d_air": "m", "beta0": "1", "phi": "m^2/J",
                                   "eta": "m^2/N^2", "alpha": "1", "sigma": "N"}
    assert (table["r_hat"] < 1.02).all() and (table["ess_bulk"] > 400).all()
    sampler = ea_fit.attr("sampler")
    assert sampler["n_steps"] - sampler["burn"] >= 50 * max(sampler["tau"].values())
    # the forces pin alpha, sigma and eta; tau0 enters only through products: mostly prior
    assert table.loc["alpha", "contraction"] > 0.95 and table.loc["sigma", "contraction"] > 0.95
    assert table.loc["tau0", "contraction"] < 0.5 and table.loc["tau0", "note"].startswith("mostly prior")
    text = ea_fit.report_text()
    for needle in ["converged: yes", "acceptance", "wall time", "outside the physical support", "tau0"]:
        assert needle in text
    t = ea_fit.attr("timings")
    assert not t["resumed"] and 0 < t["map_s"] < t["start_s"] < t["total_s"]  # start_s: MAP + importance start
    assert f"importance start {t['start_s'] - t['map_s']:.2f} s" in text


def test_summary_is_computed_once_per_content(ea_fit, tmp_path):
    """The cached summary is a copy, and an edited posterior or a new warning is a new summary
    (a saved copy of the fit is edited: the session's fit stays as it is)."""
    fit = skinfit.load_fit(ea_fit.save(tmp_path / "fit.nc"))
    first = fit.summary()
    first.loc["alpha", "mean"] = -1.0  # the caller's copy, not the cache
    assert fit.summary().loc["alpha", "mean"] == pytest.approx(float(fit.group("posterior")["alpha"].mean()))
    fit.idata["posterior"]["alpha"].values[...] *= 2.0  # in place: the draws changed
    assert fit.summary().loc["alpha", "mean"] == pytest.approx(2 * ea_fit.summary().loc["alpha", "mean"])
    fit.attrs["warnings"] = json.dumps(fit.warnings + [{"check": "bound", "parameter": "alpha", "status": "WARN",
                                                        "message": "made up"}])
    assert "ON A BOUND: made up" in fit.summary().loc["alpha", "note"]


def test_saved_summary_is_read_back_with_the_same_numbers_without_computing_it(ea_fit, tmp_path, monkeypatch):
    """A saved fit keeps its summary table: loaded, it shows the stored table, equal to the
    one computed from the same draws to the last bit, without computing it."""
    path = ea_fit.save(tmp_path / "fit.nc")
    computed = skinfit.load_fit(path)._compute_summary()
    fit_module = importlib.import_module("skinfit.results.fit")

    def fail(self):
        raise AssertionError("summary computed although stored")

    monkeypatch.setattr(fit_module.Fit, "_compute_summary", fail)
    back = skinfit.load_fit(path)
    assert back.summary_stored
    pd.testing.assert_frame_equal(back.summary(), computed, check_exact=True)
    pd.testing.assert_frame_equal(back.summary(), ea_fit.summary(), check_exact=True)
    assert back.summary().attrs == ea_fit.summary().attrs


def test_a_fit_whose_summary_fails_is_saved_without_it(ea_fit, tmp_path, monkeypatch):
    """The stored summary only saves time: when it cannot be computed the fit is saved all the
    same (with a warning), and the summary is computed when the file is read."""
    import xarray as xr

    path = ea_fit.save(tmp_path / "fit.nc")
    tree = xr.open_datatree(path).load()
    del tree.attrs["summary"]
    integrity.stamp(tree)  # the file without a stored summary, with the checksums of its content
    tree.to_netcdf(tmp_path / "bare.nc", engine="h5netcdf")
    fit_module = importlib.import_module("skinfit.results.fit")

    def fail(self):
        raise ValueError("no summary here")

    with monkeypatch.context() as m:
        m.setattr(fit_module.Fit, "_compute_summary", fail)
        with pytest.warns(UserWarning, match="saved without its summary table .ValueError: no summary here"):
            skinfit.load_fit(tmp_path / "bare.nc").save(tmp_path / "again.nc")
    again = skinfit.load_fit(tmp_path / "again.nc")
    assert "summary" not in again.attrs and not again.summary_stored
    pd.testing.assert_frame_equal(again.summary(), ea_fit.summary(), check_exact=True)


def test_a_stored_summary_is_never_shown_for_other_draws_or_records(ea_fit, tmp_path):
    """A file edited after its summary was stored (draws, warnings) or whose stored table is
    damaged shows the summary of what it now holds."""
    path = ea_fit.save(tmp_path / "fit.nc")
    tree = skinfit.load_fit(path).idata
    stored = tree.attrs["summary"]
    tree["posterior"]["alpha"].values[...] *= 2.0
    tree.attrs["summary"] = stored  # the old table kept beside new draws
    integrity.stamp(tree)  # as another tool that rewrote the file with its checksums would leave it
    tree.to_netcdf(tmp_path / "edited.nc", engine="h5netcdf")
    edited = skinfit.load_fit(tmp_path / "edited.nc")
    assert not edited.summary_stored
    assert edited.summary().loc["alpha", "mean"] == pytest.approx(2 * ea_fit.summary().loc["alpha", "mean"],
                                                                  rel=1e-12)
    warned = skinfit.load_fit(path)
    warned.attrs["warnings"] = json.dumps(warned.warnings + [{"check": "bound", "parameter": "alpha",
                                                              "status": "WARN", "message": "made up"}])
    assert "ON A BOUND: made up" in warned.summary().loc["alpha", "note"]
    for damaged in ("{not json", json.dumps({"key": json.loads(stored)["key"], "index": ["alpha"], "columns": []}),
                    stored.replace('"values": [', '"values": [1.5, ', 1)):
        fit = skinfit.load_fit(path)
        fit.attrs["summary"] = damaged
        assert not fit.summary_stored
        pd.testing.assert_frame_equal(fit.summary(), ea_fit.summary(), check_exact=True)


def test_a_loaded_fit_computes_its_pointwise_groups_on_first_use_bit_for_bit(ea_fit, tmp_path):
    """The file holds every group but the two pointwise ones (their recipe instead: seed,
    thinning, sums); load_fit gives the tree xarray reads, and the pointwise groups computed
    again on first use from the draws and data in the file are those of the fit that was saved,
    bit for bit, with their units; its PSIS-LOO the same number."""
    import xarray as xr

    from skinfit.analysis.compare import loo
    from skinfit.results.fit import DEFERRED, GROUPS

    path = ea_fit.save(tmp_path / "fit.nc")
    on_disk = xr.open_datatree(path).load()
    assert list(on_disk.children) == [g for g in GROUPS if g not in DEFERRED and g != "derived"]
    fit = skinfit.load_fit(path)
    assert "log_likelihood" not in fit.partial_tree.children and fit.content_hash() == ea_fit.content_hash()
    xr.testing.assert_identical(fit.partial_tree, on_disk)
    assert fit.summary_stored and fit.group("posterior_predictive")["tangential_force"].shape[-1] == 216
    assert list(fit.idata.children) == list(ea_fit.idata.children)
    for group in DEFERRED:
        xr.testing.assert_identical(fit.idata[group].to_dataset(), ea_fit.idata[group].to_dataset())
    assert float(loo(fit).elpd) == float(loo(ea_fit).elpd)


def test_a_fit_saved_with_its_pointwise_groups_as_float64_still_loads_them_from_its_file(ea_fit, tmp_path):
    """A file of an earlier skinfit (the pointwise groups stored, float64, no recipe) reads them
    from the file on first use, and saved again keeps them; a file replaced in between is an
    InputError, never a tree of two results."""
    import xarray as xr

    from skinfit.results.pointwise import RECIPE
    from skinfit.results.store import write_tree

    tree = ea_fit.idata.copy()
    del tree.attrs[RECIPE]
    path = write_tree(tree, tmp_path / "old.nc")
    assert xr.open_datatree(path)["log_likelihood"]["tangential_force"].dtype == np.float64
    fit = skinfit.load_fit(path)
    assert "log_likelihood" not in fit.partial_tree.children
    xr.testing.assert_identical(fit.idata, xr.open_datatree(path).load())
    fit.save(tmp_path / "again.nc")
    assert "log_likelihood" in xr.open_datatree(tmp_path / "again.nc").children
    stale = skinfit.load_fit(path)
    skinfit.load_fit(path).save(path)  # the file replaced (here by the same content)
    with pytest.raises(InputError, match="changed or removed since the fit was loaded"):
        stale.idata


def test_pointwise_groups_computed_again_to_other_numbers_are_refused(ea_fit, tmp_path):
    """A recipe whose sums differ from what the draws give now (as a skinfit whose model gives
    other numbers would find): one line naming the file, never the other numbers."""
    import json

    from skinfit.results.pointwise import RECIPE
    from skinfit.results.store import write_tree

    tree = skinfit.load_fit(ea_fit.save(tmp_path / "fit.nc")).partial_tree.copy()
    recipe = json.loads(tree.attrs[RECIPE])
    recipe["sums"]["log_likelihood"]["tangential_force"][0] *= 1 + 1e-6
    tree.attrs[RECIPE] = json.dumps(recipe)
    path = write_tree(tree, tmp_path / "other.nc")
    fit = skinfit.load_fit(path)
    with pytest.raises(InputError, match=rf"^{path}: its log_likelihood \(tangential_force\) computed again from "
                                         "its draws differs from when it was fitted"):
        fit.idata


def test_result_tree_groups_and_provenance(ea_fit):
    tree = ea_fit.idata
    assert list(tree.children) == ["posterior", "prior", "sample_stats", "log_likelihood", "posterior_predictive",
                                   "observed_data", "constant_data"]  # ArviZ's order, as az.from_dict gives it
    ds = skinfit.load_dataset("electroadhesion_synthetic")
    assert tree.attrs["dataset_sha256"] == ds.sha256
    assert tree.attrs["model_sha256"] == skinfit.load_model("electroadhesion").sha256
    assert tree.attrs["seed"] == 1
    assert tree["log_likelihood"]["tangential_force"].shape[-1] == len(ds)
    np.testing.assert_allclose(tree["observed_data"]["tangential_force"].values, ds.frame["tangential_force"])


def test_save_load_identical(ea_fit, tmp_path):
    path = ea_fit.save(tmp_path / "run" / "fit.nc")
    back = skinfit.load_fit(path)
    for group in ["posterior", "log_likelihood", "posterior_predictive", "constant_data"]:
        a, b = ea_fit.idata[group].to_dataset(), back.idata[group].to_dataset()
        for var in a.data_vars:
            np.testing.assert_array_equal(a[var].values, b[var].values)
    assert dict(back.idata.attrs) == {k: v for k, v in ea_fit.idata.attrs.items()}
    pd.testing.assert_frame_equal(back.summary(), ea_fit.summary())
    # the saved fit carries everything needed to rebuild its posterior
    theta = ea_fit.posterior.to_theta(ea_fit.posterior.to_z(np.array([list(ea_fit.map.values())])))
    assert back.posterior.log_density(theta) == pytest.approx(ea_fit.posterior.log_density(theta), rel=1e-12)


def test_same_seed_identical_samples_whenever_the_pointwise_groups_are_computed():
    """One fit complete as skinfit.fit returns it, the other made pending (complete=False) and
    completed after another fit, its groups and unrelated random draws: bit for bit the same,
    with the same check of the fit to the data; a Generator passed in is advanced by the fit
    alone (as a fit from the same seed advances its own), not by the pointwise groups."""
    generator = np.random.default_rng(7)
    a = _short_fit(rng=generator)
    after_fit = generator.bit_generator.state
    assert not a.pending and "pointwise_s" in a.attr("timings") and a.attr("misfit")["checks"]
    b_generator = np.random.default_rng(7)
    b = _short_fit(rng=b_generator, complete=False)
    assert b.pending and b_generator.bit_generator.state == after_fit
    c = _short_fit(rng=8)
    # the global legacy stream is advanced on purpose: the fits must not read it
    np.random.default_rng(0).standard_normal(1000), np.random.standard_normal(1000)  # noqa: NPY002
    b.complete()
    assert not b.pending and b.attrs["misfit"] == a.attrs["misfit"] and b.warnings == a.warnings
    for group, var in [("posterior", "E_star"), ("sample_stats", "lp"), ("log_likelihood", "tangential_force"),
                       ("posterior_predictive", "tangential_force")]:
        np.testing.assert_array_equal(a.idata[group][var].values, b.idata[group][var].values)
    for group, var in [("posterior", "E_star"), ("posterior_predictive", "tangential_force")]:
        assert not np.array_equal(a.idata[group][var].values, c.idata[group][var].values)


def test_pointwise_groups_agree_with_the_posterior(ea_fit):
    check_pointwise_groups(ea_fit)


def test_a_fit_made_pending_is_completed_by_one_explicit_call_never_by_a_property(tmp_path):
    """A fit made with complete=False: its summaries, provenance, diagnostics and evidence
    leave the pointwise groups pending; ``idata`` and the pointwise groups raise one line naming
    ``fit.complete()``, computing, checking and warning nothing; saving completes it; the
    evidence cached before is kept through both."""
    fit = _short_fit(rng=5, complete=False)
    assert fit.pending and "pointwise_s" not in fit.attr("timings")
    attrs = dict(fit.attrs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for read in (lambda: fit.idata, lambda: fit.group("log_likelihood"),
                     lambda: fit.group("posterior_predictive")):
            with pytest.raises(RuntimeError, match=r"call fit\.complete\(\) first") as caught:
                read()
            assert "\n" not in str(caught.value)
    assert fit.pending and dict(fit.attrs) == attrs and "misfit" not in fit.attrs
    fit.summary(), fit.diagnostics(), fit.attr("sampler"), fit.map, fit.warnings, fit.converged, repr(fit)
    assert fit.model_id == "electroadhesion" and fit.dataset_id == "electroadhesion_synthetic"
    assert fit.attrs["seed"] == 5 and fit.group("posterior").sizes["chain"] == fit.attr("sampler")["nwalkers"]
    assert fit.report_text().count("pointwise log-likelihood and predictive draws not computed yet") == 1
    diagnostics, _ = fit_diagnostics(fit)
    assert diagnostics.loc["wall time [s]", "criterion"].endswith("not computed yet")
    laplace = skinfit.evidence(fit, method="laplace")
    assert fit.pending and set(fit.group("posterior").data_vars) == set(TRUTH)

    path = fit.save(tmp_path / "fit.nc")
    assert not fit.pending
    timings = fit.attr("timings")
    assert timings["pointwise_s"] > 0 and timings["tree_s"] > 0
    assert f"pointwise log-likelihood and predictive draws {timings['pointwise_s']:.2f} s" in fit.report_text()
    back = skinfit.load_fit(path)
    assert not back.pending and back.attr("timings") == timings
    assert list(back.idata.children) == list(fit.idata.children)
    for group in ("log_likelihood", "posterior_predictive"):
        np.testing.assert_array_equal(back.group(group)["tangential_force"].values,
                                      fit.group(group)["tangential_force"].values)
    for f in (fit, back):
        assert json.loads(f.attrs["evidence"])["laplace"]["log_z"] == laplace.log_z


def test_different_seed_consistent_posterior(ea_fit):
    other = skinfit.fit("electroadhesion", "electroadhesion_synthetic", rng=2)
    s1, s2 = ea_fit.summary(), other.summary()
    for name in s1.index:
        # difference of means within 5 combined Monte Carlo standard errors (sd / sqrt(ESS))
        se = np.hypot(s1.loc[name, "sd"] / np.sqrt(s1.loc[name, "ess_bulk"]),
                      s2.loc[name, "sd"] / np.sqrt(s2.loc[name, "ess_bulk"]))
        assert abs(s1.loc[name, "mean"] - s2.loc[name, "mean"]) < 5 * se, name


def _noiseless_dataset(tmp_path, truth, rng):
    model = skinfit.load_model("electroadhesion_coulomb")
    v, fn = np.meshgrid(np.arange(0, 101, 25.0), np.linspace(0.2, 2, 10), indexing="ij")
    frame = pd.DataFrame({"voltage": v.ravel(), "normal_force": fn.ravel()})
    frame["tangential_force"] = model.predict(truth, frame)
    d = tmp_path / "noiseless"
    d.mkdir()
    frame.to_csv(d / "data.csv", index=False, float_format="%.17g")
    (d / "dataset.toml").write_text(
        'schema_version = 1\nid = "noiseless"\nfile = "data.csv"\n'
        '[provenance]\nkind = "simulated"\nseed = 0\ngenerating_parameters = {}\n'
        '[columns.voltage]\nunit = "V"\n[columns.normal_force]\nunit = "N"\n[columns.tangential_force]\nunit = "N"\n')
    return skinfit.load_dataset(str(d)), frame


def test_map_agrees_with_least_squares_on_noiseless_data(tmp_path, rng):
    truth = {"mu": 0.42, "E_star": 30e3, "d_air": 2e-6}
    ds, frame = _noiseless_dataset(tmp_path, truth, rng)
    model = skinfit.load_model("electroadhesion_coulomb")
    post = Posterior(model, skinfit.load_priors("electroadhesion_coulomb"), ds)
    m = find_map(post, rng).as_dict(post.names)

    def resid(logp):
        p = dict(zip(["mu", "E_star", "d_air"], np.exp(logp)))
        return model.predict(p, frame) - frame["tangential_force"].to_numpy()

    ls = optimize.least_squares(resid, np.log([0.5, 40e3, 1e-6]), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    for name, value in zip(["mu", "E_star", "d_air"], np.exp(ls.x)):
        assert value == pytest.approx(truth[name], rel=1e-4)
        # E_star moves the force only through the small electrostatic term: weakest direction
        assert m[name] == pytest.approx(value, rel=1e-3), name
    y = frame["tangential_force"].to_numpy()
    pred_map = model.predict({k: m[k] for k in ["mu", "E_star", "d_air"]}, frame)
    assert np.max(np.abs(pred_map - y)) < 1e-6 * np.max(y)


@pytest.mark.parametrize("noise", ["normal", "student_t", "lognormal"])
def test_pointwise_likelihood_matches_scipy(noise, rng):
    model = skinfit.load_model("electroadhesion_coulomb")
    ds = skinfit.load_dataset("electroadhesion_synthetic")
    priors = skinfit.load_priors("electroadhesion_coulomb")
    if noise == "student_t":
        from types import MappingProxyType

        from skinfit.io.priors import PriorSet, parse_prior

        extra = parse_prior("nu", {"dist": "gamma", "shape": 2, "scale": 10, "bounds": [1, 200],
                                   "source": "Juarez & Steel 2010 gamma(2, 0.1) prior on nu"}, "test")
        priors = PriorSet("t", priors.model, MappingProxyType({**priors.priors, "nu": extra}))
    post = Posterior(model, priors, ds, noise=noise)
    theta = post.sample_prior(4, rng)
    ll, pred, _ = post.pointwise(theta)
    y = ds.frame["tangential_force"].to_numpy()
    p = post.unpack(theta)
    mu, sigma = pred["tangential_force"], p["sigma"]
    ref = {"normal": lambda: stats.norm.logpdf(y, mu, sigma),
           "student_t": lambda: stats.t.logpdf(y, p["nu"], mu, sigma),
           "lognormal": lambda: stats.lognorm.logpdf(y, sigma, scale=mu)}[noise]()
    np.testing.assert_allclose(ll["tangential_force"], ref, rtol=1e-10)


def test_split_parameter_per_voltage(rng):
    model = skinfit.load_model("electroadhesion")
    ds = skinfit.load_dataset("electroadhesion_synthetic")
    post = Posterior(model, skinfit.load_priors("electroadhesion"), ds, split={"alpha": "voltage"})
    assert [n for n in post.names if n.startswith("alpha")] == [f"alpha[{v}]" for v in range(0, 201, 25)]
    theta = post.sample_prior(3, rng)
    alpha_rows = post.unpack(theta)["alpha"]  # (k, n): each row's own level
    for level in range(0, 201, 25):
        rows = ds.frame["voltage"].to_numpy() == level
        own = theta[:, [post.names.index(f"alpha[{level}]")]]
        np.testing.assert_array_equal(alpha_rows[:, rows], np.broadcast_to(own, (3, rows.sum())))
    fit = _short_fit(rng=3, split={"alpha": "voltage"})
    assert fit.idata["posterior"]["alpha"].dims == ("chain", "draw", "voltage")
    assert "alpha[200]" in fit.summary().index


def test_outside_support_is_minus_inf_and_counted():
    model = skinfit.load_model("electroadhesion")
    ds = skinfit.load_dataset("electroadhesion_synthetic")
    post = Posterior(model, skinfit.load_priors("electroadhesion"), ds)
    table_i = {"E_star": 35e3, "tau0": 10.64e3, "d_air": 0.19e-6, "beta0": 0.0049, "phi": 0.47,
               "eta": 3.72e-4, "alpha": 0.5, "sigma": 0.02}
    lp = post.log_density(np.array([[table_i[n] for n in post.names]]))
    assert lp[0] == -np.inf
    assert post.counts["outside_support"] == 1


def test_bad_split_and_noise_rejected():
    with pytest.raises(skinfit.InputError, match="cannot split 'alpha' by 'material'"):
        skinfit.fit("electroadhesion", "electroadhesion_synthetic", split={"alpha": "material"}, rng=0)
    with pytest.raises(skinfit.InputError, match="unknown noise model 'cauchy'"):
        skinfit.fit("electroadhesion", "electroadhesion_synthetic", noise="cauchy", rng=0)


def test_rng_types():
    with pytest.raises(TypeError, match="rng must be"):
        skinfit.fit("electroadhesion", "electroadhesion_synthetic", rng="seven")


def test_map_error_when_every_start_fails(tmp_path):
    """Priors that only allow eta so large that A_app < 0 at every point: a clear error."""
    from skinfit.inference.optimize import MAPError

    text = (ROOT / "priors" / "electroadhesion.toml").read_text()
    start, end = text.index("[eta]"), text.index("[alpha]")
    bad = tmp_path / "ea.toml"
    bad.write_text(text[:start] + '[eta]\ndist = "uniform"\nbounds = [0.5, 1.0]\nsource = "electroadhesion_friction"\n\n' + text[end:])
    with pytest.raises(MAPError, match=r"MAP failed: .* outside the physical support: \d+") as info:
        skinfit.fit("electroadhesion", "electroadhesion_synthetic", priors=skinfit.load_priors(str(bad)),
                    rng=0, n_global=200)
    assert info.value.result.evaluations >= 200


def test_only_a_shipped_models_fit_leaves_its_pointwise_groups_out_of_its_file(ea_fit):
    """A model whose forward function ships with skinfit can compute them wherever the file is
    read; a plug-in's or a user's may be missing there, so its fit keeps them (as does a fit
    without the recipe, saved by an earlier skinfit)."""
    import xarray as xr

    from skinfit.results.pointwise import RECIPE, recomputable

    assert recomputable(ea_fit.partial_tree)
    other = xr.DataTree(xr.Dataset(attrs=dict(ea_fit.attrs)))
    other.attrs["model_card"] = ea_fit.attrs["model_card"].replace(
        "skinfit.physics.electroadhesion:electroadhesion", "my_lab.models:electroadhesion")
    assert "my_lab.models" in other.attrs["model_card"] and not recomputable(other)
    del other.attrs[RECIPE]
    other.attrs["model_card"] = ea_fit.attrs["model_card"]
    assert not recomputable(other)
