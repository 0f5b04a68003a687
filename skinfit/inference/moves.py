"""The moves skinfit samples with: independence Metropolis-Hastings from a fitted mixture
(the main move, see skinfit/sampling.py), emcee's differential evolution with a vectorised
accept step, and a correct snooker move.

emcee 3.1.6 (the current release) ships a ``DESnookerMove`` whose direction vector is not a
unit vector and whose Metropolis factor is half the correct one, so it does not leave the
target invariant (fixed upstream in dfm/emcee PR #531, Dec 2024, not yet released).
:class:`SnookerMove` is the move of Ter Braak & Vrugt (2008), Stat. Comput. 18:435: for a
walker ``s`` and three other walkers ``z, z1, z2``, with ``e = (s - z)/|s - z|``::

    q = s + gamma * (e . (z1 - z2)) * e,      log factor = (d - 1) * log(|q - z| / |s - z|)

vectorised over the walkers of a half-ensemble (emcee's own loops over walkers in Python).
tests/test_moves.py checks every move on a correlated Gaussian, with emcee's released
snooker move and an independence move without its Hastings factor as negative controls.
"""

import numpy as np
from emcee import moves
from emcee.moves.move import Move
from emcee.moves.red_blue import RedBlueMove

__all__ = ["SnookerMove", "DEMove", "IndependenceMove", "default_moves"]


class _VectorisedRedBlue(RedBlueMove):
    """emcee's red-blue update with the accept step vectorised over the half-ensemble.

    emcee 3.1.6 accepts walker by walker in a Python loop (one random draw each) and converts
    the vectorised log-probabilities back to scalars one by one (checking for blobs): 0.2 ms a
    step with 32 walkers, ~15% of a step on the electroadhesion posterior.  Same proposal, same
    Metropolis-Hastings rule; for a vectorised log-probability without blobs (skinfit's).
    """

    def propose(self, model, state):
        nwalkers, ndim = state.coords.shape
        if nwalkers < 2 * ndim and not self.live_dangerously:
            raise RuntimeError("It is unadvisable to use a red-blue move with fewer walkers than twice "
                               "the number of dimensions.")
        self.setup(state.coords)
        accepted = np.zeros(nwalkers, dtype=bool)
        inds = np.arange(nwalkers) % self.nsplits
        if self.randomize_split:
            model.random.shuffle(inds)
        for split in range(self.nsplits):
            members = np.flatnonzero(inds == split)
            c = [state.coords[inds == j] for j in range(self.nsplits) if j != split]
            q, factors = self.get_proposal(state.coords[members], c, model.random)
            if not np.isfinite(q).all():
                raise ValueError("a proposal has a non-finite coordinate")
            new = np.asarray(model.log_prob_fn(q), dtype=float).reshape(len(q))
            if np.isnan(new).any():
                raise ValueError("Probability function returned NaN")
            ok = np.log(model.random.rand(len(q))) < factors + new - state.log_prob[members]
            state.coords[members[ok]] = q[ok]
            state.log_prob[members[ok]] = new[ok]
            accepted[members] = ok
        return state, accepted


class DEMove(_VectorisedRedBlue, moves.DEMove):
    """emcee's differential-evolution move (Ter Braak 2006; Nelson et al. 2013), vectorised accept."""


class SnookerMove(_VectorisedRedBlue):
    """Differential-evolution snooker update (Ter Braak & Vrugt 2008), vectorised.

    Parameters
    ----------
    gamma : float
        Step scale along the snooker axis; 1.7 as recommended by the paper.
    """

    def __init__(self, gamma=1.7, **kwargs):
        self.gamma = gamma
        super().__init__(**kwargs)

    def get_proposal(self, s, c, random):
        c = np.concatenate(c, axis=0)  # the complementary walkers (the other half)
        ns, ndim = s.shape
        picks = np.argsort(random.rand(ns, len(c)), axis=1)[:, :3]  # three distinct walkers each
        z, z1, z2 = c[picks[:, 0]], c[picks[:, 1]], c[picks[:, 2]]
        delta = s - z
        norm = np.sqrt(np.einsum("ij,ij->i", delta, delta))
        e = delta / norm[:, None]
        q = s + (self.gamma * np.einsum("ij,ij->i", e, z1 - z2))[:, None] * e
        dq = q - z
        log_factor = (ndim - 1.0) * (0.5 * np.log(np.einsum("ij,ij->i", dq, dq)) - np.log(norm))
        return q, log_factor


class IndependenceMove(Move):
    """Independence Metropolis-Hastings: every walker proposes a fresh draw ``q`` of a fixed
    density ``g`` (:class:`skinfit.inference.proposal.MixtureT`) and accepts with probability
    ``min(1, pi(q) g(x) / (pi(x) g(q)))``.

    With ``substeps`` = k > 1, one emcee step is k such updates in a row.  Their proposals do
    not depend on the walker, so all k x nwalkers of them are drawn and evaluated in one
    vectorised call before the k accept/reject decisions are made in order, each against the
    walker as the previous one left it (Jacob, Robert & Smith 2011, J. Comput. Graph. Stat.
    20:616, "Using parallel computation to improve independent Metropolis-Hastings based
    estimation"): the same Markov chain as k separate steps, for the cost of one call on k
    times the points: for 96 points against 32, 1.4-2x the time on four shipped posteriors and
    2.2-3.9x on wavy_surface, whose cost depends on the draws (best of 5 x 100 calls;
    skinfit/sampling.py).  The step counts as accepted for a walker when any of its k
    updates was.

    ``g`` must not depend on the current walkers: the sampler replaces it only between runs of
    steps (:func:`skinfit.inference.sampling.run_emcee`), so each run of steps is a time-homogeneous
    Markov chain that leaves the posterior invariant.
    """

    def __init__(self, proposal, substeps=1):
        if int(substeps) < 1:
            raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
        self.proposal = proposal
        self.substeps = int(substeps)

    def propose(self, model, state):
        nwalkers, d = state.coords.shape
        k = self.substeps
        q = self.proposal.draw(model.random, k * nwalkers)  # rows j*nwalkers: the j-th update's
        new = np.asarray(model.log_prob_fn(q), dtype=float).reshape(k, nwalkers)
        if np.isnan(new).any():
            raise ValueError("Probability function returned NaN")
        log_g = self.proposal.logpdf(np.concatenate([state.coords, q]))
        g_x, g_q = log_g[:nwalkers].copy(), log_g[nwalkers:].reshape(k, nwalkers)
        log_u = np.log(model.random.rand(k, nwalkers))
        log_prob, pick = state.log_prob.copy(), np.full(nwalkers, -1)
        with np.errstate(invalid="ignore"):  # -inf - -inf: both outside the support, reject
            for j in range(k):
                ok = log_u[j] < new[j] - log_prob + g_x - g_q[j]
                pick[ok], log_prob[ok], g_x[ok] = j, new[j, ok], g_q[j, ok]
        moved = np.flatnonzero(pick >= 0)
        state.coords[moved] = q.reshape(k, nwalkers, d)[pick[moved], moved]
        state.log_prob = log_prob
        return state, pick >= 0


def default_moves():
    """The moves for a target without an independence proposal (the population
    hyper-posterior): DE 0.9 + snooker 0.1, chosen by measurement on the shipped
    electroadhesion posterior (max autocorrelation time 35 steps with 10% snooker vs 39 with
    20%; on a standard 8-D Gaussian, 26-28 steps either way)."""
    return [(DEMove(), 0.9), (SnookerMove(), 0.1)]
