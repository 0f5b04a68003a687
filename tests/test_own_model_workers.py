"""A model made from a Python function goes everywhere a shipped model goes (issue 42): to worker
processes (pickled, its function by module and name), SBC with two workers, a population over
per-subject fits, contrasts between fits, and an experimental design from the model or a fit;
a noise prior outside [0, inf] says what applies to a noise parameter."""

import multiprocessing
import pickle
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
from own_model_function import TRUTH, fit_medians, predict_with, simulate
from test_own_model import make_model, make_priors

import skinfit
from skinfit.errors import InputError
from skinfit.io.data import as_dataset
from skinfit.io.user_functions import UserForward, restore_forward
from skinfit.io.user_priors import as_prior_set

SHORT = {"ess_target": 60, "n_global": 200}
K = {"s0": 0.45, "s1": 0.5, "s2": 0.55}  # each subject's generating k; the other parameters TRUTH's
CANDIDATES = {"normal_force": np.linspace(0.2, 2.0, 5).repeat(3), "voltage": np.tile([0.0, 100.0, 200.0], 5)}
DESIGN = {"n": 4, "rng": 1, "n_outer": 50, "n_inner": 50, "n_batch": 50, "n_draws": 200}


@pytest.fixture(scope="module")
def subject_fits():
    """Three subjects' fits of the function model (80 rows each), k as in :data:`K`."""
    model, priors = make_model(), make_priors()
    return {s: skinfit.fit(model, simulate(80, seed=i, truth={**TRUTH, "k": k}), priors=priors, rng=i, **SHORT)
            for i, (s, k) in enumerate(K.items())}


def test_a_function_model_pickles_and_evaluates_identically():
    model = make_model()
    back = pickle.loads(pickle.dumps(model))
    assert back == model and isinstance(back.function, UserForward) and back.function.func is model.function.func
    p = {"k": 0.5, "kappa": 2e-6, "n": 0.8}
    x = {"normal_force": np.array([1.0, 2.0]), "voltage": np.array([100.0, 0.0])}
    expected = 0.5 * (x["normal_force"] + 2e-6 * x["voltage"] ** 2) ** 0.8
    np.testing.assert_allclose(model.predict(p, x), expected, rtol=1e-14)
    assert np.array_equal(back.predict(p, x), model.predict(p, x))
    # a shipped card's read-only tables (nested ones too) come back read-only and equal
    shipped = skinfit.load_model("electroadhesion")
    again = pickle.loads(pickle.dumps(shipped))
    assert again == shipped and type(again.product["beta0"]) is type(shipped.product["beta0"])
    with pytest.raises(TypeError):
        again.constants["R"] = 1.0


def test_a_function_that_cannot_reach_workers_is_one_line():
    lam = make_model(lambda p, x: p["k"] * x["normal_force"] ** p["n"], id="lam")
    with pytest.raises(InputError, match=r"<lambda> cannot be sent to worker processes \(a lambda.*define it at "
                                         r"the top level of a module") as info:
        pickle.dumps(lam)
    assert "\n" not in str(info.value)
    # a notebook's function unpickled in a spawned worker, whose __main__ does not define it
    with pytest.raises(InputError, match=r"__main__:powerlaw_nb is not defined in this worker process: a function "
                                         r"defined in a notebook or at a prompt \(__main__\) reaches fork-started workers only"):
        restore_forward("__main__:powerlaw_nb", "", ("tangential_force",), "model from function powerlaw_nb")


def test_spawned_workers_evaluate_a_function_model_as_this_process_does():
    """Two spawned workers (a fresh interpreter each: the model crosses by pickle, its function
    imported there by module and name) predict what this process predicts, bit for bit."""
    model = make_model()
    x = {"normal_force": np.array([0.5, 1.5]), "voltage": np.array([200.0, 50.0])}
    params = [{"k": 0.5, "kappa": 2e-6, "n": 0.8}, {"k": 0.3, "kappa": 1e-6, "n": 1.1}]
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        there = list(pool.map(predict_with, [model] * 2, params, [x] * 2))
    for got, p in zip(there, params):
        assert np.array_equal(got, model.predict(p, x))


@pytest.mark.slow
def test_spawned_workers_fit_a_function_model_as_this_process_does():
    """Fits in two spawned workers give the posterior medians this process gives for the same
    seeds, bit for bit (~20 s on a loaded 2-core machine: behind the slow marker)."""
    model, priors = make_model(), make_priors()
    frames = [simulate(60, seed=s) for s in (3, 4)]
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        there = list(pool.map(fit_medians, [model] * 2, frames, [priors] * 2, [11, 12]))
    here = [fit_medians(model, f, priors, s) for f, s in zip(frames, (11, 12))]
    assert there == here


def test_sbc_with_two_workers_on_a_function_model():
    """SBC of the function model in two (forked) workers ranks as one process does."""
    model = make_model()
    kw = {"dataset": as_dataset(simulate(40, seed=5), model=model), "priors": as_prior_set(make_priors(), model),
          "n_sims": 2, "n_draws": 9, "ess_target": 30, "max_steps": 600, "n_global": 100, "seed": 3}
    two = skinfit.run_sbc(model, jobs=2, **kw)
    one = skinfit.run_sbc(model, jobs=1, **kw)
    assert list(two.ranks.columns) == ["k", "kappa", "n", "sigma"]
    assert two.ranks.equals(one.ranks) and two.truth.equals(one.truth)
    assert ((two.ranks >= 0) & (two.ranks <= 9)).all().all()


def test_contrasts_of_function_model_fits(subject_fits):
    """The ratio of k between subjects covers the generating ratio."""
    table = skinfit.fit_contrasts(subject_fits, "k", rng=1).set_index(["A", "B"])
    for (a, b), row in table.iterrows():
        assert row["ratio_lower"] < K[a] / K[b] < row["ratio_upper"], (a, b, row)


def test_population_over_function_model_fits(subject_fits):
    """The population of k over three subjects: its median covers the generating ones' geometric mean."""
    pop = skinfit.population(subject_fits, ["k"], rng=1, ess_target=100, max_sweeps=3000)
    row = pop.summary().set_index(["parameter", "quantity"]).loc[("k", "median")]
    assert row["lower"] < np.exp(np.mean(np.log(list(K.values())))) < row["upper"]


def test_design_from_a_function_model_and_from_its_fit(tmp_path, subject_fits):
    model, priors = make_model(), make_priors()
    baseline = simulate(60, seed=1)
    with pytest.raises(InputError, match=r"^design: priors: model 'powerlaw_ea' was made from a Python function and "
                                         r"has no prior file: pass priors="):
        skinfit.design(model, CANDIDATES, baseline=baseline, **DESIGN)
    plan = skinfit.design(model, CANDIDATES, baseline=baseline, priors=priors, **DESIGN)
    # the same model and priors as a card and a prior file plan the same measurements
    files = model.to_card(tmp_path, priors)
    card = skinfit.design(skinfit.load_model(files["model"]), CANDIDATES, baseline=baseline,
                          priors=skinfit.load_priors(files["priors"]), **DESIGN)
    assert plan.plan.equals(card.plan) and plan.table.equals(card.table)
    from_fit = skinfit.design(subject_fits["s0"], CANDIDATES, **DESIGN)
    assert len(from_fit.plan) == 4 and from_fit.settings["start"].startswith("the posterior of fit powerlaw_ea")
    with pytest.raises(InputError, match="priors= applies to a model"):
        skinfit.design(subject_fits["s0"], CANDIDATES, priors=priors, **DESIGN)
