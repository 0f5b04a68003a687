"""A model of one's own from a Python function (issue 42): ``Model.from_function`` with scipy.stats
priors fits like a shipped card, recovers the parameters that generated its data, gives bit for
bit the posterior of the same model written as a card and prior file (``Model.to_card``), is
saved and loaded in a new process, compared with a shipped model and reported; each mistake a
user makes is one line naming it."""

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import scipy.stats as st
from own_model_function import TRUTH, powerlaw_ea, simulate

import skinfit
from skinfit.errors import ForwardError, InputError
from skinfit.io.models import parse_model_text
from skinfit.report.html import write_report

TESTS = Path(__file__).resolve().parent
UNITS = {"covariates": {"normal_force": "N", "voltage": "V"}, "parameters": {"k": "N^(1-n)", "kappa": "N/V^2", "n": "1"}}
FAST = {"ess_target": 150, "n_global": 400}  # enough for intervals at this data size, a few seconds a fit


def make_model(func=powerlaw_ea, **kw):
    return skinfit.Model.from_function(func, observable=("tangential_force", "N"), **{**UNITS, **kw})


def make_priors():
    return {"k": st.lognorm(s=1.0, scale=0.5), "kappa": st.halfnorm(scale=1e-5), "n": st.uniform(0.3, 1.0),
            "sigma": st.halfnorm(scale=0.1)}


@pytest.fixture(scope="module")
def data():
    return simulate(300, seed=20261128)


@pytest.fixture(scope="module")
def own_fit(data):
    return skinfit.fit(make_model(), data, priors=make_priors(), rng=1, **FAST)


def test_the_card_records_function_and_source_hash():
    model = make_model()
    card = tomllib.loads(model.card_text)
    assert card["function"] == "own_model_function:powerlaw_ea" == model.forward_ref
    import hashlib
    import inspect

    assert card["function_sha256"] == hashlib.sha256(inspect.getsource(powerlaw_ea).encode()).hexdigest()
    assert model.parameter_names == ("k", "kappa", "n") and model.covariate_names == ("normal_force", "voltage")
    # predict evaluates the function itself: one draw, the closed form at a point
    y = model.predict({"k": 0.5, "kappa": 2e-6, "n": 0.8}, {"normal_force": np.array([1.0]), "voltage": np.array([100.])})
    assert y[0] == pytest.approx(0.5 * (1.0 + 2e-6 * 1e4) ** 0.8, rel=1e-14)


def test_recovers_generating_parameters(own_fit):
    """Data simulated at TRUTH (300 rows): each generating value inside the 95% interval."""
    post = own_fit.idata["posterior"].to_dataset()
    for name, value in TRUTH.items():
        lo, hi = np.quantile(post[name].values.ravel(), [0.025, 0.975])
        assert lo < value < hi, (name, lo, hi, value)
    assert own_fit.converged


def test_function_and_card_give_identical_posteriors(tmp_path, data):
    model, priors = make_model(), make_priors()
    files = model.to_card(tmp_path, priors)
    assert files == {"model": tmp_path / "models" / "powerlaw_ea.toml", "priors": tmp_path / "priors" / "powerlaw_ea.toml"}
    card_model, card_priors = skinfit.load_model(files["model"]), skinfit.load_priors(files["priors"])
    assert card_model.function is None and card_model.user_function  # found in the registry, from the file
    kw = {"ess_target": 60, "n_global": 200}
    a = skinfit.fit(model, data, priors=priors, rng=7, **kw)
    b = skinfit.fit(card_model, data, priors=card_priors, rng=7, **kw)
    pa, pb = a.idata["posterior"].to_dataset(), b.idata["posterior"].to_dataset()
    for name in ("k", "kappa", "n", "sigma"):
        assert np.array_equal(pa[name].values, pb[name].values), name
    # the user's prior file keeps the scipy description as its free-text source, shown as given
    assert 'source = "scipy.stats.lognorm(s=1.0, loc=0.0, scale=0.5)"' in files["priors"].read_text()
    with pytest.raises(InputError, match="exists"):
        model.to_card(tmp_path, priors)


def test_truncate_and_prior_file_tables(data):
    from skinfit.io.user_priors import as_prior_set

    model = make_model()
    ps = as_prior_set({"k": skinfit.truncate(st.lognorm(s=1.0, scale=0.5), 0.01, 5.0),
                       "kappa": {"dist": "halfnormal", "scale": 1e-5, "bounds": [0.0, 1e-3]},
                       "n": st.uniform(0.3, 1.0), "sigma": st.halfnorm(scale=0.1)}, model)
    assert (ps["k"].lower, ps["k"].upper, ps["k"].dist) == (0.01, 5.0, "lognormal")
    assert ps["kappa"].source == "given in Python" and ps["n"].upper == 1.3
    # the truncated prior is scipy's, renormalised on its bounds
    f = st.lognorm(s=1.0, scale=0.5)
    x = np.array([0.1, 1.0, 4.0])
    expected = f.logpdf(x) - np.log(f.cdf(5.0) - f.cdf(0.01))
    np.testing.assert_allclose(ps["k"].logpdf(x), expected, rtol=1e-12)


