"""The sampler: its autocorrelation estimate, the adaptive independence proposal (exact on a
known target; resume across refits: tests/test_checkpoint.py), the importance start, and
walkers placed around a MAP on a bound."""

from pathlib import Path

import emcee
import numpy as np

import skinfit
from skinfit.inference import sampling
from skinfit.inference.optimize import find_map
from skinfit.inference.proposal import MixtureT
from skinfit.inference.sampling import ADAPT_FIRST, initial_ball, integrated_time, run_emcee
from skinfit.posterior import Posterior

BENCH_PRIORS = Path(__file__).parents[1] / "bench" / "priors_electroadhesion_uniform.toml"


def _ar1(rng, n, walkers, rho, d=2):
    """AR(1) chains, whose integrated autocorrelation time is (1 + rho) / (1 - rho)."""
    x = np.empty((n, walkers, d))
    x[0] = rng.normal(size=(walkers, d))
    noise = rng.normal(size=(n, walkers, d)) * np.sqrt(1 - rho**2)
    for t in range(1, n):
        x[t] = rho * x[t - 1] + noise[t]
    return x


def test_integrated_time_agrees_with_emcee_and_the_closed_form(rng):
    x = _ar1(rng, 4000, 32, rho=0.8)
    ours = integrated_time(x)
    np.testing.assert_allclose(ours, emcee.autocorr.integrated_time(x, tol=0), rtol=0.05)
    np.testing.assert_allclose(ours, (1 + 0.8) / (1 - 0.8), rtol=0.1)


def test_integrated_time_of_a_stuck_walker_is_long_not_nan(rng):
    """A walker that never moves (an independence sampler rejecting for the whole window):
    emcee's per-walker normalisation gives NaN; ours counts the walker's offset as correlation,
    and a correlation that never decays within the chain as a long time (emcee's window
    function returns the window 0, tau = 1, when no window satisfies Sokal's condition)."""
    x = _ar1(rng, 400, 32, rho=0.5)
    x[:, 7] = 3.0
    with np.errstate(invalid="ignore", divide="ignore"):
        assert np.isnan(emcee.autocorr.integrated_time(x, tol=0)).all()
    tau = integrated_time(x)
    assert np.all(np.isfinite(tau)) and np.all(tau > 2 * (1 + 0.5) / (1 - 0.5))
    assert np.all(integrated_time(np.ones((100, 4, 2))) == np.inf)


class _Gaussian:
    """A correlated 4-D Gaussian target with the ``counts`` a Posterior keeps."""

    def __init__(self, seed=0):
        r = np.random.default_rng(seed)
        a = r.normal(size=(4, 4))
        self.cov = a @ a.T + 0.5 * np.eye(4)
        self.prec = np.linalg.inv(self.cov)
        self.mean = r.normal(size=4)
        self.counts = {"evaluations": 0}

    def __call__(self, x):
        self.counts["evaluations"] += len(x)
        r = x - self.mean
        return -0.5 * np.einsum("ij,jk,ik->i", r, self.prec, r)


def test_adaptive_run_is_exact_and_refits_on_schedule(rng):
    """From a poor starting proposal (the wrong mean, no correlations) the refitted proposal
    samples the target: moments within 5 Monte Carlo errors; refits at ADAPT_FIRST, twice
    that, ... until converged, and the kept chain starts after the last one."""
    target = _Gaussian()
    start = MixtureT([1.0], (target.mean + 2)[None], np.eye(4)[None])
    p0 = target.mean + rng.normal(size=(32, 4))
    run = run_emcee(target, p0, rng, proposal=start, ess_target=8000, check_every=100)
    assert run.converged
    assert run.evaluations == target.counts["evaluations"] > 32 * run.n_steps  # three a walker per independence step
    steps = [a["step"] for a in run.adaptation]
    assert steps[:2] == [ADAPT_FIRST, 2 * ADAPT_FIRST] and steps == [ADAPT_FIRST * 2**i for i in range(len(steps))]
    last_refit = max(a["step"] for a in run.adaptation if a["refit"])
    assert run.burn >= last_refit
    flat = run.chain.reshape(-1, 4)
    ess = run.ess_emcee.min() if len(flat) > run.ess_emcee.min() else len(flat)
    sd = np.sqrt(np.diag(target.cov))
    assert np.all(np.abs(flat.mean(axis=0) - target.mean) < 5 * sd / np.sqrt(ess))
    assert np.all(np.abs(np.diag(np.cov(flat.T)) / np.diag(target.cov) - 1) < 5 * np.sqrt(2 / ess))
    assert run.tau.max() < 10  # DE alone: ~20 on a 4-D Gaussian


