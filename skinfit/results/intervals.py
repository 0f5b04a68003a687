"""The one interval convention of every table skinfit writes: a highest-density interval (HDI)
at probability :data:`CI_PROB` (94%, ArviZ 1.x's ``stats.ci_prob`` with ``stats.ci_kind``
set to ``"hdi"``), used by the fits' summaries, the tables across subjects, the populations
and the contrasts, named in each table's header (:func:`interval_name`) and set by one option
(``--ci`` on the command line, ``ci_prob=`` in Python)."""

import math

import numpy as np

from skinfit.errors import InputError

__all__ = ["CI_PROB", "CI_KIND", "interval_name", "interval_columns", "check_ci", "hdi"]

#: Probability of every interval a table shows unless the user sets another (``--ci``)
CI_PROB = 0.94
#: Kind of every interval: the highest-density interval, as ``arviz_stats.hdi`` computes it
CI_KIND = "hdi"


def check_ci(prob, where="ci_prob"):
    """``prob`` as a float when it is a number with 0 < prob < 1, else an :class:`InputError`."""
    if isinstance(prob, bool) or not isinstance(prob, (int, float, np.floating, np.integer)) \
            or not math.isfinite(float(prob)) or not 0 < float(prob) < 1:
        raise InputError(where, f"expected an interval probability between 0 and 1, e.g. 0.94 or 0.9 (got {prob!r})",
                         field="ci_prob")
    return float(prob)


def interval_name(prob=CI_PROB):
    """The interval's name as headers show it: ``94% HDI``."""
    return f"{100 * float(prob):g}% HDI"


def interval_columns(prob=CI_PROB):
    """Names of the lower and upper ends of the HDI at ``prob`` in a summary table, by the
    share of the draws below each end of a central interval: ``("hdi_3%", "hdi_97%")`` at 0.94,
    ``("hdi_5%", "hdi_95%")`` at 0.9."""
    tail = round(50 * (1 - float(prob)), 6)
    return f"hdi_{tail:g}%", f"hdi_{100 - tail:g}%"


def hdi(x, prob=CI_PROB):
    """Highest-density interval of 1-D draws ``x``: the narrowest interval between two sorted
    draws holding ``floor(prob * n)`` steps of them, ``(lower, upper)``, as
    ``arviz_stats.hdi(x, prob)`` ("nearest" method) gives it (tests/test_contrasts.py checks
    that). Five lines of our own rather than a call: importing arviz_stats takes 1.4 s (it brings
    scipy.stats), which loading a fit and drawing its figures otherwise do without."""
    x = np.sort(np.asarray(x, dtype=float).ravel())
    if not 0 < prob <= 1 or len(x) == 0:
        raise ValueError(f"expected draws and 0 < prob <= 1 (got {len(x)} draws, prob {prob})")
    steps = min(int(np.floor(prob * len(x))), len(x) - 1)
    lo = int(np.argmin(x[steps:] - x[:len(x) - steps]))
    return float(x[lo]), float(x[lo + steps])
