"""A raw 1 kHz force recording with serially correlated noise, for the misfit check's tests
and its calibration study (bench/misfit.py)."""

import numpy as np


def power_law_recording(rng, n, phi):
    """``n`` rows at 1 kHz: time (s), normal force (N) fluctuating row to row around 1 N, and
    tangential force (N) from the empirical power law (b 0.3, c 0.67, d 0.3) plus AR(1) noise of
    lag-1 correlation ``phi`` and sd 20 mN; draws taken from ``rng`` in that order."""
    t = np.arange(n) / 1000.0
    fn = 1.0 + 0.1 * np.sin(2 * np.pi * 0.2 * t) + rng.uniform(-0.5, 0.5, n)
    innovations = rng.normal(0.0, 0.02 * np.sqrt(1 - phi**2), n)
    eps = np.empty(n)
    eps[0] = rng.normal(0.0, 0.02)
    for i in range(1, n):
        eps[i] = phi * eps[i - 1] + innovations[i]
    return t, fn, 0.3 * fn**0.67 + 0.3 * fn + eps