def test_walkers_placed_around_a_map_in_a_corner_of_the_prior(rng):
    """With uniform priors the electroadhesion posterior piles up against two upper bounds
    (E_star, phi): a centre on both bounds has three quarters of any ball around it outside the
    prior, and every walker is still placed inside.  The corner is set by hand (the MAP's other
    coordinates, E_star and phi at their bounds): where a multistart optimiser stops on that
    flat ridge is not what this test is about."""
    post = Posterior(skinfit.load_model("electroadhesion"), skinfit.load_priors(str(BENCH_PRIORS)),
                     skinfit.load_dataset("electroadhesion_synthetic"))
    corner = find_map(post, np.random.default_rng(3), n_local=4).theta.copy()
    for name in ("E_star", "phi"):  # a hair inside: exp(log(hi)) may round one ulp above hi
        corner[post.names.index(name)] = post._hi[post.names.index(name)] * (1 - 1e-12)
    z0 = post.to_z(corner[None])[0]
    assert np.isfinite(post(z0[None]))[0]
    p0 = initial_ball(post, z0, np.eye(post.ndim), 64, rng)
    assert np.all(np.isfinite(post(p0))) and len(np.unique(p0, axis=0)) == 64
    # the ball really straddles the corner: without the placement rule most draws fall outside
    naive = z0 + 0.1 * rng.normal(size=(256, post.ndim))
    assert np.mean(np.isfinite(post(naive))) < 0.5


def test_importance_start_improves_a_poor_proposal_and_places_walkers(rng):
    """From a proposal off the target (mean shifted by 1 sd, 1.5 sd wide, no correlations), population
    Monte Carlo rounds raise the effective sample size of the importance weights, and the
    walkers are distinct draws inside the support; from a hopeless proposal (far away), no
    walkers are returned and the caller falls back to the ball around the MAP."""
    from skinfit.inference.sampling import IMPORTANCE_GOOD, importance_start

    target = _Gaussian()
    sd = np.sqrt(np.diag(target.cov))
    poor = MixtureT([1.0], (target.mean + sd)[None], np.diag((1.5 * sd) ** 2)[None])
    proposal, walkers, rounds = importance_start(target, poor, 32, rng)
    ess = [r["ess"] for r in rounds]
    assert len(rounds) >= 2 and ess[-1] > 3 * ess[0] and max(ess) >= IMPORTANCE_GOOD * rounds[0]["draws"]
    assert walkers.shape == (32, 4) and len(np.unique(walkers, axis=0)) == 32
    # the returned proposal is the one that scored best, and it resembles the target
    np.testing.assert_allclose(proposal.weights @ proposal.means, target.mean, atol=0.2 * sd.max())
    far = MixtureT([1.0], (target.mean + 50 * sd)[None], np.diag(sd**2)[None])
    _, none, record = importance_start(target, far, 32, rng, tempered=0)
    assert none is None and len(record) == 1 and record[0]["ess"] < 50


