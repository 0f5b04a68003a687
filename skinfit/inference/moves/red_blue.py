"""emcee's red-blue update with the accept step vectorised over the half-ensemble."""

import numpy as np
from emcee.moves import RedBlueMove

__all__ = ["VectorisedRedBlue"]


class VectorisedRedBlue(RedBlueMove):
    """emcee's red-blue update (:class:`emcee.moves.RedBlueMove`) with the accept step
    vectorised over the half-ensemble.

    emcee 3.1.6 accepts walker by walker in a Python loop (one random draw each) and converts
    the vectorised log-probabilities back to scalars one by one (checking for blobs; its cost in
    docs/design/sampling.md).  Same proposal, same Metropolis-Hastings rule; for a vectorised
    log-probability without blobs (skinfit's).
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
