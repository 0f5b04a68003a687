"""Knows nothing about skin: the MAP start (nlopt), the proposal, emcee moves and
sampling, checkpoints, the guard rails on a run, worker processes, and one fit's run of them
(:mod:`~skinfit.inference.run`)."""
