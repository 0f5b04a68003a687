"""Differential evolution (Ter Braak 2006; Nelson et al. 2013): emcee's proposal, vectorised accept."""

from emcee import moves

from skinfit.inference.moves.red_blue import VectorisedRedBlue

__all__ = ["DEMove"]


class DEMove(VectorisedRedBlue, moves.DEMove):
    """emcee's differential-evolution move (:class:`emcee.moves.DEMove`), vectorised accept
    (:class:`~skinfit.inference.moves.red_blue.VectorisedRedBlue`)."""
