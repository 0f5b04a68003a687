"""Every prior file: closed-form densities against scipy, normalisation, sampling, refusals."""

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate, stats

import skinfit
from skinfit.io.priors import parse_prior

ROOT = Path(skinfit.__file__).resolve().parents[1]
PRIOR_FILES = sorted(p.stem for p in (ROOT / "priors").glob("*.toml"))
ALL_PRIORS = [(f, name) for f in PRIOR_FILES for name in skinfit.load_priors(f).names]


@pytest.mark.parametrize("file,name", ALL_PRIORS)
def test_logpdf_matches_scipy_truncated(file, name):
    prior = skinfit.load_priors(file)[name]
    f = prior.frozen
    mass = f.cdf(prior.upper) - f.cdf(prior.lower)
    x = prior.ppf(np.linspace(0.001, 0.999, 41))
    np.testing.assert_allclose(prior.logpdf(x), f.logpdf(x) - np.log(mass), rtol=1e-10, atol=1e-10)
    assert prior.logpdf(prior.lower - 1.0 - abs(prior.lower)) == -np.inf
    assert prior.logpdf(prior.upper + 1.0 + abs(prior.upper)) == -np.inf


@pytest.mark.parametrize("file,name", ALL_PRIORS)
def test_prior_is_normalised(file, name):
    prior = skinfit.load_priors(file)[name]
    lo, hi = prior.ppf(0.0), prior.ppf(1.0)
    # integrate in log space for positive, wide ranges
    if lo > 0:
        total, _ = integrate.quad(lambda t: math.exp(prior.logpdf(math.exp(t)) + t), math.log(lo), math.log(hi), limit=200)
    else:
        total, _ = integrate.quad(lambda t: math.exp(prior.logpdf(t)), lo, hi, limit=200,
                                  points=[float(prior.ppf(0.5))])
    assert total == pytest.approx(1.0, abs=2e-4)


@pytest.mark.parametrize("file", PRIOR_FILES)
def test_prior_only_sampling_matches_each_marginal(file, rng):
    """bilby-style prior-only check: draws through the engine's prior transform follow each
    truncated marginal (KS); then the KS p-values are themselves uniform-ish."""
    from skinfit.posterior import Posterior  # noqa: F401  (wiring exercised in test_fit)

    priors = skinfit.load_priors(file)
    pvals = []
    for name in priors.names:
        p = priors[name]
        draws = p.rvs(3000, rng)
        f = p.frozen
        c0, c1 = f.cdf(p.lower), f.cdf(p.upper)
        pvals.append(stats.kstest(draws, lambda x: (f.cdf(x) - c0) / (c1 - c0)).pvalue)
        assert np.all((draws >= p.lower) & (draws <= p.upper))
    assert min(pvals) > 1e-3, pvals


@pytest.mark.parametrize("file", PRIOR_FILES)
def test_every_prior_names_a_source_and_its_model_exists(file):
    priors = skinfit.load_priors(file)
    model = skinfit.load_model(priors.model)
    for name in priors.names:
        assert len(priors[name].source) > 10
    assert set(model.parameter_names) <= set(priors.names)


BAD_PRIORS = [
    ({"dist": "normal", "loc": 0, "scale": -5, "bounds": [0, 1], "source": "x"}, r"E_star.scale: must be > 0 \(got -5\)"),
    ({"dist": "uniform", "bounds": [0, float("inf")], "source": "x"}, "improper: give finite bounds"),
    ({"dist": "cauchy", "bounds": [0, 1], "source": "x"}, "unknown distribution 'cauchy'"),
    ({"dist": "normal", "loc": 0, "scale": 1, "bounds": [0, 1]}, r"E_star.source: missing required field"),
    ({"dist": "normal", "loc": 0, "scale": 1, "bounds": [2, 1], "source": "x"}, "expected lower < upper"),
    ({"dist": "lognormal", "median": 1, "sigma": 1, "bounds": [-1, 1], "source": "x"}, "leave the support of lognormal"),
    ({"dist": "normal", "loc": 0, "scale": 1, "bounds": [0, 1], "source": "x", "mean": 3}, r"unexpected keys \['mean'\]"),
    ({"dist": "halfnormal", "scale": 1e-3, "bounds": [50, 60], "source": "x"}, "no mass inside its bounds"),
]


@pytest.mark.parametrize("spec,match", BAD_PRIORS)
def test_bad_priors_refused(spec, match):
    with pytest.raises(skinfit.InputError, match=match):
        parse_prior("E_star", spec, "priors/x.toml")


def test_missing_prior_refused_before_sampling(tmp_path):
    text = (ROOT / "priors" / "electroadhesion.toml").read_text()
    start = text.index("[eta]")
    end = text.index("[alpha]")
    path = tmp_path / "ea.toml"
    path.write_text(text[:start] + text[end:])
    with pytest.raises(skinfit.InputError, match=r"ea.toml: no prior for eta"):
        skinfit.fit("electroadhesion", "electroadhesion_synthetic", priors=skinfit.load_priors(str(path)), rng=0)


@pytest.mark.parametrize("spec", [
    {"dist": "normal", "loc": 0.5, "scale": 1.078e16, "bounds": [0.0, 2.0]},  # found by the fuzz test
    {"dist": "normal", "loc": 0.5, "scale": 1e13, "bounds": [0.0, 2.0]},
])
def test_mass_of_bounds_narrow_beside_a_wide_prior(spec):
    """Bounds so narrow beside the prior's spread that its CDF cannot tell them apart (both
    ends read 0.5 to within 1e-12, where the CDF difference was 0 and gave a math domain
    error): the mass inside is width x density, 2 / (scale sqrt(2 pi)) (the density varies by
    (1.5 / scale)^2 across the bounds), and the truncated log-density is -log(2), that of the
    uniform it has become."""
    prior = parse_prior("mu", {**spec, "source": "test"}, "t")
    scale = spec["scale"]
    expected = math.log(2.0 / (scale * math.sqrt(2 * math.pi)))
    assert prior.log_mass == pytest.approx(expected, rel=1e-12)
    np.testing.assert_allclose(prior.logpdf(np.array([0.0, 1.0, 2.0])), -math.log(2.0), rtol=1e-12)


_SCIPY_CHECKS = ("leave the support", "no mass inside")


@pytest.mark.parametrize("spec,match", BAD_PRIORS)
def test_bounds_read_without_the_scipy_checks(spec, match):
    """``check_mass=False`` (a saved fit's priors read for its plots' axes) refuses every bad
    table as before, except the two checks that need scipy.stats: then the prior is returned
    with its bounds as written, where the full parse refuses it."""
    if not any(m in match for m in _SCIPY_CHECKS):
        with pytest.raises(skinfit.InputError, match=match):
            parse_prior("E_star", spec, "priors/x.toml", check_mass=False)
        return
    prior = parse_prior("E_star", spec, "priors/x.toml", check_mass=False)
    assert (prior.lower, prior.upper) == tuple(float(b) for b in spec["bounds"])
    with pytest.raises(skinfit.InputError, match=match):
        parse_prior("E_star", spec, "priors/x.toml")
