"""The posterior's coordinate maps: exact round trips and the Jacobian it claims."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

import skinfit
from skinfit.inference.optimize import find_map
from skinfit.posterior import Posterior

#: The shipped data set of each model used here.
SHIPPED = {"electroadhesion": "electroadhesion_synthetic", "electroadhesion_empirical": "electroadhesion_synthetic",
           "textured_surface": "textured_synthetic", "textured_no_transition": "textured_synthetic",
           "contact_area": "contact_area_synthetic", "wavy_surface": "wavy_synthetic",
           "ultrasonic": "ultrasonic_synthetic"}
#: Every card with a ``[sampling]`` table.
DECLARED = {"electroadhesion", "electroadhesion_empirical", "textured_surface", "textured_no_transition", "ultrasonic"}


def _posterior(model):
    return Posterior(skinfit.load_model(model), skinfit.load_priors(model), skinfit.load_dataset(SHIPPED[model]))


@pytest.fixture(scope="module", params=sorted(DECLARED))
def post(request):
    return _posterior(request.param)


def test_every_card_with_sampling_coordinates_is_covered():
    declared = {m for m in skinfit.list_models()
                if (c := skinfit.load_model(m)).shear or c.shift or c.product or c.linear}
    assert declared == DECLARED


@pytest.mark.parametrize("model, transforms", [
    ("electroadhesion", {"phi": "log", "d_air": "shift_log", "beta0": "product"}),
    ("textured_surface", {"alpha": "identity", "beta_h": "product", "E_fingerpad": "log"}),
    ("ultrasonic", {"mu_0": "identity", "q": "log", "mu_inf": "log"}),
])
def test_declared_coordinates_take_effect(model, transforms):
    post = _posterior(model)
    got = {s.name: s.transform for s in post.slots}
    assert {p: got[p] for p in transforms} == transforms
    sheared = {"electroadhesion": ["phi"], "ultrasonic": ["mu_inf"]}.get(model, [])
    assert [post.slots[j].base for j, _ in post._shear] == sheared


def test_round_trip(post, rng):
    theta = post.sample_prior(50, rng)
    np.testing.assert_allclose(post.to_theta(post.to_z(theta)), theta, rtol=1e-13)


def test_log_jacobian_matches_numerical_determinant(post, rng):
    for theta in post.sample_prior(5, rng):
        z = post.to_z(theta[None])[0]
        h = 1e-6 * np.maximum(1.0, np.abs(z))
        jac = np.empty((post.ndim, post.ndim))
        for i in range(post.ndim):
            e = np.zeros(post.ndim)
            e[i] = h[i]
            jac[:, i] = (post.to_theta((z + e)[None])[0] - post.to_theta((z - e)[None])[0]) / (2 * h[i])
        sign, logdet = np.linalg.slogdet(jac)
        assert sign > 0
        assert post.log_jacobian(z[None])[0] == pytest.approx(logdet, abs=1e-6)


def test_call_equals_density_plus_jacobian(post, rng):
    z = post.to_z(post.sample_prior(20, rng))
    np.testing.assert_allclose(post(z), post.log_density(post.to_theta(z)) + post.log_jacobian(z), rtol=1e-12)


@pytest.mark.parametrize("model", ["electroadhesion", "textured_surface", "contact_area", "wavy_surface", "ultrasonic"])
def test_posterior_equals_the_hand_fused_expression(model, rng):
    """An independent evaluation of the log posterior in the sampling coordinates, Jacobian
    written out by hand (bench/fused.py, the throughput floor of issue 7), at prior draws
    and points near the MAP: equal to 1e-10 relative, with the same -inf pattern."""
    spec = importlib.util.spec_from_file_location("fused", Path(__file__).parents[1] / "bench" / "fused.py")
    fused = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(fused)
    post = _posterior(model)
    z = post.to_z(post.sample_prior(48, rng))
    z_map = post.to_z(find_map(post, rng, n_global=500, n_local=1).theta[None])
    z = np.concatenate([z, z_map + 0.01 * rng.standard_normal((16, post.ndim))])
    result = fused.check_fused(post, fused.make_fused(post), z)
    assert result["finite"] >= 16


def test_new_coordinates_are_finite_at_a_zero_bound_and_exact(rng):
    """With uniform priors reaching 0 (the benchmark's), d_air = 0 and beta0 = 0 are inside the
    prior: the shifted log of d_air is finite there, and the maps stay exact inverses."""
    priors = skinfit.load_priors(str(Path(__file__).parents[1] / "bench" / "priors_electroadhesion_uniform.toml"))
    post = Posterior(skinfit.load_model("electroadhesion"), priors, skinfit.load_dataset("electroadhesion_synthetic"))
    theta = post.sample_prior(40, rng)
    theta[:10, post.names.index("d_air")] = 0.0
    theta[5:15, post.names.index("beta0")] = 0.0
    z = post.to_z(theta)
    assert np.isfinite(z).all()
    np.testing.assert_allclose(post.to_theta(z), theta, rtol=1e-12, atol=1e-300)
    assert np.all(post.log_prior(post.to_theta(z)) > -np.inf)  # d_air = 0 stays inside the prior
    np.testing.assert_allclose(post(z), post.log_density(theta) + post.log_jacobian(z), rtol=1e-12)


@pytest.mark.parametrize("model, k, sizes", [("ultrasonic", 600, [200, 200, 200]), ("wavy_surface", 96, [48, 48])])
def test_large_ensembles_are_evaluated_in_blocks_with_equal_results(rng, model, k, sizes):
    """More than CHUNK parameter vectors (memory of quadrature models), or more than
    EVAL_CELLS cells of vectors x distinct rows (cache: wavy_surface's 720 rows, 68 vectors),
    are evaluated in equal blocks (ultrasonic: CHUNK 256, so 3 blocks of 600 / 3; wavy: 49152 /
    720 = 68, so 2 of 96 / 2); totals, pointwise values, predictions and validity equal one
    single call's."""
    post = _posterior(model)
    theta = post.sample_prior(k, rng)
    seen = []
    block = post._evaluate_block
    post._evaluate_block = lambda t, *a: seen.append(len(t)) or block(t, *a)
    post.log_likelihood(theta)
    del post._evaluate_block
    assert seen == sizes
    blocked = post.log_likelihood(theta), post.pointwise(theta)
    single = Posterior(post.model, post.priors, post.dataset)
    single.CHUNK = single.EVAL_CELLS = 10**9
    np.testing.assert_array_equal(blocked[0], single.log_likelihood(theta))
    ll, pred, valid = single.pointwise(theta)
    for o in ll:
        np.testing.assert_array_equal(blocked[1][0][o], ll[o])
        np.testing.assert_array_equal(blocked[1][1][o], pred[o])
    np.testing.assert_array_equal(blocked[1][2], valid)


def _contact_area_by_subject(noise):
    """contact_area with ``m0`` split by subject and the given noise model (Student-t: a nu
    prior per observable)."""
    from types import MappingProxyType

    from skinfit.io.priors import PriorSet, parse_prior

    priors = skinfit.load_priors("contact_area")
    nu = {f"nu_{o}": parse_prior(f"nu_{o}", {"dist": "gamma", "shape": 2, "scale": 10, "bounds": [1, 200],
                                              "source": "test"}, "t") for o in ("contact_area", "impedance")}
    priors = PriorSet("t", priors.model, MappingProxyType({**priors.priors, **nu}))
    return Posterior(skinfit.load_model("contact_area"), priors, skinfit.load_dataset("contact_area_synthetic"),
                     noise=noise, split={"m0": "subject"})


@pytest.mark.parametrize("noise", ["normal", "lognormal", "student_t"])
def test_replicate_in_cache_blocks_equals_pointwise_then_simulate(noise, rng):
    """The result tree's log-likelihood and posterior predictive, computed block by block
    (:meth:`Posterior.replicate`, here 3 draws per block), equal :meth:`pointwise` followed by
    :meth:`simulate` from the same random state, bit for bit; and the simulated noise follows
    the noise model: the probability integral transform of every (draw, row) cell under
    scipy's distribution with that draw's parameters is uniform (Kolmogorov-Smirnov)."""
    post = _contact_area_by_subject(noise)
    theta = post.sample_prior(300, rng)
    theta = theta[post.pointwise(theta)[2]][:40]
    post.BLOCK_CELLS = 3 * post.n
    ll, simulated = post.replicate(theta, np.random.default_rng(5))
    ref_ll, pred, _ = post.pointwise(theta)
    ref_sim = post.simulate(theta, np.random.default_rng(5))
    p = post.unpack(theta)
    for o in post.observables:
        np.testing.assert_array_equal(ll[o], ref_ll[o])
        np.testing.assert_array_equal(simulated[o], ref_sim[o])
        mu, y, sigma = pred[o], simulated[o], p[f"sigma_{o}"]
        pit = {"normal": lambda: stats.norm.cdf(y, mu, sigma),
               "student_t": lambda: stats.t.cdf(y, p[f"nu_{o}"], mu, sigma),
               "lognormal": lambda: stats.lognorm.cdf(y, sigma, scale=mu)}[noise]()
        assert stats.kstest(pit.ravel(), "uniform").pvalue > 1e-3
    with pytest.raises(ValueError, match="outside the physical support"):
        post.replicate(post.sample_prior(300, rng), rng)


@pytest.mark.parametrize("noise", ["normal", "lognormal", "student_t"])
def test_totals_over_repeated_rows_equal_the_row_by_row_sum(noise, rng):
    """The sampling hot path evaluates the forward model once per distinct row and sums the
    normal / log-normal likelihood from group counts, means and within-group sums of squares;
    the total must equal scipy's log-density summed row by row.  contact_area: 13 subjects
    pressed at the same 42 (force, actuation force) settings, two observables; with ``m0``
    split by subject the groups must also separate the subjects (546 groups, not 42)."""
    post = _contact_area_by_subject(noise)
    model = post.model
    assert (post.n, post.n_unique) == (1638, 546)
    theta = post.sample_prior(30, rng)
    p = post.unpack(theta)
    pred, ok = model.forward(p, post.x, post.constants)  # row by row, no grouping
    ref = 0.0
    for o in post.observables:
        mu, y, sigma = pred[o], post.y[o], p[f"sigma_{o}"]
        ref = ref + {"normal": lambda: stats.norm.logpdf(y, mu, sigma),
                     "student_t": lambda: stats.t.logpdf(y, p[f"nu_{o}"], mu, sigma),
                     "lognormal": lambda: stats.lognorm.logpdf(y, sigma, scale=mu)}[noise]().sum(axis=1)
    total = post.log_likelihood(theta)
    valid = np.broadcast_to(ok, (len(theta), post.n)).all(axis=1)  # inside the physical support
    assert valid.sum() >= 5 and np.isfinite(ref).all()
    np.testing.assert_allclose(total[valid], ref[valid], rtol=1e-10)
    assert np.all(total[~valid] == -np.inf)
