"""Every move skinfit samples with, on a known target (emcee's own test_proposal pattern),
plus a negative control that must fail: emcee 3.1.6's DESnookerMove (dfm/emcee PR #531)."""

import emcee
import numpy as np
import pytest

from skinfit.moves import SnookerMove, default_moves

D = 5


def _sample(moves, seed, nsteps=6000, nwalkers=32):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(D, D))
    cov = a @ a.T + 0.5 * np.eye(D)
    prec = np.linalg.inv(cov)
    mean = rng.normal(size=D)

    def log_prob(x):
        r = x - mean
        return -0.5 * np.einsum("ij,jk,ik->i", r, prec, r)

    sampler = emcee.EnsembleSampler(nwalkers, D, log_prob, vectorize=True, moves=moves)
    p0 = mean + rng.normal(size=(nwalkers, D))
    sampler.run_mcmc(emcee.State(p0, random_state=np.random.RandomState(seed).get_state()), nsteps)
    chain = sampler.get_chain(discard=1000)
    tau = emcee.autocorr.integrated_time(chain, tol=0)
    flat = chain.reshape(-1, D)
    ess = chain.shape[0] * nwalkers / tau.max()
    return flat, mean, cov, ess


@pytest.mark.parametrize("moves", [[SnookerMove()], default_moves()], ids=["snooker", "default-mix"])
def test_move_samples_gaussian(moves):
    flat, mean, cov, ess = _sample(moves, seed=3)
    sd = np.sqrt(np.diag(cov))
    # Monte Carlo errors: mean sd/sqrt(ESS); variance ratio sqrt(2/ESS); allow 5 of them
    assert np.all(np.abs(flat.mean(axis=0) - mean) < 5 * sd / np.sqrt(ess))
    ratio = np.diag(np.cov(flat.T)) / np.diag(cov)
    assert np.all(np.abs(ratio - 1) < 5 * np.sqrt(2 / ess)), ratio


def test_negative_control_emcee_released_snooker_is_biased():
    flat, mean, cov, ess = _sample([emcee.moves.DESnookerMove()], seed=3)
    ratio = np.diag(np.cov(flat.T)) / np.diag(cov)
    # measured: variances ~25% too small in 5-D; the harness above must be able to see this
    assert np.all(np.abs(ratio - 1) > 5 * np.sqrt(2 / ess)), ratio


def test_vectorised_accept_gives_emcee_chain():
    """skinfit's moves accept a half-ensemble at once; emcee 3.1.6's RedBlueMove.propose loops
    over walkers.  Same proposals and the same random stream must give the identical chain."""
    from emcee.moves.red_blue import RedBlueMove

    from skinfit.moves import DEMove

    emcee_snooker = type("EmceeLoopSnooker", (RedBlueMove,), {"get_proposal": SnookerMove.get_proposal, "gamma": 1.7})
    chains = []
    for moves in ([(DEMove(), 0.8), (SnookerMove(), 0.2)], [(emcee.moves.DEMove(), 0.8), (emcee_snooker(), 0.2)]):
        sampler = emcee.EnsembleSampler(16, 3, lambda x: -0.5 * np.sum(x * x, axis=1), vectorize=True, moves=moves)
        p0 = np.random.default_rng(0).normal(size=(16, 3))
        sampler.run_mcmc(emcee.State(p0, random_state=np.random.RandomState(7).get_state()), 300)
        chains.append(sampler.get_chain())
    assert np.array_equal(chains[0], chains[1])
    assert 0.2 < np.mean(np.diff(chains[0], axis=0).any(axis=2)) < 0.8  # moves were accepted and rejected
