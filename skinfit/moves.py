"""A correct, vectorised differential-evolution snooker move for emcee.

emcee 3.1.6 (the current release) ships a ``DESnookerMove`` whose direction vector is not a
unit vector and whose Metropolis factor is half the correct one, so it does not leave the
target invariant (fixed upstream in dfm/emcee PR #531, Dec 2024, not yet released).  This is
the move of Ter Braak & Vrugt (2008), Stat. Comput. 18:435: for a walker ``s`` and three other
walkers ``z, z1, z2``, with ``e = (s - z)/|s - z|``::

    q = s + gamma * (e . (z1 - z2)) * e,      log factor = (d - 1) * log(|q - z| / |s - z|)

vectorised over the walkers of a half-ensemble (emcee's own loops over walkers in Python).
tests/test_moves.py checks it on a correlated Gaussian, with emcee's released move as the
negative control.
"""

import numpy as np
from emcee.moves.red_blue import RedBlueMove

__all__ = ["SnookerMove", "default_moves"]


class SnookerMove(RedBlueMove):
    """Differential-evolution snooker update (Ter Braak & Vrugt 2008), vectorised.

    Parameters
    ----------
    gamma : float
        Step scale along the snooker axis; 1.7 as recommended by the paper.
    """

    def __init__(self, gamma=1.7, **kwargs):
        self.gamma = gamma
        kwargs["nsplits"] = 4
        super().__init__(**kwargs)

    def get_proposal(self, s, c, random):
        ns, ndim = s.shape
        picks = np.stack([cj[random.randint(len(cj), size=ns)] for cj in c], axis=1)  # (ns, 3, d)
        order = np.argsort(random.rand(ns, 3), axis=1)  # random roles per walker
        picks = np.take_along_axis(picks, order[:, :, None], axis=1)
        z, z1, z2 = picks[:, 0], picks[:, 1], picks[:, 2]
        delta = s - z
        norm = np.sqrt(np.einsum("ij,ij->i", delta, delta))
        e = delta / norm[:, None]
        q = s + (self.gamma * np.einsum("ij,ij->i", e, z1 - z2))[:, None] * e
        dq = q - z
        log_factor = (ndim - 1.0) * (0.5 * np.log(np.einsum("ij,ij->i", dq, dq)) - np.log(norm))
        return q, log_factor


def default_moves():
    """The move mixture skinfit samples with (chosen by measurement, see sampling.py)."""
    from emcee.moves import DEMove

    return [(DEMove(), 0.8), (SnookerMove(), 0.2)]
