"""The differential-evolution snooker update of Ter Braak & Vrugt (2008), Stat. Comput. 18:435.

emcee 3.1.6 (the current release) ships a ``DESnookerMove`` whose direction vector is not a
unit vector and whose Metropolis factor is half the correct one, so it does not leave the
target invariant (fixed upstream in dfm/emcee PR #531, not yet released). For a walker ``s`` and
three other walkers ``z, z1, z2``, with ``e = (s - z)/|s - z|``::

    q = s + gamma * (e . (z1 - z2)) * e,      log factor = (d - 1) * log(|q - z| / |s - z|)

vectorised over the walkers of a half-ensemble (emcee's own loops over walkers in Python).
"""

import numpy as np

from skinfit.inference.moves.red_blue import VectorisedRedBlue

__all__ = ["SnookerMove"]


class SnookerMove(VectorisedRedBlue):
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