@pytest.mark.parametrize("func, match", [
    (lambda p, x: p["k"][:, 0] + 0 * x["voltage"][0],
     r"^model from function <lambda>: function: test_own_model:<lambda>: returned 'tangential_force' of shape "
     r"\(3,\); expected \(3, 300\)"),
    (lambda p, x: p["k"] * np.log(x["voltage"] - 300.0),
     "returned nan .*narrow the priors to where the model is defined"),
    (lambda p, x: p["k"][0, 0] * x["normal_force"] ** p["n"] + p["kappa"] * x["voltage"], "not vectorised"),
])
def test_a_broken_function_is_one_line(data, func, match):
    model = make_model(func, id="broken")
    with pytest.raises(ForwardError, match=match) as info:
        skinfit.fit(model, data, priors=make_priors(), rng=1, **FAST)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("change, error, match", [
    ({"mu": st.norm(0.5, 0.1)}, InputError, "a prior for 'mu', which model 'powerlaw_ea' does not have"),
    ({"sigma": None}, InputError, r"no prior for sigma \(model 'powerlaw_ea' needs priors for k, kappa, n, sigma\)"),
    ({"sigma": {"dist": "uniform", "bounds": [0.0, float("inf")]}}, InputError, "improper: give finite bounds"),
    ({"sigma": st.norm(0.0, 0.1)}, InputError, r"leave the physical range \[0, inf\] of sigma, a noise scale, "
                                               r"which cannot be negative: give it a prior on \[0, inf\] .*"
                                               r"skinfit.truncate\(dist, 0, upper\)\)$"),
    ({"k": st.cauchy(0.5, 1.0)}, InputError, "scipy.stats.cauchy is not a prior family skinfit has"),
    ({"k": st.lognorm}, InputError, "scipy.stats.lognorm is not frozen"),
    ({"k": 0.5}, InputError, "expected a frozen scipy.stats distribution"),
    ({"k": st.lognorm(s=1.0, loc=0.1, scale=0.5)}, InputError, "lognormal prior has loc=0.0"),
])
def test_a_wrong_prior_is_one_line(data, change, error, match):
    priors = {k: v for k, v in {**make_priors(), **change}.items() if v is not None}
    with pytest.raises(error, match=match) as info:
        skinfit.fit(make_model(), data, priors=priors, rng=1, **FAST)
    assert "\n" not in str(info.value)


def test_wrong_model_definitions_are_one_line():
    with pytest.raises(InputError, match="parameter 'voltage' shadows the covariate"):
        make_model(parameters={"k": "1", "voltage": "1"})
    with pytest.raises(InputError, match="parameter 'sigma' shadows the noise parameter"):
        make_model(parameters={"k": "1", "sigma": "N"})
    with pytest.raises(InputError, match="a lambda.*pass id="):
        make_model(lambda p, x: p["k"] * x["voltage"])
    with pytest.raises(InputError, match=r"must take \(p, x\)"):
        make_model(lambda p, x, c: p["k"], id="three")
    with pytest.raises(InputError, match="unknown unit"):
        make_model(parameters={"k": "furlong", "kappa": "1", "n": "1"})


def test_function_changed_since_the_fit_is_one_line(own_fit):
    text = own_fit.attrs["model_card"]
    recorded = tomllib.loads(text)["function_sha256"]
    changed = parse_model_text(text.replace(recorded, "0" * 64), "saved fit", "x", saved=True)
    with pytest.raises(InputError, match="source of own_model_function:powerlaw_ea has changed"):
        changed.forward
    moved = parse_model_text(text.replace("own_model_function:", "no_such_module_42:"), "saved fit", "x", saved=True)
    with pytest.raises(InputError, match="cannot import the model's function no_such_module_42:powerlaw_ea "
                                         r"\(ModuleNotFoundError.*needed only to evaluate the model again"):
        moved.forward


LOAD = """import importlib, json, sys
import skinfit
seen = []
for step in ("without", "with"):  # the function's module first off the path, then on it
    if step == "with":
        sys.path.insert(0, sys.argv[2])
        importlib.invalidate_caches()
    fit = skinfit.load_fit(sys.argv[1])
    try:
        posterior = fit.posterior.n  # rebuilding the posterior evaluates the model: needs the function
    except skinfit.InputError as exc:
        posterior = str(exc)
    seen.append({"k": float(fit.summary().loc["k", "mean"]), "posterior": posterior})
print(json.dumps(seen))
"""


