"""Independence Metropolis-Hastings from a fixed density (Jacob, Robert & Smith 2011 for the
vectorised substeps)."""

import numpy as np
from emcee.moves import Move

__all__ = ["IndependenceMove"]


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
    times the points (docs/design/sampling.md).  The step counts as accepted for a walker when
    any of its k updates was.

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
