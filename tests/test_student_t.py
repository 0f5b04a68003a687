"""Student-t noise offered without a prior (issue 39): `skinfit fit --help` offers
`--noise student_t`, so every shipped model must have a cited prior for its degrees of freedom
(the gamma(shape 2, rate 0.1) prior of Juarez & Steel 2010, one per observable: ``nu`` or
``nu_<observable>``), and a fit with it must run."""

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

import skinfit
from skinfit.apps.cli import main
from skinfit.io.references import parse_source, references
from skinfit.posterior import Posterior

ROOT = Path(skinfit.__file__).resolve().parents[1]


def _shipped_pairs():
    """(model, its shipped dataset) for every shipped model card: each dataset's model and variants."""
    pairs = []
    for path in sorted((ROOT / "datasets").glob("*/dataset.toml")):
        model = tomllib.loads(path.read_text()).get("model")
        if model:
            pairs += [(m, path.parent.name) for m in (model, *skinfit.load_model(model).variants)]
    return pairs


PAIRS = _shipped_pairs()


def test_the_pairs_cover_every_shipped_model_card():
    assert sorted(m for m, _ in PAIRS) == sorted(p.stem for p in (ROOT / "models").glob("*.toml"))


@pytest.mark.parametrize("model,dataset", PAIRS, ids=[m for m, _ in PAIRS])
def test_student_t_noise_without_a_prior_on_every_shipped_model(model, dataset, rng):
    """The posterior with Student-t noise builds from the shipped prior file (it used to stop at
    "no prior for nu"); each nu is the cited gamma(2, rate 0.1), whose prior draws have the
    published mean 20 and median 16.78 (gamma quantile, scipy); the likelihood is finite."""
    post = Posterior(skinfit.load_model(model), skinfit.load_priors(model), skinfit.load_dataset(dataset),
                     noise="student_t")
    nus = [n for n in post.noise_names if n.startswith("nu")]
    assert len(nus) == len(post.observables) >= 1
    draws = post.sample_prior(4000, rng)
    for name in nus:
        prior = post.priors[name]
        assert (prior.dist, dict(prior.args), prior.lower) == ("gamma", {"shape": 2.0, "scale": 10.0}, 0.0)
        assert [key for key, _ in parse_source(prior.source)] == ["juarez_steel2010"]
        nu = draws[:, post.names.index(name)]
        assert np.mean(nu) == pytest.approx(20.0, abs=4 * math.sqrt(200 / len(nu)))  # sd of gamma(2, 10): sqrt(200)
        assert np.median(nu) == pytest.approx(stats.gamma(2, scale=10).median(), rel=0.08)
    log_post = post(post.to_z(draws[:200]))
    assert not np.isnan(log_post).any() and np.isfinite(log_post).any()


def test_student_t_prior_cites_a_resolvable_work():
    ref = references()["juarez_steel2010"]
    assert ref["doi"] == "10.1198/jbes.2009.07145" and ref["year"] == 2010
    assert "Skew-t" in ref["title"]


def _cli_fit(model, dataset, out, steps):
    code = main(["fit", model, dataset, "--noise", "student_t", "--out", str(out), "--seed", "3",
                 "--max-steps", str(steps), "--ess", "10", "--quiet", "--json"])
    return code, skinfit.load_fit(out / "fit.nc") if (out / "fit.nc").exists() else None


def _check_student_t_fit(code, fit, capsys):
    assert code == 0, capsys.readouterr().err
    assert json.loads(fit.attrs["setup"])["noise"] == {o: "student_t" for o in fit.posterior.observables}
    for name in (n for n in fit.posterior.names if n.startswith("nu")):
        values = fit.group("posterior")[name].values
        assert np.all(np.isfinite(values) & (values > 0) & (values <= 1000))
        assert f"[{name}]" in fit.attrs["priors_text"] and "juarez_steel2010" in fit.attrs["priors_text"]
    assert any(n.startswith("nu") for n in fit.summary().index)


def test_student_t_noise_cli_fit(tmp_path, capsys):
    """`skinfit fit electroadhesion_coulomb electroadhesion_synthetic --noise student_t`: exit 0,
    nu sampled within its prior's bounds, the prior file it used recorded with the fit."""
    code, fit = _cli_fit("electroadhesion_coulomb", "electroadhesion_synthetic", tmp_path / "run", 60)
    _check_student_t_fit(code, fit, capsys)


@pytest.mark.slow
@pytest.mark.parametrize("model,dataset", PAIRS, ids=[m for m, _ in PAIRS])
def test_student_t_noise_cli_fit_on_every_shipped_model(model, dataset, tmp_path, capsys):
    """The same short CLI fit on every shipped model (10-25 s each: the MAP search and the
    start dominate)."""
    code, fit = _cli_fit(model, dataset, tmp_path / "run", 60)
    _check_student_t_fit(code, fit, capsys)
