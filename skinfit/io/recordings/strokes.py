"""Strokes: where the finger slides, and each stroke reduced to means with standard errors.

A stroke is a run of samples where |v| exceeds ``speed_above`` and the normal force exceeds
``normal_force_above``, with one sign of v (forward v > 0, backward v < 0).  ``trim`` seconds
are dropped at each end (the speed and force ramps) and a kept window shorter than
``min_duration`` is dropped, with that reason.  Each kept window gives, per signal, the mean and
its standard error sd / sqrt(n_eff), n_eff = n / tau with tau the integrated autocorrelation
time (emcee.autocorr.integrated_time, Sokal's automatic window c = 5): the scatter of a
filtered, serially correlated signal counts as n_eff independent samples, not n.
"""

import numpy as np
from emcee.autocorr import integrated_time

__all__ = ["runs", "window", "reduce_window", "standard_error"]


def runs(code):
    """(start, stop, sign) of each run of equal non-zero values of the int8 array ``code``
    (+1 forward, -1 backward, 0 neither); stop exclusive."""
    code = np.asarray(code, dtype=np.int8)
    if not len(code):
        return []
    edges = np.flatnonzero(np.diff(code)) + 1
    starts = np.concatenate([[0], edges])
    stops = np.concatenate([edges, [len(code)]])
    return [(int(a), int(b), int(code[a])) for a, b in zip(starts, stops) if code[a] != 0]


def window(start, stop, rate, trim, min_duration):
    """The kept window (a, b) of a stroke [start, stop) at ``rate`` Hz after trimming ``trim`` s
    at each end, and the reason it is dropped ("" when kept)."""
    k = round(trim * rate)
    a, b = start + k, stop - k
    if (b - a) / rate < min_duration or b - a < 2:
        return a, b, f"kept window {max(b - a, 0) / rate:.3g} s after trimming {trim:g} s at each end is shorter " \
                     f"than min_duration {min_duration:g} s"
    return a, b, ""


def standard_error(x):
    """(mean, se, n_eff) of a serially correlated series ``x`` (n,): se = sd / sqrt(n / tau)."""
    x = np.asarray(x, dtype=float)
    n = len(x)
    sd = float(np.std(x, ddof=1)) if n > 1 else 0.0
    tau = float(integrated_time(x, c=5, tol=0, quiet=True)[0]) if sd > 0 else 1.0
    n_eff = n / max(tau, 1.0)
    return float(np.mean(x)), sd / np.sqrt(n_eff), n_eff


def reduce_window(signals, names, rectify, sign):
    """One stroke's row: for each signal of ``names`` its mean and ``<name>_se``, the mean speed
    |v| and ``speed_se``, and ``n_eff`` (the smallest over the signals: the most correlated);
    a signal in ``rectify`` is reported as |mean| (a force whose sign follows the stroke)."""
    row, n_effs = {}, []
    for name in names:
        mean, se, n_eff = standard_error(signals[name])
        row[name] = abs(mean) if name in rectify else mean
        row[f"{name}_se"] = se
        n_effs.append(n_eff)
    mean, se, n_eff = standard_error(np.abs(signals["velocity"]))
    row["speed"], row["speed_se"] = mean, se
    n_effs.append(n_eff)
    row["n_eff"] = float(min(n_effs))
    return row