def _load_elsewhere(path):
    """What a new process that loads the fit at ``path`` sees without the function's module on
    its path, then with it."""
    env = {**os.environ, "PYTHONPATH": str(TESTS.parent), "MPLBACKEND": "Agg"}
    done = subprocess.run([sys.executable, "-c", LOAD, str(path), str(TESTS)], capture_output=True, text=True,
                          env=env, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def saved(tmp_path_factory, own_fit, data):
    """The function-defined fit and electroadhesion_coulomb's on the same data, saved, and their
    comparison."""
    folder = tmp_path_factory.mktemp("fits")
    with pytest.warns(UserWarning):  # the competitor misfits the data, as it should
        coulomb = skinfit.fit("electroadhesion_coulomb", data, units={"normal_force": "N", "voltage": "V",
                                                                      "tangential_force": "N"}, rng=1, **FAST)
    own_fit.save(folder / "own")
    coulomb.save(folder / "coulomb")
    return folder, skinfit.compare([own_fit, coulomb])


def test_compare_with_a_shipped_model(saved):
    table = saved[1]
    assert list(table.index) == ["powerlaw_ea", "electroadhesion_coulomb"]  # the model that made the data wins
    assert table["log_z"].iloc[0] - table["log_z"].iloc[1] > 100 * table["log_z_se"].max()


def test_loaded_in_a_new_process(saved, own_fit):
    """Without the function importable the draws are there, and one line says what needs the
    function; with it the model is evaluated again."""
    without, with_function = _load_elsewhere(saved[0] / "own")
    k = float(own_fit.summary().loc["k", "mean"])
    assert without["posterior"].startswith("model card saved in fit (powerlaw_ea): function: cannot import the "
                                           "model's function own_model_function:powerlaw_ea (ModuleNotFoundError")
    assert without["k"] == pytest.approx(k)
    assert with_function["posterior"] == 300 and with_function["k"] == pytest.approx(k)


def test_report_of_both(saved, tmp_path, no_figures):
    write_report([saved[0] / "own", saved[0] / "coulomb"], tmp_path / "report", comparison=saved[1])
    html = (tmp_path / "report" / "index.html").read_text()
    assert "powerlaw_ea" in html and "electroadhesion_coulomb" in html and "Python function" in html


@pytest.mark.slow
def test_report_of_both_with_figures(saved, tmp_path):
    """The report's figures drawn (~40 s on a loaded 2-core machine): the function is evaluated
    for the predictive figures of the function-defined fit, in the model's units."""
    write_report([saved[0] / "own", saved[0] / "coulomb"], tmp_path / "report", comparison=saved[1])
    figures = {p.name for p in (tmp_path / "report" / "figures").rglob("*") if p.is_file()}
    assert any("powerlaw_ea" in name for name in figures), sorted(figures)


def test_a_prior_file_refuses_scipy_names_in_one_line(tmp_path):
    """Prior files take skinfit's documented names (lognormal: median, sigma); scipy's own (s,
    scale) are refused naming the expected ones and the translation; Python takes scipy's."""
    bad = tmp_path / "priors" / "powerlaw_ea.toml"
    bad.parent.mkdir()
    bad.write_text('schema_version = 1\nmodel = "powerlaw_ea"\n\n[k]\ndist = "lognormal"\ns = 1.0\nscale = 0.5\n'
                   'bounds = [0.0, inf]\nsource = "my notes"\n')
    with pytest.raises(InputError, match=r"powerlaw_ea.toml: k: unexpected keys \['s', 'scale'\] for a lognormal "
                                         r"prior \(expected median, sigma, bounds, source; scipy's lognorm\(s, scale\) "
                                         r"is lognormal median = scale, sigma = s\)") as info:
        skinfit.load_priors(bad)
    assert "\n" not in str(info.value)


def test_priors_as_a_user_writes_them_give_the_same_priors():
    """``skinfit priors`` shows each prior as a prior-file entry and as Python; the Python form,
    typed back in, is the shipped prior (family, arguments, bounds)."""
    from skinfit.io.user_priors import as_prior_set, as_written

    shipped = skinfit.load_priors("electroadhesion_coulomb")
    assert as_written(shipped["E_star"]) == (
        'dist = "lognormal", median = 40000.0, sigma = 0.6, bounds = [2000.0, 100000.0]',
        "skinfit.truncate(st.lognorm(s=0.6, scale=40000.0), 2000.0, 100000.0)")
    assert as_written(shipped["sigma"])[1] == "skinfit.truncate(st.halfnorm(scale=0.05), 0.0, 1.0)"
    model = skinfit.load_model("electroadhesion_coulomb")
    typed = as_prior_set({"E_star": skinfit.truncate(st.lognorm(s=0.6, scale=40000.0), 2000.0, 100000.0),
                          "mu": skinfit.truncate(st.norm(loc=0.5, scale=0.3), 0.0, 2.0),
                          "sigma": skinfit.truncate(st.halfnorm(scale=0.05), 0.0, 1.0)}, model)
    for name in typed:
        a, b = typed[name], shipped[name]
        assert (a.dist, dict(a.args), a.lower, a.upper) == (b.dist, dict(b.args), b.lower, b.upper), name


def test_the_executed_tutorial_runs_and_recovers_its_truth():
    """docs/tutorials/own-model.ipynb (executed by the docs build) runs as written, as a kernel
    would (one namespace, module ``__main__``), and its intervals hold the values it simulated from."""
    notebook = TESTS.parent / "docs" / "tutorials" / "own-model.ipynb"
    ns = {"__name__": "__main__"}
    for cell in json.loads(notebook.read_text())["cells"]:
        if cell["cell_type"] == "code":
            exec(compile("".join(cell["source"]), str(notebook), "exec"), ns)
    summary, truth = ns["summary"], ns["truth"]
    assert ns["fit"].converged and ns["model"].forward_ref == "__main__:powerlaw_ea"
    for name, value in truth.items():
        assert summary.loc[name, "hdi_3%"] < value < summary.loc[name, "hdi_97%"], name


def test_several_observables_from_a_dict():
    """A function returning a dict serves several observables: predictions by name, and noise
    parameters named per observable (the prior error lists them)."""
    def contact(p, x):
        return {"tangential_force": p["mu"] * x["normal_force"], "area": p["a"] * np.sqrt(x["normal_force"]) + 0 * p["mu"]}

    model = skinfit.Model.from_function(contact, observable={"tangential_force": "N", "area": "m^2"},
                                        covariates={"normal_force": "N"}, parameters={"mu": "1", "a": "m^2/N"})
    y = model.predict({"mu": 0.5, "a": 1e-4}, {"normal_force": np.array([1.0, 4.0])})
    np.testing.assert_array_equal(y["tangential_force"], [0.5, 2.0])
    np.testing.assert_array_equal(y["area"], [1e-4, 2e-4])
    frame = simulate(10, seed=1).drop(columns="voltage").assign(area=1e-4)
    with pytest.raises(InputError, match="a prior for 'sigma', which model 'contact' does not have .*noise: "
                                         "sigma_tangential_force, nu_tangential_force, sigma_area, nu_area"):
        skinfit.fit(model, frame, priors={"mu": st.uniform(0, 2), "a": st.uniform(0, 1e-3), "sigma": st.halfnorm()})


def test_group_fits_from_python(tmp_path):
    """``fit_by`` (the CLI's ``--by``) takes the function-defined model and its scipy priors."""
    from skinfit.io.data import from_frame

    model = make_model()
    frame = simulate(80, seed=3).assign(subject=["S1", "S2"] * 40)
    index = skinfit.fit_by(model, from_frame(frame, model=model), "subject", tmp_path / "by", priors=make_priors(),
                           seed=1, ess_target=60, n_global=200)
    assert list(index["status"]) == ["done", "done"] and list(index["rows"]) == [40, 40]
    assert sorted(skinfit.load_groups(tmp_path / "by")) == ["subject=S1", "subject=S2"]


def test_a_card_naming_an_unregistered_function_is_one_line(tmp_path):
    """A card file names only registered code: its ``function`` is found in the registry (a
    plug-in's entry point, or from_function in this process), never imported from the card."""
    text = make_model().card_text
    card = tmp_path / "models" / "powerlaw_ea.toml"
    card.parent.mkdir()
    card.write_text(text.replace("own_model_function:powerlaw_ea", "os:getcwd"))
    with pytest.raises(InputError, match="function: 'os:getcwd' is not a registered model function f\\(p, x\\)"):
        skinfit.load_model(card)
    card.write_text(text.replace('function = "', 'forward = "skinfit.physics.electroadhesion:electroadhesion"\n'
                                                 'function = "'))
    with pytest.raises(InputError, match="expected either forward = .* or function = .*, not both"):
        skinfit.load_model(card)


def test_a_card_whose_function_changed_says_how_to_mend_it(tmp_path):
    card = tmp_path / "models" / "powerlaw_ea.toml"
    card.parent.mkdir()
    text = make_model().card_text
    card.write_text(text.replace(tomllib.loads(text)["function_sha256"], "1" * 64))
    with pytest.raises(InputError, match=r"function_sha256: the source of own_model_function:powerlaw_ea has "
                                         r"changed .*write the card again \(Model.to_card\)"):
        skinfit.load_model(card)
    card.write_text(text.replace(f'function_sha256 = "{tomllib.loads(text)["function_sha256"]}"\n', ""))
    assert skinfit.load_model(card).function_sha256 == ""  # deleted: nothing checked
