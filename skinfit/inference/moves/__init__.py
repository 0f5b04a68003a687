"""The moves skinfit samples with, one per module (emcee's layout): independence
Metropolis-Hastings from a fitted mixture (:mod:`.independence`, the main move, see
:mod:`skinfit.inference.sampling`), emcee's differential evolution with a vectorised accept step
(:mod:`.de`), and a correct snooker move (:mod:`.snooker`), the last two on the vectorised
red-blue update of :mod:`.red_blue`.

tests/test_moves.py checks every move on a correlated Gaussian, with emcee's released snooker
move and an independence move without its Hastings factor as negative controls.
"""

from skinfit.inference.moves.de import DEMove
from skinfit.inference.moves.independence import IndependenceMove
from skinfit.inference.moves.snooker import SnookerMove

__all__ = ["SnookerMove", "DEMove", "IndependenceMove", "default_moves"]


def default_moves():
    """The moves for a target without an independence proposal (the population
    hyper-posterior): DE 0.9 + snooker 0.1, chosen by measurement on the shipped
    electroadhesion posterior (docs/design/sampling.md)."""
    return [(DEMove(), 0.9), (SnookerMove(), 0.1)]
