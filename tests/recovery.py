"""Recovery checks shared by the tests of the shipped simulated datasets."""

import numpy as np
from scipy import stats


def coverage(checks, level):
    """Names of the truths outside their central 95% interval; asserts each truth lies inside
    its central ``level`` interval.  ``checks``: (name, posterior draws, truth)."""
    outside = []
    for name, draws, truth in checks:
        q = np.quantile(np.asarray(draws).ravel(), [(1 - level) / 2, 0.025, 0.975, (1 + level) / 2])
        assert q[0] < truth < q[3], f"{name}: truth {truth:g} outside {level:.1%} interval [{q[0]:g}, {q[3]:g}]"
        if not q[1] < truth < q[2]:
            outside.append(f"{name}: truth {truth:g} outside 95% interval [{q[1]:g}, {q[2]:g}]")
    return outside


def check_coverage(checks):
    """Calibrated for many checks per fit: every truth inside its central 99% interval, and no
    more truths outside their central 95% interval than Binomial(n, 0.05) gives with 99%
    probability (with 10-25 checks per fit, demanding every truth inside its 95% interval
    would fail a correct fit most of the time)."""
    outside = coverage(checks, 0.99)
    assert len(outside) <= stats.binom.ppf(0.99, len(checks), 0.05), outside