def test_tempered_rounds_find_a_posterior_far_from_the_proposal(rng):
    """A proposal 50 sd off the target, whose weights are degenerate: tempered refits walk it to
    the target, and the walkers start in its typical set (their mean within 0.5 sd of the target's)."""
    from skinfit.inference.sampling import IMPORTANCE_MIN_ESS, importance_start

    target = _Gaussian()
    sd = np.sqrt(np.diag(target.cov))
    far = MixtureT([1.0], (target.mean + 50 * sd)[None], np.diag(sd**2)[None])
    _, walkers, record = importance_start(target, far, 32, rng)
    assert record[0]["ess"] < IMPORTANCE_MIN_ESS <= max(r["ess"] for r in record)
    assert walkers is not None and np.all(np.abs(walkers.mean(axis=0) - target.mean) < 0.5 * sd)


class _Cusp:
    """log density -sum_i |u_i . (z - m)| / b_i: independent Laplace densities along the rows
    u_i of a rotation, a cusp at the mode m; along u_i the standard deviation is sqrt(2) b_i."""

    def __init__(self, d=4, seed=0):
        r = np.random.default_rng(seed)
        self.u = np.linalg.qr(r.normal(size=(d, d)))[0].T
        self.b = np.geomspace(0.5, 4.0, d)
        self.m = r.normal(size=d)

    def __call__(self, z):
        return -np.sum(np.abs((z - self.m) @ self.u.T) / self.b, axis=1)


def test_importance_start_widens_a_laplace_proposal_at_a_cusp(rng):
    """The start fit.start makes, on a density whose mode is a cusp: the finite-difference
    Hessian there (step 1e-3) makes the Laplace proposal ~40-120x too narrow, and its importance
    weights are degenerate.  The start must still reach an effective sample size of
    IMPORTANCE_MIN_ESS, place walkers, and return a proposal whose importance-weighted draws
    have the closed-form standard deviation sqrt(2) b_i along each axis u_i (the walkers, from
    the Laplace ball, had 1/40 of it)."""
    from skinfit.inference.optimize import laplace_covariance
    from skinfit.inference.sampling import IMPORTANCE_MIN_ESS, importance_start

    target = _Cusp()
    cov = laplace_covariance(target, target.m)
    laplace = MixtureT.with_wide_half(target.m, cov)  # as fit.start builds it
    exact = np.sqrt(2.0) * target.b
    assert np.all(np.sqrt(np.diag(target.u @ cov @ target.u.T)) < exact / 20)  # the failure this guards
    proposal, walkers, record = importance_start(target, laplace, 64, rng)
    assert record[0]["ess"] < IMPORTANCE_MIN_ESS <= max(r["ess"] for r in record) and walkers is not None
    x = proposal.draw(rng, 40000)
    w = np.exp(target(x) - proposal.logpdf(x))
    w /= w.sum()
    along = (x - target.m) @ target.u.T
    sd = np.sqrt(w @ (along - w @ along) ** 2)
    assert 1 / np.sum(w**2) > 1000
    np.testing.assert_allclose(sd, exact, rtol=0.1)
    np.testing.assert_allclose(w @ along, 0.0, atol=0.1 * exact.min())


def test_a_chain_converged_at_a_refit_step_is_kept_not_refitted(rng, monkeypatch):
    """At a step where a refit is due the convergence check comes first: a refit restarts the
    judged chain, and would throw away one that has already converged.  Exact proposal on a
    Gaussian (tau ~ 2) with refits forced (TAU_KEEP = 0) at step 300: converged there, where
    checking after the refit ran to 900 steps (refits at 300 and 600)."""
    monkeypatch.setattr(sampling, "TAU_KEEP", 0.0)
    monkeypatch.setattr(sampling, "ADAPT_FIRST", 300)
    target = _Gaussian(seed=1)
    exact = MixtureT([1.0], target.mean[None], target.cov[None])
    run = run_emcee(target, exact.draw(rng, 32), rng, proposal=exact, check_every=300)
    assert run.converged and run.n_steps == 300
    assert run.adaptation == () and run.burn < 300

